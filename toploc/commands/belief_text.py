"""The belief as the command line prints it: one formatter for ``toploc belief``, ``toploc
localize`` and ``toploc demo`` (``--json`` prints the bus message itself, unchanged).

Pure: text from a belief message (:meth:`localizer.belief.RoomBelief.to_json`). A lost belief
names no room as its answer: the latest frame matched no place of the map well enough, so the
room the filter puts first (at whatever probability) is not one.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

BAR_WIDTH = 40
"""Characters of a probability bar at p = 1."""


def ranked_rooms(belief: Mapping[str, Any]) -> list[tuple[str, float]]:
    """``(room, probability)`` from the most likely; ties by name."""
    return sorted(belief["rooms"].items(), key=lambda item: (-item[1], item[0]))


def state_line(belief: Mapping[str, Any], top: int = 3) -> str:
    """The belief in one line, its answer first:

    - ``localized in office_b (p 0.997)``
    - ``ambiguous: office_b 0.620, office_a 0.370, kitchen 0.010`` (the ``top`` rooms; also
      ``homing: ...`` while the robot drives to tell them apart)
    - ``lost: no room of the map matches (best office_b, 12 inliers)``
    """
    state = belief["state"]
    if state == "lost":
        best = belief.get("best_place")
        where = (
            "no place matched"
            if best is None
            else f"best {best['room']}, {best['inliers']} inliers"
        )
        return f"lost: no room of the map matches ({where})"
    ranked = ranked_rooms(belief)
    if state == "localized" and ranked:
        room, probability = ranked[0]
        return f"localized in {room} (p {probability:.3f})"
    rooms = ", ".join(f"{room} {p:.3f}" for room, p in ranked[:top])
    return f"{state}: {rooms or 'no rooms'}"


ENDED_WORDS: dict[str, str] = {
    "settled": "settled",
    "lost": "still lost after looking elsewhere",
    "no-telling-place": "no place of the map tells {first} from {second}",
    "drive-limit": "the drives allowed are made",
    "cancelled": "a drive was cancelled",
}
"""How ``toploc belief --active`` says why the localization ended (the reply's ``active``
``ended``; :data:`localizer.active.ENDINGS`)."""

NO_TELLING_PLACE_HINT = (
    "  (look-alike rooms with no places at the same spot of both: `toploc map info` says "
    "what to record)"
)


def partly_seen_line(belief: Mapping[str, Any]) -> str | None:
    """Why a belief sure by its odds waits (its ``partly_seen``): ``waits: circus_arena seen on
    44% of the horizon, 60% needed (...)``; None when it does not (or is not ambiguous)."""
    seen = belief.get("partly_seen")
    if seen is None or belief["state"] != "ambiguous":
        return None
    return (
        f"waits: {seen['room']} seen on {seen['horizon_share']:.0%} of the horizon, "
        f"{seen['needed_share']:.0%} needed (at its door, or in a room the map lacks? "
        "a look from one of its places tells)"
    )


def active_line(belief: Mapping[str, Any]) -> str | None:
    """The line an active localization's reply adds: ``active: 2 drives, 1.89 m; settled``;
    None for a belief without ``active``. An ending this version does not know is shown as
    it came."""
    summary = belief.get("active")
    if summary is None:
        return None
    ranked = [*ranked_rooms(belief), ("?", 0.0), ("?", 0.0)]
    ended = summary["ended"]
    words = (
        ENDED_WORDS[ended].format(first=ranked[0][0], second=ranked[1][0])
        if ended in ENDED_WORDS
        else ended
    )
    drives = summary["drives"]
    return (
        f"active: {drives} drive{'' if drives == 1 else 's'}, "
        f"{summary['distance_m']:.2f} m; {words}"
    )


def format_belief(belief: Mapping[str, Any], top: int | None = None) -> str:
    """Several lines: :func:`state_line`, entropy and stamp, the best place, why a sure belief
    waits (:func:`partly_seen_line`), how an active
    localization went (:func:`active_line`, with a hint when no place tells the top rooms
    apart), then the rooms by probability with a bar each (the ``top`` first; all if None). A
    lost belief lists no rooms: it is not an answer."""
    best = belief["best_place"]
    best_text = (
        "none"
        if best is None
        else f"place {best['place_id']} in {best['room']} ({best['inliers']} inliers)"
    )
    lines = [
        state_line(belief),
        f"entropy {belief['entropy_bits']:.3f} bits   stamp {belief['stamp']:.3f} s",
        f"best place: {best_text}",
    ]
    waits = partly_seen_line(belief)
    if waits is not None:
        lines.append(waits)
    active = active_line(belief)
    if active is not None:
        lines.append(active)
        if belief["active"]["ended"] == "no-telling-place":
            lines.append(NO_TELLING_PLACE_HINT)
    if belief["state"] == "lost":
        return "\n".join(lines)
    rooms = ranked_rooms(belief)[:top]
    width = max((len(room) for room, _ in rooms), default=0)
    lines += [
        f"  {room:<{width}}  {p:6.3f}  {'#' * round(BAR_WIDTH * p)}".rstrip() for room, p in rooms
    ]
    return "\n".join(lines)
