"""``toploc eval``: measurements on panorama datasets (homing, alignment, localization).

Each subcommand lives in its own module (``eval_<name>.py``) and is registered here.
"""

from __future__ import annotations

import click


@click.group(name="eval")
def eval_group() -> None:
    """Measure homing, alignment and localization on panorama datasets."""


from toploc.commands.eval_align import align_command  # noqa: E402
from toploc.commands.eval_homing import homing_command  # noqa: E402
from toploc.commands.eval_localize import localize_command  # noqa: E402

eval_group.add_command(homing_command)
eval_group.add_command(align_command)
eval_group.add_command(localize_command)
