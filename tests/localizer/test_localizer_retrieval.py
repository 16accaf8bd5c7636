"""The place indices (FLANN over descriptors, faiss IVF-PQ over codes): votes, shortlists,
leave-one-out, adding places, and agreement with brute-force evidence."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from localizer.evidence import EvidenceParams, place_evidence
from localizer.features import extract_preset
from localizer.retrieval import (
    CompactParams,
    CompactPlaceIndex,
    IndexParams,
    PlaceIndex,
    lists_for,
)
from localizer.robot_protocol import Pose2D
from mapdb.database import MapDatabase
from mapdb.loading import load_fingerprint_table
from mapdb.records import Fingerprint, FingerprintTable, NewPlace
from robot.conditions import get_condition
from robot.render import PanoramaCamera, render_panorama
from robot.scene import build_scene
from robot.worlds import make_world


def random_table(rng: np.random.Generator, counts: list[int], dim: int = 128) -> FingerprintTable:
    """A table of random unit-ish descriptors, ``counts[i]`` rows for place ``i``."""
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    n = int(offsets[-1])
    return FingerprintTable(
        detector="sift",
        place_ids=np.arange(10, 10 + len(counts), dtype=np.int64),
        rooms=tuple(f"room{i % 3}" for i in range(len(counts))),
        offsets=offsets,
        keypoints_xy=np.zeros((n, 2), np.float32),
        bearings_rad=np.zeros(n),
        descriptors=rng.random((n, dim), dtype=np.float32),
        alv_xy=np.zeros((len(counts), 2)),
        image_sizes_px=np.tile([512, 96], (len(counts), 1)),
        params=({},) * len(counts),
    )


def test_planted_place_is_shortlisted_first() -> None:
    rng = np.random.default_rng(0)
    table = random_table(rng, [80, 200, 120, 60, 150, 90])
    index = PlaceIndex.build(table)
    for place in range(6):
        rows = table.descriptors[table.offsets[place] : table.offsets[place + 1]]
        query = rows[::2] + rng.normal(0, 0.01, rows[::2].shape).astype(np.float32)
        assert index.shortlist(query, 3)[0] == place


def test_an_index_built_twice_over_one_map_shortlists_alike() -> None:
    rng = np.random.default_rng(3)
    table = random_table(rng, [1000] * 20)
    queries = rng.random((300, 128), dtype=np.float32)  # no place's: near neighbours by chance
    first, second = PlaceIndex.build(table), PlaceIndex.build(table)
    np.testing.assert_array_equal(first.shortlist(queries, 20), second.shortlist(queries, 20))


def test_leaving_a_place_out_lets_its_near_copy_win() -> None:
    rng = np.random.default_rng(2)
    table = random_table(rng, [100, 100, 100, 100])
    # Place 3 is a slightly changed view of place 1; the query is place 1's own descriptors.
    start = table.offsets[1]
    table.descriptors[table.offsets[3] :] = table.descriptors[start : start + 100] + 0.02
    index = PlaceIndex.build(table)
    own = table.descriptors[start : start + 100]
    assert index.shortlist(own, 2)[0] == 1
    left_out = index.shortlist(own, 2, exclude=1)
    assert left_out[0] == 3
    assert 1 not in left_out


def test_shortlist_edge_cases() -> None:
    rng = np.random.default_rng(1)
    table = random_table(rng, [30, 40])
    index = PlaceIndex.build(table)
    np.testing.assert_array_equal(
        np.sort(index.shortlist(np.zeros((0, 128), np.float32), 5)), [0, 1]
    )
    with pytest.raises(ValueError, match=r"must be \(n, 128\)"):
        index.shortlist(np.zeros((3, 64), np.float32), 1)
    with pytest.raises(ValueError, match="k must be >= 1"):
        index.shortlist(table.descriptors[:3], 0)
    empty = PlaceIndex.build(random_table(rng, []))
    assert empty.n_places == 0 and len(empty.shortlist(table.descriptors[:3], 4)) == 0
    with pytest.raises(ValueError, match="max_distance_ratio"):
        IndexParams(max_distance_ratio=0.5)


# Rendered: the corridor world (one long room, many places that look alike) at several spots.
CAMERA = PanoramaCamera(width_px=1024, height_px=192)
MAP_X_M = (2.0, 5.0, 8.0, 11.0, 14.0, 17.0, 20.0)
QUERIES = ((5.3, 1.2, 40.0), (13.7, 0.9, -100.0), (19.6, 1.1, 170.0))


@pytest.fixture(scope="module")
def corridor(tmp_path_factory: pytest.TempPathFactory) -> tuple[FingerprintTable, list]:
    world = make_world("corridor", 0)
    scene = build_scene(world)

    def fingerprint(x: float, y: float, heading_deg: float, condition: str) -> Fingerprint:
        pose = world.building_pose("corridor", Pose2D(x, y, math.radians(heading_deg)))
        image = render_panorama(
            scene, pose, CAMERA, get_condition(condition), seed=int(x * 10), grey=True
        )
        return extract_preset(image, "sift")

    path: Path = tmp_path_factory.mktemp("retrieval") / "map.db"
    with MapDatabase.open(path) as map_db:
        for i, x in enumerate(MAP_X_M):
            heading = 37.0 * i
            place = NewPlace("corridor", f"{i:064x}", f"corridor/{i}", x, 1.1, heading)
            map_db.add_place(place, [fingerprint(x, 1.1, heading, "default")])
        table = load_fingerprint_table(map_db, "sift")
    return table, [fingerprint(*q, "dim_noisy") for q in QUERIES]


def test_index_shortlist_contains_brute_force_winner(corridor) -> None:
    table, queries = corridor
    index = PlaceIndex.build(table)
    params = EvidenceParams(shortlist=3)
    for (x, _, _), query in zip(QUERIES, queries, strict=True):
        brute = place_evidence(query, table, params)
        assert brute.best is not None
        winner = int(np.flatnonzero(table.place_ids == brute.best.place_id)[0])
        assert abs(MAP_X_M[winner] - x) < 3.5  # the nearest place or its neighbour
        shortlist = index.shortlist(query.descriptors, params.shortlist)
        assert winner in shortlist
        indexed = place_evidence(query, table, params, index)
        assert len(indexed.places) == 3
        assert indexed.best is not None and indexed.best.place_id == brute.best.place_id
        assert indexed.best.inliers == brute.best.inliers  # same seed, same pairs
        assert indexed.timing_ms["retrieval"] > 0


def test_searching_on_two_threads_gives_the_same_scores() -> None:
    rng = np.random.default_rng(4)
    table = random_table(rng, [80, 200, 120, 60, 150, 90])
    query = table.descriptors[::3] + rng.normal(0, 0.05, table.descriptors[::3].shape)
    index = PlaceIndex.build(table, IndexParams(threads=1))
    one = index.scores(query.astype(np.float32))
    index.params = IndexParams(threads=2)  # the same kd-forest, searched in two halves
    two = index.scores(query.astype(np.float32))
    np.testing.assert_array_equal(one, two)
    with pytest.raises(ValueError, match="threads"):
        IndexParams(threads=0)


@pytest.fixture(scope="module")
def trained() -> CompactPlaceIndex:
    """An empty compact index trained on uniform random descriptors, as :func:`random_table`'s."""
    return CompactPlaceIndex.train(np.random.default_rng(9).random((3000, 128), np.float32))


def filled(trained: CompactPlaceIndex, table: FingerprintTable, places: int | None = None):
    """``trained``'s quantisers with the first ``places`` (default all) places of ``table``."""
    index = trained.emptied()
    count = len(table.place_ids) if places is None else places
    index.add_places([table.fingerprint(i).descriptors for i in range(count)])
    return index


def test_compact_index_shortlists_the_planted_place_first(trained) -> None:
    rng = np.random.default_rng(0)
    table = random_table(rng, [80, 200, 120, 60, 150, 90] * 3)
    index = filled(trained, table)
    assert index.n_places == 18 and index.n_codes == len(table.descriptors)
    for place in range(18):
        rows = table.fingerprint(place).descriptors
        query = rows[::2] + rng.normal(0, 0.01, rows[::2].shape).astype(np.float32)
        assert index.shortlist(query, 3)[0] == place


def test_compact_index_leaves_a_place_out_as_the_flann_index_does(trained) -> None:
    rng = np.random.default_rng(2)
    table = random_table(rng, [100] * 8)
    start = table.offsets[1]
    table.descriptors[table.offsets[7] :] = table.descriptors[start : start + 100] + 0.02
    index = filled(trained, table)
    own = table.descriptors[start : start + 100]
    assert index.shortlist(own, 2)[0] == 1
    left_out = index.shortlist(own, 2, exclude=1)
    assert left_out[0] == 7
    assert 1 not in left_out


def test_a_place_added_later_is_encoded_as_if_it_had_been_there_from_the_start(trained) -> None:
    rng = np.random.default_rng(3)
    table = random_table(rng, [120] * 8)
    later = filled(trained, table, places=7)
    assert later.add_place(table.fingerprint(7).descriptors) == 7
    assert later.n_places == 8
    np.testing.assert_array_equal(later.to_bytes(), filled(trained, table).to_bytes())
    rows = table.fingerprint(7).descriptors[::2]
    assert later.shortlist(rows + 0.01, 1)[0] == 7


def test_compact_index_round_trips_through_bytes(trained) -> None:
    rng = np.random.default_rng(5)
    table = random_table(rng, [90] * 6)
    index = filled(trained, table)
    query = table.descriptors[::4]
    copy = CompactPlaceIndex.from_bytes(index.to_bytes(), index.keypoint_counts)
    np.testing.assert_array_equal(copy.scores(query), index.scores(query))
    with pytest.raises(ValueError, match="not a compact place index"):
        CompactPlaceIndex.from_bytes(np.frombuffer(b"no index here", np.uint8), np.ones(1))
    with pytest.raises(ValueError, match="holds 540 codes, its places 539"):
        CompactPlaceIndex.from_bytes(index.to_bytes(), np.array([539]))


def test_compact_index_refuses_bad_input(trained) -> None:
    rng = np.random.default_rng(6)
    with pytest.raises(ValueError, match="n >= 1000"):
        CompactPlaceIndex.train(rng.random((100, 128), dtype=np.float32))
    index = filled(trained, random_table(rng, [100, 200]))
    with pytest.raises(ValueError, match=r"must be \(n, 128\)"):
        index.shortlist(np.zeros((3, 64), np.float32), 1)
    with pytest.raises(ValueError, match="probes"):
        CompactParams(probes=0)
    with pytest.raises(ValueError, match="bits must be 4"):
        CompactParams(bits=6)
    assert lists_for(10_000_000) == 4096 and lists_for(100) == 16


def test_compact_shortlist_contains_brute_force_winner(corridor) -> None:
    table, queries = corridor
    index = CompactPlaceIndex.train(table.descriptors[::3])  # a sample of the map's
    index.add_places([table.fingerprint(i).descriptors for i in range(len(table.place_ids))])
    params = EvidenceParams(shortlist=3)
    for query in queries:
        brute = place_evidence(query, table, params)
        assert brute.best is not None
        winner = int(np.flatnonzero(table.place_ids == brute.best.place_id)[0])
        assert winner in index.shortlist(query.descriptors, params.shortlist)
        indexed = place_evidence(query, table, params, index)
        assert indexed.best is not None and indexed.best.place_id == brute.best.place_id
        assert indexed.best.inliers == brute.best.inliers


@pytest.mark.parametrize("bits, subquantizers", [(4, 32), (8, 16)])
def test_both_code_layouts_shortlist_the_planted_place_and_read_back_as_stored(
    bits: int, subquantizers: int
) -> None:
    rng = np.random.default_rng(11)
    params = CompactParams(subquantizers=subquantizers, bits=bits)
    index = CompactPlaceIndex.train(rng.random((3000, 128), np.float32), params)
    table = random_table(rng, [100, 150, 80, 120] * 2)
    index.add_places([table.fingerprint(i).descriptors for i in range(8)])
    for place in range(8):
        rows = table.fingerprint(place).descriptors[::2]
        assert (
            index.shortlist(rows + rng.normal(0, 0.01, rows.shape).astype(np.float32), 2)[0]
            == place
        )
    # Read with the default settings, the index keeps the layout it was stored with.
    copy = CompactPlaceIndex.from_bytes(index.to_bytes(), index.keypoint_counts)
    assert (copy.params.bits, copy.params.subquantizers) == (bits, subquantizers)
    query = table.descriptors[::3]
    np.testing.assert_array_equal(copy.scores(query), index.scores(query))
