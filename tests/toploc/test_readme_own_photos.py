"""The README's "Your own photos in five commands", run as a user would, as separate processes.

A user's photos are stood in for by rendered panoramas of four rooms of the ``building`` world,
copied into one sub-folder per room (no manifest, no poses), and the views the map did not
store by ``toploc dataset perturb`` as the README says. Each ``$`` line of the README's block
runs as written, in the folder that holds ``photos/``; ``serve`` only gets a free loopback
endpoint added (tests run side by side), and a client asks it for a localization before it is
stopped with Ctrl-C.
"""

from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from bus_helpers import free_endpoint

REPO = Path(__file__).resolve().parents[2]
README = REPO / "README.md"
ROOMS = ("kitchen", "office_a", "storage", "seminar")


def own_photos_commands() -> list[list[str]]:
    """The ``$`` lines of the README's "Your own photos" section, split as a shell would."""
    text = README.read_text(encoding="utf-8")
    section = text.split("## Your own photos in five commands", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```sh\n(.*?)```", section, re.S)
    assert block is not None, "the section has no sh block"
    return [shlex.split(line[2:]) for line in block.group(1).splitlines() if line.startswith("$ ")]


def toploc(args: list[str], cwd: Path, timeout_s: float = 180.0) -> str:
    assert args[0] == "toploc", args
    done = subprocess.run(
        [sys.executable, "-m", "toploc", *args[1:]],
        cwd=cwd,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )
    assert done.returncode == 0, f"{shlex.join(args)}:\n{done.stdout}\n{done.stderr}"
    return done.stdout


@pytest.fixture(scope="module")
def user_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with ``photos/<room>/*.png`` and ``views/`` (perturbed copies of them)."""
    root = tmp_path_factory.mktemp("own_photos")
    render = "toploc dataset render rendered --world building --spacing 2.5 --width 512 --height 96"
    toploc([*render.split(), "--no-progress"], root)
    for room in ROOMS:
        (root / "photos" / room).mkdir(parents=True)
        for image in sorted((root / "rendered" / "images").glob(f"{room}_*.png")):
            image.rename(root / "photos" / room / image.name)
    perturb = "toploc dataset perturb photos views --random-roll --condition dim_noisy --seed 1"
    toploc(perturb.split(), root)
    return root


def test_the_readme_shows_five_commands() -> None:
    commands = own_photos_commands()
    assert len(commands) == 5
    assert [c[:3] for c in commands[:2]] == [["toploc", "map", "build"], ["toploc", "map", "info"]]


def test_the_five_commands_map_localize_score_and_serve_ones_photos(user_folder: Path) -> None:
    build, info, localize, evaluate, serve = own_photos_commands()
    # the README's example photo is a user's name; localize the first photo of its room here
    room = Path(localize[2]).parent.name if Path(localize[2]).parent.name in ROOMS else ROOMS[0]
    photo = sorted((user_folder / "photos" / room).iterdir())[0]
    localize = [*localize[:2], str(photo.relative_to(user_folder)), *localize[3:]]

    toploc(build, user_folder)
    shown = toploc(info, user_folder)
    assert all(name in shown for name in ROOMS)
    answer = toploc(localize, user_folder)
    assert answer.splitlines()[0].startswith(f"localized in {room} "), answer  # a stored photo
    scores = toploc(evaluate, user_folder)
    assert re.search(r"right, localized +\d+", scores), scores

    endpoint = free_endpoint()
    process = subprocess.Popen(
        [sys.executable, "-m", "toploc", *serve[1:], "--listen", endpoint, "--robot-id", "own"],
        cwd=user_folder,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        first = process.stdout.readline()
        assert first.startswith("robot id: own"), first
        belief = subprocess.run(
            [sys.executable, "-m", "toploc", "belief", "--localize", "--robot-id", "own",
             "--connect", endpoint, "--json"],
            cwd=user_folder,
            env={**os.environ, "PYTHONPATH": str(REPO)},
            capture_output=True,
            text=True,
            timeout=120,
        )  # fmt: skip
        assert belief.returncode == 0, belief.stdout + belief.stderr
        assert any(name in belief.stdout for name in ROOMS), belief.stdout
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.communicate(timeout=30)
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
    assert process.returncode is not None
