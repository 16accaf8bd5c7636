"""Homing and alignment on a tiny rendered dataset, and the ``toploc eval`` commands.

The bearing geometry of rendered landmarks (a landmark at a known position lands within a pixel
of its predicted column) is tested in tests/robot/test_sim_render.py.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from homing.alv import HomingError
from localizer.panorama_io import PanoramaError
from robot.dataset import render_dataset
from robot.render import PanoramaCamera
from toploc.cli import main
from toploc.evaluation.homing import (
    COMPASSES,
    EvaluationError,
    FeatureSettings,
    PairCache,
    evaluate_alignment,
    evaluate_homing,
    extract_fingerprints,
    load_places,
    same_room_pairs,
)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Nine 512x96 panoramas of the square room, 1 m apart, with seeded random headings."""
    out = tmp_path_factory.mktemp("square")
    render_dataset(
        out, "square", spacing_m=1.0, camera=PanoramaCamera(512, 96), heading_deg=None,
        progress=False,
    )  # fmt: skip
    return out


@pytest.fixture(scope="module")
def fingerprints(dataset: Path) -> dict[str, list]:
    places = load_places(dataset)
    return {
        detector: extract_fingerprints([p.path for p in places], FeatureSettings(detector))
        for detector in ("sift", "mser")
    }


def test_same_room_pairs_never_cross_rooms() -> None:
    pairs = same_room_pairs(["a", "b", "a", "a", "b"])
    assert {tuple(p) for p in pairs.tolist()} == {
        (0, 2), (0, 3), (2, 0), (2, 3), (3, 0), (3, 2), (1, 4), (4, 1),
    }  # fmt: skip


@pytest.mark.parametrize("detector", ["sift", "mser"])
@pytest.mark.parametrize(
    "method",
    ["thesis", "best", "alv-compass", "matched-vote", "pose-above-floor", "pose-compass"],
)
def test_every_ordered_pair_is_evaluated(dataset, fingerprints, detector, method) -> None:
    places = load_places(dataset)
    run = evaluate_homing(places, fingerprints[detector], method)
    n = len(places)
    assert run.stats.n == n
    assert run.stats.n_pairs == n * (n - 1) == len(run.errors_deg)
    finite = run.errors_deg[np.isfinite(run.errors_deg)]
    assert np.all((finite >= 0) & (finite <= 180))
    assert run.stats.best_home in {p.image for p in places}


def test_best_homes_without_headings_better_than_chance(dataset, fingerprints) -> None:
    # Headings are random here: a home vector in the wrong frame would average ~90 deg.
    run = evaluate_homing(load_places(dataset), fingerprints["sift"], "best")
    assert run.stats.mean_deg < 60.0
    assert run.stats.under_90 > 0.8


def test_alignment_matched_compass_recovers_random_headings(dataset, fingerprints) -> None:
    places = load_places(dataset)
    run = evaluate_alignment(places, fingerprints["sift"], bin_width_m=1.0)
    n = len(places)
    assert set(run.errors_deg) == set(COMPASSES)
    assert all(len(e) == n * (n - 1) for e in run.errors_deg.values())
    assert sum(b.n for b in run.bins["matched"]) == n * (n - 1)
    assert np.nanmedian(run.errors_deg["matched"]) < 20.0


def _copy(dataset: Path, tmp_path: Path) -> Path:
    target = tmp_path / "copy"
    shutil.copytree(dataset, target)
    return target


def test_bad_input_names_the_file(dataset: Path, tmp_path: Path) -> None:
    with pytest.raises(Exception, match="does not exist"):
        load_places(tmp_path / "nowhere")
    copy = _copy(dataset, tmp_path)
    manifest = copy / "manifest.csv"
    header = manifest.read_text().splitlines()[0]
    manifest.write_text(header + "\n")
    with pytest.raises(EvaluationError, match=r"manifest\.csv: no rows with a position"):
        load_places(copy)
    broken = copy / "images" / "broken.png"
    broken.write_bytes(b"not an image at all")
    with pytest.raises(PanoramaError, match=r"broken\.png"):
        extract_fingerprints([broken], FeatureSettings("sift"))


def test_missing_headings_and_unknown_method(dataset, fingerprints, tmp_path: Path) -> None:
    copy = _copy(dataset, tmp_path)
    manifest = copy / "manifest.csv"
    lines = manifest.read_text().splitlines()
    lines[1] = ",".join([*lines[1].split(",")[:4], ""])
    manifest.write_text("\n".join(lines) + "\n")
    places = load_places(copy)
    with pytest.raises(EvaluationError, match="lack heading_deg"):
        evaluate_homing(places, fingerprints["sift"], "thesis")
    with pytest.raises(EvaluationError, match="unknown method"):
        evaluate_homing(places, fingerprints["sift"], "magic")


def test_cli_homing_writes_json_and_plot(dataset: Path, tmp_path: Path) -> None:
    out_json, out_png = tmp_path / "h.json", tmp_path / "h.png"
    result = CliRunner().invoke(
        main,
        ["eval", "homing", str(dataset), "--detector", "mser", "--rows", "lower", "--workers",
         "0", "--no-progress", "--json", str(out_json), "--plot", str(out_png)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "score" in result.output and "best home" in result.output
    record = json.loads(out_json.read_text())
    keys = ("detector", "method", "n", "mean_deg", "median_deg", "std_deg", "score")
    assert set(keys) | {"best_home", "under_90", "under_10"} <= set(record)
    assert record["detector"] == "mser" and record["n"] == 9
    assert out_png.read_bytes()[:4] == b"\x89PNG"


def test_cli_homing_reads_the_images_as_given_with_clahe_clip_zero(dataset: Path, tmp_path: Path):
    out_json = tmp_path / "h.json"
    result = CliRunner().invoke(
        main,
        ["eval", "homing", str(dataset), "--clahe-clip", "0", "--workers", "0", "--no-progress",
         "--json", str(out_json)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "clahe=0" in result.output and json.loads(out_json.read_text())["clahe_clip"] == 0.0


def test_cli_homing_refuses_a_clip_limit_that_is_not_a_number(dataset: Path) -> None:
    result = CliRunner().invoke(main, ["eval", "homing", str(dataset), "--clahe-clip", "nan"])
    assert result.exit_code == 2 and "--clahe-clip" in result.output and "finite" in result.output


def test_cli_align_prints_bins(dataset: Path, tmp_path: Path) -> None:
    out_png = tmp_path / "a.png"
    result = CliRunner().invoke(
        main,
        ["eval", "align", str(dataset), "--workers", "0", "--no-progress", "--bin-m", "1",
         "--plot", str(out_png)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "histogram" in result.output and "matched" in result.output
    assert out_png.is_file()


@pytest.mark.parametrize("command", ["homing", "align"])
def test_cli_bad_input_is_one_line_error(dataset: Path, tmp_path: Path, command: str) -> None:
    runner = CliRunner()
    missing = runner.invoke(main, ["eval", command, str(tmp_path / "nowhere"), "--no-progress"])
    assert missing.exit_code == 1
    assert missing.output.startswith("Error: ") and "nowhere" in missing.output
    copy = _copy(dataset, tmp_path)
    (copy / "images" / "square_000.png").write_bytes(b"garbage")
    broken = runner.invoke(main, ["eval", command, str(copy), "--workers", "0", "--no-progress"])
    assert broken.exit_code == 1
    assert broken.output.startswith("Error: ") and "square_000.png" in broken.output
    assert len(broken.output.strip().splitlines()) == 1


def test_pairs_without_matches_fall_back_to_the_compass_alv(dataset, fingerprints) -> None:
    # Identical descriptors never pass the ratio test: no pair has a match.
    from dataclasses import replace

    blind = [replace(f, descriptors=np.zeros_like(f.descriptors)) for f in fingerprints["sift"]]
    places = load_places(dataset)
    best = evaluate_homing(places, blind, "best")
    compass = evaluate_homing(places, blind, "alv-compass")
    assert best.stats.n_failed == 0
    np.testing.assert_allclose(best.errors_deg, compass.errors_deg)


@pytest.mark.parametrize("projection", ["cylinder", "equirect"])
def test_pose_translation_points_home_on_renders(projection: str) -> None:
    """The sign convention on rendered panoramas at known poses: the verified translation of
    the pair (query here, place at home) points from here to home in the current robot frame."""
    import math

    from localizer.cameras import CameraSpec
    from localizer.features import extract_with_camera
    from localizer.matching import match_descriptors
    from localizer.robot_protocol import Pose2D
    from localizer.verification import home_direction_rad, verify
    from robot.render import render_panorama
    from robot.scene import build_scene
    from robot.worlds import make_world

    world = make_world("square")
    scene = build_scene(world)
    height = 192 if projection == "cylinder" else 256
    camera = PanoramaCamera(512, height, projection=projection)  # type: ignore[arg-type]
    room = world.room_names[0]
    here = world.building_pose(room, Pose2D(1.0, 1.2, 0.7))
    home = world.building_pose(room, Pose2D(2.6, 2.1, -1.9))
    fp_here, fp_home = (
        extract_with_camera(render_panorama(scene, pose, camera, grey=True), CameraSpec())
        for pose in (here, home)
    )
    assert fp_here.params["camera"] == projection
    pairs = match_descriptors(fp_here.descriptors, fp_home.descriptors)
    result = verify(fp_here.rays(), fp_home.rays(), pairs)
    assert result.inliers >= 10
    truth = math.atan2(home.y_m - here.y_m, home.x_m - here.x_m) - here.heading_rad
    error = math.remainder(home_direction_rad(result) - truth, 2 * math.pi)
    # the sign is what this checks (a flipped one is 180 deg off); the precision of one pair
    # depends on which features are found: 0.0 / 0.3 deg (cylinder / equirect) on the image as
    # given, 4.1 / 0.1 deg equalised (the product's extraction since CLAHE)
    assert abs(math.degrees(error)) < 10.0


def test_pose_method_homes_and_falls_back(dataset, fingerprints) -> None:
    places = load_places(dataset)
    run = evaluate_homing(places, fingerprints["sift"], "pose")
    n = len(places)
    assert run.stats.n_pairs == n * (n - 1) and run.stats.n_failed == 0
    # random headings: a direction in the wrong frame would average ~90 deg; where the pose
    # holds it is precise (one pair in 20 or so flips on these 512x96 renders)
    assert run.stats.median_deg < 5.0 and run.stats.mean_deg < 30.0
    assert run.stats.under_90 > 0.9
    # no match anywhere: verification finds no geometry, so the pose method is matched-alv's
    # own fallback, the compass ALV
    from dataclasses import replace

    blind = [replace(f, descriptors=np.zeros_like(f.descriptors)) for f in fingerprints["sift"]]
    pose = evaluate_homing(places, blind, "pose")
    compass = evaluate_homing(places, blind, "alv-compass")
    np.testing.assert_allclose(pose.errors_deg, compass.errors_deg)


def test_methods_share_one_cache(dataset, fingerprints) -> None:
    places = load_places(dataset)
    cache = PairCache(fingerprints["sift"])
    a = evaluate_homing(places, fingerprints["sift"], "pose", cache=cache)
    b = evaluate_homing(places, fingerprints["sift"], "pose")
    np.testing.assert_allclose(a.errors_deg, b.errors_deg)
    assert cache.matches(0, 1).shape[1] == 2
    np.testing.assert_array_equal(cache.matches(1, 0), cache.matches(0, 1)[:, ::-1])


@pytest.fixture(scope="module")
def equirect_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four 512x256 equirectangular panoramas of the square room, 1.5 m apart."""
    out = tmp_path_factory.mktemp("square-eq")
    camera = PanoramaCamera(512, 256, projection="equirect")
    render_dataset(out, "square", spacing_m=1.5, camera=camera, heading_deg=None, progress=False)
    return out


def test_equirect_images_are_read_as_spheres(equirect_dataset: Path) -> None:
    """A 2:1 image is extracted on the equirectangular model (its elevation limits and band are
    elevations of the sphere, not of a cylinder), unless ``--camera cylinder`` says otherwise."""
    from homing.cameras import Equirect

    places = load_places(equirect_dataset)
    auto = extract_fingerprints([places[0].path], FeatureSettings("sift"))[0]
    band = extract_fingerprints([places[0].path], FeatureSettings("sift", band_deg=10.0))[0]
    lower = extract_fingerprints([places[0].path], FeatureSettings("sift", rows="lower"))[0]
    forced = extract_fingerprints([places[0].path], FeatureSettings("sift", "cylinder"))[0]
    assert auto.params["camera"] == "equirect" and forced.params["camera"] == "cylinder"
    sphere = Equirect(auto.image_width_px, auto.image_height_px)
    elevations = np.rad2deg(sphere.elevation_rad(auto.keypoints_xy[:, 1]))
    assert elevations.min() >= -50.0 and elevations.max() <= 60.0  # the sphere's defaults
    assert np.all(np.abs(np.rad2deg(sphere.elevation_rad(band.keypoints_xy[:, 1]))) <= 10.0)
    assert 0 < band.n < auto.n
    assert np.all(lower.keypoints_xy[:, 1] >= sphere.horizon_px) and 0 < lower.n < auto.n


def test_the_evaluation_equalises_as_the_product_unless_told_not_to(dataset: Path) -> None:
    path = load_places(dataset)[0].path
    (default,) = extract_fingerprints([path], FeatureSettings("sift"))
    (as_given,) = extract_fingerprints([path], FeatureSettings("sift", clahe_clip_limit=0.0))
    assert default.params["clahe_clip_limit"] == 2.0 and as_given.params["clahe_clip_limit"] == 0.0
    assert default.n != as_given.n


def test_cli_homing_on_equirect_with_several_methods(equirect_dataset: Path, tmp_path) -> None:
    out_json = tmp_path / "h.json"
    result = CliRunner().invoke(
        main,
        ["eval", "homing", str(equirect_dataset), "--workers", "0", "--no-progress",
         "--method", "thesis", "--method", "best", "--method", "pose", "--json", str(out_json)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "camera equirect" in result.output
    records = json.loads(out_json.read_text())
    assert [r["method"] for r in records] == ["thesis", "best", "pose"]
    assert all(r["n"] == len(load_places(equirect_dataset)) for r in records)
    camera = CliRunner().invoke(main, ["eval", "align", str(equirect_dataset), "--camera", "x"])
    assert camera.exit_code == 2 and "camera" in camera.output


def test_pose_vote_is_best_and_homes(dataset, fingerprints) -> None:
    from toploc.evaluation.homing import BEST_METHOD

    assert BEST_METHOD == "pose-vote"
    places = load_places(dataset)
    run = evaluate_homing(places, fingerprints["sift"], "best")
    pose_vote = evaluate_homing(places, fingerprints["sift"], "pose-vote")
    np.testing.assert_allclose(run.errors_deg, pose_vote.errors_deg)
    assert run.stats.n_failed == 0
    assert run.stats.mean_deg < 60.0 and run.stats.under_90 > 0.8  # chance: 90 deg, 50 %


def test_the_closed_loop_steps_along_the_axis_eval_homing_best_scores(dataset, fingerprints):
    """The drive (:func:`localizer.visual_homing.home_step`) and ``eval homing --method best``
    solve the same pose (planar, refined: ``HOMING_VERIFICATION``), so they home along one
    axis; the sign's votes are their own (the matched ALV is estimated a little apart)."""
    from localizer.visual_homing import HOMING_VERIFICATION, home_step

    places, fps = load_places(dataset), fingerprints["sift"]
    run = evaluate_homing(places, fps, "best")
    assert PairCache(fps).params == HOMING_VERIFICATION
    assert HOMING_VERIFICATION.motion == "planar-refined"
    compared = 0
    for k in range(0, len(run.here), max(1, len(run.here) // 24)):
        if run.here[k] > run.home[k]:
            continue  # the evaluation solves each pair once, the lower row as the query
        try:
            step = home_step(fps[run.here[k]], fps[run.home[k]])
        except HomingError:  # too few matches to drive on: the loop turns away and looks again
            continue
        turn = np.remainder(step.direction_rad - run.home_direction_rad[k], np.pi)
        assert min(turn, np.pi - turn) < 1e-6
        compared += 1
    assert compared >= 6


def test_pose_vote_keeps_the_axis_of_the_pose(dataset, fingerprints) -> None:
    """Where the verification found geometry the direction is its translation's axis, one way
    or the other (only the sign comes from the ALVs)."""
    places = load_places(dataset)
    cache = PairCache(fingerprints["sift"])
    signed = evaluate_homing(places, fingerprints["sift"], "pose-vote", cache=cache)
    pose = evaluate_homing(places, fingerprints["sift"], "pose", cache=cache)
    pairs = zip(signed.here, signed.home, strict=True)
    geometry = np.array([cache.verification(i, j).translation_dir is not None for i, j in pairs])
    assert geometry.sum() > len(geometry) // 2
    turn = np.abs(np.remainder(signed.home_direction_rad - pose.home_direction_rad, np.pi))
    assert np.all(np.minimum(turn, np.pi - turn)[geometry] < 1e-9)
