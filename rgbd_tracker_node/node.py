"""``rgbd_tracker_node``: two-step direct RGB-D tracking (paper §III-D, Eq. 7) — frame-to-frame against the previous
frame, then frame-to-model against the relit reference of ``daylight_relight_node``.

Subscribes ``/camera/color/image_raw`` (rgb8, bgr8, rgba8, bgra8 or mono8), ``/camera/depth/image_raw`` (32FC1
metres or 16UC1 millimetres, registered to the colour camera) and ``/camera/color/camera_info``, best effort unless
``sensor_reliability`` says otherwise; colour and depth are paired by exact stamp. Per
frame the f2f step gives T≈, published as ``/tracker/coarse_pose`` (PoseStamped in ``map``, the image's stamp).
The reference colour + depth rendered there (``/relight/reference/color`` rgb8, ``/relight/reference/depth``
32FC1, paired by stamp) refine it (f2m). A frame whose reference has not come within ``reference_timeout_s`` (wall
time), or that falls out of the ``max_pending`` window, or whose successor's reference comes first, is finished
with its f2f pose. Each finished frame is published on ``/tracker/pose`` (PoseStamped, ``map``),
``/tracker/odometry`` (nav_msgs/Odometry, child frame = the image's optical frame) and ``/tracker/status``
(DiagnosticArray: source f2m/f2f, reason, mode, f2f/f2m ms, inlier ratios, latency), and on ``/tf`` as
``map_frame`` → ``camera_frame`` (``publish_tf``). Tracking starts at the ``initial_pose`` parameter (logged at the
first frame); RViz's ``/initialpose`` (PoseWithCovarianceStamped) or a PoseStamped on ``/tracker/reset`` restarts it
at that pose. Time going back (``time_jump_back_s``: /clock, or the frames' stamps; a bag played again) restarts
tracking at ``initial_pose``; a frame stamped more than ``max_stamp_ahead_s`` ahead of the node's clock is refused.

Threading: the executor's callbacks only convert and buffer, then wake one of two worker threads. The f2f worker
tracks the queued frames one at a time, applies parameter changes, resets and camera changes, and finishes frames
whose reference is overdue (it also wakes on its own every ``reference_timeout_s / 4``, at most 0.1 s). The f2m
worker refines the frame of the newest reference that came (when it falls behind, older references are dropped
and their frames keep the f2f pose: on an overloaded machine a share of the frames is refined, without a backlog).
The tracker's state is touched under one lock and the f2m alignment runs outside it, so it overlaps the f2f
alignment of the next frame (the numba kernels release the GIL).
Plain threads rather than callback groups on rclpy's MultiThreadedExecutor: there, guard-condition triggers raised
while the worker's group was busy got lost (a 20-frame demo lost 7 frames).
"""
from __future__ import annotations

import sys
import threading
import time
from collections import OrderedDict, deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, Image

from lightfast.camera import PinholeCamera
from lightfast.ros.clock import ClockJumpLatch
from lightfast.ros.convert import (
    CameraInfoReader,
    image_to_numpy,
    image_to_rgb,
    matrix_to_odometry,
    matrix_to_pose_stamped,
    pose_stamped_to_matrix,
    pose_with_covariance_to_matrix,
    stamp_to_ns,
)
from lightfast.ros.diagnostics import Level
from lightfast.ros.errors import ConversionError
from lightfast.ros.node import LightfastNode
from lightfast.ros.qos import OUTPUT_QOS, sensor_qos
from lightfast.ros.runtime import run_node
from lightfast.ros.sync import ExactTimePairs
from lightfast.ros.tf import TransformBroadcaster, transform_stamped
from lightfast.ros.worker import StepWorker
from lightfast.stamps import StampGuard, StampVerdict
from lightfast.topics import (
    COARSE_POSE_TOPIC,
    COLOR_INFO_TOPIC,
    COLOR_TOPIC,
    DEPTH_TOPIC,
    INITIAL_POSE_TOPIC,
    OPTICAL_FRAME,
    REFERENCE_COLOR_TOPIC,
    REFERENCE_DEPTH_TOPIC,
    TRACKER_ODOMETRY_TOPIC,
    TRACKER_POSE_TOPIC,
    TRACKER_RESET_TOPIC,
    TRACKER_STATUS_TOPIC,
)
from lightfast.tracking.errors import TrackingError
from lightfast.tracking.pipeline import F2FJob, RGBDTracker, TrackerConfig, TrackResult
from lightfast.tracking.rgbd_odometry import warm_up

NODE_NAME = "rgbd_tracker_node"
#: Unpaired colour / depth images (and reference colour / depth) kept per side.
MAX_UNPAIRED = 10
#: Paired live frames waiting for the tracker; when it falls behind the oldest are dropped.
MAX_QUEUED = 4
#: Options that change how frames are prepared: a change restarts tracking at the last pose.
_PREPARATION_FIELDS = ("pyramid_levels", "resolution_scale", "min_depth_m", "max_depth_m", "depth_discontinuity_m")
_MM_TO_M = np.float32(0.001)


def depth_to_metres(msg: Image) -> np.ndarray:
    """A depth image as float32 metres: 32FC1 as it is (NaN/0 invalid), 16UC1 millimetres scaled (0 stays invalid)."""
    if msg.encoding == "32FC1":
        return image_to_numpy(msg)
    if msg.encoding == "16UC1":
        return image_to_numpy(msg).astype(np.float32) * _MM_TO_M
    raise ConversionError(f"depth image encoding {msg.encoding!r} is not supported (need 32FC1 m or 16UC1 mm)")


def color_to_numpy(msg: Image) -> np.ndarray:
    """RGB (rgb8, bgr8, rgba8, bgra8) or grey (mono8): the tracker's photometric term uses intensity only."""
    return image_to_rgb(msg, allow_mono=True)


@dataclass
class _Frame:
    stamp_ns: int
    rgb: np.ndarray
    depth_m: np.ndarray
    frame_id: str
    received: float  # time.monotonic() when the pair was complete
    arrival_lag_ns: int  # node clock minus the image stamp when the pair was complete (>= 0)


@dataclass
class _Pending:
    frame_id: str
    received: float
    arrival_lag_ns: int
    coarse_at: float  # time.monotonic() when T≈ was published: the reference deadline counts from here


class RGBDTrackerNode(LightfastNode[TrackerConfig]):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, TrackerConfig, status_topic=TRACKER_STATUS_TOPIC, **kwargs)
        cfg = self.params.config
        self.config = cfg  # the configuration in use: the f2f worker applies a change between frames
        warm_s = warm_up(cfg)
        self.tracker: RGBDTracker | None = None
        self._start_pose = cfg.T_map_cam_initial  # where the tracker (re)starts when it is created
        self._last_pose: np.ndarray | None = None  # newest T≈, to restart from after a camera/config change
        self._pending: OrderedDict[int, _Pending] = OrderedDict()

        self._lock = threading.Lock()  # guards everything the input callbacks share with the workers
        self._state = threading.RLock()  # guards the tracker and the pending frames (f2f and f2m workers)
        self._live: ExactTimePairs[tuple[np.ndarray, str], np.ndarray] = ExactTimePairs(MAX_UNPAIRED)
        self._refs: ExactTimePairs[np.ndarray, np.ndarray] = ExactTimePairs(MAX_UNPAIRED)
        self._frames: deque[_Frame] = deque()
        self._ref_queue: deque[tuple[int, np.ndarray, np.ndarray]] = deque()
        self._camera: PinholeCamera | None = None
        self._read_camera_info = CameraInfoReader()
        self._reset: tuple[np.ndarray, int | None, str] | None = None
        self._guard = StampGuard(cfg)  # stamps of the live frames (f2f worker only)
        self._announce_start = True  # log where tracking starts at the next first frame
        self._new_config: TrackerConfig | None = None
        self.params.on_change = self._on_config
        self.stats |= {"frames_in": 0, "references_in": 0, "frames_tracked": 0, "f2m": 0, "f2f": 0,
                       "dropped_behind": 0, "dropped_unpaired": 0, "late_references": 0, "superseded_references": 0,
                       "time_jumps": 0}

        self.coarse_pub = self.create_publisher(PoseStamped, COARSE_POSE_TOPIC, OUTPUT_QOS)
        self.pose_pub = self.create_publisher(PoseStamped, TRACKER_POSE_TOPIC, OUTPUT_QOS)
        self.odom_pub = self.create_publisher(Odometry, TRACKER_ODOMETRY_TOPIC, OUTPUT_QOS)
        self.tf = TransformBroadcaster(self) if cfg.publish_tf else None
        sensor = sensor_qos(cfg)
        sub = self.create_subscription
        sub(Image, COLOR_TOPIC, self._on_color, sensor)
        sub(Image, DEPTH_TOPIC, self._on_depth, sensor)
        sub(CameraInfo, COLOR_INFO_TOPIC, self._on_camera_info, sensor)
        sub(Image, REFERENCE_COLOR_TOPIC, self._on_ref_color, OUTPUT_QOS)
        sub(Image, REFERENCE_DEPTH_TOPIC, self._on_ref_depth, OUTPUT_QOS)
        sub(PoseStamped, TRACKER_RESET_TOPIC, self._on_reset, OUTPUT_QOS)
        sub(PoseWithCovarianceStamped, INITIAL_POSE_TOPIC, self._on_initial_pose, OUTPUT_QOS)
        self._clock_jumps = ClockJumpLatch(self, cfg.time_jump_back_s, wake=lambda: self._f2f_worker.wake())
        self._f2f_worker = StepWorker("tracker-f2f", self._work, self._on_step_error,
                                      period_s=lambda: self._deadline_period(self.config))
        self._f2m_worker = StepWorker("tracker-f2m", self._refine_work, self._on_step_error)
        self.get_logger().info(f"mode {cfg.mode}, reference timeout {cfg.reference_timeout_s} s, start pose "
                               f"{list(cfg.initial_pose)} in {cfg.map_frame}, sensor QoS {cfg.sensor_reliability}; "
                               f"kernels warmed up in {warm_s:.2f} s")
        self.announce_ready()

    # ---------------------------------------------------------------------------------------------- helpers

    @staticmethod
    def _deadline_period(cfg: TrackerConfig) -> float:
        return min(0.1, max(0.01, cfg.reference_timeout_s / 4))

    def _problem(self, key: str, text: str, level: Level = Level.WARN, stamp_ns: int | None = None) -> None:
        self.problem(key, text, level, stamp_ns=stamp_ns, values={"stamp_ns": stamp_ns, "source": "", "reason": text})

    def status_values(self) -> dict[str, Any]:
        return {"mode": self.config.mode, "pending": len(self._pending), **self.stats}

    # ---------------------------------------------------------------------------------------------- inputs

    def _on_color(self, msg: Image) -> None:
        try:
            stamp, rgb = stamp_to_ns(msg.header.stamp), color_to_numpy(msg)
        except ConversionError as exc:
            self._problem("color", f"dropped colour image on {COLOR_TOPIC}: {exc}")
            return
        with self._lock:
            self.stats["frames_in"] += 1
            self._enqueue_frame(stamp, self._live.add_first(stamp, (rgb, msg.header.frame_id)))

    def _on_depth(self, msg: Image) -> None:
        try:
            stamp, depth = stamp_to_ns(msg.header.stamp), depth_to_metres(msg)
        except ConversionError as exc:
            self._problem("depth", f"dropped depth image on {DEPTH_TOPIC}: {exc}")
            return
        with self._lock:
            self._enqueue_frame(stamp, self._live.add_second(stamp, depth))

    def _enqueue_frame(self, stamp: int, pair: tuple[tuple[np.ndarray, str], np.ndarray] | None) -> None:
        self.stats["dropped_unpaired"] = self._live.dropped
        if pair is None:
            return
        (rgb, frame_id), depth = pair
        lag_ns = max(0, self.get_clock().now().nanoseconds - stamp)
        self._frames.append(_Frame(stamp, rgb, depth, frame_id, time.monotonic(), lag_ns))
        while len(self._frames) > MAX_QUEUED:
            self._frames.popleft()
            self.stats["dropped_behind"] += 1
        self._f2f_worker.wake()

    def _on_ref_color(self, msg: Image) -> None:
        try:
            stamp, rgb = stamp_to_ns(msg.header.stamp), color_to_numpy(msg)
        except ConversionError as exc:
            self._problem("ref_color", f"dropped reference colour on {REFERENCE_COLOR_TOPIC}: {exc}")
            return
        with self._lock:
            self._enqueue_ref(stamp, self._refs.add_first(stamp, rgb))

    def _on_ref_depth(self, msg: Image) -> None:
        try:
            stamp, depth = stamp_to_ns(msg.header.stamp), depth_to_metres(msg)
        except ConversionError as exc:
            self._problem("ref_depth", f"dropped reference depth on {REFERENCE_DEPTH_TOPIC}: {exc}")
            return
        with self._lock:
            self._enqueue_ref(stamp, self._refs.add_second(stamp, depth))

    def _enqueue_ref(self, stamp: int, pair: tuple[np.ndarray, np.ndarray] | None) -> None:
        if pair is not None:
            self.stats["references_in"] += 1
            self._ref_queue.append((stamp, *pair))
            self._f2m_worker.wake()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        try:
            camera = self._read_camera_info(msg)
        except ConversionError as exc:
            self._problem("camera_info", f"ignored {COLOR_INFO_TOPIC}: {exc}")
            return
        with self._lock:
            self._camera = camera

    def _on_reset(self, msg: PoseStamped) -> None:
        self._take_reset(msg, pose_stamped_to_matrix, TRACKER_RESET_TOPIC)

    def _on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        self._take_reset(msg, pose_with_covariance_to_matrix, INITIAL_POSE_TOPIC)

    def _take_reset(self, msg: Any, read: Any, topic: str) -> None:
        try:
            T, stamp, frame_id = read(msg)
            if frame_id not in ("", self.config.map_frame):
                raise ConversionError(f"frame_id {frame_id!r} is not {self.config.map_frame!r}")
        except ConversionError as exc:
            self._problem("reset", f"ignored reset on {topic}: {exc}")
            return
        with self._lock:
            self._reset = (T, stamp or None, topic)
        self._f2f_worker.wake()

    def _on_config(self, cfg: TrackerConfig) -> None:
        with self._lock:
            self._new_config = cfg
        self._f2f_worker.wake()

    # ---------------------------------------------------------------------------------------------- workers

    def _on_step_error(self, exc: Exception) -> None:
        self._problem("internal", f"{threading.current_thread().name} step failed: {exc!r}", Level.ERROR)

    def destroy_node(self) -> None:
        self._f2f_worker.stop()
        self._f2m_worker.stop()
        super().destroy_node()

    def _work(self) -> bool:
        """One f2f step: pending changes, overdue references, at most one new frame. Returns whether frames wait."""
        with self._lock:
            new_config, self._new_config = self._new_config, None
            reset, self._reset = self._reset, None
            clock_jump = self._clock_jumps.take()
            frame = self._frames.popleft() if self._frames else None
            camera = self._camera
            more = bool(self._frames)
        with self._state:
            if new_config is not None:
                self._apply_config(new_config)
            if camera is not None and self.tracker is not None and camera != self.tracker.camera:
                self._restart("camera_info changed")
            if clock_jump is not None and self._guard.clock_jumped_back(clock_jump):
                self._time_jumped(f"ROS time jumped back to {clock_jump * 1e-9:.3f} s")
            if reset is not None:
                self._apply_reset(*reset)
            self._finish_overdue()
            if frame is not None and not self._stamp_ok(frame.stamp_ns):
                frame = None
            job = self._start_track(frame, camera) if frame is not None else None
            if job is not None:
                self._guard.accept(job.stamp_ns)
        if job is not None:
            job.run()  # the alignment, outside the lock: f2m jobs start and finish meanwhile
            assert frame is not None  # a job is started for a frame
            with self._state:
                self._finish_track(job, frame)
        return more

    def _refine_work(self) -> bool:
        """One f2m step: the newest received reference. Older waiting ones are dropped: refining the newest frame
        finishes the older ones with their f2f pose anyway, and when f2m falls behind, working through a backlog
        would only refine frames whose poses are already late. Returns whether more wait."""
        with self._lock:
            if not self._ref_queue:
                return False
            stamp, rgb, depth = self._ref_queue.pop()
            self.stats["superseded_references"] += len(self._ref_queue)
            self._ref_queue.clear()
        self._refine(stamp, rgb, depth)
        return False

    def _apply_config(self, cfg: TrackerConfig) -> None:
        old, self.config = self.config, cfg
        if self.tracker is None:
            self._start_pose = cfg.T_map_cam_initial if old.initial_pose != cfg.initial_pose else self._start_pose
            return
        if any(getattr(old, f) != getattr(cfg, f) for f in _PREPARATION_FIELDS):
            warm_up(cfg)
            self._restart("frame preparation options changed")
        else:
            self.tracker.config = cfg

    def _restart(self, why: str) -> None:
        """Finish the waiting frames with their f2f pose and start a new tracker at the newest pose."""
        self._finish_all(f"f2f ({why})")
        self.tracker = None
        if self._last_pose is not None:
            self._start_pose = self._last_pose
        self.get_logger().info(f"tracking restarts at the last pose: {why}")

    def _stamp_ok(self, stamp: int) -> bool:
        """Check a live frame's stamp (f2f worker): refuse it, or restart tracking when time went back."""
        now = self.get_clock().now().nanoseconds
        verdict = self._guard.check(stamp, now)
        if verdict is StampVerdict.JUMPED_BACK:
            assert self._guard.last_ns is not None  # JUMPED_BACK: there is a previous stamp
            self._time_jumped(f"frame stamps went back {(self._guard.last_ns - stamp) * 1e-9:.3f} s")
        elif verdict is not StampVerdict.OK:
            self._problem("stamp", f"frame {stamp}: {self._guard.describe(verdict, stamp, now)}", stamp_ns=stamp)
            return False
        return True

    def _time_jumped(self, why: str) -> None:
        """Time went back (a bag played again or looped, a restarted simulation): the frames waiting are finished
        with their f2f pose, and tracking starts over at ``initial_pose``, as at start-up."""
        self.stats["time_jumps"] += 1
        self._finish_all("f2f (time jumped back)")
        self.tracker = None
        self._last_pose = None
        self._start_pose = self.config.T_map_cam_initial
        self._guard.reset()
        self._announce_start = True
        self.get_logger().warning(f"{why} (a bag played again, or looped?): tracking starts over at initial_pose")

    def _apply_reset(self, T: np.ndarray, stamp: int | None, topic: str) -> None:
        if self.tracker is None:
            self._start_pose = T
        else:
            self.tracker.reset(T, stamp_ns=stamp)
            dropped = [s for s in self._pending if s not in self.tracker.pending_stamps]
            for s in dropped:
                del self._pending[s]
        self._last_pose = T
        self._announce_start = False
        self.get_logger().info(f"tracking reset on {topic} to {np.round(T[:3, 3], 3).tolist()} m")
        self.publish_status(Level.OK, "tracking reset", {"stamp_ns": stamp, "source": "reset", "reason": ""})

    def _start_track(self, f: _Frame, camera: PinholeCamera | None) -> F2FJob | None:
        stamp = f.stamp_ns
        if camera is None:
            self._problem("no_camera_info", f"frame {stamp} not tracked: no camera_info on {COLOR_INFO_TOPIC} yet",
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
                self.get_logger().warning(
                    f"tracking starts at initial_pose {np.round(self._start_pose[:3, 3], 3).tolist()} m in "
                    f"{self.config.map_frame}; if the camera is elsewhere, send its pose on {INITIAL_POSE_TOPIC} "
                    f"(RViz: 2D Pose Estimate) or {TRACKER_RESET_TOPIC}")
        try:
            return self.tracker.start_coarse(stamp, f.rgb, f.depth_m)
        except TrackingError as exc:
            self._problem("track", f"frame {stamp} not tracked: {exc}", stamp_ns=stamp)
            return None

    def _finish_track(self, job: F2FJob, f: _Frame) -> None:
        stamp = f.stamp_ns
        if self.tracker is None:
            return  # only this thread restarts the tracker; kept for the type checker
        try:
            est = self.tracker.finish_coarse(job)
        except TrackingError as exc:
            self._problem("track", f"frame {stamp} not tracked: {exc}", stamp_ns=stamp)
            return
        self.stats["frames_tracked"] += 1
        self._last_pose = est.T_map_cam
        self._pending[stamp] = _Pending(self.config.camera_frame or f.frame_id or OPTICAL_FRAME, f.received,
                                        f.arrival_lag_ns, time.monotonic())
        try:
            self.coarse_pub.publish(matrix_to_pose_stamped(est.T_map_cam, stamp_ns=stamp,
                                                           frame_id=self.config.map_frame))
        except ConversionError as exc:
            self._problem("publish", f"coarse pose of frame {stamp} not published: {exc}", Level.ERROR, stamp)
        for s in self.tracker.expired():
            self._publish_result(self.tracker.skip_reference(
                s, f"no reference: more than max_pending={self.config.max_pending} frames waiting"))

    def _late(self, stamp: int) -> None:
        self.stats["late_references"] += 1
        self.problems.report("late", f"reference for frame {stamp} came late or for an unknown frame (ignored)",
                             Level.OK)

    def _refine(self, stamp: int, rgb: np.ndarray, depth: np.ndarray) -> None:
        with self._state:
            tracker = self.tracker
            if tracker is None or stamp not in self._pending:
                self._late(stamp)
                return
            for s in [s for s in self._pending if s < stamp]:  # the newest reference first: these lost theirs
                self._publish_result(tracker.skip_reference(s, "no reference (a later frame's reference came)"))
            try:
                job = tracker.start_refine(stamp, rgb, depth)
            except TrackingError as exc:
                self._bad_reference(tracker, stamp, exc)
                return
        job.run()  # the alignment, outside the lock: f2f of the next frame goes on meanwhile
        with self._state:
            if self.tracker is not tracker or stamp not in self._pending:  # restarted, reset or timed out meanwhile
                self._late(stamp)
                return
            try:
                result = tracker.finish_refine(job)
            except TrackingError as exc:
                self._bad_reference(tracker, stamp, exc)
                return
            self._publish_result(result)

    def _bad_reference(self, tracker: RGBDTracker, stamp: int, exc: TrackingError) -> None:
        self.problems.report("reference", f"bad reference for frame {stamp}: {exc}")
        self._publish_result(tracker.skip_reference(stamp, f"bad reference: {exc}"))

    def _finish_overdue(self) -> None:
        if self.tracker is None:
            return
        timeout = self.config.reference_timeout_s
        now = time.monotonic()
        for s in [s for s, p in self._pending.items() if now - p.coarse_at >= timeout]:
            self._publish_result(self.tracker.skip_reference(s, f"no reference within {timeout:g} s"))

    def _finish_all(self, reason: str) -> None:
        if self.tracker is not None:
            for s in list(self._pending):
                self._publish_result(self.tracker.skip_reference(s, reason))
        self._pending.clear()

    def _publish_result(self, r: TrackResult) -> None:
        p = self._pending.pop(r.stamp_ns)
        self.stats[r.source] = self.stats.get(r.source, 0) + 1
        map_frame = self.config.map_frame
        try:
            self.pose_pub.publish(matrix_to_pose_stamped(r.T_map_cam, stamp_ns=r.stamp_ns, frame_id=map_frame))
            self.odom_pub.publish(matrix_to_odometry(r.T_map_cam, stamp_ns=r.stamp_ns, frame_id=map_frame,
                                                     child_frame_id=p.frame_id))
            if self.tf is not None:
                self.tf.send(transform_stamped(r.T_map_cam, stamp_ns=r.stamp_ns, parent_frame=map_frame,
                                               child_frame=p.frame_id))
        except ConversionError as exc:
            self._problem("publish", f"pose of frame {r.stamp_ns} not published: {exc}", Level.ERROR, r.stamp_ns)
            return
        # image stamp -> here: the node clock's lag when the frame arrived, plus the wall time since. (The node clock
        # alone would do with a wall clock; on sim time it only advances with /clock messages, one per frame.)
        pipeline_s = time.monotonic() - p.received
        latency_ns = p.arrival_lag_ns + round(1e9 * pipeline_s)
        values = {
            "stamp_ns": r.stamp_ns,
            "source": r.source,
            "reason": r.reason,
            **{f"{k}_ms": 1e3 * v for k, v in r.seconds.items()},
            "f2f_inlier_ratio": r.f2f.inlier_ratio if r.f2f is not None else None,
            "f2f_converged": r.f2f.converged if r.f2f is not None else None,
            "f2m_inlier_ratio": r.f2m.inlier_ratio if r.f2m is not None else None,
            "f2m_converged": r.f2m.converged if r.f2m is not None else None,
            "latency_ms": 1e-6 * latency_ns,
            "pipeline_ms": 1e3 * pipeline_s,  # wall time from the paired frame to here
        }
        level = Level.OK if r.source == "f2m" else Level.WARN
        self.publish_status(level, r.source + (f": {r.reason}" if r.reason else ""), values, stamp_ns=r.stamp_ns)


def main(args: list[str] | None = None) -> int:
    return run_node(RGBDTrackerNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())

