"""Conversions between ROS 2 messages and NumPy arrays, for rclpy messages and rosbags messages alike.

Reading is duck-typed: any object with the message's field names works (rclpy messages, rosbags dataclasses,
test doubles). Building takes the keyword ``types`` (:mod:`lightfast.ros.msgtypes`): :data:`~.msgtypes.RCLPY`
(default) or ``rosbags_types()``. Nothing here imports rclpy. One module per message family, each stating its
conventions (frames, units, invalid values); every name is importable from this package:

* :mod:`.header`: ``builtin_interfaces/Time`` ↔ integer nanoseconds ``stamp_ns``, ``std_msgs/Header``;
* :mod:`.images`: ``sensor_msgs/Image`` ↔ ``(H, W)`` / ``(H, W, C)`` arrays (colour, depth in mm or m);
* :mod:`.clouds`: ``sensor_msgs/PointCloud2`` ↔ structured point arrays (metres, in ``header.frame_id``);
* :mod:`.poses`: ``geometry_msgs/Pose(Stamped)``, ``PoseWithCovarianceStamped``, ``nav_msgs/Odometry`` ↔ 4×4
  transforms ``T_frame_child`` (float64, metres; quaternions ``(x, y, z, w)``);
* :mod:`.camera_info`: ``sensor_msgs/CameraInfo`` ↔ :class:`lightfast.camera.PinholeCamera` (+ an Undistorter
  for a lens-distorted camera).
"""
from __future__ import annotations

from lightfast.ros.convert.camera_info import (
    SUPPORTED_DISTORTION_MODELS,
    CameraInfoReader,
    camera_from_camera_info,
    camera_info_from_camera,
    undistorter_from_camera_info,
)
from lightfast.ros.convert.clouds import (
    PointCloud2Fields,
    PointFieldSpec,
    numpy_to_pointcloud2,
    pointcloud2_fields,
    pointcloud2_to_numpy,
    xyz_to_pointcloud2,
)
from lightfast.ros.convert.header import make_header, ns_to_stamp, stamp_to_ns
from lightfast.ros.convert.images import (
    COLOR_ENCODINGS,
    IMAGE_ENCODINGS,
    ImageEncoding,
    ImageFields,
    depth_to_metres,
    image_fields,
    image_to_numpy,
    image_to_rgb,
    numpy_to_image,
)
from lightfast.ros.convert.poses import (
    QUATERNION_NORM_TOLERANCE,
    ROTATION_TOLERANCE,
    matrix_to_odometry,
    matrix_to_pose,
    matrix_to_pose_stamped,
    odometry_to_matrix,
    pose_stamped_to_matrix,
    pose_to_matrix,
    pose_with_covariance_to_matrix,
)

__all__ = [
    "COLOR_ENCODINGS",
    "IMAGE_ENCODINGS",
    "QUATERNION_NORM_TOLERANCE",
    "ROTATION_TOLERANCE",
    "SUPPORTED_DISTORTION_MODELS",
    "CameraInfoReader",
    "ImageEncoding",
    "ImageFields",
    "PointCloud2Fields",
    "PointFieldSpec",
    "camera_from_camera_info",
    "camera_info_from_camera",
    "depth_to_metres",
    "image_fields",
    "image_to_numpy",
    "image_to_rgb",
    "make_header",
    "matrix_to_odometry",
    "matrix_to_pose",
    "matrix_to_pose_stamped",
    "ns_to_stamp",
    "numpy_to_image",
    "numpy_to_pointcloud2",
    "odometry_to_matrix",
    "pointcloud2_fields",
    "pointcloud2_to_numpy",
    "pose_stamped_to_matrix",
    "pose_to_matrix",
    "pose_with_covariance_to_matrix",
    "stamp_to_ns",
    "undistorter_from_camera_info",
    "xyz_to_pointcloud2",
]
