"""Repeat phase of colour-constant stereo VT&R: paper §IV-B (Fig. 3–4) and §IV-C (localization failure).

Per stereo frame (:meth:`RepeatPipeline.step`, the call a node makes per synchronized pair):

1. **Front end** (:class:`~lightfast.vtr.teach.SourceFrontEnd`): landmarks of the image sources the mode needs.
2. **VO on greyscale** (§IV-B 2: "VO is performed using only the greyscale images"): ``T_prev_cur`` from
   :class:`~lightfast.vtr.visual_odometry.VisualOdometry`; it propagates the last pose into the prior
   ``T_kf_cam`` ("The VO estimate is fed to the localizer as a prior, and is used as the final pose estimate if
   localization fails").
3. **Expected nearest keyframe**: the prior's distance along the taught path (keyframe path distance + the
   camera position projected on the local path direction) → :meth:`~lightfast.vtr.map_store.TeachMap.nearest`;
   the prior is re-expressed in that keyframe's frame.
4. **Localization against a window of keyframes** (:class:`MapLocalizer`) around it (``window_radius`` keyframes
   on each side; "a current local submap consisting of the keyframe the robot is closest to, with a window of
   adjacent keyframes that are relaxed into a single coordinate frame"): the window's landmarks are moved into the
   reference keyframe's frame by the chained teach edges; **each image source is matched separately** (the
   window's landmarks of that source, all keyframes together, against the current left keypoints of the same
   source, guided by the prior within ``match_radius_px``; Lowe's ratio per landmark over the current keypoints,
   mutual nearest neighbours, so a landmark seen by several keyframes matches a keypoint once); then, by mode:

   * ``fused`` (the paper's method, Fig. 4): the matches of **all sources are placed together** and sent to ONE
     RANSAC (3-point, keyframe points vs current stereo points, scored by the stereo reprojection error; without a
     prior half of the hypotheses by PROSAC from the matches ordered by descriptor distance,
     ``ransac_ordered_fraction``; optionally part from distance-consistent triples, ``ransac_consistent_fraction``)
     and ONE nonlinear
     refinement (:func:`~lightfast.vtr.visual_odometry.estimate_pose_stereo`);
   * ``grey`` (legacy system [6], Fig. 3): greyscale matches only;
   * ``mcmanus`` ([10]: "matched features from one image source are chosen ..., favoring the greyscale matches"):
     greyscale alone; only if that fails, each colour-constant source alone (computed on demand), the one with
     the most inliers wins — no fusion.

   Success needs ``min_inliers`` (paper §IV-C: six) inliers after outlier rejection. Two checks are added to the
   paper's rule (both configurable), because six inliers alone were measured to accept wrong poses on the
   synthetic scenes of ``test/unit/vtr/test_teach_repeat.py`` (greyscale under the changed lighting "localized"
   1.1–1.5 m off with exactly six inliers and a well-constrained pose): the camera position must be constrained
   (``max_position_std_m``, from the pose covariance at a nominal 1 px noise; rejects poses resting on far points
   only), and a windowed localization must lie within ``prior_gate_m + prior_gate_per_m · (distance on VO)`` of
   the VO prior (no gate for the whole-map search, which has no prior) — unless the previous frame's localization
   was beyond the gate as well, both have ``confirm_beyond_gate_inliers`` inliers and they agree after the VO motion
   between them: then the prior is the wrong one (a VO step gone astray).
5. **Failure handling** (§IV-C): without success the VO prior is the pose and the distance driven on VO alone
   accumulates; beyond ``max_distance_on_vo_m`` (20 m) it is a **localization failure**: the robot "stops" and
   the **whole map is searched** (every keyframe alone, or with ``search_window_radius`` neighbours, unguided
   matching, the mode's sources; the most inliers win). The search is repeated every frame until it succeeds
   (``relocalized``). Before the first localization the pipeline is in the same state (the paper: "the map is
   searched until the live stereo feed localizes");
   with ``initial_keyframe`` only the window around that keyframe is tried (unguided) until the failure distance.

Output per frame: :class:`RepeatResult` — ``T_kf_cam`` (the camera in the frame of keyframe ``keyframe_index``,
the one nearest along the path; metres, REP-103 optical axes), whether this frame localized, inliers per
source, the distance on VO since the last localization, the failure flag and whether the whole-map search
succeeded now. ``failure`` is set on every frame spent in the failure state (including the frame that starts
it and the one that ends it by relocalizing) and before the first localization: the frames on which the
robot would not drive autonomously.
"""
from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.config import Config, ConfigError, config_from_mapping, param
from lightfast.vtr.color_constant import ColorConstantConfig
from lightfast.vtr.errors import VtrInputError
from lightfast.vtr.map_store import TeachMap
from lightfast.vtr.stereo import NearestMatches, StereoConfig, StereoFeatures, check_stereo_pair
from lightfast.vtr.teach import SourceFrontEnd
from lightfast.vtr.visual_odometry import (
    StereoCamera,
    VisualOdometry,
    VisualOdometryConfig,
    VoResult,
    estimate_pose_stereo,
    match_landmarks,
    max_descriptor_distance,
)

__all__ = [
    "MODES",
    "Localization",
    "MapLocalizer",
    "RepeatConfig",
    "RepeatPipeline",
    "RepeatResult",
]

log = logging.getLogger(__name__)

#: Localization modes: the paper's fused method, the legacy greyscale system [6], McManus et al. [10].
MODES = ("fused", "grey", "mcmanus")
_COLOR_SOURCES = ("fv", "fr", "peak")


@dataclass(frozen=True)
class RepeatConfig(Config):
    """Options of the repeat phase (paper §IV-B, IV-C)."""

    mode: str = param("fused", description="Localization: fused (paper), grey (legacy [6]) or mcmanus ([10]).",
                      choices=MODES)
    window_radius: int = param(
        2, description="Keyframes on each side of the expected nearest keyframe in the localization window.", min=0,
        max=50,
    )
    search_window_radius: int = param(
        2, description="Keyframes on each side of every candidate keyframe in the whole-map search (0: each keyframe "
        "alone; 2, as window_radius, doubled the candidate matches at the start of the evening repeat07).", min=0,
        max=50,
    )
    min_inliers: int = param(6, description="Fewest inliers for a successful localization (paper: 6).", min=4)
    max_distance_on_vo_m: float = param(
        20.0, description="Distance on VO alone after which a localization failure is declared (paper: 20 m), m.",
        min=0.0,
    )
    match_radius_px: float = param(
        40.0, description="Guided map matching: a keyframe landmark must project within this of the current "
        "keypoint under the VO prior, px (0: unguided).", min=0.0,
    )
    ratio: float = param(0.9, description="Lowe ratio test of keyframe-to-frame matches (0.9: more candidates under "
                         "changed lighting; the mutual check and RANSAC remove the extra wrong ones).", min=0.0,
                         max=1.0)
    mutual: bool = param(True, description="Keep only mutually nearest keyframe-to-frame matches.")
    orb_max_distance: float = param(
        80.0, description="ORB: largest Hamming distance of a keyframe-to-frame match (of 256 bits).", min=0.0
    )
    sift_max_distance: float = param(
        300.0, description="SIFT: largest Euclidean distance of a keyframe-to-frame match.", min=0.0
    )
    ransac_threshold_px: float = param(
        3.0, description="RANSAC inlier threshold on the stereo reprojection error (u, v, disparity), px (3: map "
        "landmarks and live keypoints come from different stereo pairs, so their disparity errors add).", min=0.1,
        max=100.0,
    )
    ransac_iterations: int = param(1000, description="Most RANSAC hypotheses.", min=10, max=100000)
    ransac_confidence: float = param(0.999, description="RANSAC confidence (adaptive stop).", min=0.5,
                                     max=0.999999)
    ransac_consistent_fraction: float = param(
        0.0, description="Share of RANSAC hypotheses drawn from distance-consistent triples of matches (the rest "
        "uniformly): finds a few inliers among many matches (0.5 localized the first frame of the sunset repeat10, "
        "but also found a wrong place 63 m off at the start of repeat07: off by default).", min=0.0, max=1.0,
    )
    ransac_ordered_fraction: float = param(
        0.5, description="Unguided localizations (whole-map search, start window): share of RANSAC hypotheses drawn "
        "by PROSAC's progressive sampling from the matches ordered by descriptor distance (the rest uniformly): the "
        "correct matches concentrate among the closest when most are wrong (sunset repeat10's first frame localized "
        "in 30 of 40 seeds, 9 of 40 uniformly). Not used with a prior: there it found more wrong poses (a second "
        "simulated route, repeat07: 14 localizations > 1 m off vs 4).", min=0.0, max=1.0,
    )
    max_position_std_m: float = param(
        0.5, description="A localization also needs its camera position constrained to this standard deviation "
        "(nominal 1 px noise), m: rejects poses resting on far points only.", min=0.0,
    )
    prior_gate_m: float = param(
        0.5, description="A windowed localization farther than prior_gate_m + prior_gate_per_m * (distance on VO) "
        "from the VO prior is rejected, m (0: no gate).", min=0.0,
    )
    prior_gate_per_m: float = param(
        0.1, description="Growth of the prior gate per metre driven on VO alone (allowed VO drift), m/m.", min=0.0,
    )
    confirm_beyond_gate_inliers: int = param(
        30, description="Accept a windowed localization beyond the prior gate when it and the previous frame's, also "
        "beyond the gate, have at least this many inliers and agree within prior_gate_m after the VO motion between "
        "them: then the VO prior is the wrong one (in the cloudy evening repeat24 one VO step 1.8 m off made every "
        "following localization, 45-108 inliers, fail the gate until the 20 m failure; with no inlier minimum, "
        "consecutive wrong localizations of 13 inliers in the sand of repeat07 were accepted). 0: never.", min=0,
    )
    initial_keyframe: int = param(
        -1, description="Keyframe where the repeat starts (-1: search the whole map for the first localization).",
        min=-1,
    )
    workers: int = param(
        1, description="Threads of the stereo front end (one image source per thread; 1: sequential).", min=1,
        max=8,
    )


@dataclass(frozen=True)
class Localization:
    """A localization attempt: the camera pose ``T_ref_cam`` in keyframe ``ref_index``'s frame (m), success,
    per image source the matches sent to RANSAC and the inliers kept, the inliers' RMS stereo reprojection error
    (px) and the covariance of the pose (see :class:`~lightfast.vtr.visual_odometry.PoseEstimate`)."""

    T_ref_cam: NDArray[np.float64]
    ref_index: int
    success: bool
    inliers_per_source: Mapping[str, int]
    matches_per_source: Mapping[str, int]
    rms_px: float = float("nan")
    covariance: NDArray[np.float64] = field(default_factory=lambda: np.full((6, 6), np.inf))
    gated: bool = False  # failed only by the prior gate; T_ref_cam is then the rejected pose

    @property
    def inliers(self) -> int:
        return int(sum(self.inliers_per_source.values()))


@dataclass(frozen=True)
class RepeatResult:
    """One repeat step (module docstring). ``T_kf_cam`` is ``None`` (and ``keyframe_index`` −1) until the first
    localization; ``T_prev_cur`` is the VO motion used (m); ``distance_along_path_m`` the position along the taught
    path; ``covariance`` that of the localization on localized frames (6×6, ξ = (ρ, φ) in
    ``T_kf_cam · exp(ξ)``, camera frame, nominal 1 px noise), else ``None``; ``timing_s`` the time per stage (s)."""

    stamp_ns: int
    T_kf_cam: NDArray[np.float64] | None
    keyframe_index: int
    localized: bool
    inliers_per_source: Mapping[str, int]
    distance_on_vo_m: float
    failure: bool
    relocalized: bool
    matches_per_source: Mapping[str, int] = field(default_factory=dict)
    searched_map: bool = False
    vo_success: bool = False
    vo_inliers: int = 0
    T_prev_cur: NDArray[np.float64] = field(default_factory=lambda: np.eye(4))
    distance_along_path_m: float = float("nan")
    covariance: NDArray[np.float64] | None = None
    timing_s: Mapping[str, float] = field(default_factory=dict)

    @property
    def inliers(self) -> int:
        return int(sum(self.inliers_per_source.values()))


FeatureSupplier = Callable[[], Mapping[str, StereoFeatures]]


@dataclass(frozen=True)
class _Submap:
    """The landmarks of one source of a keyframe window, moved into the reference keyframe's frame."""

    points: NDArray[np.float64]
    descriptors: NDArray[np.generic]


class MapLocalizer:
    """Localization of the current frame against a teach map (step 4 of the module docstring)."""

    def __init__(self, teach_map: TeachMap, config: RepeatConfig | None = None) -> None:
        self.map = teach_map
        self.config = config or RepeatConfig()
        c = self.config
        if "grey" not in teach_map.sources:
            raise VtrInputError(f"the map has no greyscale landmarks (sources {list(teach_map.sources)})")
        if c.mode == "grey":
            self.sources: tuple[str, ...] = ("grey",)
        else:
            self.sources = ("grey", *[s for s in teach_map.sources if s != "grey"])
        self._max_d = max_descriptor_distance(teach_map.feature, c.orb_max_distance, c.sift_max_distance)
        self._submaps: dict[tuple[int, tuple[int, ...], str], _Submap] = {}
        # during a whole-map search: per (keyframe, source) its unguided matches with the features they were made of
        self._unguided: dict[tuple[int, str], tuple[StereoFeatures, NearestMatches]] | None = None

    @property
    def first_sources(self) -> tuple[str, ...]:
        """The sources needed before anything is known: all for ``fused``, greyscale for the others."""
        return self.sources if self.config.mode == "fused" else ("grey",)

    def submap(self, ref: int, window: Sequence[int], source: str) -> _Submap:
        """Landmarks of ``source`` of the keyframes in ``window``, in keyframe ``ref``'s frame (cached)."""
        key = (ref, tuple(window), source)
        sub = self._submaps.get(key)
        if sub is None:
            pts, descs = [], []
            for j in window:
                lm = self.map.keyframes[j].landmarks[source]
                T = self.map.T_a_b(ref, j)
                pts.append(lm.points @ T[:3, :3].T + T[:3, 3])
                descs.append(lm.descriptors)
            sub = _Submap(np.concatenate(pts), np.concatenate(descs))
            if len(self._submaps) >= 64:
                self._submaps.clear()
            self._submaps[key] = sub
        return sub

    def correspondences(
        self, features: StereoFeatures, source: str, camera: StereoCamera, ref: int, window: Sequence[int],
        T_ref_cam_prior: NDArray[np.float64] | None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float32], NDArray[np.float64], NDArray[np.float32]]:
        """Matches of one source between the window's landmarks (in ``ref``'s frame) and the current keypoints:
        keyframe points, current left pixels, current effective disparities and descriptor distances (at most one
        match per current keypoint and per window landmark)."""
        c = self.config
        sub = self.submap(ref, window, source)
        guided = T_ref_cam_prior is not None and c.match_radius_px > 0
        if not guided and self._unguided is not None and c.mutual:
            parts = [self._unguided_rows(j, source, features) for j in window]
            i_ref, i_cur = NearestMatches.mutual(parts)
            dist = np.concatenate([p.d1 for p in parts])[i_ref]
        else:
            i_ref, i_cur, dist = match_landmarks(
                sub.points, sub.descriptors, features.uv_left, features.descriptors, features.kind, K=camera.K,
                T_ref_cur=T_ref_cam_prior if guided else None, radius_px=c.match_radius_px if guided else 0.0,
                ratio=c.ratio, mutual=c.mutual, max_distance=self._max_d,
            )
        return sub.points[i_ref], features.uv_left[i_cur], camera.effective_disparity(features)[i_cur], dist

    def _unguided_rows(self, keyframe: int, source: str, features: StereoFeatures) -> NearestMatches:
        """The unguided matches of one keyframe's landmarks of ``source``, computed once per search frame."""
        assert self._unguided is not None
        cached = self._unguided.get((keyframe, source))
        if cached is None or cached[0] is not features:
            rows = NearestMatches.of(self.map.keyframes[keyframe].landmarks[source].descriptors, features.descriptors,
                                     features.kind, ratio=self.config.ratio, max_distance=self._max_d)
            cached = self._unguided[(keyframe, source)] = (features, rows)
        return cached[1]

    def localize_sources(
        self, features: Mapping[str, StereoFeatures], sources: Sequence[str], camera: StereoCamera, ref: int,
        window: Sequence[int], T_ref_cam_prior: NDArray[np.float64] | None, max_deviation_m: float = math.inf,
    ) -> Localization:
        """Match each of ``sources`` separately, fuse all matches into ONE RANSAC + ONE refinement; success with
        ``min_inliers`` inliers, a well-constrained position (``max_position_std_m``) and, with a prior, a position
        within ``max_deviation_m`` of the prior's."""
        c = self.config
        objs, imgs, disps, dists, labels, matches = [], [], [], [], [], {}
        for k, s in enumerate(sources):
            if s not in features:
                raise VtrInputError(f"features of source {s!r} are missing")
            if features[s].kind != self.map.feature:
                raise VtrInputError(f"{features[s].kind} features cannot match a map of {self.map.feature} features")
            obj, img, disp, dist = self.correspondences(features[s], s, camera, ref, window, T_ref_cam_prior)
            objs.append(obj)
            imgs.append(img)
            disps.append(disp)
            dists.append(dist)
            labels.append(np.full(len(obj), k, np.intp))
            matches[s] = len(obj)
        est = estimate_pose_stereo(
            np.concatenate(objs), np.concatenate(imgs), np.concatenate(disps), camera,
            threshold_px=c.ransac_threshold_px, iterations=c.ransac_iterations, confidence=c.ransac_confidence,
            min_inliers=c.min_inliers, consistent_fraction=c.ransac_consistent_fraction,
            quality=np.concatenate(dists),
            ordered_fraction=c.ransac_ordered_fraction if T_ref_cam_prior is None else 0.0,  # unguided only
        )
        lab = np.concatenate(labels)
        counts = np.bincount(lab[est.inliers], minlength=len(sources))
        inliers = {s: int(counts[k]) for k, s in enumerate(sources)}
        success = est.success and est.position_std_m <= c.max_position_std_m
        if est.success and not success:
            log.debug("localization at keyframe %d rejected: %d inliers but position std %.2f m", ref,
                      est.num_inliers, est.position_std_m)
        gated = False
        if success and T_ref_cam_prior is not None:
            deviation = float(np.linalg.norm(est.T_ref_cur[:3, 3] - T_ref_cam_prior[:3, 3]))
            if deviation > max_deviation_m:
                success, gated = False, True
                log.debug("localization at keyframe %d rejected: %d inliers but %.2f m from the VO prior (gate "
                          "%.2f m)", ref, est.num_inliers, deviation, max_deviation_m)
        return Localization(est.T_ref_cur if success or gated else np.eye(4), ref, success, inliers, matches,
                            est.rms_px, est.covariance if success or gated else np.full((6, 6), np.inf), gated)

    def localize(
        self, features: Mapping[str, StereoFeatures], camera: StereoCamera, ref: int, window: Sequence[int],
        T_ref_cam_prior: NDArray[np.float64] | None, more: FeatureSupplier | None = None,
        max_deviation_m: float = math.inf,
    ) -> Localization:
        """Localize by the configured mode (module docstring, step 4). ``more`` supplies the colour-constant
        sources on demand in ``mcmanus`` mode (default: they must be in ``features``)."""
        gate = max_deviation_m
        if self.config.mode != "mcmanus":
            return self._complete(self.localize_sources(features, self.sources, camera, ref, window,
                                                        T_ref_cam_prior, gate))
        grey = self.localize_sources(features, ("grey",), camera, ref, window, T_ref_cam_prior, gate)
        if grey.success or len(self.sources) == 1:
            return self._complete(grey)
        feats = dict(more()) if more is not None else dict(features)
        best: Localization | None = None
        gated = grey if grey.gated else None
        inliers, matches = dict(grey.inliers_per_source), dict(grey.matches_per_source)
        for s in self.sources[1:]:
            loc = self.localize_sources(feats, (s,), camera, ref, window, T_ref_cam_prior, gate)
            matches[s] = loc.matches_per_source[s]
            inliers[s] = loc.inliers_per_source[s]
            if loc.success and (best is None or loc.inliers > best.inliers):
                best = loc
            if loc.gated and gated is None:
                gated = loc
        if best is None:
            if gated is not None:  # the favoured source's pose beyond the gate (for a confirmation next frame)
                return self._complete(replace(gated, matches_per_source=matches))
            return self._complete(Localization(np.eye(4), ref, False, inliers, matches))
        return self._complete(replace(best, matches_per_source=matches))

    def _complete(self, loc: Localization) -> Localization:
        """Every mode source appears in the per-source counts (zeros for sources not used)."""
        ins = {s: int(loc.inliers_per_source.get(s, 0)) for s in self.sources}
        mat = {s: int(loc.matches_per_source.get(s, 0)) for s in self.sources}
        return replace(loc, inliers_per_source=ins, matches_per_source=mat)

    def search(self, features: Mapping[str, StereoFeatures], camera: StereoCamera,
               more: FeatureSupplier | None = None) -> Localization:
        """Whole-map search (§IV-C): every keyframe (with ``search_window_radius`` neighbours on each side),
        unguided; the most inliers win (first on ties)."""
        best: Localization | None = None
        r, n = self.config.search_window_radius, len(self.map)
        # every keyframe is in up to 2r + 1 windows: match its landmarks once (NearestMatches), combine per window
        self._unguided = {}
        try:
            for k in range(n):
                loc = self.localize(features, camera, k, tuple(range(max(0, k - r), min(n, k + r + 1))), None, more)
                if more is not None and self.config.mode == "mcmanus" and not loc.success:
                    features, more = more(), None  # computed once; later keyframes reuse them
                if best is None or (loc.success and (not best.success or loc.inliers > best.inliers)):
                    best = loc
        finally:
            self._unguided = None
        assert best is not None
        return best


class RepeatPipeline:
    """The repeat phase (module docstring): :meth:`step` per stereo frame against a loaded :class:`TeachMap`.

    The stereo and colour options default to those the map was taught with (its metadata), so the features match.
    Not thread-safe.
    """

    def __init__(
        self,
        teach_map: TeachMap,
        config: RepeatConfig | None = None,
        *,
        stereo: StereoConfig | None = None,
        color: ColorConstantConfig | None = None,
        vo: VisualOdometryConfig | None = None,
    ) -> None:
        self.map = teach_map
        self.config = config or RepeatConfig()
        if self.config.initial_keyframe >= len(teach_map):
            raise ConfigError(f"RepeatConfig.initial_keyframe {self.config.initial_keyframe} is outside the map "
                              f"({len(teach_map)} keyframes)")
        meta = teach_map.metadata
        if stereo is None:
            stereo = config_from_mapping(StereoConfig, meta.get("stereo", {}), allow_unknown=True)
        if color is None:
            color = config_from_mapping(ColorConstantConfig, meta.get("color", {}), allow_unknown=True)
        if stereo.feature != teach_map.feature:
            raise VtrInputError(f"the map holds {teach_map.feature} features; the front end extracts {stereo.feature}")
        self.localizer = MapLocalizer(teach_map, self.config)
        self.front = SourceFrontEnd(self.localizer.sources, stereo, color, self.config.workers)
        self.vo = VisualOdometry(vo)
        self.reset()

    def reset(self) -> None:
        """Start over (a new repeat): forget the pose, the VO chain and the failure state."""
        self.vo.reset()
        self._ref = -1
        self._T_ref_cam: NDArray[np.float64] | None = None
        self._distance_on_vo_m = 0.0
        self._lost = False
        self._gated: tuple[int, NDArray[np.float64]] | None = None  # last frame's localization beyond the gate
        self.frames = 0
        self.failures = 0  # number of localization failures declared (entries into the failure state)

    def close(self) -> None:
        self.front.close()

    @property
    def sources(self) -> tuple[str, ...]:
        return self.localizer.sources

    def step(self, stamp_ns: int, left_rgb: NDArray[np.generic], right_rgb: NDArray[np.generic],
             P_left: ArrayLike, P_right: ArrayLike) -> RepeatResult:
        """Process one rectified rgb8 stereo pair with its ``camera_info`` projection matrices.

        With front-end threads (``workers > 1``) the greyscale VO runs while the colour-constant features are
        still being detected; the result is the same as :meth:`step_features` on the finished features."""
        t0 = time.perf_counter()
        Pl, Pr = check_stereo_pair(P_left, P_right)
        features = self.front.submit(left_rgb, right_rgb, Pl, Pr, self.localizer.first_sources)
        grey = features["grey"]
        submit_s = time.perf_counter() - t0 - features.seconds

        def more() -> Mapping[str, StereoFeatures]:
            rest = tuple(s for s in self.localizer.sources if s not in features)
            if rest:
                t = time.perf_counter()
                features.update(self.front.submit(left_rgb, right_rgb, Pl, Pr, rest))
                features.seconds += time.perf_counter() - t
            return features

        camera = StereoCamera.from_projections(Pl, Pr)
        t = time.perf_counter()
        vo = self.vo.process(grey, camera)
        vo_s = time.perf_counter() - t
        front_before = features.seconds
        result = self._localize_step(stamp_ns, vo, features, camera, more)
        # the time spent finishing features during localization belongs to the front end
        timing = {"front_end": submit_s + features.seconds, "vo": vo_s,
                  **{k: v - (features.seconds - front_before if k == "localization" else 0.0)
                     for k, v in result.timing_s.items()}}
        return _with_timing(result, timing)

    def step_features(self, stamp_ns: int, features: Mapping[str, StereoFeatures], P_left: ArrayLike,
                      P_right: ArrayLike, *, more: FeatureSupplier | None = None) -> RepeatResult:
        """:meth:`step` with the front end's output computed elsewhere (at least the sources of
        :attr:`MapLocalizer.first_sources`; ``more`` supplies the others on demand)."""
        if "grey" not in features:
            raise VtrInputError("greyscale features are needed (VO runs on greyscale)")
        camera = StereoCamera.from_projections(P_left, P_right)
        t = time.perf_counter()
        vo = self.vo.process(features["grey"], camera)
        vo_s = time.perf_counter() - t
        result = self._localize_step(stamp_ns, vo, features, camera, more)
        return _with_timing(result, {"vo": vo_s, **result.timing_s})

    def _localize_step(self, stamp_ns: int, vo: VoResult, features: Mapping[str, StereoFeatures],
                       camera: StereoCamera, more: FeatureSupplier | None) -> RepeatResult:
        """Steps 3–5 of the module docstring after the VO step ``vo``."""
        c = self.config
        self.frames += 1
        timing: dict[str, float] = {}
        motion = vo.T_prev_cur
        step_m = 0.0 if vo.first else float(np.linalg.norm(motion[:3, 3]))

        ref, prior = -1, None
        if self._T_ref_cam is not None:
            ref, prior = self._reanchor(self._ref, self._T_ref_cam @ motion)

        loc: Localization | None = None
        localized = relocalized = searched = failure = False
        # never localized: try the start window (if given) until the failure distance, then the whole map
        start_hint = prior is None and c.initial_keyframe >= 0 and (
            self._distance_on_vo_m + step_m <= c.max_distance_on_vo_m)
        t = time.perf_counter()
        if prior is not None and not self._lost:
            gate = math.inf
            if c.prior_gate_m > 0:
                gate = c.prior_gate_m + c.prior_gate_per_m * (self._distance_on_vo_m + step_m)
            loc = self.localizer.localize(features, camera, ref, self.map.window(ref, c.window_radius), prior, more,
                                          gate)
            localized = loc.success or self._confirmed(loc, motion)
        elif start_hint:
            k0 = c.initial_keyframe
            loc = self.localizer.localize(features, camera, k0, self.map.window(k0, c.window_radius), None, more)
            localized = loc.success
        timing["localization"] = time.perf_counter() - t

        if not localized:
            self._distance_on_vo_m += step_m
            exceeded = self._distance_on_vo_m > c.max_distance_on_vo_m
            if prior is None or self._lost or exceeded:
                if prior is not None and not self._lost:
                    self.failures += 1
                    log.warning("localization failure: %.1f m on VO alone (limit %.1f m); searching the whole map",
                                self._distance_on_vo_m, c.max_distance_on_vo_m)
                self._lost = self._lost or prior is not None
                failure = True
                if not start_hint:
                    t = time.perf_counter()
                    loc = self.localizer.search(features, camera, more)
                    timing["search"] = time.perf_counter() - t
                    searched = True
                    if loc.success:
                        localized = relocalized = True
                        self._lost = False
                        log.info("relocalized at keyframe %d with %d inliers", loc.ref_index, loc.inliers)

        self._gated = None
        if loc is not None and not localized and self._strong_beyond_gate(loc):
            self._gated = (loc.ref_index, loc.T_ref_cam)
        if localized:
            assert loc is not None
            self._distance_on_vo_m = 0.0
            self._ref, self._T_ref_cam = self._reanchor(loc.ref_index, loc.T_ref_cam)
        elif prior is not None:
            self._ref, self._T_ref_cam = ref, prior

        along = float("nan")
        if self._T_ref_cam is not None:
            along = self._along(self._ref, self._T_ref_cam)
        empty = {s: 0 for s in self.localizer.sources}
        return RepeatResult(
            stamp_ns=int(stamp_ns),
            T_kf_cam=None if self._T_ref_cam is None else self._T_ref_cam.copy(),
            keyframe_index=self._ref,
            localized=localized,
            inliers_per_source=dict(loc.inliers_per_source) if loc is not None else empty,
            distance_on_vo_m=self._distance_on_vo_m,
            failure=failure,
            relocalized=relocalized,
            matches_per_source=dict(loc.matches_per_source) if loc is not None else empty,
            searched_map=searched,
            vo_success=vo.success,
            vo_inliers=vo.num_inliers,
            T_prev_cur=motion.copy(),
            distance_along_path_m=along,
            covariance=loc.covariance.copy() if (localized and loc is not None) else None,
            timing_s=timing,
        )

    def _strong_beyond_gate(self, loc: Localization) -> bool:
        """Rejected by the prior gate only, with ``confirm_beyond_gate_inliers`` (> 0) inliers."""
        return loc.gated and loc.inliers >= self.config.confirm_beyond_gate_inliers > 0

    def _confirmed(self, loc: Localization, motion: NDArray[np.float64]) -> bool:
        """Whether a strong localization beyond the prior gate agrees with the previous frame's, also one, moved by
        the VO ``motion`` between them."""
        if self._gated is None or not self._strong_beyond_gate(loc):
            return False
        ref, T_ref_cam = self._gated
        expected = self.map.T_a_b(loc.ref_index, ref) @ T_ref_cam @ motion
        agree = float(np.linalg.norm(loc.T_ref_cam[:3, 3] - expected[:3, 3])) <= self.config.prior_gate_m
        if agree:
            log.info("localization at keyframe %d beyond the prior gate confirmed by the previous frame's: the VO "
                     "prior was off", loc.ref_index)
        return agree

    def _along(self, ref: int, T_ref_cam: NDArray[np.float64]) -> float:
        """Distance along the taught path of a pose given in keyframe ``ref``'s frame (m)."""
        return float(self.map.distance_m[ref] + T_ref_cam[:3, 3] @ self.map.path_direction(ref))

    def _reanchor(self, ref: int, T_ref_cam: NDArray[np.float64]) -> tuple[int, NDArray[np.float64]]:
        """The keyframe nearest along the path to a pose and the pose in that keyframe's frame."""
        k = self.map.nearest(self._along(ref, T_ref_cam))
        if k == ref:
            return ref, T_ref_cam
        return k, self.map.T_a_b(k, ref) @ T_ref_cam


def _with_timing(result: RepeatResult, timing: Mapping[str, float]) -> RepeatResult:
    return replace(result, timing_s=dict(timing))
