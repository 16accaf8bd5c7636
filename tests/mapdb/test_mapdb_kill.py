"""A real ``kill -9`` (and Ctrl-C) of ``toploc map build`` in a subprocess: the map stays
consistent, and re-running the build completes it.

The subprocess runs the real CLI through ``mapdb_cli_with_fake_extractor`` (a slow fake
extractor, so the build can be stopped mid-way).
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from mapdb_helpers import assert_consistent, table_counts

from toploc.commands.map import map_group

REPO = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
N_IMAGES = 16


def places_so_far(db_path: Path) -> int:
    """Committed places, read without disturbing the writer (0 before the schema exists)."""
    if not db_path.exists():
        return 0
    try:
        with sqlite3.connect(f"file:{db_path}?mode=ro", uri=True, timeout=1.0) as conn:
            return conn.execute("SELECT COUNT(*) FROM places").fetchone()[0]
    except sqlite3.OperationalError:
        return 0


@pytest.mark.skipif(not hasattr(os, "killpg"), reason="needs POSIX process groups")
@pytest.mark.usefixtures("fake_extractor")
@pytest.mark.parametrize(
    "signum", [signal.SIGKILL, signal.SIGINT, signal.SIGTERM], ids=["kill-9", "ctrl-c", "sigterm"]
)
def test_signal_mid_build_then_rerun_completes(
    make_dataset, db_path: Path, signum: signal.Signals
) -> None:
    dataset = make_dataset(N_IMAGES)
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(REPO), str(HERE)]),
        "TOPLOC_FAKE_EXTRACT_DELAY_S": "0.25",
    }
    command = [sys.executable, "-m", "mapdb_cli_with_fake_extractor", "build", str(dataset),
               "--db", str(db_path), "--workers", "2", "--no-progress",
               "--detector", "sift,mser"]  # fmt: skip
    process = subprocess.Popen(
        command,
        env=env,
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,  # its own process group: the kill reaches the workers too
    )
    try:
        deadline = time.monotonic() + 30.0
        while places_so_far(db_path) < 3:
            assert process.poll() is None, process.stderr.read().decode() if process.stderr else ""
            assert time.monotonic() < deadline, "the build did not start writing in time"
            time.sleep(0.02)
        os.killpg(process.pid, signum)  # the whole group, as a terminal's Ctrl-C does
        stdout, _ = process.communicate(timeout=20)
    finally:
        if process.poll() is None:  # a failed wait above: leave no build or worker behind
            os.killpg(process.pid, signal.SIGKILL)
            process.communicate()
    if signum == signal.SIGKILL:
        assert process.returncode == -signal.SIGKILL
    else:
        assert process.returncode == 130
        assert b"interrupted: the map is consistent" in stdout

    killed = table_counts(db_path)
    assert 3 <= killed["places"] < N_IMAGES
    assert_consistent(db_path)

    # the re-run names no detector: it follows the map's two
    result = CliRunner().invoke(
        map_group, ["build", str(dataset), "--db", str(db_path), "--no-progress"]
    )
    assert result.exit_code == 0, result.output
    assert f"added {N_IMAGES - killed['places']}, skipped {killed['places']}" in result.stdout
    assert table_counts(db_path) == {
        "rooms": 3,
        "edges": 0,
        "places": N_IMAGES,
        "fingerprints": 2 * N_IMAGES,
        "legs": 0,
    }
    assert_consistent(db_path)
