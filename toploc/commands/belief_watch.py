"""``toploc belief --watch``: show a running service's belief as it changes, until Ctrl-C.

The watch subscribes to ``localizer/belief`` and ``homing/progress`` and shows, per belief, one
block: the state, entropy and stamp, a bar per room (``office_b  ████████████████░░░░  0.810``),
the best place, and the drive of an active localization (the last ``homing/progress``: the
place it drives to, moves, metres, matches). On a terminal the block is redrawn in place (ANSI
cursor movement, lines cut to the terminal's width); piped, each belief is one more block
after a blank line, and with ``--json`` one JSON message per line (beliefs and drive progress,
told apart by their ``kind``).

With ``--localize`` (or ``--active``) it first asks for a localization (``--active``: one that
may drive to disambiguate), shows the beliefs while it runs, and ends when it ends.
"""

from __future__ import annotations

import json
import logging
import queue
import shutil
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import click
import zenoh

from toploc import bus
from toploc.commands.belief_text import active_line, partly_seen_line, ranked_rooms, state_line
from toploc.commands.bus_client import client_session

if TYPE_CHECKING:  # imported when the watch runs (the node modules load more than click needs)
    from toploc.nodes.localizer import LocalizerClient

_log = logging.getLogger(__name__)
BAR_CELLS = 20
BLOCKS = ("█", "░")
ASCII_BLOCKS = ("#", ".")
POLL_S = 0.2
"""How often the watch looks up from its queue (so that Ctrl-C ends it at once)."""
DRIVING = frozenset({"homing", "lost"})
"""``homing/progress`` states of a drive still running (any other is how it ended)."""


def bar(probability: float, blocks: tuple[str, str] = BLOCKS, cells: int = BAR_CELLS) -> str:
    """``probability`` (0..1) as ``cells`` characters, ``round(p * cells)`` of them filled."""
    filled = min(cells, max(0, round(probability * cells)))
    return blocks[0] * filled + blocks[1] * (cells - filled)


def render_watch(
    belief: dict[str, Any] | None,
    progress: dict[str, Any] | None = None,
    note: str | None = None,
    blocks: tuple[str, str] = BLOCKS,
) -> list[str]:
    """The lines of one watch block: the belief (None: none yet), the last drive's
    ``progress`` if any, then ``note`` (e.g. why there is no belief)."""
    lines = []
    if belief is not None:
        stamp = belief["stamp"]
        clock = time.strftime("%H:%M:%S", time.localtime(stamp))
        stale = ""
        if belief.get("stale"):
            age = belief.get("age_s")
            stale = "   STALE: the robot node is gone" + ("" if age is None else f" ({age:.0f} s)")
        lines.append(
            f"state: {belief['state']}   entropy: {belief['entropy_bits']:.3f} bits   "
            f"stamp: {stamp:.3f} ({clock}){stale}"
        )
        if belief["state"] == "lost":  # no room is the answer: no bars (as toploc belief)
            lines.append(f"  {state_line(belief)}")
        else:
            rooms = ranked_rooms(belief)
            width = max((len(room) for room, _ in rooms), default=0)
            lines += [f"  {room:<{width}}  {bar(p, blocks)}  {p:.3f}" for room, p in rooms]
        best = belief["best_place"]
        lines.append(
            "best place: none"
            if best is None
            else f"best place: {best['place_id']} in {best['room']} ({best['inliers']} inliers)"
        )
        waits = partly_seen_line(belief)
        if waits is not None:
            lines.append(waits)
        active = active_line(belief)  # the reply to an active localization, at its end
        if active is not None:
            lines.append(active)
    if progress is not None:
        lines.append(describe_drive(progress))
    if note is not None:
        lines.append(note)
    return lines


def describe_drive(progress: dict[str, Any]) -> str:
    """One line of a ``homing/progress`` message: ``drive to place 4: step 3, moved 1.20 m,
    40/310 matched, home 0.31, parallax 4.2 deg (homing)``: moves made, odometric metres,
    features the home vector used of those seen, the home vector's length (ALV units) and
    the matches' median parallax; the state ``homing`` (or ``lost``) while it drives, then
    how it ended (``last drive ... (arrived)``)."""
    state = progress.get("state", "homing")
    label = "drive" if state in DRIVING else "last drive"
    parts = [f"step {progress.get('step', 0)}"]
    if isinstance(progress.get("moved_m"), int | float):
        parts.append(f"moved {progress['moved_m']:.2f} m")
    parts.append(f"{progress.get('matched', 0)}/{progress.get('features', 0)} matched")
    if isinstance(progress.get("home_length"), int | float):
        parts.append(f"home {progress['home_length']:.2f}")
    if isinstance(progress.get("parallax_deg"), int | float):
        parts.append(f"parallax {progress['parallax_deg']:.1f} deg")
    return f"{label} to place {progress['place_id']}: {', '.join(parts)} ({state})"


class Screen:
    """Where the blocks go: ``out``; on a terminal each block replaces the one before (ANSI:
    cursor up, clear to the end), otherwise blocks follow each other after a blank line."""

    def __init__(self, out: TextIO, tty: bool) -> None:
        self.out = out
        self.tty = tty
        self.blocks = BLOCKS if _can_encode(out, "".join(BLOCKS)) else ASCII_BLOCKS
        self._shown = 0  # lines of the block on screen (terminal only)
        self._last: list[str] | None = None

    def show(self, lines: list[str]) -> None:
        """Draw ``lines`` as the current block (nothing if it equals the last one)."""
        if lines == self._last:
            return
        if self.tty:
            columns = shutil.get_terminal_size().columns
            lines_shown = [line[: max(columns - 1, 1)] for line in lines]
            up = f"\x1b[{self._shown}F\x1b[J" if self._shown else ""
            self.out.write(up + "".join(f"{line}\n" for line in lines_shown))
            self._shown = len(lines_shown)
        else:
            separator = "\n" if self._last is not None else ""
            self.out.write(separator + "".join(f"{line}\n" for line in lines))
        self.out.flush()
        self._last = lines


def _can_encode(out: TextIO, text: str) -> bool:
    try:
        text.encode(getattr(out, "encoding", None) or "ascii")
    except (UnicodeEncodeError, LookupError):
        return False
    return True


Event = tuple[str, Any]
"""``("belief", message)``, ``("progress", message)``, ``("note", text)`` (why no belief is
shown) or ``("done", belief | exception)`` (the localization asked for ended)."""


def watch_belief(
    robot_id: str,
    zenoh_file: Path | None,
    endpoints: tuple[str, ...],
    timeout_s: float,
    localize: bool = False,
    active: bool = False,
    reset: bool = False,
    as_json: bool = False,
) -> None:
    """Run ``toploc belief --watch`` (see the module docstring) on stdout until Ctrl-C, or until
    the localization asked for (``localize``/``active``) ends. One-line
    ``click.ClickException`` when no service answers or the localization fails."""
    from toploc.nodes.localizer import LOCALIZE_TIMEOUT_S, LocalizerClient

    events: queue.Queue[Event] = queue.Queue()
    out = sys.stdout  # click.get_text_stream is deprecated from click 8.5
    screen = Screen(out, out.isatty() and not as_json)
    subscribers: list[zenoh.Subscriber] = []
    try:
        with client_session(robot_id, zenoh_file, endpoints) as session:
            localizer = LocalizerClient(
                session, robot_id, timeout_s, max(timeout_s, LOCALIZE_TIMEOUT_S)
            )
            try:
                for suffix, kind, read in (
                    (bus.LOCALIZER_BELIEF, "belief", read_belief),
                    (bus.HOMING_PROGRESS, "progress", read_progress),
                ):
                    key_expr = bus.key(robot_id, suffix)
                    subscribers.append(_subscribe_in_order(session, key_expr, kind, read, events))
                first, note = _first_belief(localizer, reset)
                events.put(("belief", first) if first is not None else ("note", note))
                if localize or active:
                    _in_thread(lambda: localizer.localize(active=active), events)
                _follow(events, screen, as_json)
            finally:
                bus.undeclare_all(subscribers)
    except bus.BusError as error:
        raise click.ClickException(str(error)) from error


def read_belief(key_expr: str, data: bytes) -> dict[str, Any]:
    """A ``localizer/belief`` publication, checked (BusMessageError if it breaks the contract)."""
    from toploc.nodes.localizer import check_belief

    return check_belief(key_expr, bus.decode(key_expr, data))


def read_progress(key_expr: str, data: bytes) -> dict[str, Any]:
    """A ``homing/progress`` publication, checked as ``HomingClient.subscribe`` checks it."""
    return bus.decode(key_expr, data, {"place_id": int})


def _subscribe_in_order(
    session: zenoh.Session,
    key_expr: str,
    kind: str,
    read: Callable[[str, bytes], dict[str, Any]],
    events: queue.Queue[Event],
) -> zenoh.Subscriber:
    """Put ``(kind, read(sample))`` on ``events`` for each publication on ``key_expr``; a
    malformed one is skipped (logged).

    The callback is direct (zenoh's receiving thread runs it; it only puts on the queue), not
    :func:`toploc.bus.subscribe`'s own thread per subscriber: so beliefs, drive progress and
    the localization's reply reach the queue in the order the service sent them, and the
    watch of a localization does not end before the last of its drive is shown."""

    def on_sample(sample: zenoh.Sample) -> None:
        try:
            events.put((kind, read(key_expr, sample.payload.to_bytes())))
        except bus.BusMessageError as error:
            _log.warning("skipping a publication: %s", error)

    return session.declare_subscriber(key_expr, zenoh.handlers.Callback(on_sample, indirect=False))


def _first_belief(
    localizer: LocalizerClient, reset: bool
) -> tuple[dict[str, Any] | None, str | None]:
    """The belief to show first (after a reset if asked), or why there is none yet (the
    service answered with an error, e.g. its map has no places yet); BusTimeout if no
    service answers."""
    try:
        return (localizer.reset() if reset else localizer.belief()), None
    except bus.BusReplyError as error:
        return None, f"no belief yet: {error}"


def _in_thread(call: Callable[[], dict[str, Any]], events: queue.Queue[Event]) -> None:
    """Run ``call`` on a daemon thread; its result (or exception) becomes a ``done`` event."""

    def run() -> None:
        try:
            events.put(("done", call()))
        except Exception as error:  # reported by the watch, in one line
            events.put(("done", error))

    threading.Thread(target=run, name="belief-watch-localize", daemon=True).start()


def _follow(events: queue.Queue[Event], screen: Screen, as_json: bool) -> None:
    """Show each event until a ``done`` one (forever without one: Ctrl-C ends it)."""
    belief: dict[str, Any] | None = None
    progress: dict[str, Any] | None = None
    note: str | None = None
    while True:
        try:
            kind, message = events.get(timeout=POLL_S)
        except queue.Empty:
            continue
        if kind == "done" and isinstance(message, Exception):
            raise click.ClickException(f"the localization failed: {message}") from message
        repeated = False
        if kind == "note":
            note = message
        elif kind == "progress":
            progress = message
        else:
            repeated = message == belief  # the localization's reply was published too
            belief, note = message, None
        if not as_json:
            screen.show(render_watch(belief, progress, note, screen.blocks))
        elif kind == "note":
            click.echo(message, err=True)
        elif not repeated:
            screen.out.write(json.dumps(message, sort_keys=True) + "\n")
            screen.out.flush()
        if kind == "done":
            return
