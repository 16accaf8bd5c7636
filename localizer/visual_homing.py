"""Closed-loop ALV visual homing on panoramas toward a stored place's fingerprint.

The pure step (:func:`home_step`) turns the current fingerprint and the goal fingerprint (same
detector) into a home vector in the current robot frame (REP-103: x forward, y left; the vector
is dimensionless, in ALV units: its direction points home, its length grows with the distance
to go but is not metres). Three variants:

- ``"thesis"`` (Goldhoorn 2008, sections 2.4 and 5.4): the ALV over *all* feature bearings of
  each view; the unknown heading difference from the bearing-histogram visual compass
  (:func:`homing.compass.bearing_shift_rad`, eq. 5.4). No descriptor is used.
- ``"best"``: features matched by descriptor (:func:`localizer.matching.match_descriptors`,
  ratio test); the heading difference is the peak of the circular density of the matched
  bearing differences, matches further than ``outlier_deg`` from it are rejected, and the
  inliers' circular mean (:func:`homing.compass.matched_shift_rad`) refines it; the ALV is taken
  over the inliers only, in both views (the same landmarks here and at the goal):
  :func:`homing.alv.matched_home_vector`.
- ``"pose"``: the direction from the relative pose that the localizer's verification finds on
  the same descriptor matches (:func:`localizer.verification.verify`), solved for planar motion
  (:data:`HOMING_VERIFICATION`): the axis of its translation, which is precise, with the sign
  that the inliers' change of distance gives where it is significant (their elevations and their
  keypoints' sizes), else the sign most of three votes give: the pose's cheirality counted on
  the inliers above the floor, the matched ALV and the ALV of all features with the pose's yaw
  as the compass (:func:`signed_pose_direction_rad`; ``toploc eval homing --method pose-vote``).
  The step length and the arrival test are the matched ALV's, as for "best"; without a
  translation axis the step is "best"'s. The default: the method ``toploc eval homing --method
  best`` scores, and on maps recorded on one drive (world seed 22, two places per room) the
  active loop with it ended right and localized where the robot was put 18 and 15 times of 20
  (building, house), 15 and 10 with "best"; on world seed 23, 17 and 14 against 16 and 11.

The loop (:func:`drive_home`) is generic over :class:`localizer.robot_protocol.Robot`: capture,
extract, step, turn toward the home vector and drive ``gain_m * |home|`` clamped to
``[min_step_m, max_step_m]``, times a step scale that halves whenever the home vector reverses
(it turned by more than ``reverse_deg`` between two steps, in the goal view's frame: an
overshoot) and recovers by ``scale_up`` otherwise. The robot cannot see ground truth, so arrival
is decided from the images alone: the home vector is shorter than ``arrive_length`` and, for
"best" and "pose", the inliers' median parallax (:attr:`HomeStep.parallax_rad`) is below
``arrive_parallax_deg`` (a short ALV difference alone also happens far away, by cancellation;
on renders of the square room both hold within about 0.1 m of the goal) and the inliers are at
least ``arrive_matched_fraction`` of the goal's features (at the goal the view is the goal's:
with the contrast equalisation and the keypoint cap, 32-60 % of them matched at the end of the
drives that arrived within 0.16 m, on rendered tiled and bare rooms, and 24-26 % where a bare
living room's far matches had cancelled to a short vector 2.2 m away; before the equalisation
31-63 % and 2-14 %, when this was 20 %); or the step scale collapsed below
``converged_scale`` (the robot keeps overshooting a goal closer than the shortest step), which
is an arrival only if that fraction holds too (else the run ends with reason ``"converged"`` but
not arrived). A bump triggers a sidestep (turn by +-90 degrees, alternating, and drive
``sidestep_m``); ``max_bumps`` homing moves in a row ending in a bump stop the run with reason
``"blocked"``. A view with too few features or matches triggers a recovery move (turn by 120
degrees and drive ``sidestep_m``); ``max_lost`` such views in a row stop it with ``"lost"``.
An optional ``on_step`` is told of each capture (:class:`HomingProgress`) before the loop acts
on it, e.g. to publish progress; the loop itself stays the same.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import cv2
import numpy as np

from homing.alv import HomingError, alv_from_bearings, home_vector, matched_home_vector
from homing.bearings import mean_direction_rad, wrap_angle_rad
from homing.compass import CompassMethod, bearing_shift_rad, matched_shift_rad
from homing.home_directions import alv_home_directions_rad
from localizer.cameras import CameraSpec
from localizer.features import extract_preset, extract_with_camera
from localizer.matching import match_descriptors
from localizer.verification import (
    Verification,
    VerificationParams,
    cheirality_sign,
    distance_vote,
    home_direction_rad,
    verify,
)
from mapdb.records import Fingerprint

if TYPE_CHECKING:  # the protocol only: localizer does not depend on a robot implementation
    from localizer.robot_protocol import Robot

DISTANCE_VOTE_MIN_T = 2.0
"""The distance vote (:func:`localizer.verification.distance_vote`) sets the "pose" variant's
sign when its t-statistic is at least this (chosen on bare houses 1.5-3 m, the tiled square
and building rooms and corridors: docs/homing.md)."""

HOMING_VERIFICATION = VerificationParams(motion="planar-refined")
"""The relative pose the "pose" variant takes its axis from: the planar pose (a yaw and a
horizontal translation, :mod:`localizer.planar`; the robot's camera moves on the floor) refined
to any pose on its inliers (:func:`localizer.verification.refined_planar_pose`). The general
5-point pose fits a scene whose inliers mostly lie on one plane (the floor of a bare room) with
a wrong axis as readily as the right one; the planar model admits only the right one, and the
refinement takes in a camera tilted a degree or two (docs/homing.md)."""

HomingVariant = Literal["thesis", "best", "pose"]
VARIANTS: tuple[str, ...] = ("thesis", "best", "pose")


@dataclass(frozen=True)
class StepParams:
    """How one home vector is computed.

    ``compass``: the thesis variant's compass method. ``ratio``: the descriptor ratio test.
    ``outlier_deg``: the best variant keeps matches whose bearing difference lies within this
    many degrees of the density peak (parallax makes near landmarks differ by tens of degrees).
    ``min_matches``: fewer inliers than this is a :class:`HomingError`.
    """

    variant: HomingVariant = "pose"
    compass: CompassMethod = "histogram"
    ratio: float = 0.8
    outlier_deg: float = 45.0
    min_matches: int = 6

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"unknown homing variant {self.variant!r}; use one of {VARIANTS}")
        if not 0 < self.outlier_deg <= 180:
            raise ValueError(f"outlier_deg must be in (0, 180], got {self.outlier_deg}")


@dataclass(frozen=True)
class HomeStep:
    """A home vector ``home_xy`` (2,) in the current robot frame (ALV units), the estimated
    rotation ``shift_rad`` of the current view against the goal view (a goal feature at bearing
    b is seen at b + shift_rad), and the number of features it used (the matched inliers for
    "best" and "pose").

    ``parallax_rad`` ("best" and "pose"; NaN for "thesis"): the median absolute bearing change
    of the matched inliers once the rotation is removed; 0 at the goal, it grows with the
    distance to it whatever the layout, where the ALV difference can cancel by chance.
    """

    home_xy: np.ndarray
    shift_rad: float
    n_used: int
    parallax_rad: float = math.nan

    @property
    def length(self) -> float:
        """Length of the home vector (ALV units)."""
        return float(np.hypot(*self.home_xy))

    @property
    def direction_rad(self) -> float:
        """Direction of the home vector in the current robot frame (CCW from forward)."""
        return float(np.arctan2(self.home_xy[1], self.home_xy[0]))


def density_peak_rad(angles_rad: np.ndarray, sigma_deg: float = 4.0, bins: int = 360) -> float:
    """The mode of a circular density of ``angles_rad`` (von Mises kernel of about
    ``sigma_deg``), evaluated on ``bins`` directions; in (-pi, pi]."""
    grid = np.linspace(-np.pi, np.pi, bins, endpoint=False)
    kappa = 1.0 / math.radians(sigma_deg) ** 2
    score = np.exp(kappa * (np.cos(grid[:, None] - np.asarray(angles_rad)[None, :]) - 1.0))
    return float(grid[int(np.argmax(score.sum(axis=1)))])


def _thesis_step(
    current: Fingerprint, goal: Fingerprint, params: StepParams, shift_rad: float | None
) -> HomeStep:
    if current.n == 0 or goal.n == 0:
        raise HomingError(f"no features: {current.n} here, {goal.n} at the goal")
    shift = (
        bearing_shift_rad(goal.bearings_rad, current.bearings_rad, method=params.compass)
        if shift_rad is None
        else shift_rad
    )
    alv_here = alv_from_bearings(current.bearings_rad)
    alv_goal = alv_from_bearings(goal.bearings_rad)
    return HomeStep(home_vector(alv_here, alv_goal, 0.0, shift), shift, current.n)


def matched_inliers(
    current: Fingerprint,
    goal: Fingerprint,
    params: StepParams,
    shift_rad: float | None = None,
    pairs: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Descriptor matches ``(k, 2)`` [current_row, goal_row] consistent with one rotation, and
    that rotation (radians, goal -> current bearings; ``shift_rad`` if known, else estimated).
    ``pairs``: the descriptor matches if already made (else they are made here)."""
    if pairs is None:
        pairs = match_descriptors(current.descriptors, goal.descriptors, params.ratio)
    if len(pairs) < params.min_matches:
        raise HomingError(f"only {len(pairs)} descriptor matches (need {params.min_matches})")
    here = current.bearings_rad[pairs[:, 0]]
    there = goal.bearings_rad[pairs[:, 1]]
    peak = density_peak_rad(wrap_angle_rad(here - there)) if shift_rad is None else shift_rad
    inlier = np.abs(wrap_angle_rad(here - there - peak)) <= math.radians(params.outlier_deg)
    if inlier.sum() < params.min_matches:
        raise HomingError(f"only {int(inlier.sum())} matches agree on a rotation")
    if shift_rad is not None:
        return pairs[inlier], shift_rad
    shift = float(matched_shift_rad(there[inlier], here[inlier], np.ones(int(inlier.sum()))))
    return pairs[inlier], shift


def _best_step(
    current: Fingerprint,
    goal: Fingerprint,
    params: StepParams,
    shift_rad: float | None,
    matches: np.ndarray | None = None,
) -> HomeStep:
    pairs, shift = matched_inliers(current, goal, params, shift_rad, matches)
    here = current.bearings_rad[pairs[:, 0]]
    there = goal.bearings_rad[pairs[:, 1]]
    home = matched_home_vector(here, there, shift)
    if not np.all(np.isfinite(home)):
        raise HomingError(f"no home vector from {len(pairs)} inliers and rotation {shift} rad")
    parallax = float(np.median(np.abs(wrap_angle_rad(here - there - shift))))
    return HomeStep(home, shift, len(pairs), parallax)


def counted_distance_vote(
    verification: Verification,
    rays_here: np.ndarray,
    rays_home: np.ndarray,
    sizes_here_rad: np.ndarray | None,
    sizes_home_rad: np.ndarray | None,
) -> int:
    """The distance vote of :func:`localizer.verification.distance_vote` (query: here, place:
    home; the keypoint sizes as angles, :meth:`mapdb.records.Fingerprint.keypoint_sizes_rad`,
    None where not known) where its t-statistic is at least :data:`DISTANCE_VOTE_MIN_T`,
    else 0."""
    vote, statistic = distance_vote(
        verification, rays_here, rays_home, sizes_here_rad, sizes_home_rad
    )
    return vote if abs(statistic) >= DISTANCE_VOTE_MIN_T else 0


def signed_pose_direction_rad(
    verification: Verification,
    matched_rad: float,
    alv_here: np.ndarray,
    alv_home: np.ndarray,
    cheirality: int,
    distance: int = 0,
) -> float:
    """The home direction of the "pose" variant (rad, current robot frame, (-pi, pi]).

    The axis of ``verification``'s translation (query: here, place: home) with the sign that
    ``distance`` gives (+1: the translation as it is, -1: its opposite, 0: none; the inliers'
    change of distance where it is significant: :func:`counted_distance_vote`), else the sign
    that most of three votes give: ``cheirality`` (the same signs;
    :func:`localizer.verification.cheirality_sign`), ``matched_rad`` (the matched-ALV
    direction; no vote if NaN) and the ALV home vector of all features (``alv_here``,
    ``alv_home`` (2,), each in its own robot frame) rotated by the pose's yaw; an ALV votes for
    the side of the axis it lies on, and a tie goes the cheirality's way. The three fail where
    the points lie near the axis and their bearings barely change (along a hall), where the
    distances change most; each fails somewhere else too: the cheirality where a repeating floor
    texture outvotes the walls, the ALV of all features where they are unevenly spread (the
    tiled square room), the matched ALV with few matches. Without a translation axis: the
    circular mean of the rough directions there are (the matched ALV alone when the pose has
    no yaw); NaN if none.
    """
    alv_dir_rad = math.nan
    if math.isfinite(verification.yaw_rad):
        alv_dir_rad = float(
            alv_home_directions_rad(
                np.asarray(alv_here, dtype=float)[None, :2],
                np.asarray(alv_home, dtype=float)[None, :2],
                np.array([-verification.yaw_rad]),
            )[0]
        )
    axis_rad = home_direction_rad(verification)
    if math.isnan(axis_rad):
        return float(mean_direction_rad(matched_rad, alv_dir_rad))
    if distance:
        flip = distance < 0
    else:
        rough = [d for d in (matched_rad, alv_dir_rad) if math.isfinite(d)]
        votes = cheirality + sum(float(np.sign(math.cos(d - axis_rad))) for d in rough)
        flip = votes < 0 or (votes == 0 and cheirality < 0)
    return float(wrap_angle_rad(axis_rad + math.pi)) if flip else axis_rad


def _pose_step(
    current: Fingerprint, goal: Fingerprint, params: StepParams, shift_rad: float | None
) -> HomeStep:
    matches = match_descriptors(current.descriptors, goal.descriptors, params.ratio)
    matched = _best_step(current, goal, params, shift_rad, matches)
    rays_here, rays_goal = current.rays(), goal.rays()
    verification = verify(rays_here, rays_goal, matches, HOMING_VERIFICATION)
    if math.isnan(home_direction_rad(verification)):
        return matched
    direction = signed_pose_direction_rad(
        verification,
        matched.direction_rad,
        alv_from_bearings(current.bearings_rad),
        alv_from_bearings(goal.bearings_rad),
        cheirality_sign(verification, rays_here, rays_goal),
        counted_distance_vote(
            verification,
            rays_here,
            rays_goal,
            current.keypoint_sizes_rad(),
            goal.keypoint_sizes_rad(),
        ),
    )
    home = matched.length * np.array([math.cos(direction), math.sin(direction)])
    shift = -verification.yaw_rad if shift_rad is None else shift_rad
    return HomeStep(home, shift, matched.n_used, matched.parallax_rad)


def home_step(
    current: Fingerprint,
    goal: Fingerprint,
    params: StepParams | None = None,
    shift_rad: float | None = None,
) -> HomeStep:
    """The home vector from ``current`` toward ``goal`` (see the module docstring).

    ``shift_rad``: the rotation from the goal view to the current view (a goal feature at
    bearing b is seen at b + shift_rad; i.e. goal heading minus current heading) when it is
    known, e.g. from a magnetic compass; None estimates it from the images.

    Raises ``ValueError`` if the fingerprints come from different detectors and
    :class:`homing.alv.HomingError` when there are too few features or matches.
    """
    params = params or StepParams()
    if current.detector != goal.detector:
        raise ValueError(f"detectors differ: current {current.detector!r}, goal {goal.detector!r}")
    if params.variant == "thesis":
        return _thesis_step(current, goal, params, shift_rad)
    if params.variant == "pose":
        return _pose_step(current, goal, params, shift_rad)
    return _best_step(current, goal, params, shift_rad)


@dataclass(frozen=True)
class HomingParams:
    """The homing loop's settings (distances in metres; see the module docstring)."""

    step: StepParams = StepParams()
    gain_m: float = 2.0
    min_step_m: float = 0.05
    max_step_m: float = 0.5
    arrive_length: float = 0.02
    arrive_parallax_deg: float = 2.0
    arrive_matched_fraction: float = 0.3
    converged_scale: float = 0.2
    reverse_deg: float = 90.0
    scale_down: float = 0.5
    scale_up: float = 1.25
    max_steps: int = 40
    max_bumps: int = 3
    max_lost: int = 2
    sidestep_m: float = 0.2

    def __post_init__(self) -> None:
        if not 0 < self.min_step_m <= self.max_step_m:
            raise ValueError(f"need 0 < min_step_m <= max_step_m, got {self}")
        if self.gain_m <= 0 or self.arrive_length < 0 or self.max_steps < 1:
            raise ValueError(f"gain_m > 0, arrive_length >= 0 and max_steps >= 1, got {self}")
        if not 0 <= self.arrive_matched_fraction <= 1:
            raise ValueError(
                f"arrive_matched_fraction must be in [0, 1], got {self.arrive_matched_fraction}"
            )


CANCELLED = "cancelled"
"""The :attr:`HomingResult.reason` of a drive someone cancelled (the service's homing node):
no further drive follows."""


@dataclass(frozen=True)
class HomingResult:
    """How a homing run ended.

    ``arrived``: the images say the robot is at the goal; ``steps``: moves made (sidesteps
    included); ``distance_m``: odometric distance driven; ``reason``: ``"arrived"``,
    ``"converged"``, ``"max_steps"``, ``"blocked"`` or ``"lost"`` (too few features or matches);
    ``last``: the fingerprint of the last capture; ``lengths``: home-vector length per capture.
    """

    arrived: bool
    steps: int
    distance_m: float
    reason: str
    last: Fingerprint
    lengths: tuple[float, ...] = ()


@dataclass(frozen=True)
class HomingProgress:
    """What :func:`drive_home` knows after one capture: ``steps`` moves made and
    ``distance_m`` driven (odometric) so far, the current ``view`` and its ``home`` step, None
    when the view had too few features or matches (a recovery move
    follows). There is no metric distance to the goal: the ALV length and, for "best", the
    parallax shrink toward it, but a bearing-only view has no scale."""

    steps: int
    distance_m: float
    view: Fingerprint
    home: HomeStep | None


def grey_extractor(
    preset: str = "sift", camera: CameraSpec | None = None
) -> Callable[[np.ndarray], Fingerprint]:
    """An ``extract`` for :func:`drive_home`: BGR or grey uint8 panorama -> fingerprint.

    ``camera``: read the image through that camera model
    (:func:`localizer.features.extract_with_camera`; ``CameraSpec()`` reads a 2:1 image as
    equirectangular); None extracts on the whole image as a cylinder (``extract_preset``).
    """

    def extract(image: np.ndarray) -> Fingerprint:
        grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
        if camera is not None:
            return extract_with_camera(grey, camera, preset)
        return extract_preset(grey, preset)

    return extract


def _goal_in_view(step: HomeStep, goal: Fingerprint, p: HomingParams) -> bool:
    """Whether the matched inliers are at least ``arrive_matched_fraction`` of the goal's
    features (always, for the thesis variant: it matches nothing)."""
    if p.step.variant == "thesis":
        return True
    return step.n_used >= p.arrive_matched_fraction * goal.n


def _arrived(step: HomeStep, goal: Fingerprint, p: HomingParams) -> bool:
    """The image-only arrival test: a short home vector and, where known, little parallax and
    most of the goal's view matched."""
    small_parallax = math.isnan(step.parallax_rad) or (
        step.parallax_rad < math.radians(p.arrive_parallax_deg)
    )
    return step.length < p.arrive_length and small_parallax and _goal_in_view(step, goal, p)


def same_spot(here: Fingerprint, there: Fingerprint, params: HomingParams | None = None) -> bool:
    """Whether the view ``here`` was taken where the view ``there`` was, by the images alone:
    homing from ``here`` toward ``there`` would say it has arrived (a short home vector, little
    parallax, ``arrive_matched_fraction`` of ``there``'s features matched; see the module
    docstring): within about 0.1 m in the rendered square room. False where
    the two views match too little to tell, or come from different detectors. By default the
    "best" step: the test needs its length, parallax and matches only, not the pose."""
    params = params or HomingParams(step=StepParams("best"))
    if here.detector != there.detector:
        return False
    try:
        step = home_step(here, there, params.step)
    except HomingError:
        return False
    return _arrived(step, there, params)


def drive_home(
    robot: Robot,
    goal: Fingerprint,
    extract: Callable[[np.ndarray], Fingerprint],
    params: HomingParams | None = None,
    on_step: Callable[[HomingProgress], None] | None = None,
) -> HomingResult:
    """Drive ``robot`` by visual homing until the images say it reached ``goal``.

    ``extract`` must use the goal's detector and settings. See the module docstring for the
    step length, the arrival test and what happens on a bump. ``on_step`` is called after each
    capture with the :class:`HomingProgress` so far (an exception it raises ends the run).
    """
    p = params or HomingParams()
    notify = on_step or (lambda progress: None)
    steps, distance, bumps, lost, scale = 0, 0.0, 0, 0, 1.0
    previous_goal_dir: float | None = None
    lengths: list[float] = []

    def done(arrived: bool, reason: str, last: Fingerprint) -> HomingResult:
        return HomingResult(arrived, steps, distance, reason, last, tuple(lengths))

    def move(turn_rad: float, forward_m: float) -> bool:
        nonlocal steps, distance
        moved = robot.move(turn_rad, forward_m)
        steps, distance = steps + 1, distance + abs(moved.moved_m)
        return moved.bumped

    while True:
        current = extract(robot.capture().image)
        try:
            step = home_step(current, goal, p.step)
        except HomingError:
            notify(HomingProgress(steps, distance, current, None))
            lost += 1
            if lost > p.max_lost or steps >= p.max_steps:
                return done(False, "lost", current)
            move(2.0 * math.pi / 3.0, p.sidestep_m)  # look from a little further on
            previous_goal_dir = None
            continue
        lost = 0
        notify(HomingProgress(steps, distance, current, step))
        lengths.append(step.length)
        if _arrived(step, goal, p):
            return done(True, "arrived", current)
        goal_dir = step.direction_rad - step.shift_rad  # home direction in the goal view's frame
        if previous_goal_dir is not None:
            turned = abs(float(wrap_angle_rad(goal_dir - previous_goal_dir)))
            reversed_ = turned > math.radians(p.reverse_deg)
            scale = scale * p.scale_down if reversed_ else min(1.0, scale * p.scale_up)
        previous_goal_dir = goal_dir
        if scale < p.converged_scale:
            return done(_goal_in_view(step, goal, p), "converged", current)
        if steps >= p.max_steps:
            return done(False, "max_steps", current)
        length_m = float(np.clip(p.gain_m * step.length, p.min_step_m, p.max_step_m))
        if not move(step.direction_rad, max(length_m * scale, p.min_step_m)):
            bumps = 0
            continue
        bumps += 1  # consecutive homing moves that ended in contact
        if bumps > p.max_bumps:
            return done(False, "blocked", current)
        side = math.pi / 2 if bumps % 2 else -math.pi / 2
        if move(side, p.sidestep_m):
            move(math.pi, p.sidestep_m)  # boxed in on that side too: back off the other way
        previous_goal_dir = None  # the sidestep is not a homing step: no overshoot test
