"""Calibrating the likelihood on a map's own places: which places are queried, and a fit on the
rendered building (with its look-alike offices) that the map keeps."""

from __future__ import annotations

from localizer.calibration import calibrate, query_places
from localizer.likelihood import RatioLikelihood
from localizer.loaded_map import LoadedMap
from mapdb.database import MapDatabase
from mapdb.loading import load_snapshot
from toploc.maps import calibrate_map, load_map


def test_queries_are_spread_over_the_rooms() -> None:
    rooms = ["a"] * 5 + ["b"] * 2 + ["c"] * 10
    chosen = query_places(rooms, 8)
    assert len(chosen) == 8 and chosen == sorted(set(chosen))
    per_room = [sum(rooms[i] == r for i in chosen) for r in "abc"]
    assert per_room == [3, 2, 3]  # every room gets its share before any gets more
    assert query_places(["a"] * 3, 10) == [0, 1, 2]


def test_the_building_map_calibrates_with_its_twin_offices_set_apart(building_map) -> None:
    loaded = LoadedMap.from_snapshot(load_snapshot(building_map[0]))
    model, samples = calibrate(loaded, max_queries=24)
    assert samples.n_lookalike > 0  # office_a explains office_b's views: not chance
    assert len(samples.same_room) == 24
    assert model.fit["same_room_median"] > 3 * model.fit["other_room_median"]
    # a typical own-room count is strong evidence, a typical other-room count is not
    assert model.log_ratio(model.fit["same_room_median"]) > 2.0
    assert model.log_ratio(model.fit["other_room_median"]) < 0.0


def test_the_map_keeps_its_calibration(building_map, tmp_path) -> None:
    db_path = tmp_path / "map.db"
    db_path.write_bytes(building_map[0].read_bytes())
    with MapDatabase.open(db_path, create=False) as map_db:
        map_db.set_likelihood("sift", RatioLikelihood(intercept=-1.0).to_json())
    assert load_map(db_path).likelihood == RatioLikelihood(intercept=-1.0)
    stored = calibrate_map(db_path, "sift")
    assert load_map(db_path).likelihood == stored != RatioLikelihood(intercept=-1.0)


def test_a_twin_the_queries_missed_is_asked_before_the_pair_is_judged(building_map) -> None:
    loaded = LoadedMap.from_snapshot(load_snapshot(building_map[0]))
    # two queries: one from the corridor, one from office_a; office_b is asked afterwards
    model, _ = calibrate(loaded, max_queries=2)
    assert model.lookalikes == (("office_a", "office_b"),)
