"""``rgbd_tracker_node``: two-step direct RGB-D tracking (paper §III-D, Eq. 7) — frame-to-frame against the previous
frame, then frame-to-model against the relit reference of ``daylight_relight_node``.

Live colour + depth (+ camera_info; best effort unless ``sensor_reliability`` says otherwise) paired by exact
stamp give T≈ on ``/tracker/coarse_pose``; the relit reference rendered there refines it. Finished frames go to
``/tracker/pose``, ``/tracker/odometry``, ``/tracker/status`` and ``/tf`` (``map_frame`` → ``camera_frame``);
``/initialpose`` or ``/tracker/reset`` restart at a pose. Every topic and parameter: docs/nodes.md. The policy
(f2m or f2f, restarts, time jumps) is :class:`lightfast.tracking.session.TrackingSession`; this node converts,
buffers and publishes. Threading (:class:`~lightfast.ros.worker.StepWorker`): callbacks only convert and buffer;
the f2f worker tracks queued frames and applies changes (waking every ``reference_timeout_s / 4``, at most 0.1 s,
for overdue frames); the f2m worker refines the frame of the newest reference (older ones dropped: no backlog).
"""
from __future__ import annotations

import sys
import threading
import time
from collections import deque
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, Image

from lightfast import topics
from lightfast.camera import PinholeCamera, Undistorter
from lightfast.ros import convert
from lightfast.ros.clock import ClockJumpLatch
from lightfast.ros.diagnostics import Level
from lightfast.ros.errors import ConversionError
from lightfast.ros.node import LightfastNode
from lightfast.ros.qos import OUTPUT_QOS, sensor_qos
from lightfast.ros.runtime import run_node
from lightfast.ros.tf import TransformBroadcaster, transform_stamped
from lightfast.sync import ExactTimePairs
from lightfast.tracking.pipeline import TrackerConfig
from lightfast.tracking.rgbd_odometry import warm_up
from lightfast.tracking.session import CoarsePose, Event, Finished, Frame, TrackingSession

NODE_NAME = "rgbd_tracker_node"
#: Unpaired colour / depth images (and reference colour / depth) kept per side.
MAX_UNPAIRED = 10
#: Paired live frames waiting for the tracker; when it falls behind the oldest are dropped.
MAX_QUEUED = 4


class RGBDTrackerNode(LightfastNode[TrackerConfig]):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, TrackerConfig, status_topic=topics.TRACKER_STATUS_TOPIC, **kwargs)
        cfg = self.params.config
        warm_s = warm_up(cfg)
        self.session = TrackingSession(
            cfg, self._on_event, stats=self.stats, camera_info_hint=f" on {topics.COLOR_INFO_TOPIC}",
            start_hint=f"; if the camera is elsewhere, send its pose on {topics.INITIAL_POSE_TOPIC} (RViz: 2D Pose "
                       f"Estimate) or {topics.TRACKER_RESET_TOPIC}")
        self._lock = threading.Lock()  # guards everything the input callbacks share with the workers
        self._live: ExactTimePairs[tuple[int, np.ndarray, str], tuple[np.ndarray, str]] = ExactTimePairs(
            MAX_UNPAIRED, slop_ns=round(cfg.pair_slop_s * 1e9))
        self._refs: ExactTimePairs[np.ndarray, np.ndarray] = ExactTimePairs(MAX_UNPAIRED)
        self._frames: deque[Frame] = deque()
        self._ref_queue: deque[tuple[int, np.ndarray, np.ndarray]] = deque()
        self._camera: PinholeCamera | None = None
        self._undistorter: Undistorter | None = None  # of self._camera's lens, None if it has no distortion
        self._read_camera_info = convert.CameraInfoReader(undistort=cfg.undistort)
        self._reset: tuple[np.ndarray, int | None, str] | None = None
        self._new_config: TrackerConfig | None = None
        self.params.on_change = self._on_config
        self.stats |= {"frames_in": 0, "references_in": 0, "dropped_behind": 0, "dropped_unpaired": 0,
                       "superseded_references": 0}

        self.coarse_pub = self.create_publisher(PoseStamped, topics.COARSE_POSE_TOPIC, OUTPUT_QOS)
        self.pose_pub = self.create_publisher(PoseStamped, topics.TRACKER_POSE_TOPIC, OUTPUT_QOS)
        self.odom_pub = self.create_publisher(Odometry, topics.TRACKER_ODOMETRY_TOPIC, OUTPUT_QOS)
        self.tf = TransformBroadcaster(self) if cfg.publish_tf else None
        sensor = sensor_qos(cfg)
        sub = self.create_subscription
        sub(Image, topics.COLOR_TOPIC, self._on_color, sensor)
        sub(Image, topics.DEPTH_TOPIC, self._on_depth, sensor)
        sub(CameraInfo, topics.COLOR_INFO_TOPIC, self._on_camera_info, sensor)
        sub(Image, topics.REFERENCE_COLOR_TOPIC, self._on_ref_color, OUTPUT_QOS)
        sub(Image, topics.REFERENCE_DEPTH_TOPIC, self._on_ref_depth, OUTPUT_QOS)
        sub(PoseStamped, topics.TRACKER_RESET_TOPIC, lambda m: self._take_reset(m, convert.pose_stamped_to_matrix,
                                                                          topics.TRACKER_RESET_TOPIC), OUTPUT_QOS)
        sub(PoseWithCovarianceStamped, topics.INITIAL_POSE_TOPIC,
            lambda m: self._take_reset(m, convert.pose_with_covariance_to_matrix, topics.INITIAL_POSE_TOPIC),
            OUTPUT_QOS)
        self._clock_jumps = ClockJumpLatch(self, cfg.time_jump_back_s, wake=lambda: self._f2f_worker.wake())
        self._f2f_worker = self.start_worker("tracker-f2f", self._work, period_s=self.session.deadline_period_s)
        self._f2m_worker = self.start_worker("tracker-f2m", self._refine_work)
        self.get_logger().info(f"mode {cfg.mode}, reference timeout {cfg.reference_timeout_s} s, start pose "
                               f"{list(cfg.initial_pose)} in {cfg.map_frame}, sensor QoS {cfg.sensor_reliability}; "
                               f"kernels warmed up in {warm_s:.2f} s")
        self.announce_ready()

    @property
    def config(self) -> TrackerConfig:
        """The configuration in use (the f2f worker applies a change between frames)."""
        return self.session.config

    def _problem(self, key: str, text: str, level: Level = Level.WARN, stamp_ns: int | None = None) -> None:
        self.problem(key, text, level, stamp_ns=stamp_ns, values={"stamp_ns": stamp_ns, "source": "", "reason": text})

    def status_values(self) -> dict[str, Any]:
        return {"mode": self.config.mode, "pending": self.session.waiting, **self.stats}

    # ---------------------------------------------------------------------------------------------- inputs

    def _read(self, msg: Any, read: Any, key: str, what: str, topic: str) -> tuple[int, Any] | None:
        try:
            return convert.stamp_to_ns(msg.header.stamp), read(msg)
        except ConversionError as exc:
            self._problem(key, f"dropped {what} on {topic}: {exc}")
            return None

    def _on_color(self, msg: Image) -> None:
        if (got := self._read(msg, lambda m: convert.image_to_rgb(m, allow_mono=True), "color", "colour image",
                              topics.COLOR_TOPIC)):
            with self._lock:
                self.stats["frames_in"] += 1
                self._enqueue_frame(self._live.add_first(got[0], (got[0], got[1], msg.header.frame_id)))

    def _on_depth(self, msg: Image) -> None:
        if (got := self._read(msg, convert.depth_to_metres, "depth", "depth image", topics.DEPTH_TOPIC)):
            with self._lock:
                self._enqueue_frame(self._live.add_second(got[0], (got[1], msg.header.frame_id)))

    def _enqueue_frame(self, pair: tuple[tuple[int, np.ndarray, str], tuple[np.ndarray, str]] | None) -> None:
        if self._live.dropped > self.stats["dropped_unpaired"]:  # throttled
            self._problem("unpaired", f"{self._live.dropped} colour or depth images had no partner within "
                          f"pair_slop_s={self.config.pair_slop_s} s of their stamp (lost on the way, or a driver "
                          "that stamps the two apart: raise pair_slop_s)")
        self.stats["dropped_unpaired"] = self._live.dropped
        if pair is None:
            return
        (stamp, rgb, frame_id), (depth, depth_frame_id) = pair
        lag_ns = max(0, self.now_ns() - stamp)
        self._frames.append(Frame(stamp, rgb, depth, frame_id, time.monotonic(), lag_ns, depth_frame_id))
        while len(self._frames) > MAX_QUEUED:
            self._frames.popleft()
            self.stats["dropped_behind"] += 1
        self._f2f_worker.wake()

    def _on_ref_color(self, msg: Image) -> None:
        if (got := self._read(msg, convert.image_to_rgb, "ref_color", "reference colour",
                              topics.REFERENCE_COLOR_TOPIC)):
            with self._lock:
                self._enqueue_ref(got[0], self._refs.add_first(*got))

    def _on_ref_depth(self, msg: Image) -> None:
        if (got := self._read(msg, convert.depth_to_metres, "ref_depth", "reference depth",
                              topics.REFERENCE_DEPTH_TOPIC)):
            with self._lock:
                self._enqueue_ref(got[0], self._refs.add_second(*got))

    def _enqueue_ref(self, stamp: int, pair: tuple[np.ndarray, np.ndarray] | None) -> None:
        if pair is not None:
            self.stats["references_in"] += 1
            self._ref_queue.append((stamp, *pair))
            self._f2m_worker.wake()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        try:
            camera = self._read_camera_info(msg)
        except ConversionError as exc:
            self._problem("camera_info", f"ignored {topics.COLOR_INFO_TOPIC}: {exc}")
            return
        with self._lock:
            self._camera, self._undistorter = camera, self._read_camera_info.undistorter

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

    def _work(self) -> bool:
        """One f2f step: pending changes, overdue references, at most one new frame. Returns whether frames wait."""
        with self._lock:
            new_config, self._new_config = self._new_config, None
            reset, self._reset = self._reset, None
            frame = self._frames.popleft() if self._frames else None
            camera, undistorter, more = self._camera, self._undistorter, bool(self._frames)
        job = self.session.start_frame(frame, camera=camera, undistorter=undistorter, now_ns=self.now_ns(),
                                       config=new_config, reset=reset, clock_jump_ns=self._clock_jumps.take())
        if job is not None and frame is not None:
            self.session.finish_frame(job.run(), frame)  # f2m jobs start and finish during job.run()
        return more

    def _refine_work(self) -> bool:
        """One f2m step: the newest received reference. Older waiting ones are dropped: refining the newest frame
        finishes the older ones with their f2f pose anyway."""
        with self._lock:
            if not self._ref_queue:
                return False
            stamp, rgb, depth = self._ref_queue.pop()
            self.stats["superseded_references"] += len(self._ref_queue)
            self._ref_queue.clear()
        refinement = self.session.start_refine(stamp, rgb, depth)
        if refinement is not None:
            refinement.job.run()  # f2f of the next frame goes on meanwhile
            self.session.finish_refine(refinement)
        return False

    # ---------------------------------------------------------------------------------------------- outputs

    def _on_event(self, event: Event) -> None:
        """What the session decided (called under its lock, in order)."""
        try:
            if isinstance(event, CoarsePose):
                self.coarse_pub.publish(convert.matrix_to_pose_stamped(event.T_map_cam, stamp_ns=event.stamp_ns,
                                                               frame_id=self.config.map_frame))
            elif isinstance(event, Finished):
                self._publish_result(event, self.config.map_frame)
            else:
                self.report(event)
        except ConversionError as exc:
            self._problem("publish", f"output not published: {exc}", Level.ERROR)

    def _publish_result(self, f: Finished, map_frame: str) -> None:
        r, frame_id = f.result, f.frame_id or topics.OPTICAL_FRAME
        self.pose_pub.publish(convert.matrix_to_pose_stamped(r.T_map_cam, stamp_ns=r.stamp_ns, frame_id=map_frame))
        self.odom_pub.publish(convert.matrix_to_odometry(r.T_map_cam, stamp_ns=r.stamp_ns, frame_id=map_frame,
                                                 child_frame_id=frame_id))
        if self.tf is not None:
            self.tf.send(transform_stamped(r.T_map_cam, stamp_ns=r.stamp_ns, parent_frame=map_frame,
                                           child_frame=frame_id))
        self.report(f.status(time.monotonic()))


def main(args: list[str] | None = None) -> int:
    return run_node(RGBDTrackerNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
