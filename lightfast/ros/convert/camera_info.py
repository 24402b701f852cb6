"""``sensor_msgs/CameraInfo`` ↔ :class:`lightfast.camera.PinholeCamera` (+ :class:`~lightfast.camera.Undistorter`).

:class:`~lightfast.camera.PinholeCamera` models undistorted images only (REP-103 optical frame, intrinsics in px;
no binning, full-image ROI); the intrinsics come from ``K``. A ``CameraInfo`` with non-zero distortion coefficients
converts only when the caller undistorts the images (``undistort=True``: a ``plumb_bob``, ``rational_polynomial``
or ``equidistant`` lens, whose images :class:`~lightfast.camera.Undistorter` resamples into the pinhole image of
``K``); otherwise it is refused with one line. Written ``CameraInfo`` have ``P = [K | 0]``, ``R = I`` and ``D = 0``
(plumb_bob).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from lightfast.camera import DISTORTION_MODELS, PinholeCamera, Undistorter
from lightfast.errors import CameraModelError
from lightfast.ros.convert.header import make_header
from lightfast.ros.errors import CameraInfoError
from lightfast.ros.msgtypes import RCLPY, MessageTypes

__all__ = ["SUPPORTED_DISTORTION_MODELS", "CameraInfoReader", "camera_from_camera_info", "camera_info_from_camera",
           "undistorter_from_camera_info"]

SUPPORTED_DISTORTION_MODELS = ("plumb_bob", "rational_polynomial", "equidistant", "")
"""Distortion models accepted by :func:`camera_from_camera_info` with all-zero coefficients ("" too); the first
three also with non-zero ones when the images are undistorted (:func:`undistorter_from_camera_info`)."""


def camera_from_camera_info(msg: Any, *, undistort: bool = False) -> PinholeCamera:
    """The :class:`~lightfast.camera.PinholeCamera` of a ``sensor_msgs/CameraInfo``.

    Requires ``width, height > 0``, a distortion model in :data:`SUPPORTED_DISTORTION_MODELS` with every
    coefficient of ``D`` zero (or ``D`` empty) — or, with ``undistort``, any coefficients that
    :func:`undistorter_from_camera_info` accepts (the caller then undistorts every image) —, no binning
    (``binning_x/y`` 0 or 1) and a full-image ROI; else :class:`CameraInfoError`. The intrinsics come from ``K``
    (``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``). ``P`` is only checked for the projection-matrix layout when it is
    non-zero: for a rectified stereo pair ``P[:3, :3]`` legitimately differs from ``K``, and ``R`` is ignored.
    """
    width, height = int(msg.width), int(msg.height)
    if width <= 0 or height <= 0:
        raise CameraInfoError(f"CameraInfo.width={width} and height={height} must be > 0 (camera not calibrated?)")
    model = str(msg.distortion_model)
    d = np.asarray(msg.d, dtype=np.float64).reshape(-1)
    if model not in SUPPORTED_DISTORTION_MODELS or (np.any(d != 0.0) and not (undistort and model in
                                                                                DISTORTION_MODELS)):
        raise CameraInfoError(
            f"CameraInfo.distortion_model={model!r} with D={d.tolist()} is not supported: "
            + ("lightfast undistorts plumb_bob, rational_polynomial and equidistant lenses only" if undistort else
               "lightfast models ideal pinhole cameras, so give it rectified images (e.g. from image_proc), or let "
               "rgbd_tracker_node and daylight_relight_node undistort them (parameter undistort true)")
        )
    for name in ("binning_x", "binning_y"):
        binning = int(getattr(msg, name, 0))
        if binning not in (0, 1):
            raise CameraInfoError(f"CameraInfo.{name}={binning} is not supported (only 0 or 1)")
    roi = getattr(msg, "roi", None)
    if roi is not None:
        roi_values = (int(roi.x_offset), int(roi.y_offset), int(roi.width), int(roi.height))
        if roi_values not in ((0, 0, 0, 0), (0, 0, width, height)):
            raise CameraInfoError(
                f"CameraInfo.roi (x_offset, y_offset, width, height)={roi_values} is not supported (full image only)"
            )
    k = np.asarray(msg.k, dtype=np.float64).reshape(-1)
    if k.size != 9 or not np.all(np.isfinite(k)):
        raise CameraInfoError(f"CameraInfo.k must be 9 finite numbers (row-major 3x3), got {k.tolist()}")
    p = np.asarray(msg.p, dtype=np.float64).reshape(-1)
    if p.size != 12:
        raise CameraInfoError(f"CameraInfo.p must have 12 elements (row-major 3x4), got {p.size}")
    if np.any(p != 0.0):
        P = p.reshape(3, 4)
        if (
            not np.all(np.isfinite(P))
            or not np.array_equal(P[2], [0.0, 0.0, 1.0, 0.0])
            or P[0, 1] != 0.0
            or P[1, 0] != 0.0
            or P[0, 0] <= 0.0
            or P[1, 1] <= 0.0
        ):
            raise CameraInfoError(
                f"CameraInfo.p={P.tolist()} is not a projection matrix [[fx', 0, cx', Tx], [0, fy', cy', Ty], "
                "[0, 0, 1, 0]]"
            )
    try:
        return PinholeCamera.from_matrix(k.reshape(3, 3), width, height)
    except CameraModelError as exc:
        raise CameraInfoError(f"CameraInfo.k: {exc}") from exc


def undistorter_from_camera_info(msg: Any) -> Undistorter | None:
    """The :class:`~lightfast.camera.Undistorter` of a ``CameraInfo`` whose ``D`` is not all zero (None if it is),
    mapping its images to the pinhole camera of :func:`camera_from_camera_info` (``undistort=True``).
    :class:`CameraInfoError` for a model it cannot invert or a wrong number of coefficients."""
    return _undistorter(camera_from_camera_info(msg, undistort=True), msg)


def _undistorter(camera: PinholeCamera, msg: Any) -> Undistorter | None:
    """:func:`undistorter_from_camera_info` for ``msg`` whose ``camera`` is already converted."""
    d = np.asarray(msg.d, dtype=np.float64).reshape(-1)
    if not np.any(d != 0.0):
        return None
    try:
        return Undistorter(camera, str(msg.distortion_model), d)
    except CameraModelError as exc:
        raise CameraInfoError(f"CameraInfo.d: {exc}") from exc


class CameraInfoReader:
    """:func:`camera_from_camera_info` that keeps its last result: a driver sends the same ``CameraInfo`` with every
    image, and a node that converts each one spends more on the checks than on anything else it does per message.
    With ``undistort`` a lens-distorted ``CameraInfo`` is accepted and :attr:`undistorter` (None for an undistorted
    one) resamples its images into the returned camera's (:func:`undistorter_from_camera_info`)."""

    def __init__(self, undistort: bool = False) -> None:
        self._undistort = undistort
        self._key: tuple[Any, ...] | None = None
        self._camera: PinholeCamera | None = None
        self.undistorter: Undistorter | None = None

    def __call__(self, msg: Any) -> PinholeCamera:
        roi = getattr(msg, "roi", None)
        key = (int(msg.width), int(msg.height), str(msg.distortion_model), bytes(np.asarray(msg.d, np.float64)),
               bytes(np.asarray(msg.k, np.float64)), bytes(np.asarray(msg.p, np.float64)),
               getattr(msg, "binning_x", 0), getattr(msg, "binning_y", 0),
               None if roi is None else (roi.x_offset, roi.y_offset, roi.width, roi.height))
        if key != self._key or self._camera is None:
            camera = camera_from_camera_info(msg, undistort=self._undistort)  # raises before the key is kept
            self.undistorter = _undistorter(camera, msg) if self._undistort else None
            self._camera, self._key = camera, key
        return self._camera


def camera_info_from_camera(
    camera: PinholeCamera, *, stamp_ns: int = 0, frame_id: str = "", types: MessageTypes = RCLPY
) -> Any:
    """A ``sensor_msgs/CameraInfo`` for ``camera``: ``K``, ``P = [K | 0]``, ``R = I``, ``D = 0`` (plumb_bob)."""
    K = camera.K
    P = np.hstack([K, np.zeros((3, 1))])
    return types.new(
        "sensor_msgs/msg/CameraInfo",
        header=make_header(stamp_ns, frame_id, types=types),
        height=int(camera.height),
        width=int(camera.width),
        distortion_model="plumb_bob",
        d=types.float64_sequence(np.zeros(5)),
        k=types.float64_array(K),
        r=types.float64_array(np.eye(3)),
        p=types.float64_array(P),
        binning_x=0,
        binning_y=0,
        roi=types.new(
            "sensor_msgs/msg/RegionOfInterest", x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )
