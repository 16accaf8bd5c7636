"""Plain dataclasses for what goes into and comes out of the map database.

Positions are in metres and headings in degrees, in the metric frame of the place's own room
(REP-103: x forward, y left, CCW positive); ``None`` means unknown. Times are ISO-8601 UTC text.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class NewPlace:
    """A panorama about to be added: where it was taken and where its image came from."""

    room: str
    image_sha256: str
    source: str
    x_m: float | None = None
    y_m: float | None = None
    heading_deg: float | None = None
    captured_utc: str | None = None

    def __post_init__(self) -> None:
        if not self.room.strip():
            raise ValueError(f"room name must not be empty, got {self.room!r}")
        if len(self.image_sha256) != 64:
            raise ValueError(f"image_sha256 must be 64 hex digits, got {self.image_sha256!r}")


@dataclass(frozen=True)
class Place:
    """A stored place (one panorama) of the map."""

    id: int
    room: str
    x_m: float | None
    y_m: float | None
    heading_deg: float | None
    image_sha256: str
    image_width_px: int
    image_height_px: int
    captured_utc: str | None
    source: str
    added_utc: str


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
