"""``toploc map`` with the slow fake extractor, for tests that run the CLI as a real process.

``python -m mapdb_cli_with_fake_extractor build DATASET --db MAP ...`` (with this folder and the
repository on ``PYTHONPATH``) runs the real ``toploc map`` click group, its process pool and its
signal handling, with ``toploc.extraction.extract_panorama`` replaced by
:func:`mapdb_fake_extractor.slow_extract` (delay: ``TOPLOC_FAKE_EXTRACT_DELAY_S`` seconds).
The extractor is pickled by reference: the spawned workers import ``mapdb_fake_extractor`` too.
"""

from __future__ import annotations

from mapdb_fake_extractor import slow_extract

from toploc import extraction
from toploc.commands import map as map_cli


def main() -> None:
    """Patch the extractor, then run ``toploc map`` on ``sys.argv``."""
    extraction.extract_panorama = slow_extract  # type: ignore[assignment]
    map_cli.map_group.main(prog_name="toploc map")


if __name__ == "__main__":
    main()
