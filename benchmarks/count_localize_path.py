"""Count the modules `toploc localize IMAGE --db FILE` visits from the image to the belief.

What is counted: every Python ``call`` event (``sys.setprofile``) of a function defined in
toploc's own packages (``homing``, ``mapdb``, ``localizer``, ``robot``, ``toploc``) while the
command's path runs once: reading the image (``localizer.panorama_io.read_panorama``) and one
one-shot query (``Localizer.localize_once``). The map is loaded before tracing starts, and
nothing is imported during it (the query runs once untraced first), so import time is not
counted. C functions (OpenCV, numpy) are not Python calls and are left out.

The calls, in order, are a sequence of modules. A *visit* is a maximal run of calls in one
module; a module *re-entered* ``k`` times has ``k + 1`` visits (the path left it for another
module and came back ``k`` times). Printed: the distinct modules, the total of visits, and each
module's visits and calls.

    python -m benchmarks.count_localize_path [--db FILE --image IMAGE] [--detector sift]

(run from the repository, so that its packages are the ones imported: the code it counts is
printed first).

Without ``--db``, a small map of the rendered ``building`` world (512 x 96 px, 2 m spacing) is
built in a temporary folder and one of its own panoramas is the query.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

PACKAGES = ("homing", "mapdb", "localizer", "robot", "toploc")


def small_map(root: Path) -> tuple[Path, Path]:
    """A SIFT map of the rendered ``building`` world under ``root``: ``(db_path, image)``."""
    from mapdb.build import build_map
    from mapdb.database import MapDatabase
    from mapdb.dataset import read_edges, read_manifest
    from mapdb.graph import connect_known_rooms
    from robot.dataset import render_dataset
    from robot.render import PanoramaCamera
    from toploc.extraction import resolve_extractor

    dataset = root / "dataset"
    render_dataset(
        dataset, "building", spacing_m=2.0, camera=PanoramaCamera(512, 96), progress=False
    )
    db_path = root / "map.db"
    entries = read_manifest(dataset)
    with MapDatabase.open(db_path) as map_db:
        build_map(map_db, entries, resolve_extractor(("sift",)), workers=0, progress=False)
        connect_known_rooms(map_db, read_edges(dataset))
    return db_path, entries[len(entries) // 2].path


def module_of(frame: FrameType) -> str | None:
    """The toploc module whose code ``frame`` runs, or None for any other code."""
    name = str(frame.f_globals.get("__name__", ""))
    return name if name.split(".")[0] in PACKAGES else None


CAMERA_MODELS = ("Cylinder", "Equirect")


def traced_modules(run: Callable[[], Any]) -> tuple[list[str], int]:
    """The module of each Python call event into toploc's packages while ``run()`` runs, and
    how many camera models were built (``__post_init__`` of a ``Cylinder`` or ``Equirect``)."""
    calls: list[str] = []
    cameras = 0

    def profile(frame: FrameType, event: str, _arg: object) -> None:
        nonlocal cameras
        if event == "call":
            module = module_of(frame)
            if module is not None:
                calls.append(module)
                own = frame.f_locals.get("self")
                if frame.f_code.co_name == "__post_init__" and type(own).__name__ in CAMERA_MODELS:
                    cameras += 1

    sys.setprofile(profile)
    try:
        run()
    finally:
        sys.setprofile(None)
    return calls, cameras


def visits(calls: list[str]) -> Counter[str]:
    """How many maximal runs of consecutive calls each module has in ``calls``."""
    runs: Counter[str] = Counter()
    previous = None
    for module in calls:
        if module != previous:
            runs[module] += 1
        previous = module
    return runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, help="a map database (default: a small one, built)")
    parser.add_argument("--image", type=Path, help="the query panorama (with --db)")
    parser.add_argument("--detector", default="sift")
    parser.add_argument("--sequence", action="store_true", help="print the visits in order")
    args = parser.parse_args()

    from localizer.panorama_io import read_panorama
    from toploc.commands.localize import load_localizer

    with tempfile.TemporaryDirectory() as tmp:
        if args.db is None:
            db_path, image = small_map(Path(tmp))
        else:
            db_path, image = args.db, args.image
        localizer = load_localizer(db_path, args.detector, None)

        def path() -> None:
            localizer.localize_once(read_panorama(image))

        path()  # once untraced: every lazy import done, every cache warm
        calls, cameras = traced_modules(path)
    runs = visits(calls)
    per_module = Counter(calls)
    import localizer

    print(f"code: {Path(localizer.__file__).parent.parent}; query: {image}")
    print(
        f"{len(runs)} modules, {sum(runs.values())} visits, "
        f"{sum(1 for n in runs.values() if n > 1)} modules visited more than once, "
        f"{sum(n - 1 for n in runs.values())} re-entries; {len(calls)} calls; "
        f"{cameras} camera models built"
    )
    print(f"{'module':32s} {'visits':>6s} {'calls':>6s}")
    for module, n in sorted(runs.items(), key=lambda item: (-item[1], item[0])):
        print(f"{module:32s} {n:6d} {per_module[module]:6d}")
    if args.sequence:
        print(" -> ".join(m for i, m in enumerate(calls) if i == 0 or calls[i - 1] != m))


if __name__ == "__main__":
    main()
