"""Message conversions of the rACR topics (``racr_node``, the platform simulator, the VSE stand-in): relative hand
motions and keyframe poses as ``geometry_msgs/TransformStamped``, the VSE cloud with intensities, keyframe images.

Duck-typed like :mod:`lightfast.ros.convert` (rclpy and rosbags messages alike; builders take ``types``); nothing
here imports rclpy. Conventions (README, rACR topics):

* ``TransformStamped`` ``T_parent_child`` maps points of ``child_frame_id`` into ``header.frame_id`` (REP-105);
  a hand motion ``M_B = T_hand_hand'`` is published as ``platform_hand → platform_hand_goal``, a keyframe pose
  ``T_vse_cam`` as ``vse → vse_keyframe_<id>``.
* ``/vse/points``: float ``x, y, z`` (VSE units) and an optional float ``intensity`` field in the units of the
  keyframe images after :func:`keyframe_image_to_float` (grey value / 255 for ``mono8``).
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.ros.convert import (
    image_to_numpy,
    make_header,
    matrix_to_pose,
    pointcloud2_to_numpy,
    stamp_to_ns,
)
from lightfast.ros.convert.poses import _pose_to_matrix
from lightfast.ros.errors import ImageConversionError, PointCloudConversionError
from lightfast.ros.msgtypes import RCLPY, MessageTypes

__all__ = [
    "KEYFRAME_ENCODINGS",
    "keyframe_image_to_float",
    "matrix_to_transform_stamped",
    "transform_stamped_to_matrix",
    "vse_cloud_to_arrays",
]

#: Keyframe image encodings and the factor that maps them to [0, 1] (32FC1 is taken as it is).
KEYFRAME_ENCODINGS = {"mono8": 1.0 / 255.0, "mono16": 1.0 / 65535.0, "32FC1": 1.0}


class _PoseView:
    """A Transform seen as a Pose (``translation`` → ``position``, ``rotation`` → ``orientation``)."""

    def __init__(self, transform: Any) -> None:
        self.position = transform.translation
        self.orientation = transform.rotation


def transform_stamped_to_matrix(msg: Any) -> tuple[NDArray[np.float64], int, str, str]:
    """``(T_frame_child, stamp_ns, frame_id, child_frame_id)`` of a ``geometry_msgs/TransformStamped``; raises
    :class:`~lightfast.ros.errors.PoseConversionError` for non-finite values or a non-unit quaternion."""
    T = _pose_to_matrix(_PoseView(msg.transform), "TransformStamped.transform")
    return T, stamp_to_ns(msg.header.stamp), str(msg.header.frame_id), str(msg.child_frame_id)


def matrix_to_transform_stamped(T: ArrayLike, *, stamp_ns: int, frame_id: str, child_frame_id: str,
                                types: MessageTypes = RCLPY) -> Any:
    """A ``geometry_msgs/TransformStamped`` of the rigid 4×4 ``T`` (``child_frame_id`` in ``frame_id``)."""
    pose = matrix_to_pose(T, types=types)
    p, q = pose.position, pose.orientation
    return types.new(
        "geometry_msgs/msg/TransformStamped",
        header=make_header(stamp_ns, frame_id, types=types),
        child_frame_id=child_frame_id,
        transform=types.new(
            "geometry_msgs/msg/Transform",
            translation=types.new("geometry_msgs/msg/Vector3", x=p.x, y=p.y, z=p.z),
            rotation=types.new("geometry_msgs/msg/Quaternion", x=q.x, y=q.y, z=q.z, w=q.w),
        ),
    )


def vse_cloud_to_arrays(msg: Any) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """``(points (N, 3), intensity (N,) or None)`` of a VSE ``PointCloud2`` (float64 copies). Needs float fields
    ``x``, ``y``, ``z``; ``intensity`` is optional. Non-finite values are kept (the core drops those rows)."""
    cloud = pointcloud2_to_numpy(msg)
    names = cloud.dtype.names or ()
    missing = [n for n in ("x", "y", "z") if n not in names]
    if missing:
        raise PointCloudConversionError(f"PointCloud2 has no field(s) {missing} (fields: {list(names)})")
    fields: Mapping[str, Any] = cloud.dtype.fields or {}  # None only without names: then x is missing above
    for n in ("x", "y", "z", "intensity"):
        if n in names and fields[n][0].shape:
            raise PointCloudConversionError(f"PointCloud2 field {n!r} must have count 1")
    xyz = np.stack([cloud[n].astype(np.float64) for n in ("x", "y", "z")], axis=1).reshape(-1, 3)
    inten = cloud["intensity"].astype(np.float64) if "intensity" in names else None
    return xyz, inten


def keyframe_image_to_float(msg: Any) -> NDArray[np.float64]:
    """A keyframe ``Image`` as float64 ``(H, W)`` in [0, 1] (``mono8`` / 255, ``mono16`` / 65535, ``32FC1`` as
    is), the units of the cloud's ``intensity``."""
    factor = KEYFRAME_ENCODINGS.get(msg.encoding)
    if factor is None:
        raise ImageConversionError(f"keyframe image encoding {msg.encoding!r} is not supported (use one of "
                                   f"{', '.join(KEYFRAME_ENCODINGS)})")
    return image_to_numpy(msg).astype(np.float64) * factor

