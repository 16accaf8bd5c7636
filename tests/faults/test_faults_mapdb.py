"""Issue 11, map part: faults a user can cause with `toploc map`, each a reproduction.

Processes: a killed or terminated build leaves no worker behind. Paths and files: a manifest
may only name regular files inside its folder. Errors: one line naming the input, exit 1.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

import pytest
from faults_mapdb_helpers import (
    assert_consistent,
    live_session_members,
    make_dataset,
    places_so_far,
    start_slow_build,
)

N_IMAGES = 24
on_linux = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="finds processes through /proc"
)


def wait_for_places(process, db_path: Path, n: int, timeout_s: float = 30.0) -> None:
    """Wait until the build has committed ``n`` places (its workers are running then)."""
    deadline = time.monotonic() + timeout_s
    while places_so_far(db_path) < n:
        if process.poll() is not None:
            raise AssertionError(process.stderr.read().decode())
        assert time.monotonic() < deadline, "the build did not start writing in time"
        time.sleep(0.02)


def wait_until_gone(session_id: int, timeout_s: float = 5.0) -> list[int]:
    """The session's living processes once they are all gone, or those left at the timeout."""
    deadline = time.monotonic() + timeout_s
    while (left := live_session_members(session_id)) and time.monotonic() < deadline:
        time.sleep(0.05)
    return left


@on_linux
def test_kill_9_of_map_build_takes_its_workers_along(tmp_path: Path) -> None:
    db_path = tmp_path / "map.db"
    process = start_slow_build(make_dataset(tmp_path / "ds", N_IMAGES), db_path)
    try:
        wait_for_places(process, db_path, 2)
        assert len(live_session_members(process.pid)) >= 3  # the build and its two workers
        os.kill(process.pid, signal.SIGKILL)  # the build alone, not its process group
        process.wait(timeout=10)
        left = wait_until_gone(process.pid)
    finally:
        for pid in live_session_members(process.pid):
            os.kill(pid, signal.SIGKILL)
        process.communicate(timeout=10)
    assert left == [], f"processes of the killed build still run: {left}"
    assert_consistent(db_path)


@on_linux
def test_sigterm_of_map_build_is_a_clean_interrupt(tmp_path: Path) -> None:
    db_path = tmp_path / "map.db"
    process = start_slow_build(make_dataset(tmp_path / "ds", N_IMAGES), db_path)
    try:
        wait_for_places(process, db_path, 2)
        os.kill(process.pid, signal.SIGTERM)
        stdout, stderr = process.communicate(timeout=20)
        left = wait_until_gone(process.pid)
    finally:
        for pid in live_session_members(process.pid):
            os.kill(pid, signal.SIGKILL)
    assert process.returncode == 130, stderr.decode()
    assert b"Traceback" not in stderr + stdout
    assert b"interrupted: the map is consistent" in stdout
    assert len((stdout + stderr).decode().splitlines()) <= 3, (stdout + stderr).decode()
    assert left == [], f"processes of the terminated build still run: {left}"
    assert 2 <= places_so_far(db_path) < N_IMAGES
    assert_consistent(db_path)
