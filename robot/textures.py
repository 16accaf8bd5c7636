"""Surface textures for the rendered world: real photographs shipped with scikit-image, plain
colours, and procedural paint, wood, tiles, windows and doors (:mod:`robot.procedural_textures`).

Every texture is a square RGB tile of ``TEXTURE_SIZE_PX`` texels (photographs are centre-cropped
to a square, then resized) with a mip-map pyramid of ``MIP_LEVELS`` levels, each half the size of
the one before. Texel row 0 is the top of the picture. A :class:`TextureAtlas` packs the pyramids
of the textures one world uses into one flat texel array, so the renderer looks up every pixel
with a single gather.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import cache

import numpy as np

from robot.procedural_textures import PROCEDURAL_TEXTURES, procedural_texture

TEXTURE_SIZE_PX = 512
MIP_LEVELS = 7

# Photographs (and a few scans) from ``skimage.data``, by texture name -> loader name.
_PHOTOS: dict[str, str] = {
    "astronaut": "astronaut",
    "brick": "brick",
    "camera": "camera",
    "cat": "cat",
    "chelsea": "chelsea",
    "clock": "clock",
    "coffee": "coffee",
    "coins": "coins",
    "colorwheel": "colorwheel",
    "grass": "grass",
    "gravel": "gravel",
    "hubble": "hubble_deep_field",
    "cells": "immunohistochemistry",
    "logo": "logo",
    "moon": "moon",
    "page": "page",
    "retina": "retina",
    "rocket": "rocket",
    "text": "text",
}

# Plain colours (RGB), for ceilings, test landmarks and painted surfaces.
_PLAIN: dict[str, tuple[int, int, int]] = {
    "white": (232, 230, 224),
    "grey": (128, 128, 128),
    "black": (16, 16, 16),
    "red": (210, 32, 32),
    "green": (40, 170, 60),
    "blue": (40, 70, 200),
    "yellow": (230, 210, 40),
}

PHOTO_TEXTURES: tuple[str, ...] = tuple(sorted(_PHOTOS))
PLAIN_TEXTURES: tuple[str, ...] = tuple(sorted(_PLAIN))
TEXTURE_NAMES: tuple[str, ...] = tuple(sorted((*_PHOTOS, *_PLAIN, *PROCEDURAL_TEXTURES)))


def check_texture_name(name: str) -> None:
    """Raise ``ValueError`` naming ``name`` if it is not a known texture."""
    if name not in TEXTURE_NAMES:
        raise ValueError(f"unknown texture {name!r}; known textures: {', '.join(TEXTURE_NAMES)}")


def _load_rgb(name: str) -> np.ndarray:
    """The source picture of texture ``name`` as an (h, w, 3) uint8 RGB array."""
    if name in _PLAIN:
        return np.broadcast_to(np.array(_PLAIN[name], np.uint8), (8, 8, 3)).copy()
    if name in PROCEDURAL_TEXTURES:
        return procedural_texture(name, TEXTURE_SIZE_PX)
    import skimage.data  # imported lazily: it is slow to import and only needed here

    loader: Callable[[], np.ndarray] = getattr(skimage.data, _PHOTOS[name])
    image = np.asarray(loader())
    if image.dtype == bool:
        image = image.astype(np.uint8) * 255
    if image.ndim == 2:
        image = np.repeat(image[:, :, None], 3, axis=2)
    return np.ascontiguousarray(image[:, :, :3].astype(np.uint8))


def _square(image: np.ndarray, size_px: int) -> np.ndarray:
    """Centre-crop ``image`` to a square and resize it to ``size_px`` x ``size_px``."""
    import cv2  # imported here so that listing worlds (e.g. for the CLI) stays light

    h, w = image.shape[:2]
    side = min(h, w)
    top, left = (h - side) // 2, (w - side) // 2
    crop = image[top : top + side, left : left + side]
    interpolation = cv2.INTER_AREA if side > size_px else cv2.INTER_CUBIC
    return cv2.resize(crop, (size_px, size_px), interpolation=interpolation)


@cache
def texture_pyramid(name: str) -> tuple[np.ndarray, ...]:
    """Mip-map pyramid of texture ``name``: ``MIP_LEVELS`` read-only (s, s, 3) uint8 RGB arrays.

    Level ``l`` has side ``TEXTURE_SIZE_PX >> l`` texels; each level is the area average of the
    one before, so a level matches a pixel footprint ``2**l`` level-0 texels wide.
    """
    import cv2

    check_texture_name(name)
    level = _square(_load_rgb(name), TEXTURE_SIZE_PX)
    levels = [level]
    for _ in range(1, MIP_LEVELS):
        side = levels[-1].shape[0] // 2
        levels.append(cv2.resize(levels[-1], (side, side), interpolation=cv2.INTER_AREA))
    for array in levels:
        array.setflags(write=False)
    return tuple(levels)


@dataclass(frozen=True)
class TextureAtlas:
    """Mip-mapped textures packed into one flat array for gathering.

    Texel ``(row, col)`` of level ``l`` of texture ``i`` is
    ``texels[level_offset[i, l] + row * (size_px >> l) + col]``.
    """

    names: tuple[str, ...]
    texels: np.ndarray  # (n, 3) uint8 RGB
    level_offset: np.ndarray  # (n_textures, MIP_LEVELS) int64
    size_px: int = TEXTURE_SIZE_PX
    levels: int = MIP_LEVELS

    def index(self, name: str) -> int:
        """Index of texture ``name`` in the atlas."""
        try:
            return self.names.index(name)
        except ValueError:
            raise ValueError(f"texture {name!r} is not in this atlas: {self.names}") from None


def build_atlas(names: Iterable[str]) -> TextureAtlas:
    """Pack the pyramids of the distinct textures in ``names`` (kept in first-seen order)."""
    unique = tuple(dict.fromkeys(names))
    chunks: list[np.ndarray] = []
    offsets = np.zeros((len(unique), MIP_LEVELS), np.int64)
    position = 0
    for i, name in enumerate(unique):
        for level, array in enumerate(texture_pyramid(name)):
            offsets[i, level] = position
            chunks.append(array.reshape(-1, 3))
            position += array.shape[0] * array.shape[1]
    texels = np.concatenate(chunks) if chunks else np.zeros((0, 3), np.uint8)
    return TextureAtlas(names=unique, texels=texels, level_offset=offsets)
