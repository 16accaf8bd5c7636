"""The ``toploc`` command line: a click group that registers one module per subcommand."""

from __future__ import annotations

import click

from toploc import __version__
from toploc.commands.belief import belief
from toploc.commands.dataset import dataset
from toploc.commands.demo import demo
from toploc.commands.eval import eval_group
from toploc.commands.localize import localize
from toploc.commands.map import map_group
from toploc.commands.serve import serve
from toploc.commands.sim import sim_group
from toploc.commands.simulate import simulate


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="toploc")
def main() -> None:
    """toploc: which room is the robot in, and where should it drive to find out."""


main.add_command(simulate)
main.add_command(dataset)
main.add_command(map_group)
main.add_command(eval_group)
main.add_command(sim_group)
main.add_command(belief)
main.add_command(localize)
main.add_command(demo)
main.add_command(serve)
