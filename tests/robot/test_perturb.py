"""Perturbed copies of a dataset (`toploc dataset perturb`): rolled, resized, under a condition,
their headings turned with the roll."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

from localizer.panorama_io import read_grey_image
from mapdb.dataset import read_edges, read_manifest
from robot.conditions import DEFAULT_CONDITION, get_condition
from robot.perturb import Perturbation, perturb_dataset, perturb_image, rolled_heading_deg
from toploc.commands.dataset import dataset


def panorama(seed: int, width_px: int = 128) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, (width_px // 2, width_px), dtype=np.uint8)


def write_source(folder: Path) -> Path:
    """Three panoramas in two rooms with poses, and the door between them."""
    rows = ["image,room,x_m,y_m,heading_deg"]
    for i, (room, heading) in enumerate((("hall", 10.0), ("hall", ""), ("kitchen", -170.0))):
        (folder / "img").mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(folder / "img" / f"p{i}.png"), panorama(i))
        rows.append(f"img/p{i}.png,{room},{i},0,{heading}")
    (folder / "manifest.csv").write_text("\n".join(rows) + "\n")
    (folder / "edges.csv").write_text("room_a,room_b\nhall,kitchen\n")
    return folder


def test_a_roll_alone_moves_the_columns_and_keeps_the_values() -> None:
    image = panorama(0)
    copy = perturb_image(image, 5, None, DEFAULT_CONDITION, np.random.default_rng(0))
    assert np.array_equal(copy, np.roll(image, 5, axis=1))


def test_a_resize_keeps_the_aspect() -> None:
    copy = perturb_image(panorama(0), 0, 256, DEFAULT_CONDITION, np.random.default_rng(0))
    assert copy.shape == (128, 256) and copy.dtype == np.uint8


def test_dim_light_darkens_the_copy() -> None:
    image = panorama(0)
    dim = perturb_image(image, 0, None, get_condition("dim"), np.random.default_rng(0))
    assert dim.mean() < 0.6 * image.mean()


@given(
    heading_deg=st.floats(-180, 180),
    column=st.integers(0, 359),
    roll_px=st.integers(-720, 720),
)
def test_a_landmark_keeps_its_world_direction_when_the_panorama_rolls(
    heading_deg: float, column: int, roll_px: int
) -> None:
    # columns run clockwise from the heading: a landmark at column c lies at heading - c degrees
    width_px = 360
    new_heading = rolled_heading_deg(heading_deg, roll_px, width_px)
    assert new_heading is not None
    new_column = (column + roll_px) % width_px
    before, after = heading_deg - column, new_heading - new_column
    assert (before - after + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-5)


def test_an_unknown_heading_stays_unknown() -> None:
    assert rolled_heading_deg(None, 10, 360) is None


def test_bad_perturbations_are_refused() -> None:
    with pytest.raises(ValueError, match="jpeg_quality"):
        Perturbation(jpeg_quality=0)
    with pytest.raises(ValueError, match="roll_deg"):
        Perturbation(roll_deg=float("nan"))


def test_the_copy_keeps_rooms_and_poses_turns_headings_and_keeps_the_door(tmp_path: Path) -> None:
    source = write_source(tmp_path / "src")
    manifest = perturb_dataset(
        source, tmp_path / "out", Perturbation(roll_deg=90.0, width_px=256), progress=False
    )
    rows = read_manifest(manifest.parent)
    assert [(r.room, r.x_m, r.heading_deg) for r in rows] == [
        ("hall", 0.0, 100.0),
        ("hall", 1.0, None),
        ("kitchen", 2.0, -80.0),
    ]
    assert read_grey_image(rows[0].path).shape == (128, 256)
    assert read_edges(manifest.parent) == [("hall", "kitchen")]


def test_the_same_seed_gives_the_same_copies(tmp_path: Path) -> None:
    source = write_source(tmp_path / "src")
    noisy = Perturbation(roll_deg=None, condition=get_condition("noisy"), jpeg_quality=None)
    first = perturb_dataset(source, tmp_path / "a", noisy, seed=3, progress=False)
    second = perturb_dataset(source, tmp_path / "b", noisy, seed=3, progress=False)
    for a, b in zip(read_manifest(first.parent), read_manifest(second.parent), strict=True):
        assert a.heading_deg == b.heading_deg
        assert np.array_equal(read_grey_image(a.path), read_grey_image(b.path))


def test_a_room_subset_drops_the_doors_to_the_rooms_left_out(tmp_path: Path) -> None:
    source = write_source(tmp_path / "src")
    manifest = perturb_dataset(
        source, tmp_path / "out", Perturbation(), rooms=["hall"], progress=False
    )
    assert {r.room for r in read_manifest(manifest.parent)} == {"hall"}
    assert not (manifest.parent / "edges.csv").exists()


def test_the_command_copies_room_folders_as_jpeg(tmp_path: Path) -> None:
    photos = tmp_path / "photos"
    (photos / "lab").mkdir(parents=True)
    cv2.imwrite(str(photos / "lab" / "R0010001.JPG"), panorama(1))
    out = tmp_path / "out"
    args = [str(photos), str(out), "--random-roll", "--condition", "dim_noisy", "--no-progress"]
    result = CliRunner().invoke(dataset, ["perturb", *args])
    assert result.exit_code == 0, result.output
    assert "wrote 1 panoramas" in result.output
    (row,) = read_manifest(out)
    assert row.room == "lab" and row.image.endswith(".jpg")


def test_the_command_names_a_missing_room_and_a_corrupt_image(tmp_path: Path) -> None:
    source = write_source(tmp_path / "src")
    missing = CliRunner().invoke(dataset, ["perturb", str(source), str(tmp_path / "o1"),
                                           "--rooms", "attic", "--no-progress"])  # fmt: skip
    assert missing.exit_code == 1 and "has no room attic" in missing.output
    (source / "img" / "p1.png").write_bytes(b"\x89PNG\r\n\x1a\ntruncated")
    corrupt = CliRunner().invoke(dataset, ["perturb", str(source), str(tmp_path / "o2"),
                                           "--no-progress"])  # fmt: skip
    assert corrupt.exit_code == 1 and "p1.png" in corrupt.output


def test_a_copy_into_its_own_source_is_refused_before_anything_is_deleted(tmp_path: Path) -> None:
    source = write_source(tmp_path / "src")
    with pytest.raises(ValueError, match="holds images of"):
        perturb_dataset(source, source, Perturbation(), overwrite=True, progress=False)
    assert len(read_manifest(source)) == 3 and (source / "edges.csv").exists()


def test_no_rooms_is_refused(tmp_path: Path) -> None:
    source = write_source(tmp_path / "src")
    with pytest.raises(ValueError, match="none given"):
        perturb_dataset(source, tmp_path / "out", Perturbation(), rooms=[], progress=False)


def test_a_fixed_and_a_random_roll_together_are_refused(tmp_path: Path) -> None:
    source = write_source(tmp_path / "src")
    args = [str(source), str(tmp_path / "out"), "--roll-deg", "90", "--random-roll"]
    result = CliRunner().invoke(dataset, ["perturb", *args])
    assert result.exit_code == 2 and "not both" in result.output
