"""Text tables of simulation results in the thesis's layout, the thesis's figures beside ours."""

from __future__ import annotations

from collections.abc import Iterable
from itertools import groupby
from typing import Any

from homing.thesis.reference import reference_key, thesis_rows

_TITLES = {
    "B1": "Table B.1: first experiment, start (-1,-1), goal (1,1)",
    "B2": "Table B.2: square rooms",
    "B3": "Table B.3: second experiment, start (-2,-2), goal (2,2)",
    "B4": "Table B.4: random rotation of the projection",
}


def _pct(rate: float | None) -> str:
    return "   -" if rate is None else f"{100 * rate:4.0f}"


def _num(value: float | None, width: int = 6) -> str:
    return " " * (width - 1) + "-" if value is None else f"{value:{width}.1f}"


def _value(parameter: str, value: float) -> str:
    if parameter == "max_rotation_rad":
        return f"{round(value / 3.141592653589793 * 10):2d}pi/10"
    return f"{value:g}"


def format_tables(rows: Iterable[dict[str, Any]]) -> str:
    """One table per (experiment, world): success, failures and iterations; paper vs ours.

    Columns: ``paper`` is the thesis's printed figure, ``thesis`` our run of appendix A,
    ``best`` toploc's controller. Failures are ours (thesis method): max iterations / max empty
    projections / max distance, in percent.
    """
    reference = thesis_rows()
    by_setting: dict[tuple[str, int, str, float], dict[str, dict[str, Any]]] = {}
    for row in rows:
        key = (row["experiment"], row["world"], row["parameter"], row["value"])
        by_setting.setdefault(key, {})[row["method"]] = row
    lines: list[str] = []
    header = (
        f"{'parameter':>17} {'value':>8} | {'success %':^17} | {'fails % (thesis)':^16} |"
        f" {'iterations median':^23} | {'excess distance m':^23}"
    )
    sub = (
        f"{'':>17} {'':>8} | paper thesis  best | iter proj dist   |"
        f"  paper  thesis    best |  paper  thesis    best"
    )
    for (experiment, world), group in groupby(by_setting.items(), key=lambda kv: kv[0][:2]):
        lines += ["", f"{_TITLES[experiment]} — world {world}", header, sub, "-" * len(header)]
        for (_, _, parameter, value), methods in group:
            paper = reference.get(reference_key(experiment, world, parameter, value), {})
            ours = methods.get("thesis", {})
            best = methods.get("best", {})
            lines.append(
                f"{parameter:>17} {_value(parameter, value):>8} |"
                f"  {_pct(paper.get('success_rate'))}   {_pct(ours.get('success_rate'))}  "
                f"{_pct(best.get('success_rate'))} |"
                f" {_pct(ours.get('fail_max_iter'))} {_pct(ours.get('fail_max_proj'))}"
                f" {_pct(ours.get('fail_max_dist'))}   |"
                f" {_num(paper.get('iterations_median'))}  {_num(ours.get('iterations_median'))}"
                f"  {_num(best.get('iterations_median'))} |"
                f" {_num(paper.get('excess_distance_mean'))}"
                f"  {_num(ours.get('excess_distance_mean'))}"
                f"  {_num(best.get('excess_distance_mean'))}"
            )
    return "\n".join(lines)


def agreement(rows: Iterable[dict[str, Any]], tolerance: float = 0.2) -> dict[str, Any]:
    """How many of our thesis-method rows are within ``tolerance`` of the paper's success rate."""
    reference = thesis_rows()
    compared, within, outside = 0, 0, []
    for row in rows:
        if row["method"] != "thesis":
            continue
        key = reference_key(row["experiment"], row["world"], row["parameter"], row["value"])
        paper = reference.get(key, {}).get("success_rate")
        if paper is None:
            continue
        compared += 1
        if abs(row["success_rate"] - paper) <= tolerance + 1e-9:
            within += 1
        else:
            outside.append((*key, paper, row["success_rate"]))
    return {"compared": compared, "within": within, "outside": outside}


def summarise_explanations(rows: Iterable[dict[str, Any]]) -> str:
    """How many thesis-method rows differ from the paper, counted by cause (see explanations)."""
    from homing.thesis.explanations import CAUSES, explain  # scipy only when asked for

    explanations = explain(rows)
    counts = {cause: sum(e.cause == cause for e in explanations) for cause in CAUSES}
    lines = [f"rows that differ from the paper (success or iteration median): {len(explanations)}"]
    lines += [f"  {n:4d}  {CAUSES[cause]}" for cause, n in counts.items() if n]
    return "\n".join(lines)
