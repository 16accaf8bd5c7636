"""The docs site builds strictly, and every command the docs and the README show is a real one.

The site (``mkdocs.yml``, ``docs/``) is built as CI builds it: ``python -m mkdocs build --strict``
fails on a broken link or anchor. A shell line ``$ toploc ...`` or ``$ python -m toploc ...`` in a
page names a command of ``toploc.cli.main`` and options that command has; the commands are parsed
with click, never run.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import click
import pytest

from toploc.cli import main

REPO = Path(__file__).resolve().parents[2]
PAGES = sorted((REPO / "docs").glob("*.md"))
README = REPO / "README.md"


def shell_lines(text: str) -> Iterator[str]:
    """The ``$ `` lines of ``text``'s code blocks, continuation lines (``\\``) joined."""
    lines = iter(text.splitlines())
    for line in lines:
        if not line.startswith("$ "):
            continue
        command = line[2:]
        while command.endswith("\\"):
            command = command[:-1] + " " + next(lines).strip()
        yield command


def toploc_invocations(command: str) -> Iterator[list[str]]:
    """The arguments after ``toploc`` of each ``toploc``/``python -m toploc`` call in ``command``
    (a shell line: calls joined by ``&&``, a trailing ``# comment``)."""
    for part in re.split(r"&&|\|\||;", command):
        words = shlex.split(part, comments=True)
        if words[:1] == ["toploc"]:
            yield words[1:]
        elif words[:3] == ["python", "-m", "toploc"]:
            yield words[3:]


def check_invocation(args: list[str]) -> str:
    """The command path ``args`` names (``toploc map build``); ``AssertionError`` saying which
    command or option does not exist, or which choice is not among a choice option's."""
    command: click.Command = main
    path = ["toploc"]
    words = list(args)
    while words:
        word = words.pop(0)
        if word == "--":
            break
        if word.startswith("-"):
            name, _, inline_value = word.partition("=")
            option = _option(command, name)
            assert option is not None, f"{' '.join(path)} has no option {name} ({args})"
            if option.is_flag or option.count or inline_value:
                continue
            for _ in range(option.nargs):
                assert words, f"{' '.join(path)} {name} needs a value ({args})"
                _check_choice(option, words.pop(0), path)
        elif isinstance(command, click.Group):
            sub = command.get_command(click.Context(command), word)
            assert sub is not None, f"{' '.join(path)} has no command {word!r} ({args})"
            command, path = sub, [*path, word]
    return " ".join(path)


def _option(command: click.Command, name: str) -> click.Option | None:
    for param in command.get_params(click.Context(command)):
        if isinstance(param, click.Option) and name in (*param.opts, *param.secondary_opts):
            return param
    return None


def _check_choice(option: click.Option, value: str, path: list[str]) -> None:
    if isinstance(option.type, click.Choice):
        assert value in option.type.choices, (
            f"{' '.join(path)} {option.opts[0]}: {value!r} is not one of {option.type.choices}"
        )


def documented_commands() -> list[tuple[str, list[str]]]:
    """Every toploc call on a ``$`` line of the docs pages and the README, with its page."""
    found = []
    for page in (*PAGES, README):
        for line in shell_lines(page.read_text(encoding="utf-8")):
            found += [(page.name, args) for args in toploc_invocations(line)]
    return found


def command_paths(command: click.Command, path: str = "toploc") -> Iterator[str]:
    """``toploc``, ``toploc map``, ``toploc map build``, ...: every command under ``command``."""
    yield path
    if isinstance(command, click.Group):
        for name in command.list_commands(click.Context(command)):
            sub = command.get_command(click.Context(command), name)
            assert sub is not None
            yield from command_paths(sub, f"{path} {name}")


def test_the_docs_site_builds_strictly_with_every_command_in_its_reference(tmp_path: Path):
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
        cwd=REPO, capture_output=True, text=True, env=env, timeout=600,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    reference = (tmp_path / "cli" / "index.html").read_text(encoding="utf-8")
    for path in command_paths(main):
        assert f'id="{path.replace(" ", "-")}"' in reference, f"{path} is not in the reference"


@pytest.mark.parametrize(("page", "args"), documented_commands(), ids=lambda v: str(v)[:60])
def test_a_documented_command_names_a_real_command_and_options(page: str, args: list[str]):
    assert check_invocation(args) != "toploc", f"{page}: toploc {args} names no command"


def test_the_docs_show_commands_of_every_kind() -> None:
    commands = {check_invocation(args) for _, args in documented_commands()}
    assert {"toploc demo", "toploc map build", "toploc serve", "toploc localize"} <= commands


def test_a_misspelt_option_or_command_is_caught() -> None:
    with pytest.raises(AssertionError, match="toploc map build has no option --detectr"):
        check_invocation(["map", "build", "photos", "--db", "my.db", "--detectr", "sift"])
    with pytest.raises(AssertionError, match="toploc map has no command 'biuld'"):
        check_invocation(["map", "biuld", "photos"])
    with pytest.raises(AssertionError, match="is not one of"):
        check_invocation(["sim", "kidnap", "--policy", "nearest"])


def test_the_readme_quickstart_lines_come_first() -> None:
    lines = list(shell_lines(README.read_text(encoding="utf-8")))
    assert lines[0] == "python -m pip install . && python -m toploc demo"
    assert "pytest" in lines[1] and ".[test,docs]" in lines[1]
    assert not any("pytest" in line for line in lines[2:])  # .ci/run takes the first


def test_the_readme_links_and_figure_exist() -> None:
    text = README.read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    local = [t for t in targets if "://" not in t]
    assert local, "the README links to no page of the docs"
    for target in local:
        assert (REPO / target).exists(), f"README links to a missing {target}"
    figures = [t for t in local if t.endswith(".png")]
    assert figures and all((REPO / f).stat().st_size < 300_000 for f in figures)
