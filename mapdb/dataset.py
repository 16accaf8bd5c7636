"""A panorama dataset folder: its ``manifest.csv`` and ``edges.csv`` read and written, one
:class:`ManifestEntry` per row either way, and the SHA-256 of its images.

The manifest has the header ``image,room,x_m,y_m,heading_deg`` (extra columns are ignored);
``image`` is relative to the folder; ``x_m``, ``y_m`` (metres) and ``heading_deg`` (degrees, CCW)
are in the frame of the row's room and may be empty when unknown (``x_m`` and ``y_m`` together).
Manifest and ``edges.csv`` are UTF-8 (a byte-order mark is allowed). An image must lie inside
the folder once symbolic links are resolved (unless ``allow_outside``), and only regular files
are read: a FIFO or a device such as ``/dev/zero`` would block or never end.
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
import os
import stat
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from mapdb.errors import ManifestError
from mapdb.records import check_finite, check_name

MANIFEST_NAME = "manifest.csv"
MANIFEST_COLUMNS = ("image", "room", "x_m", "y_m", "heading_deg")
EDGES_NAME = "edges.csv"
EDGES_COLUMNS = ("room_a", "room_b")


@dataclass(frozen=True)
class ManifestEntry:
    """One row of a manifest, read (:func:`read_manifest`) or to be written
    (:func:`write_manifest`): an image, its room and its (optional) pose in that room.

    ``image`` is the manifest's text, relative to the dataset folder; ``path`` the file it names
    (``folder / image``). ``x_m``, ``y_m`` (metres) and ``heading_deg`` (degrees, CCW) are in the
    frame of the room, ``None`` when unknown (``x_m`` and ``y_m`` together). ``line`` is the
    row's line in the manifest it was read from, 0 for an entry not read from one (an image
    given directly, a row about to be written). Raises ``ValueError`` for a room name no map
    can hold, a NaN or infinite coordinate, or only one of ``x_m`` and ``y_m``: a manifest
    written from entries is one :func:`read_manifest` reads back.
    """

    image: str
    path: Path
    room: str
    x_m: float | None
    y_m: float | None
    heading_deg: float | None
    line: int = 0

    def __post_init__(self) -> None:
        if not self.image.strip():
            raise ValueError(f"manifest entry of room {self.room!r}: image must not be empty")
        check_name(self.room)
        check_finite(self.x_m, "x_m")
        check_finite(self.y_m, "y_m")
        check_finite(self.heading_deg, "heading_deg")
        if (self.x_m is None) != (self.y_m is None):
            raise ValueError(
                f"manifest entry {self.image!r}: give both x_m and y_m or neither, "
                f"got {self.x_m} and {self.y_m}"
            )


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


def _check_room(room: str, line: int, path: Path) -> None:
    """A :class:`ManifestError` naming file and line for a room name no map can hold."""
    try:
        check_name(room)
    except ValueError as error:
        raise ManifestError(f"{path} line {line}: {error}", path) from None


def _read_text(path: Path) -> str:
    """The UTF-8 text of ``path``; a :class:`ManifestError` names the line and byte offset of
    the first byte that is not UTF-8 (e.g. a file saved as Latin-1)."""
    try:
        data = path.read_bytes()
    except OSError as error:
        raise ManifestError(f"cannot read {path}: {error.strerror or error}", path) from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise ManifestError(
            f"{path} line {line}: byte {error.start} ({data[error.start]:#04x}) is not UTF-8; "
            f"save the file as UTF-8",
            path,
        ) from None


def _csv_rows(path: Path) -> csv.DictReader[str]:
    """A ``csv.DictReader`` over the UTF-8 text of ``path``."""
    return csv.DictReader(io.StringIO(_read_text(path), newline=""))


def _inside(image: str, folder: Path, where: str, source: Path, allow_outside: bool) -> Path:
    """``folder / image``; a :class:`ManifestError` (saying ``where``, naming ``source``) if it
    resolves (through symbolic links, or as an absolute path) to a file outside ``folder`` and
    ``allow_outside`` is False."""
    if "\x00" in image:
        raise ManifestError(f"{where}: image {image!r} has a NUL byte", source)
    path = folder / image
    if allow_outside:
        return path
    resolved = path.resolve()
    if not resolved.is_relative_to(folder.resolve()):
        raise ManifestError(
            f"{where}: image {image!r} lies outside the dataset folder "
            f"{folder} (it is {resolved}); move it in, or pass --allow-outside to `map build`",
            source,
        )
    return path


def _entry(
    row: dict[str, str | None], line: int, folder: Path, manifest: Path, allow_outside: bool
) -> ManifestEntry:
    image = (row["image"] or "").strip()
    room = (row["room"] or "").strip()
    if not image or not room:
        column = "image" if not image else "room"
        raise ManifestError(f"{manifest} line {line}: column {column!r} is empty", manifest)
    _check_room(room, line, manifest)
    x_m = _optional_float(row["x_m"], "x_m", line, manifest)
    y_m = _optional_float(row["y_m"], "y_m", line, manifest)
    if (x_m is None) != (y_m is None):
        raise ManifestError(
            f"{manifest} line {line}: give both 'x_m' and 'y_m' or leave both empty", manifest
        )
    heading_deg = _optional_float(row["heading_deg"], "heading_deg", line, manifest)
    path = _inside(image, folder, f"{manifest} line {line}", manifest, allow_outside)
    return ManifestEntry(image, path, room, x_m, y_m, heading_deg, line)


def read_manifest(dataset_dir: Path | str, allow_outside: bool = False) -> list[ManifestEntry]:
    """All entries of ``dataset_dir/manifest.csv``, in file order.

    Raises :class:`ManifestError` naming the file (and the line and column) when the manifest
    is missing, is not UTF-8 or not CSV, lacks a column, has a malformed value, or names an
    image outside ``dataset_dir`` (symbolic links resolved; allowed with ``allow_outside``).
    Image files are not read here: a missing or corrupt image is a per-image failure of the
    build.
    """
    folder = Path(dataset_dir)
    manifest = folder / MANIFEST_NAME
    if not folder.is_dir():
        raise ManifestError(f"dataset folder {folder} does not exist", folder)
    if not manifest.is_file():
        raise ManifestError(f"{manifest} not found: a dataset needs a {MANIFEST_NAME}", manifest)
    reader = _csv_rows(manifest)
    try:
        header = [name.strip() for name in reader.fieldnames or []]
        missing = [column for column in MANIFEST_COLUMNS if column not in header]
        if missing:
            raise ManifestError(
                f"{manifest} lacks column(s) {', '.join(repr(c) for c in missing)}; "
                f"the header must include {','.join(MANIFEST_COLUMNS)} (got {','.join(header)})",
                manifest,
            )
        reader.fieldnames = header
        return [_entry(row, reader.line_num, folder, manifest, allow_outside) for row in reader]
    except csv.Error as error:
        raise ManifestError(f"{manifest} line {reader.line_num}: {error}", manifest) from None


def write_manifest(dataset_dir: Path | str, entries: Iterable[ManifestEntry]) -> Path:
    """Write ``dataset_dir/manifest.csv`` (UTF-8, the header ``image,room,x_m,y_m,heading_deg``)
    with one row per entry, in order: its ``image`` and room, and empty cells for an unknown
    position or heading (numbers written exactly, as ``repr`` of the float). ``path`` and
    ``line`` are not written. Returns the manifest's path; ``OSError`` if it cannot be written.
    """
    manifest = Path(dataset_dir) / MANIFEST_NAME
    with manifest.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(MANIFEST_COLUMNS)
        for e in entries:
            values = (e.x_m, e.y_m, e.heading_deg)
            writer.writerow(
                [e.image, e.room, *("" if v is None else repr(float(v)) for v in values)]
            )
    return manifest


def write_edges(dataset_dir: Path | str, edges: Iterable[tuple[str, str]]) -> Path:
    """Write ``dataset_dir/edges.csv``: the header ``room_a,room_b`` and one row per edge, in
    order. Returns its path; ``OSError`` if it cannot be written."""
    path = Path(dataset_dir) / EDGES_NAME
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(EDGES_COLUMNS)
        writer.writerows(edges)
    return path


IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".webp")
"""File name endings (any case) that a folder of room sub-folders is read for."""


def read_dataset(dataset_dir: Path | str, allow_outside: bool = False) -> list[ManifestEntry]:
    """The panoramas of a dataset folder: its ``manifest.csv`` (:func:`read_manifest`) if it has
    one, else its room sub-folders (:func:`read_room_folders`)."""
    folder = Path(dataset_dir)
    if (folder / MANIFEST_NAME).exists() or not folder.is_dir():
        return read_manifest(folder, allow_outside)
    return read_room_folders(folder, allow_outside)


def _is_image_name(name: str) -> bool:
    # Hidden files are skipped: macOS writes "._IMG_0001.JPG" resource forks beside photos.
    return not name.startswith(".") and name.lower().endswith(IMAGE_SUFFIXES)


def read_room_folders(dataset_dir: Path | str, allow_outside: bool = False) -> list[ManifestEntry]:
    """One entry per image file (:data:`IMAGE_SUFFIXES`) in each sub-folder of ``dataset_dir``,
    whose name is the image's room; no pose (``x_m``, ``y_m``, ``heading_deg`` None; ``line``
    0). Sorted by room, then file name. This is how photos from a 360° camera are usually kept:
    ``house/kitchen/IMG_0001.JPG``.

    Raises :class:`ManifestError` naming the folder when it holds images directly (their room
    is unknown), when it has an ``images`` sub-folder (the layout of a dataset whose manifest
    is missing), when no sub-folder holds an image, when a sub-folder's name is not a valid
    room name, or when an image resolves outside the folder (unless ``allow_outside``).
    """
    folder = Path(dataset_dir)
    if not folder.is_dir():
        raise ManifestError(f"dataset folder {folder} does not exist", folder)
    loose = sorted(p.name for p in folder.iterdir() if _is_image_name(p.name) and not p.is_dir())
    if loose:
        raise ManifestError(
            f"{folder} has no {MANIFEST_NAME} and holds images directly ({', '.join(loose[:3])}"
            f"{', ...' if len(loose) > 3 else ''}): put each room's panoramas in a sub-folder "
            f"named after the room, or write a {MANIFEST_NAME}",
            folder,
        )
    if (folder / "images").is_dir():  # a rendered or copied dataset whose manifest is gone
        raise ManifestError(
            f"{folder} has no {MANIFEST_NAME} but an images/ folder: is the manifest missing? "
            f"(a room cannot be named 'images' in a folder of room sub-folders)",
            folder,
        )
    entries = []
    for room_dir in sorted(
        p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(".")
    ):
        images = sorted(
            p.name for p in room_dir.iterdir() if _is_image_name(p.name) and not p.is_dir()
        )
        if images:
            try:
                check_name(room_dir.name)
            except ValueError as error:
                raise ManifestError(
                    f"{room_dir}: the folder's name is the room's: {error}", room_dir
                ) from None
        for name in images:
            image = f"{room_dir.name}/{name}"
            path = _inside(image, folder, str(folder), folder, allow_outside)
            entries.append(ManifestEntry(image, path, room_dir.name, None, None, None, 0))
    if not entries:
        raise ManifestError(
            f"{folder} has no {MANIFEST_NAME} and no room sub-folder with images "
            f"({', '.join(IMAGE_SUFFIXES)}): a dataset is a {MANIFEST_NAME} "
            f"(image,room,x_m,y_m,heading_deg) or one sub-folder of panoramas per room",
            folder,
        )
    return entries


def read_edges(dataset_dir: Path | str) -> list[tuple[str, str]]:
    """The room graph of a dataset: ``dataset_dir/edges.csv`` rows ``room_a,room_b``.

    The file is optional: none gives no edges. Raises :class:`ManifestError` naming the file and
    line for a missing column, an empty cell or a self-loop.
    """
    return [(a, b) for a, b, _ in read_edge_rows(dataset_dir)]


def check_edge_rooms(
    dataset_dir: Path | str, rows: list[tuple[str, str, int]], known: set[str]
) -> None:
    """A :class:`ManifestError` naming ``edges.csv``, the line and the room for the first edge
    whose room is not in ``known`` (the manifest's rooms and the map's)."""
    path = Path(dataset_dir) / EDGES_NAME
    for a, b, line in rows:
        for room in (a, b):
            if room not in known:
                raise ManifestError(
                    f"{path} line {line}: room {room!r} is in neither {MANIFEST_NAME} nor the "
                    f"map; fix the name, or pass --create-rooms to `map build` to create it",
                    path,
                )


def read_edge_rows(dataset_dir: Path | str) -> list[tuple[str, str, int]]:
    """:func:`read_edges` with the line of each edge: ``(room_a, room_b, line)``."""
    path = Path(dataset_dir) / EDGES_NAME
    if not path.is_file():
        return []
    reader = _csv_rows(path)
    try:
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
            _check_room(a, reader.line_num, path)
            _check_room(b, reader.line_num, path)
            edges.append((a, b, reader.line_num))
        return edges
    except csv.Error as error:
        raise ManifestError(f"{path} line {reader.line_num}: {error}", path) from None


_FILE_KINDS = (
    (stat.S_ISDIR, "directory"),
    (stat.S_ISFIFO, "FIFO (named pipe)"),
    (stat.S_ISCHR, "character device"),
    (stat.S_ISBLK, "block device"),
    (stat.S_ISSOCK, "socket"),
)


class NotARegularFileError(ValueError):
    """A path that names a directory, FIFO, device or socket where a file's bytes are read."""


def _check_regular(path: Path, mode: int) -> None:
    if not stat.S_ISREG(mode):
        kind = next((name for test, name in _FILE_KINDS if test(mode)), "special file")
        raise NotARegularFileError(f"{path} is a {kind}, not a regular file")


def open_regular_file(path: Path) -> BinaryIO:
    """``path`` opened for reading bytes, if it is a regular file (after symbolic links).

    Checked with ``os.stat`` before opening and again on the open descriptor (opened without
    blocking, so a FIFO swapped in meanwhile cannot hang it). Raises
    :class:`NotARegularFileError` (a ``ValueError``) naming the path and its kind, ``OSError``
    if it cannot be read.
    """
    _check_regular(path, os.stat(path).st_mode)
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    handle = os.fdopen(fd, "rb")
    try:
        _check_regular(path, os.fstat(fd).st_mode)
    except BaseException:
        handle.close()
        raise
    return handle


def sha256_file(path: Path, chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of the file's bytes (read in chunks). Raises ``OSError`` if unreadable and
    :class:`NotARegularFileError` for anything but a regular file."""
    digest = hashlib.sha256()
    with open_regular_file(path) as handle:
        while chunk := handle.read(chunk_bytes):
            digest.update(chunk)
    return digest.hexdigest()
