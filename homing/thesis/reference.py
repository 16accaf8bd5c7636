"""The thesis's own simulation figures (tables B.1-B.4), typed in as reference data.

``reference/thesis_appendix_b.csv`` holds one row per (experiment, world, parameter, value) with
the keys of the simulation's result rows; empty cells are figures the thesis does not give (its
PDF lost some columns; the ``note`` column says which were inferred).
"""

from __future__ import annotations

import csv
from functools import cache
from importlib import resources
from typing import Any

ReferenceKey = tuple[str, int, str, float]

_TEXT_COLUMNS = {"experiment", "parameter", "note"}


def reference_key(experiment: str, world: int, parameter: str, value: float) -> ReferenceKey:
    """The lookup key of one setting (values rounded to 6 decimals, as in the CSV)."""
    return (experiment, int(world), parameter, round(float(value), 6))


@cache
def thesis_rows() -> dict[ReferenceKey, dict[str, Any]]:
    """All reference rows by key; numbers as floats, missing figures as ``None``."""
    text = resources.files("homing.thesis").joinpath("reference/thesis_appendix_b.csv").read_text()
    rows: dict[ReferenceKey, dict[str, Any]] = {}
    for raw in csv.DictReader(text.splitlines()):
        row: dict[str, Any] = {
            k: (v if k in _TEXT_COLUMNS else (float(v) if v != "" else None))
            for k, v in raw.items()
        }
        key = reference_key(row["experiment"], int(row["world"]), row["parameter"], row["value"])
        rows[key] = row
    return rows
