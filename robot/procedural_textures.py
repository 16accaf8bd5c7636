"""Procedural textures for bare interiors: painted walls, wooden and tiled floors, windows, doors.

Every texture is a deterministic square RGB tile of ``size_px`` texels (uint8, row 0 at the top)
that tiles seamlessly: its noise is periodic (white noise low-pass filtered in the Fourier
domain), and planks and tiles repeat within the square. One tile covers the material's
``tile_m`` metres, so the spatial frequencies below are per tile:

- ``paint_<colour>``: a flat colour, 3 % (std) low-frequency shading (up to 3 cycles per tile) and
  2 grey levels (std) of fine noise: a painted wall, almost featureless.
- ``wood_<tone>``: 8 planks per tile, each with its own tone, a grain stretched along the plank
  and staggered ends.
- ``tiles_<colour>``: 4 x 4 ceramic tiles per tile with 3 % grout lines and slight tile tints.
- ``window``: an overexposed (near-white) glazed window with a light frame and a cross bar; meant
  to be stretched once over a window-sized poster.
- ``door``: a wooden door leaf with four recessed panels and a handle, stretched once.
"""

from __future__ import annotations

import zlib

import numpy as np

PAINTS: dict[str, tuple[int, int, int]] = {
    "white": (226, 224, 216),
    "cream": (234, 222, 190),
    "sage": (176, 190, 160),
    "sky": (170, 196, 214),
    "rose": (220, 184, 178),
    "sand": (214, 196, 160),
    "grey": (178, 178, 174),
    "lilac": (196, 184, 210),
}
WOODS: dict[str, tuple[int, int, int]] = {"oak": (170, 124, 78), "walnut": (108, 72, 46)}
TILES: dict[str, tuple[int, int, int]] = {"white": (236, 236, 232), "slate": (96, 100, 108)}

PROCEDURAL_TEXTURES: tuple[str, ...] = tuple(
    [f"paint_{c}" for c in PAINTS]
    + [f"wood_{c}" for c in WOODS]
    + [f"tiles_{c}" for c in TILES]
    + ["window", "door"]
)


def periodic_noise(
    rng: np.random.Generator, shape: tuple[int, int], max_cycles: float
) -> np.ndarray:
    """Seamlessly tiling noise of zero mean and unit std with frequencies up to ``max_cycles``
    cycles per image side (white noise low-passed with a Gaussian in the Fourier domain)."""
    white = rng.standard_normal(shape)
    fy = np.fft.fftfreq(shape[0]) * shape[0]
    fx = np.fft.rfftfreq(shape[1]) * shape[1]
    gain = np.exp(-0.5 * (fy[:, None] ** 2 + fx[None, :] ** 2) / max_cycles**2)
    smooth = np.fft.irfft2(np.fft.rfft2(white) * gain, s=shape)
    return (smooth - smooth.mean()) / max(float(smooth.std()), 1e-12)


def _rgb(base: tuple[int, int, int], factor: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """``base * factor + offset`` per texel, clipped to uint8 (arrays (s, s) or (s, s, 3))."""
    colour = np.asarray(base, np.float64)
    if factor.ndim == 2:
        factor = factor[..., None]
    if offset.ndim == 2:
        offset = offset[..., None]
    return np.clip(np.rint(colour * factor + offset), 0, 255).astype(np.uint8)


def paint(rng: np.random.Generator, base: tuple[int, int, int], size_px: int) -> np.ndarray:
    """A painted surface: ``base`` colour, 3 % (std) low-frequency shading, 2 levels fine noise."""
    shading = 1.0 + 0.03 * periodic_noise(rng, (size_px, size_px), 3.0)
    fine = 2.0 * rng.standard_normal((size_px, size_px))
    return _rgb(base, shading, fine)


def wood(rng: np.random.Generator, base: tuple[int, int, int], size_px: int) -> np.ndarray:
    """8 planks per tile along x (columns), staggered ends, a tone per plank, stretched grain."""
    planks = 8
    plank_px = size_px // planks
    grain = periodic_noise(rng, (size_px, size_px // 8), 12.0)  # fine across, coarse along
    grain = np.repeat(grain, 8, axis=1)[:, :size_px]
    factor = 1.0 + 0.08 * grain + 0.025 * periodic_noise(rng, (size_px, size_px), 4.0)
    rows = np.arange(size_px)
    plank = np.minimum(rows // plank_px, planks - 1)
    seams = np.zeros((size_px, size_px), bool)
    seams[rows % plank_px == 0, :] = True
    for k in range(planks):
        end = int(rng.integers(size_px))
        tone = float(rng.uniform(0.85, 1.12))
        factor[plank == k] *= tone
        seams[plank == k, end : end + 2] = True
    factor[seams] *= 0.55
    return _rgb(base, factor, 2.0 * rng.standard_normal((size_px, size_px)))


def tiles(rng: np.random.Generator, base: tuple[int, int, int], size_px: int) -> np.ndarray:
    """4 x 4 ceramic tiles per texture tile, grout lines 3 % of a tile, slight tints."""
    per_side = 4
    tile_px = size_px // per_side
    index = np.arange(size_px) // tile_px
    tint = rng.uniform(0.95, 1.05, (per_side, per_side))
    factor = tint[index[:, None], index[None, :]] + 0.02 * periodic_noise(
        rng, (size_px, size_px), 6.0
    )
    grout_px = max(1, round(0.03 * tile_px))
    grout_line = (np.arange(size_px) % tile_px) < grout_px
    grout = grout_line[:, None] | grout_line[None, :]
    factor[grout] = 0.72 if np.mean(base) > 128 else 1.5
    return _rgb(base, factor, 1.5 * rng.standard_normal((size_px, size_px)))


def window(rng: np.random.Generator, size_px: int) -> np.ndarray:
    """A window: near-white glass (246..255), a grey frame and cross bar. The scene renders it
    brighter than white (:data:`robot.scene.EMISSIVE_SHADE`), so the glass clips: overexposed."""
    glass = 251.0 + 2.0 * periodic_noise(rng, (size_px, size_px), 2.0)
    image = np.repeat(np.clip(glass, 246, 255)[..., None], 3, axis=2)
    frame_px = size_px // 16
    bar_px = size_px // 40
    centre = size_px // 2
    frame = np.zeros((size_px, size_px), bool)
    frame[:frame_px, :] = frame[-frame_px:, :] = True
    frame[:, :frame_px] = frame[:, -frame_px:] = True
    frame[centre - bar_px : centre + bar_px, :] = True
    frame[:, centre - bar_px : centre + bar_px] = True
    image[frame] = (168, 168, 162)
    return np.rint(image).astype(np.uint8)


def door(rng: np.random.Generator, size_px: int) -> np.ndarray:
    """A wooden door leaf: grain, four recessed (darker-edged) panels and a metal handle."""
    leaf = wood(rng, (150, 110, 70), size_px).astype(np.float64)
    leaf = leaf.transpose(1, 0, 2)  # grain vertical, along the leaf
    margin, gap = size_px // 8, size_px // 16
    half = size_px // 2
    for top in (margin, half + gap // 2):
        for left in (margin, half + gap // 2):
            bottom, right = top + half - margin - gap, left + half - margin - gap
            leaf[top:bottom, left:right] *= 0.9
            edge = 4
            leaf[top : top + edge, left:right] *= 0.7
            leaf[top:bottom, left : left + edge] *= 0.7
    row, col = half, size_px - margin // 2 - 6
    leaf[row - 4 : row + 4, col - 20 : col + 4] = (200, 200, 196)
    return np.clip(np.rint(leaf), 0, 255).astype(np.uint8)


def procedural_texture(name: str, size_px: int) -> np.ndarray:
    """The (size_px, size_px, 3) uint8 RGB tile of texture ``name``, the same on every call.

    Raises ``ValueError`` naming ``name`` if it is not in ``PROCEDURAL_TEXTURES``.
    """
    if name not in PROCEDURAL_TEXTURES:
        raise ValueError(f"unknown procedural texture {name!r}; known: {PROCEDURAL_TEXTURES}")
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    kind, _, variant = name.partition("_")
    if kind == "paint":
        return paint(rng, PAINTS[variant], size_px)
    if kind == "wood":
        return wood(rng, WOODS[variant], size_px)
    if kind == "tiles":
        return tiles(rng, TILES[variant], size_px)
    if kind == "window":
        return window(rng, size_px)
    return door(rng, size_px)
