"""The two-step camera tracking of paper §III-D: frame-to-frame, then frame-to-model against the relit reference.

:class:`RGBDTracker` is the pipeline ``rgbd_tracker_node`` runs. Per live frame:

1. :meth:`~RGBDTracker.track_coarse` — f2f: Eq. 7 against the previous frame gives the relative motion and the
   coarse pose ``T≈ = T_map_prev · T_prev_cur`` (published for the relight step, which renders the reference
   there);
2. :meth:`~RGBDTracker.refine` — f2m: Eq. 7 of the live frame against the reference colour + depth rendered at
   ``T≈``, started at identity, gives ``T_ref_cur`` and the final pose ``T = T≈ · T_ref_cur``;
   or :meth:`~RGBDTracker.skip_reference` when no reference comes (the f2f pose is final).

The paper does not say where the f2f minimisation starts; here it starts at the previous frame's relative motion
scaled to this frame's interval (a constant-velocity prior, ``motion_prior``; frames a busy node dropped lengthen
the interval), which widens the basin of convergence for fast hand-held rotations (measured on DS1.T1: identity
fails from ~4.5°/frame, the prior tracks 8°/frame), or at identity.

The steps may interleave: frame k+1 can be coarse-tracked before frame k's reference arrives (a pipelined node).
Each pending frame remembers its predecessor and relative motion, so when frame k is refined, the best-known poses
of the frames after it are re-chained from the refined pose.

Not in the paper: an f2m correction of T≈ beyond ``max_f2m_correction_m`` / ``_deg`` is rejected. Once
``f2m_confirm_frames`` such corrections in a row agree in the map frame (after f2f has gone off, every later T≈ is
off by the same transform, which f2m against the map undoes each time), the next T≈ is moved by it (a probe: the
reference is rendered there), and the track moves there if f2m against that reference needs no large correction.

Modes (the ablation of §IV-C): ``proposed`` and ``refl-f2m`` use E_C + w_G E_G in both steps (they differ in the
reference the relight step renders), ``depth-only`` uses E_G alone in both, ``no-color-f2m`` E_C + E_G in f2f and
E_G alone in f2m.
"""
from __future__ import annotations

import dataclasses
import functools
import logging
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.config import ConfigError, param
from lightfast.geometry import inverse, make_transform, quat_to_matrix, rotation_angle_deg
from lightfast.node_options import CameraInputOptions, SensorInputOptions, StampOptions
from lightfast.tracking.errors import TrackingError, TrackingInputError
from lightfast.tracking.rgbd_odometry import (
    MOTION_PRIOR_MAX_GAP_S,
    MOTION_PRIORS,
    AlignResult,
    MotionPrior,
    RGBDFrame,
    TrackingConfig,
    align_frames,
    prepare_frame,
    repeated_input,
)

__all__ = ["CoarseEstimate", "F2FJob", "F2MJob", "RGBDTracker", "TrackResult", "TrackerConfig", "f2m_rejection"]

log = logging.getLogger(__name__)


def f2m_rejection(result: AlignResult, config: TrackerConfig) -> str:
    """Why an f2m result is not used (the frame keeps its f2f pose), or "" when it is: it did not converge, or its
    correction of T≈ exceeds ``max_f2m_correction_m`` / ``max_f2m_correction_deg``."""
    if not result.converged:
        return "f2m did not converge"
    dt = float(np.linalg.norm(result.T_target_source[:3, 3]))
    dr = float(rotation_angle_deg(result.T_target_source[:3, :3]))
    if dt > config.max_f2m_correction_m or dr > config.max_f2m_correction_deg:
        return f"f2m correction too large ({dt:.3f} m, {dr:.1f} deg)"
    return ""


def _within(T: NDArray[np.float64], max_m: float, max_deg: float) -> bool:
    return float(np.linalg.norm(T[:3, 3])) <= max_m and float(rotation_angle_deg(T[:3, :3])) <= max_deg


@dataclass(frozen=True)
class TrackerConfig(TrackingConfig, SensorInputOptions, CameraInputOptions, StampOptions):
    """Options of the two-step tracker (``rgbd_tracker_node``): the Eq. 7 options plus the f2m acceptance, and the
    node's frames, sensor QoS and stamp checks."""

    map_frame: str = param("map", description="Frame of the published poses (REP 105's map); /tracker/reset and "
                           "/initialpose must be in it.", read_only=True)
    camera_frame: str = param("", description="Child frame of the pose on /tf and /tracker/odometry; empty: the "
                              "colour image's frame_id (camera_color_optical_frame if that is empty). On a robot "
                              "whose TF tree has the camera frame already, name another frame here (a frame has "
                              "one parent).", read_only=True)
    publish_tf: bool = param(True, description="Broadcast each pose on /tf as map_frame -> camera_frame.",
                             read_only=True)
    pair_slop_s: float = param(
        0.0, min=0.0, max=0.05, read_only=True,
        description="Colour and depth images are paired by stamp: exactly (0), or the closest within this many "
        "seconds, for drivers that stamp the two streams apart (keep it below half the frame period). A frame takes "
        "its colour image's stamp.",
    )

    initial_pose: tuple[float, ...] = param(
        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
        description="Start pose T_map_cam as x y z (m) qx qy qz qw, also after time jumped back (a bag played "
        "again); /initialpose and /tracker/reset override it.",
    )
    reference_timeout_s: float = param(0.5, description="A frame whose reference has not arrived after this "
                                       "long (wall time) is finished with its f2f pose.", min=0.0, max=60.0)
    f2f_finest_level: int = param(
        1, description="Pyramid level where frame-to-frame tracking stops (1: half resolution); T≈ only seeds the "
        "frame-to-model step, which runs down to finest_level (to level 1 against a half-resolution reference).",
        min=0, max=5
    )
    f2m_iterations: tuple[int, ...] = param(
        (10, 10, 5), description="Gauss-Newton iterations per level of the f2m step, coarse to fine (it starts at "
        "T≈, close to the solution). Against a half-resolution reference (daylight_relight_node's reference_scale "
        "0.5) the alignment stops at level 1, the reference's resolution, and the last entry is not used.",
        min=1, max=200
    )
    pose_prior_weight: float = param(
        0.3, description="f2f: weight per associated pixel of a prior at the constant-velocity prediction (per m^2 and "
        "rad^2, Eq. 7 cost units; 0 = off). Views of a plain wall leave directions Eq. 7 does not constrain; without "
        "the prior f2f drifts there by cm per frame.", min=0.0,
    )
    f2m_pose_prior_weight: float = param(
        0.0, description="pose_prior_weight of the f2m step (its prior is at T≈; 0 = off: f2m corrects T≈ freely).",
        min=0.0,
    )
    motion_prior: str = param("constant-velocity", description="Start of the f2f alignment: the previous frame's "
                              "relative motion scaled to the time since the previous frame (constant-velocity: a "
                              "frame after dropped frames is predicted over its whole interval), that motion as it "
                              "is whatever the interval (last-motion, as DVO and ORB-SLAM predict), or identity "
                              "(none).", choices=MOTION_PRIORS)
    motion_prior_max_gap_s: float = param(MOTION_PRIOR_MAX_GAP_S, description="A frame further than this from the "
                                          "previous one (s) starts f2f at identity: no constant-velocity "
                                          "prediction across a long gap.", min=0.0)
    max_pending: int = param(8, description="Frames kept waiting for their reference; older ones are finished "
                             "with the f2f pose (8: 0.27 s at 30 Hz, the reference's round trip through "
                             "daylight_relight_node with some slack).", min=1, max=100)
    max_f2m_correction_m: float = param(0.10, description="An f2m correction of T≈ larger than this is rejected "
                                        "(the f2f pose is kept) unless f2m_confirm_frames agree on it, metres.",
                                        min=0.0)
    max_f2m_correction_deg: float = param(10.0, description="An f2m rotation correction larger than this is "
                                          "rejected, degrees.", min=0.0)
    f2m_confirm_frames: int = param(2, description="A converged f2m correction larger than max_f2m_correction_m "
                                    "or _deg is rejected; once this many in a row agree (within "
                                    "f2m_confirm_tolerance_m / _deg), the next frame's reference is rendered at the "
                                    "pose they give, and if f2m against it needs no large correction the tracker "
                                    "takes that pose: after f2f has drifted away, or from a wrong start pose, the map "
                                    "is found again. 0 = a large correction is always rejected.", min=0, max=100)
    f2m_confirm_tolerance_m: float = param(0.02, description="Consecutive large f2m corrections agree when their "
                                           "map-frame corrections differ by less than this, metres.", min=0.0)
    f2m_confirm_tolerance_deg: float = param(2.0, description="Consecutive large f2m corrections agree when their "
                                             "map-frame corrections differ by less than this rotation, degrees.",
                                             min=0.0)

    def check(self) -> None:
        super().check()
        if len(self.f2m_iterations) != self.pyramid_levels:
            raise ConfigError(f"f2m_iterations has {len(self.f2m_iterations)} entries, expected pyramid_levels="
                              f"{self.pyramid_levels}")
        if self.f2f_finest_level >= self.pyramid_levels:
            raise ConfigError(f"f2f_finest_level={self.f2f_finest_level} must be below pyramid_levels="
                              f"{self.pyramid_levels}")
        if len(self.initial_pose) != 7:
            raise ConfigError(f"initial_pose needs 7 numbers (x y z qx qy qz qw), got {len(self.initial_pose)}")
        if abs(float(np.linalg.norm(self.initial_pose[3:])) - 1.0) > 1e-3:
            raise ConfigError(f"initial_pose quaternion must be unit length, got {self.initial_pose[3:]}")

    @property
    def T_map_cam_initial(self) -> NDArray[np.float64]:
        return make_transform(quat_to_matrix(self.initial_pose[3:]), self.initial_pose[:3])

    @functools.cached_property
    def f2f_config(self) -> TrackerConfig:
        """The options of the f2f alignment (it stops at ``f2f_finest_level``); built once, not per frame."""
        return dataclasses.replace(self, finest_level=max(self.finest_level, self.f2f_finest_level))

    @functools.cached_property
    def f2m_config(self) -> TrackerConfig:
        """The options of the f2m alignment (its own iterations and pose prior)."""
        return dataclasses.replace(self, iterations=self.f2m_iterations, pose_prior_weight=self.f2m_pose_prior_weight)

    @property
    def f2f_color(self) -> bool:
        return self.mode != "depth-only"

    @property
    def f2m_color(self) -> bool:
        return self.mode in ("proposed", "refl-f2m")


@dataclass(frozen=True, eq=False)
class CoarseEstimate:
    """Result of f2f tracking for one frame: ``T_map_cam`` is T≈ (where the reference is to be rendered);
    ``repeated``: which image repeats the previous frame's (:func:`~lightfast.tracking.repeated_input`)."""

    stamp_ns: int
    T_map_cam: NDArray[np.float64]
    f2f: AlignResult | None  # None for the first frame after a reset and a frame whose depth repeats
    seconds: float
    repeated: str = ""


@dataclass(frozen=True, eq=False)
class TrackResult:
    """The final pose of one frame. ``source``: ``"f2m"`` (refined against the reference), ``"f2f"`` (no reference,
    or the f2m result was rejected — see ``reason``) or ``"reset"``."""

    stamp_ns: int
    T_map_cam: NDArray[np.float64]
    source: str
    reason: str
    f2f: AlignResult | None
    f2m: AlignResult | None
    seconds: dict[str, float] = field(default_factory=dict)


@dataclass
class _Pending:
    frame: RGBDFrame
    T_coarse: NDArray[np.float64]  # T≈ as published (the reference is rendered there; a probe's pose, see _probe)
    T_best: NDArray[np.float64]  # best-known pose, re-chained when a predecessor is refined
    prev_stamp: int | None
    T_prev_cur: NDArray[np.float64]
    f2f: AlignResult | None
    f2f_seconds: float
    probe: bool = False  # T_coarse is T_best moved by the tracker's probe


@dataclass(eq=False)
class F2FJob:
    """The f2f alignment of a new live frame (:meth:`RGBDTracker.start_coarse`): prepare the frame and align it to
    the previous one from the constant-velocity prediction. :meth:`run` reads only the job's own inputs; its outcome
    is ``frame``, ``repeated`` and ``result`` (None for the first frame after a reset and for a frame whose depth
    image repeats the previous one's: not aligned; E_G alone when only the colour repeats) or ``error``."""

    stamp_ns: int
    rgb: ArrayLike
    depth_m: ArrayLike
    camera: PinholeCamera
    config: TrackerConfig
    previous: tuple[int, RGBDFrame] | None  # stamp and frame of the previous frame; None: the first after a reset
    T_prev_cur_init: NDArray[np.float64] | None
    frame: RGBDFrame | None = None
    result: AlignResult | None = None
    repeated: str = ""
    error: TrackingError | None = None
    seconds: float = 0.0

    def run(self) -> F2FJob:
        t0 = time.perf_counter()
        cfg = self.config
        try:
            self.frame = prepare_frame(self.rgb, self.depth_m, self.camera, config=cfg, name=f"frame {self.stamp_ns}")
            if self.previous is not None:
                self.repeated = repeated_input(self.frame, self.previous[1])
                if self.repeated != "depth":
                    self.result = align_frames(
                        self.frame, self.previous[1], init_T_target_source=self.T_prev_cur_init,
                        config=cfg.f2f_config, use_color=cfg.f2f_color and self.repeated != "colour", use_depth=True)
        except TrackingError as exc:
            self.error = exc
        self.seconds = time.perf_counter() - t0
        return self


@dataclass(eq=False)
class F2MJob:
    """The f2m alignment of one pending frame against its reference (:meth:`RGBDTracker.start_refine`): prepare the
    reference and align the frame to it. :meth:`run` reads only the job's own inputs, so it may run on another
    thread; its outcome is in ``result`` (None: the reference has no valid depth) or ``error``."""

    stamp_ns: int
    source: RGBDFrame
    ref_rgb: ArrayLike
    ref_depth_m: ArrayLike
    ref_camera: PinholeCamera
    config: TrackerConfig
    result: AlignResult | None = None
    error: TrackingError | None = None
    seconds: float = 0.0

    def run(self) -> F2MJob:
        t0 = time.perf_counter()
        cfg = self.config
        try:
            ref = prepare_frame(self.ref_rgb, self.ref_depth_m, self.ref_camera, config=cfg,
                                name=f"reference {self.stamp_ns}")
            self.result = align_frames(self.source, ref, config=cfg.f2m_config, use_color=cfg.f2m_color,
                                       use_depth=True)
        except TrackingError as exc:
            if "no valid depth" not in str(exc):
                self.error = exc
        self.seconds = time.perf_counter() - t0
        return self


class RGBDTracker:
    """Two-step RGB-D tracking for one camera; see the module docstring. Call :meth:`reset` with the start pose."""

    def __init__(self, camera: PinholeCamera, *, config: TrackerConfig | None = None) -> None:
        self.camera = camera
        self.config = TrackerConfig() if config is None else config
        self._pending: OrderedDict[int, _Pending] = OrderedDict()
        self._last: tuple[int, RGBDFrame, NDArray[np.float64]] | None = None  # f2f target: stamp, frame, best pose
        self._last_stamp: int | None = None  # of the last frame (after _last's when its depth repeated _last's)
        self._T_start: NDArray[np.float64] | None = None
        self._motion = MotionPrior(self.config.motion_prior, self.config.motion_prior_max_gap_s)  # f2f's start
        self._large: list[NDArray[np.float64]] = []  # map-frame corrections of the last f2m results too large
        self._probe: NDArray[np.float64] | None = None  # the agreed one: new frames' T≈ are moved by it

    @property
    def initialized(self) -> bool:
        return self._T_start is not None or self._last is not None

    @property
    def pending_stamps(self) -> list[int]:
        return list(self._pending)

    def reset(self, T_map_cam: ArrayLike, *, stamp_ns: int | None = None) -> None:
        """Restart tracking at pose ``T_map_cam``: of the frame ``stamp_ns`` if it was already coarse-tracked (the
        evaluation's reset to ground truth after a tracking loss), else of the next frame."""
        T = np.asarray(T_map_cam, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise TrackingInputError(f"reset pose must be a finite 4x4 matrix, got shape {T.shape}")
        self._pending.clear()
        self._motion.reset()
        self._large.clear()
        self._probe = None
        if stamp_ns is not None and self._last is not None and self._last_stamp == int(stamp_ns):
            self._last = (self._last[0], self._last[1], T.copy())
            self._T_start = None  # (a frame whose depth repeated _last's has _last's pose)
        else:
            self._last = self._last_stamp = None
            self._T_start = T.copy()

    def track_coarse(self, stamp_ns: int, rgb: ArrayLike, depth_m: ArrayLike) -> CoarseEstimate:
        """f2f step for a new live frame (stamps must increase); returns T≈. The same as :meth:`finish_coarse` of
        :meth:`start_coarse`'s job after :meth:`F2FJob.run`."""
        return self.finish_coarse(self.start_coarse(stamp_ns, rgb, depth_m).run())

    def start_coarse(self, stamp_ns: int, rgb: ArrayLike, depth_m: ArrayLike) -> F2FJob:
        """The f2f work of a new live frame as a job that touches no tracker state (it reads the previous frame and
        the constant-velocity prior as they are now): run it outside the lock that guards this tracker, so that f2m
        jobs can start and finish meanwhile, then :meth:`finish_coarse`. One f2f job at a time."""
        if not self.initialized:
            raise TrackingInputError("tracker has no start pose: call reset(T_map_cam) first")
        stamp = int(stamp_ns)
        if self._last_stamp is not None and stamp <= self._last_stamp:
            raise TrackingInputError(f"frame stamp {stamp} is not after the previous frame's {self._last_stamp}")
        prev = None if self._last is None else self._last[:2]
        init = None if self._last_stamp is None else self._motion.predict(stamp - self._last_stamp)
        return F2FJob(stamp, rgb, depth_m, self.camera, self.config, prev, init)

    def finish_coarse(self, job: F2FJob) -> CoarseEstimate:
        """Add the frame of a job that has run: T≈ chains its f2f motion to the previous frame's pose as it is now
        (f2m may have refined it meanwhile). Raises the job's :class:`TrackingError`, or one if the tracker was
        reset meanwhile."""
        if job.error is not None:
            raise job.error
        assert job.frame is not None
        stamp, res = job.stamp_ns, job.result
        if job.previous is None:
            if self._last is not None or self._T_start is None:
                raise TrackingInputError(f"frame {stamp}: the tracker was reset or moved on while it was tracked")
            T, prev_stamp, T_rel = self._T_start.copy(), None, np.eye(4)
            self._T_start = None
        else:
            prev_stamp = job.previous[0]
            if self._last is None or self._last[0] != prev_stamp or self._last[1] is not job.previous[1]:
                raise TrackingInputError(f"frame {stamp}: the tracker was reset or moved on while it was tracked")
            if res is None:  # the depth repeats the previous frame's: no motion measured; it stays the f2f target
                T_rel = np.eye(4)
            else:
                T_rel = res.T_target_source
                if self._last_stamp is not None:  # (always, with _last)
                    self._motion.measured(T_rel, stamp - self._last_stamp, res.converged)
            T = self._last[2] @ T_rel
        T_coarse = T.copy() if self._probe is None else self._probe @ T  # a probe: the reference is rendered there
        self._pending[stamp] = _Pending(job.frame, T_coarse, T.copy(), prev_stamp, T_rel, res, job.seconds,
                                        self._probe is not None)
        if job.repeated != "depth":
            self._last = (stamp, job.frame, T.copy())
        self._last_stamp = stamp
        return CoarseEstimate(stamp, T_coarse.copy(), res, job.seconds, job.repeated)

    def expired(self) -> list[int]:
        """Stamps of pending frames beyond ``max_pending`` (oldest first): finish them with :meth:`skip_reference`."""
        extra = len(self._pending) - self.config.max_pending
        return list(self._pending)[:extra] if extra > 0 else []

    def _finish(self, stamp: int, T: NDArray[np.float64], source: str, reason: str, f2m: AlignResult | None,
                seconds: dict[str, float]) -> TrackResult:
        p = self._pending.pop(stamp)
        p.T_best = T
        # re-chain the later frames (and the last frame) from the final pose of this one. A frame whose depth
        # repeated its f2f target's does not move the target: its f2m paired a newer colour image with the target's
        # depth, and the target has its own f2m (a confirmed probe moves the whole track in finish_refine).
        prev_T = {stamp: T}
        for s, q in self._pending.items():
            if q.prev_stamp in prev_T:
                q.T_best = prev_T[q.prev_stamp] @ q.T_prev_cur
                prev_T[s] = q.T_best
        if self._last is not None and self._last[0] in prev_T:
            self._last = (self._last[0], self._last[1], prev_T[self._last[0]].copy())
        seconds = {"f2f": p.f2f_seconds, **seconds}
        return TrackResult(stamp, T.copy(), source, reason, p.f2f, f2m, seconds)

    def refine(self, stamp_ns: int, ref_rgb: ArrayLike, ref_depth_m: ArrayLike) -> TrackResult:
        """f2m step: align the pending frame ``stamp_ns`` to the reference rendered at its T≈; finishes the frame.

        Earlier pending frames stay pending (see :meth:`expired` and :meth:`skip_reference`).
        Raises :class:`TrackingError` if the frame is not pending or the reference is malformed (the frame stays
        pending). The same as :meth:`finish_refine` of :meth:`start_refine`'s job after :meth:`F2MJob.run`."""
        job = self.start_refine(stamp_ns, ref_rgb, ref_depth_m)
        return self.finish_refine(job.run())

    def start_refine(self, stamp_ns: int, ref_rgb: ArrayLike, ref_depth_m: ArrayLike) -> F2MJob:
        """The f2m work of the pending frame ``stamp_ns`` as a job that touches no tracker state: run it on another
        thread (its kernels release the GIL) while this tracker goes on with f2f, then :meth:`finish_refine`."""
        stamp = int(stamp_ns)
        if stamp not in self._pending:
            raise TrackingInputError(f"no pending frame with stamp {stamp} (late or unknown reference)")
        half = self.camera.scaled(0.5)
        ref_shape = np.shape(ref_depth_m)[:2]
        if ref_shape not in (self.camera.shape, half.shape):
            raise TrackingInputError(f"reference {stamp}: depth image {ref_shape} is neither the camera's size "
                                     f"{self.camera.shape} nor half of it {half.shape}")
        return F2MJob(stamp, self._pending[stamp].frame, ref_rgb, ref_depth_m,
                      self.camera if ref_shape == self.camera.shape else half, self.config)

    def finish_refine(self, job: F2MJob) -> TrackResult:
        """Finish the frame of a job that has run: its f2m pose, or its f2f pose if the f2m result is rejected.
        Raises :class:`TrackingError` if the frame was finished meanwhile (a reset, a timeout) or the reference
        was malformed (the frame stays pending)."""
        stamp = job.stamp_ns
        p = self._pending.get(stamp)
        if p is None or p.frame is not job.source:
            raise TrackingInputError(f"frame {stamp} was finished while its reference was aligned")
        if job.error is not None:
            raise job.error
        res, seconds = job.result, {"f2m": job.seconds}
        if res is None:
            return self._finish(stamp, p.T_best, "f2f", "reference has no valid depth", None, seconds)
        # the reference was rendered at T≈ as published; later re-chaining of T_best does not move it
        T_f2m = p.T_coarse @ res.T_target_source
        rejected = f2m_rejection(res, self.config)
        if p.probe:  # against a reference rendered where agreeing large corrections put the pose
            self._probe = None  # one answer decides
            if rejected:
                return self._finish(stamp, p.T_best, "f2f", f"{rejected}; a large correction not confirmed", res,
                                    seconds)
            D = T_f2m @ inverse(p.T_best)
            if not _within(D, self.config.max_f2m_correction_m, self.config.max_f2m_correction_deg):
                # the whole track moves: the frames still pending and the f2f target too (also when this frame's
                # depth repeated the target's, so that re-chaining from it would not reach the target)
                for q in self._pending.values():
                    q.T_best = D @ q.T_best
                if self._last is not None:
                    self._last = (self._last[0], self._last[1], D @ self._last[2])
                return self._finish(stamp, T_f2m, "f2m", "large correction confirmed", res, seconds)
        if rejected and res.converged:
            if self._probe is None and self._agreed(T_f2m @ inverse(p.T_best)):
                self._probe = self._large[-1]
                self._large.clear()
        else:
            self._large.clear()
        if rejected:
            return self._finish(stamp, p.T_best, "f2f", rejected, res, seconds)
        return self._finish(stamp, T_f2m, "f2m", "", res, seconds)

    def _agreed(self, correction: NDArray[np.float64]) -> bool:
        """Add a large f2m correction (``T_f2m T_best⁻¹``, map frame) to the run of consecutive ones; True when the
        last ``f2m_confirm_frames`` agree. If f2f went off at one frame and tracks on, every later frame's best pose
        is off by the same map-frame transform, which each f2m result undoes; but f2m from a pose that far off can
        settle on the same wrong answer frame after frame, so an agreed correction is only a probe until f2m against
        a reference rendered there confirms it."""
        cfg = self.config
        if cfg.f2m_confirm_frames == 0:
            return False
        if not all(_within(inverse(c) @ correction, cfg.f2m_confirm_tolerance_m, cfg.f2m_confirm_tolerance_deg)
                   for c in self._large):
            self._large.clear()
        self._large.append(correction)
        return len(self._large) >= cfg.f2m_confirm_frames

    def skip_reference(self, stamp_ns: int, reason: str = "no reference") -> TrackResult:
        """Finish a pending frame without f2m: its (re-chained) f2f pose is final."""
        stamp = int(stamp_ns)
        if stamp not in self._pending:
            raise TrackingInputError(f"no pending frame with stamp {stamp}")
        return self._finish(stamp, self._pending[stamp].T_best, "f2f", reason, None, {})
