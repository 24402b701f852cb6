"""Two-step tracking over a live stream (paper §III-D): when a frame is finished by f2m, when by f2f, and when
tracking starts over — the policy ``rgbd_tracker_node`` runs, apart from ROS.

A :class:`TrackingSession` owns the :class:`~lightfast.tracking.pipeline.RGBDTracker` of the current camera and the
frames waiting for their reference. Per live frame the f2f step gives T≈ (:class:`CoarsePose`, where the reference
is rendered); the frame is finished (:class:`Finished`) by the f2m step when its reference comes, or with its f2f
pose when the reference has not come within ``reference_timeout_s`` (counted from T≈), when more than
``max_pending`` frames wait, when a later frame's reference comes first, or when tracking restarts. Tracking
restarts at the newest pose when the camera or the frame-preparation options change, at a pose given by a reset,
and at ``initial_pose`` when time goes back (stamps, or the clock: a bag played again).

Two threads may drive a session: one the f2f steps (:meth:`start_frame` … :meth:`finish_frame`), one the f2m steps
(:meth:`start_refine` … :meth:`finish_refine`); the alignments (``job.run()``) run outside the session's lock, so
f2m of one frame overlaps f2f of the next. Everything the session decides goes, in order and under its lock, to the
``emit`` callback as events: poses to publish, problems, log lines, statuses. Frames are in ``map`` (``T_map_cam``),
stamps in ns, times from ``clock`` in seconds.
"""
from __future__ import annotations

import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lightfast.camera import PinholeCamera, Undistorter
from lightfast.errors import CameraModelError
from lightfast.stamps import StampGuard, StampVerdict
from lightfast.status import Level, Log, Problem, Status
from lightfast.tracking.errors import TrackingError
from lightfast.tracking.pipeline import F2FJob, F2MJob, RGBDTracker, TrackerConfig, TrackResult
from lightfast.tracking.rgbd_odometry import warm_up

__all__ = ["CoarsePose", "Event", "Finished", "Frame", "Refinement", "TrackingSession"]

#: Options that change how frames are prepared: a change restarts tracking at the last pose.
PREPARATION_FIELDS = ("pyramid_levels", "resolution_scale", "min_depth_m", "max_depth_m", "depth_discontinuity_m")


@dataclass(frozen=True, eq=False)
class Frame:
    """A paired live frame: colour (H×W×3 RGB or H×W grey), depth in metres, the images' frame ids."""

    stamp_ns: int
    rgb: NDArray[Any]
    depth_m: NDArray[np.float32]
    frame_id: str
    received_s: float  # clock() when the pair was complete
    arrival_lag_ns: int  # node clock minus the image stamp when the pair was complete (>= 0)
    depth_frame_id: str = ""  # the depth image's; "" = not said


@dataclass(frozen=True, eq=False)
class CoarsePose:
    """T≈ of a frame: publish it, the reference is rendered there."""

    stamp_ns: int
    T_map_cam: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Finished:
    """The final pose of a frame; ``frame_id`` is the camera frame to publish it for."""

    result: TrackResult
    frame_id: str
    received_s: float
    arrival_lag_ns: int

    def status(self, now_s: float) -> Status:
        """The frame's status at ``now_s`` (clock()): OK when refined by f2m, else WARN with the reason. Latency
        is image stamp → now: the node clock's lag when the frame arrived plus the time since (the node clock alone
        would do with a wall clock; on sim time it only advances with /clock messages, one per frame)."""
        r = self.result
        pipeline_s = now_s - self.received_s
        values = {
            "stamp_ns": r.stamp_ns, "source": r.source, "reason": r.reason,
            **{f"{k}_ms": 1e3 * v for k, v in r.seconds.items()},
            "f2f_inlier_ratio": r.f2f.inlier_ratio if r.f2f is not None else None,
            "f2f_converged": r.f2f.converged if r.f2f is not None else None,
            "f2m_inlier_ratio": r.f2m.inlier_ratio if r.f2m is not None else None,
            "f2m_converged": r.f2m.converged if r.f2m is not None else None,
            "latency_ms": 1e-6 * (self.arrival_lag_ns + round(1e9 * pipeline_s)),
            "pipeline_ms": 1e3 * pipeline_s,  # from the paired frame to here
        }
        level = Level.OK if r.source == "f2m" else Level.WARN
        return Status(level, r.source + (f": {r.reason}" if r.reason else ""), values, r.stamp_ns)


Event = CoarsePose | Finished | Problem | Log | Status


@dataclass(frozen=True, eq=False)
class Refinement:
    """An f2m alignment started by :meth:`TrackingSession.start_refine`: run ``job.run()``, then hand it back."""

    job: F2MJob
    tracker: RGBDTracker


@dataclass
class _Waiting:
    frame_id: str
    received_s: float
    arrival_lag_ns: int
    coarse_s: float  # clock() when T≈ was given: the reference deadline counts from here


class TrackingSession:
    """The tracker's state between frames and references; see the module docstring."""

    def __init__(self, config: TrackerConfig, emit: Callable[[Event], None], *,
                 clock: Callable[[], float] = time.monotonic, stats: dict[str, int] | None = None,
                 start_hint: str = "", camera_info_hint: str = "") -> None:
        self.config = config
        self._start_hint = start_hint  # appended to the line saying where tracking starts
        self._camera_info_hint = camera_info_hint  # appended to "no camera_info": where it is expected
        self._emit = emit
        self._clock = clock
        #: held while the session changes state (not while an alignment runs)
        self.lock = threading.RLock()
        self.tracker: RGBDTracker | None = None
        self._start_pose = config.T_map_cam_initial  # where the tracker (re)starts when it is created
        self._last_pose: NDArray[np.float64] | None = None  # newest T≈, to restart from
        self._waiting: OrderedDict[int, _Waiting] = OrderedDict()
        self._guard = StampGuard(config)
        self._announce_start = True  # say where tracking starts at the next first frame
        #: counters (added to ``stats`` when given: a node's counters)
        self.stats: dict[str, int] = {} if stats is None else stats
        self.stats |= {"frames_tracked": 0, "f2m": 0, "f2f": 0, "late_references": 0, "time_jumps": 0}

    @property
    def waiting(self) -> int:
        """Frames waiting for their reference."""
        return len(self._waiting)

    def deadline_period_s(self) -> float:
        """How often to call :meth:`start_frame` without a frame so that overdue frames are finished in time."""
        return min(0.1, max(0.01, self.config.reference_timeout_s / 4))

    # ------------------------------------------------------------------------------------------ f2f thread

    def start_frame(self, frame: Frame | None, *, camera: PinholeCamera | None, now_ns: int,
                    config: TrackerConfig | None = None, reset: tuple[NDArray[np.float64], int | None, str] | None
                    = None, clock_jump_ns: int | None = None, undistorter: Undistorter | None = None
                    ) -> F2FJob | None:
        """One f2f step: apply a new configuration, a camera change, a clock jump back (to ``clock_jump_ns``) and
        a reset (pose, stamp, source), finish overdue frames, and start the f2f alignment of ``frame`` (None: no
        new frame), undistorted into ``camera``'s pinhole image by ``undistorter`` (that of a lens-distorted
        camera_info). Returns the job to run and hand to :meth:`finish_frame`, or None."""
        with self.lock:
            if config is not None:
                self._apply_config(config)
            if camera is not None and self.tracker is not None and camera != self.tracker.camera:
                self._restart("camera_info changed")
            if clock_jump_ns is not None and self._guard.clock_jumped_back(clock_jump_ns):
                self._time_jumped(f"ROS time jumped back to {clock_jump_ns * 1e-9:.3f} s")
            if reset is not None:
                self._apply_reset(*reset)
            self._finish_overdue()
            if frame is None or not self._stamp_ok(frame.stamp_ns, now_ns):
                return None
            job = self._start_track(frame, camera, undistorter)
            if job is not None:
                self._guard.accept(job.stamp_ns)
            return job

    def finish_frame(self, job: F2FJob, frame: Frame) -> None:
        """Take the result of a run f2f job: T≈ is emitted, frames beyond ``max_pending`` finished."""
        with self.lock:
            stamp = frame.stamp_ns
            if self.tracker is None:
                return  # restarted meanwhile (only the f2f thread restarts: kept for the type checker)
            try:
                est = self.tracker.finish_coarse(job)
            except TrackingError as exc:
                self._problem("track", f"frame {stamp} not tracked: {exc}", stamp_ns=stamp)
                return
            self.stats["frames_tracked"] += 1
            self._last_pose = est.T_map_cam
            self._waiting[stamp] = _Waiting(self.config.camera_frame or frame.frame_id, frame.received_s,
                                            frame.arrival_lag_ns, self._clock())
            self._emit(CoarsePose(stamp, est.T_map_cam))
            for s in self.tracker.expired():
                self._finish(self.tracker.skip_reference(
                    s, f"no reference: more than max_pending={self.config.max_pending} frames waiting"))

    # ------------------------------------------------------------------------------------------ f2m thread

    def start_refine(self, stamp_ns: int, rgb: NDArray[Any], depth_m: NDArray[np.float32]) -> Refinement | None:
        """Start the f2m alignment of frame ``stamp_ns`` against its reference (colour, depth in metres). Frames
        older than it lose their reference (finished with f2f). None: nothing to refine."""
        with self.lock:
            tracker = self.tracker
            if tracker is None or stamp_ns not in self._waiting:
                self._late(stamp_ns)
                return None
            for s in [s for s in self._waiting if s < stamp_ns]:
                self._finish(tracker.skip_reference(s, "no reference (a later frame's reference came)"))
            try:
                return Refinement(tracker.start_refine(stamp_ns, rgb, depth_m), tracker)
            except TrackingError as exc:
                self._bad_reference(tracker, stamp_ns, exc)
                return None

    def finish_refine(self, refinement: Refinement) -> None:
        """Take the result of a run f2m job (ignored when tracking restarted or the frame finished meanwhile)."""
        stamp = refinement.job.stamp_ns
        with self.lock:
            if self.tracker is not refinement.tracker or stamp not in self._waiting:
                self._late(stamp)
                return
            try:
                result = refinement.tracker.finish_refine(refinement.job)
            except TrackingError as exc:
                self._bad_reference(refinement.tracker, stamp, exc)
                return
            self._finish(result)

    def finish_all(self, reason: str) -> None:
        """Finish every waiting frame with its f2f pose."""
        with self.lock:
            if self.tracker is not None:
                for s in list(self._waiting):
                    self._finish(self.tracker.skip_reference(s, reason))
            self._waiting.clear()

    # ------------------------------------------------------------------------------------------ policy

    def _problem(self, key: str, text: str, level: Level = Level.WARN, stamp_ns: int | None = None) -> None:
        self._emit(Problem(key, text, level, stamp_ns, {"stamp_ns": stamp_ns, "source": "", "reason": text}))

    def _apply_config(self, cfg: TrackerConfig) -> None:
        old, self.config = self.config, cfg
        if self.tracker is None:
            if old.initial_pose != cfg.initial_pose:
                self._start_pose = cfg.T_map_cam_initial
            return
        if any(getattr(old, f) != getattr(cfg, f) for f in PREPARATION_FIELDS):
            warm_up(cfg)
            self._restart("frame preparation options changed")
        else:
            self.tracker.config = cfg

    def _restart(self, why: str) -> None:
        """Finish the waiting frames with their f2f pose and start a new tracker at the newest pose."""
        self.finish_all(f"f2f ({why})")
        self.tracker = None
        if self._last_pose is not None:
            self._start_pose = self._last_pose
        self._emit(Log(f"tracking restarts at the last pose: {why}"))

    def _stamp_ok(self, stamp: int, now_ns: int) -> bool:
        """Check a live frame's stamp: refuse it, or restart tracking when time went back."""
        verdict = self._guard.check(stamp, now_ns)
        if verdict is StampVerdict.JUMPED_BACK:
            assert self._guard.last_ns is not None  # JUMPED_BACK: there is a previous stamp
            self._time_jumped(f"frame stamps went back {(self._guard.last_ns - stamp) * 1e-9:.3f} s")
        elif verdict is not StampVerdict.OK:
            self._problem("stamp", f"frame {stamp}: {self._guard.describe(verdict, stamp, now_ns)}", stamp_ns=stamp)
            return False
        return True

    def _time_jumped(self, why: str) -> None:
        """Time went back (a bag played again or looped, a restarted simulation): the frames waiting are finished
        with their f2f pose, and tracking starts over at ``initial_pose``, as at start-up."""
        self.stats["time_jumps"] += 1
        self.finish_all("f2f (time jumped back)")
        self.tracker = None
        self._last_pose = None
        self._start_pose = self.config.T_map_cam_initial
        self._guard.reset()
        self._announce_start = True
        self._emit(Log(f"{why} (a bag played again, or looped?): tracking starts over at initial_pose", Level.WARN))

    def _apply_reset(self, T: NDArray[np.float64], stamp: int | None, source: str) -> None:
        if self.tracker is None:
            self._start_pose = T
        else:
            self.tracker.reset(T, stamp_ns=stamp)
            for s in [s for s in self._waiting if s not in self.tracker.pending_stamps]:
                del self._waiting[s]
        self._last_pose = T
        self._announce_start = False
        self._emit(Log(f"tracking reset on {source} to {np.round(T[:3, 3], 3).tolist()} m"))
        self._emit(Status(Level.OK, "tracking reset", {"stamp_ns": stamp, "source": "reset", "reason": ""}))

    def _start_track(self, f: Frame, camera: PinholeCamera | None, undistorter: Undistorter | None
                     ) -> F2FJob | None:
        stamp = f.stamp_ns
        if camera is None:
            self._problem("no_camera_info", f"frame {stamp} not tracked: no camera_info{self._camera_info_hint} yet",
                          stamp_ns=stamp)
            return None
        if f.rgb.shape[:2] != camera.shape or f.depth_m.shape != camera.shape:
            self._problem("size", f"frame {stamp} not tracked: colour {f.rgb.shape[1]}x{f.rgb.shape[0]}, depth "
                          f"{f.depth_m.shape[1]}x{f.depth_m.shape[0]}, camera_info {camera.width}x{camera.height}",
                          stamp_ns=stamp)
            return None
        if self.tracker is None:
            self.tracker = RGBDTracker(camera, config=self.config)
            self.tracker.reset(self._start_pose)
            if self._announce_start:  # nothing says where the camera is but the parameter: say it once
                self._announce_start = False
                self._emit(Log(f"tracking starts at initial_pose {np.round(self._start_pose[:3, 3], 3).tolist()} "
                               f"m in {self.config.map_frame}{self._start_hint}", Level.WARN))
        if f.depth_frame_id not in ("", f.frame_id):  # e.g. a driver's raw depth topic instead of its aligned one
            self._emit(Log(f"depth images in frame {f.depth_frame_id!r}, colour in {f.frame_id!r}: the tracker needs "
                           "depth registered to the colour camera (a driver's aligned_depth_to_color); tracking "
                           "them as if it were", Level.WARN, key="depth_frame"))
        try:
            rgb, depth = f.rgb, f.depth_m
            if undistorter is not None:
                rgb, depth = undistorter.colour(rgb), undistorter.depth(depth)
            return self.tracker.start_coarse(stamp, rgb, depth)
        except (TrackingError, CameraModelError) as exc:
            self._problem("track", f"frame {stamp} not tracked: {exc}", stamp_ns=stamp)
            return None

    def _late(self, stamp: int) -> None:
        self.stats["late_references"] += 1
        self._emit(Log(f"reference for frame {stamp} came late or for an unknown frame (ignored)", key="late"))

    def _bad_reference(self, tracker: RGBDTracker, stamp: int, exc: TrackingError) -> None:
        self._emit(Log(f"bad reference for frame {stamp}: {exc}", Level.WARN, key="reference"))
        self._finish(tracker.skip_reference(stamp, f"bad reference: {exc}"))

    def _finish_overdue(self) -> None:
        if self.tracker is None:
            return
        timeout = self.config.reference_timeout_s
        now = self._clock()
        for s in [s for s, w in self._waiting.items() if now - w.coarse_s >= timeout]:
            self._finish(self.tracker.skip_reference(s, f"no reference within {timeout:g} s"))

    def _finish(self, r: TrackResult) -> None:
        w = self._waiting.pop(r.stamp_ns)
        self.stats[r.source] = self.stats.get(r.source, 0) + 1
        self._emit(Finished(r, w.frame_id, w.received_s, w.arrival_lag_ns))
