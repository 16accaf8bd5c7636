"""The localizer: the evidence of one panorama, and the belief over rooms.

:class:`Localizer` turns a panorama into evidence (extraction, retrieval, verification) against
a :class:`~localizer.loaded_map.LoadedMap` and keeps the Bayes filter over rooms. It holds no
open database handle.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property

import cv2
import numpy as np

from localizer.belief import (
    BeliefFilter,
    LocalizationState,
    PartlySeen,
    RoomBelief,
    StateThresholds,
)
from localizer.cameras import CameraSpec
from localizer.evidence import (
    EvidenceParams,
    QueryEvidence,
    azimuth_coverage,
    evaluate_place,
    place_evidence,
)
from localizer.features import extract_with_camera, matching_overrides
from localizer.likelihood import Likelihood, RatioLikelihood, room_inliers, room_likelihood
from localizer.loaded_map import LoadedMap
from localizer.lookalikes import (
    EXACT_COUNTERPART_SHARE,
    lookalike_groups,
    partners_of,
    twin_counts,
)
from localizer.policy import PlaceSimilarity
from localizer.robot_protocol import Pose2D
from localizer.visual_homing import same_spot
from mapdb.records import Fingerprint

HOMED_ONE_PLACE_RATIO = 3.0
"""A frame taken where the robot homed to the one place of a room without a known look-alike
favours that room over the next by at most this ratio. Homing arrives wherever the view looks
like the place: in its room, or in a twin the calibration could not find, one place per room
giving it nothing to compare (a house recorded one place per room, world seed 21: the twin
bedrooms' places verified each other at 4–5 spread inliers, as chance does; two robots in
bedroom_b homed to bedroom_a's place and the frame there said bedroom_a, 0.998). The room is
then checked by a recorded route (:mod:`localizer.route_checks`), which a twin's different door
tells apart."""

PARTIAL_VIEW_RATIO = 3.0
"""A frame that sees a room on less than ``StateThresholds.min_coverage`` of its horizon
favours that room over each room it opens onto by at most this ratio (as
:data:`HOMED_ONE_PLACE_RATIO`, one view that cannot tell two rooms apart): a robot in the next
room, looking through the door, sees it so (:meth:`Localizer.frame_likelihood`)."""

SAME_VIEW_M = 0.3
"""A frame taken within this many metres (odometric) of the latest frame sees what that frame
saw: it replaces the latest frame's evidence in the belief instead of multiplying with it.
Views of one scene 0.25 m apart still verify each other on about a quarter of their keypoints,
at 0.5 m on 0.14–0.21, at 1 m on 0.10 (``building``'s offices, see
:data:`localizer.lookalikes.COUNTERPART_SHARE`). On the small rendered ``building`` map a robot
in office_a read office_b 4 : 1 on the twins' counterparts at its first look, homing then
stopped 0.2 m away, the next look read 2.7 : 1 the same way, and the two made it sure of
office_b, 0.92."""


@dataclass(frozen=True)
class LocalizerConfig:
    """How the localizer works; the defaults are documented in each part's class.

    ``detector``: the extraction preset the map was built with (``sift``, ``mser``, ...).
    ``use_index``: shortlist places with the retrieval index before verification (``None``:
    when the map has at least :data:`~localizer.loaded_map.INDEX_MIN_PLACES` places).
    ``camera``: the model of the panoramas to localize (:mod:`localizer.cameras`; ``auto`` by
    their size).
    ``stay_probability``: per move, the chance of staying in the same room (the prediction
    along the room graph). ``likelihood``: how a frame's evidence weighs the rooms (None: the
    map's calibration, else :class:`~localizer.likelihood.RatioLikelihood`'s defaults); its
    ``min_inliers`` is also the ``lost`` test. ``extraction_threads``: a query panorama's halves
    are detected on this many threads (:func:`localizer.features.extract`; 1: one call).
    ``passive_anywhere_probability``: a passive frame (:meth:`Localizer.update`) from a new
    view first spreads the belief along the room graph and this share of it over every room:
    between two requests the robot may have been driven through several rooms, carried, or
    taken through a door the map does not hold (a map of photos has no doors at all).
    """

    detector: str = "sift"
    evidence: EvidenceParams = field(default_factory=EvidenceParams)
    likelihood: Likelihood | None = None
    thresholds: StateThresholds = field(default_factory=StateThresholds)
    stay_probability: float = 0.8
    use_index: bool | None = None
    camera: CameraSpec = field(default_factory=CameraSpec)
    extraction_threads: int = 2
    passive_anywhere_probability: float = 0.05

    def __post_init__(self) -> None:
        if self.extraction_threads < 1:
            raise ValueError(f"extraction_threads must be >= 1, got {self.extraction_threads!r}")
        if not 0.0 <= self.passive_anywhere_probability <= 1.0:
            raise ValueError(
                "passive_anywhere_probability must be in [0, 1], got "
                f"{self.passive_anywhere_probability!r}"
            )


@dataclass(frozen=True)
class Observation:
    """One panorama seen by the localizer: its fingerprint, its evidence and the timings (ms);
    ``at_place``: the place the robot homed to before capturing it (None: it was not driven
    to one; see :func:`localizer.lookalikes.twin_counts`); ``odometry``: the robot's odometric
    pose when it was captured (None: unknown), by which frames taken at one spot count once
    (:data:`SAME_VIEW_M`)."""

    fingerprint: Fingerprint
    evidence: QueryEvidence
    timing_ms: Mapping[str, float]
    at_place: int | None = None
    odometry: Pose2D | None = None

    @cached_property
    def room_coverages(self) -> dict[str, float]:
        """For each room with inliers in this frame, the share of its horizon (0 to 1) that
        those inliers, with all of the room's places together, cover
        (:func:`~localizer.evidence.azimuth_coverage`); computed once per frame (the belief
        reads it on every request)."""
        rows: dict[str, list[np.ndarray]] = {}
        for item in self.evidence.places:
            if len(item.inlier_pairs):
                rows.setdefault(item.room, []).append(item.inlier_pairs[:, 0])
        if not rows:
            return {}
        rays = self.fingerprint.rays()
        return {room: azimuth_coverage(rays[np.concatenate(parts)]) for room, parts in rows.items()}


def to_grey(image: np.ndarray) -> np.ndarray:
    """A uint8 grey panorama from a grey or BGR one (``ValueError`` for other shapes)."""
    if image.ndim == 2:
        return image
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    raise ValueError(f"a panorama must be H x W or H x W x 3, got shape {image.shape}")


class Localizer:
    """Evidence and belief for panoramas against one loaded map.

    Not thread-safe: a service serialises calls (see ``toploc.service``).
    """

    def __init__(self, loaded: LoadedMap, config: LocalizerConfig | None = None) -> None:
        self.config = config or LocalizerConfig()
        self.latest: Observation | None = None
        self.doubted: frozenset[str] = frozenset()
        # the first frame of the latest view and the belief before it: frames from its spot
        # replace the evidence since, instead of adding to it
        self._view: tuple[Observation, np.ndarray] | None = None
        # the latest frame and, per room, whether it was taken on one of the room's places
        self._on_place: tuple[Observation | None, dict[str, bool]] = (None, {})
        self._use(loaded)

    def _use(self, loaded: LoadedMap) -> None:
        """Localize against ``loaded`` from now on: its graph, likelihood and evidence params."""
        self.map = loaded
        self.filter = BeliefFilter(loaded.rooms, loaded.edges, self.config.stay_probability)
        self._similarity: dict[tuple[int, int], int] = {}
        self.likelihood: Likelihood = (
            self.config.likelihood or loaded.likelihood or RatioLikelihood()
        )
        calibrated = self.likelihood if isinstance(self.likelihood, RatioLikelihood) else None
        self.evidence_params = _resolved(self.config.evidence, calibrated)
        pairs = calibrated.lookalikes if calibrated is not None else ()
        self.lookalike_groups = lookalike_groups(pairs, loaded.rooms)
        self.lookalikes = partners_of(pairs)
        index = {room: i for i, room in enumerate(loaded.rooms)}
        self._lookalike_pairs = [(index[a], index[b]) for a, b in pairs if {a, b} <= index.keys()]
        self.doors = partners_of(loaded.edges)  # the rooms each room opens onto
        self.counterparts = partners_of(calibrated.counterparts if calibrated is not None else ())
        # a query is extracted as the map's places were: their equalisation and keypoint cap
        self._overrides = matching_overrides(loaded.table.params[0]) if loaded.table.params else {}

    def replace_map(self, loaded: LoadedMap) -> RoomBelief:
        """Localize against ``loaded`` (the map re-read after places, rooms or edges were added)
        from now on, keeping the belief: each room both maps know keeps its probability, a new
        room starts at ``1 / n_rooms`` (then all are normalised). The latest observation stays
        (its places are still in the map). Returns the belief."""
        old = self.filter.as_dict()
        self._use(loaded)
        share = 1.0 / len(loaded.rooms)
        prior = {room: old.get(room, share) for room in loaded.rooms}
        self.filter.reset(prior if sum(prior.values()) > 0 else None)
        self._view = None  # of the old map's rooms
        return self.belief()

    def extract(self, image: np.ndarray, source: str = "image") -> Fingerprint:
        """The fingerprint of a camera image (grey or BGR uint8) with the map's detector,
        contrast equalisation and keypoint cap (:func:`localizer.features.matching_overrides`),
        read through the configured camera model; ``source`` names the image if its size is
        no 360° panorama's (:class:`~localizer.cameras.NotPanoramaError`)."""
        return extract_with_camera(
            to_grey(image),
            self.config.camera,
            self.config.detector,
            threads=self.config.extraction_threads,
            source=source,
            **self._overrides,
        )

    def observe(self, image: np.ndarray, source: str = "image") -> Observation:
        """Extract and gather evidence against the map; the belief is not changed. ``source``
        names the image in errors (see :meth:`extract`)."""
        t0 = time.perf_counter()
        fingerprint = self.extract(image, source)
        extraction_ms = (time.perf_counter() - t0) * 1e3
        return self.observe_fingerprint(fingerprint, extraction_ms)

    def observe_fingerprint(
        self, fingerprint: Fingerprint, extraction_ms: float = 0.0, exclude: int | None = None
    ) -> Observation:
        """Evidence for an already extracted fingerprint; ``exclude`` leaves one place out
        (leave-one-out evaluation of the map's own places)."""
        evidence = place_evidence(
            fingerprint,
            self.map.table,
            self.evidence_params,
            self.map.index,
            exclude=exclude,
        )
        timing = {"extraction": extraction_ms, **evidence.timing_ms}
        return Observation(fingerprint, evidence, timing)

    def frame_likelihood(self, observation: Observation) -> np.ndarray:
        """One frame's likelihood per room (order of the map's rooms, sums to 1); look-alike
        rooms the map's calibration found are read on counterparts, or weighed as equally
        likely where the frame has none (:mod:`localizer.lookalikes`)."""
        seen = self._through_doors(self._frame_likelihood(observation), observation)
        return self._held_doubted(self._one_viewpoint(seen, observation.at_place))

    def _frame_likelihood(self, observation: Observation) -> np.ndarray:
        model, evidence = self.likelihood, observation.evidence.places
        if not self.lookalike_groups or not isinstance(model, RatioLikelihood):
            return room_likelihood(evidence, self.map.rooms, model)
        counts = room_inliers(evidence, self.map.rooms, count=model.count)
        read, aliased = twin_counts(
            evidence,
            self.map.rooms,
            counts,
            self.lookalike_groups,
            self._readable_counterparts(observation.at_place),
            count=model.count,
            at_place=self._inexact_counterpart(observation.at_place),
            min_count=model.min_inliers,
        )
        compared = [group for group in self.lookalike_groups if group not in aliased]
        return model.from_counts(counts, aliased, compared, read, self._lookalike_pairs)

    def _through_doors(self, likelihood: np.ndarray, observation: Observation) -> np.ndarray:
        """``likelihood`` with the rooms that a room seen on less than ``min_coverage`` of
        ``observation``'s horizon (:attr:`Observation.room_coverages`) opens onto
        (:attr:`doors`) raised to at least that room's likelihood over
        :data:`PARTIAL_VIEW_RATIO`: a room seen on part of the horizon is what a robot sees of
        it from its door, standing in the next room, as much as from inside it. On world seed
        49's house recorded two places per room, four robots in the kitchen saw the hall's
        place on 0.37-0.54 of the horizon (19-45 inliers; the kitchen's own places at 3-7) and
        said the hall, 0.997-1.0."""
        if len(likelihood) < 2:
            return likelihood
        limit = self.config.thresholds.min_coverage
        rooms = self.map.rooms
        coverages = observation.room_coverages
        partial = [
            room for room, share in coverages.items() if share < limit and self.doors.get(room)
        ]
        if not partial:
            return likelihood
        raised = likelihood.copy()
        for room in partial:
            value = likelihood[rooms.index(room)] / PARTIAL_VIEW_RATIO
            for other in self.doors[room]:
                j = rooms.index(other)
                raised[j] = max(raised[j], value)
        return raised / raised.sum()

    def alone(self, room: str) -> bool:
        """Whether ``room`` has one place and no known look-alike: a frame at that place, homed
        to, may come from a twin the map does not know (:data:`HOMED_ONE_PLACE_RATIO`)."""
        return self.map.places_per_room[room] < 2 and not self.lookalikes.get(room)

    def _one_viewpoint(self, likelihood: np.ndarray, at_place: int | None) -> np.ndarray:
        """``likelihood`` with the room of ``at_place`` (the place homed to) held to
        :data:`HOMED_ONE_PLACE_RATIO` times the next room when it is :meth:`alone`."""
        if at_place is None or len(likelihood) < 2:
            return likelihood
        room = self.map.place(at_place).room
        if not self.alone(room):
            return likelihood
        i = self.map.rooms.index(room)
        cap = HOMED_ONE_PLACE_RATIO * float(np.delete(likelihood, i).max())
        if not 0.0 < cap < likelihood[i]:
            return likelihood
        held = likelihood.copy()
        held[i] = cap
        return held / held.sum()

    def doubt(self, room: str) -> RoomBelief:
        """Take back what frames told for ``room``: its probability is brought down to the
        likeliest other room's, and until :meth:`reset` a frame favours it no more than that
        room. For a room that is :meth:`alone` whose check by a route did not arrive, or whose
        one place the robot could not home to: a frame that looks like it may come from a twin
        the map does not know, or from a room whose walls look like a part of it (world seed
        30's house, one place per room: a robot in bedroom_b whose check of bedroom_a missed,
        0.81, looked twice more near the spot of bedroom_a's place in its own bedroom and ended
        sure of bedroom_a, 1.0; on seed 31's, a first look 0.999 sure of the twin outlasted the
        miss). Returns the belief."""
        if room not in self.map.rooms:
            raise ValueError(f"no room {room!r} in the map {self.map.path}")
        self.doubted = self.doubted | {room}
        probabilities = self.filter.probabilities
        i = self.map.rooms.index(room)
        others = float(np.delete(probabilities, i).max()) if len(probabilities) > 1 else 0.0
        if 0.0 < others < probabilities[i]:
            values = np.ones(len(probabilities))
            values[i] = others / probabilities[i]
            self.filter.update(values)
            self._view = None
        return self.belief()

    def _held_doubted(self, likelihood: np.ndarray) -> np.ndarray:
        """``likelihood`` with each :attr:`doubted` room held to the likeliest other room."""
        if not self.doubted or len(likelihood) < 2:
            return likelihood
        held = likelihood.copy()
        for room in self.doubted:
            i = self.map.rooms.index(room)
            held[i] = min(held[i], float(np.delete(likelihood, i).max()))
        return held / held.sum() if held.sum() > 0 else likelihood

    def same_spot_places(self, place_id: int) -> tuple[int, ...]:
        """The counterparts of ``place_id`` that stand on its spot: they verify each other on
        at least :data:`~localizer.lookalikes.EXACT_COUNTERPART_SHARE` of its keypoints (a
        map rendered on a grid in each twin's frame). Homing to one of them ends where homing
        to ``place_id`` did, and a frame there repeats the view already taken."""
        keypoints = self.map.keypoints(place_id)
        return tuple(
            sorted(
                partner
                for partner in self.counterparts.get(place_id, ())
                if self._pair_inliers(place_id, partner) >= EXACT_COUNTERPART_SHARE * keypoints
            )
        )

    def _readable_counterparts(self, at_place: int | None) -> dict[int, frozenset[int]]:
        """The counterparts a frame's twins are read on (:func:`twin_counts`): those on one
        spot (:meth:`same_spot_places`), and those of ``at_place``, the place the robot homed
        to. Read from anywhere else, a pair that stands off one spot says which of its places
        stands nearer the robot, as the twins' best counts do (world seed 34's building, two
        places per room: a robot in office_a homed to the spot of office_b's place 5, and the
        frame read the pair of office_a's 4 and office_b's 6, which stand apart, 115 against
        147 spread inliers: most of what a check of office_b that missed had told was taken
        back)."""
        readable = {}
        for place, partners in self.counterparts.items():
            exact = set(self.same_spot_places(place))
            kept = {p for p in partners if at_place in (place, p) or p in exact}
            if kept:
                readable[place] = frozenset(kept)
        return readable

    def _inexact_counterpart(self, place_id: int | None) -> int | None:
        """``place_id`` if one of its counterparts stands off its spot (they verify each other
        on less than :data:`~localizer.lookalikes.EXACT_COUNTERPART_SHARE`), else None."""
        if place_id is None or place_id not in self.counterparts:
            return None
        apart = self.counterparts[place_id] - set(self.same_spot_places(place_id))
        return place_id if apart else None

    def update(self, observation: Observation, passive: bool = False) -> RoomBelief:
        """Fold an observation into the belief (Bayes update) and return the new belief.

        A frame of the latest view (:meth:`_same_view`: taken on the spot of that view's first
        frame), with nothing else folded in since, replaces the evidence of the view's frames
        instead of adding to it: one view of a scene is one piece of evidence, however often
        it is captured. ``passive``: the service's passive localizations, which do not know
        how the robot moved: a frame of a new view, after an earlier frame, is folded in after
        the belief is spread along the room graph and
        :attr:`LocalizerConfig.passive_anywhere_probability` of it over every room (the
        active loop spreads it itself, by the drives it makes)."""
        likelihood = self.frame_likelihood(observation)
        if self._view is not None and self._same_view(observation, self._view[0]):
            self.filter.reset(dict(zip(self.map.rooms, self._view[1], strict=True)))
        else:
            if passive and self.latest is not None:
                self.filter.predict(anywhere_probability=self.config.passive_anywhere_probability)
            self._view = (observation, self.filter.probabilities)
        self.filter.update(likelihood)
        self.latest = observation
        return self.belief()

    @staticmethod
    def _same_view(observation: Observation, first: Observation) -> bool:
        """Whether ``observation`` was taken within :data:`SAME_VIEW_M` of ``first``, by their
        odometry; without odometry on either, whether the images say they were taken on one
        spot (:func:`localizer.visual_homing.same_spot`, a stricter test: about 0.1 m in the
        rendered square room): a camera alone, asked again and again while it stands still."""
        here, there = observation.odometry, first.odometry
        if here is None or there is None:
            return same_spot(observation.fingerprint, first.fingerprint)
        return float(np.hypot(here.x_m - there.x_m, here.y_m - there.y_m)) <= SAME_VIEW_M

    def update_rooms(self, likelihood: Mapping[str, float]) -> RoomBelief:
        """Fold a likelihood given per room (a room not named: 1) into the belief, as a check
        that is no frame does (a recorded route driven, :mod:`localizer.route_checks`); the latest
        observation stays. ``ValueError`` for an unknown room or a likelihood that is not a
        finite number >= 0."""
        unknown = set(likelihood) - set(self.map.rooms)
        if unknown:
            raise ValueError(f"no room {sorted(unknown)} in the map {self.map.path}")
        values = np.array([likelihood.get(room, 1.0) for room in self.map.rooms], dtype=float)
        if not (np.all(np.isfinite(values)) and np.all(values >= 0)):
            raise ValueError(f"a room likelihood must be a finite number >= 0, got {likelihood}")
        self.filter.update(values)
        self._view = None  # a frame after this adds to it, whatever the spot
        return self.belief()

    def predict(self, stay_probability: float | None = None) -> None:
        """The robot moved: spread the belief along the room graph."""
        self.filter.predict(stay_probability)

    def reset(self, prior: Mapping[str, float] | None = None) -> RoomBelief:
        """Uniform belief (global localization), or ``prior`` (``{room: weight}``)."""
        self.filter.reset(prior)
        self.latest = None
        self.doubted = frozenset()
        self._view = None
        return self.belief()

    def belief(self, state: LocalizationState | None = None) -> RoomBelief:
        """The current belief; ``state`` overrides the computed one (the service's homing)."""
        belief = self._belief_by_odds()
        if state is None and self._held_back(belief):
            room = belief.top[0]
            seen = PartlySeen(room, self._seen_share(room), self.config.thresholds.min_coverage)
            return replace(belief, state=LocalizationState.AMBIGUOUS, partly_seen=seen)
        return belief if state is None else belief.with_state(state)

    def _belief_by_odds(self) -> RoomBelief:
        """The current belief, its state by the probabilities and the latest frame's best count
        alone (:func:`localizer.belief.classify`)."""
        evidence = None if self.latest is None else self.latest.evidence.places
        return RoomBelief.from_probabilities(
            self.map.rooms,
            self.filter.probabilities,
            self._thresholds(self.filter.probabilities),
            evidence,
            stamp_s=time.time(),
            count=self.likelihood.count,
        )

    def unseen_room(self) -> str | None:
        """The most likely room when the belief would be ``localized`` but for that room not
        seen all round in the latest frame (:meth:`_seen_all_round`: the robot may be in its
        doorway, or in the next room); else None. Homing to one of its places and looking
        there answers it."""
        belief = self._belief_by_odds()
        return belief.top[0] if self._held_back(belief) else None

    def _held_back(self, belief: RoomBelief) -> bool:
        """Whether ``belief``, ``localized`` by its odds, waits because its most likely room
        is not seen all round in the latest frame (:meth:`_seen_all_round`)."""
        localized = belief.state is LocalizationState.LOCALIZED
        return localized and not self._seen_all_round(belief.top[0])

    def _seen_all_round(self, room: str) -> bool:
        """Whether the latest frame's inliers with ``room``'s places, all of them together,
        cover at least ``min_coverage`` of its horizon (see
        :class:`~localizer.belief.StateThresholds`); True before any frame. A robot in a
        doorway, or in the next room looking through the door, sees a room on half the horizon
        or less, whichever of its places it matches: taken for one place only, the test let
        a room of two places be said from its door (the first looks of world seeds 35-45's
        recorded maps, two places per room: 14 sure and wrong, 3 with the union of the
        places; docs/results.md), or whether the frame was taken on one of the room's places
        (:meth:`_on_a_place_of`)."""
        if self._seen_share(room) >= self.config.thresholds.min_coverage:
            return True
        return self._on_a_place_of(room)

    def _on_a_place_of(self, room: str) -> bool:
        """Whether the images say the latest frame was taken on the spot of one of ``room``'s
        places (:func:`~localizer.visual_homing.same_spot` with the two it verified with most
        inliers; memoized per frame): there the robot stands in the room, not at its door,
        however little of the horizon the room's bare walls let it match. On world seed 133's
        house recorded two places per room, three robots homed to bedroom_a's two places and
        arrived, and saw the room on 0.58-0.60 of the horizon from each (place 3's own
        keypoints cover 0.60 of it): they ended ambiguous at 0.99, right."""
        latest = self.latest
        if latest is None:
            return False
        if self._on_place[0] is not latest:
            self._on_place = (latest, {})
        known = self._on_place[1]
        if room not in known:
            seen = sorted(
                (item for item in latest.evidence.places if item.room == room and item.inliers),
                key=lambda item: item.inliers,
                reverse=True,
            )[:2]
            known[room] = any(
                same_spot(latest.fingerprint, self.map.fingerprint(item.place_id)) for item in seen
            )
        return known[room]

    def _seen_share(self, room: str) -> float:
        """The share of the horizon (0 to 1) the latest frame's inliers with ``room``'s
        places cover (:attr:`Observation.room_coverages`); 1 before any frame."""
        if self.latest is None:
            return 1.0
        return self.latest.room_coverages.get(room, 0.0)

    def _thresholds(self, probabilities: np.ndarray) -> StateThresholds:
        """The configured thresholds with the likelihood's lost test, and the stricter
        ``one_place_ratio`` when the most likely room has fewer than two places in the map."""
        thresholds = replace(self.config.thresholds, lost_min_inliers=self.likelihood.min_inliers)
        top_room = self.map.rooms[int(np.argmax(probabilities))]
        if self.map.places_per_room[top_room] < 2:
            ratio = max(thresholds.localized_ratio, thresholds.one_place_ratio)
            thresholds = replace(thresholds, localized_ratio=ratio)
        return thresholds

    def localize_once(
        self, image: np.ndarray, source: str = "image"
    ) -> tuple[RoomBelief, Observation]:
        """One-shot: uniform prior, one update with ``image`` (named ``source`` in errors)."""
        self.reset()
        observation = self.observe(image, source)
        return self.update(observation), observation

    def similarity(self, rows: tuple[int, ...], columns: tuple[int, ...] = ()) -> PlaceSimilarity:
        """Verified inliers between stored views, for the separating policy.

        The matrix covers ``rows`` and ``columns``; only the entries a policy reads are matched:
        each row against itself (its keypoint count: a view matches itself completely) and
        against every column. The others are 0. Each pair is matched once and cached.
        """
        ids = tuple(dict.fromkeys((*rows, *columns)))
        index = {place_id: i for i, place_id in enumerate(ids)}
        matrix = np.zeros((len(ids), len(ids)))
        for a in rows:
            for b in (a, *columns):
                matrix[index[a], index[b]] = self._pair_inliers(a, b)
        return PlaceSimilarity(ids, matrix)

    def _pair_inliers(self, query_id: int, reference_id: int) -> int:
        if query_id == reference_id:
            return self.map.keypoints(query_id)
        key = (query_id, reference_id)
        if key not in self._similarity:
            query = self.map.fingerprint(query_id)
            evidence = evaluate_place(
                query,
                query.rays(),
                self.map.fingerprint(reference_id),
                reference_id,
                self.map.table.rooms[self.map.table_index(reference_id)],
                self.evidence_params,
            )
            self._similarity[key] = evidence.inliers
        return self._similarity[key]


def _resolved(params: EvidenceParams, calibrated: RatioLikelihood | None) -> EvidenceParams:
    """``params`` with ``motion`` ``"auto"`` replaced by the calibrated likelihood's choice
    (general without one)."""
    if params.motion != "auto":
        return params
    return replace(params, motion="general" if calibrated is None else calibrated.motion)
