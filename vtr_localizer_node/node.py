"""``vtr_localizer_node``: colour-constant stereo visual teach & repeat (paper: Paton et al., ICRA 2015, §IV-B, IV-C)
on a rectified stereo stream, with the ROS-free pipelines of :mod:`lightfast.vtr`.

Inputs: ``/stereo/left/image_raw`` and ``/stereo/right/image_raw`` (colour: rgb8, bgr8, rgba8 or bgra8, *rectified*;
best-effort subscriptions unless ``sensor_reliability`` asks otherwise; paired by exact stamp, either
may come first) and ``/stereo/{left,right}/camera_info`` (the newest of each is used; only the rectified projection
matrices ``P`` and the image size matter: images must already be rectified, so ``D``/``K``/``R`` are ignored).
A pair that comes before the first ``camera_info`` of both cameras waits for it up to ``CAMERA_INFO_WAIT_S``.

Parameters: ``config/vtr_localizer_node.yaml``, from :class:`lightfast.vtr.localizer_config.VtrLocalizerConfig`.

``mode: teach`` builds a map at ``map_path`` (:class:`~lightfast.vtr.teach.TeachPipeline`): keyframes of all image
sources linked by greyscale VO, written keyframe by keyframe into a hidden staging directory. The service
``/vtr/finish_teach`` (``std_srvs/srv/Trigger``) first processes the stereo pairs still queued, then finishes the
teach: the manifest is written and the map moved into place in one step, replacing a previous map only then (and
only with ``overwrite_map``); the reply says how many keyframes and how long a path were written. When the node
shuts down (Ctrl-C, SIGTERM, ``destroy_node``) before that, the partial teach is aborted: its staging directory is
removed and a previous complete map at ``map_path`` stays as it was. After a finished teach further pairs are
ignored (the status says so).

``mode: repeat`` localizes against the map (:class:`~lightfast.vtr.repeat.RepeatPipeline`, ``repeat.mode`` fused /
grey / mcmanus). A missing or corrupt map does not stop the node: the status reports why (level ERROR), pairs are
skipped, and loading is retried every ``map_retry_s`` (e.g. until a teach in another process has finished).

Outputs, per processed stereo pair and stamped with it:

* ``/vtr/localization`` (``geometry_msgs/PoseWithCovarianceStamped``, repeat only, from the first localization on):
  the pose of the left camera relative to the taught path, i.e. in the frame of the nearest keyframe along the
  path, ``frame_id = vtr_keyframe_<index>`` (``keyframe_frame_prefix``; that keyframe's left optical frame). On a
  localized pair the covariance is the localization's (nominal 1 px noise), turned from the camera-frame
  perturbation of the core (ξ = (ρ, φ) in ``T·exp(ξ)``) into position and rotation perturbations in the keyframe
  frame (J = diag(R, R)); on a pair carried by VO alone (the paper: "the VO estimate is used as the final pose
  estimate if localization fails") it is diagonal, growing with the distance on VO (``vo_drift_m_per_m``,
  ``vo_drift_deg_per_m``).
* ``/vtr/odometry`` (``nav_msgs/Odometry``, teach and repeat): the greyscale VO chained from the first pair
  processed, ``frame_id = vtr_odom`` (``odom_frame``) → ``child_frame_id`` = the left image's frame; twist from
  the last VO step (child frame); covariances zero (unknown).
* ``/tf`` (``publish_tf``): ``odom_frame`` → left camera (the VO chain) and left camera → ``vtr_keyframe_<index>``
  (the inverse of the localization), so the camera keeps one parent and RViz shows the localized keyframe.
* ``/vtr/status`` (``diagnostic_msgs/DiagnosticArray``): per pair (``stamp_ns``) whether it localized, the
  keyframe id, inliers and matches per source, distance on VO, failure / relocalized / whole-map search, VO
  inliers, distance along the path, stage timings in ms; in a teach the keyframe id, new keyframe, keyframes and
  path length so far, landmarks per source; bad input and map problems (``stamp_ns`` of the pair, if any); and a
  1 Hz heartbeat (counters, queue length) whose level and message repeat the last state.
* ``/vtr/color_constant/fv`` and ``/vtr/color_constant/fr`` (``sensor_msgs/Image`` mono8): the 8-bit F_v and F_r
  images of the left camera, computed only while someone subscribes (``publish_images``).

Bad input — an image not in colour, missing or unusable camera_info, left and right (or image and camera_info) sizes
that differ, a black pair (mean below ``black_level``), a camera other than the map's — is reported on
``/vtr/status`` and in a throttled log line, and the pair is skipped; the node keeps running.

Time going back (ROS time, or the pairs' stamps, by more than ``time_jump_back_s``: a bag played again) restarts a
repeat (VO at its origin, a whole-map search); a teach refuses such pairs. Pairs stamped more than
``max_stamp_ahead_s`` ahead of the node's clock are refused.

Threading as in the other nodes: the subscription callbacks only convert and buffer; the pipelines run in a
guard-condition callback of their own mutually exclusive callback group (one pair per call), which the finish
service and the heartbeat share, so nothing touches a pipeline concurrently.
"""
from __future__ import annotations

import functools
import math
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger

from lightfast.config import ConfigError
from lightfast.errors import InputError, LightfastError
from lightfast.geometry import inverse, so3_log
from lightfast.ros.clock import ClockJumpLatch
from lightfast.ros.convert import (
    image_to_rgb,
    make_header,
    matrix_to_odometry,
    matrix_to_pose,
    numpy_to_image,
    stamp_to_ns,
)
from lightfast.ros.diagnostics import Level
from lightfast.ros.errors import ConversionError
from lightfast.ros.node import LightfastNode
from lightfast.ros.qos import OUTPUT_QOS, sensor_qos
from lightfast.ros.runtime import run_node
from lightfast.ros.sync import ExactTimePairs
from lightfast.ros.tf import TransformBroadcaster, transform_stamped
from lightfast.stamps import StampGuard, StampVerdict
from lightfast.topics import (
    STEREO_LEFT_FRAME,
    STEREO_LEFT_IMAGE_TOPIC,
    STEREO_LEFT_INFO_TOPIC,
    STEREO_RIGHT_IMAGE_TOPIC,
    STEREO_RIGHT_INFO_TOPIC,
    VTR_FINISH_TEACH_SERVICE,
    VTR_FR_TOPIC,
    VTR_FV_TOPIC,
    VTR_LOCALIZATION_TOPIC,
    VTR_ODOMETRY_TOPIC,
    VTR_STATUS_TOPIC,
)
from lightfast.vtr.color_constant import ColorConstantConfig, image_sources
from lightfast.vtr.errors import MapError, VtrError
from lightfast.vtr.localizer_config import VtrLocalizerConfig
from lightfast.vtr.map_store import MapStore, TeachMap
from lightfast.vtr.repeat import RepeatPipeline, RepeatResult
from lightfast.vtr.stereo import check_projection, check_stereo_pair
from lightfast.vtr.teach import TeachPipeline, TeachResult
from lightfast.vtr.visual_odometry import warm_up

NODE_NAME = "vtr_localizer_node"
#: Unpaired left / right images kept per side.
MAX_UNPAIRED = 10
STATUS_PERIOD_S = 1.0
#: A repeat's camera must match the map's projection matrices to this relative tolerance.
CAMERA_RTOL = 1e-4
#: A stereo pair waits this long for the first camera_info of both cameras before it is reported and skipped, s.
CAMERA_INFO_WAIT_S = 1.0
#: Smallest image side accepted (OpenCV's ORB fails on images of a few pixels).
MIN_IMAGE_PX = 16
_SIDES = {"left": (STEREO_LEFT_IMAGE_TOPIC, STEREO_LEFT_INFO_TOPIC),
          "right": (STEREO_RIGHT_IMAGE_TOPIC, STEREO_RIGHT_INFO_TOPIC)}


@dataclass(frozen=True)
class StereoInfo:
    """What the node uses of a ``camera_info``: the rectified projection matrix and the image size (w, h)."""

    P: np.ndarray
    size: tuple[int, int]


def stereo_info(msg: CameraInfo, side: str) -> StereoInfo:
    width, height = int(msg.width), int(msg.height)
    if width <= 0 or height <= 0:
        raise ConversionError(f"width={width} and height={height} must be > 0 (camera not calibrated?)")
    p = np.asarray(msg.p, dtype=np.float64)
    if p.size != 12 or not np.any(p != 0.0):
        raise ConversionError("P is zero: no rectified projection matrix (camera not calibrated?)")
    try:
        P = check_projection(p, f"P of the {side} camera")
    except VtrError as exc:
        raise ConversionError(str(exc)) from None
    return StereoInfo(P, (width, height))


def pose_covariance(T: np.ndarray, cov_xi: np.ndarray) -> np.ndarray:
    """A covariance of ξ = (ρ, φ) in ``T·exp(ξ)`` (camera frame) as ROS wants it: position and rotation
    perturbations in the parent frame, p' = p + R ρ, R' = exp(R φ) R, i.e. J = diag(R, R)."""
    J = np.zeros((6, 6))
    J[:3, :3] = J[3:, 3:] = T[:3, :3]
    C = J @ cov_xi @ J.T
    return 0.5 * (C + C.T)


@dataclass
class _Frame:
    stamp_ns: int
    left: np.ndarray
    right: np.ndarray
    frame_id: str
    received: float  # time.monotonic() when the pair was complete


class VtrLocalizerNode(LightfastNode[VtrLocalizerConfig]):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, VtrLocalizerConfig, status_topic=VTR_STATUS_TOPIC, **kwargs)
        cfg = self.params.config
        self.config = cfg
        if not cfg.map_path:
            raise ConfigError("parameter map_path is required (the teach map directory)")
        self.map_path = Path(cfg.map_path).expanduser()
        self.teach: TeachPipeline | None = None
        self.repeat: RepeatPipeline | None = None
        self.finished: TeachMap | None = None  # the map a finished teach wrote
        self._map_error: str | None = None
        self._map_attempt: float | None = None
        warm_up()  # the jitted RANSAC scoring: compiled (or loaded) now, not on the first stereo pair
        if cfg.mode == "teach":
            self._check_teach_target(cfg)
            self.teach = TeachPipeline(self.map_path, cfg.teach, stereo=cfg.stereo,
                                       overwrite=cfg.overwrite_map)

        self._lock = threading.Lock()  # guards everything the input callbacks share with the worker
        self._pairs: ExactTimePairs[tuple[np.ndarray, str], np.ndarray] = ExactTimePairs(MAX_UNPAIRED)
        self._frames: deque[_Frame] = deque()
        self._info: dict[str, StereoInfo] = {}
        self._T_odom_cam = np.eye(4)
        self._last_stamp_ns: int | None = None
        self._guard = StampGuard(cfg)  # stamps of the stereo pairs (worker only)
        self.stats |= {"frames_in": 0, "frames_done": 0, "dropped_behind": 0, "dropped_unpaired": 0,
                      "ignored": 0, "time_jumps": 0}
        self.last_status = (Level.OK, "waiting for stereo pairs")

        inputs = MutuallyExclusiveCallbackGroup()
        work = MutuallyExclusiveCallbackGroup()
        self.localization_pub = self.create_publisher(PoseWithCovarianceStamped, VTR_LOCALIZATION_TOPIC, OUTPUT_QOS)
        self.odom_pub = self.create_publisher(Odometry, VTR_ODOMETRY_TOPIC, OUTPUT_QOS)
        self.image_pubs = {"fv": self.create_publisher(Image, VTR_FV_TOPIC, OUTPUT_QOS),
                           "fr": self.create_publisher(Image, VTR_FR_TOPIC, OUTPUT_QOS)}
        self.tf = TransformBroadcaster(self) if cfg.publish_tf else None
        sensor = sensor_qos(cfg)
        for side, (image_topic, info_topic) in _SIDES.items():
            self.create_subscription(Image, image_topic, functools.partial(self._on_image, side=side), sensor,
                                     callback_group=inputs)
            self.create_subscription(CameraInfo, info_topic, functools.partial(self._on_info, side=side), sensor,
                                     callback_group=inputs)
        self._clock_jumps = ClockJumpLatch(self, cfg.time_jump_back_s, wake=lambda: self.work_trigger.trigger())
        self.work_trigger = self.create_guard_condition(self._work, callback_group=work)
        self.finish_service = self.create_service(Trigger, VTR_FINISH_TEACH_SERVICE, self._on_finish,
                                                  callback_group=work)
        self.status_timer = self.create_timer(STATUS_PERIOD_S, self._heartbeat, callback_group=work)
        if cfg.mode == "teach":
            self.get_logger().info(f"teach: building a map at {self.map_path} ({', '.join(cfg.teach.sources)}, "
                                   f"{cfg.stereo.feature}); finish it with {VTR_FINISH_TEACH_SERVICE}")
        else:
            self.get_logger().info(f"repeat ({cfg.repeat.mode}) against the map at {self.map_path}")
            self._load_map()
        self.announce_ready()

    # ---------------------------------------------------------------------------------------------- helpers

    @staticmethod
    def _check_teach_target(cfg: VtrLocalizerConfig) -> None:
        """Never replace something that is not a teach map (``overwrite_map`` replaces maps only)."""
        path = Path(cfg.map_path).expanduser()
        if not path.exists() or MapStore.exists(path):
            return  # a previous map: TeachPipeline refuses it unless overwrite_map
        if not (path.is_dir() and not any(path.iterdir())):
            raise ConfigError(f"map_path {path} exists and is not a teach map: refusing to replace it")
        if not cfg.overwrite_map:
            raise ConfigError(f"map_path {path} exists (an empty directory): set overwrite_map to teach into it")

    def _problem(self, key: str, text: str, level: Level = Level.WARN, stamp_ns: int | None = None, *,
                 count: bool = True) -> None:
        self.problem(key, text, level, stamp_ns=stamp_ns, values={"stamp_ns": stamp_ns, "problem": key}, count=count)

    def status_values(self) -> dict[str, Any]:
        cfg = self.config
        common: dict[str, Any] = {"mode": cfg.mode, "map_path": str(self.map_path)}
        if cfg.mode == "repeat":
            common |= {"repeat_mode": cfg.repeat.mode, "map_loaded": self.repeat is not None,
                       "map_error": self._map_error or ""}
        else:
            teach = self.teach
            common |= {"teach_finished": self.finished is not None,
                       "keyframes": len(self.finished) if self.finished is not None else
                       (teach.num_keyframes if teach is not None else 0)}
        return {**common, **self.stats, "queued": len(self._frames)}

    def _heartbeat(self) -> None:
        if self.config.mode == "repeat" and self.repeat is None:
            self._load_map()
        self.publish_status(*self.last_status)
        if self._frames:
            self.work_trigger.trigger()  # pairs that waited for camera_info in vain are reported now

    def _load_map(self) -> bool:
        """Load the map of a repeat (retried every ``map_retry_s`` while it fails); True when there is one."""
        if self.repeat is not None:
            return True
        now = time.monotonic()
        if self._map_attempt is not None and now - self._map_attempt < self.config.map_retry_s:
            return False
        self._map_attempt = now
        try:
            teach_map = MapStore.load(self.map_path)
            self.repeat = RepeatPipeline(teach_map, self.config.repeat)
        except (MapError, VtrError, ConfigError, OSError) as exc:
            self._map_error = f"no usable teach map: {exc}"
            self._problem(f"map:{type(exc).__name__}", f"{self._map_error} (retrying every "
                          f"{self.config.map_retry_s:g} s)", Level.ERROR, count=False)
            return False
        self._map_error = None
        m = self.repeat.map
        text = (f"map loaded: {len(m)} keyframes, {m.length_m:.2f} m, sources {','.join(m.sources)}, "
                f"{m.feature}, {m.image_size[0]}x{m.image_size[1]}")
        self.get_logger().info(text)
        self.publish_status(Level.OK, text)
        return True

    # ---------------------------------------------------------------------------------------------- inputs

    def _on_image(self, msg: Image, side: str) -> None:
        topic = _SIDES[side][0]
        try:
            stamp, rgb = stamp_to_ns(msg.header.stamp), image_to_rgb(msg)  # colour: the colour-constant images
        except ConversionError as exc:
            self._problem(f"{side}_image", f"dropped {side} image on {topic}: {exc}")
            return
        with self._lock:
            if side == "left":
                pair = self._pairs.add_first(stamp, (rgb, msg.header.frame_id))
            else:
                pair = self._pairs.add_second(stamp, rgb)
            self.stats["dropped_unpaired"] = self._pairs.dropped
            if pair is None:
                return
            (left, frame_id), right = pair
            self.stats["frames_in"] += 1
            self._frames.append(_Frame(stamp, left, right, frame_id or STEREO_LEFT_FRAME, time.monotonic()))
            while len(self._frames) > self.params.config.max_queued_frames:
                self._frames.popleft()
                self.stats["dropped_behind"] += 1
        self.work_trigger.trigger()

    def _on_info(self, msg: CameraInfo, side: str) -> None:
        try:
            info = stereo_info(msg, side)
        except ConversionError as exc:
            self._problem(f"{side}_info", f"ignored {_SIDES[side][1]}: {exc}")
            return
        with self._lock:
            self._info[side] = info
            waiting = bool(self._frames)
        if waiting:
            self.work_trigger.trigger()

    # ---------------------------------------------------------------------------------------------- worker

    def _stamp_ok(self, f: _Frame) -> bool:
        """Refuse a pair stamped ahead of the clock or out of order; when the stamps went back, a repeat starts
        over (a teach refuses pairs from before its newest: it would teach the route twice)."""
        now = self.get_clock().now().nanoseconds
        verdict = self._guard.check(f.stamp_ns, now)
        if verdict is StampVerdict.JUMPED_BACK and self.teach is None:
            assert self._guard.last_ns is not None  # JUMPED_BACK: there is a previous stamp
            self._time_jumped(f"stereo pair stamps went back {(self._guard.last_ns - f.stamp_ns) * 1e-9:.3f} s")
        elif verdict is StampVerdict.JUMPED_BACK:
            self._problem("stamp", f"stereo pair {f.stamp_ns} ignored: the stamps went back during a teach (a bag "
                          f"played again?); finish the teach with {VTR_FINISH_TEACH_SERVICE} or restart the node",
                          stamp_ns=f.stamp_ns)
            return False
        elif verdict is not StampVerdict.OK:
            self._problem("stamp", f"stereo pair {f.stamp_ns}: {self._guard.describe(verdict, f.stamp_ns, now)}",
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
            self.repeat = RepeatPipeline(self.repeat.map, self.config.repeat)
        self.get_logger().warning(f"{why} (a bag played again, or looped?): the repeat starts over with a search of "
                                  "the whole map, the VO chain at its origin")

    def _work(self) -> None:
        clock_jump = self._clock_jumps.take()
        if clock_jump is not None and self.teach is None and self._guard.clock_jumped_back(clock_jump):
            self._time_jumped(f"ROS time jumped back to {clock_jump * 1e-9:.3f} s")
        with self._lock:
            self.config = self.params.config
            frame = self._frames.popleft() if self._frames else None
            if frame is not None and self._awaiting_info(frame):
                self._frames.appendleft(frame)  # the camera_info of a pair's stamp often comes just after it
                return  # _on_info or the heartbeat wakes the worker
            more = bool(self._frames)
        if frame is not None:
            self._process_safely(frame)
        if more:
            self.work_trigger.trigger()  # one pair per call: the other callbacks get their turn in between

    def _awaiting_info(self, frame: _Frame) -> bool:
        """Whether a pair waits for the first camera_info of either side (for up to CAMERA_INFO_WAIT_S)."""
        return len(self._info) < 2 and time.monotonic() - frame.received < CAMERA_INFO_WAIT_S

    def _process_safely(self, frame: _Frame) -> None:
        try:
            self._process(frame)
        except (LightfastError, cv2.error) as exc:  # bad input the core refused (an InputError), or a failed step
            level = Level.WARN if isinstance(exc, InputError) else Level.ERROR
            self._problem(f"step:{type(exc).__name__}", f"stereo pair {frame.stamp_ns} not processed: {exc}", level,
                          frame.stamp_ns)

    def _check_frame(self, f: _Frame) -> tuple[np.ndarray, np.ndarray] | None:
        """The projection matrices for a pair, or None after reporting why the pair cannot be used."""
        stamp = f.stamp_ns
        with self._lock:
            left_info, right_info = self._info.get("left"), self._info.get("right")
        missing = [_SIDES[s][1] for s, i in (("left", left_info), ("right", right_info)) if i is None]
        if missing:
            self._problem("no_camera_info", f"stereo pair {stamp} skipped: no usable camera_info on "
                          f"{' and '.join(missing)} yet", stamp_ns=stamp)
            return None
        assert left_info is not None and right_info is not None
        (hl, wl), (hr, wr) = f.left.shape[:2], f.right.shape[:2]
        if (hl, wl) != (hr, wr):
            self._problem("size", f"stereo pair {stamp} skipped: left image {wl}x{hl} and right image {wr}x{hr} "
                          "differ in size", stamp_ns=stamp)
            return None
        if min(hl, wl) < MIN_IMAGE_PX:
            self._problem("size", f"stereo pair {stamp} skipped: images of {wl}x{hl} are too small (at least "
                          f"{MIN_IMAGE_PX}x{MIN_IMAGE_PX})", stamp_ns=stamp)
            return None
        for side, info in (("left", left_info), ("right", right_info)):
            if info.size != (wl, hl):
                self._problem("info_size", f"stereo pair {stamp} skipped: images are {wl}x{hl} but the {side} "
                              f"camera_info says {info.size[0]}x{info.size[1]}", stamp_ns=stamp)
                return None
        try:
            Pl, Pr = check_stereo_pair(left_info.P, right_info.P)
        except VtrError as exc:
            self._problem("stereo_info", f"stereo pair {stamp} skipped: {exc}", stamp_ns=stamp)
            return None
        means = (float(f.left.mean()), float(f.right.mean()))
        if min(means) < self.config.black_level:
            which = " and ".join(s for s, m in zip(("left", "right"), means, strict=True)
                                 if m < self.config.black_level)
            self._problem("black", f"stereo pair {stamp} skipped: black {which} image (mean "
                          f"{min(means):.1f} < black_level {self.config.black_level:g})", stamp_ns=stamp)
            return None
        return Pl, Pr

    def _process(self, f: _Frame) -> None:
        if self.config.mode == "teach" and (self.teach is None or self.finished is not None):
            self.stats["ignored"] += 1
            text = ("teach finished: map written to " + str(self.map_path)) if self.finished is not None else \
                "teach aborted"
            self.problems.report("finished", f"stereo pair {f.stamp_ns} ignored: {text}", Level.OK)
            self.publish_status(Level.OK, text, {"stamp_ns": f.stamp_ns})
            return
        if self.config.mode == "repeat" and not self._load_map():
            self._problem("no_map", f"stereo pair {f.stamp_ns} skipped: {self._map_error}", Level.ERROR, f.stamp_ns,
                          count=False)
            return
        P = self._check_frame(f)
        if P is None or not self._stamp_ok(f):
            return
        if self.teach is not None:
            self._teach_step(f, *P)
        else:
            self._repeat_step(f, *P)

    # ---------------------------------------------------------------------------------------------- teach

    def _teach_step(self, f: _Frame, Pl: np.ndarray, Pr: np.ndarray) -> None:
        teach = self.teach
        assert teach is not None
        t0 = time.perf_counter()
        features = teach.front.process(f.left, f.right, Pl, Pr)
        t1 = time.perf_counter()
        r: TeachResult = teach.step_features(f.stamp_ns, features, Pl, Pr, (f.left.shape[1], f.left.shape[0]))
        t2 = time.perf_counter()
        # after a step the VO's constant-velocity prediction is the motion it chained (estimate or prediction)
        self._publish_odometry(f, teach.vo.prediction)
        self._publish_images(f, teach.front.color)
        self.stats["frames_done"] += 1
        values: dict[str, Any] = {
            "stamp_ns": f.stamp_ns,
            "keyframe_id": r.keyframe_index,
            "new_keyframe": r.new_keyframe,
            "distance_m": r.distance_m,
            "vo_success": r.vo_success,
            "vo_inliers": r.vo_inliers,
            "vo_failures": teach.vo_failures,
            **{f"landmarks_{s}": n for s, n in r.landmarks.items()},
            "front_end_ms": 1e3 * (t1 - t0),
            "teach_ms": 1e3 * (t2 - t1),
            "total_ms": 1e3 * (time.perf_counter() - t0),
            "pipeline_ms": 1e3 * (time.monotonic() - f.received),
        }
        if r.vo_success:
            level, text = Level.OK, (f"keyframe {r.keyframe_index} added" if r.new_keyframe else
                                     f"taught ({r.distance_m:.2f} m from keyframe 0)")
        else:
            level, text = Level.WARN, "VO failed: the constant-velocity prediction is chained"
        self.publish_status(level, text, values, stamp_ns=f.stamp_ns)

    def _drain(self) -> None:
        """Process every queued pair now (before the teach is finished)."""
        while True:
            with self._lock:
                frame = self._frames.popleft() if self._frames else None
            if frame is None:
                return
            self._process_safely(frame)

    def _on_finish(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        del request
        if self.config.mode != "teach":
            response.success, response.message = False, "not teaching: this node runs in repeat mode"
            return response
        if self.finished is not None:
            m = self.finished
            response.success = False
            response.message = (f"the teach has already finished: {len(m)} keyframes, {m.length_m:.2f} m path "
                                f"written to {self.map_path}")
            return response
        teach = self.teach
        if teach is None:
            response.success, response.message = False, "the teach was aborted"
            return response
        self._drain()
        if teach.num_keyframes == 0:
            response.success = False
            response.message = f"nothing taught yet (no usable stereo pair): no map written to {self.map_path}"
            self.publish_status(Level.WARN, response.message)
            return response
        try:
            m = teach.finish()
        except (VtrError, OSError) as exc:
            self.teach = None
            response.success = False
            response.message = (f"finishing the teach failed: {exc}; nothing was written to {self.map_path} "
                                "(a previous map there is unchanged)")
            self._problem("finish", response.message, Level.ERROR, count=False)
            return response
        self.finished = m
        response.success = True
        response.message = (f"map written to {self.map_path}: {len(m)} keyframes, {m.length_m:.2f} m path, "
                            f"{teach.frames} stereo pairs, {teach.vo_failures} VO failures")
        self.get_logger().info(response.message)
        self.publish_status(Level.OK, response.message, {"path_length_m": m.length_m})
        return response

    # ---------------------------------------------------------------------------------------------- repeat

    def _repeat_step(self, f: _Frame, Pl: np.ndarray, Pr: np.ndarray) -> None:
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
        r: RepeatResult = rp.step(f.stamp_ns, f.left, f.right, Pl, Pr)
        total_ms = 1e3 * (time.perf_counter() - t0)
        self._publish_odometry(f, r.T_prev_cur)
        if r.T_kf_cam is not None:
            self._publish_localization(f, r)
        self._publish_images(f, rp.front.color)
        self.stats["frames_done"] += 1
        values: dict[str, Any] = {
            "stamp_ns": f.stamp_ns,
            "localized": r.localized,
            "keyframe_id": r.keyframe_index,
            "inliers": r.inliers,
            **{f"inliers_{s}": n for s, n in r.inliers_per_source.items()},
            **{f"matches_{s}": n for s, n in r.matches_per_source.items()},
            "distance_on_vo_m": r.distance_on_vo_m,
            "failure": r.failure,
            "relocalized": r.relocalized,
            "searched_map": r.searched_map,
            "failures": rp.failures,
            "vo_success": r.vo_success,
            "vo_inliers": r.vo_inliers,
            "distance_along_path_m": r.distance_along_path_m,
            **{f"{k}_ms": 1e3 * v for k, v in r.timing_s.items()},
            "total_ms": total_ms,
            "pipeline_ms": 1e3 * (time.monotonic() - f.received),
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
        self.publish_status(level, text, values, stamp_ns=f.stamp_ns)

    def _publish_localization(self, f: _Frame, r: RepeatResult) -> None:
        T = r.T_kf_cam
        assert T is not None
        if r.localized and r.covariance is not None and np.all(np.isfinite(r.covariance)):
            cov = pose_covariance(T, r.covariance)
        else:  # carried by VO alone: the assumed drift since the last localization
            d = r.distance_on_vo_m
            var_p = (self.config.vo_drift_m_per_m * d) ** 2 + 1e-6
            var_r = math.radians(self.config.vo_drift_deg_per_m * d) ** 2 + 1e-8
            cov = np.diag([var_p] * 3 + [var_r] * 3)
        keyframe_frame = f"{self.config.keyframe_frame_prefix}{r.keyframe_index}"
        msg = PoseWithCovarianceStamped()
        msg.header = make_header(f.stamp_ns, keyframe_frame)
        msg.pose.pose = matrix_to_pose(T)
        msg.pose.covariance = [float(x) for x in cov.reshape(-1)]
        self.localization_pub.publish(msg)
        if self.tf is not None:  # the keyframe as a child of the camera: the camera has one parent, odom_frame
            self.tf.send(transform_stamped(inverse(T), stamp_ns=f.stamp_ns, parent_frame=f.frame_id,
                                           child_frame=keyframe_frame))

    # ---------------------------------------------------------------------------------------------- both

    def _publish_odometry(self, f: _Frame, T_prev_cur: np.ndarray) -> None:
        self._T_odom_cam = self._T_odom_cam @ T_prev_cur
        dt = 0.0 if self._last_stamp_ns is None else 1e-9 * (f.stamp_ns - self._last_stamp_ns)
        self._last_stamp_ns = f.stamp_ns
        linear = angular = np.zeros(3)
        if dt > 0.0:
            R, t = T_prev_cur[:3, :3], T_prev_cur[:3, 3]
            linear = R.T @ t / dt  # velocity of the current camera, in its own frame
            angular = np.asarray(so3_log(R), dtype=np.float64) / dt
        self.odom_pub.publish(matrix_to_odometry(self._T_odom_cam, stamp_ns=f.stamp_ns,
                                                 frame_id=self.config.odom_frame, child_frame_id=f.frame_id,
                                                 twist_linear=linear, twist_angular=angular))
        if self.tf is not None:
            self.tf.send(transform_stamped(self._T_odom_cam, stamp_ns=f.stamp_ns,
                                           parent_frame=self.config.odom_frame, child_frame=f.frame_id))

    def _publish_images(self, f: _Frame, color: ColorConstantConfig) -> None:
        if not self.config.publish_images:
            return
        wanted = tuple(s for s, pub in self.image_pubs.items() if pub.get_subscription_count() > 0)
        if not wanted:
            return
        for s, src in image_sources(f.left, color, wanted).items():
            self.image_pubs[s].publish(numpy_to_image(src.image, "mono8", stamp_ns=f.stamp_ns, frame_id=f.frame_id))

    # ---------------------------------------------------------------------------------------------- shutdown

    def destroy_node(self) -> None:
        """An unfinished teach is aborted: its staging directory goes, a previous map at map_path stays."""
        teach, self.teach = self.teach, None
        if teach is not None and self.finished is None:
            try:
                teach.abort()
            except (OSError, LightfastError) as exc:  # pragma: no cover - the staging directory is hidden anyway
                self.get_logger().warning(f"aborting the teach: {exc}")
            else:
                self.get_logger().warning(
                    f"teach not finished ({teach.num_keyframes} keyframes discarded): nothing written to "
                    f"{self.map_path}; a previous map there is unchanged")
        if self.repeat is not None:
            self.repeat.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(VtrLocalizerNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
