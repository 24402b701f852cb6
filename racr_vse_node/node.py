"""``racr_vse_node``: the VSE (visual SLAM engine) stand-in of a live rACR run (paper §3.3: a monocular direct SLAM
such as DSO), with :class:`lightfast.sim.racr_platform.VseStandIn` rendering the scene by ray casting (Embree).

Parameters: ``config/racr_vse_node.yaml``, from :class:`lightfast.sim.racr_live.RacrVseSimConfig` (keyframes,
point selection, noise and drift of :class:`~lightfast.sim.racr_platform.VseConfig`, ``scene_path``, ``lighting``,
``seed``, ``scale_m_per_vse``, ``republish_s``).

Input: ``/sim/ground_truth/camera_pose`` (``PoseStamped``, ``world``) from the platform simulator: the true camera
pose, stamped when the platform came to rest. Each new stamp is one observation: the stand-in renders its keyframes
at and around that pose and publishes, stamped with the time the rendering started (after the stop) — the camera's
capture time:

* ``/vse/camera_info`` (``CameraInfo``): the keyframe camera (rectified, no distortion);
* per keyframe ``/vse/keyframe/image`` (``mono8`` grey, ``frame_id`` ``vse_keyframe_<id>``) and
  ``/vse/keyframe/pose`` (``TransformStamped`` ``vse → vse_keyframe_<id>``, the keyframe pose ``T_vse_cam`` in VSE
  units), all with the observation's stamp;
* ``/vse/pose`` (``PoseStamped``, ``vse``): the current camera pose ``T_vse_cam`` (VSE units);
* ``/vse/points`` (``PointCloud2``, ``vse``): the semi-dense cloud, float32 ``x, y, z`` in VSE units (an unknown
  monocular scale) and ``intensity`` = grey value / 255 of the host keyframe, published last.

The last observation is republished every ``republish_s`` with its original stamps (a subscriber that joined late
gets it; ``racr_node`` ignores repeats). The stand-in reads the truth — it is the simulator — but publishes only
what a real VSE would.
"""
from __future__ import annotations

import sys
from typing import Any

from geometry_msgs.msg import PoseStamped, TransformStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from lightfast.errors import LightfastError
from lightfast.ros.convert import (
    camera_info_from_camera,
    matrix_to_pose_stamped,
    numpy_to_image,
    pose_stamped_to_matrix,
    xyz_to_pointcloud2,
)
from lightfast.ros.diagnostics import Level
from lightfast.ros.errors import ConversionError
from lightfast.ros.node import LightfastNode
from lightfast.ros.qos import OUTPUT_QOS
from lightfast.ros.racr_msgs import matrix_to_transform_stamped
from lightfast.ros.runtime import run_node
from lightfast.sim.racr_live import RacrVseSimConfig, load_node_scene
from lightfast.sim.racr_platform import VseObservation
from lightfast.topics import (
    SIM_CAMERA_POSE_TOPIC,
    VSE_CAMERA_INFO_TOPIC,
    VSE_FRAME,
    VSE_KEYFRAME_FRAME_PREFIX,
    VSE_KEYFRAME_IMAGE_TOPIC,
    VSE_KEYFRAME_POSE_TOPIC,
    VSE_POINTS_TOPIC,
    VSE_POSE_TOPIC,
    VSE_STATUS_TOPIC,
)

NODE_NAME = "racr_vse_node"
#: Keyframe topics keep every keyframe of an observation (at most 16, VseConfig.n_keyframes).
KEYFRAME_QOS = QoSProfile(depth=32, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


class RacrVseNode(LightfastNode[RacrVseSimConfig]):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, RacrVseSimConfig, status_topic=VSE_STATUS_TOPIC, **kwargs)
        cfg = self.params.config
        scene = load_node_scene(cfg.scene_path)
        self.scene_name = scene.spec.name
        self.vse = scene.make_vse(cfg.lighting, config=cfg.vse_config(), seed=cfg.seed,
                                  scale_m_per_vse=cfg.scale_m_per_vse or None)
        self.observations = 0
        self._keyframe_id = 0
        self._last_truth_stamp: int | None = None
        self._last_messages: list[tuple[Any, Any]] = []
        self.info_pub = self.create_publisher(CameraInfo, VSE_CAMERA_INFO_TOPIC, OUTPUT_QOS)
        self.image_pub = self.create_publisher(Image, VSE_KEYFRAME_IMAGE_TOPIC, KEYFRAME_QOS)
        self.kf_pose_pub = self.create_publisher(TransformStamped, VSE_KEYFRAME_POSE_TOPIC, KEYFRAME_QOS)
        self.pose_pub = self.create_publisher(PoseStamped, VSE_POSE_TOPIC, OUTPUT_QOS)
        self.points_pub = self.create_publisher(PointCloud2, VSE_POINTS_TOPIC, OUTPUT_QOS)
        self.create_subscription(PoseStamped, SIM_CAMERA_POSE_TOPIC, self._on_truth, OUTPUT_QOS)
        self.create_timer(cfg.republish_s, self._republish)
        self.get_logger().info(f"VSE stand-in for scene {self.scene_name} under the {cfg.lighting!r} lighting")
        self.announce_ready()

    def _on_truth(self, msg: PoseStamped) -> None:
        try:
            T_world_cam, stamp_ns, _ = pose_stamped_to_matrix(msg)
        except ConversionError as exc:
            self.problems.report("truth", f"ground-truth camera pose skipped: {exc}")
            return
        if stamp_ns == self._last_truth_stamp:
            return  # a repeat of the pose already observed
        self._last_truth_stamp = stamp_ns
        obs_stamp = max(self.now_ns(), stamp_ns + 1)  # captured after the stop
        try:
            obs = self.vse.observe(T_world_cam, stamp_s=obs_stamp * 1e-9)
        except (LightfastError, ValueError) as exc:
            self.problems.report("observe", f"observation failed: {exc}", Level.ERROR)
            return
        self.observations += 1
        self._last_messages = self._messages(obs, obs_stamp)
        for pub, msg_out in self._last_messages:
            pub.publish(msg_out)
        values = {"scene": self.scene_name, "observations": self.observations, "points": len(obs.points_vse),
                  "keyframes": len(obs.keyframes), "stamp_ns": obs_stamp}
        self.publish_status(Level.OK, f"observation {self.observations}: {len(obs.points_vse)} points", values,
                            stamp_ns=obs_stamp)

    def _messages(self, obs: VseObservation, stamp_ns: int) -> list[tuple[Any, Any]]:
        """The messages of one observation in publishing order (camera_info, keyframes, pose, cloud last)."""
        out: list[tuple[Any, Any]] = []
        camera = obs.keyframes[0].camera if obs.keyframes else self.vse.kf_camera
        out.append((self.info_pub, camera_info_from_camera(camera, stamp_ns=stamp_ns, frame_id=VSE_FRAME)))
        for kf in obs.keyframes:
            self._keyframe_id += 1
            frame = f"{VSE_KEYFRAME_FRAME_PREFIX}{self._keyframe_id}"
            out.append((self.image_pub, numpy_to_image(kf.image, "mono8", stamp_ns=stamp_ns, frame_id=frame)))
            out.append((self.kf_pose_pub, matrix_to_transform_stamped(kf.T_vse_cam, stamp_ns=stamp_ns,
                                                                      frame_id=VSE_FRAME, child_frame_id=frame)))
        out.append((self.pose_pub, matrix_to_pose_stamped(obs.T_vse_cam, stamp_ns=stamp_ns, frame_id=VSE_FRAME)))
        out.append((self.points_pub, xyz_to_pointcloud2(obs.points_vse, stamp_ns=stamp_ns, frame_id=VSE_FRAME,
                                                        extra_fields={"intensity": obs.intensity})))
        return out

    def _republish(self) -> None:
        for pub, msg in self._last_messages:
            pub.publish(msg)


def main(args: list[str] | None = None) -> int:
    return run_node(RacrVseNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
