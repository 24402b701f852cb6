"""Repeat phase of colour-constant stereo VT&R: paper §IV-B (Fig. 3–4) and §IV-C (localization failure).

Per rectified stereo pair (:meth:`RepeatPipeline.step`: rgb8 images and projection matrices in, :class:`RepeatResult`
out):
1. **Front end** (:class:`~lightfast.vtr.teach.SourceFrontEnd`): landmarks of the image sources the mode needs.
2. **VO on greyscale** (§IV-B 2: "VO is performed using only the greyscale images"): ``T_prev_cur`` of
   :class:`~lightfast.vtr.visual_odometry.VisualOdometry` moves the last pose to the prior ``T_kf_cam`` ("The VO
   estimate is fed to the localizer as a prior, and is used as the final pose estimate if localization fails"; if
   the VO fails, the prior moves along the taught path at the last localized frames' speed).
3. **Expected nearest keyframe** by the prior's distance along the taught path
   (:meth:`~lightfast.vtr.map_store.TeachMap.nearest`); the prior is re-expressed in that keyframe's frame.
4. **Localization against a window of keyframes** around it (``window_radius`` on each side) by
   :class:`~lightfast.vtr.localization.MapLocalizer` (modes ``fused``, ``grey``, ``mcmanus``), within the prior gate
   ``prior_gate_m + prior_gate_per_m · (distance on VO)`` of the VO prior or within standard deviations of both
   (:class:`~lightfast.vtr.vo_prior.PriorGate`); fused with the prior (``vo_prior``) — unless it and the previous
   frame's lie beyond the radius (refused, or admitted by the widening: ``confirm_admitted``), both with
   ``confirm_beyond_gate_inliers`` inliers, agreeing after the VO motion: then the prior is wrong and is replaced.
5. **Failure handling** (§IV-C): without success the VO prior is the pose and the distance driven on VO alone
   accumulates; beyond ``max_distance_on_vo_m`` (20 m) it is a **localization failure**: the robot "stops" and the
   whole map is searched (:mod:`lightfast.vtr.map_search`) every frame until a place has the evidence that rules
   out look-alikes (``search_min_inliers``, ``search_margin``; below ``search_accept_inliers`` found again within
   ``search_hold_frames`` by a search or a windowed localization from it, ``search_track_held``; ``relocalized``; the
   gate widens by ``search_gate_sigmas`` until ``search_confirm_inliers`` confirm it). Likewise before the first
   localization (``initial_keyframe``: its window first, until the failure distance).

Output per frame: :class:`RepeatResult` — ``T_kf_cam`` (the camera in keyframe ``keyframe_index``'s frame, the one
nearest along the path; metres, REP-103 optical axes), whether it localized, inliers per source, the distance on VO
since the last localization (m), the failure flag (every frame from a failure to the relocalization, and before the
first localization: the robot would not drive) and the search's success.
"""
from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.config import ConfigError, config_from_mapping
from lightfast.vtr.color_constant import ColorConstantConfig
from lightfast.vtr.errors import VtrInputError
from lightfast.vtr.features import StereoFeatures
from lightfast.vtr.localization import FeatureSupplier, Localization, MapLocalizer
from lightfast.vtr.map_store import TeachMap
from lightfast.vtr.pose_estimation import StereoCamera
from lightfast.vtr.repeat_config import RepeatConfig
from lightfast.vtr.stereo_config import StereoConfig
from lightfast.vtr.stereo_front_end import check_stereo_pair
from lightfast.vtr.teach import SourceFrontEnd
from lightfast.vtr.visual_odometry import VisualOdometry, VisualOdometryConfig, VoResult
from lightfast.vtr.vo_prior import PriorGate, add_keyframe_noise, fuse, propagate_covariance

__all__ = ["RepeatPipeline", "RepeatResult"]

log = logging.getLogger(__name__)

#: the localized frames (of the last ``2 * _SPEED_FRAMES``) whose positions along the taught path give the speed of
#: ``follow_path_on_vo_failure``
_SPEED_FRAMES = 5


@dataclass(frozen=True)
class RepeatResult:
    """One repeat step (module docstring). ``T_kf_cam`` is ``None`` (and ``keyframe_index`` −1) until the first
    localization; ``T_prev_cur`` is the motion used (m; the VO's, or along the path after a VO failure);
    ``distance_along_path_m`` the position along the taught path; ``covariance`` that of the pose on localized frames
    (6×6, ξ = (ρ, φ) in ``T_kf_cam · exp(ξ)``, camera frame: the localization's nominal one ×
    ``localization_cov_scale²``, fused with the VO prior's), else ``None``; ``timing_s`` the time per stage (s)."""

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
        self._cov: NDArray[np.float64] | None = None  # of _T_ref_cam (vo_prior's convention); None: unknown
        self._distance_on_vo_m = 0.0
        self._lost = False
        self._provisional = False  # the pose rests on a search place not yet confirmed (search_gate_sigmas)
        self._gated: tuple[int, NDArray[np.float64]] | None = None  # last frame's localization beyond the gate
        # weak places of the whole-map search: (frame number, keyframe, T_ref_cam moved to the last frame)
        self._held: list[tuple[int, int, NDArray[np.float64]]] = []
        # localized frames: (frame number, stamp_ns, m along the path); the stamp of the frame before this one
        self._alongs: deque[tuple[int, int, float]] = deque(maxlen=_SPEED_FRAMES)
        self._last_stamp_ns: int | None = None
        self.frames = 0
        self.failures = 0  # number of localization failures declared (entries into the failure state)
        self.refused_places = 0  # places of the whole-map search refused as ambiguous
        self.held_places = 0  # weak places of the whole-map search held for the next frame's confirmation

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
        if not (vo.success or vo.first) and c.follow_path_on_vo_failure:
            motion = self._path_motion(motion, stamp_ns)
        step_m = 0.0 if vo.first else float(np.linalg.norm(motion[:3, 3]))
        # the weak places of the last search_hold_frames frames' searches, moved by the motion to this frame
        self._held = [(f, ref, T @ motion) for f, ref, T in self._held if self.frames - f <= c.search_hold_frames]

        ref, prior, prior_cov = -1, None, None
        if self._T_ref_cam is not None:
            ref, prior = self._reanchor(self._ref, self._T_ref_cam @ motion)
            if self._cov is not None:
                step_cov = c.vo_cov_scale**2 * vo.covariance if (c.vo_cov_scale > 0 and vo.success) else None
                prior_cov = propagate_covariance(self._cov, motion, step_m, c.vo_position_noise_per_m,
                                                 c.vo_rotation_noise_deg_per_m, step_cov)
                if ref != self._ref:
                    prior_cov = add_keyframe_noise(prior_cov, c.keyframe_position_noise_m,
                                                   c.keyframe_rotation_noise_deg)

        loc: Localization | None = None
        localized = relocalized = searched = failure = beyond = confirmed = False
        beyond_place: tuple[int, NDArray[np.float64]] | None = None
        # never localized: try the start window (if given) until the failure distance, then the whole map
        start_hint = prior is None and c.initial_keyframe >= 0 and (
            self._distance_on_vo_m + step_m <= c.max_distance_on_vo_m)
        t = time.perf_counter()
        if prior is not None and not self._lost:
            gate = self._prior_gate(prior, prior_cov, step_m)
            loc = self.localizer.localize(features, camera, ref, self.map.window(ref, c.window_radius), prior, more,
                                          gate)
            T_prior = self.map.T_a_b(loc.ref_index, ref) @ prior if loc.ref_index != ref else prior
            beyond = self._strong_beyond_gate(loc, T_prior, gate)
            if beyond:
                beyond_place = (loc.ref_index, loc.T_ref_cam)  # before any fusion
            confirmed = beyond and self._confirmed(loc, motion)
            localized = loc.success or confirmed
            loc = self._scaled(loc)
            if loc.success and not confirmed and c.fuse_vo_prior and prior_cov is not None:
                T_fused, cov = fuse(loc.T_ref_cam, loc.covariance, T_prior, prior_cov)
                loc = replace(loc, T_ref_cam=T_fused, covariance=cov)
        elif start_hint:
            k0 = c.initial_keyframe
            loc = self._scaled(self.localizer.localize(features, camera, k0, self.map.window(k0, c.window_radius),
                                                       None, more))
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
                tracked = None if start_hint else self._held_tracked(features, camera, more)
                if tracked is not None:
                    loc, localized = tracked, True
                    log.info("relocalized at keyframe %d: a held place of the search tracked with %d inliers",
                             loc.ref_index, loc.inliers)
                elif not start_hint:
                    t = time.perf_counter()
                    loc = self._scaled(self.localizer.search(features, camera, more))
                    timing["search"] = time.perf_counter() - t
                    searched = True
                    if loc.success and self._unambiguous(loc) and self._found_again(loc):
                        localized = True
                        log.info("relocalized at keyframe %d with %d inliers (next distinct place %d)",
                                 loc.ref_index, loc.inliers, loc.runner_up_inliers)
                    elif loc.success and self._unambiguous(loc):
                        self._held.append((self.frames, loc.ref_index, loc.T_ref_cam))
                        self.held_places += 1
                        log.info("whole-map search: keyframe %d with %d inliers held until a search of the next %d "
                                 "frames finds it again (accepted at once from %d)", loc.ref_index, loc.inliers,
                                 c.search_hold_frames, c.search_accept_inliers)
                    elif loc.success:
                        self.refused_places += 1
                        log.info("whole-map search: keyframe %d with %d inliers refused (a distinct place has %d; "
                                 "needs %d and %.3g times as many)", loc.ref_index, loc.inliers,
                                 loc.runner_up_inliers, c.search_min_inliers, c.search_margin)
                if localized:
                    relocalized, self._lost = True, False
                    self._held.clear()

        self._gated = beyond_place if (beyond and not confirmed and not searched) else None
        if localized:
            assert loc is not None
            self._provisional = relocalized or (self._provisional and loc.inliers < c.search_confirm_inliers)
            self._distance_on_vo_m = 0.0
            self._ref, self._T_ref_cam = self._reanchor(loc.ref_index, loc.T_ref_cam)
            self._cov = loc.covariance if np.all(np.isfinite(loc.covariance)) else None
            if self._cov is not None and self._ref != loc.ref_index:
                self._cov = add_keyframe_noise(self._cov, c.keyframe_position_noise_m, c.keyframe_rotation_noise_deg)
        elif prior is not None:
            self._ref, self._T_ref_cam, self._cov = ref, prior, prior_cov

        along = float("nan")
        if relocalized:
            self._alongs.clear()
        if self._T_ref_cam is not None:
            along = self.map.along_path_m(self._ref, self._T_ref_cam)
            if localized:
                self._alongs.append((self.frames, int(stamp_ns), along))
        self._last_stamp_ns = int(stamp_ns)
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

    def _scaled(self, loc: Localization) -> Localization:
        """``loc`` with its covariance scaled by ``localization_cov_scale²`` (:mod:`lightfast.vtr.vo_prior`)."""
        return replace(loc, covariance=self.config.localization_cov_scale ** 2 * loc.covariance)

    def _unambiguous(self, loc: Localization) -> bool:
        """A place of the whole-map search with the evidence that rules out look-alikes: ``search_min_inliers``
        and ``search_margin`` times the inliers of the best distinct place."""
        c = self.config
        return loc.inliers >= c.search_min_inliers and loc.inliers >= c.search_margin * loc.runner_up_inliers

    def _found_again(self, loc: Localization) -> bool:
        """Whether an unambiguous place of the search is accepted: at once with ``search_accept_inliers``, else when
        the search of one of the last ``search_hold_frames`` frames held a place that, moved by the motion since,
        lies within ``search_agree_m``."""
        c = self.config
        if loc.inliers >= c.search_accept_inliers:
            return True
        return any(self._offset_m(loc, (ref, T)) <= c.search_agree_m for _, ref, T in self._held)

    def _held_tracked(self, features: Mapping[str, StereoFeatures], camera: StereoCamera,
                      more: FeatureSupplier | None) -> Localization | None:
        """A held place found again by a windowed localization from it (``search_track_held``): guided matching from
        the place moved by the motion since, with ``search_min_inliers`` inliers within ``prior_gate_m`` of it (the
        newest held place first); None if none is."""
        c = self.config
        if not c.search_track_held:
            return None
        for _, ref, T_ref_cam in reversed(self._held):
            loc = self.localizer.localize(features, camera, ref, self.map.window(ref, c.window_radius), T_ref_cam,
                                          more, PriorGate(c.prior_gate_m))
            if loc.success and loc.inliers >= c.search_min_inliers:
                return self._scaled(loc)
        return None

    def _offset_m(self, loc: Localization, place: tuple[int, NDArray[np.float64]]) -> float:
        """Distance (m) between ``loc``'s camera and ``place`` = ``(keyframe, T_ref_cam)`` (an earlier frame's, moved to
        this frame)."""
        ref, T_ref_cam = place
        expected = self.map.T_a_b(loc.ref_index, ref) @ T_ref_cam
        return float(np.linalg.norm(loc.T_ref_cam[:3, 3] - expected[:3, 3]))

    def _prior_gate(self, prior: NDArray[np.float64], prior_cov: NDArray[np.float64] | None,
                    step_m: float) -> PriorGate | None:
        """The gate of this frame's windowed localization: ``prior_gate_m`` grown with the distance on VO, widened by
        the prior's position covariance (``prior_gate_sigmas`` with ``confirm_beyond_gate_inliers`` inliers; after a
        place of the search ``search_gate_sigmas`` with ``search_min_inliers``); None without a gate."""
        c = self.config
        if c.prior_gate_m <= 0:
            return None
        sigmas, min_inliers = c.prior_gate_sigmas, c.confirm_beyond_gate_inliers
        if self._provisional and c.search_gate_sigmas > 0:
            sigmas, min_inliers = max(sigmas, c.search_gate_sigmas), c.search_min_inliers
        position_cov = None  # only the Mahalanobis widening reads it
        if prior_cov is not None and sigmas > 0:
            R = prior[:3, :3]
            position_cov = R @ prior_cov[:3, :3] @ R.T
        return PriorGate(c.prior_gate_m + c.prior_gate_per_m * (self._distance_on_vo_m + step_m), position_cov,
                         sigmas, min_inliers, c.localization_cov_scale if c.prior_gate_innovation else 0.0)

    def _strong_beyond_gate(self, loc: Localization, T_prior: NDArray[np.float64], gate: PriorGate | None) -> bool:
        """A localization with ``confirm_beyond_gate_inliers`` (> 0) inliers rejected by the prior gate only, or
        (``confirm_admitted``) admitted by its Mahalanobis widening beyond its radius from the prior ``T_prior``."""
        c = self.config
        if not loc.inliers >= c.confirm_beyond_gate_inliers > 0:
            return False
        if loc.gated:
            return True
        return (c.confirm_admitted and loc.success and gate is not None
                and float(np.linalg.norm(loc.T_ref_cam[:3, 3] - T_prior[:3, 3])) > gate.radius_m)

    def _confirmed(self, loc: Localization, motion: NDArray[np.float64]) -> bool:
        """Whether a strong localization beyond the prior gate agrees with the previous frame's, also one, moved by
        the VO ``motion`` between them: then it replaces the prior (the prior is the wrong one)."""
        if self._gated is None:
            return False
        ref, T_ref_cam = self._gated
        agree = self._offset_m(loc, (ref, T_ref_cam @ motion)) <= self.config.prior_gate_m
        if agree:
            log.info("localization at keyframe %d beyond the prior gate confirmed by the previous frame's: the VO "
                     "prior was off", loc.ref_index)
        return agree

    def _path_motion(self, fallback: NDArray[np.float64], stamp_ns: int) -> NDArray[np.float64]:
        """The motion ``T_prev_cur`` of a camera moving along the taught path's local direction at the speed of the
        last localized frames (``follow_path_on_vo_failure``: the slope of their positions along the path over their
        stamps) since the previous frame; ``fallback`` without a pose, without two localized frames among the last
        ``2 * _SPEED_FRAMES`` or with stamps that do not increase."""
        recent = [(t, a) for i, t, a in self._alongs if self.frames - i <= 2 * _SPEED_FRAMES]
        if (self._T_ref_cam is None or self._last_stamp_ns is None or len(recent) < 2
                or not recent[0][0] < recent[-1][0] <= self._last_stamp_ns < stamp_ns):
            return fallback
        distance_m = (recent[-1][1] - recent[0][1]) / (recent[-1][0] - recent[0][0]) * (stamp_ns - self._last_stamp_ns)
        T = np.eye(4)
        T[:3, 3] = self._T_ref_cam[:3, :3].T @ self.map.path_direction(self._ref) * distance_m
        return T

    def _reanchor(self, ref: int, T_ref_cam: NDArray[np.float64]) -> tuple[int, NDArray[np.float64]]:
        """The keyframe nearest along the path to a pose and the pose in that keyframe's frame."""
        k = self.map.nearest(self.map.along_path_m(ref, T_ref_cam))
        if k == ref:
            return ref, T_ref_cam
        return k, self.map.T_a_b(k, ref) @ T_ref_cam


def _with_timing(result: RepeatResult, timing: Mapping[str, float]) -> RepeatResult:
    return replace(result, timing_s=dict(timing))
