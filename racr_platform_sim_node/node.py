"""``racr_platform_sim_node``: the simulated robotic platform of a live rACR run (paper §3.6: 1.5 s per cm), with
the simulator of :mod:`lightfast.sim.racr_platform` and the timing of :class:`lightfast.sim.racr_live.TimedPlatform`.

Parameters: ``config/racr_platform_sim_node.yaml``, from :class:`lightfast.sim.racr_live.RacrPlatformSimConfig`
(the mechanical error and speed of :class:`~lightfast.sim.racr_platform.PlatformConfig`, ``scene_path``, ``seed``,
``time_scale``, ``state_rate_hz``). The platform starts with the camera at the scene's initial pose and carries it
at the scene's hand–eye transform X.

Input: ``/racr/hand_motion`` (``geometry_msgs/TransformStamped`` ``platform_hand → platform_hand_goal``): the
relative hand motion ``M_B = T_hand_hand'`` to execute (``T_base_hand' = T_base_hand · M_B``). The platform
executes it with mechanical error; it takes the simulated duration (1.5 s per cm + 0.5 s per degree) divided by
``time_scale`` in wall time. A command that is not a rigid transform in ``platform_hand``, exceeds the limits, or
arrives while a motion runs is refused: nothing moves, the status says why, and the platform reports that it is at
rest (a stop) at once.

Outputs:

* ``/platform/pose`` (``PoseStamped``, ``platform_base``): the reported hand pose ``T_base_hand`` (the encoders:
  the product of the commanded motions; the mechanical error is invisible to them), at ``state_rate_hz`` and on
  every stop. While moving it is the pose the motion started from.
* ``/platform/stopped`` (``PoseStamped``, ``platform_base``): once per command, when the platform is at rest again,
  stamped at that moment, with the reported hand pose. A client knows the platform is moving from its command until
  a stop stamped at or after the command.
* ``/platform/status`` (``DiagnosticArray``): moving, motions executed / refused, the simulated time spent moving,
  the last refusal.
* ``/sim/ground_truth/camera_pose`` (``PoseStamped``, ``world``): the TRUE camera pose, stamped at the last stop
  (republished at ``state_rate_hz`` with that stamp). For the VSE stand-in, which renders from it, and for
  evaluations; ``racr_node`` never subscribes to it.
"""
from __future__ import annotations

import sys
from typing import Any

from geometry_msgs.msg import PoseStamped, TransformStamped
from rclpy.timer import Timer

from lightfast.ros.convert import matrix_to_pose_stamped
from lightfast.ros.diagnostics import Level
from lightfast.ros.errors import ConversionError
from lightfast.ros.node import LightfastNode
from lightfast.ros.qos import OUTPUT_QOS
from lightfast.ros.racr_msgs import transform_stamped_to_matrix
from lightfast.ros.runtime import run_node
from lightfast.sim.racr_live import RacrPlatformSimConfig, TimedPlatform, load_node_scene
from lightfast.topics import (
    PLATFORM_BASE_FRAME,
    PLATFORM_HAND_FRAME,
    PLATFORM_POSE_TOPIC,
    PLATFORM_STATUS_TOPIC,
    PLATFORM_STOPPED_TOPIC,
    RACR_HAND_MOTION_TOPIC,
    SIM_CAMERA_POSE_TOPIC,
    SIM_WORLD_FRAME,
)

NODE_NAME = "racr_platform_sim_node"


class RacrPlatformSimNode(LightfastNode[RacrPlatformSimConfig]):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, RacrPlatformSimConfig, status_topic=PLATFORM_STATUS_TOPIC, **kwargs)
        cfg = self.params.config
        scene = load_node_scene(cfg.scene_path)
        self.scene_name = scene.spec.name
        self.platform = TimedPlatform(scene.make_platform(cfg.platform_config(), seed=cfg.seed),
                                      time_scale=cfg.time_scale)
        self.last_error = ""
        self.commands = 0
        self.bad_commands = 0  # not even a rigid transform in platform_hand
        self._truth_stamp_ns = self.now_ns()
        self._stop_timer: Timer | None = None
        self.pose_pub = self.create_publisher(PoseStamped, PLATFORM_POSE_TOPIC, OUTPUT_QOS)
        self.stopped_pub = self.create_publisher(PoseStamped, PLATFORM_STOPPED_TOPIC, OUTPUT_QOS)
        self.truth_pub = self.create_publisher(PoseStamped, SIM_CAMERA_POSE_TOPIC, OUTPUT_QOS)
        self.create_subscription(TransformStamped, RACR_HAND_MOTION_TOPIC, self._on_command, OUTPUT_QOS)
        self.state_timer = self.create_timer(1.0 / cfg.state_rate_hz, self._publish_state)
        self.get_logger().info(f"platform of scene {self.scene_name} ready (time_scale {cfg.time_scale:g}); "
                               f"executing {RACR_HAND_MOTION_TOPIC}")
        self._publish_state()
        self.announce_ready()

    # ------------------------------------------------------------------------------------------------ input
    def _on_command(self, msg: TransformStamped) -> None:
        self.commands += 1
        now_ns = self.now_ns()
        try:
            M, _, frame_id, _ = transform_stamped_to_matrix(msg)
            if frame_id != PLATFORM_HAND_FRAME:
                raise ConversionError(f"a hand motion must be expressed in {PLATFORM_HAND_FRAME!r}, got frame_id "
                                      f"{frame_id!r}")
        except ConversionError as exc:
            self.bad_commands += 1
            self._refuse(f"hand motion refused: {exc}", now_ns)
            return
        start = self.platform.command(M, now_ns * 1e-9)
        if not start.accepted:
            self._refuse(f"hand motion refused: {start.error}", now_ns)
            return
        wait_s = max(start.stop_due - now_ns * 1e-9, 0.0)
        self._stop_timer = self.create_timer(max(wait_s, 1e-4), self._on_stop_due)
        self.publish_status(Level.OK, f"executing a motion of {start.duration_s:.2f} simulated s")

    def _refuse(self, text: str, now_ns: int) -> None:
        self.last_error = text
        self.problems.report("refused", text)
        if not self.platform.moving:  # at rest: report the stop that ends this command
            self.platform.poll(now_ns * 1e-9)
            self._stopped(now_ns)
        self.publish_status(Level.WARN, text)

    def _on_stop_due(self) -> None:
        timer, self._stop_timer = self._stop_timer, None
        if timer is not None:
            timer.cancel()
            self.destroy_timer(timer)
        now_ns = self.now_ns()
        if self.platform.poll(now_ns * 1e-9):
            self._stopped(now_ns)
            self.publish_status(Level.OK, "at rest")
        elif self.platform.moving:  # the timer fired a little early
            self._stop_timer = self.create_timer(1e-3, self._on_stop_due)

    # ------------------------------------------------------------------------------------------------ output
    def _stopped(self, now_ns: int) -> None:
        self._truth_stamp_ns = now_ns
        T = self.platform.reported_hand_pose
        self.stopped_pub.publish(matrix_to_pose_stamped(T, stamp_ns=now_ns, frame_id=PLATFORM_BASE_FRAME))
        self.pose_pub.publish(matrix_to_pose_stamped(T, stamp_ns=now_ns, frame_id=PLATFORM_BASE_FRAME))
        self._publish_truth()

    def _publish_truth(self) -> None:
        self.truth_pub.publish(matrix_to_pose_stamped(self.platform.true_camera_pose, stamp_ns=self._truth_stamp_ns,
                                                      frame_id=SIM_WORLD_FRAME))

    def _publish_state(self) -> None:
        now_ns = self.now_ns()
        self.pose_pub.publish(matrix_to_pose_stamped(self.platform.reported_hand_pose, stamp_ns=now_ns,
                                                     frame_id=PLATFORM_BASE_FRAME))
        self._publish_truth()
        self.publish_status(Level.OK, "moving" if self.platform.moving else "at rest")

    def status_values(self) -> dict[str, Any]:
        p = self.platform
        return {"scene": self.scene_name, "moving": p.moving, "commands": self.commands, "executed": p.executed,
                "refused": p.refused, "bad_commands": self.bad_commands, "simulated_time_s": p.simulated_time_s,
                "time_scale": p.time_scale, "last_error": self.last_error}


def main(args: list[str] | None = None) -> int:
    return run_node(RacrPlatformSimNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
