"""Why rows of the thesis simulation differ from the paper: the rules and the CLI table."""

from math import comb

import pytest
from click.testing import CliRunner

from homing.thesis.explanations import (
    CAUSES,
    explain,
    explain_row,
    fisher_p_value,
    format_explanations,
    medians_far,
)
from homing.thesis.reference import reference_key
from toploc.cli import main


def _fisher_by_enumeration(a: int, n: int, b: int, m: int) -> float:
    """Two-sided Fisher p: sum of hypergeometric tables no likelier than the observed one."""
    total = a + b

    def prob(k: int) -> float:
        return comb(n, k) * comb(m, total - k) / comb(n + m, total)

    observed = prob(a)
    ks = range(max(0, total - m), min(n, total) + 1)
    return sum(prob(k) for k in ks if prob(k) <= observed * (1 + 1e-7))


@pytest.mark.parametrize(("a", "b"), [(12, 17), (8, 20), (0, 20), (10, 10), (2, 9), (19, 1)])
def test_fisher_p_value_agrees_with_enumerating_tables(a, b):
    assert fisher_p_value(a, 20, b, 20) == pytest.approx(_fisher_by_enumeration(a, 20, b, 20))


def test_fisher_p_value_names_bad_counts():
    with pytest.raises(ValueError, match="successes_b=21"):
        fisher_p_value(3, 20, 21, 20)


def test_medians_far_needs_both_a_factor_and_a_difference():
    assert medians_far(178.0, 90.5)
    assert not medians_far(7.0, 11.0)  # factor 1.57 but only 4 iterations
    assert not medians_far(60.0, 80.0)  # 20 iterations but factor 1.33
    assert not medians_far(None, 11.0)


def _row(parameter, value, rate, world=1, median=12.0, **fails):
    return {
        "experiment": "B3",
        "world": world,
        "method": "thesis",
        "parameter": parameter,
        "value": value,
        "runs": 20,
        "success_rate": rate,
        "fail_max_iter": fails.get("it", 0.0),
        "fail_max_proj": fails.get("pr", 0.0),
        "fail_max_dist": fails.get("di", 1.0 - rate),
        "iterations_median": median if rate > 0 else None,
    }


@pytest.mark.parametrize(
    ("paper", "ours", "cause"),
    [
        (_row("removed_features", 950, 0.6), _row("removed_features", 950, 0.85), "sampling"),
        (_row("noise_sd", 0.01, 0.4), _row("noise_sd", 0.01, 1.0), "noise_model"),
        (_row("max_rotation_rad", 0.6, 0.0), _row("max_rotation_rad", 0.6, 0.8), "rotation"),
        (
            _row("wall_length_m", 30, 0.55, it=0.45, di=0.0),
            _row("wall_length_m", 30, 1.0),
            "long_room",
        ),
        (
            _row("features", 40, 0.45, world=4, it=0.55, di=0.0),
            _row("features", 40, 1.0, world=4),
            "paper_stalls",
        ),
        (
            _row("removed_features", 995, 0.0, pr=0.5, di=0.5),
            _row("removed_features", 995, 0.55),
            "removed_empty_views",
        ),
        (
            _row("fake_features", 700, 0.95, world=4, median=20.0),
            _row("fake_features", 700, 1.0, world=4, median=11.0),
            "fake_box",
        ),
        (_row("features", 500, 0.0), _row("features", 500, 1.0), "unexplained"),
    ],
)
def test_each_rule_names_its_cause(paper, ours, cause):
    explanation = explain_row(ours, paper)
    assert explanation is not None
    assert explanation.cause == cause
    assert explanation.reason == CAUSES[cause]


def test_rows_that_agree_get_no_explanation():
    assert explain_row(_row("features", 500, 0.9), _row("features", 500, 1.0)) is None


def test_explain_looks_rows_up_in_the_reference_and_skips_other_methods():
    paper = _row("noise_sd", 0.01, 0.4)
    reference = {reference_key("B3", 1, "noise_sd", 0.01): paper}
    ours = _row("noise_sd", 0.01, 1.0)
    best = {**ours, "method": "best"}
    unknown = _row("noise_sd", 0.02, 1.0)
    found = explain([ours, best, unknown], reference)
    assert [(e.parameter, e.value, e.cause) for e in found] == [("noise_sd", 0.01, "noise_model")]
    table = format_explanations(found)
    assert "| B3 | 1 | noise_sd | 0.01 | 40 | 100 |" in table
    assert CAUSES["noise_model"] in table


def test_simulate_explain_writes_a_markdown_table(tmp_path):
    path = tmp_path / "why.md"
    args = ["simulate", "--experiment", "B4", "--world", "1", "--runs", "4", "--jobs", "1"]
    args += ["--method", "thesis", "--explain", str(path)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    lines = path.read_text().splitlines()
    assert lines[0].startswith("| experiment | world | parameter | value | paper % | ours % |")
    body = [line for line in lines[2:] if line.startswith("| B4 | 1 |")]
    assert body, "B4 world 1 differs from the paper at small rotations"
    assert all(any(reason in line for reason in CAUSES.values()) for line in body)
    assert "rows that differ from the paper" in result.output
