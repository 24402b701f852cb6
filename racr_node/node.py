"""``racr_node``: active camera relocalization (paper: "Fast and robust active camera relocalization in the wild",
§3) on the output of any visual SLAM engine (VSE) and a robotic platform, with the ROS-free
:class:`lightfast.racr.session.RacrSession` (initialization motions, hand–eye and real scale, the parallel or serial
scheme of §3.6).

Parameters: ``config/racr_node.yaml``, from :class:`lightfast.racr.node_config.RacrNodeConfig`. The reference
observation (point cloud in metres, reference camera pose, image, intrinsics) is read from the directory
``reference_path`` (format ``lightfast-racr-reference``, :func:`lightfast.racr.reference.load_reference`); with
``reference_scene`` a reference made for another scene is refused. While it cannot be loaded the node reports why
on ``/racr/status`` (level ERROR, stage ``no_reference``), issues nothing and retries every ``reference_retry_s``.

Inputs (README, rACR topics):

* ``/vse/points`` (``PointCloud2``): the VSE's semi-dense cloud, float ``x, y, z`` in VSE units and ``intensity``
  in the units of the keyframe images as read below ([0, 1] for ``mono8`` / 255). A cloud is paired with the
  ``/vse/pose`` of exactly its stamp (the camera pose of the observation) and with the keyframes stamped like it;
  it waits for them up to ``input_wait_s`` (``keyframes_per_cloud`` keyframes and ``/vse/camera_info``), then is
  used with what arrived, or dropped (reported) without its pose. A cloud repeating the last stamp is ignored.
* ``/vse/pose`` (``PoseStamped``): the VSE camera pose ``T_vse_cam`` (VSE units), the T_A of Eq. 3.
* ``/vse/keyframe/image`` (``Image`` ``mono8``, ``mono16`` or ``32FC1``, ``frame_id`` = the keyframe's frame) and
  ``/vse/keyframe/pose`` (``TransformStamped`` ``vse → <keyframe frame>``, ``T_vse_cam`` of the keyframe), paired
  by stamp and keyframe frame; ``/vse/camera_info`` (``CameraInfo``, rectified): the keyframe camera.
* ``/platform/pose`` (``PoseStamped``): the reported hand pose ``T_base_hand`` (m).
* ``/platform/stopped`` (``PoseStamped``): the reported hand pose when the platform came to rest, stamped then; the
  node regards the platform as moving from a command until a stop stamped at or after it.

Outputs:

* ``/racr/hand_motion`` (``TransformStamped`` ``platform_hand → platform_hand_goal``): the next relative hand
  motion ``M_B = T_hand_hand'`` the platform must execute, ``T_base_hand' = T_base_hand · M_B``, stamped when it
  was issued; first the initialization motions (§3.2), then the adjustments of Eq. 3 until ``g ≤ eta``. One at a
  time: the next one only after the stop of the previous one and a VSE pose taken after that stop. Nothing is
  issued while no platform subscribes to the topic, without a reference, after a failed initialization, or after
  convergence.
* ``/racr/status`` (``DiagnosticArray``, one status ``racr_node``): stage (``no_reference``, ``waiting_for_platform``,
  ``waiting_for_vse``, ``initializing``, ``initialization_failed``, ``aligning``, ``ready``, ``moving``,
  ``converged``, ``platform_timeout``, ``failed``), level and a one-line message, the initialization (motions done,
  s, hand–eye residuals, X), the estimate (σ_p, fast/fine), g, eta, converged, counts of motions, observations,
  alignments, failures and bad inputs; every ``status_period_s`` and on every change of stage.
* ``/racr/aligned_cloud`` (``PointCloud2``, the reference frame): the newest VSE cloud mapped by the latest
  ``(T_p, σ_p)`` and ``s``, for inspection, whenever the estimate changes; ``/racr/reference_cloud`` (latched):
  the reference; ``/racr/camera_pose`` (``PoseStamped``, the reference frame): the current camera ``T_ref_cam``.

Bad input — malformed messages, empty or non-finite clouds, non-unit quaternions, keyframes whose size does not
match the camera, a cloud without its pose — is reported on ``/racr/status`` and in throttled log lines, and
skipped; the node keeps running. Threading: callbacks only convert and hand arrays to the session; the alignment
runs in the scheme's own thread, so no callback waits for an alignment.
"""
from __future__ import annotations

import sys
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TransformStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from lightfast.camera import PinholeCamera
from lightfast.config import ConfigError
from lightfast.errors import LightfastError
from lightfast.geometry import matrix_to_quat, rotation_angle_deg
from lightfast.node_options import TIME_JUMP_BACK_S
from lightfast.racr.errors import RacrError
from lightfast.racr.node_config import RacrNodeConfig
from lightfast.racr.reference import ReferenceObservation, load_reference
from lightfast.racr.session import MotionCommand, RacrSession, SessionStatus
from lightfast.ros.clock import on_time_jump_back
from lightfast.ros.convert import (
    camera_from_camera_info,
    matrix_to_pose_stamped,
    pose_stamped_to_matrix,
    stamp_to_ns,
    xyz_to_pointcloud2,
)
from lightfast.ros.diagnostics import Level, ProblemLog, diagnostic_array, diagnostic_status, log_at
from lightfast.ros.errors import ConversionError
from lightfast.ros.params import ConfigParameters
from lightfast.ros.qos import LATCHED_QOS, OUTPUT_QOS, sensor_qos
from lightfast.ros.racr_msgs import (
    keyframe_image_to_float,
    matrix_to_transform_stamped,
    transform_stamped_to_matrix,
    vse_cloud_to_arrays,
)
from lightfast.ros.ready import announce_ready
from lightfast.ros.runtime import run_node
from lightfast.topics import (
    PLATFORM_HAND_FRAME,
    PLATFORM_HAND_GOAL_FRAME,
    PLATFORM_POSE_TOPIC,
    PLATFORM_STOPPED_TOPIC,
    RACR_ALIGNED_CLOUD_TOPIC,
    RACR_CAMERA_POSE_TOPIC,
    RACR_HAND_MOTION_TOPIC,
    RACR_REFERENCE_CLOUD_TOPIC,
    RACR_STATUS_TOPIC,
    VSE_CAMERA_INFO_TOPIC,
    VSE_KEYFRAME_IMAGE_TOPIC,
    VSE_KEYFRAME_POSE_TOPIC,
    VSE_POINTS_TOPIC,
    VSE_POSE_TOPIC,
)

NODE_NAME = "racr_node"
STAGE_NO_REFERENCE = "no_reference"
#: Keyframe topics: every keyframe of an observation must fit into the queue.
KEYFRAME_QOS = QoSProfile(depth=32, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
#: Buffered VSE poses (by stamp) and keyframe halves (by stamp and frame) waiting for their clouds.
MAX_POSES = 64
MAX_KEYFRAME_PARTS = 256
_LEVELS = {"ok": Level.OK, "warn": Level.WARN, "error": Level.ERROR}


def pose7(T: np.ndarray | None) -> str:
    """``"x y z qx qy qz qw"`` of a transform (empty for None), for status values."""
    if T is None:
        return ""
    return " ".join(f"{v:.6g}" for v in (*T[:3, 3], *matrix_to_quat(T[:3, :3])))


@dataclass
class _Cloud:
    stamp_ns: int
    points: np.ndarray
    intensity: np.ndarray | None
    received: float  # time.monotonic()
    expired: bool = False  # the wait was over at a tick: the next tick uses it as it is


class RacrNode(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.params = ConfigParameters(self, RacrNodeConfig)
        cfg = self.params.config
        self.config = cfg
        if not cfg.reference_path:
            raise ConfigError("parameter reference_path is required (a reference observation directory)")
        self.reference_path = Path(cfg.reference_path).expanduser()
        self.problems = ProblemLog(lambda level, text: log_at(self.get_logger(), level, text))
        self.session: RacrSession | None = None
        self.reference: ReferenceObservation | None = None
        self._reference_error: str | None = None
        self._reference_attempt: float | None = None
        self._dead = False  # the alignment thread stopped on an unexpected error
        self._poses: OrderedDict[int, np.ndarray] = OrderedDict()
        self._kf_images: OrderedDict[tuple[int, str], np.ndarray] = OrderedDict()
        self._kf_poses: OrderedDict[tuple[int, str], np.ndarray] = OrderedDict()
        self._camera: PinholeCamera | None = None
        self._pending: _Cloud | None = None
        self._last_cloud_stamp: int | None = None
        self._last_estimate_stamp: float | None = None
        self._last_state: tuple[str, int] | None = None
        self._last_command: MotionCommand | None = None
        self.stats = {"bad_inputs": 0, "clouds_used": 0, "clouds_dropped": 0, "clouds_superseded": 0}

        self.motion_pub = self.create_publisher(TransformStamped, RACR_HAND_MOTION_TOPIC, OUTPUT_QOS)
        self.status_pub = self.create_publisher(DiagnosticArray, RACR_STATUS_TOPIC, OUTPUT_QOS)
        self.aligned_pub = self.create_publisher(PointCloud2, RACR_ALIGNED_CLOUD_TOPIC, OUTPUT_QOS)
        self.reference_pub = self.create_publisher(PointCloud2, RACR_REFERENCE_CLOUD_TOPIC, LATCHED_QOS)
        self.camera_pose_pub = self.create_publisher(PoseStamped, RACR_CAMERA_POSE_TOPIC, OUTPUT_QOS)
        sensor = sensor_qos(cfg)  # streams; keyframes and the platform's stop event stay reliable
        self.create_subscription(PointCloud2, VSE_POINTS_TOPIC, self._on_points, sensor)
        self.create_subscription(PoseStamped, VSE_POSE_TOPIC, self._on_vse_pose, sensor)
        self.create_subscription(Image, VSE_KEYFRAME_IMAGE_TOPIC, self._on_keyframe_image, KEYFRAME_QOS)
        self.create_subscription(TransformStamped, VSE_KEYFRAME_POSE_TOPIC, self._on_keyframe_pose, KEYFRAME_QOS)
        self.create_subscription(CameraInfo, VSE_CAMERA_INFO_TOPIC, self._on_camera_info, sensor)
        self.create_subscription(PoseStamped, PLATFORM_POSE_TOPIC, self._on_platform_pose, sensor)
        self.create_subscription(PoseStamped, PLATFORM_STOPPED_TOPIC, self._on_platform_stopped, OUTPUT_QOS)
        self._jump_handle = on_time_jump_back(self, TIME_JUMP_BACK_S, self._on_clock_jump)
        self.create_timer(cfg.adjust_period_s, self._tick)
        self.create_timer(cfg.status_period_s, self._heartbeat)
        self._ready_pub = announce_ready(self)  # for `lightfast wait-ready` in launch-free scripts
        self._load_reference()

    # ---------------------------------------------------------------------------------------------- helpers
    def _on_clock_jump(self, now_ns: int, jump_ns: int) -> None:
        """ROS time went back (a restarted simulation, a bag played again): the session's motions and waits are
        timed on the old time line, so the relocalization starts over with a new session (executor thread)."""
        self._stop_session()
        self._poses.clear()
        self._kf_images.clear()
        self._kf_poses.clear()
        self._pending = None
        self._last_cloud_stamp = self._last_estimate_stamp = self._last_state = self._last_command = None
        self._reference_attempt = None
        self._dead = False
        self.get_logger().warning(f"ROS time jumped back {-jump_ns * 1e-9:.3f} s (a restarted simulation, or a bag "
                                  "played again?): the relocalization starts over")

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _problem(self, key: str, text: str, level: Level = Level.WARN, *, count: bool = True) -> None:
        """Bad input or a failed step: a throttled log line and a status message; the node carries on."""
        if count:
            self.stats["bad_inputs"] += 1
        self.problems.report(key, text, level)
        self._publish_status(override=(level, text, key))

    def _load_reference(self) -> bool:
        """Load the reference and start the session (retried every ``reference_retry_s`` while it fails)."""
        if self.session is not None:
            return True
        now = time.monotonic()
        if self._reference_attempt is not None and now - self._reference_attempt < self.config.reference_retry_s:
            return False
        self._reference_attempt = now
        cfg = self.config
        try:
            ref = load_reference(self.reference_path, scene=cfg.reference_scene or None)
            session = RacrSession(
                ref.points_m, ref.T_ref_camref, config=cfg.session, scheme_config=cfg.scheme, fast_config=cfg.fast,
                fine_config=cfg.fine, adjustment_config=cfg.adjustment, init_config=cfg.initialization,
                clock=self._now_s,
            )
        except (LightfastError, OSError) as exc:
            first = self._reference_error is None
            self._reference_error = f"reference {self.reference_path}: {exc}"
            self.problems.report("reference", f"{self._reference_error} (retrying every "
                                 f"{cfg.reference_retry_s:g} s; no motion is issued)", Level.ERROR)
            if first:
                self._publish_status()
            return False
        self.reference, self.session, self._reference_error = ref, session, None
        self.get_logger().info(f"reference observation of scene {ref.scene!r} ({len(ref.points_m)} points, "
                               f"frame {ref.frame_id!r}) loaded from {self.reference_path}")
        self.reference_pub.publish(xyz_to_pointcloud2(ref.points_m, stamp_ns=self.get_clock().now().nanoseconds,
                                                      frame_id=ref.frame_id,
                                                      extra_fields={"intensity": ref.intensity}))
        self._publish_status()
        return True

    # ---------------------------------------------------------------------------------------------- inputs
    def _on_points(self, msg: PointCloud2) -> None:
        try:
            stamp_ns = stamp_to_ns(msg.header.stamp)
            points, intensity = vse_cloud_to_arrays(msg)
        except ConversionError as exc:
            self._problem("cloud", f"VSE cloud skipped: {exc}")
            return
        if stamp_ns == self._last_cloud_stamp or (self._pending is not None and self._pending.stamp_ns == stamp_ns):
            return  # the VSE repeated an observation we have
        if self._pending is not None:
            self.stats["clouds_superseded"] += 1
        self._pending = _Cloud(stamp_ns, points, intensity, time.monotonic())
        self._complete_cloud()

    def _on_vse_pose(self, msg: PoseStamped) -> None:
        try:
            T, stamp_ns, _ = pose_stamped_to_matrix(msg)
        except ConversionError as exc:
            self._problem("vse_pose", f"VSE pose skipped: {exc}")
            return
        if stamp_ns in self._poses:
            return  # a repeat
        self._poses[stamp_ns] = T
        while len(self._poses) > MAX_POSES:
            self._poses.popitem(last=False)
        if self.session is not None:
            try:
                self.session.add_vse_pose(T, stamp=stamp_ns * 1e-9)
            except RacrError as exc:
                self._problem("vse_pose", f"VSE pose {stamp_ns} skipped: {exc}")
        self._complete_cloud()

    def _on_keyframe_image(self, msg: Image) -> None:
        try:
            key = (stamp_to_ns(msg.header.stamp), str(msg.header.frame_id))
            image = keyframe_image_to_float(msg)
        except ConversionError as exc:
            self._problem("keyframe", f"keyframe image skipped: {exc}")
            return
        self._store(self._kf_images, key, image)

    def _on_keyframe_pose(self, msg: TransformStamped) -> None:
        try:
            T, stamp_ns, _, child = transform_stamped_to_matrix(msg)
        except ConversionError as exc:
            self._problem("keyframe", f"keyframe pose skipped: {exc}")
            return
        self._store(self._kf_poses, (stamp_ns, child), T)

    def _store(self, buffer: OrderedDict, key: tuple[int, str], value: np.ndarray) -> None:
        buffer[key] = value
        while len(buffer) > MAX_KEYFRAME_PARTS:
            buffer.popitem(last=False)
        self._complete_cloud()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        try:
            self._camera = camera_from_camera_info(msg)
        except ConversionError as exc:
            self._problem("camera_info", f"VSE camera_info skipped: {exc}")

    def _on_platform_pose(self, msg: PoseStamped) -> None:
        self._platform_input(msg, stopped=False)

    def _on_platform_stopped(self, msg: PoseStamped) -> None:
        self._platform_input(msg, stopped=True)

    def _platform_input(self, msg: PoseStamped, *, stopped: bool) -> None:
        what = "platform stop" if stopped else "platform pose"
        try:
            T, stamp_ns, _ = pose_stamped_to_matrix(msg)
        except ConversionError as exc:
            self._problem("platform", f"{what} skipped: {exc}")
            return
        if self.session is None:
            return
        try:
            if stopped:
                self.session.platform_stopped(T, stamp=stamp_ns * 1e-9)
            else:
                self.session.add_platform_pose(T, stamp=stamp_ns * 1e-9)
        except RacrError as exc:
            self._problem("platform", f"{what} {stamp_ns} skipped: {exc}")

    def _complete_cloud(self, *, at_tick: bool = False) -> None:
        """Hand the pending cloud to the session once its pose, keyframes and camera are there, or when its wait
        was over at two ticks in a row (the input callbacks get their turn between two ticks, so messages that
        queued up while the executor was busy are not missed)."""
        c = self._pending
        if c is None or self.session is None:
            return
        cfg = self.config
        pose = self._poses.get(c.stamp_ns)
        keys = [k for k in self._kf_images if k[0] == c.stamp_ns and k in self._kf_poses]
        complete = pose is not None and len(keys) >= cfg.keyframes_per_cloud and (
            self._camera is not None or cfg.keyframes_per_cloud == 0)
        if not complete:
            if not at_tick or time.monotonic() - c.received < cfg.input_wait_s:
                return
            if not c.expired:
                c.expired = True
                return
        self._pending = None
        if pose is None:
            self.stats["clouds_dropped"] += 1
            self._problem("cloud_pose", f"VSE cloud {c.stamp_ns} dropped: no {VSE_POSE_TOPIC} with its stamp within "
                          f"{cfg.input_wait_s:g} s")
            return
        keyframes = []
        if keys and self._camera is None:
            self._problem("camera_info", f"VSE cloud {c.stamp_ns}: keyframes unused, no {VSE_CAMERA_INFO_TOPIC} yet")
        elif self._camera is not None:
            cam = self._camera
            for k in keys:
                image = self._kf_images[k]
                if image.shape != cam.shape:
                    self._problem("keyframe", f"keyframe {k[1]} of cloud {c.stamp_ns} unused: image "
                                  f"{image.shape[1]}x{image.shape[0]} but camera_info {cam.width}x{cam.height}")
                    continue
                keyframes.append((image, self._kf_poses[k], cam))
        if len(keyframes) < cfg.keyframes_per_cloud:
            self.problems.report("few_keyframes", f"VSE cloud {c.stamp_ns} used with {len(keyframes)} of "
                                 f"{cfg.keyframes_per_cloud} keyframes")
        try:
            self.session.add_vse_observation(c.points, c.intensity, pose, keyframes, stamp=c.stamp_ns * 1e-9)
        except RacrError as exc:
            self.stats["clouds_dropped"] += 1
            self._problem("cloud", f"VSE cloud {c.stamp_ns} skipped: {exc}")
            return
        self._last_cloud_stamp = c.stamp_ns
        self.stats["clouds_used"] += 1

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
                self._problem("thread", f"rACR stopped: {exc}", Level.ERROR, count=False)
                return
            if cmd is not None:
                self._publish_motion(cmd)
        status = session.status
        stamp = status.scheme.estimate_stamp if status.scheme is not None else None
        if stamp is not None and stamp != self._last_estimate_stamp:
            self._last_estimate_stamp = stamp
            self._publish_estimate()
        state = (status.stage, status.motions_issued)
        if state != self._last_state:
            self._last_state = state
            level = _LEVELS[status.level]
            log_at(self.get_logger(), level, f"{status.stage}: {status.message}")
            self._publish_status(status)

    def _publish_motion(self, cmd: MotionCommand) -> None:
        self._last_command = cmd
        stamp_ns = round(cmd.stamp * 1e9)
        self.motion_pub.publish(matrix_to_transform_stamped(cmd.M_hand, stamp_ns=stamp_ns,
                                                            frame_id=PLATFORM_HAND_FRAME,
                                                            child_frame_id=PLATFORM_HAND_GOAL_FRAME))
        t = float(np.linalg.norm(cmd.M_hand[:3, 3]))
        angle = float(rotation_angle_deg(cmd.M_hand[:3, :3]))
        g = "" if cmd.g is None else f", g={cmd.g:.3g}"
        self.get_logger().info(f"{cmd.kind} motion {cmd.index}: {100 * t:.2f} cm, {angle:.2f} deg{g}")

    def _publish_estimate(self) -> None:
        session, ref = self.session, self.reference
        assert session is not None and ref is not None
        now_ns = self.get_clock().now().nanoseconds
        T_ref_cam = session.camera_pose_in_reference()
        if T_ref_cam is not None:
            self.camera_pose_pub.publish(matrix_to_pose_stamped(T_ref_cam, stamp_ns=now_ns, frame_id=ref.frame_id))
        n_max = self.config.aligned_cloud_max_points
        if n_max < 0 or self.aligned_pub.get_subscription_count() == 0:
            return
        cloud = session.aligned_cloud()
        if cloud is None:
            return
        points, intensity = cloud
        if 0 < n_max < len(points):
            keep = np.linspace(0, len(points) - 1, n_max).astype(np.int64)
            points = points[keep]
            intensity = None if intensity is None else intensity[keep]
        extra = {} if intensity is None else {"intensity": intensity}
        self.aligned_pub.publish(xyz_to_pointcloud2(points, stamp_ns=now_ns, frame_id=ref.frame_id,
                                                    extra_fields=extra))

    # ---------------------------------------------------------------------------------------------- status
    def _heartbeat(self) -> None:
        self._publish_status()

    def _publish_status(self, status: SessionStatus | None = None, *,
                        override: tuple[Level, str, str] | None = None) -> None:
        cfg = self.config
        values: dict[str, Any] = {"reference_path": str(self.reference_path), **self.stats,
                                  "platform_subscribed": self.motion_pub.get_subscription_count() > 0,
                                  "eta": cfg.adjustment.eta, "mode": cfg.scheme.mode}
        session = self.session
        if session is None:
            level, message, stage = Level.ERROR, self._reference_error or "loading the reference", STAGE_NO_REFERENCE
            values["stage"] = stage
        else:
            st = status or session.status
            level, message = _LEVELS[st.level], st.message
            if not values["platform_subscribed"] and st.stage not in ("converged", "initialization_failed"):
                level, message = max(level, Level.WARN), f"no platform subscribes to {RACR_HAND_MOTION_TOPIC}; " \
                                                         + message
            values.update(self._session_values(st))
        if override is not None:
            o_level, o_text, key = override
            values["problem"] = key
            if o_level >= level:
                level, message = o_level, o_text
        now_ns = self.get_clock().now().nanoseconds
        self.status_pub.publish(diagnostic_array(now_ns, [diagnostic_status(NODE_NAME, level, message, values)]))

    def _session_values(self, st: SessionStatus) -> dict[str, Any]:
        ref = self.reference
        now = st.time_s
        he = st.hand_eye
        sch = st.scheme
        values: dict[str, Any] = {
            "stage": st.stage,
            "reference_scene": "" if ref is None else ref.scene,
            "reference_points": 0 if ref is None else len(ref.points_m),
            "motions_issued": st.motions_issued,
            "init_motions_done": st.init_motions_done,
            "init_motions_total": st.init_motions_total,
            "init_error": st.init_error,
            "scale_m_per_vse": st.scale_m_per_vse,
            "hand_eye_rotation_residual_deg": None if he is None else he.rotation_residual_deg,
            "hand_eye_translation_residual_m": None if he is None else he.translation_residual_m,
            "T_cam_hand": pose7(st.T_cam_hand),
            "vse_poses": st.vse_poses,
            "vse_observations": st.vse_observations,
            "platform_stops": st.platform_stops,
            "vse_age_s": None if st.last_vse_stamp is None else now - st.last_vse_stamp,
            "platform_age_s": None if st.last_platform_stamp is None else now - st.last_platform_stamp,
            "converged": sch is not None and sch.converged,
        }
        if sch is not None:
            values.update({
                "g": sch.g, "sigma_p": sch.sigma, "estimate_kind": sch.estimate_kind, "adjustments": sch.adjustments,
                "observations": sch.observations, "dropped_observations": sch.dropped_observations,
                "fast_alignments": sch.fast_alignments, "fine_alignments": sch.fine_alignments,
                "alignment_failures": sch.alignment_failures, "last_alignment_error": sch.last_alignment_error,
                "T_ref_cur": pose7(sch.T_ref_cur),
            })
        return values

    # ---------------------------------------------------------------------------------------------- shutdown
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
