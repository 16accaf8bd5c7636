"""Keypoints and descriptors on a 360° panorama: SIFT (DoG) and MSER, each with a bearing.

``extract(image, params)`` takes a grey ``uint8`` panorama (column 0 along the heading, columns
clockwise; see :mod:`homing.bearings`) and returns a :class:`~mapdb.records.Fingerprint`.
``params.camera`` names its camera model (:mod:`homing.cameras`: ``cylinder`` or ``equirect``),
built once per panorama and carried by its fingerprint (``Fingerprint.camera``);
:func:`extract_with_camera` chooses it from a :class:`~localizer.cameras.CameraSpec` and the
image's size (:func:`localizer.cameras.panorama_kind`: ``auto`` reads a 2:1 image as
equirectangular and refuses one that is no 360° panorama) with per-camera defaults
(:data:`CAMERA_DEFAULTS`).

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

Resolution: an image wider than ``max_width_px`` is first shrunk to that width (``INTER_AREA``);
keypoints, image size and camera are those of the shrunk image.

Contrast: the image is equalised by CLAHE (``cv2.createCLAHE``; clip limit ``clahe_clip_limit``)
in full-width horizontal bands ``clahe_band_deg`` tall before detection. SIFT's contrast
threshold is absolute, so a dim room gave a seventh of the keypoints of the same room lit, and
dim queries against a lit map were lost; equalised, they localize (docs/localization.md). A
fingerprint recorded without ``clahe_clip_limit`` (a map written before this step) was not
equalised: :func:`matching_overrides` tells a query to match it.

Filters (thesis §5.8-5.9): a horizon band of ± ``band_deg`` degrees, and the ``"lower"`` or
``"upper"`` half of the rows; and an elevation band ``[min_elevation_deg, max_elevation_deg]``
that leaves out the nadir (tripod, robot body) and the zenith (ceiling lamps) of a sphere.
Filters act on keypoint positions after detection, so detection near
the band edge sees the whole image. ``max_keypoints`` then keeps the strongest (SIFT response;
MSER: largest size).

Parameters come as a frozen :class:`ExtractionParams`; named presets are merged over the defaults
(``params_from_preset("mser-lower", max_keypoints=500)``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import cv2
import numpy as np

from homing.bearings import bearing_rad_from_column, wrap_angle_deg
from homing.cameras import CAMERA_MODELS, camera_from_params
from localizer.cameras import ROWS_SELECTIONS, CameraSpec, panorama_kind, rows_kept
from localizer.panorama_io import unwrap_omni
from mapdb.records import Fingerprint

DETECTORS: tuple[str, ...] = ("sift", "mser")
SIFT_DESCRIPTOR_SIZE = 128


@dataclass(frozen=True)
class ExtractionParams:
    """How features are extracted from a panorama (recorded in each Fingerprint's ``params``).

    ``camera``: the panorama's model, ``"cylinder"`` or ``"equirect"`` (:mod:`localizer.cameras`).
    ``band_deg``: keep keypoints within ± this many degrees of the horizon (None: all rows).
    ``min_elevation_deg`` / ``max_elevation_deg``: keep keypoints seen between these elevations
    (None: no limit on that side).
    ``rows``: ``"all"``, ``"lower"`` or ``"upper"`` half (relative to the horizon row).
    ``focal_px`` / ``horizon_row_px``: the cylinder geometry (see ``Cylinder``), in pixels of
    the image as given (scaled with it when it is shrunk).
    ``max_width_px``: shrink wider images to this width before detection (None: never).
    ``max_keypoints``: keep at most this many after filtering, the strongest (None: no limit).
    1,000 by default: equalised, a textured room gives 1,100-2,300 keypoints, and matching grows
    with the product of two panoramas' counts; the strongest 1,000 kept the photo rooms' and the
    house's outcomes at 180 instead of 245 ms per query (docs/localization.md); a bare or dim
    room has fewer and mostly keeps all of its.
    ``wrap_margin_px``: columns of circular padding on each side for the 360° wrap-around.
    ``clahe_clip_limit``: CLAHE's clip limit (0: the image as given); ``clahe_band_deg``: the
    height of its full-width bands, in degrees at the panorama's ``360 / W`` degrees per pixel.
    ``sift_*`` / ``mser_*``: the OpenCV detector parameters.
    ``upright``: describe every keypoint at orientation 0 (the camera does not roll, so the
    dominant-gradient rotation only adds ambiguity). ``descriptor``: ``"sift"``, or
    ``"rootsift"`` (Arandjelović & Zisserman 2012: L1-normalised, square-rooted, so the L2
    distance between descriptors is the Hellinger distance).
    """

    detector: str = "sift"
    camera: str = "cylinder"
    band_deg: float | None = None
    min_elevation_deg: float | None = None
    max_elevation_deg: float | None = None
    max_width_px: int | None = None
    rows: str = "all"
    max_keypoints: int | None = 1000
    focal_px: float | None = None
    horizon_row_px: float | None = None
    wrap_margin_px: int = 128
    clahe_clip_limit: float = 2.0
    clahe_band_deg: float = 45.0
    sift_n_octave_layers: int = 3
    sift_contrast_threshold: float = 0.04
    sift_edge_threshold: float = 10.0
    sift_sigma: float = 1.6
    sift_precise_upscale: bool = True
    upright: bool = False
    descriptor: str = "sift"
    mser_delta: int = 5
    mser_min_area: int = 30
    mser_max_area: int = 14400
    mser_max_variation: float = 0.25

    def __post_init__(self) -> None:
        if self.detector not in DETECTORS:
            raise ValueError(f"detector must be one of {DETECTORS}, got {self.detector!r}")
        if self.rows not in ROWS_SELECTIONS:
            raise ValueError(f"rows must be one of {ROWS_SELECTIONS}, got {self.rows!r}")
        if self.descriptor not in ("sift", "rootsift"):
            raise ValueError(f"descriptor must be sift or rootsift, got {self.descriptor!r}")
        if self.camera not in CAMERA_MODELS:
            raise ValueError(f"camera must be one of {CAMERA_MODELS}, got {self.camera!r}")
        if self.max_width_px is not None and self.max_width_px < 8:
            raise ValueError(f"max_width_px must be None or >= 8, got {self.max_width_px!r}")
        low, high = self.min_elevation_deg, self.max_elevation_deg
        if low is not None and high is not None and not low < high:
            raise ValueError(f"min_elevation_deg {low} must be below max_elevation_deg {high}")
        if self.band_deg is not None and not 0.0 <= self.band_deg < 90.0:
            raise ValueError(f"band_deg must be None or in [0, 90), got {self.band_deg!r}")
        if self.max_keypoints is not None and self.max_keypoints < 0:
            raise ValueError(f"max_keypoints must be None or >= 0, got {self.max_keypoints!r}")
        if self.wrap_margin_px < 0:
            raise ValueError(f"wrap_margin_px must be >= 0, got {self.wrap_margin_px!r}")
        if not self.clahe_clip_limit >= 0.0:
            raise ValueError(f"clahe_clip_limit must be >= 0, got {self.clahe_clip_limit!r}")
        if not 0.0 < self.clahe_band_deg <= 360.0:
            raise ValueError(f"clahe_band_deg must be in (0, 360], got {self.clahe_band_deg!r}")

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

    @classmethod
    def from_record(cls, record: Mapping[str, Any]) -> ExtractionParams:
        """The parameters a stored fingerprint's ``params`` record (``to_dict``) describes: a
        missing field that may be None was None (``to_dict`` leaves those out), a record without
        the contrast fields is from before the equalisation (:data:`UNEQUALISED_RECORD`), and
        keys of no field are ignored (a map outlives the code that wrote it)."""
        nullable = {f.name: None for f in fields(cls) if "None" in str(f.type)}
        names = {f.name for f in fields(cls)}
        known = {k: v for k, v in record.items() if k in names}
        return cls(**{**nullable, **UNEQUALISED_RECORD, **known})


UNEQUALISED_RECORD: dict[str, Any] = {"clahe_clip_limit": 0.0}
"""What a fingerprint record without the contrast fields means: extracted without CLAHE."""

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

CAMERA_DEFAULTS: dict[str, dict[str, Any]] = {
    "cylinder": {},
    "equirect": {"max_width_px": 1024, "min_elevation_deg": -50.0, "max_elevation_deg": 60.0},
}
"""Per camera model, merged under a preset. A 360° camera's 2048 x 1024 sphere is read at
1024 x 512 (SIFT takes about 0.4 s there, 0.8 s at full size, on one core here), without the
nadir below -50° (tripod or robot body, and the floor right under the camera) or the zenith
above 60° (ceiling lamps)."""


def params_from_preset(name: str, **overrides: Any) -> ExtractionParams:
    """The preset ``name`` merged over the defaults, then ``overrides`` merged over that."""
    if name not in PRESETS:
        raise ValueError(f"unknown extraction preset {name!r}; known: {sorted(PRESETS)}")
    return ExtractionParams.from_mapping({**PRESETS[name], **overrides})


def matching_overrides(record: Mapping[str, Any]) -> dict[str, Any]:
    """The extraction settings a query must take from a stored fingerprint's ``record``
    (its ``params``) to be comparable with it: the contrast equalisation and the keypoint cap,
    which change which keypoints are found (:meth:`ExtractionParams.from_record`: a record from
    before the equalisation means none, and one without ``max_keypoints`` no cap), and the width
    the place was read at when it is not its camera's default (``toploc map build
    --read-width``): a map read at the defaults leaves every query at its own camera's default
    (a 2048-wide sphere read at 1024 against a cylinder map, a wide cylinder at full width
    against a sphere map, as before the option existed)."""
    stored = ExtractionParams.from_record(record)
    overrides: dict[str, Any] = {
        "clahe_clip_limit": stored.clahe_clip_limit,
        "clahe_band_deg": stored.clahe_band_deg,
        "max_keypoints": stored.max_keypoints,
    }
    default_width = CAMERA_DEFAULTS.get(stored.camera, {}).get("max_width_px")
    if stored.max_width_px != default_width:
        overrides["max_width_px"] = stored.max_width_px
    return overrides


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


def equalised(image: np.ndarray, params: ExtractionParams) -> np.ndarray:
    """``image`` after CLAHE in horizontal bands ``clahe_band_deg`` tall (at ``360 / W`` degrees
    per pixel, rounded to whole bands), each band one tile the panorama's full width; unchanged
    when the clip limit is 0.

    Full-width bands keep the equalisation exact under a yaw roll of the panorama: square tiles
    changed with the roll (a rolled test panorama lost 1.2 % of its MSER keypoints)."""
    if params.clahe_clip_limit <= 0.0:
        return image
    h, w = image.shape
    bands = max(round(h / (w * params.clahe_band_deg / 360.0)), 1)
    clahe = cv2.createCLAHE(clipLimit=params.clahe_clip_limit, tileGridSize=(1, bands))
    return clahe.apply(image)


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
    if params.detector == "sift" and params.upright:
        keypoints, descriptors = sift.compute(padded, _upright(sift.detect(padded, None)))
    elif params.detector == "sift":
        keypoints, descriptors = sift.detectAndCompute(padded, None)
    else:
        mser_keypoints = _mser_keypoints(padded, params)
        if not mser_keypoints:
            return [], None
        keypoints, descriptors = sift.compute(padded, mser_keypoints)
    if descriptors is None:
        return keypoints, None
    values = np.asarray(descriptors, dtype=np.float32)
    return keypoints, _root(values) if params.descriptor == "rootsift" else values


def _upright(keypoints: Sequence[cv2.KeyPoint]) -> list[cv2.KeyPoint]:
    """The keypoints at orientation 0, once each: SIFT repeats a location once per dominant
    orientation, which become duplicates when the orientation is dropped."""
    seen: set[tuple[float, float, float]] = set()
    upright = []
    for kp in keypoints:
        key = (round(kp.pt[0], 2), round(kp.pt[1], 2), round(kp.size, 2))
        if key not in seen:
            seen.add(key)
            upright.append(cv2.KeyPoint(kp.pt[0], kp.pt[1], kp.size, 0.0, kp.response, kp.octave))
    return upright


def _root(descriptors: np.ndarray) -> np.ndarray:
    """RootSIFT: each row L1-normalised and square-rooted (unit L2 norm)."""
    total = np.abs(descriptors).sum(axis=1, keepdims=True)
    return np.sqrt(descriptors / np.maximum(total, 1e-12)).astype(np.float32)


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


def _shrunk(image: np.ndarray, params: ExtractionParams) -> tuple[np.ndarray, ExtractionParams]:
    """The image at most ``max_width_px`` wide, and the params with the cylinder geometry
    scaled to it."""
    h, w = image.shape
    if params.max_width_px is None or w <= params.max_width_px:
        return image, params
    scale = params.max_width_px / w
    size = (params.max_width_px, max(round(h * scale), 1))
    shrunk = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    focal, horizon = params.focal_px, params.horizon_row_px
    return shrunk, replace(
        params,
        focal_px=None if focal is None else focal * scale,
        horizon_row_px=None if horizon is None else (horizon + 0.5) * scale - 0.5,
    )


def _detect_strip(
    padded: np.ndarray, params: ExtractionParams, start_px: int, stop_px: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Keypoints whose column lies in ``[start, stop)`` of the panorama (``xy`` in its pixel
    coordinates, size, angle, response, descriptors), detected on that strip of the circularly
    padded image with the wrap margin on both sides."""
    margin = params.wrap_margin_px
    keypoints, descriptors = _detect(padded[:, start_px : stop_px + 2 * margin], params)
    if not keypoints or descriptors is None:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 128), "f4")
    xy = np.array([kp.pt for kp in keypoints], dtype=np.float64)
    xy[:, 0] += start_px - margin
    keep = (xy[:, 0] >= start_px - 0.5) & (xy[:, 0] < stop_px - 0.5)
    return (
        xy[keep],
        np.array([kp.size for kp in keypoints], dtype=np.float64)[keep],
        np.array([kp.angle for kp in keypoints], dtype=np.float64)[keep],
        np.array([kp.response for kp in keypoints], dtype=np.float64)[keep],
        np.asarray(descriptors, dtype=np.float32)[keep],
    )


def extract(
    image: np.ndarray, params: ExtractionParams = DEFAULT_PARAMS, threads: int = 1
) -> Fingerprint:
    """Detect and describe features on grey uint8 panorama ``image`` (H x W) with ``params``.

    ``threads = 2`` detects the two halves of the panorama (each with the wrap margin of
    overlap) on two threads: about 1.5x faster on two cores, with the same keypoints but for a
    few near the halves' border (SIFT's pyramid sees a narrower image); the map build runs one
    process per core instead.

    Returns a Fingerprint whose keypoints lie in ``-0.5 <= x < W - 0.5`` with robot-frame bearings
    ``-2*pi*x/W`` wrapped to (-pi, pi] (``W`` after shrinking to ``max_width_px``). Nothing
    detected (a blank wall, or an image under 3 rows) gives an empty Fingerprint: 0 rows,
    descriptors of shape (0, 128) float32.
    """
    image, params = _shrunk(_check_image(image), params)
    h, w = image.shape
    record = params.to_dict()
    if h < 3:
        return Fingerprint.empty(params.detector, w, h, SIFT_DESCRIPTOR_SIZE, record)
    padded = pad_circular(equalised(image, params), params.wrap_margin_px)
    if threads >= 2 and w >= 4 * params.wrap_margin_px:
        # OpenCV releases the GIL: two threads detect the two halves on the two cores
        halves = [(0, w // 2), (w // 2, w)]
        with ThreadPoolExecutor(len(halves)) as pool:
            strips = list(pool.map(lambda b: _detect_strip(padded, params, *b), halves))
    else:
        strips = [_detect_strip(padded, params, 0, w)]
    xy, size, angle_deg, response, descriptors = (
        np.concatenate(column) for column in zip(*strips, strict=True)
    )
    if not len(xy):
        return Fingerprint.empty(params.detector, w, h, SIFT_DESCRIPTOR_SIZE, record)
    keep = ~_seam_duplicates(xy, size, angle_deg, w)

    camera = camera_from_params(w, h, record)
    keep &= rows_kept(
        xy[:, 1],
        camera,
        params.band_deg,
        params.min_elevation_deg,
        params.max_elevation_deg,
        params.rows,
    )
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
        keypoint_sizes_px=size[index].astype(np.float32),
        camera_model=camera,
    )


def extract_preset(image: np.ndarray, preset: str = "sift", **overrides: Any) -> Fingerprint:
    """``extract`` with the named preset merged over the defaults (and ``overrides`` over that)."""
    return extract(image, params_from_preset(preset, **overrides))


def extract_with_camera(
    image: np.ndarray,
    camera: CameraSpec,
    preset: str = "sift",
    threads: int = 1,
    source: str = "image",
    **overrides: Any,
) -> Fingerprint:
    """``extract`` on a 360° camera image: a mirror image (``camera`` omni) is unwrapped into a
    cylinder first; the camera model is chosen by ``camera`` from the panorama's size, with that
    model's :data:`CAMERA_DEFAULTS` under the preset and ``overrides`` over everything.
    ``threads``: see :func:`extract`. An image that is no 360° panorama for ``camera``
    raises :class:`~localizer.cameras.NotPanoramaError` naming ``source``
    (:func:`~localizer.cameras.panorama_kind`)."""
    image = _check_image(image)
    if camera.mirror is not None:
        image = unwrap_omni(image, camera.mirror, source)
    kind = panorama_kind(camera, image.shape[1], image.shape[0], source)
    merged = {**CAMERA_DEFAULTS[kind], "camera": kind, **overrides}
    return extract(image, params_from_preset(preset, **merged), threads)
