"""The real 360° photos shipped with toploc (package data) and their box rooms.

``robot/data/photos/`` holds the 17 indoor equirectangular photos (1024 x 512 JPEG) of Poly
Haven's HDRI library (CC0 1.0, tone mapped from the 1k HDRs; see its README.md) and
``manifest.csv``, which gives each its box room: size, height and capture point in metres
(:class:`~robot.photo_room.PhotoRoom`). They are read with :mod:`importlib.resources`, so they
work from an installed wheel as from a checkout.
"""

from __future__ import annotations

import csv
import dataclasses
import io
from functools import cache
from importlib import resources
from importlib.abc import Traversable

import cv2
import numpy as np

from robot.photo_room import PhotoRoom


def _photo_dir() -> Traversable:
    return resources.files("robot") / "data" / "photos"


@cache
def _manifest() -> dict[str, tuple[str, PhotoRoom]]:
    """Room name -> (image file name, box room), in manifest order."""
    text = (_photo_dir() / "manifest.csv").read_text(encoding="utf-8")
    rooms: dict[str, tuple[str, PhotoRoom]] = {}
    for row in csv.DictReader(io.StringIO(text)):
        room = PhotoRoom(
            row["room"],
            (float(row["size_x_m"]), float(row["size_y_m"])),
            float(row["height_m"]),
            (float(row["capture_x_m"]), float(row["capture_y_m"])),
        )
        rooms[row["room"]] = (row["image"], room)
    return rooms


def photo_room_names() -> tuple[str, ...]:
    """Names of the shipped photo rooms (Poly Haven asset names), in manifest order."""
    return tuple(_manifest())


def _entry(name: str) -> tuple[str, PhotoRoom]:
    try:
        return _manifest()[name]
    except KeyError:
        known = ", ".join(photo_room_names())
        raise ValueError(f"unknown photo room {name!r}; known photo rooms: {known}") from None


def photo_room(name: str, **overrides: object) -> PhotoRoom:
    """The box room of photo ``name``, with fields replaced by ``overrides`` (e.g.
    ``size_m=(5.0, 4.0)``, ``capture_m=(2.0, 2.0)``); ``ValueError`` for unknown names."""
    return dataclasses.replace(_entry(name)[1], **overrides)  # type: ignore[arg-type]


@cache
def load_photo(name: str) -> np.ndarray:
    """The (512, 1024, 3) uint8 RGB equirectangular photo of room ``name`` (read-only)."""
    data = (_photo_dir() / _entry(name)[0]).read_bytes()
    bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"photo of {name!r} could not be decoded")
    rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    rgb.setflags(write=False)
    return rgb
