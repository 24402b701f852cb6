"""Teach or repeat over a live stereo stream (paper §III: teach builds the map, repeat localizes against it) — what
``vtr_localizer_node`` runs per stereo pair, apart from ROS.

A :class:`VtrLocalizer` owns the :class:`~lightfast.vtr.teach.TeachPipeline` (``mode: teach``) or the
:class:`~lightfast.vtr.repeat.RepeatPipeline` on the map at ``map_path`` (``mode: repeat``; loaded, and retried
every ``map_retry_s`` while it fails). Per stereo pair (left and right RGB images, rectified, with the projection
matrices ``P`` (3×4) of both cameras) it checks the input (sizes, camera_info, black images, the map's camera,
stamps), steps the pipeline and hands out, in order, to ``emit``: the VO chain (:class:`OdometryOut`:
``T_odom_cam`` in ``odom_frame``, the twist of the current camera in its own frame, m/s and rad/s), the repeat's
localization (:class:`LocalizationOut`: ``T_kf_cam`` relative to the keyframe with a 6×6 covariance of (x, y, z,
roll, pitch, yaw) in the keyframe frame — from the estimate's covariance, or the assumed VO drift
``vo_drift_m_per_m`` / ``vo_drift_deg_per_m`` since the last localization), the colour-constant images
(:class:`ImagesOut`), problems and statuses (:mod:`lightfast.status`).

Time going back (stamps or clock) restarts a repeat (a whole-map search, the VO chain at its origin); a teach
refuses pairs from before its newest. :meth:`finish_teach` writes the map; :meth:`close` aborts an unfinished
teach (a previous map at ``map_path`` stays). Callers serialize calls with :attr:`lock`.
"""
from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from lightfast.config import ConfigError
from lightfast.errors import InputError, LightfastError
from lightfast.geometry import so3_log
from lightfast.stamps import StampGuard, StampVerdict
from lightfast.status import Level, Log, Problem, Status
from lightfast.vtr.color_constant import ColorConstantConfig
from lightfast.vtr.errors import MapError, VtrError
from lightfast.vtr.localizer_config import VtrLocalizerConfig
from lightfast.vtr.map_store import MapStore, TeachMap
from lightfast.vtr.repeat import RepeatPipeline, RepeatResult
from lightfast.vtr.stereo_front_end import check_stereo_pair
from lightfast.vtr.teach import TeachPipeline

__all__ = ["ImagesOut", "LocalizationOut", "OdometryOut", "StereoCamera", "StereoPair", "VtrLocalizer",
           "pose_covariance"]

Array = NDArray[np.float64]
#: A repeat's camera must match the map's projection matrices to this relative tolerance.
CAMERA_RTOL = 1e-4
#: Smallest image side accepted (OpenCV's ORB fails on images of a few pixels).
MIN_IMAGE_PX = 16


@dataclass(frozen=True, eq=False)
class StereoPair:
    """Left and right RGB images (H×W×3 uint8) of one stamp; ``frame_id`` is the left camera's frame."""

    stamp_ns: int
    left: NDArray[np.uint8]
    right: NDArray[np.uint8]
    frame_id: str
    received_s: float  # clock() when the pair was complete


@dataclass(frozen=True, eq=False)
class StereoCamera:
    """One rectified camera of the pair: the projection matrix ``P`` (3×4, pixels) and the image size (w, h)."""

    P: Array
    size: tuple[int, int]


@dataclass(frozen=True, eq=False)
class OdometryOut:
    stamp_ns: int
    T_odom_cam: Array
    linear_mps: Array  # velocity of the current camera in its own frame
    angular_radps: Array
    frame_id: str


@dataclass(frozen=True, eq=False)
class LocalizationOut:
    stamp_ns: int
    T_kf_cam: Array
    covariance: Array  # 6×6, (x, y, z, roll, pitch, yaw) in the keyframe frame
    keyframe_frame: str
    frame_id: str


@dataclass(frozen=True, eq=False)
class ImagesOut:
    stamp_ns: int
    left: NDArray[np.uint8]
    color: ColorConstantConfig
    frame_id: str


Event = OdometryOut | LocalizationOut | ImagesOut | Problem | Log | Status


def pose_covariance(T: Array, cov_xi: Array) -> Array:
    """A covariance of ξ = (ρ, φ) in ``T·exp(ξ)`` (camera frame) as ROS wants it: position and rotation
    perturbations in the parent frame, p' = p + R ρ, R' = exp(R φ) R, i.e. J = diag(R, R)."""
    J = np.zeros((6, 6))
    J[:3, :3] = J[3:, 3:] = T[:3, :3]
    C = J @ cov_xi @ J.T
    return 0.5 * (C + C.T)


def drift_covariance(distance_m: float, drift_m_per_m: float, drift_deg_per_m: float) -> Array:
    """The covariance of a pose carried by VO alone for ``distance_m``: the assumed drift per metre (σ grows
    linearly with the distance), with a small floor."""
    var_p = (drift_m_per_m * distance_m) ** 2 + 1e-6
    var_r = math.radians(drift_deg_per_m * distance_m) ** 2 + 1e-8
    return np.diag([var_p] * 3 + [var_r] * 3)


class VtrLocalizer:
    """Teach or repeat for one stereo camera; see the module docstring. ``sources`` name where the camera_info of
    each side and the finish request come from (``left_info``, ``right_info``, ``finish``), for the texts."""

    def __init__(self, config: VtrLocalizerConfig, emit: Callable[[Event], None], *,
                 clock: Callable[[], float] = time.monotonic, sources: Mapping[str, str] | None = None,
                 stats: dict[str, int] | None = None) -> None:
        if not config.map_path:
            raise ConfigError("parameter map_path is required (the teach map directory)")
        self.config = config
        self._emit = emit
        self._clock = clock
        self._sources = {"left_info": "the left camera_info", "right_info": "the right camera_info",
                         "finish": "finish_teach", **(sources or {})}
        self.lock = threading.RLock()
        self.map_path = Path(config.map_path).expanduser()
        self.teach: TeachPipeline | None = None
        self.repeat: RepeatPipeline | None = None
        self.finished: TeachMap | None = None  # the map a finished teach wrote
        self.map_error: str | None = None
        self._map_attempt_s: float | None = None
        self._guard = StampGuard(config)
        self._T_odom_cam = np.eye(4)
        self._last_stamp_ns: int | None = None
        #: counters (added to ``stats`` when given: a node's counters)
        self.stats: dict[str, int] = {} if stats is None else stats
        self.stats |= {"frames_done": 0, "ignored": 0, "time_jumps": 0}
        if config.mode == "teach":
            _check_teach_target(self.map_path, config.overwrite_map)
            self.teach = TeachPipeline(self.map_path, config.teach, stereo=config.stereo, vo=config.vo,
                                       overwrite=config.overwrite_map)

    def status_values(self) -> dict[str, Any]:
        cfg = self.config
        values: dict[str, Any] = {"mode": cfg.mode, "map_path": str(self.map_path)}
        if cfg.mode == "repeat":
            return values | {"repeat_mode": cfg.repeat.mode, "map_loaded": self.repeat is not None,
                             "map_error": self.map_error or ""}
        keyframes = len(self.finished) if self.finished is not None else \
            (self.teach.num_keyframes if self.teach is not None else 0)
        return values | {"teach_finished": self.finished is not None, "keyframes": keyframes}

    # ------------------------------------------------------------------------------------------ map

    def load_map(self) -> bool:
        """Load the map of a repeat (retried every ``map_retry_s`` while it fails); True when there is one."""
        if self.repeat is not None:
            return True
        now = self._clock()
        if self._map_attempt_s is not None and now - self._map_attempt_s < self.config.map_retry_s:
            return False
        self._map_attempt_s = now
        try:
            self.repeat = RepeatPipeline(MapStore.load(self.map_path), self.config.repeat, vo=self.config.vo)
        except (MapError, VtrError, ConfigError, OSError) as exc:
            self.map_error = f"no usable teach map: {exc}"
            self._problem(f"map:{type(exc).__name__}", f"{self.map_error} (retrying every "
                          f"{self.config.map_retry_s:g} s)", Level.ERROR, counted=False)
            return False
        self.map_error = None
        m = self.repeat.map
        text = (f"map loaded: {len(m)} keyframes, {m.length_m:.2f} m, sources {','.join(m.sources)}, "
                f"{m.feature}, {m.image_size[0]}x{m.image_size[1]}")
        self._emit(Log(text))
        self._emit(Status(Level.OK, text))
        return True

    # ------------------------------------------------------------------------------------------ stream

    def clock_jumped(self, now_ns: int) -> None:
        """ROS time jumped back to ``now_ns``: a repeat whose newest pair lies beyond it starts over."""
        if self.teach is None and self._guard.clock_jumped_back(now_ns):
            self._time_jumped(f"ROS time jumped back to {now_ns * 1e-9:.3f} s")

    def process(self, f: StereoPair, left: StereoCamera | None, right: StereoCamera | None, now_ns: int) -> None:
        """One stereo pair with the cameras known now; bad input and failed steps are reported, never raised."""
        try:
            self._process(f, left, right, now_ns)
        except (LightfastError, cv2.error) as exc:  # bad input the core refused (an InputError), or a failed step
            level = Level.WARN if isinstance(exc, InputError) else Level.ERROR
            self._problem(f"step:{type(exc).__name__}", f"stereo pair {f.stamp_ns} not processed: {exc}", level,
                          f.stamp_ns)

    def _problem(self, key: str, text: str, level: Level = Level.WARN, stamp_ns: int | None = None, *,
                 counted: bool = True) -> None:
        self._emit(Problem(key, text, level, stamp_ns, {"stamp_ns": stamp_ns, "problem": key}, counted))

    def _process(self, f: StereoPair, left: StereoCamera | None, right: StereoCamera | None, now_ns: int) -> None:
        if self.config.mode == "teach" and (self.teach is None or self.finished is not None):
            self.stats["ignored"] += 1
            text = ("teach finished: map written to " + str(self.map_path)) if self.finished is not None else \
                "teach aborted"
            self._emit(Log(f"stereo pair {f.stamp_ns} ignored: {text}", key="finished"))
            self._emit(Status(Level.OK, text, {"stamp_ns": f.stamp_ns}))
            return
        if self.config.mode == "repeat" and not self.load_map():
            self._problem("no_map", f"stereo pair {f.stamp_ns} skipped: {self.map_error}", Level.ERROR, f.stamp_ns,
                          counted=False)
            return
        P = self._check_pair(f, left, right)
        if P is None or not self._stamp_ok(f, now_ns):
            return
        if self.teach is not None:
            self._teach_step(f, *P)
        else:
            self._repeat_step(f, *P)

    def _check_pair(self, f: StereoPair, left: StereoCamera | None,
                    right: StereoCamera | None) -> tuple[Array, Array] | None:
        """The projection matrices for a pair, or None after reporting why the pair cannot be used."""
        stamp = f.stamp_ns
        missing = [self._sources[f"{s}_info"] for s, c in (("left", left), ("right", right)) if c is None]
        if missing:
            self._problem("no_camera_info", f"stereo pair {stamp} skipped: no usable camera_info on "
                          f"{' and '.join(missing)} yet", stamp_ns=stamp)
            return None
        assert left is not None and right is not None
        (hl, wl), (hr, wr) = f.left.shape[:2], f.right.shape[:2]
        if (hl, wl) != (hr, wr):
            self._problem("size", f"stereo pair {stamp} skipped: left image {wl}x{hl} and right image {wr}x{hr} "
                          "differ in size", stamp_ns=stamp)
            return None
        if min(hl, wl) < MIN_IMAGE_PX:
            self._problem("size", f"stereo pair {stamp} skipped: images of {wl}x{hl} are too small (at least "
                          f"{MIN_IMAGE_PX}x{MIN_IMAGE_PX})", stamp_ns=stamp)
            return None
        for side, cam in (("left", left), ("right", right)):
            if cam.size != (wl, hl):
                self._problem("info_size", f"stereo pair {stamp} skipped: images are {wl}x{hl} but the {side} "
                              f"camera_info says {cam.size[0]}x{cam.size[1]}", stamp_ns=stamp)
                return None
        try:
            Pl, Pr = check_stereo_pair(left.P, right.P)
        except VtrError as exc:
            self._problem("stereo_info", f"stereo pair {stamp} skipped: {exc}", stamp_ns=stamp)
            return None
        means = (float(f.left.mean()), float(f.right.mean()))
        black = self.config.black_level
        if min(means) < black:
            which = " and ".join(s for s, m in zip(("left", "right"), means, strict=True) if m < black)
            self._problem("black", f"stereo pair {stamp} skipped: black {which} image (mean {min(means):.1f} < "
                          f"black_level {black:g})", stamp_ns=stamp)
            return None
        return Pl, Pr

    def _stamp_ok(self, f: StereoPair, now_ns: int) -> bool:
        """Refuse a pair stamped ahead of the clock or out of order; when the stamps went back, a repeat starts
        over (a teach refuses pairs from before its newest: it would teach the route twice)."""
        verdict = self._guard.check(f.stamp_ns, now_ns)
        if verdict is StampVerdict.JUMPED_BACK and self.teach is None:
            assert self._guard.last_ns is not None  # JUMPED_BACK: there is a previous stamp
            self._time_jumped(f"stereo pair stamps went back {(self._guard.last_ns - f.stamp_ns) * 1e-9:.3f} s")
        elif verdict is StampVerdict.JUMPED_BACK:
            self._problem("stamp", f"stereo pair {f.stamp_ns} ignored: the stamps went back during a teach (a bag "
                          f"played again?); finish the teach with {self._sources['finish']} or restart the node",
                          stamp_ns=f.stamp_ns)
            return False
        elif verdict is not StampVerdict.OK:
            self._problem("stamp", f"stereo pair {f.stamp_ns}: {self._guard.describe(verdict, f.stamp_ns, now_ns)}",
                          stamp_ns=f.stamp_ns)
            return False
        self._guard.accept(f.stamp_ns)
        return True

    def _time_jumped(self, why: str) -> None:
        """Time went back in a repeat: the VO chain and the localization prior start over (a whole-map search)."""
        self.stats["time_jumps"] += 1
        self._guard.reset()
        self._T_odom_cam = np.eye(4)
        self._last_stamp_ns = None
        if self.repeat is not None:
            self.repeat = RepeatPipeline(self.repeat.map, self.config.repeat, vo=self.config.vo)
        self._emit(Log(f"{why} (a bag played again, or looped?): the repeat starts over with a search of the whole "
                       "map, the VO chain at its origin", Level.WARN))

    # ------------------------------------------------------------------------------------------ teach

    def _teach_step(self, f: StereoPair, Pl: Array, Pr: Array) -> None:
        teach = self.teach
        assert teach is not None
        t0 = time.perf_counter()
        features = teach.front.process(f.left, f.right, Pl, Pr)
        t1 = time.perf_counter()
        r = teach.step_features(f.stamp_ns, features, Pl, Pr, (f.left.shape[1], f.left.shape[0]))
        t2 = time.perf_counter()
        # after a step the VO's constant-velocity prediction is the motion it chained (estimate or prediction)
        self._odometry(f, teach.vo.prediction)
        self._emit(ImagesOut(f.stamp_ns, f.left, teach.front.color, f.frame_id))
        self.stats["frames_done"] += 1
        values: dict[str, Any] = {
            "stamp_ns": f.stamp_ns, "keyframe_id": r.keyframe_index, "new_keyframe": r.new_keyframe,
            "distance_m": r.distance_m, "vo_success": r.vo_success, "vo_inliers": r.vo_inliers,
            "vo_failures": teach.vo_failures, **{f"landmarks_{s}": n for s, n in r.landmarks.items()},
            "front_end_ms": 1e3 * (t1 - t0), "teach_ms": 1e3 * (t2 - t1),
            "total_ms": 1e3 * (time.perf_counter() - t0), "pipeline_ms": 1e3 * (self._clock() - f.received_s),
        }
        if r.vo_success:
            level, text = Level.OK, (f"keyframe {r.keyframe_index} added" if r.new_keyframe else
                                     f"taught ({r.distance_m:.2f} m from keyframe 0)")
        else:
            level, text = Level.WARN, "VO failed: the constant-velocity prediction is chained"
        self._emit(Status(level, text, values, f.stamp_ns))

    def finish_teach(self) -> tuple[bool, str]:
        """Write the taught map (queued pairs are to be processed before); success and a one-line message."""
        if self.config.mode != "teach":
            return False, "not teaching: this node runs in repeat mode"
        if self.finished is not None:
            m = self.finished
            return False, (f"the teach has already finished: {len(m)} keyframes, {m.length_m:.2f} m path written to "
                           f"{self.map_path}")
        teach = self.teach
        if teach is None:
            return False, "the teach was aborted"
        if teach.num_keyframes == 0:
            text = f"nothing taught yet (no usable stereo pair): no map written to {self.map_path}"
            self._emit(Status(Level.WARN, text))
            return False, text
        try:
            m = teach.finish()
        except (VtrError, OSError) as exc:
            self.teach = None
            text = (f"finishing the teach failed: {exc}; nothing was written to {self.map_path} (a previous map "
                    "there is unchanged)")
            self._problem("finish", text, Level.ERROR, counted=False)
            return False, text
        self.finished = m
        text = (f"map written to {self.map_path}: {len(m)} keyframes, {m.length_m:.2f} m path, {teach.frames} stereo "
                f"pairs, {teach.vo_failures} VO failures")
        self._emit(Log(text))
        self._emit(Status(Level.OK, text, {"path_length_m": m.length_m}))
        return True, text

    # ------------------------------------------------------------------------------------------ repeat

    def _repeat_step(self, f: StereoPair, Pl: Array, Pr: Array) -> None:
        rp = self.repeat
        assert rp is not None
        m = rp.map
        size = (f.left.shape[1], f.left.shape[0])
        if size != m.image_size or not (np.allclose(Pl, m.P_left, rtol=CAMERA_RTOL, atol=1e-9)
                                        and np.allclose(Pr, m.P_right, rtol=CAMERA_RTOL, atol=1e-9)):
            self._problem("camera", f"stereo pair {f.stamp_ns} skipped: the camera ({size[0]}x{size[1]}, P) differs "
                          f"from the map's ({m.image_size[0]}x{m.image_size[1]}); repeat with the taught camera",
                          stamp_ns=f.stamp_ns)
            return
        t0 = time.perf_counter()
        r = rp.step(f.stamp_ns, f.left, f.right, Pl, Pr)
        total_ms = 1e3 * (time.perf_counter() - t0)
        self._odometry(f, r.T_prev_cur)
        if r.T_kf_cam is not None:
            self._localization(f, r)
        self._emit(ImagesOut(f.stamp_ns, f.left, rp.front.color, f.frame_id))
        self.stats["frames_done"] += 1
        values: dict[str, Any] = {
            "stamp_ns": f.stamp_ns, "localized": r.localized, "keyframe_id": r.keyframe_index, "inliers": r.inliers,
            **{f"inliers_{s}": n for s, n in r.inliers_per_source.items()},
            **{f"matches_{s}": n for s, n in r.matches_per_source.items()},
            "distance_on_vo_m": r.distance_on_vo_m, "failure": r.failure, "relocalized": r.relocalized,
            "searched_map": r.searched_map, "failures": rp.failures, "vo_success": r.vo_success,
            "vo_inliers": r.vo_inliers, "distance_along_path_m": r.distance_along_path_m,
            **{f"{k}_ms": 1e3 * v for k, v in r.timing_s.items()},
            "total_ms": total_ms, "pipeline_ms": 1e3 * (self._clock() - f.received_s),
        }
        c = rp.config
        if r.localized:
            how = "relocalized by the whole-map search" if r.relocalized else "localized"
            level, text = Level.OK, f"{how} at keyframe {r.keyframe_index} ({r.inliers} inliers)"
        elif r.keyframe_index < 0:
            level, text = Level.WARN, "not localized yet: " + ("searching the whole map" if r.searched_map else
                                                               f"trying keyframe {c.initial_keyframe}")
        elif r.failure:
            level, text = Level.ERROR, (f"localization failure: {r.distance_on_vo_m:.1f} m on VO alone (limit "
                                        f"{c.max_distance_on_vo_m:g} m); searching the whole map")
        else:
            level, text = Level.WARN, (f"not localized: on VO for {r.distance_on_vo_m:.2f} m near keyframe "
                                       f"{r.keyframe_index}")
        self._emit(Status(level, text, values, f.stamp_ns))

    def _localization(self, f: StereoPair, r: RepeatResult) -> None:
        T = r.T_kf_cam
        assert T is not None
        if r.localized and r.covariance is not None and np.all(np.isfinite(r.covariance)):
            cov = pose_covariance(T, r.covariance)
        else:  # carried by VO alone: the assumed drift since the last localization
            cov = drift_covariance(r.distance_on_vo_m, self.config.vo_drift_m_per_m, self.config.vo_drift_deg_per_m)
        self._emit(LocalizationOut(f.stamp_ns, T, cov, f"{self.config.keyframe_frame_prefix}{r.keyframe_index}",
                                   f.frame_id))

    def _odometry(self, f: StereoPair, T_prev_cur: Array) -> None:
        self._T_odom_cam = self._T_odom_cam @ T_prev_cur
        dt = 0.0 if self._last_stamp_ns is None else 1e-9 * (f.stamp_ns - self._last_stamp_ns)
        self._last_stamp_ns = f.stamp_ns
        linear = angular = np.zeros(3)
        if dt > 0.0:
            R, t = T_prev_cur[:3, :3], T_prev_cur[:3, 3]
            linear = R.T @ t / dt  # velocity of the current camera, in its own frame
            angular = np.asarray(so3_log(R), dtype=np.float64) / dt
        self._emit(OdometryOut(f.stamp_ns, self._T_odom_cam.copy(), linear, angular, f.frame_id))

    def close(self) -> None:
        """An unfinished teach is aborted (its staging directory goes, a previous map stays); the repeat closed."""
        teach, self.teach = self.teach, None
        if teach is not None and self.finished is None:
            try:
                teach.abort()
            except (OSError, LightfastError) as exc:  # pragma: no cover - the staging directory is hidden anyway
                self._emit(Log(f"aborting the teach: {exc}", Level.WARN))
            else:
                self._emit(Log(f"teach not finished ({teach.num_keyframes} keyframes discarded): nothing written to "
                               f"{self.map_path}; a previous map there is unchanged", Level.WARN))
        if self.repeat is not None:
            self.repeat.close()


def _check_teach_target(path: Path, overwrite_map: bool) -> None:
    """Never replace something that is not a teach map (``overwrite_map`` replaces maps only)."""
    if not path.exists() or MapStore.exists(path):
        return  # a previous map: TeachPipeline refuses it unless overwrite_map
    if not (path.is_dir() and not any(path.iterdir())):
        raise ConfigError(f"map_path {path} exists and is not a teach map: refusing to replace it")
    if not overwrite_map:
        raise ConfigError(f"map_path {path} exists (an empty directory): set overwrite_map to teach into it")
