"""Fixtures for the map database tests: map files, filled maps and datasets."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from mapdb_fake_extractor import fake_extract
from mapdb_helpers import make_fingerprint, new_place, write_image

from mapdb.database import MapDatabase


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


@pytest.fixture
def fake_extractor(monkeypatch: pytest.MonkeyPatch) -> None:
    """``toploc map`` run in this process extracts with ``mapdb_fake_extractor.fake_extract``."""
    from toploc import extraction

    monkeypatch.setattr(extraction, "extract_panorama", fake_extract)


@pytest.fixture
def db_path(tmp_path: Path) -> Path:
    return tmp_path / "map.db"


@pytest.fixture
def map_db(db_path: Path) -> Iterator[MapDatabase]:
    with MapDatabase.open(db_path) as opened:
        yield opened


@pytest.fixture
def filled_map(map_db: MapDatabase, rng: np.random.Generator) -> MapDatabase:
    """Kitchen (2 places), hall (1 place), an edge kitchen-hall; sift and mser each."""
    for index, room in enumerate(["kitchen", "kitchen", "hall"]):
        fingerprints = [make_fingerprint(rng, "sift", 12), make_fingerprint(rng, "mser", 7)]
        map_db.add_place(new_place(room, index), fingerprints)
    map_db.connect_rooms("kitchen", "hall")
    return map_db


DatasetMaker = Callable[..., Path]


@pytest.fixture
def make_dataset(tmp_path: Path) -> DatasetMaker:
    """``make_dataset(n, rooms=..., corrupt=(...), name=...)``: a folder with a manifest."""

    def make(
        n: int,
        rooms: tuple[str, ...] = ("kitchen", "hall", "office"),
        corrupt: tuple[int, ...] = (),
        name: str = "dataset",
    ) -> Path:
        folder = tmp_path / name
        lines = ["image,room,x_m,y_m,heading_deg"]
        for i in range(n):
            image = folder / "img" / f"pano_{i:03d}.png"
            if i in corrupt:
                image.parent.mkdir(parents=True, exist_ok=True)
                image.write_bytes(b"\x89PNG\r\n\x1a\n this is not really a png")
            else:
                write_image(image, seed=i)
            pose = f"{i * 0.5},{-i * 0.25},{i * 10.0}" if i % 3 else ",,"
            lines.append(f"img/pano_{i:03d}.png,{rooms[i % len(rooms)]},{pose}")
        (folder / "manifest.csv").write_text("\n".join(lines) + "\n")
        return folder

    return make
