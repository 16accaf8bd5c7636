"""The ``toploc`` command line: a click group that registers one module per subcommand.

Errors: a command reports what the user can fix as ``Error: <message>`` (a
``click.ClickException``). Anything else that escapes a command is still printed as one line,
``Error: <type>: <message> (run with --debug for the traceback)``, exit status 1; ``toploc
--debug <command>`` lets it through with its traceback. SIGTERM is handled like Ctrl-C
(``KeyboardInterrupt``: cleanup runs, exit status 130), unless a command installs its own
handler (``serve`` and ``node`` do).

Logging (:mod:`toploc.logs`): ``-v`` (repeatable) and ``--log-level`` on the group, before the
command (``toploc -v serve``, ``toploc --log-level debug node map ...``), to stderr.
"""

from __future__ import annotations

import faulthandler
import signal
import sys
from types import FrameType
from typing import Any

import click

from toploc import __version__
from toploc.commands.belief import belief
from toploc.commands.dataset import dataset
from toploc.commands.demo import demo
from toploc.commands.drive import drive
from toploc.commands.eval import eval_group
from toploc.commands.localize import localize
from toploc.commands.map import map_group
from toploc.commands.node import node_group
from toploc.commands.serve import serve
from toploc.commands.sim import sim_group
from toploc.commands.simulate import simulate
from toploc.commands.site import site_group
from toploc.logs import LEVELS, chosen_level, configure_logging

INTERRUPTED_EXIT = 130  # 128 + SIGINT, what shells report for Ctrl-C


def one_line(error: BaseException) -> str:
    """The first line of ``error``'s message, prefixed with its type (an unexpected error)."""
    lines = str(error).strip().splitlines()
    text = lines[0] if lines else "(no message)"
    return f"{type(error).__name__}: {text}"


def _terminate_like_ctrl_c(signum: int, _frame: FrameType | None) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


class ToplocGroup(click.Group):
    """The root group: one-line errors unless ``--debug``; Ctrl-C and SIGTERM exit 130."""

    def invoke(self, ctx: click.Context) -> Any:
        previous = signal.getsignal(signal.SIGTERM)
        if previous is signal.SIG_DFL:
            signal.signal(signal.SIGTERM, _terminate_like_ctrl_c)
        try:
            return super().invoke(ctx)
        except (click.ClickException, click.exceptions.Exit, click.Abort):
            raise
        except KeyboardInterrupt:
            click.echo("interrupted", err=True)
            sys.exit(INTERRUPTED_EXIT)
        except Exception as error:
            if ctx.obj and ctx.obj.get("debug"):
                raise
            raise click.ClickException(
                f"{one_line(error)} (run with --debug for the traceback)"
            ) from error
        finally:
            if previous is signal.SIG_DFL:
                signal.signal(signal.SIGTERM, signal.SIG_DFL)


@click.group(cls=ToplocGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="toploc")
@click.option("--debug", is_flag=True, help="Show the traceback of an unexpected error.")
@click.option(
    "-v",
    "--verbose",
    count=True,
    help="Log more on stderr: one step per -v from the command's default level (WARNING; "
    "INFO for serve and node), INFO then DEBUG.",
)
@click.option(
    "--log-level",
    type=click.Choice(LEVELS, case_sensitive=False),
    default=None,
    envvar="TOPLOC_LOG_LEVEL",
    help="Log at this level on stderr (wins over -v). [default: WARNING; INFO for serve and "
    "node] [env: TOPLOC_LOG_LEVEL]",
)
@click.pass_context
def main(ctx: click.Context, debug: bool, verbose: int, log_level: str | None) -> None:
    """toploc: which room is the robot in, and where should it drive to find out."""
    ctx.obj = {"debug": debug}
    configure_logging(chosen_level(ctx.invoked_subcommand, verbose, log_level))


def run() -> None:
    """The ``toploc`` program: :func:`main`, with ``SIGUSR1`` printing every thread's stack to
    stderr (for a service that seems stuck: ``kill -USR1 PID``; it goes on running)."""
    if hasattr(signal, "SIGUSR1"):
        faulthandler.register(signal.SIGUSR1, all_threads=True)
    main()


main.add_command(simulate)
main.add_command(dataset)
main.add_command(map_group)
main.add_command(eval_group)
main.add_command(sim_group)
main.add_command(belief)
main.add_command(drive)
main.add_command(localize)
main.add_command(demo)
main.add_command(serve)
main.add_command(node_group)
main.add_command(site_group)
