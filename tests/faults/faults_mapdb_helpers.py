"""Helpers for the map fault tests: tiny datasets, the CLI as a process, and process lookup.

The CLI subprocess runs ``tests/mapdb/mapdb_cli_with_fake_extractor`` (the real ``toploc map``
group with a slow fake extractor), so a build can be stopped mid-way.
"""

from __future__ import annotations

import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
from mapdb_helpers import assert_consistent, table_counts, write_image

from mapdb.records import Fingerprint

__all__ = ["assert_consistent", "table_counts", "write_image"]  # the fault tests use them too

REPO = Path(__file__).resolve().parents[2]
MAPDB_TESTS = REPO / "tests" / "mapdb"


def make_dataset(folder: Path, n: int, rooms: tuple[str, ...] = ("kitchen", "hall")) -> Path:
    """``folder`` with ``n`` random images under ``img/`` and their ``manifest.csv``."""
    lines = ["image,room,x_m,y_m,heading_deg"]
    for i in range(n):
        write_image(folder / "img" / f"pano_{i:03d}.png", seed=i)
        lines.append(f"img/pano_{i:03d}.png,{rooms[i % len(rooms)]},{i},0,0")
    write_manifest(folder, lines)
    return folder


def write_manifest(folder: Path, lines: list[str], encoding: str = "utf-8") -> Path:
    """Write ``lines`` as ``folder/manifest.csv``; return the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "manifest.csv").write_text("\n".join(lines) + "\n", encoding=encoding)
    return folder


def places_so_far(db_path: Path) -> int:
    """Committed places, read without disturbing the writer (0 before the schema exists)."""
    if not db_path.exists():
        return 0
    try:
        with sqlite3.connect(f"file:{db_path}?mode=ro", uri=True, timeout=1.0) as conn:
            return int(conn.execute("SELECT COUNT(*) FROM places").fetchone()[0])
    except sqlite3.OperationalError:
        return 0


def start_slow_build(dataset: Path, db_path: Path, delay_s: float = 0.3) -> subprocess.Popen:
    """``toploc map build DATASET --db DB --workers 2`` in a new session, slow fake extractor."""
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(REPO), str(MAPDB_TESTS)]),
        "TOPLOC_FAKE_EXTRACT_DELAY_S": str(delay_s),
    }
    command = [sys.executable, "-m", "mapdb_cli_with_fake_extractor", "build", str(dataset),
               "--db", str(db_path), "--workers", "2", "--no-progress",
               "--no-calibrate", "--detector", "sift,mser"]  # fmt: skip
    return subprocess.Popen(
        command,
        env=env,
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,  # session id = its pid: finds the workers after it died
    )


def live_session_members(session_id: int) -> list[int]:
    """Pids of the living (not zombie) processes of session ``session_id`` (Linux ``/proc``)."""
    members = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue  # ended meanwhile
        fields = stat[stat.rindex(")") + 2 :].split()
        state, session = fields[0], int(fields[3])
        if session == session_id and state not in ("Z", "X"):
            members.append(int(entry.name))
    return members


def fake_extract(
    path: Path, presets: tuple[str, ...], camera: str = "auto", overrides: object = None
) -> list[Fingerprint]:
    """Decode ``path`` (``ValueError`` if corrupt); one tiny synthetic fingerprint per preset
    (``camera`` and ``overrides`` as :func:`toploc.extraction.extract_panorama` takes them)."""
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise ValueError(f"{path}: corrupt or not an image")
    height_px, width_px = image.shape
    rng = np.random.default_rng(int(image.sum()))
    xy = rng.uniform([0, 0], [width_px - 1, height_px - 1], size=(8, 2))
    return [
        Fingerprint(
            detector=preset.split("-")[0],
            image_width_px=width_px,
            image_height_px=height_px,
            keypoints_xy=xy.astype(np.float32),
            bearings_rad=np.angle(np.exp(-2j * np.pi * xy[:, 0] / width_px)),
            descriptors=rng.random((8, 128), dtype=np.float32),
            params={"detector": preset.split("-")[0]},
        )
        for preset in presets
    ]


def run_toploc(*args: str | Path, timeout_s: float = 120.0) -> subprocess.CompletedProcess:
    """``python -m toploc ARGS`` as a user runs it (text output, never hangs the tests)."""
    return subprocess.run(
        [sys.executable, "-m", "toploc", *(str(a) for a in args)],
        env={**os.environ, "PYTHONPATH": str(REPO)},
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def can_bind_mount_read_only() -> bool:
    """True if ``unshare -m`` can make a private read-only bind mount here (root with
    CAP_SYS_ADMIN, as in a CI container); root ignores file modes, so this is its read-only."""
    if shutil.which("unshare") is None:
        return False
    probe = ["unshare", "-m", "--propagation", "private", "mount", "--bind", "-o", "ro", "/", "/"]
    try:
        return subprocess.run(probe, capture_output=True, timeout=10).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def on_read_only_folder(folder: Path, argv: list[str]) -> list[str]:
    """``argv`` wrapped to run with ``folder`` read-only: as root in a private mount namespace
    with a read-only bind mount of it; otherwise the caller has chmod-ed it (0o555/0o444)."""
    if os.geteuid() != 0:
        return argv
    script = 'mount --bind -o ro "$1" "$1" && shift && exec "$@"'
    return ["unshare", "-m", "--propagation", "private", "sh", "-c", script, "sh", str(folder),
            *argv]  # fmt: skip


def make_read_only(folder: Path) -> None:
    """Without root, chmod ``folder`` and its files read-only (root uses a mount instead)."""
    if os.geteuid() != 0:
        for path in folder.iterdir():
            path.chmod(0o444)
        folder.chmod(0o555)


def make_writable(folder: Path) -> None:
    """Undo :func:`make_read_only` (so that pytest can remove ``folder``)."""
    folder.chmod(0o755)
    for path in folder.iterdir():
        path.chmod(0o644)
