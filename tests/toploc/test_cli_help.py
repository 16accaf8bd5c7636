"""Every ``toploc`` command and option says what it is for; the long-running ones say how they
stop (Ctrl-C exits 130, SIGTERM 0)."""

from __future__ import annotations

from collections.abc import Iterator

import click
from click.testing import CliRunner

from toploc.cli import main
from toploc.commands.options import STOP_SIGNALS_HELP

LONG_RUNNING = [
    ("serve",),
    ("node", "robot"),
    ("node", "camera"),
    ("node", "localizer"),
    ("node", "map"),
    ("sim", "p2os"),
]


def commands(
    group: click.Group, path: tuple[str, ...] = ()
) -> Iterator[tuple[tuple[str, ...], click.Command]]:
    for name, command in group.commands.items():
        if isinstance(command, click.Group):
            yield from commands(command, (*path, name))
        else:
            yield (*path, name), command


def test_every_command_and_option_has_help() -> None:
    missing = [
        f"toploc {' '.join(path)} {' '.join(param.opts) if param else '(the command)'}"
        for path, command in commands(main)
        for param in [None, *(p for p in command.params if isinstance(p, click.Option))]
        if not (command.help if param is None else param.help)
    ]
    assert missing == []


def test_each_long_running_command_says_how_it_stops() -> None:
    for path in LONG_RUNNING:
        result = CliRunner().invoke(main, [*path, "--help"], terminal_width=1000)
        assert result.exit_code == 0, result.output
        assert STOP_SIGNALS_HELP in " ".join(result.output.split()), path
