"""The text report of ``toploc eval localize``: the five outcomes of the queries from rooms of
the map first (what a user reads), the queries from rooms the map lacks on their own line, then
each true room and the time per query. Pure: text from a
:class:`~toploc.evaluation.localization.LocalizationScore`."""

from __future__ import annotations

from toploc.evaluation.localization import OUTCOMES, LocalizationScore

OUTCOME_LABELS = {
    "right_localized": "right, localized",
    "right_ambiguous": "right, ambiguous",
    "wrong_localized": "wrong, localized",
    "wrong_ambiguous": "wrong, ambiguous",
    "lost": "lost",
}
"""How the report names each of :data:`~toploc.evaluation.localization.OUTCOMES`."""
SHORT_LABELS = {
    "right_localized": "R loc",
    "right_ambiguous": "R amb",
    "wrong_localized": "W loc",
    "wrong_ambiguous": "W amb",
    "lost": "lost",
}


def format_outcomes(score: LocalizationScore) -> str:
    """The headline, on the queries from rooms of the map: the five outcomes with count and
    share, then top-1 (lost counts as not right), the answer rate and top-1 among answered
    queries; then the queries from rooms the map lacks on a line of their own
    (:func:`format_unknown_rooms`: lost is right there, localized the failure)."""
    known = score.known_room
    unknown = format_unknown_rooms(score)
    if known.n == 0:
        return "\n".join(["no query is from a room of the map", unknown])
    whose = f"  (the {known.n} queries from rooms of the map)" if unknown else ""
    lines = [f"{'outcome':18s} {'n':>5s} {'share':>7s}{whose}"]
    rates = known.rates or {}
    for outcome in OUTCOMES:
        note = "  <- confidently wrong" if outcome == "wrong_localized" else ""
        lines.append(
            f"{OUTCOME_LABELS[outcome]:18s} {known.outcomes[outcome]:5d} "
            f"{rates[outcome]:7.1%}{note}"
        )
    answered = "n/a" if known.top1_answered is None else f"{known.top1_answered:.1%}"
    lines.append(
        f"n {known.n}: top-1 room {known.top1 or 0.0:.1%} (lost counts as not right), "
        f"answered {known.answer_rate or 0.0:.1%}, top-1 among answered {answered}, "
        f"ambiguous {known.ambiguous_rate or 0.0:.1%}"
    )
    return "\n".join([*lines, unknown] if unknown else lines)


def format_per_room(score: LocalizationScore) -> str:
    """One line per true room: n, the count of each outcome, top-1 and the share ambiguous;
    rooms the map lacks are marked."""
    names = {
        room: room if score.per_room_outcomes[room].in_map else f"{room} (not in map)"
        for room in score.per_room
    }
    width = max(18, *(len(name) for name in names.values()))
    header = "".join(f"{SHORT_LABELS[o]:>6s}" for o in OUTCOMES)
    lines = [f"  {'true room':{width}s} {'n':>4s}{header} {'top-1':>7s} {'ambig.':>7s}"]
    for room, row in score.per_room.items():
        cells = "".join(f"{score.per_room_outcomes[room].counts[o]:6d}" for o in OUTCOMES)
        lines.append(
            f"  {names[room]:{width}s} {row['n']:4.0f}{cells} {row['top1']:7.1%} "
            f"{row['ambiguous_rate']:7.1%}"
        )
    return "\n".join(lines)


def format_unknown_rooms(score: LocalizationScore) -> str:
    """Queries from rooms the map lacks, by state (right only when lost); empty if none."""
    unknown = score.unknown_room
    if unknown.n == 0:
        return ""
    return (
        f"rooms not in the map ({', '.join(unknown.rooms)}): n {unknown.n}, "
        f"lost {unknown.lost} (right), ambiguous {unknown.ambiguous}, "
        f"localized {unknown.localized} (confidently wrong: the failure here)"
    )


def format_timing(score: LocalizationScore) -> str:
    """Median and 95th percentile of the time per query, and each stage's median (ms)."""
    stages = ", ".join(f"{k} {v:.0f}" for k, v in score.stage_ms_median.items())
    return (
        f"time per query: {score.ms_median:.0f} ms median / {score.ms_p95:.0f} ms p95 "
        f"({stages} ms median)"
    )


def format_calibration(score: LocalizationScore) -> str:
    """The reliability table (per bin of the top room's stated probability: n, mean stated,
    fraction right) and the Brier score."""
    lines = [f"  {'stated p':11s} {'n':>5s} {'mean stated':>12s} {'right':>7s}"]
    for b in score.calibration.bins:
        stated = "-" if b.mean_stated is None else f"{b.mean_stated:.3f}"
        right = "-" if b.fraction_right is None else f"{b.fraction_right:.1%}"
        lines.append(f"  {b.low:4.2f}-{b.high:<6.2f} {b.n:5d} {stated:>12s} {right:>7s}")
    lines.append(f"  Brier score of the top room {score.calibration.brier:.3f} (0 is perfect)")
    return "calibration (is the top room right as often as stated?)\n" + "\n".join(lines)
