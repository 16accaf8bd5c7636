"""``toploc map`` through click's CliRunner: commands, messages and exit statuses."""

from __future__ import annotations

import importlib
import json
import sqlite3
from pathlib import Path

import networkx as nx
import pytest
from click.testing import CliRunner, Result
from mapdb_helpers import assert_consistent, table_counts, write_image

from mapdb.database import MapDatabase
from toploc.commands import map as map_cli
from toploc.commands.map import map_group


def run(*args: str | Path) -> Result:
    return CliRunner().invoke(map_group, [str(a) for a in args], catch_exceptions=False)


def build(dataset: Path, db: Path, *extra: str) -> Result:
    return run("build", dataset, "--db", db, "--no-progress", *extra)


@pytest.mark.usefixtures("fake_extractor")
def test_build_then_rerun_is_idempotent(make_dataset, db_path: Path) -> None:
    dataset = make_dataset(6)
    first = build(dataset, db_path, "--workers", "2")
    assert first.exit_code == 0, first.output
    assert "added 6, skipped 0, failed 0 in " in first.stdout
    assert "the map holds 6 places in 3 rooms" in first.stdout
    second = build(dataset, db_path, "--workers", "2")
    assert second.exit_code == 0
    assert "added 0, skipped 6, failed 0" in second.stdout
    assert "skipped 6 image(s) already in the map" in second.stdout
    third = build(dataset, db_path, "--workers", "0", "--verbose")
    assert "skipped img/pano_000.png: already in the map as place" in third.stderr
    counts = {"rooms": 3, "edges": 0, "places": 6, "fingerprints": 6, "legs": 0}
    assert table_counts(db_path) == counts


@pytest.mark.usefixtures("fake_extractor")
def test_build_from_one_sub_folder_per_room(tmp_path: Path, db_path: Path) -> None:
    photos = tmp_path / "photos"
    for i, room in enumerate(("kitchen", "kitchen", "hall")):
        write_image(photos / room / f"IMG_{i:04d}.JPG", seed=i)
    result = build(photos, db_path, "--workers", "0")
    assert result.exit_code == 0, result.output
    assert "added 3, skipped 0, failed 0" in result.stdout
    with MapDatabase.open(db_path, readonly=True) as map_db:
        places = map_db.places()
    assert sorted(p.room for p in places) == ["hall", "kitchen", "kitchen"]
    assert {(p.x_m, p.y_m, p.heading_deg) for p in places} == {(None, None, None)}


@pytest.mark.usefixtures("fake_extractor")
def test_build_connects_the_rooms_listed_in_edges_csv(make_dataset, db_path: Path) -> None:
    dataset = make_dataset(3)
    (dataset / "edges.csv").write_text("room_a,room_b\nhall,kitchen\n")
    result = build(dataset, db_path, "--workers", "0")
    assert result.exit_code == 0, result.output
    assert "connected 1 pair(s) of rooms from edges.csv" in result.stdout
    with MapDatabase.open(db_path) as map_db:
        assert map_db.edges() == [("hall", "kitchen")]


@pytest.mark.usefixtures("fake_extractor")
def test_build_with_corrupt_image_imports_the_rest_and_fails(make_dataset, db_path) -> None:
    result = build(make_dataset(5, corrupt=(3,)), db_path, "--workers", "2", "-v")
    assert result.exit_code == 1
    assert "failed img/pano_003.png:" in result.stderr
    assert "Error: 1 image(s) failed: img/pano_003.png" in result.stderr
    assert "added img/pano_000.png: room 'kitchen', sift 24\n" in result.stderr  # sift only
    assert table_counts(db_path)["places"] == 4
    assert_consistent(db_path, detectors=1)


@pytest.mark.usefixtures("fake_extractor")
def test_build_with_manifest_lacking_a_column_writes_nothing(tmp_path, db_path) -> None:
    folder = tmp_path / "ds"
    write_image(folder / "a.png", 1)
    (folder / "manifest.csv").write_text("image,x_m,y_m,heading_deg\na.png,1,2,3\n")
    result = build(folder, db_path)
    assert result.exit_code == 1
    assert "manifest.csv lacks column(s) 'room'" in result.stderr
    assert not db_path.exists()


@pytest.mark.usefixtures("fake_extractor")
def test_build_into_a_file_that_is_not_sqlite(make_dataset, tmp_path: Path) -> None:
    target = tmp_path / "thesis.pdf"
    target.write_bytes(b"%PDF-1.5\n" + b"x" * 5000)
    result = build(make_dataset(2), target)
    assert result.exit_code == 1
    assert "thesis.pdf is not a valid SQLite database" in result.stderr
    assert target.read_bytes() == b"%PDF-1.5\n" + b"x" * 5000


@pytest.mark.usefixtures("fake_extractor")
def test_build_into_newer_schema_is_refused(make_dataset, db_path: Path) -> None:
    MapDatabase.open(db_path).close()
    with sqlite3.connect(db_path) as conn:
        conn.execute("UPDATE meta SET value = '7' WHERE key = 'schema_version'")
    conn.close()
    result = build(make_dataset(2), db_path)
    assert result.exit_code == 1
    assert "schema version 7, newer than this toploc supports" in result.stderr
    assert table_counts(db_path)["places"] == 0


def test_unknown_detector_is_a_usage_error(make_dataset, db_path: Path) -> None:
    result = build(make_dataset(1), db_path, "--detector", "sift,orb")
    assert result.exit_code == 2
    assert "unknown detector 'orb'" in result.stderr
    result = build(make_dataset(1), db_path, "--detector", "sift,sift-lower")
    assert result.exit_code == 2 and "each detector may appear once" in result.stderr


@pytest.mark.usefixtures("fake_extractor")
def test_full_disk_and_locked_database_during_build(
    make_dataset, db_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    dataset = make_dataset(6)
    assert build(make_dataset(2, name="small"), db_path).exit_code == 0
    before = table_counts(db_path)

    class FullDisk(MapDatabase):
        @classmethod
        def open(cls, path: Path | str, **kwargs: object) -> MapDatabase:  # type: ignore[override]
            map_db = MapDatabase.open(path, **kwargs)  # type: ignore[arg-type]
            pages = map_db.db.execute("PRAGMA page_count").fetchone()[0]
            map_db.db.execute(f"PRAGMA max_page_count = {pages}")
            return map_db

    class ImpatientLock(MapDatabase):
        @classmethod
        def open(cls, path: Path | str, **kwargs: object) -> MapDatabase:  # type: ignore[override]
            return MapDatabase.open(path, busy_timeout_s=0.05, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(map_cli, "MapDatabase", FullDisk)
    full = build(dataset, db_path, "--workers", "0")
    assert full.exit_code == 1
    assert "Error: no space left for" in full.stderr and "map.db" in full.stderr
    monkeypatch.setattr(map_cli, "MapDatabase", ImpatientLock)
    holder = sqlite3.connect(db_path, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")
    try:
        locked = run("connect", "kitchen", "hall", "--db", db_path)
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    assert locked.exit_code == 1 and "is locked by another process" in locked.stderr
    assert table_counts(db_path) == before
    assert_consistent(db_path, detectors=1)


@pytest.mark.usefixtures("fake_extractor")
def test_add_connect_info_and_export(tmp_path: Path, db_path: Path) -> None:
    pano = write_image(tmp_path / "p1.png", 11)
    other = write_image(tmp_path / "p2.png", 12)
    added = run("add", pano, "--db", db_path, "--room", "lab", "--x-m", "1", "--y-m", "2",
                "--heading-deg", "45")  # fmt: skip
    assert added.exit_code == 0 and added.stdout.startswith("added p1.png: room 'lab'")
    assert run("add", other, "--db", db_path, "--room", "corridor").exit_code == 0
    again = run("add", pano, "--db", db_path, "--room", "lab")
    assert again.exit_code == 0 and "skipped p1.png: already in the map as place 1" in again.stdout

    assert run("connect", "lab", "corridor", "--db", db_path).stdout == (
        "connected lab <-> corridor\n"
    )
    assert "already connected" in run("connect", "corridor", "lab", "--db", db_path).stdout

    text = run("info", "--db", db_path)
    assert text.exit_code == 0
    assert "2 rooms, 2 places" in text.stdout and "  lab: 1 places" in text.stdout
    assert "fingerprints: sift 2" in text.stdout and "corridor <-> lab" in text.stdout
    info = json.loads(run("info", "--db", db_path, "--json").stdout)
    assert info["n_places"] == 2 and info["edges"] == [["corridor", "lab"]]
    assert info["fingerprints_per_detector"] == {"sift": 2}
    assert info["file_size_bytes"] > 0

    out = tmp_path / "rooms.graphml"
    exported = run("export", "--db", db_path, "--graphml", out)
    assert exported.exit_code == 0 and "2 rooms, 1 edges" in exported.stdout
    assert set(nx.read_graphml(out).edges) in ({("lab", "corridor")}, {("corridor", "lab")})

    with MapDatabase.open(db_path) as map_db:
        (lab,) = map_db.places("lab")
        assert (lab.x_m, lab.y_m, lab.heading_deg) == (1.0, 2.0, 45.0)


@pytest.mark.usefixtures("fake_extractor")
def test_add_errors(tmp_path: Path, db_path: Path) -> None:
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"garbage")
    result = run("add", bad, "--db", db_path, "--room", "lab")
    assert result.exit_code == 1 and "bad.png" in result.stderr and "corrupt" in result.stderr
    half = run("add", bad, "--db", db_path, "--room", "lab", "--x-m", "1")
    assert half.exit_code == 2 and "both --x-m and --y-m" in half.stderr
    assert not db_path.exists()  # refused before a place was written: no empty map is left


def test_connect_unknown_room_and_missing_database(filled_map: MapDatabase, tmp_path) -> None:
    filled_map.close()
    before = table_counts(filled_map.path)
    result = run("connect", "kitchen", "cellar", "--db", filled_map.path)
    assert result.exit_code == 1 and "unknown room 'cellar'" in result.stderr
    assert table_counts(filled_map.path) == before
    missing = tmp_path / "missing.db"
    for args in (("connect", "a", "b"), ("info",), ("export", "--graphml", tmp_path / "g")):
        result = run(*args, "--db", missing)
        assert result.exit_code == 1 and "missing.db does not exist" in result.stderr
    assert not missing.exists()


def _real_extraction_available() -> bool:
    try:
        importlib.import_module("localizer.features")
        importlib.import_module("localizer.panorama_io")
    except ImportError:
        return False
    return True


@pytest.mark.skipif(not _real_extraction_available(), reason="localizer.features unavailable")
def test_build_with_real_extraction(tmp_path: Path, db_path: Path) -> None:
    folder = tmp_path / "real"
    lines = ["image,room,x_m,y_m,heading_deg"]
    for i in range(3):
        write_image(folder / f"p{i}.png", 100 + i, size_px=(240, 48))
        lines.append(f"p{i}.png,room{i % 2},{i},0,0")
    (folder / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\ntruncated")
    lines.append("broken.png,room0,,,")
    (folder / "manifest.csv").write_text("\n".join(lines) + "\n")
    result = build(folder, db_path, "--workers", "2", "--detector", "sift,mser")
    assert result.exit_code == 1, result.output
    assert "broken.png" in result.stderr and "added 3, skipped 0, failed 1" in result.stdout
    with MapDatabase.open(db_path, readonly=True) as map_db:
        counts = map_db.fingerprint_counts()
        assert counts == {"mser": 3, "sift": 3}
        (place,) = [p for p in map_db.places() if p.source.endswith("p0.png")]
        assert (place.image_width_px, place.image_height_px) == (240, 48)
    assert_consistent(db_path)


@pytest.mark.skipif(not _real_extraction_available(), reason="localizer.features unavailable")
def test_a_map_read_at_a_chosen_width_keeps_it_and_refuses_another(tmp_path, db_path) -> None:
    photos = tmp_path / "photos"
    write_image(photos / "lab" / "a.png", 1, size_px=(1200, 600))  # 2:1, a sphere
    write_image(photos / "lab" / "b.png", 2, size_px=(1200, 600))
    first = build(photos, db_path, "--workers", "0", "--read-width", "1200", "--no-calibrate")
    assert first.exit_code == 0, first.output
    with MapDatabase.open(db_path, readonly=True) as map_db:
        assert map_db.stored_params()["max_width_px"] == 1200  # not the sphere's default 1024
    write_image(photos / "lab" / "c.png", 3, size_px=(1200, 600))
    other = build(photos, db_path, "--workers", "0", "--read-width", "1024", "--no-calibrate")
    assert other.exit_code == 2
    assert "--read-width 1024: the map's places were read at up to 1200 px wide" in other.output
    follows = build(photos, db_path, "--workers", "0", "--no-calibrate")
    assert "added 1, skipped 2" in follows.stdout
    with sqlite3.connect(db_path) as conn:
        rows = conn.execute("SELECT params_json FROM fingerprints").fetchall()
    assert {json.loads(params)["max_width_px"] for (params,) in rows} == {1200}


def test_info_names_the_rooms_with_one_place(filled_map: MapDatabase, db_path: Path) -> None:
    text = run("info", "--db", db_path).stdout
    (hint,) = [line for line in text.splitlines() if "one place only" in line]
    assert "hall" in hint and "kitchen" not in hint  # the kitchen has two places


@pytest.mark.skipif(not _real_extraction_available(), reason="localizer.features unavailable")
def test_add_refuses_a_four_by_three_photo_naming_it(tmp_path: Path, db_path: Path) -> None:
    photo = write_image(tmp_path / "photo.png", 1, size_px=(640, 480))
    result = run("add", photo, "--db", db_path, "--room", "lab", "--no-calibrate")
    assert result.exit_code == 1
    assert f"{photo}: 640x480 px (1.33:1) is not a 360° panorama" in result.output
    assert result.output.count(str(photo)) == 1
    assert "--camera equirect or --camera cylinder" in result.output


@pytest.mark.skipif(not _real_extraction_available(), reason="localizer.features unavailable")
def test_a_refused_first_add_leaves_no_empty_map_behind(tmp_path: Path, db_path: Path) -> None:
    photo = write_image(tmp_path / "photo.png", 1, size_px=(640, 480))
    result = run("add", photo, "--db", db_path, "--room", "lab", "--no-calibrate")
    assert result.exit_code == 1
    assert list(tmp_path.iterdir()) == [photo]


@pytest.mark.skipif(not _real_extraction_available(), reason="localizer.features unavailable")
def test_a_refused_add_into_an_existing_map_keeps_the_map(tmp_path: Path, db_path: Path) -> None:
    with MapDatabase.open(db_path) as map_db:
        map_db.add_room("lab")
    photo = write_image(tmp_path / "photo.png", 1, size_px=(640, 480))
    result = run("add", photo, "--db", db_path, "--room", "lab", "--no-calibrate")
    assert result.exit_code == 1
    with MapDatabase.open(db_path, readonly=True) as map_db:
        assert [room.name for room in map_db.rooms()] == ["lab"]
        assert map_db.places() == []


@pytest.mark.skipif(not _real_extraction_available(), reason="localizer.features unavailable")
def test_add_takes_a_photo_whose_camera_is_named(tmp_path: Path, db_path: Path) -> None:
    photo = write_image(tmp_path / "photo.png", 1, size_px=(640, 480))
    result = run(
        "add", photo, "--db", db_path, "--room", "lab", "--camera", "cylinder", "--no-calibrate"
    )
    assert result.exit_code == 0, result.output
    with MapDatabase.open(db_path, readonly=True) as map_db:
        assert map_db.stored_params()["camera"] == "cylinder"


@pytest.mark.skipif(not _real_extraction_available(), reason="localizer.features unavailable")
def test_add_takes_a_two_to_one_image_as_a_sphere(tmp_path: Path, db_path: Path) -> None:
    sphere = write_image(tmp_path / "sphere.png", 1, size_px=(1024, 512))
    result = run("add", sphere, "--db", db_path, "--room", "lab", "--no-calibrate")
    assert result.exit_code == 0, result.output
    with MapDatabase.open(db_path, readonly=True) as map_db:
        assert map_db.stored_params()["camera"] == "equirect"


@pytest.mark.skipif(not _real_extraction_available(), reason="localizer.features unavailable")
def test_build_fails_a_four_by_three_photo_and_adds_the_panoramas(tmp_path, db_path) -> None:
    photos = tmp_path / "photos"
    write_image(photos / "lab" / "sphere.png", 1, size_px=(1024, 512))
    write_image(photos / "lab" / "cylinder.png", 2, size_px=(512, 96))
    write_image(photos / "lab" / "photo.png", 3, size_px=(640, 480))
    result = build(photos, db_path, "--workers", "0", "--no-calibrate", "--detector", "sift")
    assert result.exit_code == 1
    assert "added 2, skipped 0, failed 1" in result.stdout
    assert "photo.png: 640x480 px (1.33:1) is not a 360° panorama" in result.stderr


@pytest.mark.usefixtures("fake_extractor")
def test_build_stores_sift_unless_told_and_a_repeated_detector_adds_mser(make_dataset, tmp_path):
    dataset = make_dataset(2)
    for db_path, extra, expected in [
        (tmp_path / "default.db", (), {"sift": 2}),
        (
            tmp_path / "both.db",
            ("--detector", "sift", "--detector", "mser"),
            {"mser": 2, "sift": 2},
        ),
    ]:
        assert build(dataset, db_path, "--workers", "0", *extra).exit_code == 0
        with MapDatabase.open(db_path, readonly=True) as map_db:
            assert map_db.fingerprint_counts() == expected


@pytest.mark.usefixtures("fake_extractor")
def test_build_prints_its_result_before_the_calibration_in_plain_words(make_dataset, db_path):
    result = build(make_dataset(4), db_path, "--workers", "0")
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert "added 4, skipped 0, failed 0" in lines[0]
    assert lines[1].startswith("sift: calibrat")
    assert "log ratio" not in result.stdout  # the formula: map info, or -v
    verbose = build(make_dataset(4), db_path.with_name("v.db"), "--workers", "0", "-v")
    assert "sift likelihood: log ratio" in verbose.stdout


@pytest.mark.usefixtures("fake_extractor")
def test_a_place_added_to_a_map_of_two_detectors_gets_both(make_dataset, tmp_path, db_path):
    both = ("--detector", "sift", "--detector", "mser")
    assert build(make_dataset(2), db_path, "--workers", "0", *both).exit_code == 0
    pano = write_image(tmp_path / "later.png", 21)
    added = run("add", pano, "--db", db_path, "--room", "kitchen", "--no-calibrate")
    assert added.exit_code == 0, added.output
    assert "sift 24, mser 24" in added.stdout
    assert_consistent(db_path, detectors=2)
