"""``toploc eval``: measurements on panorama datasets (homing, alignment, localization).

Each subcommand lives in its own module (``eval_<name>.py``) and is registered here.
"""

from __future__ import annotations

import click


@click.group(name="eval")
def eval_group() -> None:
    """Measure homing, alignment and localization on panorama datasets."""
