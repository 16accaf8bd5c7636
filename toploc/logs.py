"""Logging for the ``toploc`` program, configured in one place: :func:`configure_logging`.

Every module logs to its own ``logging.getLogger(__name__)``; nothing but this module adds a
handler. Lines go to stderr as ``2026-12-01 18:57:18,123 INFO toploc.runner: localized ...``.

Levels: ``--log-level LEVEL`` names one; else the command's default (WARNING for one-shot
commands, INFO for ``serve`` and ``node``, which run a service) lowered one step per ``-v``
(WARNING -> INFO -> DEBUG). The level applies to toploc's own packages; other libraries log at
WARNING (or the chosen level if it is higher), so ``-vv`` does not print their debug lines.
"""

from __future__ import annotations

import logging
import sys
from typing import TextIO

LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")
PACKAGES = ("toploc", "localizer", "mapdb", "homing", "robot")
SERVICE_COMMANDS = frozenset({"serve", "node"})
FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"
_HANDLER_NAME = "toploc"


def default_level(command: str | None) -> int:
    """The level of ``command`` (the subcommand's name) without ``-v`` or ``--log-level``."""
    return logging.INFO if command in SERVICE_COMMANDS else logging.WARNING


def chosen_level(command: str | None, verbose: int, log_level: str | None) -> int:
    """The level to log at: ``log_level`` (one of :data:`LEVELS`, any case) if given, else
    :func:`default_level` lowered by 10 (one step) per ``verbose``, down to DEBUG."""
    if log_level is not None:
        name = log_level.upper()
        if name not in LEVELS:
            raise ValueError(f"log level {log_level!r} is not one of {', '.join(LEVELS)}")
        return logging.getLevelNamesMapping()[name]
    return max(logging.DEBUG, default_level(command) - 10 * verbose)


def configure_logging(level: int, stream: TextIO | None = None) -> None:
    """Log toploc's packages at ``level`` and everything else at WARNING (or ``level`` if
    higher), as :data:`FORMAT` lines on ``stream`` (default: ``sys.stderr`` at the time of
    each line, so a test's captured stderr gets them). Calling it again replaces the handler."""
    root = logging.getLogger()
    for handler in [h for h in root.handlers if h.get_name() == _HANDLER_NAME]:
        root.removeHandler(handler)
    handler = _StderrHandler() if stream is None else logging.StreamHandler(stream)
    handler.set_name(_HANDLER_NAME)
    handler.setFormatter(logging.Formatter(FORMAT))
    root.addHandler(handler)
    root.setLevel(max(level, logging.WARNING))
    for package in PACKAGES:
        logging.getLogger(package).setLevel(level)


class _StderrHandler(logging.StreamHandler[TextIO]):
    """A stream handler that writes to whatever ``sys.stderr`` is when a line is logged."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, _value: TextIO) -> None:
        """The stream is always the current ``sys.stderr``."""
