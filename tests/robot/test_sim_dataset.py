"""Rendering a panorama dataset to a folder, from Python and from the ``toploc dataset`` CLI."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from localizer.robot_protocol import Pose2D
from mapdb.dataset import MANIFEST_COLUMNS, read_manifest
from robot.conditions import get_condition
from robot.dataset import render_dataset
from robot.render import PanoramaCamera, render_panorama
from robot.scene import build_scene
from robot.world import capture_places
from robot.worlds import make_world
from toploc.commands.dataset import dataset

TINY = PanoramaCamera(128, 32)


def render_tiny(out: Path, **kwargs: object) -> Path:
    options: dict[str, object] = {"spacing_m": 1.0, "camera": TINY, "progress": False}
    options.update(kwargs)
    return render_dataset(out, "square", **options)  # type: ignore[arg-type]


def test_manifest_rows_match_images(tmp_path: Path) -> None:
    manifest = render_tiny(tmp_path / "ds", heading_deg=30.0)
    assert manifest == tmp_path / "ds" / "manifest.csv"
    with manifest.open() as f:
        assert tuple(next(csv.reader(f))) == MANIFEST_COLUMNS
    rows = read_manifest(manifest.parent)
    world = make_world("square")
    places = capture_places(world, 1.0)
    assert [(r.room, r.x_m, r.y_m) for r in rows] == [(p.room, p.x_m, p.y_m) for p in places]
    assert len({r.image for r in rows}) == len(rows)
    scene = build_scene(world)
    for row in rows:
        image = cv2.imread(str(manifest.parent / row.image), cv2.IMREAD_COLOR)
        assert image.shape == (32, 128, 3)
        assert row.heading_deg == 30.0
    row = rows[1]
    pose = world.building_pose(row.room, Pose2D(row.x_m, row.y_m, math.radians(30.0)))
    expected = render_panorama(scene, pose, TINY, get_condition("default"), seed=(0, 2, 1))
    written = cv2.imread(str(manifest.parent / row.image), cv2.IMREAD_COLOR)
    assert np.array_equal(cv2.cvtColor(written, cv2.COLOR_BGR2RGB), expected)


def test_a_building_dataset_lists_the_rooms_joined_by_doors(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    render_dataset(out, "building", spacing_m=4.0, camera=TINY, progress=False)
    with (out / "edges.csv").open() as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["room_a", "room_b"]
    doors = make_world("building").doors
    assert {tuple(r) for r in rows[1:]} == {tuple(sorted((d.room_a, d.room_b))) for d in doors}


def test_random_headings_and_grey(tmp_path: Path) -> None:
    rows = read_manifest(render_tiny(tmp_path / "ds", heading_deg=None, grey=True, seed=2).parent)
    headings = [r.heading_deg for r in rows]
    assert all(h is not None and -180 < h <= 180 for h in headings)
    assert len(set(headings)) == len(headings)
    image = cv2.imread(str(tmp_path / "ds" / rows[0].image), cv2.IMREAD_UNCHANGED)
    assert image.shape == (32, 128)


def test_bad_arguments_name_the_bad_value(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown world 'moon'"):
        render_dataset(tmp_path / "a", "moon", progress=False)
    with pytest.raises(ValueError, match="unknown condition 'rain'"):
        render_dataset(tmp_path / "a", "square", condition="rain", progress=False)
    for spacing in (0.0, -0.5):
        with pytest.raises(ValueError, match=f"spacing_m must be positive, got {spacing}"):
            render_dataset(tmp_path / "a", "square", spacing_m=spacing, progress=False)
    assert not (tmp_path / "a").exists()


def test_non_empty_folder_needs_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    render_tiny(out, spacing_m=2.0)
    with pytest.raises(ValueError, match="is not empty"):
        render_tiny(out)
    manifest = render_tiny(out, overwrite=True)
    rows = read_manifest(manifest.parent)
    assert sorted(p.name for p in (out / "images").iterdir()) == sorted(
        Path(r.image).name for r in rows
    )


def test_cli_render(tmp_path: Path) -> None:
    out = tmp_path / "cli"
    args = ["render", str(out), "--world", "square", "--spacing", "1.5", "--width", "64"]
    result = CliRunner().invoke(dataset, [*args, "--height", "16", "--condition", "dim"])
    assert result.exit_code == 0, result.output
    assert str(out / "manifest.csv") in result.output
    rows = read_manifest(out)
    assert f"square: {len(rows)} places" in result.output
    again = CliRunner().invoke(dataset, args)
    assert again.exit_code != 0 and "not empty" in again.output
    bad = CliRunner().invoke(dataset, ["render", str(tmp_path / "x"), "--world", "attic"])
    assert bad.exit_code != 0 and "attic" in bad.output
