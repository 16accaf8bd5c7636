"""The compact index of a big map, kept beside it: built once, read again, extended when places
are added, rebuilt (and said) when damaged or stale; and a localizer on a map read from disk
gives the evidence it gives on the map in memory."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from mapdb_helpers import make_fingerprint, new_place

from localizer.evidence import EvidenceParams
from localizer.localizer import Localizer, LocalizerConfig
from mapdb.database import MapDatabase
from mapdb.dataset import read_manifest
from mapdb.store import SqlitePlaceStore
from toploc.map_index import FORMAT, compact_index, index_path, refresh_index_files
from toploc.maps import load_map


def random_map(path: Path, places: int, seed: int, first: int = 0) -> Path:
    """``places`` places of 100 random SIFT-sized keypoints each, in three rooms."""
    rng = np.random.default_rng(seed)
    with MapDatabase.open(path) as map_db:
        for i in range(first, first + places):
            map_db.add_place(new_place(f"room{i % 3}", i), [make_fingerprint(rng, "sift", 100)])
    return path


@pytest.fixture
def big_map(tmp_path: Path) -> Path:
    return random_map(tmp_path / "map.db", 30, seed=1)


def own_view(store: SqlitePlaceStore, i: int) -> np.ndarray:
    """Half of place ``i``'s descriptors, slightly changed: a query that should find it."""
    return store.fingerprint(i).descriptors[::2] + 0.01


def test_the_index_is_built_once_then_read_from_its_file(big_map: Path) -> None:
    store = SqlitePlaceStore.open(big_map, "sift")
    built, report = compact_index(store)
    assert (report.action, report.why) == ("built", "no index file")
    assert index_path(big_map, "sift").is_file()
    again, report = compact_index(SqlitePlaceStore.open(big_map, "sift"))
    assert report.action == "read" and again.n_places == 30
    query = own_view(store, 7)
    np.testing.assert_array_equal(again.scores(query), built.scores(query))
    assert again.shortlist(query, 1)[0] == 7


def test_adding_a_place_extends_the_index_without_rebuilding_it(big_map: Path) -> None:
    before, _ = compact_index(SqlitePlaceStore.open(big_map, "sift"))
    random_map(big_map, 1, seed=2, first=30)  # `map add`: one more place
    store = SqlitePlaceStore.open(big_map, "sift")
    after, report = compact_index(store)
    assert (report.action, report.added) == ("extended", 1)
    assert after.n_places == 31
    np.testing.assert_array_equal(after.emptied().to_bytes(), before.emptied().to_bytes())
    assert after.shortlist(own_view(store, 30), 1)[0] == 30
    _, report = compact_index(SqlitePlaceStore.open(big_map, "sift"))
    assert report.action == "read"  # the extended index was written back


def test_refreshing_after_map_add_encodes_the_new_place_into_the_file(big_map: Path) -> None:
    assert refresh_index_files(big_map) == []  # no index file: nothing to do
    compact_index(SqlitePlaceStore.open(big_map, "sift"))
    random_map(big_map, 2, seed=4, first=30)
    (report,) = refresh_index_files(big_map)
    assert (report.action, report.added) == ("extended", 2)
    assert compact_index(SqlitePlaceStore.open(big_map, "sift"))[1].action == "read"


def test_a_damaged_index_file_is_said_and_built_again(big_map: Path, caplog) -> None:
    compact_index(SqlitePlaceStore.open(big_map, "sift"))
    path = index_path(big_map, "sift")
    path.write_bytes(path.read_bytes()[:1000])  # cut short
    with caplog.at_level(logging.WARNING, logger="toploc.map_index"):
        index, report = compact_index(SqlitePlaceStore.open(big_map, "sift"))
    assert report.action == "built" and report.why.startswith("damaged")
    (record,) = caplog.records
    assert str(path) in record.getMessage() and "\n" not in record.getMessage()
    assert index.n_places == 30
    with MapDatabase.open(big_map, readonly=True) as map_db:
        assert map_db.info().n_places == 30  # the map is untouched
    assert compact_index(SqlitePlaceStore.open(big_map, "sift"))[1].action == "read"


def test_an_index_file_of_other_places_is_stale_and_built_again(big_map: Path, tmp_path) -> None:
    other = random_map(tmp_path / "other.db", 30, seed=3, first=100)
    compact_index(SqlitePlaceStore.open(other, "sift"))
    shutil.copy(index_path(other, "sift"), index_path(big_map, "sift"))
    store = SqlitePlaceStore.open(big_map, "sift")
    index, report = compact_index(store)
    assert report.action == "built" and report.why.startswith("stale")
    assert index.shortlist(own_view(store, 4), 1)[0] == 4


def test_an_index_file_of_an_earlier_layout_is_said_and_built_again(big_map: Path, caplog) -> None:
    compact_index(SqlitePlaceStore.open(big_map, "sift"))
    path = index_path(big_map, "sift")
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    arrays["header"] = np.array(json.dumps({"format": FORMAT - 1, "detector": "sift"}))
    with open(path, "wb") as out:
        np.savez(out, **arrays)
    with caplog.at_level(logging.WARNING, logger="toploc.map_index"):
        _, report = compact_index(SqlitePlaceStore.open(big_map, "sift"))
    assert report.action == "built" and report.why.startswith("stale")
    (record,) = caplog.records
    assert str(path) in record.getMessage() and "\n" not in record.getMessage()
    assert compact_index(SqlitePlaceStore.open(big_map, "sift"))[1].action == "read"


def test_a_localizer_on_the_map_read_from_disk_sees_what_it_sees_in_memory(
    building_map, tmp_path: Path
) -> None:
    db_path = Path(shutil.copy(building_map[0], tmp_path / "map.db"))
    on_disk = load_map(db_path, storage="disk")
    in_memory = load_map(db_path, storage="memory")
    assert isinstance(on_disk.table, SqlitePlaceStore)
    n_places = len(on_disk.places)
    config = LocalizerConfig(evidence=EvidenceParams(shortlist=n_places))  # verify every place
    entry = read_manifest(building_map[1])[3]
    image = cv2.imread(str(entry.path), cv2.IMREAD_GRAYSCALE)
    disk_belief, disk_seen = Localizer(on_disk, config).localize_once(image)
    memory_belief, memory_seen = Localizer(in_memory, config).localize_once(image)
    key = [(e.place_id, e.inliers, e.matches) for e in disk_seen.evidence.places]
    assert key == [(e.place_id, e.inliers, e.matches) for e in memory_seen.evidence.places]
    assert disk_belief.probabilities == memory_belief.probabilities
    assert disk_belief.best_place_room == entry.room
