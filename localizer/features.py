"""Keypoints and descriptors on a cylindrical panorama: SIFT (DoG) and MSER, each with a bearing.

``extract(image, params)`` takes a grey ``uint8`` panorama (column 0 along the heading, columns
clockwise; see :mod:`homing.bearings`) and returns a :class:`~mapdb.records.Fingerprint`.

- ``"sift"``: Lowe's DoG keypoints with SIFT descriptors (``cv2.SIFT_create``).
- ``"mser"``: maximally stable extremal regions (``cv2.MSER_create``); each region becomes a
  keypoint at its centroid whose size is the major axis of the region's second-moment ellipse
  (``4*sqrt(largest eigenvalue)``, the diameter for a disc), described by SIFT descriptors via
  ``sift.compute`` at the SIFT pyramid level matching their size. MSER keypoints are upright
  (angle 0): the robot's camera does not roll.

360° wrap-around: the image is padded circularly by ``wrap_margin_px`` columns on both sides
before detection, so features straddling column 0 are detected and described as in the middle of
the image. Keypoints are kept only where ``-0.5 <= x < W - 0.5`` (each physical point exactly
once); copies the detector places a hair differently near the seam are dropped as duplicates.
MSER regions cut by the end of the padding are dropped (their centroid would be wrong). Features
larger than the margin that straddle the seam may still differ from those of a rolled panorama,
because MSER stability and SIFT's coarse octaves see the truncated neighbourhood.

Filters (thesis §5.8-5.9): a horizon band of ± ``band_deg`` degrees, and the ``"lower"`` or
``"upper"`` half of the rows. Filters act on keypoint positions after detection, so detection near
the band edge sees the whole image. ``max_keypoints`` then keeps the strongest (SIFT response;
MSER: largest size).

Parameters come as a frozen :class:`ExtractionParams`; named presets are merged over the defaults
(``params_from_preset("mser-lower", max_keypoints=500)``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any

import cv2
import numpy as np

from homing.bearings import bearing_rad_from_column, wrap_angle_deg
from localizer.panorama import ROWS_SELECTIONS, Cylinder, horizon_band_mask, rows_mask
from mapdb.records import Fingerprint

DETECTORS: tuple[str, ...] = ("sift", "mser")
SIFT_DESCRIPTOR_SIZE = 128


@dataclass(frozen=True)
class ExtractionParams:
    """How features are extracted from a panorama (recorded in each Fingerprint's ``params``).

    ``band_deg``: keep keypoints within ± this many degrees of the horizon (None: all rows).
    ``rows``: ``"all"``, ``"lower"`` or ``"upper"`` half (relative to the horizon row).
    ``focal_px`` / ``horizon_row_px``: the cylinder geometry for the band (see ``Cylinder``).
    ``max_keypoints``: keep at most this many after filtering (None: no limit).
    ``wrap_margin_px``: columns of circular padding on each side for the 360° wrap-around.
    ``sift_*`` / ``mser_*``: the OpenCV detector parameters.
    """

    detector: str = "sift"
    band_deg: float | None = None
    rows: str = "all"
    max_keypoints: int | None = None
    focal_px: float | None = None
    horizon_row_px: float | None = None
    wrap_margin_px: int = 128
    sift_n_octave_layers: int = 3
    sift_contrast_threshold: float = 0.04
    sift_edge_threshold: float = 10.0
    sift_sigma: float = 1.6
    sift_precise_upscale: bool = True
    mser_delta: int = 5
    mser_min_area: int = 30
    mser_max_area: int = 14400
    mser_max_variation: float = 0.25

    def __post_init__(self) -> None:
        if self.detector not in DETECTORS:
            raise ValueError(f"detector must be one of {DETECTORS}, got {self.detector!r}")
        if self.rows not in ROWS_SELECTIONS:
            raise ValueError(f"rows must be one of {ROWS_SELECTIONS}, got {self.rows!r}")
        if self.band_deg is not None and not 0.0 <= self.band_deg < 90.0:
            raise ValueError(f"band_deg must be None or in [0, 90), got {self.band_deg!r}")
        if self.max_keypoints is not None and self.max_keypoints < 0:
            raise ValueError(f"max_keypoints must be None or >= 0, got {self.max_keypoints!r}")
        if self.wrap_margin_px < 0:
            raise ValueError(f"wrap_margin_px must be >= 0, got {self.wrap_margin_px!r}")

    def to_dict(self) -> dict[str, float | int | str | bool]:
        """The parameters as a flat mapping; fields that are None are left out."""
        return {k: v for k, v in asdict(self).items() if v is not None}

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> ExtractionParams:
        """Inverse of ``to_dict``: missing fields take their defaults; unknown keys are an error."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - names)
        if unknown:
            raise ValueError(f"unknown extraction parameters {unknown}; known: {sorted(names)}")
        return cls(**dict(values))


DEFAULT_PARAMS = ExtractionParams()

PRESETS: dict[str, dict[str, Any]] = {
    "sift": {"detector": "sift"},
    "mser": {"detector": "mser"},
    "sift-lower": {"detector": "sift", "rows": "lower"},
    "mser-lower": {"detector": "mser", "rows": "lower"},
    "sift-upper": {"detector": "sift", "rows": "upper"},
    "mser-upper": {"detector": "mser", "rows": "upper"},
    "sift-band20": {"detector": "sift", "band_deg": 20.0},
    "mser-band20": {"detector": "mser", "band_deg": 20.0},
}
"""Named configurations, merged over ``DEFAULT_PARAMS`` (thesis §5.8: ±20° was best on Vardy's
mirror images; §5.9: the lower half helped in the robot laboratory)."""


def params_from_preset(name: str, **overrides: Any) -> ExtractionParams:
    """The preset ``name`` merged over the defaults, then ``overrides`` merged over that."""
    if name not in PRESETS:
        raise ValueError(f"unknown extraction preset {name!r}; known: {sorted(PRESETS)}")
    return ExtractionParams.from_mapping({**PRESETS[name], **overrides})


def _check_image(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(
            f"expected a 2-D uint8 grey panorama, got shape {image.shape} dtype {image.dtype}"
        )
    if image.shape[1] < 1:
        raise ValueError(f"panorama has no columns: shape {image.shape}")
    return image


def pad_circular(image: np.ndarray, margin_px: int) -> np.ndarray:
    """``image`` with ``margin_px`` columns wrapped around onto each side (any margin, even > W)."""
    w = image.shape[1]
    columns = np.mod(np.arange(-margin_px, w + margin_px), w)
    return np.ascontiguousarray(image[:, columns])


def _sift(params: ExtractionParams) -> cv2.SIFT:
    return cv2.SIFT.create(
        nfeatures=0,
        nOctaveLayers=params.sift_n_octave_layers,
        contrastThreshold=params.sift_contrast_threshold,
        edgeThreshold=params.sift_edge_threshold,
        sigma=params.sift_sigma,
        enable_precise_upscale=params.sift_precise_upscale,
    )


def _mser_keypoints(padded: np.ndarray, params: ExtractionParams) -> list[cv2.KeyPoint]:
    """One upright keypoint per MSER region: centroid, size = major axis of its moment ellipse."""
    mser = cv2.MSER.create(
        delta=params.mser_delta,
        min_area=params.mser_min_area,
        max_area=params.mser_max_area,
        max_variation=params.mser_max_variation,
    )
    regions, boxes = mser.detectRegions(padded)
    keypoints = []
    for region, (x0, _, box_w, _) in zip(regions, boxes, strict=True):
        if params.wrap_margin_px > 0 and (x0 == 0 or x0 + box_w >= padded.shape[1]):
            continue  # cut off by the end of the circular padding: centroid would be wrong
        pts = np.asarray(region, dtype=np.float64)  # (n, 2) as (x, y)
        centre = pts.mean(axis=0)
        cov = np.cov(pts, rowvar=False) if len(pts) > 1 else np.zeros((2, 2))
        size = max(4.0 * float(np.sqrt(max(np.linalg.eigvalsh(cov)[-1], 0.0))), 2.0)
        octave = _pack_octave(size, padded.shape, params)
        keypoints.append(cv2.KeyPoint(float(centre[0]), float(centre[1]), size, 0.0, size, octave))
    return keypoints


def _pack_octave(size_px: float, shape: tuple[int, ...], params: ExtractionParams) -> int:
    """OpenCV's packed ``octave | layer << 8`` of the SIFT pyramid level matching ``size_px``.

    A SIFT keypoint of diameter ``size`` lives where ``2*sigma*2**(octave + layer/n) == size``;
    describing MSER keypoints at that level (not on the full-resolution image) makes
    ``sift.compute`` ~10x faster and samples large regions from a smoothed image, as for DoG.
    """
    n = params.sift_n_octave_layers
    v = max(np.log2(size_px / (2.0 * params.sift_sigma)) * n, 0.0)
    max_octave = max(int(np.log2(min(shape[:2]))) - 3, 0)
    octave = min(int(v // n), max_octave)
    layer = int(np.clip(round(v - octave * n), 1, n))
    return octave | (layer << 8)


def _detect(
    padded: np.ndarray, params: ExtractionParams
) -> tuple[Sequence[cv2.KeyPoint], np.ndarray | None]:
    """Keypoints and SIFT descriptors (``None`` without keypoints) on the padded image for the
    chosen detector."""
    sift = _sift(params)
    if params.detector == "sift":
        keypoints, descriptors = sift.detectAndCompute(padded, None)
    else:
        mser_keypoints = _mser_keypoints(padded, params)
        if not mser_keypoints:
            return [], None
        keypoints, descriptors = sift.compute(padded, mser_keypoints)
    return keypoints, None if descriptors is None else np.asarray(descriptors)


def _seam_duplicates(
    xy: np.ndarray, size: np.ndarray, angle_deg: np.ndarray, width_px: int, tol_px: float = 1.0
) -> np.ndarray:
    """Boolean mask of keypoints that repeat an earlier one across the 0/W seam."""
    near = np.flatnonzero((xy[:, 0] < tol_px) | (xy[:, 0] > width_px - 1 - tol_px))
    drop = np.zeros(len(xy), dtype=bool)
    for a_pos, i in enumerate(near):
        for j in near[a_pos + 1 :]:
            dx = abs(xy[i, 0] - xy[j, 0])
            dx = min(dx, width_px - dx)
            d_angle = abs(float(wrap_angle_deg(angle_deg[i] - angle_deg[j])))
            if (
                dx < tol_px
                and abs(xy[i, 1] - xy[j, 1]) < tol_px
                and abs(np.log(size[i] / size[j])) < 0.1
                and d_angle < 5.0
                and not drop[i]
            ):
                drop[j] = True
    return drop


def extract(image: np.ndarray, params: ExtractionParams = DEFAULT_PARAMS) -> Fingerprint:
    """Detect and describe features on grey uint8 panorama ``image`` (H x W) with ``params``.

    Returns a Fingerprint whose keypoints lie in ``-0.5 <= x < W - 0.5`` with robot-frame bearings
    ``-2*pi*x/W`` wrapped to (-pi, pi]. Nothing detected (a blank wall, or an image under 3 rows)
    gives an empty Fingerprint: 0 rows, descriptors of shape (0, 128) float32.
    """
    image = _check_image(image)
    h, w = image.shape
    record = params.to_dict()
    if h < 3:
        return Fingerprint.empty(params.detector, w, h, SIFT_DESCRIPTOR_SIZE, record)
    padded = pad_circular(image, params.wrap_margin_px)
    keypoints, descriptors = _detect(padded, params)
    if not keypoints or descriptors is None:
        return Fingerprint.empty(params.detector, w, h, SIFT_DESCRIPTOR_SIZE, record)

    xy = np.array([kp.pt for kp in keypoints], dtype=np.float64)
    xy[:, 0] -= params.wrap_margin_px
    size = np.array([kp.size for kp in keypoints], dtype=np.float64)
    angle_deg = np.array([kp.angle for kp in keypoints], dtype=np.float64)
    response = np.array([kp.response for kp in keypoints], dtype=np.float64)
    descriptors = np.asarray(descriptors, dtype=np.float32)

    keep = (xy[:, 0] >= -0.5) & (xy[:, 0] < w - 0.5)
    xy, size, angle_deg, response = xy[keep], size[keep], angle_deg[keep], response[keep]
    descriptors = descriptors[keep]
    keep = ~_seam_duplicates(xy, size, angle_deg, w)

    cylinder = Cylinder(w, h, params.focal_px, params.horizon_row_px)
    keep &= horizon_band_mask(xy[:, 1], cylinder, params.band_deg)
    keep &= rows_mask(xy[:, 1], cylinder, params.rows)  # type: ignore[arg-type]
    index = np.flatnonzero(keep)
    if params.max_keypoints is not None and len(index) > params.max_keypoints:
        strength = response if params.detector == "sift" else size
        order = np.argsort(-strength[index], kind="stable")[: params.max_keypoints]
        index = np.sort(index[order])

    return Fingerprint(
        detector=params.detector,
        image_width_px=w,
        image_height_px=h,
        keypoints_xy=xy[index],
        bearings_rad=bearing_rad_from_column(xy[index, 0], w),
        descriptors=descriptors[index],
        params=record,
    )


def extract_preset(image: np.ndarray, preset: str = "sift", **overrides: Any) -> Fingerprint:
    """``extract`` with the named preset merged over the defaults (and ``overrides`` over that)."""
    return extract(image, params_from_preset(preset, **overrides))
