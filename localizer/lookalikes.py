"""Look-alike rooms, and when their inlier counts may be compared (issue 19, section 2).

Two rooms are look-alikes when, in the map's own leave-one-out, each explains most of the
other's views nearly as well as their own room does, or far above chance
(:class:`localizer.likelihood_fit.CalibrationSamples`), or shows what they show without verifying
it, as a twin a metre off does (:func:`alike_by_appearance`): the twin offices of
``building``, the twin bedrooms of ``house``. Between look-alikes the
inlier count measures how near the robot is to a stored place, not which room it is in. On a
map recorded a few places per room, the twins' places stand at different spots of their
identical frames, and the twin whose place is nearer the robot wins by dozens of inliers (a
robot in office_a, its best place 0.90 m away: 97 spread inliers; office_b's best 0.48 m away
in office_b's frame: 167).

A frame's counts do tell twins apart when they are read on **counterparts**: a place of each
twin at the same spot of their frames (:data:`COUNTERPART_SHARE`; a map rendered on a grid laid
out in each room's frame has them everywhere). The robot is then equally far from both, and
what one gets more of is what only its room shows (the corridor seen through its door). So
:func:`twin_counts` replaces each look-alike room's count by its count on the best counterpart
pair the frame verified (one frame moves their odds by at most
:data:`~localizer.likelihood.MAX_TWIN_LOG_RATIO`); where the frame has none, the group is
**aliased** and each of its rooms is weighed as likely as the likeliest of its own look-alikes
(:func:`localizer.likelihood.lookalike_log_ratios`; in a group of twins, all equally): the
counts say nothing about which twin it is, and the active loop must drive to a counterpart
place or check a room by a recorded route. Counterparts recorded by hand stand
a few decimetres apart; the localizer reads them only where the robot homed to one of them
(:meth:`localizer.localizer.Localizer.frame_likelihood`).

Pure core: numpy, no I/O.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Mapping, Sequence
from typing import TypeVar

import numpy as np

from localizer.likelihood import PlaceScore, place_count
from localizer.likelihood_fit import medians_without_each

K = TypeVar("K", bound=Hashable)

COUNTERPART_SHARE = 0.3
"""Two places of look-alike rooms are counterparts when one verifies the other on at least this
share of its keypoints: the same spot of the twins' frames. Measured on ``building``'s offices
(1024 x 192 SIFT, random headings): 0.80–0.94 between the batch map's twin places (a 1 m grid
in each room's frame); rendered by the simulated robot at five random spots, 0.33–0.74 at the
same spot of the other office (0.43–0.68 for the same office, another heading), 0.23–0.24 at
0.25 m from it, 0.14–0.21 at 0.5 m, 0.10 at 1 m; at most 0.22 between the twins' places of maps
recorded with 2, 3 and 5 places per room."""


EXACT_COUNTERPART_SHARE = 0.6
"""Counterparts that verify each other on at least this share stand at one spot so exactly that
a frame taken where the robot homed to one of them compares both fairly: the batch map's grid
twins (0.80–0.94). Below it (0.3–0.5: a few decimetres apart, as counterparts recorded by hand
are), the place homed to wins by the offset alone, and its pair is read only when that place
loses it (:func:`twin_counts`' ``at_place``)."""


APPEARANCE_MIN_MATCHES = 20
"""A room looks like a view's own room by its descriptors when its best-matching place gives
the view at least this many ratio-test matches (before any geometry), ..."""
APPEARANCE_OWN_FRACTION = 0.5
"""... at least this share of the own room's best matches (when the own room has another
place), ..."""
APPEARANCE_CHANCE_FACTOR = 2.5
"""... at least this many times the median of the other rooms' best matches (or
:data:`APPEARANCE_BEST_CHANCE_FACTOR` times for the room that matches the view best), ..."""
APPEARANCE_BEST_CHANCE_FACTOR = 2.0
"""The chance factor for the room beyond the view's walls (no door between them) that matches
the view best: a twin is the room that looks most like its twin's views, and a room that
merely shares a few objects or a wallpaper with the view's room is rarely the best of all,
for a twin of it would match better. A bare house recorded with one place per room (world seed
26) matched its twin bathrooms at 42 and 40, every other room at 6-19 (medians 12.5 and
16.5): one side missed 2.5 times the median, the twins went unpaired and 5 of 20
kidnappings into the house's twins ended sure of the wrong one. 2.0 for every room instead
paired a building's kitchen with office_b by its shared photographs (world seed 27, two places
per room: office_b's views matched the kitchen at 63 and 72, office_a at 166 and 249, the
other rooms at 14-31) and its kidnappings went from 10 to 0 of 20 right and localized."""
APPEARANCE_MAX_VERIFIED = 0.5
"""... and the essential matrix verifies at most this share of those matches: what the view
shows alike does not stand where that place sees it."""


def alike_by_appearance(
    own_room: str,
    matches: Mapping[str, tuple[int, int]],
    room_sizes: Mapping[str, int],
    edges: Iterable[tuple[str, str]] = (),
) -> frozenset[str]:
    """The rooms that look like the room of a view (``own_room``) by its descriptors:
    ``matches`` holds, per room, the (matches, inliers) of its best-matching place for the view
    (rooms missing: none); ``room_sizes``: places per room; rooms joined by one of ``edges``
    are left out (they see each other through their door).

    Matches count what two views show alike; inliers also ask that it stand where it stands in
    the other view. Twins recorded a metre or more apart in their frames show the same things
    from elsewhere: many matches, few inliers. On maps recorded with one place per room, twin
    offices matched at 99 and 109 and verified each other at 20 and 23 spread inliers (every
    other room 9–26 matches), the bare house's twin bathrooms at 44 and 54 matches and 5
    (others 6–19 matches). A room seen through a door or an opening is matched and verified
    alike (the dense house's living room on a bedroom's places: 124–165 matches, 70–87 %
    verified) and is left to the inlier counts. When the view's room has no other place, the
    best-matching room stands in for its own: a room that shares a few objects with the twins
    is not their twin (a building recorded with one place per room, world seed 21: office_b's
    view matched office_a at 98 and the kitchen at 42, every other room at 7–18; paired with
    office_b, the kitchen joined the offices' aliased group and all 20 kidnappings into the
    offices ended ambiguous between the three). Thresholds: :data:`APPEARANCE_MIN_MATCHES`,
    :data:`APPEARANCE_OWN_FRACTION`, :data:`APPEARANCE_CHANCE_FACTOR` (for the best-matching
    room, :data:`APPEARANCE_BEST_CHANCE_FACTOR`), :data:`APPEARANCE_MAX_VERIFIED`."""
    adjacent = {frozenset(edge) for edge in edges}
    rooms = [r for r in room_sizes if r != own_room]
    if room_sizes.get(own_room, 0) >= 2:
        own = float(matches.get(own_room, (0, 0))[0])
    else:  # no other place of its own: the room that matches the view best stands in for it
        own = max((float(matches.get(r, (0, 0))[0]) for r in rooms), default=0.0)
    beyond_walls = [r for r in rooms if frozenset((own_room, r)) not in adjacent]
    best = max(beyond_walls, key=lambda r: matches.get(r, (0, 0))[0], default=None)
    alike = set()
    chances = medians_without_each([float(matches.get(r, (0, 0))[0]) for r in rooms])
    for room, chance in zip(rooms, chances, strict=True):
        n_matches, n_inliers = matches.get(room, (0, 0))
        factor = APPEARANCE_BEST_CHANCE_FACTOR if room == best else APPEARANCE_CHANCE_FACTOR
        bar = max(APPEARANCE_MIN_MATCHES, APPEARANCE_OWN_FRACTION * own, factor * chance)
        if (
            n_matches >= bar
            and n_inliers <= APPEARANCE_MAX_VERIFIED * n_matches
            and room in beyond_walls
        ):
            alike.add(room)
    return frozenset(alike)


def lookalike_groups(
    pairs: Iterable[tuple[str, str]], rooms: Sequence[str]
) -> tuple[tuple[int, ...], ...]:
    """The groups of mutually look-alike rooms (connected components of ``pairs``), as sorted
    indices into ``rooms``; rooms in no pair and pairs naming a room not in ``rooms`` are left
    out (a map that lost a room keeps its other groups)."""
    index = {room: i for i, room in enumerate(rooms)}
    parent = list(range(len(rooms)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    linked: set[int] = set()
    for a, b in pairs:
        if a in index and b in index and a != b:
            parent[root(index[a])] = root(index[b])
            linked |= {index[a], index[b]}
    groups: dict[int, list[int]] = {}
    for i in sorted(linked):
        groups.setdefault(root(i), []).append(i)
    return tuple(tuple(members) for members in groups.values())


def partners_of(pairs: Iterable[tuple[K, K]]) -> dict[K, frozenset[K]]:
    """Each member of ``pairs`` (rooms or place ids) with the members it is paired with."""
    partners: dict[K, frozenset[K]] = {}
    for a, b in pairs:
        partners[a] = partners.get(a, frozenset()) | {b}
        partners[b] = partners.get(b, frozenset()) | {a}
    return partners


def is_counterpart(inliers: int, keypoints: int) -> bool:
    """Whether a place whose view has ``keypoints`` keypoints and verifies another place of a
    look-alike room on ``inliers`` of them has that place as its counterpart."""
    return keypoints > 0 and inliers >= COUNTERPART_SHARE * keypoints


def pairs_without_counterparts(
    pairs: Iterable[tuple[str, str]],
    counterparts: Iterable[tuple[int, int]],
    room_of: Mapping[int, str],
) -> tuple[tuple[str, str], ...]:
    """The look-alike ``pairs`` of rooms that no ``counterparts`` pair (place ids; ``room_of``
    names each place's room) joins: twins no frame can tell apart."""
    joined = {
        frozenset((room_of[a], room_of[b]))
        for a, b in counterparts
        if a in room_of and b in room_of
    }
    return tuple(pair for pair in pairs if frozenset(pair) not in joined)


def twin_counts(
    evidence: Sequence[PlaceScore],
    rooms: Sequence[str],
    counts: np.ndarray,
    groups: Sequence[Sequence[int]],
    counterparts: Mapping[int, frozenset[int]],
    *,
    count: str,
    at_place: int | None = None,
    min_count: float = 0.0,
) -> tuple[np.ndarray, tuple[tuple[int, ...], ...]]:
    """The frame's best count per room (``counts``, order of ``rooms``) with each look-alike
    group read on counterparts, and the groups that stay aliased.

    For a group, the frame's places of its rooms that have a counterpart (``counterparts``:
    each place id's counterparts, :func:`partners_of`) in every other room of the group, both
    verified in ``evidence``, are candidates; the one with the highest count (``count``, see
    :func:`~localizer.likelihood.place_count`) gives its room its count and every other room of
    the group its counterpart's. A group without a candidate keeps its counts and is returned
    as aliased, as is a group whose best reading falls below ``min_count`` (the model's
    ``min_inliers``): counts at chance on a counterpart pair say nothing about which twin it is
    (world seed 34's building: robots in office_a near its door verified office_b at 14 spread
    inliers and the corridor at 7; the offices' one counterpart pair read 1.8 against 0.5).
    The counts read say which twin; how strongly the frame shows the group against the other
    rooms stays its best count's (:func:`localizer.likelihood.lookalike_log_ratios`).

    ``at_place``: the place the robot homed to before this frame. Homing stops where that
    place's view is matched best, so its count there beats its counterpart's by however far the
    counterpart stands from the exact spot (0.2 m cost a third of the inliers in ``building``),
    whichever room the robot is in: a pair with that place is read only when the place homed
    to loses it (its counterpart's room then shows more although the offset favoured the
    place homed to); the frame's other counterpart pairs are read as usual (on a grid, the
    neighbours' pairs, equally far from the robot). The localizer passes it only when a
    counterpart of that place stands off its spot (:data:`EXACT_COUNTERPART_SHARE`).
    """
    out = np.array(counts, dtype=float)
    by_id = {int(item.place_id): item for item in evidence}
    room_index = {room: i for i, room in enumerate(rooms)}
    aliased: list[tuple[int, ...]] = []
    for group in groups:
        best: tuple[float, dict[int, float]] | None = None
        for item in evidence:
            member = room_index.get(item.room, -1)
            if member not in group:
                continue
            read = {member: place_count(item, count)}
            read_from = {member: int(item.place_id)}
            for other in group:
                if other == member:
                    continue
                found = [
                    (place_count(by_id[p], count), p)
                    for p in counterparts.get(int(item.place_id), ())
                    if p in by_id and by_id[p].room == rooms[other]
                ]
                if not found:
                    break
                read[other], read_from[other] = max(found)
            else:
                if _homed_place_wins(read, read_from, at_place):
                    continue
                if best is None or read[member] > best[0]:
                    best = (read[member], read)
        if best is None or best[0] < min_count:
            aliased.append(tuple(group))
            continue
        for member, value in best[1].items():
            out[member] = value
    return out, tuple(aliased)


def _homed_place_wins(
    read: Mapping[int, float], read_from: Mapping[int, int], at_place: int | None
) -> bool:
    """Whether a counterpart reading (``read``: count per room; ``read_from``: the place each
    count came from) takes a count from ``at_place``, the place homed to, and that count is
    the reading's highest: what the offset alone would give."""
    homed = [room for room, place in read_from.items() if place == at_place]
    if not homed:
        return False
    rivals = [value for room, value in read.items() if room != homed[0]]
    return read[homed[0]] >= max(rivals)
