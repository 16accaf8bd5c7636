"""``toploc simulate`` as a user runs it."""

import json

from click.testing import CliRunner

from homing.thesis.experiments import ROW_KEYS
from toploc.cli import main


def test_simulate_writes_rows_tables_and_a_plot(tmp_path):
    out, plot = tmp_path / "out.json", tmp_path / "sim.png"
    result = CliRunner().invoke(
        main,
        [
            "simulate",
            "--experiment",
            "B4",
            "--world",
            "2",
            "--runs",
            "2",
            "--jobs",
            "1",
            "--json",
            str(out),
            "--plot",
            str(plot),
        ],
    )
    assert result.exit_code == 0, result.output
    rows = json.loads(out.read_text())
    assert len(rows) == 2 * 11  # two methods, eleven rotations
    assert all(tuple(row) == ROW_KEYS for row in rows)
    assert {row["parameter"] for row in rows} == {"max_rotation_rad"}
    assert "Table B.4" in result.output and "world 2" in result.output
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_simulate_refuses_an_unknown_experiment():
    result = CliRunner().invoke(main, ["simulate", "--experiment", "B9"])
    assert result.exit_code != 0
    assert "B9" in result.output
