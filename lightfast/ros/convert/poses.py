"""``geometry_msgs`` poses and ``nav_msgs/Odometry`` ↔ 4×4 homogeneous transforms.

Poses are 4×4 homogeneous transforms ``T_frame_child`` in float64 (metres), mapping points of the child frame into
the parent frame: for ``PoseStamped`` (and ``PoseWithCovarianceStamped``) the parent is ``header.frame_id``; for
``Odometry`` the pose maps ``child_frame_id`` into ``header.frame_id`` (the twist, m/s and rad/s, is expressed in
``child_frame_id``). Quaternions are ``(x, y, z, w)``; read ones within :data:`QUATERNION_NORM_TOLERANCE` of unit
norm are normalized, written ones have ``w >= 0``. Stamps come back as integer nanoseconds.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from lightfast.ros.convert.header import _header_of, make_header
from lightfast.ros.errors import PoseConversionError
from lightfast.ros.msgtypes import RCLPY, MessageTypes

__all__ = [
    "QUATERNION_NORM_TOLERANCE",
    "ROTATION_TOLERANCE",
    "matrix_to_odometry",
    "matrix_to_pose",
    "matrix_to_pose_stamped",
    "odometry_to_matrix",
    "pose_stamped_to_matrix",
    "pose_to_matrix",
    "pose_with_covariance_to_matrix",
]

QUATERNION_NORM_TOLERANCE = 1e-3
"""Quaternions with ``|norm - 1| <= QUATERNION_NORM_TOLERANCE`` are normalized; others are rejected."""

ROTATION_TOLERANCE = 1e-5
"""Largest ``|RᵀR - I|`` element (and ``|det R - 1|``) accepted for the rotation part of a transform."""


def _vector3(v: Any) -> NDArray[np.float64]:
    return np.array([float(v.x), float(v.y), float(v.z)])


def _pose_to_matrix(pose: Any, what: str) -> NDArray[np.float64]:
    p = _vector3(pose.position)
    o = pose.orientation
    q = np.array([float(o.x), float(o.y), float(o.z), float(o.w)])
    if not np.all(np.isfinite(p)):
        raise PoseConversionError(f"{what}.position={p.tolist()} is not finite")
    if not np.all(np.isfinite(q)):
        raise PoseConversionError(f"{what}.orientation={q.tolist()} is not finite")
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise PoseConversionError(
            f"{what}.orientation (x, y, z, w)={q.tolist()} has norm {norm:.6g}, not a unit quaternion "
            f"(tolerance {QUATERNION_NORM_TOLERANCE})"
        )
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(q / norm).as_matrix()
    T[:3, 3] = p
    return T


def pose_to_matrix(pose: Any) -> NDArray[np.float64]:
    """The 4×4 transform of a ``geometry_msgs/Pose`` (metres). Near-unit quaternions are normalized."""
    return _pose_to_matrix(pose, "Pose")


def _split_transform(T: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    M = np.asarray(T, dtype=np.float64)
    if M.shape != (4, 4):
        raise PoseConversionError(f"transform must have shape (4, 4), got {M.shape}")
    if not np.all(np.isfinite(M)):
        raise PoseConversionError("transform has non-finite entries")
    if np.max(np.abs(M[3] - [0.0, 0.0, 0.0, 1.0])) > ROTATION_TOLERANCE:
        raise PoseConversionError(f"transform's last row must be [0, 0, 0, 1], got {M[3].tolist()}")
    R = M[:3, :3]
    orthogonality = float(np.max(np.abs(R.T @ R - np.eye(3))))
    det = float(np.linalg.det(R))
    if orthogonality > ROTATION_TOLERANCE or abs(det - 1.0) > ROTATION_TOLERANCE:
        raise PoseConversionError(
            f"transform's rotation part is not a rotation: max |RᵀR - I| = {orthogonality:.3g}, det = {det:.6g} "
            f"(tolerance {ROTATION_TOLERANCE})"
        )
    return R, M[:3, 3]


def matrix_to_pose(T: ArrayLike, *, types: MessageTypes = RCLPY) -> Any:
    """A ``geometry_msgs/Pose`` of a 4×4 rigid transform (quaternion with ``w >= 0``).

    Raises :class:`PoseConversionError` unless the rotation part is a rotation within :data:`ROTATION_TOLERANCE`.
    """
    R, t = _split_transform(T)
    x, y, z, w = (float(c) for c in Rotation.from_matrix(R).as_quat(canonical=True))
    return types.new(
        "geometry_msgs/msg/Pose",
        position=types.new("geometry_msgs/msg/Point", x=float(t[0]), y=float(t[1]), z=float(t[2])),
        orientation=types.new("geometry_msgs/msg/Quaternion", x=x, y=y, z=z, w=w),
    )


def pose_stamped_to_matrix(msg: Any) -> tuple[NDArray[np.float64], int, str]:
    """``(T_frame_pose, stamp_ns, frame_id)`` of a ``geometry_msgs/PoseStamped``."""
    stamp_ns, frame_id = _header_of(msg)
    return _pose_to_matrix(msg.pose, "PoseStamped.pose"), stamp_ns, frame_id


def pose_with_covariance_to_matrix(msg: Any) -> tuple[NDArray[np.float64], int, str]:
    """``(T_frame_pose, stamp_ns, frame_id)`` of a ``geometry_msgs/PoseWithCovarianceStamped`` (RViz's
    ``/initialpose``); the covariance is not read."""
    stamp_ns, frame_id = _header_of(msg)
    return _pose_to_matrix(msg.pose.pose, "PoseWithCovarianceStamped.pose.pose"), stamp_ns, frame_id


def matrix_to_pose_stamped(T: ArrayLike, *, stamp_ns: int, frame_id: str, types: MessageTypes = RCLPY) -> Any:
    """A ``geometry_msgs/PoseStamped`` of the transform ``T`` expressed in ``frame_id``."""
    return types.new(
        "geometry_msgs/msg/PoseStamped",
        header=make_header(stamp_ns, frame_id, types=types),
        pose=matrix_to_pose(T, types=types),
    )


def odometry_to_matrix(msg: Any) -> tuple[NDArray[np.float64], int, str, str]:
    """``(T_frame_child, stamp_ns, frame_id, child_frame_id)`` of a ``nav_msgs/Odometry``."""
    stamp_ns, frame_id = _header_of(msg)
    return _pose_to_matrix(msg.pose.pose, "Odometry.pose.pose"), stamp_ns, frame_id, str(msg.child_frame_id)


def _optional_array(value: ArrayLike | None, name: str, shapes: tuple[tuple[int, ...], ...]) -> NDArray[np.float64]:
    if value is None:
        return np.zeros(shapes[0])
    a = np.asarray(value, dtype=np.float64)
    if a.shape not in shapes:
        raise PoseConversionError(f"{name} must have shape {' or '.join(map(str, shapes))}, got {a.shape}")
    return a


def matrix_to_odometry(
    T: ArrayLike,
    *,
    stamp_ns: int,
    frame_id: str,
    child_frame_id: str,
    twist_linear: ArrayLike | None = None,
    twist_angular: ArrayLike | None = None,
    pose_covariance: ArrayLike | None = None,
    twist_covariance: ArrayLike | None = None,
    types: MessageTypes = RCLPY,
) -> Any:
    """A ``nav_msgs/Odometry`` with pose ``T`` (``child_frame_id`` in ``frame_id``).

    The twist (m/s, rad/s) is in ``child_frame_id``; covariances are ``(6, 6)`` or ``(36,)``, row-major over
    ``(x, y, z, rot_x, rot_y, rot_z)``. Omitted values are zeros (a zero covariance means "unknown").
    """
    linear = _optional_array(twist_linear, "twist_linear", ((3,),))
    angular = _optional_array(twist_angular, "twist_angular", ((3,),))
    pose_cov = _optional_array(pose_covariance, "pose_covariance", ((36,), (6, 6)))
    twist_cov = _optional_array(twist_covariance, "twist_covariance", ((36,), (6, 6)))

    def vector3(v: NDArray[np.float64]) -> Any:
        return types.new("geometry_msgs/msg/Vector3", x=float(v[0]), y=float(v[1]), z=float(v[2]))

    twist = types.new("geometry_msgs/msg/Twist", linear=vector3(linear), angular=vector3(angular))
    return types.new(
        "nav_msgs/msg/Odometry",
        header=make_header(stamp_ns, frame_id, types=types),
        child_frame_id=child_frame_id,
        pose=types.new(
            "geometry_msgs/msg/PoseWithCovariance",
            pose=matrix_to_pose(T, types=types),
            covariance=types.float64_array(pose_cov),
        ),
        twist=types.new(
            "geometry_msgs/msg/TwistWithCovariance", twist=twist, covariance=types.float64_array(twist_cov)
        ),
    )

