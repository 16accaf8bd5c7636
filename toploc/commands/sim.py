"""``toploc sim``: closed-loop runs of the simulated robot in a rendered world.

Each subcommand lives in its own module (``sim_<name>.py``) and is registered here.
"""

from __future__ import annotations

import click

from toploc.commands.sim_kidnap import kidnap
from toploc.commands.sim_p2os import p2os


@click.group(name="sim")
def sim_group() -> None:
    """Run the simulated robot closed-loop in a rendered world."""


sim_group.add_command(kidnap)
sim_group.add_command(p2os)
