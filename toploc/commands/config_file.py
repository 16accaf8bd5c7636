"""``--config FILE.toml``: a command's options from a TOML file (``toploc serve --config``).

The file has one key per option: the option's long name without its leading dashes, as on the
command line (``robot-id``, ``sim-world``, ``no-sim``; not ``robot_id``). Values are TOML's own
types: a string, an integer, a number, ``true``/``false`` for a flag, a list of strings for a
repeatable option (``listen = ["tcp/127.0.0.1:7447"]``). A relative path is relative to the
file's folder. What the command line gives wins over the file (click's ``default_map``: the
file's values stand in for the options' defaults).

Every key is checked when the file is read, before anything runs: an unreadable file, an
unknown key, a value of the wrong type or one the option refuses is a one-line error naming the
file, the key and what was expected.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

F = TypeVar("F", bound=Callable[..., Any])
NOT_FROM_FILE = frozenset({"config", "help"})


class ConfigFileError(click.ClickException):
    """A config file that cannot be used, in one line: ``FILE: key 'K': expected ..., got ...``."""


def config_file_option(command: F) -> F:
    """Add ``--config FILE.toml`` (eager: read before the other options) to a click command."""
    return click.option(
        "--config",
        type=click.Path(dir_okay=False, path_type=Path),
        is_eager=True,
        expose_value=False,
        callback=_read_config,
        help="A TOML file of this command's options (keys: the option names without the "
        'leading dashes, e.g. robot-id = "r1"); options on the command line win over it.',
    )(command)


def file_keys(command: click.Command) -> dict[str, click.Option]:
    """The keys a config file of ``command`` may hold: each option's long names without the
    dashes (``--no-sim`` -> ``no-sim``), but not ``--config`` and ``--help``."""
    keys = {}
    for param in command.params:
        if not isinstance(param, click.Option):
            continue
        for name in (*param.opts, *param.secondary_opts):
            key = name[2:]
            if name.startswith("--") and key not in NOT_FROM_FILE:
                keys[key] = param
    return keys


def _read_config(ctx: click.Context, _param: click.Parameter, path: Path | None) -> None:
    if path is None:
        return
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise ConfigFileError(f"{path}: cannot read the config ({error})") from None
    keys = file_keys(ctx.command)
    defaults = {}
    for key, value in table.items():
        option = keys.get(key)
        if option is None:
            raise ConfigFileError(f"{path}: {_unknown(key, keys)}")
        assert option.name is not None
        defaults[option.name] = _option_value(ctx, path, key, option, value)
    ctx.default_map = {**(ctx.default_map or {}), **defaults}


def _unknown(key: str, keys: dict[str, click.Option]) -> str:
    dashed = key.replace("_", "-")
    hint = f" (did you mean {dashed!r}?)" if dashed in keys else ""
    return f"unknown key {key!r}{hint}; known: {', '.join(sorted(keys))}"


def _option_value(
    ctx: click.Context, path: Path, key: str, option: click.Option, value: Any
) -> Any:
    """``value`` of ``key`` checked against ``option``'s type and converted as the command line
    would be (paths relative to ``path``'s folder; the option's own check run)."""
    where = f"{path}: key {key!r}"
    if option.is_flag and not option.multiple:
        if not isinstance(value, bool):
            raise ConfigFileError(f"{where}: expected true or false, got {value!r}")
        if key in (name[2:] for name in option.secondary_opts):
            value = not value  # no-x = true sets x false
        return value
    if option.multiple:
        if not isinstance(value, list):
            raise ConfigFileError(
                f"{where}: expected a list, each item {_expected(option.type)}, got {value!r}"
            )
        items = [_item(where, path, option.type, item) for item in value]
        converted: Any = tuple(_convert(ctx, where, option, item) for item in items)
    else:
        converted = _convert(ctx, where, option, _item(where, path, option.type, value))
    if option.callback is not None:
        try:
            converted = option.callback(ctx, option, converted)
        except click.BadParameter as error:
            raise ConfigFileError(f"{where}: {error.message}") from None
    return converted


def _expected(kind: click.ParamType) -> str:
    """What a TOML value for a ``kind`` option must be, in words."""
    if isinstance(kind, click.Choice):
        return f"one of {', '.join(map(str, kind.choices))}"
    if isinstance(kind, click.types.IntParamType):
        return "an integer"
    if isinstance(kind, click.types.FloatParamType):
        return "a number"
    if isinstance(kind, click.Path):
        return "a path (a string)"
    return "a string"


def _item(where: str, path: Path, kind: click.ParamType, value: Any) -> Any:
    """``value`` if TOML gave the type a ``kind`` option takes (a relative path made relative
    to ``path``'s folder); else ConfigFileError."""
    if isinstance(kind, click.types.IntParamType):
        valid = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(kind, click.types.FloatParamType):
        valid = isinstance(value, int | float) and not isinstance(value, bool)
    else:
        valid = isinstance(value, str)
    if not valid:
        raise ConfigFileError(f"{where}: expected {_expected(kind)}, got {value!r}")
    if isinstance(kind, click.Path):
        given = Path(value).expanduser()
        return str(given if given.is_absolute() else path.parent / given)
    return value


def _convert(ctx: click.Context, where: str, option: click.Option, value: Any) -> Any:
    try:
        return option.type.convert(value, option, ctx)
    except click.BadParameter as error:
        raise ConfigFileError(f"{where}: {error.message}") from None
