"""``daylight_relight_node``: the relit reference colour + depth of each live frame at its coarse pose (paper §III-C,
§III-D), for the frame-to-model step of ``rgbd_tracker_node``.

Subscribes the live colour image ``/camera/color/image_raw`` (rgb8, bgr8, rgba8 or bgra8) with
``/camera/color/camera_info`` (best effort unless ``sensor_reliability`` says otherwise), the
tracker's coarse pose ``/tracker/coarse_pose`` (PoseStamped in ``map``, stamped with the image it belongs to) and
the B̂_sun chunks ``/radiosity/sun_chunk`` of ``sun_update_node``. For each image paired with its pose it publishes,
with the image's stamp and frame: ``/relight/reference/color`` (rgb8), ``/relight/reference/depth`` (32FC1 metres,
0 = no geometry), the averaged brightness scales ``/relight/scale/{sun,sky,ground}`` (Vector3Stamped, x=r, y=g,
z=b) and ``/relight/status`` (DiagnosticArray: sun epoch, chunk progress, pixels used, stage timings); nothing
before the first complete sun epoch. What is paired, queued, swapped in, refused or restarted when time goes back
(``time_jump_back_s``, ``max_sun_epoch_ahead_s``) is decided by
:class:`~lightfast.daylight.relight_session.RelightSession`; this module converts, publishes and logs.

Threading: the executor's callbacks only convert and hand the inputs to the session, then wake a worker thread
(:class:`~lightfast.ros.worker.StepWorker`, why: docs/nodes.md) that relights the queued frames one at a time and
applies a completed B̂_sun and parameter changes, so nothing mutates the relighter while it renders.
"""
from __future__ import annotations

import sys
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped, Vector3, Vector3Stamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from lightfast.camera import PinholeCamera
from lightfast.config import ConfigError
from lightfast.daylight.crf import load_crf
from lightfast.daylight.errors import BrightnessError
from lightfast.daylight.lighting_map import LightingMap
from lightfast.daylight.relight import DaylightRelighter, Reference, RelightConfig
from lightfast.daylight.relight_session import RelightFrame, RelightSession, Relit, Skip
from lightfast.errors import CameraModelError
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
#: The chunk stream must not lose a chunk, or its epoch never completes.
CHUNK_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
CHUNK_FIELDS = ("vertex", "r", "g", "b")
STATUS_PERIOD_S = 1.0


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
        lmap.caster.intersect(np.zeros(3), np.array([[0.0, 0.0, 1.0]]))  # builds the lazy BVH before the 1st frame
        self.stats |= {"frames_in": 0, "poses_in": 0, "references": 0, "dropped_behind": 0, "dropped_unpaired": 0,
                       "waiting_for_sun": 0, "bad_inputs": 0, "chunks": 0, "dropped_epochs": 0, "time_jumps": 0}
        self.session = RelightSession(self.relighter, cfg, self.now_ns, stats=self.stats)
        self._read_camera_info = CameraInfoReader(undistort=cfg.undistort)  # .undistorter: of its lens, or None
        self.params.on_change = self._on_config
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
        self._worker = self.start_worker("relight", self._work_once)
        self.get_logger().info(
            f"lighting map {cfg.lighting_map}: {lmap.num_vertices} vertices; camera response {cfg.crf_file}; "
            f"reference {cfg.reference}, method {cfg.method}, sensor QoS {cfg.sensor_reliability}; waiting for the "
            "first complete sun epoch"
        )
        self.announce_ready()

    # ---------------------------------------------------------------------------------------------- helpers

    @property
    def _camera(self) -> PinholeCamera | None:
        """The latest camera_info's camera (``None``: none yet)."""
        return self.session.camera

    def publish_status(self, level: Level, message: str, values: Mapping[str, Any] | None = None, *,
                       stamp_ns: int | None = None) -> None:
        # stamp_ns: the frame this status is about (None: not about a frame)
        super().publish_status(level, message, {"stamp_ns": stamp_ns, **(values or {})}, stamp_ns=stamp_ns)

    def status_values(self) -> dict[str, Any]:
        return {**self.session.status_values(), **self.stats, "queued": self.session.queued, **self._last}

    def _report_waiting(self) -> None:
        self.problems.report("waiting", f"no reference yet: waiting for the first complete sun epoch on "
                             f"{SUN_CHUNK_TOPIC}{self.session.epoch_progress()}", Level.OK)

    def _heartbeat(self) -> None:
        if not self.relighter.ready:
            self._report_waiting()
        self.publish_status(*self.last_status)

    def _time_jumped(self, why: str) -> None:
        self.get_logger().warning(f"{why} (a bag played again, or looped?): the brightness average restarts and "
                                  "the next complete sun epoch is used whatever its time")

    # ---------------------------------------------------------------------------------------------- inputs

    def _on_image(self, msg: Image) -> None:
        try:
            stamp = stamp_to_ns(msg.header.stamp)
            rgb = image_to_rgb(msg)
            if (undistorter := self._read_camera_info.undistorter) is not None:
                rgb = undistorter.colour(rgb)
        except (ConversionError, CameraModelError) as exc:
            self.problem("image", f"dropped colour image on {COLOR_TOPIC}: {exc}")
            return
        if self.session.add_image(stamp, rgb, msg.header.frame_id):
            self._worker.wake()

    def _on_pose(self, msg: PoseStamped) -> None:
        try:
            T, stamp, frame_id = pose_stamped_to_matrix(msg)
            queued = self.session.add_pose(stamp, T, frame_id)
        except (ConversionError, BrightnessError) as exc:
            self.problem("pose", f"dropped coarse pose on {COARSE_POSE_TOPIC}: {exc}")
            return
        if queued:
            self._worker.wake()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        try:
            camera = self._read_camera_info(msg)
        except ConversionError as exc:
            self.problem("camera_info", f"ignored {COLOR_INFO_TOPIC}: {exc}")
            return
        self.session.set_camera(camera)  # the reader took the lens first: no image goes undistorted

    def _on_chunk(self, msg: PointCloud2) -> None:
        try:
            epoch = stamp_to_ns(msg.header.stamp)
            points = pointcloud2_to_numpy(msg)
            missing = [f for f in CHUNK_FIELDS if f not in (points.dtype.names or ())]
            if missing:
                raise ConversionError(f"chunk lacks the field(s) {', '.join(missing)} (needs vertex, r, g, b)")
            radiosity = np.stack([points["r"], points["g"], points["b"]], axis=1)
            result = self.session.add_chunk(epoch, points["vertex"], radiosity)
        except (ConversionError, BrightnessError) as exc:
            self.problem("chunk", f"dropped sun chunk on {SUN_CHUNK_TOPIC}: {exc}", Level.ERROR)
            return
        if result.dropped is not None:
            self.get_logger().warning(f"dropped sun epoch {epoch}: {result.dropped}")
        if result.complete:
            self._worker.wake()

    def _on_config(self, cfg: RelightConfig) -> None:
        self.session.set_config(cfg)
        self._worker.wake()

    # ---------------------------------------------------------------------------------------------- worker


    def _work_once(self) -> bool:
        """Apply a new B̂_sun / new options, relight the oldest queued frame; returns whether frames wait."""
        work = self.session.take_work(self._clock_jumps.take())
        if work.time_jump is not None:
            self._time_jumped(work.time_jump)
        if work.sun_epoch_ns is not None:
            self.get_logger().info(f"sun epoch {work.sun_epoch_ns} complete: B̂_sun swapped in"
                                   + ("; publishing references" if work.first_sun else ""))
            self.publish_status(Level.OK, f"sun epoch {work.sun_epoch_ns} swapped in")
        if work.frame is not None:
            self._report(work.frame, self.session.relight(work.frame))
        return work.more

    def _report(self, f: RelightFrame, r: Relit) -> None:
        """Log, count and publish what relighting a frame gave."""
        stamp = f.stamp_ns
        if r.time_jump is not None:
            self._time_jumped(r.time_jump)
        if r.skip is Skip.WAITING:
            self._report_waiting()
            self.publish_status(Level.WARN, "waiting for the first complete sun epoch", stamp_ns=stamp)
        elif r.skip is not None:
            why = f"no camera_info on {COLOR_INFO_TOPIC} yet" if r.skip is Skip.NO_CAMERA else r.reason
            text = f"frame {stamp}: {why}" if r.skip is Skip.AHEAD else f"no reference for frame {stamp}: {why}"
            self.problem(r.skip.value, text, Level.ERROR if r.skip is Skip.FAILED else Level.WARN, stamp_ns=stamp)
        elif (ref := r.reference) is not None:
            self._publish_reference(ref, f.frame_id)
            self.stats["references"] += 1
            self._last = {"pixels_used": ref.num_pixels, "frame_scales_used": ref.frame_scales is not None,
                          **{f"{k}_ms": 1e3 * v for k, v in ref.seconds.items()},
                          "total_ms": 1e3 * (time.perf_counter() - r.started),
                          "pose_latency_ms": f.pose_latency_ms,  # image stamp -> coarse pose here (f2f + transport)
                          "latency_ms": f.latency_ms()}  # image stamp -> reference published
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
