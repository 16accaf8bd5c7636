"""``toploc localize``, ``toploc eval localize`` and ``toploc sim kidnap`` as a user runs them."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
from click.testing import CliRunner

from toploc.cli import main


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_localize_prints_the_belief_as_json(building_map):
    db_path, dataset = building_map
    image = dataset / "images" / "kitchen_003.png"
    result = run("localize", image, "--db", db_path, "--json")
    assert result.exit_code == 0, result.output
    belief = json.loads(result.output)
    assert belief["top"]["room"] == "kitchen"
    assert belief["state"] in {"localized", "ambiguous"}
    assert set(belief["timing_ms"]) == {"extraction", "retrieval", "verification"}


def test_localize_prints_each_best_place_with_the_share_of_the_horizon_it_covers(building_map):
    db_path, dataset = building_map
    result = run("localize", dataset / "images" / "kitchen_003.png", "--db", db_path)
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    start = lines.index("best places (room, place id, inliers / matches, share of the horizon):")
    first = lines[start + 1].split()
    assert first[0] == "kitchen"
    assert first[-1].endswith("%") and 0 < int(first[-1].rstrip("%")) <= 100


def test_localize_names_a_corrupt_image(building_map, tmp_path):
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    result = run("localize", bad, "--db", building_map[0])
    assert result.exit_code == 1
    assert "bad.png" in result.output


def test_localize_refuses_a_pinhole_crop_naming_it(building_map, tmp_path):
    import cv2

    panorama = cv2.imread(str(building_map[1] / "images" / "kitchen_003.png"))
    crop = tmp_path / "crop.png"
    cv2.imwrite(str(crop), panorama[:, 100:228])  # 128 x 96: a pinhole's field, 4:3
    result = run("localize", crop, "--db", building_map[0])
    assert result.exit_code == 1
    assert f"{crop}: 128x96 px (1.33:1) is not a 360° panorama" in result.output
    named = run("localize", crop, "--db", building_map[0], "--camera", "cylinder")
    assert named.exit_code == 0, named.output


def test_localize_names_a_missing_map(building_map, tmp_path):
    image = building_map[1] / "images" / "kitchen_000.png"
    result = run("localize", image, "--db", tmp_path / "nowhere.db")
    assert result.exit_code == 1
    assert "nowhere.db does not exist" in result.output


def test_eval_localize_on_a_dataset_writes_the_issue_keys(building_map, tmp_path):
    db_path, dataset = building_map
    out = tmp_path / "score.json"
    result = run("eval", "localize", dataset, "--db", db_path, "--json", out, "--no-progress")
    assert result.exit_code == 0, result.output
    score = json.loads(out.read_text())
    assert score["n"] == sum(1 for _ in (dataset / "manifest.csv").open()) - 1
    assert score["top1"] >= 0.9  # the map's own images, same condition
    assert set(score["confusion"]) == set(score["per_room"])
    assert sum(score["outcomes"].values()) == score["n"]
    assert score["outcomes"]["wrong_localized"] == 0
    assert score["unknown_room"]["n"] == 0
    for label in ("right, localized", "right, ambiguous", "wrong, localized", "lost"):
        assert label in result.output
    assert sum(b["n"] for b in score["calibration"]["bins"]) == score["n"]
    assert "Brier score of the top room" in result.output


def test_eval_localize_counts_a_room_the_map_lacks(building_map, tmp_path):
    db_path, dataset = building_map
    queries = tmp_path / "queries"
    (queries / "images").mkdir(parents=True)
    shutil.copy(dataset / "images" / "kitchen_003.png", queries / "images" / "attic_000.png")
    shutil.copy(dataset / "images" / "kitchen_000.png", queries / "images" / "kitchen_000.png")
    (queries / "manifest.csv").write_text(
        "image,room,x_m,y_m,heading_deg\n"
        "images/attic_000.png,attic,,,\n"
        "images/kitchen_000.png,kitchen,,,\n"
    )
    out = tmp_path / "score.json"
    result = run("eval", "localize", queries, "--db", db_path, "--json", out, "--no-progress")
    assert result.exit_code == 0, result.output
    score = json.loads(out.read_text())
    unknown = score["unknown_room"]
    assert (unknown["n"], unknown["rooms"]) == (1, ["attic"])
    assert score["per_room"]["attic"]["top1"] == 0.0  # a kitchen view cannot be the attic
    assert score["per_room_outcomes"]["attic"]["in_map"] is False
    assert "rooms not in the map (attic)" in result.output


def test_eval_localize_reads_one_sub_folder_per_room_without_a_manifest(building_map, tmp_path):
    db_path, dataset = building_map
    queries = tmp_path / "photos"
    for room, image in (("kitchen", "kitchen_003.png"), ("attic", "kitchen_000.png")):
        (queries / room).mkdir(parents=True)
        shutil.copy(dataset / "images" / image, queries / room / "IMG_0001.PNG")
    out = tmp_path / "score.json"
    result = run("eval", "localize", queries, "--db", db_path, "--json", out, "--no-progress")
    assert result.exit_code == 0, result.output
    score = json.loads(out.read_text())
    assert score["n"] == 2
    assert score["per_room"]["kitchen"]["top1"] == 1.0
    assert score["unknown_room"]["rooms"] == ["attic"]


def test_eval_localize_leave_one_out_needs_no_dataset_and_plots(building_map, tmp_path):
    plot = tmp_path / "calibration.png"
    result = run(
        "eval",
        "localize",
        "--db",
        building_map[0],
        "--leave-one-out",
        "--no-progress",
        "--plot",
        plot,
    )
    assert result.exit_code == 0, result.output
    assert "top-1 room" in result.output
    assert plot.read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
    assert f"wrote {plot}" in result.output


def test_eval_localize_wants_a_dataset_or_leave_one_out(building_map):
    result = run("eval", "localize", "--db", building_map[0])
    assert result.exit_code == 2
    assert "give a DATASET or --leave-one-out" in result.output


def test_sim_kidnap_reports_each_trial_and_the_totals(building_map, tmp_path):
    out = tmp_path / "kidnap.json"
    result = run(
        "sim", "kidnap", "--trials", "1", "--db", building_map[0], "--json", out, "--seed", "3"
    )
    assert result.exit_code == 0, result.output
    report = json.loads(out.read_text())
    (trial,) = report["trials"]
    assert trial["true_room"] == "office_a"
    assert {"final_belief", "steps", "distance_m", "frames", "success"} <= set(trial)
    assert report["totals"]["trials"] == 1
    assert report["totals"]["success_rate"] == float(trial["success"])
    assert report["totals"]["endings"] == {trial["ended"]: 1}
    put_back = trial["success"] and trial["end_room"] == trial["true_room"]
    assert report["totals"]["right_where_put"] == int(put_back)
    assert f"ended: {trial['ended']} 1" in result.output


def test_map_calibrate_stores_the_likelihood_that_map_info_shows(building_map, tmp_path):
    db_path = tmp_path / "map.db"
    shutil.copy(building_map[0], db_path)
    result = run("map", "calibrate", "--db", db_path, "--no-progress")
    assert result.exit_code == 0, result.output
    assert result.output.startswith("sift: calibrated on the map's own places")
    assert "spread inliers" in result.output  # says which count the model reads
    assert "log ratio" not in result.output  # the formula is map info's
    shown = run("map", "info", "--db", db_path)
    assert "log ratio" in shown.output and "n = spread inliers" in shown.output
    info = run("map", "info", "--db", db_path, "--json")
    likelihood = json.loads(info.output)["likelihoods"]["sift"]
    assert likelihood["model"] == "ratio" and likelihood["fit"]["n_same_room"] > 0
    assert likelihood["count"] == "spread"


def test_a_bad_camera_is_refused_by_name(building_map):
    image = building_map[1] / "images" / "kitchen_000.png"
    result = run("localize", image, "--db", building_map[0], "--camera", "fisheye")
    assert result.exit_code == 2
    assert "camera 'fisheye'" in result.output


def test_an_equirectangular_panorama_localizes_against_a_cylinder_map(building_map, tmp_path):
    import cv2
    import numpy as np

    from localizer.robot_protocol import Pose2D
    from robot.render import PanoramaCamera, render_panorama
    from robot.scene import build_scene
    from robot.worlds import make_world

    world = make_world("building")
    camera = PanoramaCamera(1024, 512, projection="equirect")
    kitchen = world.room("kitchen")
    pose = Pose2D(kitchen.origin_m[0] + 1.7, kitchen.origin_m[1] + 1.4, 0.6)
    image = render_panorama(build_scene(world), pose, camera)
    path = tmp_path / "sphere.png"
    cv2.imwrite(str(path), np.ascontiguousarray(image[..., ::-1]))
    result = run("localize", path, "--db", building_map[0], "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["top"]["room"] == "kitchen"


def test_localize_with_a_detector_the_map_lacks_names_the_ones_it_holds(building_map):
    db_path, dataset = building_map
    image = dataset / "images" / "kitchen_000.png"
    mser = run("localize", image, "--db", db_path, "--detector", "mser")
    assert mser.exit_code == 1
    assert "has no 'mser' fingerprints: it holds sift (--detector sift;" in mser.output
    assert "built with --detector mser" in mser.output
    orb = run("eval", "localize", dataset, "--db", db_path, "--detector", "orb", "--no-progress")
    assert orb.exit_code == 1
    assert "has no 'orb' fingerprints: it holds sift" in orb.output
    assert "toploc's detectors are mser, sift" in orb.output


def test_localize_of_a_frame_matching_no_place_says_lost_and_names_no_room(building_map, tmp_path):
    noise = tmp_path / "noise.png"
    cv2.imwrite(str(noise), np.random.default_rng(0).integers(0, 256, (96, 512), np.uint8))
    result = run("localize", noise, "--db", building_map[0])
    assert result.exit_code == 0, result.output
    first = result.output.splitlines()[0]
    assert first.startswith("lost: no room of the map matches (best ")
    assert " 1.000" not in result.output.split("best places")[0]


def test_rooms_declared_look_alike_stay_so_through_later_calibrations(building_map, tmp_path):
    from toploc.maps import calibrate_map, load_map

    db_path = tmp_path / "map.db"
    shutil.copy(building_map[0], db_path)
    assert ("kitchen", "storage") not in load_map(db_path).likelihood.lookalikes
    result = run("map", "lookalike", "storage", "kitchen", "--db", db_path, "--no-progress")
    assert result.exit_code == 0, result.output
    assert "declared look-alikes: storage and kitchen" in result.output
    assert "kitchen ~ storage" in result.output
    calibrate_map(db_path, "sift")  # as map add does after a new place
    model = load_map(db_path).likelihood
    assert model.declared == (("kitchen", "storage"),)
    assert ("kitchen", "storage") in model.lookalikes


def test_a_look_alike_of_a_room_the_map_lacks_is_refused_by_name(building_map, tmp_path):
    db_path = tmp_path / "map.db"
    shutil.copy(building_map[0], db_path)
    result = run("map", "lookalike", "kitchen", "attic", "--db", db_path, "--no-progress")
    assert result.exit_code == 1
    assert "no room 'attic'" in result.output and "kitchen" in result.output
