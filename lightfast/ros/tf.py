"""Poses as TF: transforms on ``/tf`` as ``tf2_ros.TransformBroadcaster`` sends them.

tf2_ros has no wheel here, and tf2_msgs neither: ``scripts/setup.sh`` builds tf2_msgs' one interface with the
rosidl toolchain from PyPI (a real Jazzy install has it). When ``tf2_msgs`` cannot be imported, a
:class:`TransformBroadcaster` says so once in the node's log and sends nothing.
"""
from __future__ import annotations

from typing import Any

from numpy.typing import ArrayLike
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from lightfast.ros.convert import make_header, matrix_to_pose

__all__ = ["TF_QOS", "TF_TOPIC", "TransformBroadcaster", "transform_stamped"]

TF_TOPIC = "/tf"
#: tf2_ros' QoS of /tf: reliable, volatile, depth 100.
TF_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)


def transform_stamped(T_parent_child: ArrayLike, *, stamp_ns: int, parent_frame: str, child_frame: str) -> Any:
    """A ``geometry_msgs/TransformStamped`` holding the 4x4 ``T_parent_child`` (the child frame's pose in the
    parent's), as tf2 defines it: header.frame_id = parent, child_frame_id = child."""
    from geometry_msgs.msg import Transform, TransformStamped, Vector3

    pose = matrix_to_pose(T_parent_child)
    p = pose.position
    return TransformStamped(header=make_header(stamp_ns, parent_frame), child_frame_id=child_frame,
                            transform=Transform(translation=Vector3(x=p.x, y=p.y, z=p.z), rotation=pose.orientation))


class TransformBroadcaster:
    """Sends transforms on ``/tf`` from ``node``."""

    def __init__(self, node: Node) -> None:
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError:
            self._message = None
            self._publisher = None
            node.get_logger().warning("tf2_msgs is not installed: no transforms on /tf (scripts/setup.sh builds it; "
                                      "on a real ROS 2 install it comes with ros-jazzy-tf2-msgs)")
            return
        self._message = TFMessage
        self._publisher = node.create_publisher(TFMessage, TF_TOPIC, TF_QOS)

    def send(self, *transforms: Any) -> None:
        """Publish ``TransformStamped`` messages (one TFMessage)."""
        if self._publisher is not None and self._message is not None and transforms:
            self._publisher.publish(self._message(transforms=list(transforms)))
