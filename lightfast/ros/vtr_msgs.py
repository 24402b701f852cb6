"""Message conversions of the VT&R topics (``vtr_localizer_node``): a stereo camera's ``camera_info`` to the
rectified projection the localizer uses, and a localization to ``geometry_msgs/PoseWithCovarianceStamped``.

Duck-typed like :mod:`lightfast.ros.convert` (rclpy and rosbags messages alike; builders take ``types``); nothing
here imports rclpy. Only the rectified projection ``P`` and the image size of a ``camera_info`` matter: the
images must already be rectified, so ``D``, ``K`` and ``R`` are ignored.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from lightfast.ros.convert import make_header, matrix_to_pose
from lightfast.ros.errors import ConversionError
from lightfast.ros.msgtypes import RCLPY, MessageTypes
from lightfast.vtr.errors import VtrError
from lightfast.vtr.localizer import LocalizationOut, StereoCamera
from lightfast.vtr.stereo_front_end import check_projection

__all__ = ["localization_to_msg", "stereo_camera"]


def stereo_camera(msg: Any, side: str) -> StereoCamera:
    """The rectified projection matrix and image size of the ``side`` camera's ``camera_info``."""
    width, height = int(msg.width), int(msg.height)
    if width <= 0 or height <= 0:
        raise ConversionError(f"width={width} and height={height} must be > 0 (camera not calibrated?)")
    p = np.asarray(msg.p, dtype=np.float64)
    if p.size != 12 or not np.any(p != 0.0):
        raise ConversionError("P is zero: no rectified projection matrix (camera not calibrated?)")
    try:
        return StereoCamera(check_projection(p, f"P of the {side} camera"), (width, height))
    except VtrError as exc:
        raise ConversionError(str(exc)) from None


def localization_to_msg(loc: LocalizationOut, *, types: MessageTypes = RCLPY) -> Any:
    """``T_kf_cam`` with its 6×6 covariance, in the keyframe's frame, stamped like the stereo pair."""
    pose = types.new("geometry_msgs/msg/PoseWithCovariance", pose=matrix_to_pose(loc.T_kf_cam, types=types),
                     covariance=types.float64_array(loc.covariance))
    return types.new("geometry_msgs/msg/PoseWithCovarianceStamped",
                     header=make_header(loc.stamp_ns, loc.keyframe_frame, types=types), pose=pose)
