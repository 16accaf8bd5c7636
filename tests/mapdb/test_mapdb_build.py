"""The build pipeline with a fake extractor: parallel, idempotent, partial failures, interrupts."""

from __future__ import annotations

import functools
import os
import subprocess
import sys
from pathlib import Path

import pytest
from mapdb_fake_extractor import crashing_extract, fake_extract, first_slow_extract
from mapdb_helpers import assert_consistent, table_counts

from mapdb.build import Status, build_map
from mapdb.database import MapDatabase
from mapdb.dataset import read_manifest
from mapdb.errors import BuildAbortedError, DiskFullError
from mapdb.loading import load_fingerprints

EXTRACT = functools.partial(fake_extract, presets=("sift", "mser"))


def test_a_parallel_build_stores_the_places_in_the_manifests_order(
    make_dataset, map_db: MapDatabase
) -> None:
    entries = read_manifest(make_dataset(5))
    extract = functools.partial(first_slow_extract, presets=("sift",))
    build_map(map_db, entries, extract, workers=2, progress=False)
    stored = [Path(place.source).name for place in sorted(map_db.places(), key=lambda p: p.id)]
    assert stored == [entry.path.name for entry in entries]


@pytest.mark.parametrize("workers", [0, 2])
def test_build_imports_every_image_with_its_pose(
    make_dataset, map_db: MapDatabase, db_path: Path, workers: int
) -> None:
    entries = read_manifest(make_dataset(7))
    report = build_map(map_db, entries, EXTRACT, workers=workers, progress=False)
    assert report.ok and report.count(Status.ADDED) == 7
    counts = {"rooms": 3, "edges": 0, "places": 7, "fingerprints": 14, "legs": 0}
    assert table_counts(db_path) == counts
    by_source = {Path(p.source).name: p for p in map_db.places()}
    assert by_source["pano_004.png"].room == "hall"
    assert (by_source["pano_004.png"].x_m, by_source["pano_004.png"].heading_deg) == (2.0, 40.0)
    assert by_source["pano_003.png"].x_m is None
    assert (
        by_source["pano_000.png"].image_width_px,
        by_source["pano_000.png"].image_height_px,
    ) == (
        96,
        24,
    )
    assert by_source["pano_000.png"].captured_utc is not None
    assert_consistent(db_path)


def test_rerun_skips_every_image_and_says_so(make_dataset, map_db: MapDatabase) -> None:
    entries = read_manifest(make_dataset(5))
    build_map(map_db, entries, EXTRACT, workers=0, progress=False)
    seen = []
    again = build_map(map_db, entries, EXTRACT, workers=2, progress=False, on_outcome=seen.append)
    assert again.ok and again.count(Status.SKIPPED) == 5
    assert seen == again.outcomes
    assert "already in the map as place" in seen[0].describe()
    assert len(map_db.places()) == 5


def test_exact_repeat_of_an_image_is_skipped_with_a_warning(
    make_dataset, map_db: MapDatabase
) -> None:
    folder = make_dataset(2)
    manifest = folder / "manifest.csv"
    manifest.write_text(manifest.read_text() + "img/pano_001.png,hall,0.5,-0.25,10.0\n")
    report = build_map(map_db, read_manifest(folder), EXTRACT, workers=0, progress=False)
    assert (report.count(Status.ADDED), report.count(Status.SKIPPED)) == (2, 1)
    (skipped,) = [o for o in report.outcomes if o.status is Status.SKIPPED]
    assert skipped.warning
    assert "line 4: exact duplicate of line 3" in skipped.message


def test_same_image_in_two_rooms_fails_both_rows(make_dataset, map_db: MapDatabase) -> None:
    folder = make_dataset(2)
    manifest = folder / "manifest.csv"
    manifest.write_text(manifest.read_text() + "img/pano_001.png,office,,,\n")
    report = build_map(map_db, read_manifest(folder), EXTRACT, workers=0, progress=False)
    assert (report.count(Status.ADDED), report.count(Status.FAILED)) == (1, 2)
    messages = sorted(o.message for o in report.outcomes if o.status is Status.FAILED)
    assert messages[0].startswith("line 3: same image as line 4 (img/pano_001.png)")
    assert messages[1].startswith("line 4: same image as line 3 (img/pano_001.png)")
    assert "conflicting duplicates" in messages[0]
    assert [p.room for p in map_db.places()] == ["kitchen"]


@pytest.mark.parametrize("workers", [0, 2])
def test_corrupt_and_missing_images_fail_alone(
    make_dataset, map_db: MapDatabase, db_path: Path, workers: int
) -> None:
    folder = make_dataset(6, corrupt=(2,))
    (folder / "img" / "pano_004.png").unlink()
    report = build_map(map_db, read_manifest(folder), EXTRACT, workers=workers, progress=False)
    failed = {o.image: o.message for o in report.outcomes if o.status is Status.FAILED}
    assert set(failed) == {"img/pano_002.png", "img/pano_004.png"}
    assert "pano_002.png: corrupt" in failed["img/pano_002.png"]
    assert "cannot read" in failed["img/pano_004.png"]
    assert not report.ok and report.count(Status.ADDED) == 4
    assert "failed 2" in report.summary()
    assert_consistent(db_path)


def test_ctrl_c_mid_build_keeps_committed_places_and_rerun_completes(
    make_dataset, map_db: MapDatabase, db_path: Path
) -> None:
    entries = read_manifest(make_dataset(6))
    calls = []

    def interrupting(path: Path) -> list:
        calls.append(path)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return EXTRACT(path)

    report = build_map(map_db, entries, interrupting, workers=0, progress=False)
    assert report.interrupted and not report.ok
    assert report.count(Status.ADDED) == 2
    assert table_counts(db_path)["places"] == 2
    assert_consistent(db_path)
    rerun = build_map(map_db, entries, EXTRACT, workers=0, progress=False)
    assert (rerun.count(Status.SKIPPED), rerun.count(Status.ADDED)) == (2, 4)
    assert table_counts(db_path)["fingerprints"] == 12
    assert_consistent(db_path)


def test_full_disk_stops_the_build_and_keeps_earlier_places(
    make_dataset, map_db: MapDatabase, db_path: Path
) -> None:
    entries = read_manifest(make_dataset(6))
    build_map(map_db, entries[:2], EXTRACT, workers=0, progress=False)
    stored = {s.place_id: s.fingerprint.descriptors.copy() for s in load_fingerprints(map_db)}
    page_count = map_db.db.execute("PRAGMA page_count").fetchone()[0]
    map_db.db.execute(f"PRAGMA max_page_count = {page_count + 2}")
    with pytest.raises(DiskFullError, match=r"map\.db"):
        build_map(map_db, entries, EXTRACT, workers=2, progress=False)
    map_db.close()
    assert_consistent(db_path)
    with MapDatabase.open(db_path) as reopened:
        after = {s.place_id: s.fingerprint.descriptors for s in load_fingerprints(reopened)}
        assert set(stored) <= set(after)
        for key, descriptors in stored.items():
            assert (after[key] == descriptors).all()
        rerun = build_map(reopened, entries, EXTRACT, workers=0, progress=False)
    assert rerun.ok
    assert table_counts(db_path)["places"] == 6


def test_dead_worker_aborts_cleanly_and_rerun_completes(
    make_dataset, map_db: MapDatabase, db_path: Path
) -> None:
    entries = read_manifest(make_dataset(8))
    crashing = functools.partial(crashing_extract, presets=("sift", "mser"))
    with pytest.raises(BuildAbortedError, match=r"worker process died.*re-run the build"):
        build_map(map_db, entries, crashing, workers=2, progress=False)
    assert_consistent(db_path)
    rerun = build_map(map_db, entries, EXTRACT, workers=2, progress=False)
    assert rerun.ok
    assert table_counts(db_path)["places"] == 8


HALF_SENDING_BUILD = """
import functools, sys
from pathlib import Path
from mapdb_fake_extractor import half_sending_extract
from mapdb.build import build_map
from mapdb.database import MapDatabase
from mapdb.dataset import read_manifest
from mapdb.errors import BuildAbortedError

extract = functools.partial(half_sending_extract, presets=("sift", "mser"))
with MapDatabase.open(Path(sys.argv[2])) as map_db:
    try:
        build_map(map_db, read_manifest(Path(sys.argv[1])), extract, workers=2, progress=False)
    except BuildAbortedError as error:
        print(error)
"""


def test_a_worker_killed_while_sending_its_result_aborts_the_build(
    make_dataset, db_path: Path
) -> None:
    """The out-of-memory killer may end a worker between the two writes of a large result; the
    pool then never says so, and the build used to wait for ever (run in a subprocess, so a
    hang fails this test instead of the suite)."""
    dataset = make_dataset(8)
    here = Path(__file__).resolve().parent
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(here.parents[1]), str(here)])}
    try:
        done = subprocess.run(
            [sys.executable, "-c", HALF_SENDING_BUILD, str(dataset), str(db_path)],
            env=env, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
    except subprocess.TimeoutExpired:
        pytest.fail("the build did not end: it is waiting for a result that never comes")
    assert done.returncode == 0, done.stderr
    assert "worker process died: process" in done.stdout
    assert "was killed by SIGKILL" in done.stdout and "re-run the build" in done.stdout
    assert_consistent(db_path)
    with MapDatabase.open(db_path) as map_db:
        rerun = build_map(map_db, read_manifest(dataset), EXTRACT, workers=2, progress=False)
    assert rerun.ok
    assert table_counts(db_path)["places"] == 8
