"""The map's versions and change log, and replicas kept from its snapshot and changes (issue 22):
real SQLite files; bad input leaves the replica as it was."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mapdb_helpers import assert_consistent, make_fingerprint, new_place

from mapdb.database import MapDatabase
from mapdb.errors import ReplicaError, UnknownVersionError
from mapdb.loading import load_fingerprints
from mapdb.replica import (
    apply_changes,
    check_same_map,
    read_changes,
    read_snapshot,
    replica_state,
    write_snapshot,
)
from mapdb.replication import (
    MAGIC,
    BadMapDataError,
    MapChange,
    decode_changes,
    decode_snapshot,
    encode_changes,
    encode_snapshot,
    join_chunks,
    sha256_hex,
    split_chunks,
)

REPO = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent


def fill(map_db: MapDatabase, rng: np.random.Generator, start: int, n: int) -> None:
    for i in range(start, start + n):
        map_db.add_place(new_place("hall" if i % 2 else "kitchen", i), [make_fingerprint(rng)])


@pytest.fixture
def site(db_path: Path, rng: np.random.Generator):
    """A map of three places in two connected rooms."""
    with MapDatabase.open(db_path) as map_db:
        fill(map_db, rng, 1, 3)
        map_db.connect_rooms("hall", "kitchen")
        yield map_db


@pytest.fixture
def replica(site: MapDatabase, tmp_path: Path) -> Path:
    path = tmp_path / "robot" / "replica.db"
    write_snapshot(path, encode_snapshot(read_snapshot(site)), str(site.map_id()))
    return path


def rows_of(path: Path):
    with MapDatabase.open(path, readonly=True) as map_db:
        return read_snapshot(map_db)


def test_each_write_takes_the_next_version(map_db: MapDatabase, rng) -> None:
    assert map_db.map_version() == 0
    map_db.add_room("hall")
    map_db.add_room("hall")  # already there: no write, no version
    map_db.add_place(new_place("kitchen", 1), [make_fingerprint(rng)])
    map_db.connect_rooms("hall", "kitchen")
    map_db.connect_rooms("kitchen", "hall")  # already there
    map_db.set_likelihood("sift", {"kind": "ratio"})
    log = map_db.db.execute("SELECT version, kind FROM changes ORDER BY version").fetchall()
    assert log == [(1, "room"), (2, "place"), (3, "edge"), (4, "likelihood")]
    assert map_db.map_version() == 4


def test_a_failed_add_takes_no_version(site: MapDatabase, rng) -> None:
    before = site.map_version()
    with pytest.raises(Exception, match="already"):
        site.add_place(new_place("hall", 1), [make_fingerprint(rng)])
    assert site.map_version() == before


def test_a_map_has_an_id_of_its_own_that_can_be_named(tmp_path: Path) -> None:
    with MapDatabase.open(tmp_path / "a.db") as a, MapDatabase.open(tmp_path / "b.db") as b:
        assert a.map_id() != b.map_id() and str(a.map_id()).startswith("map-")
        a.set_map_id("site-1")
        assert a.map_id() == "site-1"
        with pytest.raises(ValueError, match="map id 'a/b' must not contain"):
            a.set_map_id("a/b")


def test_a_replica_from_the_snapshot_equals_the_map(site: MapDatabase, replica: Path) -> None:
    assert rows_of(replica) == read_snapshot(site)
    assert replica_state(replica).version == site.map_version() == 4  # type: ignore[union-attr]
    assert not replica.with_name(replica.name + "-wal").exists()
    assert sorted(p.name for p in replica.parent.iterdir()) == ["replica.db"]


def test_changes_after_its_version_bring_the_replica_to_the_map(site, replica, rng) -> None:
    fill(site, rng, 10, 2)
    site.add_room("garden")
    site.connect_rooms("garden", "hall")
    site.set_likelihood("sift", {"kind": "ratio", "count": 3})
    map_id, changes = decode_changes(encode_changes(str(site.map_id()), read_changes(site, 4)))
    assert [c.kind for c in changes] == ["place", "place", "room", "edge", "likelihood"]
    state = apply_changes(replica, map_id, changes)
    assert state.version == site.map_version() == 9
    assert rows_of(replica) == read_snapshot(site)


def test_changes_come_at_most_a_batch_at_a_time(site: MapDatabase) -> None:
    assert [c.version for c in read_changes(site, 0, limit=2)] == [1, 2]
    assert read_changes(site, 4) == []


@pytest.mark.parametrize("after", [5, -1])
def test_changes_after_an_unknown_version_are_refused(site: MapDatabase, after: int) -> None:
    with pytest.raises(UnknownVersionError, match=f"has no version {after}: it is at version 4"):
        read_changes(site, after)


def test_a_truncated_snapshot_leaves_the_replica_as_it_was(site, replica, rng) -> None:
    fill(site, rng, 20, 1)
    before = replica.read_bytes()
    data = encode_snapshot(read_snapshot(site))
    for cut in (len(data) - 100, len(MAGIC) + 10):
        with pytest.raises(ReplicaError, match=r"snapshot refused: .*(truncated|beyond)"):
            write_snapshot(replica, data[:cut], str(site.map_id()))
    assert replica.read_bytes() == before
    assert sorted(p.name for p in replica.parent.iterdir()) == ["replica.db"]


def test_missing_chunks_or_another_checksum_are_named() -> None:
    data = bytes(range(256)) * 40
    chunks = dict(enumerate(split_chunks(data, 1000)))
    assert join_chunks(chunks, len(chunks), sha256_hex(data), "snapshot") == data
    del chunks[3]
    with pytest.raises(BadMapDataError, match="snapshot is truncated: 1 of 11 chunks missing"):
        join_chunks(chunks, 11, sha256_hex(data), "snapshot")
    chunks[3] = b"x" * 1000
    with pytest.raises(BadMapDataError, match="snapshot: SHA-256"):
        join_chunks(chunks, 11, sha256_hex(data), "snapshot")


def _with_fingerprint_rows(data: bytes, edit) -> bytes:
    """``data`` (encoded changes) with ``edit`` applied to each change's fingerprint rows."""
    header_end = len(MAGIC) + 4 + int.from_bytes(data[len(MAGIC) : len(MAGIC) + 4], "big")
    header = json.loads(data[len(MAGIC) + 4 : header_end])
    for change in header["changes"]:
        for row in change["tables"].get("fingerprints", []):
            edit(row)
    text = json.dumps(header).encode()
    return MAGIC + len(text).to_bytes(4, "big") + text + data[header_end:]


def _with_short_descriptors(data: bytes) -> bytes:
    """``data`` (encoded changes) with the fingerprints' descriptor blobs 8 bytes short."""

    def shorten(row: list) -> None:
        row[8][1] -= 8  # the descriptors' [offset, length]

    return _with_fingerprint_rows(data, shorten)


def test_a_fingerprint_blob_that_does_not_decode_is_refused(site, replica, rng) -> None:
    fill(site, rng, 30, 1)
    data = _with_short_descriptors(encode_changes(str(site.map_id()), read_changes(site, 4)))
    with pytest.raises(
        BadMapDataError, match=r"change 5: fingerprints row 0 .*descriptors blob has"
    ):
        decode_changes(data)


def test_changes_from_a_map_before_keypoint_sizes_are_applied_without_them(
    site, replica, rng
) -> None:
    fill(site, rng, 30, 1)
    data = encode_changes(str(site.map_id()), read_changes(site, 4))
    older = _with_fingerprint_rows(data, lambda row: row.pop())  # no sizes column
    map_id, changes = decode_changes(older)
    apply_changes(replica, map_id, changes)
    with MapDatabase.open(replica, readonly=True) as copy:
        (stored,) = [
            f for f in load_fingerprints(copy) if f.place_id == changes[0].rows.places[0][0]
        ]
    assert stored.fingerprint.keypoint_sizes_px is None


def test_keypoint_sizes_that_are_not_one_per_keypoint_are_refused(site, replica, rng) -> None:
    fill(site, rng, 30, 1)
    data = encode_changes(str(site.map_id()), read_changes(site, 4))

    def shorten(row: list) -> None:
        row[12][1] -= 4  # the sizes' [offset, length]

    with pytest.raises(BadMapDataError, match=r"keypoint_sizes_px blob has .* for 10 keypoints"):
        decode_changes(_with_fingerprint_rows(data, shorten))


def test_a_change_out_of_order_leaves_the_replica_as_it_was(site, replica, rng) -> None:
    fill(site, rng, 40, 3)
    before = replica.read_bytes()
    changes = read_changes(site, 4)
    with pytest.raises(ReplicaError, match="change out of order: version 6 where 5 comes next"):
        apply_changes(replica, str(site.map_id()), changes[1:])
    with pytest.raises(BadMapDataError, match="change out of order: version 7 after 5"):
        decode_changes(encode_changes(str(site.map_id()), [changes[0], changes[2]]))
    assert replica.read_bytes() == before


def test_a_change_that_fails_half_way_applies_nothing(site, replica, rng) -> None:
    fill(site, rng, 50, 2)
    before = replica.read_bytes()
    first, second = read_changes(site, 4)
    clash = MapChange(second.version, "place", first.rows)  # place of version 5 again
    with pytest.raises(ReplicaError, match="changes refused, none applied: change 6"):
        apply_changes(replica, str(site.map_id()), [first, clash])
    assert replica.read_bytes() == before


def test_a_replica_of_another_map_or_ahead_of_the_map_is_refused(site, replica) -> None:
    state = replica_state(replica)
    assert state is not None
    with pytest.raises(ReplicaError, match=r"is of map .*, not 'other-site': refused"):
        check_same_map(replica, state, "other-site")
    with pytest.raises(ReplicaError, match=r"at version 4, ahead of map .* at version 2: refused"):
        check_same_map(replica, state, state.map_id, version=2)
    with pytest.raises(ReplicaError, match="the snapshot is of map"):
        write_snapshot(replica, encode_snapshot(read_snapshot(site)), "other-site")


def test_decoding_refuses_what_is_not_map_rows() -> None:
    with pytest.raises(BadMapDataError, match="not toploc map rows"):
        decode_snapshot(b"PNG\x00 something else entirely")
    with pytest.raises(BadMapDataError, match="expected a snapshot, got 'changes'"):
        decode_snapshot(encode_changes("m", []))


ADDER = """
import sys
import numpy as np
sys.path.insert(0, sys.argv[2])
from mapdb_helpers import make_fingerprint, new_place
from mapdb.database import MapDatabase
rng = np.random.default_rng(0)
with MapDatabase.open(sys.argv[1]) as map_db:
    for i in range(100000):
        pair = [make_fingerprint(rng, n=400), make_fingerprint(rng, "mser", n=400)]
        map_db.add_place(new_place("hall", i), pair)
        print(i, flush=True)
"""


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs kill -9")
def test_kill_9_mid_add_loses_no_committed_place_and_leaves_no_half_one(db_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen(
        [sys.executable, "-c", ADDER, str(db_path), str(HERE.parent)],
        stdout=subprocess.PIPE, text=True, env=env, cwd=REPO,
    )  # fmt: skip
    assert process.stdout is not None
    committed = [int(process.stdout.readline()) for _ in range(20)]  # 20 adds reported done
    process.send_signal(signal.SIGKILL)
    process.wait(10)
    assert_consistent(db_path, detectors=2)
    with MapDatabase.open(db_path) as map_db:
        n_places = len(map_db.places())
        assert n_places >= len(committed)
        assert map_db.map_version() == n_places  # one version per whole place, none more
        log = map_db.db.execute("SELECT COUNT(*) FROM changes WHERE kind = 'place'").fetchone()
        assert log[0] == n_places
