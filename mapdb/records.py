"""Plain dataclasses for what goes into and comes out of the map database: places, rooms and
the fingerprints of panoramas (pure: numpy only, no SQLite), shared by every layer above.

Positions are in metres and headings in degrees, in the metric frame of the place's own room
(REP-103: x forward, y left, CCW positive); ``None`` means unknown. A place recorded on a drive
(its :class:`Leg`) shares one odometry frame with the place the drive came from. Times are
ISO-8601 UTC text.
"""

from __future__ import annotations

import math
import unicodedata
from collections.abc import Mapping, Sequence
from dataclasses import InitVar, asdict, dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from homing.cameras import CameraModel, ParamValue, camera_from_params, rays_from_keypoints

MAX_NAME_CHARS = 128
"""The longest name the map stores, in characters: room names, and every other name-like
string (detector, camera model). A name appears in one-line messages, bus replies, GraphML and
the belief's JSON; 128 is far above any real room name and far below what hurts them."""


def _shown(text: str, chars: int = 24) -> str:
    """``repr`` of ``text``, cut to ``chars`` characters for a one-line message."""
    return repr(text) if len(text) <= chars else repr(text[:chars]) + "…"


def check_name(name: str, what: str = "room name") -> str:
    """``name`` if it is a usable name, else ``ValueError`` saying why (naming ``what``).

    Usable: not blank, at most :data:`MAX_NAME_CHARS` characters, no control characters (a
    newline would split a one-line message or a CSV row).
    """
    if not name.strip():
        raise ValueError(f"{what} must not be empty, got {name!r}")
    if len(name) > MAX_NAME_CHARS:
        raise ValueError(
            f"{what} {_shown(name)} has {len(name)} characters, more than {MAX_NAME_CHARS}"
        )
    if any(unicodedata.category(char) == "Cc" for char in name):
        raise ValueError(f"{what} {_shown(name)} has a control character")
    return name


def check_finite(value: float | None, what: str) -> None:
    """``ValueError`` naming ``what`` unless ``value`` is ``None`` (unknown) or finite."""
    if value is not None and not math.isfinite(value):
        raise ValueError(f"{what} must be a finite number or unknown, got {value!r}")


MAX_VIA_POINTS = 10_000
"""The most odometry positions a :class:`Leg` holds (a drive of kilometres at 0.1 m)."""


@dataclass(frozen=True)
class Leg:
    """How the robot came to a place on one drive: from place ``from_place``, through the
    odometry positions ``via_xy_m`` (metres, in order, the ends excluded). The place's pose,
    ``from_place``'s pose and ``via_xy_m`` are in one frame, the odometry's on that drive
    (``toploc map record`` stores them; the active localizer drives a recorded route back).

    Raises ``ValueError`` for a place id below 1, a via point that is not two finite numbers,
    or more than :data:`MAX_VIA_POINTS` of them."""

    from_place: int
    via_xy_m: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        if isinstance(self.from_place, bool) or not isinstance(self.from_place, int):
            raise ValueError(f"leg from_place must be a place id, got {self.from_place!r}")
        if self.from_place < 1:
            raise ValueError(f"leg from_place must be a place id >= 1, got {self.from_place}")
        if len(self.via_xy_m) > MAX_VIA_POINTS:
            raise ValueError(f"leg has {len(self.via_xy_m)} via points, more than {MAX_VIA_POINTS}")
        points = []
        for i, point in enumerate(self.via_xy_m):
            if len(point) != 2 or not all(
                isinstance(v, int | float) and math.isfinite(v) for v in point
            ):
                raise ValueError(f"leg via point {i} must be two finite numbers, got {point!r}")
            points.append((float(point[0]), float(point[1])))
        object.__setattr__(self, "via_xy_m", tuple(points))


@dataclass(frozen=True)
class NewPlace:
    """A panorama about to be added: where it was taken and where its image came from.

    Raises ``ValueError`` for a room name :func:`check_name` refuses, a coordinate or heading
    that is NaN or infinite, or a malformed hash: nothing unreadable reaches the map.
    """

    room: str
    image_sha256: str
    source: str
    x_m: float | None = None
    y_m: float | None = None
    heading_deg: float | None = None
    captured_utc: str | None = None
    leg: Leg | None = None

    def __post_init__(self) -> None:
        check_name(self.room)
        check_finite(self.x_m, "x_m")
        check_finite(self.y_m, "y_m")
        check_finite(self.heading_deg, "heading_deg")
        if len(self.image_sha256) != 64:
            raise ValueError(f"image_sha256 must be 64 hex digits, got {self.image_sha256!r}")
        if self.leg is not None and (self.x_m is None or self.y_m is None):
            raise ValueError("a place with a leg needs its odometry position (x_m and y_m)")


@dataclass(frozen=True)
class Place:
    """A stored place (one panorama) of the map: its id, room and pose in the room's frame
    (``None`` where unknown), the panorama's bookkeeping (empty where not read from a map
    database, e.g. in a test or a simulation) and the drive it was recorded on (``leg``; then
    the pose is in that drive's odometry frame)."""

    id: int
    room: str
    x_m: float | None = None
    y_m: float | None = None
    heading_deg: float | None = None
    image_sha256: str = ""
    image_width_px: int = 0
    image_height_px: int = 0
    captured_utc: str | None = None
    source: str = ""
    added_utc: str = ""
    camera: str = "cylinder"
    leg: Leg | None = None

    @property
    def xy_m(self) -> tuple[float, float] | None:
        """``(x_m, y_m)`` in the room's frame, or ``None`` when either is unknown."""
        if self.x_m is None or self.y_m is None:
            return None
        return (float(self.x_m), float(self.y_m))


@dataclass(frozen=True)
class RoomSummary:
    """A room and how many places it has."""

    id: int
    name: str
    n_places: int


@dataclass(frozen=True)
class MapInfo:
    """An overview of a map database, for ``toploc map info``."""

    path: Path
    schema_version: int
    file_size_bytes: int
    rooms: list[RoomSummary]
    edges: list[tuple[str, str]]
    fingerprints_per_detector: dict[str, int] = field(default_factory=dict)
    likelihoods: dict[str, dict[str, Any]] = field(default_factory=dict)
    fingerprints_without_sizes: int = 0
    """Fingerprints stored before schema 5, without their keypoints' sizes."""

    @property
    def n_places(self) -> int:
        """Number of places over all rooms."""
        return sum(room.n_places for room in self.rooms)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (paths as text, edges as two-item lists)."""
        data = asdict(self)
        data["path"] = str(self.path)
        data["edges"] = [list(edge) for edge in self.edges]
        data["n_places"] = self.n_places
        return data


@dataclass(frozen=True)
class Fingerprint:
    """Features of one panorama found by one detector.

    ``keypoints_xy`` are OpenCV pixel coordinates (x right, y down; pixel centres at integers) on
    the cylindrical panorama of ``image_width_px`` x ``image_height_px``. ``bearings_rad`` are
    robot-frame azimuths (REP-103: counter-clockwise positive, 0 along the heading), which for a
    cylindrical panorama is ``-2*pi*x/W`` wrapped to (-pi, pi]. ``descriptors`` are float32 rows
    (128 values for SIFT). ``params`` records how they were extracted (for the map database),
    among them the camera model (:func:`homing.cameras.camera_from_params`).
    ``keypoint_sizes_px`` are the keypoints' diameters (px on that panorama, as the detector
    gives them: a feature seen nearer is larger), None where they are not known (places stored
    before schema version 5, see :mod:`mapdb.schema`).

    ``camera`` is the panorama's camera model (:mod:`homing.cameras`), built once: the
    ``camera_model`` given (the one the extraction used; it must be of the image's size), else
    the one ``params`` record.
    """

    detector: str
    image_width_px: int
    image_height_px: int
    keypoints_xy: np.ndarray
    bearings_rad: np.ndarray
    descriptors: np.ndarray
    params: Mapping[str, ParamValue] = field(default_factory=dict)
    keypoint_sizes_px: np.ndarray | None = None
    camera_model: InitVar[CameraModel | None] = None
    camera: CameraModel = field(init=False, repr=False, compare=False)

    def __post_init__(self, camera_model: CameraModel | None) -> None:
        if camera_model is None:
            camera_model = camera_from_params(
                self.image_width_px, self.image_height_px, self.params
            )
        elif (camera_model.width_px, camera_model.height_px) != (
            self.image_width_px,
            self.image_height_px,
        ):
            raise ValueError(
                f"{camera_model.kind} camera is {camera_model.width_px}x{camera_model.height_px}"
                f" px but the fingerprint's panorama is {self.image_width_px}x"
                f"{self.image_height_px} px"
            )
        object.__setattr__(self, "camera", camera_model)
        n = len(self.bearings_rad)
        if self.keypoints_xy.shape != (n, 2):
            raise ValueError(
                f"keypoints_xy must have shape ({n}, 2) to match {n} bearings, "
                f"got {self.keypoints_xy.shape}"
            )
        if len(self.descriptors) != n:
            raise ValueError(f"descriptors has {len(self.descriptors)} rows for {n} bearings")
        if self.keypoint_sizes_px is not None and np.shape(self.keypoint_sizes_px) != (n,):
            raise ValueError(
                f"keypoint_sizes_px must have shape ({n},) to match {n} bearings, "
                f"got {np.shape(self.keypoint_sizes_px)}"
            )

    @property
    def n(self) -> int:
        """Number of keypoints."""
        return len(self.bearings_rad)

    @classmethod
    def empty(
        cls,
        detector: str,
        image_width_px: int,
        image_height_px: int,
        descriptor_size: int = 128,
        params: Mapping[str, ParamValue] | None = None,
    ) -> Fingerprint:
        """A fingerprint with no keypoints (e.g. a blank wall): 0 rows, float32 descriptors."""
        return cls(
            detector=detector,
            image_width_px=image_width_px,
            image_height_px=image_height_px,
            keypoints_xy=np.zeros((0, 2), dtype=np.float64),
            bearings_rad=np.zeros(0, dtype=np.float64),
            descriptors=np.zeros((0, descriptor_size), dtype=np.float32),
            params=dict(params or {}),
            keypoint_sizes_px=np.zeros(0, dtype=np.float32),
        )

    def select(self, mask: np.ndarray) -> Fingerprint:
        """The keypoints where boolean ``mask`` (or an index array) selects, other fields kept."""
        mask = np.asarray(mask)
        if mask.dtype == bool and mask.shape != (self.n,):
            raise ValueError(f"boolean mask must have shape ({self.n},), got {mask.shape}")
        return replace(
            self,
            keypoints_xy=self.keypoints_xy[mask],
            bearings_rad=self.bearings_rad[mask],
            descriptors=self.descriptors[mask],
            keypoint_sizes_px=None
            if self.keypoint_sizes_px is None
            else self.keypoint_sizes_px[mask],
            camera_model=self.camera,
        )

    def keypoint_sizes_rad(self) -> np.ndarray | None:
        """The keypoints' sizes as angles (radians: px times 2 pi over the panorama's width, the
        horizontal scale of every camera model here), comparable between panoramas of different
        widths; None where not known."""
        if self.keypoint_sizes_px is None:
            return None
        return np.asarray(self.keypoint_sizes_px, dtype=np.float64) * (
            2.0 * np.pi / self.image_width_px
        )

    def rays(self) -> np.ndarray:
        """(n, 3) float64 unit rays (robot frame, REP-103) of the keypoints through this
        fingerprint's own camera, row ``i`` for keypoint ``i``; (0, 3) when empty."""
        return rays_from_keypoints(self.keypoints_xy, self.bearings_rad, self.camera)


@dataclass(frozen=True)
class StoredFingerprint:
    """A fingerprint with the place and room it belongs to and its stored ALV (robot frame)."""

    place_id: int
    room: str
    alv_xy: tuple[float, float]
    fingerprint: Fingerprint


@dataclass(frozen=True)
class FingerprintTable:
    """All fingerprints of one detector, stacked; place ``i`` owns rows ``offsets[i]:offsets[i+1]``.

    ``keypoints_xy`` (N, 2) float32 px, ``bearings_rad`` (N,) float64, ``descriptors`` (N, d)
    float32, ``alv_xy`` (m, 2) float64, ``place_ids`` (m,) int64, ``rooms`` one name per place,
    ``image_sizes_px`` (m, 2) int64 ``(width, height)`` of each place's panorama, ``params`` each
    place's extraction parameters, ``keypoint_place_index`` (N,) index into ``place_ids`` of each
    row, ``keypoint_sizes_px`` (N,) float32 the keypoints' diameters (NaN for a place whose sizes
    are not known; None when no place's are).
    """

    detector: str
    place_ids: np.ndarray
    rooms: tuple[str, ...]
    offsets: np.ndarray
    keypoints_xy: np.ndarray
    bearings_rad: np.ndarray
    descriptors: np.ndarray
    alv_xy: np.ndarray
    image_sizes_px: np.ndarray
    params: tuple[Mapping[str, ParamValue], ...]
    keypoint_sizes_px: np.ndarray | None = None

    def __post_init__(self) -> None:
        m = len(self.place_ids)
        if len(self.offsets) != m + 1 or len(self.rooms) != m or len(self.params) != m:
            raise ValueError(
                f"{m} places need {m + 1} offsets, {m} rooms and {m} params, got "
                f"{len(self.offsets)}, {len(self.rooms)} and {len(self.params)}"
            )
        if np.shape(self.image_sizes_px) != (m, 2):
            raise ValueError(
                f"image_sizes_px must have shape ({m}, 2), got {np.shape(self.image_sizes_px)}"
            )

    @classmethod
    def stack(
        cls,
        detector: str,
        place_ids: Sequence[int],
        rooms: Sequence[str],
        fingerprints: Sequence[Fingerprint],
        alv_xy: np.ndarray | None = None,
    ) -> FingerprintTable:
        """The table of ``fingerprints`` (one per place, all of ``detector``), in that order;
        ``alv_xy`` (m, 2) defaults to zeros. Built in memory, e.g. for an experiment."""
        if not len(place_ids) == len(rooms) == len(fingerprints):
            raise ValueError(
                f"{len(place_ids)} place ids, {len(rooms)} rooms and {len(fingerprints)} "
                f"fingerprints must match"
            )
        if any(fp.detector != detector for fp in fingerprints):
            raise ValueError(f"every fingerprint must be of detector {detector!r}")
        offsets = np.zeros(len(fingerprints) + 1, dtype=np.int64)
        np.cumsum([fp.n for fp in fingerprints], out=offsets[1:])
        dim = fingerprints[0].descriptors.shape[1] if fingerprints else 128
        return cls(
            detector=detector,
            place_ids=np.asarray(place_ids, dtype=np.int64),
            rooms=tuple(rooms),
            offsets=offsets,
            keypoints_xy=np.concatenate(
                [fp.keypoints_xy for fp in fingerprints] or [np.zeros((0, 2))]
            ).astype(np.float32),
            bearings_rad=np.concatenate([fp.bearings_rad for fp in fingerprints] or [np.zeros(0)]),
            descriptors=np.concatenate(
                [fp.descriptors for fp in fingerprints] or [np.zeros((0, dim))]
            ).astype(np.float32),
            alv_xy=np.zeros((len(fingerprints), 2)) if alv_xy is None else np.asarray(alv_xy),
            image_sizes_px=np.array(
                [(fp.image_width_px, fp.image_height_px) for fp in fingerprints], dtype=np.int64
            ).reshape(-1, 2),
            params=tuple(fp.params for fp in fingerprints),
            keypoint_sizes_px=stacked_sizes_px(
                [fp.keypoint_sizes_px for fp in fingerprints], [fp.n for fp in fingerprints]
            ),
        )

    @cached_property
    def cameras(self) -> tuple[CameraModel, ...]:
        """Each place's camera model, from its image size and extraction parameters (built
        once per table)."""
        return tuple(
            camera_from_params(int(w), int(h), params)
            for (w, h), params in zip(self.image_sizes_px, self.params, strict=True)
        )

    @property
    def keypoint_place_index(self) -> np.ndarray:
        """For each stacked row, the index of its place in ``place_ids``."""
        return np.repeat(np.arange(len(self.place_ids)), np.diff(self.offsets))

    @cached_property
    def keypoint_counts(self) -> np.ndarray:
        """(m,) int64 keypoints of each place."""
        return np.diff(self.offsets).astype(np.int64)

    @property
    def descriptor_dim(self) -> int:
        """Values per descriptor (0 for an empty table)."""
        return int(self.descriptors.shape[1]) if self.descriptors.ndim == 2 else 0

    def fingerprints(self, indices: Sequence[int] | np.ndarray) -> list[Fingerprint]:
        """The fingerprints of the places at ``indices``, in that order (:meth:`fingerprint`)."""
        return [self.fingerprint(int(i)) for i in indices]

    def rows(self, i: int) -> slice:
        """The stacked rows of the place at index ``i``."""
        return slice(int(self.offsets[i]), int(self.offsets[i + 1]))

    def rays(self) -> np.ndarray:
        """(N, 3) float64 unit rays (robot frame, REP-103) of every stacked keypoint, each place
        through its own camera (:attr:`cameras`); row ``r`` for the table's row ``r``."""
        rays = np.zeros((len(self.bearings_rad), 3))
        for i, camera in enumerate(self.cameras):
            rows = self.rows(i)
            rays[rows] = rays_from_keypoints(
                self.keypoints_xy[rows], self.bearings_rad[rows], camera
            )
        return rays

    def fingerprint(self, i: int) -> Fingerprint:
        """The fingerprint of the place at index ``i`` (views into the stacked arrays)."""
        rows = self.rows(i)
        width, height = (int(v) for v in self.image_sizes_px[i])
        return Fingerprint(
            detector=self.detector,
            image_width_px=width,
            image_height_px=height,
            keypoints_xy=self.keypoints_xy[rows],
            bearings_rad=self.bearings_rad[rows],
            descriptors=self.descriptors[rows],
            params=self.params[i],
            keypoint_sizes_px=known_sizes_px(self.keypoint_sizes_px, rows),
            camera_model=self.cameras[i],
        )

    def subset(self, places: Sequence[int] | np.ndarray) -> FingerprintTable:
        """The table restricted to the place indices ``places``, in that order."""
        indices = np.asarray(places, dtype=np.int64).reshape(-1)
        spans = [np.arange(self.offsets[i], self.offsets[i + 1]) for i in indices]
        rows = np.concatenate(spans) if spans else np.zeros(0, dtype=np.int64)
        offsets = np.zeros(len(indices) + 1, dtype=np.int64)
        np.cumsum(np.diff(self.offsets)[indices], out=offsets[1:])
        return FingerprintTable(
            detector=self.detector,
            place_ids=self.place_ids[indices],
            rooms=tuple(self.rooms[i] for i in indices),
            offsets=offsets,
            keypoints_xy=self.keypoints_xy[rows],
            bearings_rad=self.bearings_rad[rows],
            descriptors=np.ascontiguousarray(self.descriptors[rows]),
            alv_xy=self.alv_xy[indices],
            image_sizes_px=self.image_sizes_px[indices],
            params=tuple(self.params[i] for i in indices),
            keypoint_sizes_px=None
            if self.keypoint_sizes_px is None
            else self.keypoint_sizes_px[rows],
        )


def stacked_sizes_px(
    sizes: Sequence[np.ndarray | None], counts: Sequence[int]
) -> np.ndarray | None:
    """The keypoint sizes of places with ``counts`` keypoints each, stacked as float32 with NaN
    for a place whose sizes are None; None when none are known. ``ValueError`` if a place's
    sizes are not one per keypoint."""
    if all(s is None for s in sizes):
        return None
    for i, (s, n) in enumerate(zip(sizes, counts, strict=True)):
        if s is not None and len(s) != n:
            raise ValueError(f"place {i} has {len(s)} keypoint sizes for {n} keypoints")
    parts = [
        np.full(n, np.nan, np.float32) if s is None else np.asarray(s, np.float32)
        for s, n in zip(sizes, counts, strict=True)
    ]
    return np.concatenate(parts) if parts else np.zeros(0, np.float32)


def known_sizes_px(stacked: np.ndarray | None, rows: slice) -> np.ndarray | None:
    """The sizes of one place's ``rows`` of a stack (:func:`stacked_sizes_px`); None if its
    sizes are not known."""
    if stacked is None:
        return None
    sizes = stacked[rows]
    return None if np.isnan(sizes).any() else sizes


class PlaceStore(Protocol):
    """Where a localizer reads one detector's stored places from: compact per-place metadata
    held in memory (the same fields as :class:`FingerprintTable`'s, place ``i`` of each), the
    full fingerprints read on demand.

    :class:`FingerprintTable` is the store in memory (small maps, tests);
    :class:`mapdb.store.SqlitePlaceStore` reads them from the SQLite map, keeping a few.
    """

    @property
    def detector(self) -> str: ...

    @property
    def place_ids(self) -> np.ndarray: ...

    @property
    def rooms(self) -> tuple[str, ...]: ...

    @property
    def alv_xy(self) -> np.ndarray: ...

    @property
    def image_sizes_px(self) -> np.ndarray: ...

    @property
    def params(self) -> tuple[Mapping[str, ParamValue], ...]: ...

    @property
    def keypoint_counts(self) -> np.ndarray:
        """(m,) int64 keypoints of each place."""
        ...

    @property
    def descriptor_dim(self) -> int:
        """Values per descriptor (0 for an empty store)."""
        ...

    def fingerprint(self, i: int) -> Fingerprint:
        """The full fingerprint of the place at index ``i``."""
        ...

    def fingerprints(self, indices: Sequence[int] | np.ndarray) -> list[Fingerprint]:
        """The full fingerprints of the places at ``indices``, in that order."""
        ...


@dataclass(frozen=True)
class MapSnapshot:
    """What a localizer reads from a map once at start-up: one detector's fingerprints (stacked
    in memory, or a store reading them from the map on demand),
    the places that have one, the rooms that have such places, the room graph, and the
    likelihood calibrated on that detector's evidence (JSON; None if the map has none)."""

    path: Path
    table: PlaceStore
    places: tuple[Place, ...]
    rooms: tuple[str, ...]
    edges: tuple[tuple[str, str], ...]
    likelihood: Mapping[str, Any] | None = None
