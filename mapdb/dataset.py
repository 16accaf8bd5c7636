"""Reading a panorama dataset folder: its ``manifest.csv`` and the SHA-256 of its images.

The manifest has the header ``image,room,x_m,y_m,heading_deg`` (extra columns are ignored);
``image`` is relative to the folder; ``x_m``, ``y_m`` (metres) and ``heading_deg`` (degrees, CCW)
are in the frame of the row's room and may be empty when unknown (``x_m`` and ``y_m`` together).
"""

from __future__ import annotations

import csv
import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

from mapdb.errors import ManifestError

MANIFEST_NAME = "manifest.csv"
MANIFEST_COLUMNS = ("image", "room", "x_m", "y_m", "heading_deg")
EDGES_NAME = "edges.csv"
EDGES_COLUMNS = ("room_a", "room_b")


@dataclass(frozen=True)
class ManifestEntry:
    """One row of a manifest: an image file, its room and its (optional) pose in that room."""

    image: str
    path: Path
    room: str
    x_m: float | None
    y_m: float | None
    heading_deg: float | None
    line: int


def _optional_float(text: str | None, column: str, line: int, manifest: Path) -> float | None:
    """Parse a finite float, or ``None`` for an empty cell; errors name file, line and column."""
    text = (text or "").strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        raise ManifestError(
            f"{manifest} line {line}: column {column!r} must be a number or empty, got {text!r}",
            manifest,
        ) from None
    if not math.isfinite(value):
        raise ManifestError(
            f"{manifest} line {line}: column {column!r} must be finite, got {text!r}", manifest
        )
    return value


def _entry(row: dict[str, str | None], line: int, folder: Path, manifest: Path) -> ManifestEntry:
    image = (row["image"] or "").strip()
    room = (row["room"] or "").strip()
    if not image or not room:
        column = "image" if not image else "room"
        raise ManifestError(f"{manifest} line {line}: column {column!r} is empty", manifest)
    x_m = _optional_float(row["x_m"], "x_m", line, manifest)
    y_m = _optional_float(row["y_m"], "y_m", line, manifest)
    if (x_m is None) != (y_m is None):
        raise ManifestError(
            f"{manifest} line {line}: give both 'x_m' and 'y_m' or leave both empty", manifest
        )
    heading_deg = _optional_float(row["heading_deg"], "heading_deg", line, manifest)
    return ManifestEntry(image, folder / image, room, x_m, y_m, heading_deg, line)


def read_manifest(dataset_dir: Path | str) -> list[ManifestEntry]:
    """All entries of ``dataset_dir/manifest.csv``, in file order.

    Raises :class:`ManifestError` naming the file (and the line and column) when the manifest
    is missing, lacks a column, or has a malformed value. Image files are not checked here: a
    missing or corrupt image is a per-image failure of the build.
    """
    folder = Path(dataset_dir)
    manifest = folder / MANIFEST_NAME
    if not folder.is_dir():
        raise ManifestError(f"dataset folder {folder} does not exist", folder)
    if not manifest.is_file():
        raise ManifestError(f"{manifest} not found: a dataset needs a {MANIFEST_NAME}", manifest)
    with manifest.open(newline="", encoding="utf-8-sig") as handle:
        reader = csv.DictReader(handle)
        header = [name.strip() for name in reader.fieldnames or []]
        missing = [column for column in MANIFEST_COLUMNS if column not in header]
        if missing:
            raise ManifestError(
                f"{manifest} lacks column(s) {', '.join(repr(c) for c in missing)}; "
                f"the header must include {','.join(MANIFEST_COLUMNS)} (got {','.join(header)})",
                manifest,
            )
        reader.fieldnames = header
        return [_entry(row, reader.line_num, folder, manifest) for row in reader]


def read_edges(dataset_dir: Path | str) -> list[tuple[str, str]]:
    """The room graph of a dataset: ``dataset_dir/edges.csv`` rows ``room_a,room_b``.

    The file is optional: none gives no edges. Raises :class:`ManifestError` naming the file and
    line for a missing column, an empty cell or a self-loop.
    """
    path = Path(dataset_dir) / EDGES_NAME
    if not path.is_file():
        return []
    with path.open(newline="", encoding="utf-8-sig") as handle:
        reader = csv.DictReader(handle)
        header = [name.strip() for name in reader.fieldnames or []]
        if any(column not in header for column in EDGES_COLUMNS):
            raise ManifestError(
                f"{path} must have the header {','.join(EDGES_COLUMNS)} (got {','.join(header)})",
                path,
            )
        reader.fieldnames = header
        edges = []
        for row in reader:
            a, b = ((row[c] or "").strip() for c in EDGES_COLUMNS)
            if not a or not b or a == b:
                raise ManifestError(
                    f"{path} line {reader.line_num}: an edge needs two different rooms, "
                    f"got {a!r} and {b!r}",
                    path,
                )
            edges.append((a, b))
        return edges


def sha256_file(path: Path, chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of the file's bytes (read in chunks). Raises ``OSError`` if unreadable."""
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        while chunk := handle.read(chunk_bytes):
            digest.update(chunk)
    return digest.hexdigest()
