"""``toploc sim``: closed-loop runs of the simulated robot in a rendered world.

Each subcommand lives in its own module (``sim_<name>.py``) and is registered here.
"""

from __future__ import annotations

import click


@click.group(name="sim")
def sim_group() -> None:
    """Run the simulated robot closed-loop in a rendered world."""
