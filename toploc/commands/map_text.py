"""The map as ``toploc map`` prints it: ``map info`` (:func:`format_info`), and a fitted
likelihood in plain words after a build or an add (:func:`explain_likelihood`) or as its formula
in ``map info`` and with ``-v`` (:func:`describe_likelihood`). Pure: text from records."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence

from localizer.likelihood import RatioLikelihood
from localizer.lookalikes import pairs_without_counterparts, partners_of
from localizer.routes import (
    ROUTE_MAX_M,
    Route,
    leg_graph,
    rooms_with_routes_out,
    route_beyond,
    shared_rooms,
)
from mapdb.records import MapInfo, Place


def _counted(model: RatioLikelihood) -> str:
    return "spread inliers" if model.count == "spread" else "inliers (raw)"


def describe_likelihood(model: RatioLikelihood) -> str:
    """One line: the fitted ratio's formula and where it came from."""
    fit = model.fit
    where = (
        f"fitted on {fit['n_same_room']:.0f} same-room and {fit['n_other_room']:.0f} other-room "
        f"counts (medians {fit['same_room_median']:.0f} and {fit['other_room_median']:.0f})"
        if "n_same_room" in fit
        else "ratio left at the defaults (no room has two places to compare)"
    )
    counted = _counted(model)
    return (
        f"log ratio {model.intercept:.2f} + {model.slope:.2f} log(1 + n) + "
        f"{model.per_inlier:.4f} n ({model.motion} motion, n = {counted}), lost below "
        f"{model.min_inliers} {counted}; {where}"
    )


def explain_likelihood(detector: str, model: RatioLikelihood) -> str:
    """One line in plain words: how many inliers a view of the same room and one of another
    room gave on the map's own places (medians), and below how many a frame is lost."""
    fit = model.fit
    counted = _counted(model)
    lost = f"a frame with fewer than {model.min_inliers} {counted} is lost"
    if "n_same_room" not in fit:
        return (
            f"{detector}: calibration left at the defaults (no room has two places to compare); "
            f"{lost}"
        )
    return (
        f"{detector}: calibrated on the map's own places: a view matches a place of its own "
        f"room with {fit['same_room_median']:.0f} {counted} (median), of another room with "
        f"{fit['other_room_median']:.0f}; {lost}"
    )


def lookalike_lines(
    model: RatioLikelihood, places: Sequence[Place], edges: Sequence[tuple[str, str]] = ()
) -> list[str]:
    """What the calibration found of look-alike rooms (:mod:`localizer.lookalikes`), and for
    twins without counterparts whether recorded routes tell them apart
    (:mod:`localizer.routes`) or what to record so that they can be; ``places`` and ``edges``
    (the doors): the map's."""
    if not model.lookalikes:
        return []
    room_of = {place.id: place.room for place in places}
    without = list(pairs_without_counterparts(model.lookalikes, model.counterparts, room_of))
    told = [pair for pair in model.lookalikes if pair not in without]
    paired = {room for pair in model.lookalikes for room in pair}
    doors, twins = partners_of(edges), partners_of(model.lookalikes)
    graph = leg_graph(places)
    # each twin's shortest recorded drive (up to ROUTE_MAX_M) on beyond the hall the pair shares
    drives = {room: route_beyond(graph, places, room, twins, doors, ROUTE_MAX_M) for room in paired}
    beyond = {room for room, drive in drives.items() if drive is not None}
    routed = rooms_with_routes_out(places, paired, ROUTE_MAX_M, paired, graph)
    blind = [pair for pair in without if not set(pair) <= routed]
    # a drive that ends in the hall both twins open onto arrives from the twin too where the
    # hall looks alike at both doors; a twin's drive on beyond it tells for the pair
    in_hall = [pair for pair in without if set(pair) <= routed and not set(pair) & beyond]
    driven = [pair for pair in without if set(pair) <= routed and set(pair) & beyond]
    # a room the map knows from one view may have a look-alike it cannot see (a copy of the
    # twins' wing): a drive that ends there may end alike in that look-alike from the twin
    counts = Counter(room_of.values())
    ends = {pair: _drive_ends(pair, drives, room_of) for pair in driven}
    unsure = [pair for pair in driven if all(counts[room] == 1 for room in ends[pair])]
    driven = [pair for pair in driven if pair not in unsure]
    lines = []
    if told:
        lines.append(
            f"  look-alike rooms: {_pairs(told)}; some of their places stand at the same spots "
            "(counterparts): a frame there, or a drive to one, tells them apart"
        )
    if driven:
        lines.append(
            f"  look-alike rooms: {_pairs(driven)}; no frame tells them apart, but each has a "
            "recorded drive out to a room without a look-alike: an active localization drives "
            "it out and back and tells them apart"
        )
    for pair in unsure:
        names = ", ".join(sorted(ends[pair]))
        lines.append(
            f"  look-alike rooms: {_pairs([pair])}; no frame tells them apart, and their "
            f"recorded drives beyond end in {names}, known from one place: a room of one place "
            "may have a look-alike the map cannot see, where the drive from the twin ends "
            f"alike. Record a second place in {names} (toploc map record), or the drive on "
            "into a room of several places"
        )
    if in_hall:
        rooms = sorted({room for pair in in_hall for room in pair})
        halls = sorted({hall for room in rooms for hall in shared_rooms(doors, room, twins[room])})
        lines.append(
            f"  look-alike rooms: {_pairs(in_hall)}; no frame tells them apart, and the drives "
            f"recorded out of them end only in {', '.join(halls)}, which both open onto: "
            "driven from the look-alike such a drive ends there too, and arrives where the "
            "hall looks the same at both doors. Record the drive on from one of them into a "
            "room beyond (toploc map record --every-m, --after)"
        )
    if blind:
        lines.append(
            f"  look-alike rooms: {_pairs(blind)}; none of their places stand at the same spot "
            "of both, so a frame cannot tell them apart (they stay ambiguous). Record the drive "
            "from each through its door into a room without a look-alike (toploc map record "
            "--every-m, --after), or two places in each at the same two spots (the same "
            "distances from the same corner, e.g. 1 m inside the door and the middle); an "
            "active localization then drives there and tells them apart"
        )
    return lines


def _pairs(pairs: list[tuple[str, str]] | tuple[tuple[str, str], ...]) -> str:
    return ", ".join(f"{a} ~ {b}" for a, b in pairs)


def format_info(info: MapInfo, places: Sequence[Place] = ()) -> str:
    """``map info``'s text: rooms and places, fingerprints, edges, each likelihood's formula."""
    single = [room.name for room in info.rooms if room.n_places == 1]
    hint = (
        [
            f"  one place only: {', '.join(single)} (a view far from it, at a door or in a "
            "corner, may stay ambiguous; from one place the map may not find a look-alike of "
            "the room, and one view of that twin may then be taken for it: a second place "
            "there helps and lets the calibration measure the room; twins you know of: "
            "toploc map lookalike A B)"
        ]
        if single
        else []
    )
    models = [RatioLikelihood.from_json(model) for model in info.likelihoods.values()]
    lookalikes = lookalike_lines(models[0], places, info.edges) if models else []
    lines = [
        f"{info.path}: schema {info.schema_version}, {info.file_size_bytes / 1e6:.2f} MB, "
        f"{len(info.rooms)} rooms, {info.n_places} places",
        "rooms:",
        *(f"  {room.name}: {room.n_places} places" for room in info.rooms),
        *hint,
        "fingerprints: "
        + (", ".join(f"{d} {n}" for d, n in info.fingerprints_per_detector.items()) or "none"),
        *(
            [
                f"  {info.fingerprints_without_sizes} stored without their keypoints' sizes "
                "(before schema 5): homing to those places judges nearer and farther by "
                "elevations alone; record them again to keep the sizes"
            ]
            if info.fingerprints_without_sizes
            else []
        ),
        f"edges ({len(info.edges)}):",
        *(f"  {a} <-> {b}" for a, b in info.edges),
        "likelihood:",
        *(
            f"  {detector}: {describe_likelihood(RatioLikelihood.from_json(model))}"
            for detector, model in info.likelihoods.items()
        ),
    ]
    if not info.likelihoods:
        lines[-1] += " not calibrated (toploc map calibrate)"
    return "\n".join(lines + lookalikes)


def _drive_ends(
    pair: tuple[str, str], drives: Mapping[str, Route | None], room_of: Mapping[int, str]
) -> set[str]:
    """The rooms the twins' drives beyond (``drives``, by room) end in."""
    return {room_of[drive.end] for room in pair if (drive := drives[room]) is not None}
