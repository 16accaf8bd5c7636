"""Issue 11, map part: faults a user can cause with `toploc map`, each a reproduction.

Processes: a killed or terminated build leaves no worker behind. Paths and files: a manifest
may only name regular files inside its folder. Errors: one line naming the input, exit 1.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest
from click.testing import CliRunner, Result
from faults_mapdb_helpers import (
    REPO,
    can_bind_mount_read_only,
    fake_extract,
    live_session_members,
    make_dataset,
    make_read_only,
    make_writable,
    on_read_only_folder,
    places_so_far,
    run_toploc,
    start_slow_build,
    write_manifest,
)
from mapdb_helpers import assert_consistent, write_image

from mapdb.build import build_map
from mapdb.database import MapDatabase
from mapdb.dataset import read_manifest
from mapdb.errors import InvalidValueError, NotAMapDatabaseError
from mapdb.loading import open_for_reading
from mapdb.records import MAX_NAME_CHARS, NewPlace
from mapdb.schema import MIGRATIONS
from toploc.commands.localize import localize
from toploc.commands.map import map_group
from toploc.extraction import resolve_extractor

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


@pytest.fixture
def fake_extractor(monkeypatch: pytest.MonkeyPatch) -> None:
    """``toploc map`` run in this process extracts with the helpers' ``fake_extract``."""
    from toploc import extraction

    monkeypatch.setattr(extraction, "extract_panorama", fake_extract)


def build(dataset: Path, db_path: Path, *extra: str) -> Result:
    """``toploc map build`` in this process, in-process extraction, no calibration."""
    args = ["build", str(dataset), "--db", str(db_path), "--workers", "0", "--no-progress"]
    return CliRunner().invoke(map_group, [*args, "--no-calibrate", *extra])


def assert_one_line_error(result: Result | subprocess.CompletedProcess, *names: str) -> str:
    """Exit 1, no traceback, and an ``Error:`` line that names every one of ``names``."""
    output = result.output if isinstance(result, Result) else result.stdout + result.stderr
    code = result.exit_code if isinstance(result, Result) else result.returncode
    assert code == 1, output
    assert "Traceback" not in output, output
    if isinstance(result, Result):
        assert result.exception is None or isinstance(result.exception, SystemExit), output
    (line,) = [line for line in output.splitlines() if line.startswith("Error: ")]
    for name in names:
        assert name in line, line
    return line


@pytest.mark.parametrize("where", ["dotdot", "absolute", "symlink"])
def test_manifest_image_outside_the_dataset_is_refused(
    tmp_path: Path, where: str, fake_extractor: None
) -> None:
    outside = write_image(tmp_path / "elsewhere" / "x.png", seed=5)
    dataset = make_dataset(tmp_path / "deep" / "ds", 2)
    if where == "symlink":
        (dataset / "img" / "link.png").symlink_to(outside)
    name = {"dotdot": "../../elsewhere/x.png", "absolute": str(outside), "symlink": "img/link.png"}
    manifest = (dataset / "manifest.csv").read_text() + f"{name[where]},hall,1,1,0\n"
    (dataset / "manifest.csv").write_text(manifest)
    db_path = tmp_path / "map.db"
    line = assert_one_line_error(build(dataset, db_path), "manifest.csv line 4", name[where])
    assert "outside the dataset folder" in line
    assert not db_path.exists() or places_so_far(db_path) == 0  # nothing imported

    allowed = build(dataset, db_path, "--allow-outside")
    assert allowed.exit_code == 0, allowed.output
    assert "added 3, skipped 0, failed 0" in allowed.stdout


def build_process(dataset: Path, db_path: Path, *extra: str) -> subprocess.CompletedProcess:
    """``python -m toploc map build`` (SIFT, in-process), stopped after 60 s if it hangs."""
    return run_toploc("map", "build", dataset, "--db", db_path, "--workers", "0",
                      "--no-progress", "--no-calibrate", "--detector", "sift", *extra,
                      timeout_s=60)  # fmt: skip


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_fifo_row_fails_at_once_instead_of_hanging(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "ds", 1)
    os.mkfifo(dataset / "img" / "pipe.png")
    lines = (dataset / "manifest.csv").read_text().splitlines()
    write_manifest(dataset, [*lines, "img/pipe.png,hall,,,"])
    db_path = tmp_path / "map.db"
    result = build_process(dataset, db_path)
    assert_one_line_error(result, "1 image(s) failed", "img/pipe.png")
    assert "line 3: " in result.stderr
    assert "pipe.png is a FIFO (named pipe), not a regular file" in result.stderr
    assert places_so_far(db_path) == 1


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="needs /dev/zero")
def test_dev_zero_row_fails_at_once_instead_of_hanging(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "ds", 1)
    lines = (dataset / "manifest.csv").read_text().splitlines()
    write_manifest(dataset, [*lines, "/dev/zero,hall,,,"])
    result = build_process(dataset, tmp_path / "map.db", "--allow-outside")
    assert_one_line_error(result, "1 image(s) failed", "/dev/zero")
    assert "line 3: /dev/zero is a character device, not a regular file" in result.stderr


def test_latin_1_manifest_is_one_line_naming_line_and_byte(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "ds", 2, rooms=("kitchen", "hall"))
    lines = (dataset / "manifest.csv").read_text().splitlines()
    write_manifest(dataset, [*lines, "img/pano_000.png,café,,,"], encoding="latin-1")
    offset = len("\n".join(lines)) + 1 + len("img/pano_000.png,caf")
    line = assert_one_line_error(
        build(dataset, tmp_path / "map.db"), "manifest.csv line 4", f"byte {offset}", "UTF-8"
    )
    assert "0xe9" in line


def test_manifest_image_with_a_nul_byte_is_one_line(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "ds", 1)
    (dataset / "manifest.csv").write_bytes(
        b"image,room,x_m,y_m,heading_deg\nimg/a\x00.png,hall,,,\n"
    )
    assert_one_line_error(build(dataset, tmp_path / "map.db"), "manifest.csv line 2")


def bad_map(tmp_path: Path, kind: str) -> Path:
    """A map file that cannot be served: ``empty-map`` (a map without places), ``zero-bytes``,
    ``text`` (not SQLite) or ``null-version`` (``meta.schema_version`` is NULL)."""
    path = tmp_path / f"{kind}.db"
    if kind == "zero-bytes":
        path.touch()
    elif kind == "text":
        path.write_text("these are my notes, not a map\n" * 100)
    else:
        MapDatabase.open(path).close()
    if kind == "null-version":
        with sqlite3.connect(path) as conn:
            conn.execute("UPDATE meta SET value = NULL WHERE key = 'schema_version'")
        conn.close()
    return path


MAP_FAULTS = ["empty-map", "zero-bytes", "text", "null-version"]


@pytest.mark.parametrize(
    ("kind", "sim"),
    # a map without places is not bad: it is served, with the simulated robot or without (a
    # map about to be recorded: tests/toploc/test_node_commands.py, tests/robot/
    # test_p2os_end_to_end.py)
    [(kind, sim) for kind in MAP_FAULTS for sim in (True, False) if kind != "empty-map"],
    ids=lambda value: {True: "sim", False: "no-sim"}.get(value, value),
)
def test_serve_a_bad_map_is_one_line(tmp_path: Path, kind: str, sim: bool) -> None:
    db_path = bad_map(tmp_path, kind)
    extra = [] if sim else ["--no-sim"]
    result = run_toploc("serve", "--db", db_path, "--listen", "tcp/127.0.0.1:0", *extra,
                        timeout_s=60)  # fmt: skip
    assert_one_line_error(result, str(db_path))


@pytest.mark.parametrize("kind", MAP_FAULTS)
def test_localize_and_map_info_on_a_bad_map_are_one_line(tmp_path: Path, kind: str) -> None:
    db_path = bad_map(tmp_path, kind)
    image = write_image(tmp_path / "query.png", seed=3)
    result = CliRunner().invoke(localize, [str(image), "--db", str(db_path)])
    assert_one_line_error(result, str(db_path))
    if kind != "empty-map":  # an empty map has an empty summary
        info = CliRunner().invoke(map_group, ["info", "--db", str(db_path)])
        assert_one_line_error(info, str(db_path))


def test_null_schema_version_is_not_a_map(tmp_path: Path) -> None:
    db_path = bad_map(tmp_path, "null-version")
    with pytest.raises(NotAMapDatabaseError, match=r"null-version\.db is an SQLite database but"):
        MapDatabase.open(db_path)


@pytest.mark.parametrize(
    ("option", "value"), [("--x-m", "nan"), ("--y-m", "inf"), ("--heading-deg", "-inf")]
)
def test_map_add_refuses_a_non_finite_pose(
    tmp_path: Path, option: str, value: str, fake_extractor: None
) -> None:
    image = write_image(tmp_path / "a.png", seed=1)
    db_path = tmp_path / "map.db"
    pose = {"--x-m": "1", "--y-m": "2", "--heading-deg": "3", option: value}
    args = ["add", str(image), "--db", str(db_path), "--room", "hall", "--no-calibrate"]
    result = CliRunner().invoke(map_group, [*args, *(t for kv in pose.items() for t in kv)])
    assert_one_line_error(result, option, value)
    assert places_so_far(db_path) == 0


@pytest.mark.parametrize("field", ["x_m", "y_m", "heading_deg"])
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_the_write_path_refuses_a_non_finite_pose(tmp_path: Path, field: str, value: float) -> None:
    pose = {"x_m": 1.0, "y_m": 2.0, "heading_deg": 3.0, field: value}
    with pytest.raises(ValueError, match=rf"{field} must be a finite number or unknown"):
        NewPlace(room="hall", image_sha256="a" * 64, source="a.png", **pose)
    place = NewPlace(room="hall", image_sha256="a" * 64, source="a.png")
    with pytest.raises(ValueError, match=rf"{field} must be a finite number"):
        replace(place, **{field: value})


LONG_NAME = "x" * 100_000


def test_map_add_and_connect_refuse_a_name_beyond_the_bound(
    tmp_path: Path, fake_extractor: None
) -> None:
    image = write_image(tmp_path / "a.png", seed=1)
    db_path = tmp_path / "map.db"
    base = ["--db", str(db_path), "--no-calibrate"]
    result = CliRunner().invoke(map_group, ["add", str(image), *base, "--room", LONG_NAME])
    line = assert_one_line_error(result, "--room", f"more than {MAX_NAME_CHARS}")
    assert len(line) < 200
    assert places_so_far(db_path) == 0
    at_bound = "y" * MAX_NAME_CHARS
    added = CliRunner().invoke(map_group, ["add", str(image), *base, "--room", at_bound])
    assert added.exit_code == 0, added.output
    connect = ["connect", at_bound, LONG_NAME, "--db", str(db_path)]
    line = assert_one_line_error(CliRunner().invoke(map_group, connect), str(db_path))
    assert "100000 characters" in line and len(line) < 300
    with MapDatabase.open(db_path) as map_db, pytest.raises(InvalidValueError):
        map_db.add_room(LONG_NAME)
    with MapDatabase.open(db_path) as map_db, pytest.raises(InvalidValueError, match="control"):
        map_db.add_room("hall\nkitchen")


def test_manifest_room_name_beyond_the_bound_is_one_line(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "ds", 2)
    lines = (dataset / "manifest.csv").read_text().splitlines()
    write_manifest(dataset, [*lines, f"img/pano_000.png,{LONG_NAME},,,"])
    line = assert_one_line_error(build(dataset, tmp_path / "map.db"), "manifest.csv line 4")
    assert f"more than {MAX_NAME_CHARS}" in line and len(line) < 300


read_only_possible = pytest.mark.skipif(
    os.geteuid() == 0 and not can_bind_mount_read_only(),
    reason="root ignores file modes and cannot bind-mount read-only here",
)


@pytest.fixture
def read_only_map(tmp_path: Path) -> Iterator[tuple[Path, Path]]:
    """``(db_path, query_image)``: a small SIFT map in WAL mode, alone in a folder that is
    read-only for the commands run through :func:`on_read_only_folder` (no ``-shm`` there)."""
    dataset = make_dataset(tmp_path / "ds", 4, rooms=("kitchen", "hall"))
    folder = tmp_path / "ro"
    folder.mkdir()
    db_path = folder / "map.db"
    with MapDatabase.open(db_path) as map_db:
        entries = read_manifest(dataset)
        build_map(map_db, entries, resolve_extractor(("sift",)), workers=0, progress=False)
    assert db_path.read_bytes()[18:20] == b"\x02\x02"  # file format versions 2: WAL mode
    assert sorted(p.name for p in folder.iterdir()) == ["map.db"]  # no -wal, no -shm
    make_read_only(folder)
    try:
        yield db_path, dataset / "img" / "pano_001.png"
    finally:
        make_writable(folder)


def run_on_read_only(folder: Path, *args: str | Path) -> subprocess.CompletedProcess:
    argv = [sys.executable, "-m", "toploc", *(str(a) for a in args)]
    return subprocess.run(
        on_read_only_folder(folder, argv),
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=120,
    )


@read_only_possible
def test_a_wal_map_on_read_only_media_opens_for_info_and_localize(
    read_only_map: tuple[Path, Path],
) -> None:
    db_path, query = read_only_map
    folder = db_path.parent
    info = run_on_read_only(folder, "map", "info", "--db", db_path, "--json")
    assert info.returncode == 0, info.stderr
    assert json.loads(info.stdout)["n_places"] == 4
    found = run_on_read_only(folder, "localize", query, "--db", db_path, "--json")
    assert found.returncode == 0, found.stderr
    assert set(json.loads(found.stdout)["rooms"]) == {"kitchen", "hall"}
    writing = run_on_read_only(folder, "map", "connect", "kitchen", "hall", "--db", db_path)
    assert_one_line_error(writing, str(db_path))
    assert sorted(p.name for p in folder.iterdir()) == ["map.db"]


@read_only_possible
def test_a_wal_map_on_read_only_media_is_served(read_only_map: tuple[Path, Path]) -> None:
    db_path, _ = read_only_map
    argv = [sys.executable, "-m", "toploc", "serve", "--db", str(db_path), "--no-sim",
            "--listen", "tcp/127.0.0.1:0"]  # fmt: skip
    process = subprocess.Popen(
        on_read_only_folder(db_path.parent, argv),
        env={**os.environ, "PYTHONPATH": str(REPO)},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        process.stdout.readline()  # "robot id: ..."
        serving = process.stdout.readline()  # "serving ..." once the map is loaded
    finally:
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=30)
    assert serving.startswith(f"serving {db_path}"), serving + stderr


@read_only_possible
def test_an_unfinished_wal_on_read_only_media_is_one_line(tmp_path: Path) -> None:
    folder = tmp_path / "ro"
    folder.mkdir()
    writer = MapDatabase.open(tmp_path / "live.db")
    try:
        writer.db.execute("PRAGMA wal_autocheckpoint = 0")
        writer.add_room("kitchen")  # in the -wal only, until a checkpoint
        for suffix in ("", "-wal"):
            shutil.copy(tmp_path / f"live.db{suffix}", folder / f"map.db{suffix}")
    finally:
        writer.close()
    make_read_only(folder)
    try:
        result = run_on_read_only(folder, "map", "info", "--db", folder / "map.db")
    finally:
        make_writable(folder)
    line = assert_one_line_error(result, str(folder / "map.db"), "map.db-wal")
    assert "read-only" in line


def test_an_older_map_is_read_without_writing(tmp_path: Path) -> None:
    db_path = tmp_path / "old.db"
    with MapDatabase.open(db_path, migrations=MIGRATIONS[:1]) as old:
        old.add_room("hall")
    before = db_path.read_bytes()
    with open_for_reading(db_path) as map_db:
        assert map_db.schema_version() == 1
        assert map_db.places() == [] and [r.name for r in map_db.rooms()] == ["hall"]
    assert db_path.read_bytes() == before


def test_edges_naming_an_unknown_room_is_an_error_or_creates_it(
    tmp_path: Path, fake_extractor: None
) -> None:
    dataset = make_dataset(tmp_path / "ds", 2)
    (dataset / "edges.csv").write_text("room_a,room_b\nhall,kitchen\nhall,garden\n")
    db_path = tmp_path / "map.db"
    assert_one_line_error(build(dataset, db_path), "edges.csv line 3", "'garden'", "--create-rooms")
    assert places_so_far(db_path) == 0
    created = build(dataset, db_path, "--create-rooms")
    assert created.exit_code == 0, created.output
    assert "connected 2 pair(s) of rooms from edges.csv" in created.stdout
    with MapDatabase.open(db_path, readonly=True) as map_db:
        assert map_db.edges() == [("garden", "hall"), ("hall", "kitchen")]
        assert {r.name: r.n_places for r in map_db.rooms()} == {
            "garden": 0,
            "hall": 1,
            "kitchen": 1,
        }


def test_same_image_under_two_rooms_is_an_error_naming_both_rows(
    tmp_path: Path, fake_extractor: None
) -> None:
    dataset = make_dataset(tmp_path / "ds", 2)  # line 3: img/pano_001.png in the hall at 1,0,0
    lines = (dataset / "manifest.csv").read_text().splitlines()
    write_manifest(
        dataset, [*lines, "img/pano_001.png,kitchen,1,0,0", "img/pano_000.png,kitchen,0,0,0"]
    )
    db_path = tmp_path / "map.db"
    result = build(dataset, db_path)
    assert_one_line_error(result, "2 image(s) failed", "img/pano_001.png")
    assert "line 3: same image as line 4 (img/pano_001.png) but in room 'hall'" in result.stderr
    assert "line 4: same image as line 3 (img/pano_001.png) but in room 'kitchen'" in result.stderr
    duplicate = "line 5: exact duplicate of line 2 (img/pano_000.png), skipped"
    assert duplicate in result.stderr  # a warning, not -v
    with MapDatabase.open(db_path, readonly=True) as map_db:
        assert [(p.room, p.x_m) for p in map_db.places()] == [("kitchen", 0.0)]
