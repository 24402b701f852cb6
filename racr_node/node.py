"""``racr_node``: active camera relocalization (paper: "Fast and robust active camera relocalization in the wild",
§3) on the output of any visual SLAM engine (VSE) and a robotic platform, with the ROS-free
:class:`lightfast.racr.session.RacrSession` (initialization, hand–eye and real scale, the schemes of §3.6).

The reference is read from ``reference_path`` (retried every ``reference_retry_s`` while it fails). The VSE's
cloud, pose, keyframes and camera are assembled by :class:`lightfast.racr.vse_inputs.VseInputs`; the platform's
pose and stops go to the session; the next hand motion goes out on ``/racr/hand_motion`` (one at a time, only while
a platform subscribes), the run's state on ``/racr/status`` (:func:`lightfast.racr.status_report.racr_status`), the
estimate on ``/racr/camera_pose`` and ``/racr/aligned_cloud``. Every topic, frame and parameter: docs/nodes.md.
Bad input is reported and skipped. Threading: callbacks and the ``adjust_period_s`` tick only convert, hand arrays
to the session and publish; the alignment runs in the session's scheme thread (the parallel scheme of §3.6).
"""
from __future__ import annotations

import sys
import time
from typing import Any

from geometry_msgs.msg import PoseStamped, TransformStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from lightfast import topics
from lightfast.config import ConfigError
from lightfast.node_options import TIME_JUMP_BACK_S
from lightfast.racr.errors import RacrError
from lightfast.racr.node_config import RacrNodeConfig, ReferenceLoader
from lightfast.racr.reference import ReferenceObservation
from lightfast.racr.session import MotionCommand, RacrSession, SessionStatus
from lightfast.racr.status_report import LEVELS, racr_status, thin_cloud
from lightfast.racr.vse_inputs import VseInputs
from lightfast.ros import convert, racr_msgs
from lightfast.ros.clock import on_time_jump_back
from lightfast.ros.diagnostics import Level
from lightfast.ros.errors import ConversionError
from lightfast.ros.node import LightfastNode
from lightfast.ros.qos import LATCHED_QOS, OUTPUT_QOS, sensor_qos
from lightfast.ros.runtime import run_node

NODE_NAME = "racr_node"
#: Keyframe topics: every keyframe of an observation must fit into the queue.
KEYFRAME_QOS = QoSProfile(depth=32, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


class RacrNode(LightfastNode[RacrNodeConfig]):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, RacrNodeConfig, status_topic=topics.RACR_STATUS_TOPIC, **kwargs)
        cfg = self.config = self.params.config
        if not cfg.reference_path:
            raise ConfigError("parameter reference_path is required (a reference observation directory)")
        self.loader = ReferenceLoader(cfg)
        self.session: RacrSession | None = None
        self.reference: ReferenceObservation | None = None
        self._dead = False  # the alignment thread stopped on an unexpected error
        self.inputs = VseInputs(cfg.keyframes_per_cloud, cfg.input_wait_s, pose_source=topics.VSE_POSE_TOPIC,
                                camera_source=topics.VSE_CAMERA_INFO_TOPIC, stats=self.stats)
        self._last_estimate_stamp: float | None = None
        self._last_state: tuple[str, int] | None = None

        pub = self.create_publisher
        self.motion_pub = pub(TransformStamped, topics.RACR_HAND_MOTION_TOPIC, OUTPUT_QOS)
        self.aligned_pub = pub(PointCloud2, topics.RACR_ALIGNED_CLOUD_TOPIC, OUTPUT_QOS)
        self.reference_pub = pub(PointCloud2, topics.RACR_REFERENCE_CLOUD_TOPIC, LATCHED_QOS)
        self.camera_pose_pub = pub(PoseStamped, topics.RACR_CAMERA_POSE_TOPIC, OUTPUT_QOS)
        sensor = sensor_qos(cfg)  # streams; keyframes and the platform's stop event stay reliable
        sub = self.create_subscription
        sub(PointCloud2, topics.VSE_POINTS_TOPIC, self._on_points, sensor)
        sub(PoseStamped, topics.VSE_POSE_TOPIC, self._on_vse_pose, sensor)
        sub(Image, topics.VSE_KEYFRAME_IMAGE_TOPIC, self._on_keyframe_image, KEYFRAME_QOS)
        sub(TransformStamped, topics.VSE_KEYFRAME_POSE_TOPIC, self._on_keyframe_pose, KEYFRAME_QOS)
        sub(CameraInfo, topics.VSE_CAMERA_INFO_TOPIC, self._on_camera_info, sensor)
        sub(PoseStamped, topics.PLATFORM_POSE_TOPIC, lambda m: self._platform_input(m, stopped=False), sensor)
        sub(PoseStamped, topics.PLATFORM_STOPPED_TOPIC, lambda m: self._platform_input(m, stopped=True), OUTPUT_QOS)
        self._jump_handle = on_time_jump_back(self, TIME_JUMP_BACK_S, self._on_clock_jump)
        self.create_timer(cfg.adjust_period_s, self._tick)
        self.create_timer(cfg.status_period_s, self._publish_status)
        self.announce_ready()
        self._load_reference()

    def _on_clock_jump(self, now_ns: int, jump_ns: int) -> None:
        """ROS time went back (a restarted simulation, a bag played again): the session's motions and waits are
        timed on the old time line, so the relocalization starts over with a new session (executor thread)."""
        self._stop_session()
        self.inputs.clear()
        self._last_estimate_stamp = self._last_state = None
        self.loader.forget_attempts()
        self._dead = False
        self.get_logger().warning(f"ROS time jumped back {-jump_ns * 1e-9:.3f} s (a restarted simulation, or a bag "
                                  "played again?): the relocalization starts over")

    def problem(self, key: str, text: str, level: Level = Level.WARN, *, stamp_ns: int | None = None,
                values: Any = None, count: bool = True) -> None:
        """Bad input or a failed step: a throttled log line and the run's status with it; the node carries on."""
        self.stats["bad_inputs"] += count
        self.problems.report(key, text, level)
        self._publish_status(problem=(level, text, key))

    def _load_reference(self) -> bool:
        """Load the reference and start the session (retried every ``reference_retry_s`` while it fails)."""
        if self.session is not None:
            return True
        first = self.loader.error is None
        if (got := self.loader.attempt(time.monotonic(), clock=lambda: self.now_ns() * 1e-9)) is None:
            if self.loader.error is not None:
                self.problems.report("reference", f"{self.loader.error} (retrying every "
                                     f"{self.config.reference_retry_s:g} s; no motion is issued)", Level.ERROR)
                if first:
                    self._publish_status()
            return False
        (ref, self.session), self.reference = got, got[0]
        self.get_logger().info(f"reference observation of scene {ref.scene!r} ({len(ref.points_m)} points, "
                               f"frame {ref.frame_id!r}) loaded from {self.loader.path}")
        self.reference_pub.publish(convert.xyz_to_pointcloud2(ref.points_m, stamp_ns=self.now_ns(),
                                                              frame_id=ref.frame_id,
                                                              extra_fields={"intensity": ref.intensity}))
        self._publish_status()
        return True

    def _read(self, key: str, what: str, read: Any, msg: Any) -> Any:
        try:
            return read(msg)
        except ConversionError as exc:
            self.problem(key, f"{what} skipped: {exc}")
            return None

    def _on_points(self, msg: PointCloud2) -> None:
        read = lambda m: (convert.stamp_to_ns(m.header.stamp), *racr_msgs.vse_cloud_to_arrays(m))  # noqa: E731
        if (got := self._read("cloud", "VSE cloud", read, msg)) and self.inputs.add_cloud(time.monotonic(), *got):
            self._complete_cloud()

    def _on_vse_pose(self, msg: PoseStamped) -> None:
        if (got := self._read("vse_pose", "VSE pose", convert.pose_stamped_to_matrix, msg)) is None:
            return
        T, stamp_ns, _ = got
        if not self.inputs.add_pose(stamp_ns, T):
            return  # a repeat
        if self.session is not None:
            try:
                self.session.add_vse_pose(T, stamp=stamp_ns * 1e-9)
            except RacrError as exc:
                self.problem("vse_pose", f"VSE pose {stamp_ns} skipped: {exc}")
        self._complete_cloud()

    def _on_keyframe_image(self, msg: Image) -> None:
        read = lambda m: (convert.stamp_to_ns(m.header.stamp), str(m.header.frame_id),  # noqa: E731
                          racr_msgs.keyframe_image_to_float(m))
        if (got := self._read("keyframe", "keyframe image", read, msg)) is not None:
            self.inputs.add_keyframe_image(*got)
            self._complete_cloud()

    def _on_keyframe_pose(self, msg: TransformStamped) -> None:
        if (got := self._read("keyframe", "keyframe pose", racr_msgs.transform_stamped_to_matrix, msg)):
            T, stamp_ns, _, child = got
            self.inputs.add_keyframe_pose(stamp_ns, child, T)
            self._complete_cloud()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        if (camera := self._read("camera_info", "VSE camera_info", convert.camera_from_camera_info, msg)):
            self.inputs.camera = camera

    def _platform_input(self, msg: PoseStamped, *, stopped: bool) -> None:
        what = "platform stop" if stopped else "platform pose"
        if (got := self._read("platform", what, convert.pose_stamped_to_matrix, msg)) is None or self.session is None:
            return
        T, stamp_ns, _ = got
        try:
            (self.session.platform_stopped if stopped else self.session.add_platform_pose)(T, stamp=stamp_ns * 1e-9)
        except RacrError as exc:
            self.problem("platform", f"{what} {stamp_ns} skipped: {exc}")

    def _complete_cloud(self, *, at_tick: bool = False) -> None:
        """Hand the waiting cloud to the session once it is complete (or its wait is over)."""
        if self.session is not None:
            for report in self.inputs.feed(self.session, time.monotonic(), at_tick=at_tick):
                self.report(report)

    # ---------------------------------------------------------------------------------------------- work
    def _tick(self) -> None:
        if not self._load_reference():
            return
        self._complete_cloud(at_tick=True)  # a cloud whose wait is over
        session = self.session
        assert session is not None
        if not self._dead and self.motion_pub.get_subscription_count() > 0:
            try:
                cmd = session.next_hand_motion()
            except RacrError as exc:  # the alignment thread died (SchemeError)
                self._dead = True
                self.problem("thread", f"rACR stopped: {exc}", Level.ERROR, count=False)
                return
            if cmd is not None:
                self._publish_motion(cmd)
        status = session.status
        stamp = status.scheme.estimate_stamp if status.scheme is not None else None
        if stamp is not None and stamp != self._last_estimate_stamp:
            self._last_estimate_stamp = stamp
            self._publish_estimate(session)
        if (status.stage, status.motions_issued) != self._last_state:
            self._last_state = (status.stage, status.motions_issued)
            self.log(LEVELS[status.level], f"{status.stage}: {status.message}")
            self._publish_status(status)

    def _publish_motion(self, cmd: MotionCommand) -> None:
        self.motion_pub.publish(racr_msgs.matrix_to_transform_stamped(
            cmd.M_hand, stamp_ns=round(cmd.stamp * 1e9), frame_id=topics.PLATFORM_HAND_FRAME,
            child_frame_id=topics.PLATFORM_HAND_GOAL_FRAME))
        self.get_logger().info(cmd.describe())

    def _publish_estimate(self, session: RacrSession) -> None:
        assert self.reference is not None
        now_ns, frame_id = self.now_ns(), self.reference.frame_id
        if (T_ref_cam := session.camera_pose_in_reference()) is not None:
            self.camera_pose_pub.publish(convert.matrix_to_pose_stamped(T_ref_cam, stamp_ns=now_ns, frame_id=frame_id))
        n_max = self.config.aligned_cloud_max_points
        if n_max < 0 or self.aligned_pub.get_subscription_count() == 0 or (cloud := session.aligned_cloud()) is None:
            return
        points, intensity = thin_cloud(*cloud, n_max)
        self.aligned_pub.publish(convert.xyz_to_pointcloud2(
            points, stamp_ns=now_ns, frame_id=frame_id, extra_fields={} if intensity is None else
            {"intensity": intensity}))

    def _publish_status(self, status: SessionStatus | None = None, *,
                        problem: tuple[Level, str, str] | None = None) -> None:
        cfg, session = self.config, self.session
        self.report(racr_status(
            None if session is None else status or session.status, reference=self.reference,
            reference_error=self.loader.error, platform_subscribed=self.motion_pub.get_subscription_count() > 0,
            motion_topic=topics.RACR_HAND_MOTION_TOPIC, problem=problem,
            values={"reference_path": str(self.loader.path), "eta": cfg.adjustment.eta, "mode": cfg.scheme.mode}))

    def _stop_session(self) -> None:
        session, self.session = self.session, None
        if session is not None:
            try:
                session.stop()
            except RacrError as exc:
                self.get_logger().error(f"rACR alignment thread: {exc}")

    def destroy_node(self) -> None:
        self._stop_session()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(RacrNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
