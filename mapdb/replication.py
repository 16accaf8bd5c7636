"""Pure encoding of a map's rows for its replicas: a snapshot, and the changes after a version.

A replica is a map file of its own that holds the same rows as the map it copies, under the
same ids (a place is the same place on every robot). What crosses the bus is :class:`MapRows`:
rows of ``rooms``, ``edges``, ``places``, ``fingerprints`` and ``legs`` in the columns of
:mod:`mapdb.schema`, and the stored likelihoods. A :class:`Snapshot` is the whole map at one
version; a :class:`MapChange` the rows one write added (a place brings its room, its
fingerprints and its leg; an edge its two rooms), so applying a change is inserting rows that
may already be there.

The encoding (:func:`encode_snapshot`, :func:`encode_changes`): ``MAGIC``, the header's length
(4 bytes, big-endian), the header as UTF-8 JSON, then the blobs (keypoints, bearings,
descriptors, keypoint sizes) one after another; a blob cell in the header is ``[offset,
length]`` into that tail (or null where a blob may be NULL). Decoding checks everything a
replica would store: the envelope, every row's columns and types, every fingerprint's blob
sizes against its keypoint count and descriptor size, and that changes come in contiguous
versions (a row of an older schema may lack its trailing optional columns); anything else is
a :class:`BadMapDataError` naming what is wrong. A large snapshot travels in chunks
(:func:`split_chunks`) joined and checked against its SHA-256 (:func:`join_chunks`). No I/O
here.
"""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from mapdb.codec import leg_from_row

MAGIC = b"toploc-map-rows\x001"
CHUNK_BYTES = 4 << 20
"""The size of a snapshot's chunks on the bus (the last one is shorter)."""

_INT, _STR, _OPT_STR, _OPT_FLOAT, _FLOAT = "int", "str", "str?", "float?", "float"
_BLOB, _OPT_BLOB = "blob", "blob?"
COLUMNS: dict[str, tuple[tuple[str, str], ...]] = {
    "rooms": (("id", _INT), ("name", _STR), ("created_utc", _STR)),
    "edges": (("room_a_id", _INT), ("room_b_id", _INT), ("created_utc", _STR)),
    "places": (
        ("id", _INT), ("room_id", _INT), ("x_m", _OPT_FLOAT), ("y_m", _OPT_FLOAT),
        ("heading_deg", _OPT_FLOAT), ("image_sha256", _STR), ("image_width_px", _INT),
        ("image_height_px", _INT), ("captured_utc", _OPT_STR), ("source", _STR),
        ("added_utc", _STR), ("camera", _STR),
    ),
    "fingerprints": (
        ("id", _INT), ("place_id", _INT), ("detector", _STR), ("n_keypoints", _INT),
        ("descriptor_dim", _INT), ("keypoints_xy", _BLOB), ("bearings_rad", _BLOB),
        ("descriptor_dtype", _STR), ("descriptors", _BLOB), ("alv_x", _FLOAT), ("alv_y", _FLOAT),
        ("params_json", _STR), ("keypoint_sizes_px", _OPT_BLOB),
    ),
    "legs": (("place_id", _INT), ("from_place_id", _INT), ("via_json", _STR)),
}  # fmt: skip
"""Each table's columns in order, with their kind (``?``: may be NULL). A row may leave out
trailing columns that may be NULL (rows of a map of an older schema): they decode as NULL."""
TABLES = tuple(COLUMNS)
DESCRIPTOR_BYTES = {"u1": 1, "f4": 4}
"""Bytes per descriptor value by the ``descriptor_dtype`` code (:mod:`mapdb.codec`)."""

Row = tuple[Any, ...]


class BadMapDataError(ValueError):
    """Map rows, a snapshot or changes that cannot be stored as they are (the message says
    what); nothing was applied."""


@dataclass(frozen=True)
class MapRows:
    """Rows of each table in :data:`COLUMNS`' order, and the stored likelihoods
    ``(detector, json_text)``."""

    rooms: tuple[Row, ...] = ()
    edges: tuple[Row, ...] = ()
    places: tuple[Row, ...] = ()
    fingerprints: tuple[Row, ...] = ()
    legs: tuple[Row, ...] = ()
    likelihoods: tuple[tuple[str, str], ...] = ()

    def table(self, name: str) -> tuple[Row, ...]:
        """The rows of table ``name`` (one of :data:`TABLES`)."""
        rows: tuple[Row, ...] = getattr(self, name)
        return rows


@dataclass(frozen=True)
class Snapshot:
    """The whole map ``map_id`` as of ``version``."""

    map_id: str
    version: int
    rows: MapRows = field(default_factory=MapRows)


@dataclass(frozen=True)
class MapChange:
    """What write ``version`` (a ``kind``: place, room, edge, likelihood) added."""

    version: int
    kind: str
    rows: MapRows = field(default_factory=MapRows)


# --- encoding -------------------------------------------------------------------------------


def _encode(header: dict[str, Any], blobs: list[bytes]) -> bytes:
    text = json.dumps(header, separators=(",", ":")).encode()
    return b"".join([MAGIC, struct.pack(">I", len(text)), text, *blobs])


class _Blobs:
    """Collects blobs and hands out their ``[offset, length]``."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.size = 0

    def add(self, blob: bytes) -> list[int]:
        self.parts.append(blob)
        self.size += len(blob)
        return [self.size - len(blob), len(blob)]


def _rows_to_json(rows: MapRows, blobs: _Blobs) -> dict[str, Any]:
    tables: dict[str, Any] = {}
    for name in TABLES:
        kinds = [kind for _, kind in COLUMNS[name]]
        tables[name] = [
            [
                blobs.add(bytes(v)) if k.startswith(_BLOB) and v is not None else v
                for v, k in zip(row, kinds, strict=True)
            ]
            for row in rows.table(name)
        ]
    tables["likelihoods"] = [list(pair) for pair in rows.likelihoods]
    return tables


def encode_snapshot(snapshot: Snapshot) -> bytes:
    """``snapshot`` as bytes (see the module docstring)."""
    blobs = _Blobs()
    header = {
        "what": "snapshot",
        "map_id": snapshot.map_id,
        "version": snapshot.version,
        "tables": _rows_to_json(snapshot.rows, blobs),
    }
    return _encode(header, blobs.parts)


def encode_changes(map_id: str, changes: Sequence[MapChange]) -> bytes:
    """The changes of map ``map_id`` as bytes, in the order given (contiguous versions)."""
    blobs = _Blobs()
    header = {
        "what": "changes",
        "map_id": map_id,
        "changes": [
            {"version": c.version, "kind": c.kind, "tables": _rows_to_json(c.rows, blobs)}
            for c in changes
        ],
    }
    return _encode(header, blobs.parts)


# --- decoding -------------------------------------------------------------------------------


def _header(data: bytes, what: str) -> tuple[dict[str, Any], memoryview]:
    """The JSON header of ``data`` (which must be a ``what``) and the blob tail."""
    if not isinstance(data, bytes | bytearray | memoryview):
        raise BadMapDataError(f"the {what} is {type(data).__name__}, not bytes")
    view = memoryview(data)
    start = len(MAGIC) + 4
    if len(view) < start or bytes(view[: len(MAGIC)]) != MAGIC:
        raise BadMapDataError(f"the {what} is not toploc map rows (no {MAGIC[:15]!r} header)")
    (length,) = struct.unpack(">I", view[len(MAGIC) : start])
    if start + length > len(view):
        raise BadMapDataError(
            f"the {what} is truncated: its header needs {start + length} bytes, it has {len(view)}"
        )
    try:
        header = json.loads(bytes(view[start : start + length]))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise BadMapDataError(f"the {what}'s header is not JSON ({error})") from None
    if not isinstance(header, dict) or header.get("what") != what:
        got = header.get("what") if isinstance(header, dict) else type(header).__name__
        raise BadMapDataError(f"expected a {what}, got {got!r}")
    if not isinstance(header.get("map_id"), str) or not header["map_id"]:
        raise BadMapDataError(f"the {what} names no map id")
    return header, view[start + length :]


def _cell(value: Any, kind: str, tail: memoryview, where: str) -> Any:
    """One decoded cell of column kind ``kind`` (a blob: its bytes from ``tail``)."""
    if value is None and kind.endswith("?"):
        return None
    if kind.startswith(_BLOB):
        ok = (
            isinstance(value, list)
            and len(value) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in value)
        )
        if not ok:
            raise BadMapDataError(f"{where}: not a blob reference [offset, length]: {value!r}")
        offset, length = value
        if offset + length > len(tail):
            raise BadMapDataError(
                f"{where}: blob at {offset} of {length} bytes lies beyond the {len(tail)} bytes "
                "received (truncated?)"
            )
        return bytes(tail[offset : offset + length])
    if value is None and kind.endswith("?"):
        return None
    base = kind.rstrip("?")
    if base == _INT:
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif base == _FLOAT:
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        value = float(value) if ok else value
    else:
        ok = isinstance(value, str)
    if not ok:
        raise BadMapDataError(f"{where}: expected {kind}, got {value!r}")
    return value


def check_fingerprint_row(row: Row, where: str) -> None:
    """Raise :class:`BadMapDataError` unless ``row`` (a ``fingerprints`` row) decodes: known
    descriptor code, blob sizes that match its keypoint count and descriptor size (the sizes'
    blob may be NULL), parameters that are a JSON object."""
    columns = dict(zip((name for name, _ in COLUMNS["fingerprints"]), row, strict=True))
    n, dim, code = columns["n_keypoints"], columns["descriptor_dim"], columns["descriptor_dtype"]
    where = f"{where} (fingerprint {columns['id']}, place {columns['place_id']})"
    if n < 0 or dim < 0:
        raise BadMapDataError(f"{where}: negative size {n} x {dim}")
    if code not in DESCRIPTOR_BYTES:
        raise BadMapDataError(f"{where}: unknown descriptor code {code!r} (u1 or f4)")
    expected = {
        "keypoints_xy": n * 2 * 4,
        "bearings_rad": n * 8,
        "descriptors": n * dim * DESCRIPTOR_BYTES[code],
        "keypoint_sizes_px": n * 4,
    }
    for name, size in expected.items():
        if columns[name] is not None and len(columns[name]) != size:
            raise BadMapDataError(
                f"{where}: its {name} blob has {len(columns[name])} bytes, {size} expected for "
                f"{n} keypoints" + (f" of {dim} {code}" if name == "descriptors" else "")
            )
    try:
        params = json.loads(columns["params_json"])
    except json.JSONDecodeError as error:
        raise BadMapDataError(f"{where}: params_json is not JSON ({error})") from None
    if not isinstance(params, dict):
        raise BadMapDataError(f"{where}: params_json is not a JSON object")


def _rows_from_json(tables: Any, tail: memoryview, where: str) -> MapRows:
    if not isinstance(tables, dict):
        raise BadMapDataError(f"{where}: no tables")
    decoded: dict[str, tuple[Row, ...]] = {}
    for name in TABLES:
        columns = COLUMNS[name]
        rows = tables.get(name, [])
        if not isinstance(rows, list):
            raise BadMapDataError(f"{where}: table {name} is not a list of rows")
        out = []
        for i, row in enumerate(rows):
            at = f"{where}: {name} row {i}"
            if isinstance(row, list) and all(k.endswith("?") for _, k in columns[len(row) :]):
                row = row + [None] * (len(columns) - len(row))  # an older schema's row
            if not isinstance(row, list) or len(row) != len(columns):
                raise BadMapDataError(f"{at}: expected {len(columns)} columns, got {row!r:.60}")
            cells = tuple(
                _cell(v, kind, tail, f"{at} column {column}")
                for v, (column, kind) in zip(row, columns, strict=True)
            )
            if name == "fingerprints":
                check_fingerprint_row(cells, at)
            if name == "legs":
                try:
                    leg_from_row(cells[1], cells[2])
                except ValueError as error:
                    raise BadMapDataError(f"{at}: {error}") from None
            out.append(cells)
        decoded[name] = tuple(out)
    likelihoods = tables.get("likelihoods", [])
    pairs = []
    for pair in likelihoods if isinstance(likelihoods, list) else [likelihoods]:
        if not (
            isinstance(pair, list) and len(pair) == 2 and all(isinstance(v, str) for v in pair)
        ):
            raise BadMapDataError(f"{where}: a likelihood is not [detector, json]: {pair!r:.60}")
        pairs.append((pair[0], pair[1]))
    return MapRows(**decoded, likelihoods=tuple(pairs))


def _version(value: Any, where: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise BadMapDataError(f"{where}: version {value!r} is not a whole number >= 0")
    return value


def decode_snapshot(data: bytes) -> Snapshot:
    """The snapshot in ``data``; :class:`BadMapDataError` if any part of it is not right."""
    header, tail = _header(data, "snapshot")
    version = _version(header.get("version"), "the snapshot")
    rows = _rows_from_json(header.get("tables"), tail, f"snapshot of version {version}")
    return Snapshot(header["map_id"], version, rows)


def decode_changes(data: bytes) -> tuple[str, tuple[MapChange, ...]]:
    """The map id and the changes in ``data``, checked to come in contiguous versions."""
    header, tail = _header(data, "changes")
    items = header.get("changes")
    if not isinstance(items, list):
        raise BadMapDataError("the changes hold no list of changes")
    changes: list[MapChange] = []
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            raise BadMapDataError(f"change {i} is not an object")
        version = _version(item.get("version"), f"change {i}")
        if changes and version != changes[-1].version + 1:
            raise BadMapDataError(
                f"change out of order: version {version} after {changes[-1].version}"
            )
        kind = item.get("kind")
        if not isinstance(kind, str):
            raise BadMapDataError(f"change {version} has no kind")
        changes.append(MapChange(version, kind, _rows_from_json(item.get("tables"), tail,
                                                                 f"change {version}")))  # fmt: skip
    return header["map_id"], tuple(changes)


# --- chunks ---------------------------------------------------------------------------------


def sha256_hex(data: bytes) -> str:
    """The SHA-256 of ``data`` as hex text."""
    return hashlib.sha256(data).hexdigest()


def split_chunks(data: bytes, chunk_bytes: int = CHUNK_BYTES) -> list[bytes]:
    """``data`` in pieces of at most ``chunk_bytes`` (one empty piece for empty data)."""
    if chunk_bytes <= 0:
        raise ValueError(f"chunk_bytes must be positive, got {chunk_bytes}")
    return [data[i : i + chunk_bytes] for i in range(0, len(data), chunk_bytes)] or [b""]


def join_chunks(chunks: Mapping[int, bytes], n_chunks: int, sha256: str, what: str) -> bytes:
    """Chunks ``0 .. n_chunks - 1`` joined, checked against ``sha256``; a missing chunk or a
    checksum that differs is a :class:`BadMapDataError` naming ``what``."""
    missing = [i for i in range(n_chunks) if i not in chunks]
    if missing:
        raise BadMapDataError(
            f"{what} is truncated: {len(missing)} of {n_chunks} chunks missing (first {missing[0]})"
        )
    data = b"".join(chunks[i] for i in range(n_chunks))
    if sha256_hex(data) != sha256:
        raise BadMapDataError(f"{what}: SHA-256 {sha256_hex(data)[:12]}... is not {sha256[:12]}...")
    return data
