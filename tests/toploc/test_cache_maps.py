"""toploc's own cached world maps (the demo's, `sim kidnap`'s) are made again when an older
toploc made them or they are not as toploc built them; a user's map never is."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from filelock import FileLock, Timeout

from localizer.cameras import CameraSpec
from localizer.features import extract_with_camera
from localizer.likelihood import RatioLikelihood
from mapdb.database import MapDatabase
from mapdb.records import NewPlace
from toploc import maps
from toploc.maps import (
    CACHE_LOCK_NAME,
    changed_cache_map,
    ensure_world_map,
    outdated_cache_map,
)


def panorama(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (64, 256), dtype=np.uint8)


def old_fingerprint(seed: int):
    """A fingerprint as toploc stored it before the contrast equalisation."""
    fingerprint = extract_with_camera(panorama(seed), CameraSpec(), "sift", clahe_clip_limit=0.0)
    params = {k: v for k, v in fingerprint.params.items() if not k.startswith("clahe_")}
    return replace(fingerprint, params=params)


def map_with(db_path: Path, fingerprint) -> Path:
    with MapDatabase.open(db_path) as map_db:
        map_db.add_place(NewPlace("hall", "ab" * 32, "a.png"), [fingerprint])
    return db_path


def test_a_map_extracted_as_this_version_does_is_current(tmp_path: Path) -> None:
    fresh = extract_with_camera(panorama(0), CameraSpec(), "sift")
    assert outdated_cache_map(map_with(tmp_path / "m.db", fresh), "sift") is None


def test_a_map_extracted_before_the_equalisation_is_outdated(tmp_path: Path) -> None:
    db_path = map_with(tmp_path / "m.db", old_fingerprint(0))
    assert outdated_cache_map(db_path, "sift") == "its places were extracted with other settings"


def test_a_likelihood_on_raw_inliers_is_outdated(tmp_path: Path) -> None:
    db_path = map_with(tmp_path / "m.db", extract_with_camera(panorama(0), CameraSpec(), "sift"))
    legacy = RatioLikelihood(count="inliers").to_json()
    with MapDatabase.open(db_path) as map_db:
        map_db.set_likelihood("sift", legacy)
    assert outdated_cache_map(db_path, "sift") == "its likelihood reads another count"


def test_an_outdated_cached_world_map_is_made_again(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "square-0"
    dataset = folder / "dataset"
    (dataset / "images").mkdir(parents=True)
    rows = ["image,room,x_m,y_m,heading_deg"]
    for i, room in enumerate(("hall", "hall", "lab", "lab")):
        cv2.imwrite(str(dataset / "images" / f"p{i}.png"), panorama(i))
        rows.append(f"images/p{i}.png,{room},{i},0,0")
    (dataset / "manifest.csv").write_text("\n".join(rows) + "\n")
    map_with(folder / "map.db", old_fingerprint(9))
    (folder / "built-sift").touch()

    db_path = ensure_world_map("square", root=tmp_path, progress=False)
    assert "made by an older toploc" in capsys.readouterr().err
    assert outdated_cache_map(db_path, "sift") is None
    with MapDatabase.open(db_path, readonly=True) as map_db:
        assert len(map_db.places()) == 4  # the dataset's, not the old map's one place
        likelihood = map_db.likelihood("sift")
    assert likelihood is not None and likelihood["count"] == "spread"


def square_dataset(folder: Path) -> Path:
    """A cached world's dataset of four random panoramas, two rooms."""
    dataset = folder / "dataset"
    (dataset / "images").mkdir(parents=True)
    rows = ["image,room,x_m,y_m,heading_deg"]
    for i, room in enumerate(("hall", "hall", "lab", "lab")):
        cv2.imwrite(str(dataset / "images" / f"p{i}.png"), panorama(i))
        rows.append(f"images/p{i}.png,{room},{i},0,0")
    (dataset / "manifest.csv").write_text("\n".join(rows) + "\n")
    return dataset


def test_a_cached_world_map_with_places_added_to_it_is_made_again(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    square_dataset(tmp_path / "square-0")
    db_path = ensure_world_map("square", root=tmp_path, progress=False)
    capsys.readouterr()
    with MapDatabase.open(db_path) as map_db:  # as `toploc map add --db <the cache's map>` does
        fresh = extract_with_camera(panorama(7), CameraSpec(), "sift")
        map_db.add_place(NewPlace("garage", "cd" * 32, "mine.png"), [fresh])

    assert ensure_world_map("square", root=tmp_path, progress=False) == db_path
    assert "not as toploc built it (it holds 5 places, its dataset 4)" in capsys.readouterr().err
    with MapDatabase.open(db_path, readonly=True) as map_db:
        assert sorted(room.name for room in map_db.rooms()) == ["hall", "lab"]


def test_a_cached_world_map_as_built_is_reused_without_a_word(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    square_dataset(tmp_path / "square-0")
    db_path = ensure_world_map("square", root=tmp_path, progress=False)
    capsys.readouterr()
    assert changed_cache_map(db_path, tmp_path / "square-0" / "dataset") is None
    assert ensure_world_map("square", root=tmp_path, progress=False) == db_path
    assert capsys.readouterr().err == ""


def test_a_cached_world_map_is_made_by_one_process_at_a_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    square_dataset(tmp_path / "square-0")
    build_map = maps.build_map
    held = []

    def build_map_checking_the_lock(*args, **kwargs):
        other = FileLock(tmp_path / "square-0" / CACHE_LOCK_NAME)  # as another process would
        with pytest.raises(Timeout):
            other.acquire(timeout=0)
        held.append(True)
        return build_map(*args, **kwargs)

    monkeypatch.setattr(maps, "build_map", build_map_checking_the_lock)
    ensure_world_map("square", root=tmp_path, progress=False)
    assert held == [True]
    other = FileLock(tmp_path / "square-0" / CACHE_LOCK_NAME)
    other.acquire(timeout=0)  # released once the map is made
    other.release()


def test_a_process_that_finds_the_map_being_made_says_it_waits(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    square_dataset(tmp_path / "square-0")
    db_path = ensure_world_map("square", root=tmp_path, progress=False)
    capsys.readouterr()
    other = FileLock(tmp_path / "square-0" / CACHE_LOCK_NAME)
    other.acquire()
    released = False

    def release_when_asked_to_wait(message: str) -> None:
        nonlocal released
        if "another toploc is making this map; waiting for it" in message and not released:
            released = True
            other.release()  # the other process finishes: the wait ends

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(maps, "_said_waiting", release_when_asked_to_wait)
        assert ensure_world_map("square", root=tmp_path, progress=False) == db_path
    assert released
