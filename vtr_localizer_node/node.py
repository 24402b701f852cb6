"""``vtr_localizer_node``: colour-constant stereo visual teach & repeat (paper: Paton et al., ICRA 2015, §IV-B, IV-C)
on a rectified stereo stream, with the ROS-free :class:`lightfast.vtr.localizer.VtrLocalizer`.

Inputs: ``/stereo/{left,right}/image_raw`` (colour, rectified; paired by exact stamp) and
``/stereo/{left,right}/camera_info`` (the rectified ``P`` and the size). ``mode: teach`` builds a map at
``map_path`` (finished by the ``/vtr/finish_teach`` service, aborted on shutdown); ``mode: repeat`` localizes
against it. Outputs: ``/vtr/localization`` (relative to the nearest keyframe, with covariance), ``/vtr/odometry``,
``/tf`` (``odom_frame`` → left camera → ``vtr_keyframe_<i>``), ``/vtr/status`` (per pair and a 1 Hz heartbeat) and
the colour-constant images ``/vtr/color_constant/{fv,fr}``. Every topic, parameter and behaviour: docs/nodes.md.

Threading (a :class:`~lightfast.ros.worker.StepWorker`, as in the other nodes): callbacks only convert and queue;
the worker, the finish service and the heartbeat's map retry take the localizer's lock.
"""
from __future__ import annotations

import functools
import sys
import threading
import time
from collections import deque
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger

from lightfast import topics
from lightfast.geometry import inverse
from lightfast.ros import convert, vtr_msgs
from lightfast.ros.clock import ClockJumpLatch
from lightfast.ros.diagnostics import Level
from lightfast.ros.errors import ConversionError
from lightfast.ros.node import LightfastNode
from lightfast.ros.qos import OUTPUT_QOS, sensor_qos
from lightfast.ros.runtime import run_node
from lightfast.ros.tf import TransformBroadcaster, transform_stamped
from lightfast.sync import ExactTimePairs
from lightfast.vtr.color_constant import image_sources
from lightfast.vtr.localizer import (
    Event,
    ImagesOut,
    LocalizationOut,
    OdometryOut,
    StereoCamera,
    StereoPair,
    VtrLocalizer,
)
from lightfast.vtr.localizer_config import VtrLocalizerConfig
from lightfast.vtr.pose_estimation import warm_up
from lightfast.vtr.teach import TeachPipeline

NODE_NAME = "vtr_localizer_node"
#: Unpaired left / right images kept per side.
MAX_UNPAIRED = 10
STATUS_PERIOD_S = 1.0
#: A stereo pair waits this long for the first camera_info of both cameras before it is reported and skipped, s.
CAMERA_INFO_WAIT_S = 1.0
_SIDES = {"left": (topics.STEREO_LEFT_IMAGE_TOPIC, topics.STEREO_LEFT_INFO_TOPIC),
          "right": (topics.STEREO_RIGHT_IMAGE_TOPIC, topics.STEREO_RIGHT_INFO_TOPIC)}


class VtrLocalizerNode(LightfastNode[VtrLocalizerConfig]):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, VtrLocalizerConfig, status_topic=topics.VTR_STATUS_TOPIC, **kwargs)
        cfg = self.params.config
        warm_up()  # the jitted RANSAC scoring: compiled (or loaded) now, not on the first stereo pair
        self.localizer = VtrLocalizer(cfg, self._on_event, stats=self.stats, sources={
            "left_info": topics.STEREO_LEFT_INFO_TOPIC, "right_info": topics.STEREO_RIGHT_INFO_TOPIC,
            "finish": topics.VTR_FINISH_TEACH_SERVICE})
        self._lock = threading.Lock()  # guards everything the input callbacks share with the worker
        self._pairs: ExactTimePairs[tuple[np.ndarray, str], np.ndarray] = ExactTimePairs(MAX_UNPAIRED)
        self._frames: deque[StereoPair] = deque()
        self._info: dict[str, StereoCamera] = {}
        self.stats |= {"frames_in": 0, "dropped_behind": 0, "dropped_unpaired": 0}
        self.last_status = (Level.OK, "waiting for stereo pairs")

        pub = self.create_publisher
        self.localization_pub = pub(PoseWithCovarianceStamped, topics.VTR_LOCALIZATION_TOPIC, OUTPUT_QOS)
        self.odom_pub = pub(Odometry, topics.VTR_ODOMETRY_TOPIC, OUTPUT_QOS)
        self.image_pubs = {"fv": pub(Image, topics.VTR_FV_TOPIC, OUTPUT_QOS),
                           "fr": pub(Image, topics.VTR_FR_TOPIC, OUTPUT_QOS)}
        self.tf = TransformBroadcaster(self) if cfg.publish_tf else None
        for side, (image_topic, info_topic) in _SIDES.items():
            self.create_subscription(Image, image_topic, functools.partial(self._on_image, side=side),
                                     sensor_qos(cfg))
            self.create_subscription(CameraInfo, info_topic, functools.partial(self._on_info, side=side),
                                     sensor_qos(cfg))
        self.worker = self.start_worker("vtr", self._work)
        self._clock_jumps = ClockJumpLatch(self, cfg.time_jump_back_s, wake=self.worker.wake)
        self.finish_service = self.create_service(Trigger, topics.VTR_FINISH_TEACH_SERVICE, self._on_finish)
        self.status_timer = self.create_timer(STATUS_PERIOD_S, self._heartbeat)
        if cfg.mode == "teach":
            self.get_logger().info(f"teach: building a map at {self.localizer.map_path} "
                                   f"({', '.join(cfg.teach.sources)}, {cfg.stereo.feature}); finish it with "
                                   f"{topics.VTR_FINISH_TEACH_SERVICE}")
        else:
            self.get_logger().info(f"repeat ({cfg.repeat.mode}) against the map at {self.localizer.map_path}")
            with self.localizer.lock:
                self.localizer.load_map()
        self.announce_ready()

    @property
    def teach(self) -> TeachPipeline | None:
        """The teach pipeline (None in a repeat, or after the teach ended)."""
        return self.localizer.teach

    def status_values(self) -> dict[str, Any]:
        return {**self.localizer.status_values(), **self.stats, "queued": len(self._frames)}

    def _heartbeat(self) -> None:
        if self.localizer.config.mode == "repeat" and self.localizer.repeat is None:
            with self.localizer.lock:
                self.localizer.load_map()
        self.publish_status(*self.last_status)
        if self._frames:
            self.worker.wake()  # pairs that waited for camera_info in vain are reported now

    # ---------------------------------------------------------------------------------------------- inputs

    def _on_image(self, msg: Image, side: str) -> None:
        try:
            stamp, rgb = convert.stamp_to_ns(msg.header.stamp), convert.image_to_rgb(msg)  # colour-constant images
        except ConversionError as exc:
            self.problem(f"{side}_image", f"dropped {side} image on {_SIDES[side][0]}: {exc}",
                         values={"stamp_ns": None, "problem": f"{side}_image"})
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
            self._frames.append(StereoPair(stamp, left, right, frame_id or topics.STEREO_LEFT_FRAME,
                                           time.monotonic()))
            while len(self._frames) > self.params.config.max_queued_frames:
                self._frames.popleft()
                self.stats["dropped_behind"] += 1
        self.worker.wake()

    def _on_info(self, msg: CameraInfo, side: str) -> None:
        try:
            camera = vtr_msgs.stereo_camera(msg, side)
        except ConversionError as exc:
            self.problem(f"{side}_info", f"ignored {_SIDES[side][1]}: {exc}",
                         values={"stamp_ns": None, "problem": f"{side}_info"})
            return
        with self._lock:
            self._info[side] = camera
            waiting = bool(self._frames)
        if waiting:
            self.worker.wake()

    # ---------------------------------------------------------------------------------------------- worker

    def _next(self) -> tuple[StereoPair | None, bool]:
        """The next pair to process (None: none, or it waits for the first camera_info), and whether more wait."""
        with self._lock:
            if not self._frames:
                return None, False
            frame = self._frames[0]
            if len(self._info) < 2 and time.monotonic() - frame.received_s < CAMERA_INFO_WAIT_S:
                return None, False  # the camera_info of a pair's stamp often comes just after it
            self._frames.popleft()
            return frame, bool(self._frames)

    def _process_next(self) -> bool:
        """Process one queued pair (under the localizer's lock); returns whether more wait."""
        with self.localizer.lock:
            frame, more = self._next()
            if frame is not None:
                self.localizer.config = self.params.config
                with self._lock:
                    left, right = self._info.get("left"), self._info.get("right")
                self.localizer.process(frame, left, right, self.now_ns())
        return more

    def _work(self) -> bool:
        if (clock_jump := self._clock_jumps.take()) is not None:
            with self.localizer.lock:
                self.localizer.clock_jumped(clock_jump)
        return self._process_next()

    def _on_finish(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        del request
        with self.localizer.lock:
            if self.localizer.teach is not None and self.localizer.finished is None:
                while self._frames:  # the pairs still queued first
                    self._process_next()
            response.success, response.message = self.localizer.finish_teach()
        return response

    # ---------------------------------------------------------------------------------------------- outputs

    def _on_event(self, event: Event) -> None:
        """What the localizer decided (in order, under its lock)."""
        cfg = self.localizer.config
        if isinstance(event, OdometryOut):
            self.odom_pub.publish(convert.matrix_to_odometry(
                event.T_odom_cam, stamp_ns=event.stamp_ns, frame_id=cfg.odom_frame, child_frame_id=event.frame_id,
                twist_linear=event.linear_mps, twist_angular=event.angular_radps))
            if self.tf is not None:
                self.tf.send(transform_stamped(event.T_odom_cam, stamp_ns=event.stamp_ns,
                                               parent_frame=cfg.odom_frame, child_frame=event.frame_id))
        elif isinstance(event, LocalizationOut):
            self.localization_pub.publish(vtr_msgs.localization_to_msg(event))
            if self.tf is not None:  # the keyframe as a child of the camera: the camera has one parent, odom_frame
                self.tf.send(transform_stamped(inverse(event.T_kf_cam), stamp_ns=event.stamp_ns,
                                               parent_frame=event.frame_id, child_frame=event.keyframe_frame))
        elif isinstance(event, ImagesOut) and cfg.publish_images:
            wanted = tuple(s for s, p in self.image_pubs.items() if p.get_subscription_count() > 0)
            for s, src in (image_sources(event.left, event.color, wanted) if wanted else {}).items():
                self.image_pubs[s].publish(convert.numpy_to_image(src.image, "mono8", stamp_ns=event.stamp_ns,
                                                                  frame_id=event.frame_id))
        elif not isinstance(event, ImagesOut):
            self.report(event)

    def destroy_node(self) -> None:
        """An unfinished teach is aborted: its staging directory goes, a previous map at map_path stays."""
        self.stop_workers()  # the worker first: it may be inside a step
        with self.localizer.lock:
            self.localizer.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(VtrLocalizerNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
