"""``daylight_relight_node``: the relit reference colour + depth of each live frame at its coarse pose (paper §III-C,
§III-D), for the frame-to-model step of ``rgbd_tracker_node``.

Subscribes the live colour image ``/camera/color/image_raw`` (rgb8, bgr8, rgba8 or bgra8) with
``/camera/color/camera_info`` (best effort unless ``sensor_reliability`` says otherwise), the
tracker's coarse pose ``/tracker/coarse_pose`` (PoseStamped in ``map``, stamped with the image it belongs to) and
the B̂_sun chunks ``/radiosity/sun_chunk`` of ``sun_update_node``. Image and coarse pose are paired by exact stamp
(either may come first). A new B̂_sun is swapped in only when every vertex of its epoch has arrived; until the first
complete epoch no reference is published. For each pair it publishes, with the image's stamp and frame:
``/relight/reference/color`` (rgb8), ``/relight/reference/depth`` (32FC1 metres, 0 = no geometry), the averaged
brightness scales ``/relight/scale/{sun,sky,ground}`` (Vector3Stamped, x=r, y=g, z=b) and ``/relight/status``
(DiagnosticArray: sun epoch, chunk progress, pixels used, stage timings). Sun epochs stamped more than
``max_sun_epoch_ahead_s`` ahead of the node's clock, or older than the one in use, are dropped with a log line; time
going back (``time_jump_back_s``) restarts the brightness average and lets the next complete epoch in, whatever
its time.

Threading: the executor's callbacks only convert and buffer, then wake a worker thread that relights the queued
frames one at a time and also applies a completed B̂_sun and parameter changes, so nothing mutates the relighter
while it renders, and the inputs are taken while a frame renders. (With the relighting in an executor callback the
inputs waited in the DDS history behind each frame: at 30 Hz the coarse poses reached the node ~230 ms late, past
the tracker's deadline. rclpy's MultiThreadedExecutor fixed that but spent a third of the process's CPU on its own
bookkeeping; a plain thread, as in ``rgbd_tracker_node``, costs nothing while it waits.)
"""
from __future__ import annotations

import sys
import threading
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped, Vector3, Vector3Stamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from lightfast.camera import PinholeCamera
from lightfast.config import ConfigError
from lightfast.daylight.crf import load_crf
from lightfast.daylight.lighting_map import LightingMap
from lightfast.daylight.relight import DaylightRelighter, Reference, RelightConfig
from lightfast.daylight.sun_update import SunEpochAssembler
from lightfast.errors import LightfastError
from lightfast.ros.clock import ClockJumpLatch
from lightfast.ros.convert import (
    CameraInfoReader,
    image_to_rgb,
    make_header,
    numpy_to_image,
    pointcloud2_to_numpy,
    pose_stamped_to_matrix,
    stamp_to_ns,
)
from lightfast.ros.diagnostics import Level
from lightfast.ros.errors import ConversionError
from lightfast.ros.node import LightfastNode
from lightfast.ros.qos import OUTPUT_QOS, sensor_qos
from lightfast.ros.runtime import run_node
from lightfast.ros.sync import ExactTimePairs
from lightfast.ros.worker import StepWorker
from lightfast.stamps import StampGuard, StampVerdict
from lightfast.topics import (
    COARSE_POSE_TOPIC,
    COLOR_INFO_TOPIC,
    COLOR_TOPIC,
    REFERENCE_COLOR_TOPIC,
    REFERENCE_DEPTH_TOPIC,
    RELIGHT_STATUS_TOPIC,
    SCALE_TOPIC_PREFIX,
    SUN_CHUNK_TOPIC,
)

NODE_NAME = "daylight_relight_node"
#: Images and coarse poses waiting for their partner (per side): about a second of frames at 30 Hz.
MAX_UNPAIRED = 30
#: Paired frames waiting for the relighter; when it falls behind the oldest are dropped: their references would come
#: after the tracker's deadline, so rendering them would only delay the references of the newer frames.
MAX_QUEUED = 2
#: The chunk stream must not lose a chunk, or its epoch never completes.
CHUNK_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
CHUNK_FIELDS = ("vertex", "r", "g", "b")
STATUS_PERIOD_S = 1.0


#: When a message of a frame came: time.monotonic() then, and the node clock minus the frame's stamp (>= 0, ns).
_Arrival = tuple[float, int]


@dataclass
class _Frame:
    stamp_ns: int
    rgb: np.ndarray
    frame_id: str
    T_map_cam: np.ndarray
    arrival: _Arrival  # the first of image and pose
    pose_latency_ms: float  # image stamp -> coarse pose here

    def latency_ms(self) -> float:
        """Image stamp -> now: the node clock's lag when the first of image and pose came, plus the wall time since
        (on sim time the node clock only moves with /clock messages, about one per frame)."""
        return 1e-6 * self.arrival[1] + 1e3 * (time.monotonic() - self.arrival[0])


class DaylightRelightNode(LightfastNode[RelightConfig]):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, RelightConfig, status_topic=RELIGHT_STATUS_TOPIC, **kwargs)
        cfg = self.params.config
        if not cfg.lighting_map:
            raise ConfigError("parameter lighting_map is required (a directory made by `lightfast daylight prepare`)")
        if not cfg.crf_file:
            raise ConfigError("parameter crf_file is required (`lightfast crf calibrate` output or a camera.yaml)")
        lmap = LightingMap.load(cfg.lighting_map)
        self.relighter = DaylightRelighter(lmap, load_crf(cfg.crf_file), config=cfg)
        self.assembler = SunEpochAssembler(lmap.num_vertices)
        self._warm_up(lmap)

        self._lock = threading.Lock()  # guards everything the input callbacks share with the worker
        self._pairs: ExactTimePairs[tuple[np.ndarray, str, _Arrival], tuple[np.ndarray, _Arrival]] = ExactTimePairs(
            MAX_UNPAIRED)
        self._queue: deque[_Frame] = deque()
        self._camera: PinholeCamera | None = None
        self._read_camera_info = CameraInfoReader()
        self._new_sun: tuple[np.ndarray, int] | None = None
        self._new_config: RelightConfig | None = None
        self.params.on_change = self._on_config
        self.stats |= {"frames_in": 0, "poses_in": 0, "references": 0, "dropped_behind": 0, "dropped_unpaired": 0,
                      "waiting_for_sun": 0, "bad_inputs": 0, "chunks": 0, "dropped_epochs": 0, "time_jumps": 0}
        self._guard = StampGuard(cfg)  # stamps of the paired frames (worker only)
        self._dropped_epochs: set[int] = set()  # sun epochs already reported as dropped (one line each)
        self._last: dict[str, Any] = {}
        self.last_status = (Level.WARN, "waiting for the first complete sun epoch")

        self.color_pub = self.create_publisher(Image, REFERENCE_COLOR_TOPIC, OUTPUT_QOS)
        self.depth_pub = self.create_publisher(Image, REFERENCE_DEPTH_TOPIC, OUTPUT_QOS)
        self.scale_pubs = {name: self.create_publisher(Vector3Stamped, SCALE_TOPIC_PREFIX + name, OUTPUT_QOS)
                           for name in self.relighter.names}
        sensor = sensor_qos(cfg)
        self.create_subscription(Image, COLOR_TOPIC, self._on_image, sensor)
        self.create_subscription(CameraInfo, COLOR_INFO_TOPIC, self._on_camera_info, sensor)
        self.create_subscription(PoseStamped, COARSE_POSE_TOPIC, self._on_pose, OUTPUT_QOS)
        self.create_subscription(PointCloud2, SUN_CHUNK_TOPIC, self._on_chunk, CHUNK_QOS)
        self._clock_jumps = ClockJumpLatch(self, cfg.time_jump_back_s, wake=lambda: self._worker.wake())
        self.status_timer = self.create_timer(STATUS_PERIOD_S, self._heartbeat)
        self._worker = StepWorker("relight", self._work_once, self._on_step_error)
        self.get_logger().info(
            f"lighting map {cfg.lighting_map}: {lmap.num_vertices} vertices; camera response {cfg.crf_file}; "
            f"reference {cfg.reference}, method {cfg.method}, sensor QoS {cfg.sensor_reliability}; waiting for the "
            "first complete sun epoch"
        )
        self.announce_ready()

    # ---------------------------------------------------------------------------------------------- helpers

    @staticmethod
    def _warm_up(lmap: LightingMap) -> None:
        """Build the ray-casting BVH now (it is lazy), so the first frame does not pay for it."""
        lmap.caster.intersect(np.zeros(3), np.array([[0.0, 0.0, 1.0]]))

    def publish_status(self, level: Level, message: str, values: Mapping[str, Any] | None = None, *,
                       stamp_ns: int | None = None) -> None:
        # stamp_ns: the frame this status is about (None: not about a frame)
        super().publish_status(level, message, {"stamp_ns": stamp_ns, **(values or {})}, stamp_ns=stamp_ns)

    def status_values(self) -> dict[str, Any]:
        a = self.assembler
        return {"sun_epoch_ns": self.relighter.sun_epoch_ns, "pending_epoch_ns": a.pending_epoch_ns,
                "chunk_progress": a.progress if a.pending_epoch_ns is not None else None, **self.stats,
                "queued": len(self._queue), **self._last}

    def _heartbeat(self) -> None:
        if not self.relighter.ready:
            a = self.assembler
            progress = f" (epoch {a.pending_epoch_ns} at {100 * a.progress:.0f}%)" if a.pending_epoch_ns else ""
            self.problems.report("waiting", f"no reference yet: waiting for the first complete sun epoch on "
                                 f"{SUN_CHUNK_TOPIC}{progress}", Level.OK)
        self.publish_status(*self.last_status)

    # ---------------------------------------------------------------------------------------------- inputs

    def _on_image(self, msg: Image) -> None:
        try:
            stamp = stamp_to_ns(msg.header.stamp)
            rgb = image_to_rgb(msg)
        except ConversionError as exc:
            self.problem("image", f"dropped colour image on {COLOR_TOPIC}: {exc}")
            return
        arrival = self._arrival(stamp)
        with self._lock:
            self.stats["frames_in"] += 1
            pair = self._pairs.add_first(stamp, (rgb, msg.header.frame_id, arrival))
            self._enqueue(stamp, pair)

    def _on_pose(self, msg: PoseStamped) -> None:
        try:
            T, stamp, frame_id = pose_stamped_to_matrix(msg)
            if frame_id not in ("", self.params.config.map_frame):
                raise ConversionError(f"frame_id {frame_id!r} is not {self.params.config.map_frame!r}")
        except ConversionError as exc:
            self.problem("pose", f"dropped coarse pose on {COARSE_POSE_TOPIC}: {exc}")
            return
        arrival = self._arrival(stamp)
        with self._lock:
            self.stats["poses_in"] += 1
            self._enqueue(stamp, self._pairs.add_second(stamp, (T, arrival)))

    def _arrival(self, stamp: int) -> _Arrival:
        return time.monotonic(), max(0, self.now_ns() - stamp)

    def _enqueue(self, stamp: int, pair: tuple[tuple[np.ndarray, str, _Arrival], tuple[np.ndarray, _Arrival]] | None
                 ) -> None:
        self.stats["dropped_unpaired"] = self._pairs.dropped
        if pair is None:
            return
        (rgb, frame_id, image_arrival), (T, pose_arrival) = pair
        first = min(image_arrival, pose_arrival)
        pose_latency_ms = 1e-6 * first[1] + 1e3 * (pose_arrival[0] - first[0])
        self._queue.append(_Frame(stamp, rgb, frame_id, T, first, pose_latency_ms))
        while len(self._queue) > MAX_QUEUED:
            self._queue.popleft()
            self.stats["dropped_behind"] += 1
        self._worker.wake()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        try:
            camera = self._read_camera_info(msg)
        except ConversionError as exc:
            self.problem("camera_info", f"ignored {COLOR_INFO_TOPIC}: {exc}")
            return
        with self._lock:
            self._camera = camera

    def _on_chunk(self, msg: PointCloud2) -> None:
        try:
            epoch = stamp_to_ns(msg.header.stamp)
            points = pointcloud2_to_numpy(msg)
            missing = [f for f in CHUNK_FIELDS if f not in (points.dtype.names or ())]
            if missing:
                raise ConversionError(f"chunk lacks the field(s) {', '.join(missing)} (needs vertex, r, g, b)")
            radiosity = np.stack([points["r"], points["g"], points["b"]], axis=1)
            with self._lock:  # the worker restarts the assembler when time jumps back
                if not self._epoch_ok(epoch):
                    return
                complete = self.assembler.add(epoch, points["vertex"], radiosity)
        except (ConversionError, ValueError) as exc:
            self.problem("chunk", f"dropped sun chunk on {SUN_CHUNK_TOPIC}: {exc}", Level.ERROR)
            return
        self.stats["chunks"] += 1
        if complete is not None:
            with self._lock:
                self._new_sun = (complete, epoch)
            self._worker.wake()

    def _epoch_ok(self, epoch: int) -> bool:
        """(Under the input lock.) Refuse a sun epoch stamped implausibly far ahead of the clock, or older than the
        one in use; one log line per dropped epoch."""
        now = self.now_ns()
        ahead_ns = round(self.params.config.max_sun_epoch_ahead_s * 1e9)
        why: str | None
        if ahead_ns > 0 and now > 0 and epoch - now > ahead_ns:
            why = (f"stamped {(epoch - now) * 1e-9:.1f} s ahead of this node's clock (max_sun_epoch_ahead_s "
                   f"{self.params.config.max_sun_epoch_ahead_s:g})")
        else:
            why = self.assembler.drop_reason(epoch)
        if why is None:
            return True
        if epoch not in self._dropped_epochs:
            self._dropped_epochs.add(epoch)
            self.stats["dropped_epochs"] += 1
            self.get_logger().warning(f"dropped sun epoch {epoch}: {why}")
        return False

    def _time_jumped(self, why: str) -> None:
        """(Worker, under the input lock.) Time went back: the scale average restarts and the next complete sun
        epoch is taken whatever its time (the B̂_sun in use stays until then)."""
        self.stats["time_jumps"] += 1
        self._guard.reset()
        self.relighter.restart_average()
        self.assembler.restart()
        self._dropped_epochs.clear()
        self.get_logger().warning(f"{why} (a bag played again, or looped?): the brightness average restarts and "
                                  "the next complete sun epoch is used whatever its time")

    def _on_config(self, cfg: RelightConfig) -> None:
        with self._lock:
            self._new_config = cfg
        self._worker.wake()

    # ---------------------------------------------------------------------------------------------- worker

    def _on_step_error(self, exc: Exception) -> None:
        self.problem("internal", f"relight step failed: {exc!r}", Level.ERROR)

    def destroy_node(self) -> None:
        self._worker.stop()
        super().destroy_node()

    def _work_once(self) -> bool:
        """Apply a new B̂_sun / new options, relight the oldest queued frame; returns whether frames wait."""
        with self._lock:
            new_sun, self._new_sun = self._new_sun, None
            new_config, self._new_config = self._new_config, None
            clock_jump = self._clock_jumps.take()
            frame = self._queue.popleft() if self._queue else None
            camera = self._camera
            more = bool(self._queue)
            if clock_jump is not None and self._guard.clock_jumped_back(clock_jump):
                self._time_jumped(f"ROS time jumped back to {clock_jump * 1e-9:.3f} s")
        if new_config is not None:
            self.relighter.reconfigure(new_config)
        if new_sun is not None:
            first = not self.relighter.ready
            self.relighter.set_sun_radiosity(*new_sun)
            self.get_logger().info(f"sun epoch {new_sun[1]} complete: B̂_sun swapped in"
                                   + ("; publishing references" if first else ""))
            self.publish_status(Level.OK, f"sun epoch {new_sun[1]} swapped in")
        if frame is not None and self._stamp_ok(frame.stamp_ns):
            self._process(frame, camera)
        return more

    def _stamp_ok(self, stamp: int) -> bool:
        """Refuse a frame stamped ahead of the clock; restart the time-dependent state when the stamps went back.
        (Frames are relit independently: one slightly out of order is relit as it is.)"""
        now = self.now_ns()
        verdict = self._guard.check(stamp, now)
        if verdict is StampVerdict.AHEAD:
            self.problem("stamp", f"frame {stamp}: {self._guard.describe(verdict, stamp, now)}", stamp_ns=stamp)
            return False
        if verdict is StampVerdict.JUMPED_BACK:
            assert self._guard.last_ns is not None  # JUMPED_BACK: there is a previous stamp
            with self._lock:
                self._time_jumped(f"frame stamps went back {(self._guard.last_ns - stamp) * 1e-9:.3f} s")
        if verdict is not StampVerdict.OUT_OF_ORDER:
            self._guard.accept(stamp)
        return True

    def _process(self, f: _Frame, camera: PinholeCamera | None) -> None:
        stamp = f.stamp_ns
        if camera is None:
            self.problem("no_camera_info", f"no reference for frame {stamp}: no camera_info on {COLOR_INFO_TOPIC} "
                          "yet", stamp_ns=stamp)
            return
        if f.rgb.shape[:2] != camera.shape:
            self.problem("size", f"no reference for frame {stamp}: colour image is {f.rgb.shape[1]}x"
                          f"{f.rgb.shape[0]}, camera_info says {camera.width}x{camera.height}", stamp_ns=stamp)
            return
        if not self.relighter.ready:
            self.stats["waiting_for_sun"] += 1
            a = self.assembler
            progress = f" (epoch {a.pending_epoch_ns} at {100 * a.progress:.0f}%)" if a.pending_epoch_ns else ""
            self.problems.report("waiting", f"no reference yet: waiting for the first complete sun epoch on "
                                 f"{SUN_CHUNK_TOPIC}{progress}", Level.OK)
            self.publish_status(Level.WARN, "waiting for the first complete sun epoch", stamp_ns=stamp)
            return
        t0 = time.perf_counter()
        try:
            ref = self.relighter.step(stamp, f.rgb, f.T_map_cam, camera)
        except LightfastError as exc:
            self.problem("step", f"no reference for frame {stamp}: {exc}", Level.ERROR, stamp_ns=stamp)
            return
        self._publish_reference(ref, f.frame_id)
        self.stats["references"] += 1
        self._last = {
            "pixels_used": ref.num_pixels,
            "frame_scales_used": ref.frame_scales is not None,
            **{f"{k}_ms": 1e3 * v for k, v in ref.seconds.items()},
            "total_ms": 1e3 * (time.perf_counter() - t0),
            "pose_latency_ms": f.pose_latency_ms,  # image stamp -> coarse pose here (tracker f2f + transport)
            "latency_ms": f.latency_ms(),  # image stamp -> reference published
        }
        self.publish_status(Level.OK, "reference published", stamp_ns=stamp)

    def _publish_reference(self, ref: Reference, frame_id: str) -> None:
        stamp = ref.stamp_ns
        self.color_pub.publish(numpy_to_image(ref.color, "rgb8", stamp_ns=stamp, frame_id=frame_id))
        self.depth_pub.publish(numpy_to_image(ref.depth_m, "32FC1", stamp_ns=stamp, frame_id=frame_id))
        for name, pub in self.scale_pubs.items():
            s = ref.scale(name)
            pub.publish(Vector3Stamped(header=make_header(stamp, frame_id),
                                       vector=Vector3(x=float(s[0]), y=float(s[1]), z=float(s[2]))))


def main(args: list[str] | None = None) -> int:
    return run_node(DaylightRelightNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
