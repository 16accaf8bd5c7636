"""The service's bounds on what a bus client may ask: the sizes of moves, messages and images, and
how often the camera may be triggered.

:class:`Limits` holds them with defaults; ``toploc serve --limits FILE`` reads a TOML file whose
keys are its field names (docs/limits.md lists them). Every bound is checked
before anything is done: a request beyond one gets an error reply naming the field and the limit,
and the robot does not move.
"""

from __future__ import annotations

import math
import threading
import time
import tomllib
from collections import deque
from dataclasses import dataclass, fields
from pathlib import Path

from localizer.panorama_io import MAX_IMAGE_PIXELS


@dataclass(frozen=True)
class Limits:
    """Bounds of the service (SI units; angles in degrees).

    ``max_forward_m``/``max_turn_deg``: the largest ``|forward_m|``/``|turn_deg|`` of one
    ``base/cmd``. ``move_timeout_s``: a move still running after this is stopped
    (``Robot.stop``) and answered with an error. ``max_request_bytes``: the largest JSON request
    payload. ``max_string_chars``: the longest string in a request (room names of a prior).
    ``max_captures_per_s``: ``camera/capture`` answers at most this many captures in any one
    second (a 360° camera's video rate); more get an error reply.
    ``max_pending_localizations``: ``localizer/localize`` queries waiting for their turn beyond
    this are refused at once. ``max_image_pixels``: the
    largest image (width x height) decoded, checked in its header first. ``max_image_bytes``:
    the largest encoded image a client may send (the PNG of ``map/add``).
    """

    max_forward_m: float = 5.0
    max_turn_deg: float = 360.0
    move_timeout_s: float = 60.0
    max_request_bytes: int = 64 * 1024
    max_string_chars: int = 256
    max_captures_per_s: int = 30
    max_pending_localizations: int = 8
    max_image_pixels: int = MAX_IMAGE_PIXELS
    max_image_bytes: int = 64 * 1024 * 1024

    def __post_init__(self) -> None:
        for field in fields(self):
            value = getattr(self, field.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"limit {field.name} must be a number, got {value!r}")
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"limit {field.name} must be finite and > 0, got {value!r}")
            if field.type == "int" and value != int(value):
                raise ValueError(f"limit {field.name} must be an integer, got {value!r}")


def load_limits(path: Path) -> Limits:
    """The :class:`Limits` of the TOML file ``path`` (its keys are field names; missing keys keep
    their defaults). ``ValueError`` naming the file for unreadable TOML, an unknown key or a bad
    value."""
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise ValueError(f"{path}: cannot read the limits ({error})") from None
    known = {field.name for field in fields(Limits)}
    unknown = sorted(set(table) - known)
    if unknown:
        raise ValueError(f"{path}: unknown limit(s) {unknown}; known: {sorted(known)}")
    try:
        return Limits(**table)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


class RateLimit:
    """At most ``max_events`` per ``window_s`` seconds (a sliding window of event times).

    Hand-written: ten lines, and the rate-limit libraries on PyPI are built for HTTP servers.
    Thread-safe.
    """

    def __init__(self, max_events: int, window_s: float = 1.0) -> None:
        self.max_events = int(max_events)  # a TOML file may give 30.0
        self.window_s = window_s
        self._times: deque[float] = deque()
        self._lock = threading.Lock()

    def allow(self, now_s: float | None = None) -> bool:
        """Record an event now and return True, or return False if the window is full."""
        now = time.monotonic() if now_s is None else now_s
        with self._lock:
            while self._times and now - self._times[0] >= self.window_s:
                self._times.popleft()
            if len(self._times) >= self.max_events:
                return False
            self._times.append(now)
            return True

    def wait_s(self, now_s: float | None = None) -> float:
        """Seconds until :meth:`allow` would admit an event (0 if it would now)."""
        now = time.monotonic() if now_s is None else now_s
        with self._lock:
            live = [t for t in self._times if now - t < self.window_s]
            if len(live) < self.max_events:
                return 0.0
            return live[len(live) - self.max_events] + self.window_s - now
