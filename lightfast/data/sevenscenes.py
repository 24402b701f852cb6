"""Microsoft 7-Scenes RGB-D frames (as in ``../shared/data/7scenes_redkitchen_300``) to a rosbag2 MCAP bag.

Input (see that folder's PROVENANCE.md): ``frame-NNNNNN.color.jpg`` (640×480 RGB), ``frame-NNNNNN.depth.png``
(16-bit, millimetres; 0 and 65535 invalid), ``frame-NNNNNN.pose.txt`` (4×4 camera-to-world, metres),
``camera-intrinsics.txt`` (3×3 K; the 7-Scenes download has none: then its documented fx = fy = 585,
(cx, cy) = (320, 240)) and optionally ``gravity-direction.txt`` (world-frame gravity). Frame numbers may start
anywhere (a sequence's later part alone); ``indices`` lists those present, sorted.

Output topics (one message per frame each, stamped at ``start_ns + i / rate_hz``; 7-Scenes has no timestamps):

========================================  ==========================  ============================================
topic                                     type                        content
========================================  ==========================  ============================================
``/camera/color/image_raw``               sensor_msgs/Image           rgb8
``/camera/color/camera_info``             sensor_msgs/CameraInfo      K from camera-intrinsics.txt, no distortion
``/camera/depth/image_raw``               sensor_msgs/Image           16UC1 depth in millimetres, 0 = invalid
``/camera/depth/camera_info``             sensor_msgs/CameraInfo      same K (the data set treats depth as
                                                                      registered to colour)
``/ground_truth/pose``                    geometry_msgs/PoseStamped   ``T_map_camera``: the optical frame in ``map``
========================================  ==========================  ============================================

Frames: both images are in ``camera_color_optical_frame`` (REP-103 optical: x right, y down, z forward). ``map``
is the 7-Scenes world frame rotated so that +z points up (against ``gravity-direction.txt``, REP-103/105), with the
same origin; without a gravity file it is the world frame itself.
"""
from __future__ import annotations

import logging
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from lightfast.bag.writer import BagWriter, make_qos
from lightfast.camera import PinholeCamera
from lightfast.data.errors import DatasetError
from lightfast.geometry import project_to_so3
from lightfast.progress import track
from lightfast.ros.convert import camera_info_from_camera, matrix_to_pose_stamped, numpy_to_image
from lightfast.ros.msgtypes import rosbags_types
from lightfast.topics import (
    COLOR_INFO_TOPIC,
    COLOR_TOPIC,
    DEPTH_INFO_TOPIC,
    DEPTH_TOPIC,
    GT_POSE_TOPIC,
    MAP_FRAME,
    OPTICAL_FRAME,
)

log = logging.getLogger(__name__)

#: 2013-06-01T12:00:00Z, an arbitrary fixed start (the data set has no timestamps).
DEFAULT_START_NS = 1_370_088_000 * 10**9
INVALID_DEPTH_MM = 65535
_FRAME_RE = re.compile(r"frame-(\d{6})\.color\.(?:jpg|png)$")
#: The intrinsics the 7-Scenes page gives for all sequences (the KinectFusion defaults of the depth camera), used
#: when a folder has no ``camera-intrinsics.txt`` (the original download has none).
SEVENSCENES_K = np.array([[585.0, 0.0, 320.0], [0.0, 585.0, 240.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class SevenScenesFrame:
    """One RGB-D frame: ``rgb`` (H, W, 3) uint8, ``depth_mm`` (H, W) uint16 with 0 invalid, ``T_world_cam``
    (its rotation re-orthonormalized)."""

    index: int
    rgb: NDArray[np.uint8]
    depth_mm: NDArray[np.uint16]
    T_world_cam: NDArray[np.float64]


class SevenScenes:
    """A folder of 7-Scenes frames; ``intrinsics_file`` is False where :data:`SEVENSCENES_K` stands in for a
    missing ``camera-intrinsics.txt``."""

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise DatasetError(f"no 7-Scenes folder at {self.root}")
        self.indices = sorted(int(m.group(1)) for p in self.root.iterdir() if (m := _FRAME_RE.match(p.name)))
        if not self.indices:
            raise DatasetError(f"{self.root} holds no frame-NNNNNN.color.jpg files")
        k_file = self.root / "camera-intrinsics.txt"
        self.intrinsics_file = k_file.is_file()
        self.K = self._read_matrix(k_file, (3, 3)) if self.intrinsics_file else SEVENSCENES_K.copy()
        if not self.intrinsics_file:
            log.info("%s has no camera-intrinsics.txt: using the 7-Scenes intrinsics (585, 585, 320, 240)", self.root)
        gravity_file = self.root / "gravity-direction.txt"
        self.T_map_world = np.eye(4)
        if gravity_file.is_file():
            gravity = np.loadtxt(gravity_file).reshape(3)
            up = -gravity / np.linalg.norm(gravity)
            rot, _ = Rotation.align_vectors([[0.0, 0.0, 1.0]], [up])
            self.T_map_world[:3, :3] = rot.as_matrix()
        first = self.frame(self.indices[0])
        h, w = first.depth_mm.shape
        self.camera = PinholeCamera.from_matrix(self.K, width=w, height=h)

    @staticmethod
    def _read_matrix(path: Path, shape: tuple[int, int]) -> NDArray[np.float64]:
        try:
            m = np.loadtxt(path)
        except (OSError, ValueError) as exc:
            raise DatasetError(f"cannot read {path}: {exc}") from None
        if m.shape != shape or not np.all(np.isfinite(m)):
            raise DatasetError(f"{path}: expected a finite {shape[0]}x{shape[1]} matrix, got shape {m.shape}")
        return m

    def frame(self, index: int) -> SevenScenesFrame:
        stem = self.root / f"frame-{index:06d}"
        color_path = stem.with_name(stem.name + ".color.jpg")
        if not color_path.exists():
            color_path = stem.with_name(stem.name + ".color.png")
        bgr = cv2.imread(str(color_path), cv2.IMREAD_COLOR)
        depth = cv2.imread(str(stem.with_name(stem.name + ".depth.png")), cv2.IMREAD_UNCHANGED)
        if bgr is None:
            raise DatasetError(f"cannot read colour image {color_path}")
        if depth is None or depth.dtype != np.uint16 or depth.ndim != 2:
            raise DatasetError(f"{stem.name}.depth.png is missing or not a 16-bit single-channel PNG")
        if depth.shape != bgr.shape[:2]:
            raise DatasetError(f"{stem.name}: colour {bgr.shape[:2]} and depth {depth.shape} sizes differ")
        depth = depth.copy()
        depth[depth == INVALID_DEPTH_MM] = 0
        T = self._read_matrix(stem.with_name(stem.name + ".pose.txt"), (4, 4))
        # KinectFusion stored the rotations in single precision (|RᵀR - I| ~ 1e-4): snap to the nearest rotation
        T[:3, :3] = project_to_so3(T[:3, :3])
        rgb = cast(NDArray[np.uint8], cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        return SevenScenesFrame(index, rgb, cast(NDArray[np.uint16], depth), T)  # uint16: checked above

    def T_map_cam(self, frame: SevenScenesFrame) -> NDArray[np.float64]:
        return self.T_map_world @ frame.T_world_cam


@dataclass(frozen=True)
class ColourRegistration:
    """Where the colour of a depth pixel ``(u, v)`` lies in a 7-Scenes colour image:
    ``u_c = cx + scale (u - cx) + dx_px``, ``v_c = cy + scale (v - cy) + dy_px``, with ``(cx, cy)`` the (depth)
    camera's principal point. ``scale`` is the colour camera's focal length over the depth camera's; the shift stands
    for the cameras' baseline at the scene's depth and their relative rotation."""

    scale: float
    dx_px: float
    dy_px: float

    def matrix(self, camera: PinholeCamera) -> NDArray[np.float32]:
        """The 2×3 affine map from depth pixels to colour pixels (for ``cv2.warpAffine`` with ``WARP_INVERSE_MAP``)."""
        s = self.scale
        return np.array([[s, 0.0, camera.cx * (1.0 - s) + self.dx_px],
                         [0.0, s, camera.cy * (1.0 - s) + self.dy_px]], dtype=np.float32)


def colour_registration(
    frames: Iterable[tuple[NDArray[np.uint8], NDArray[np.uint16]]], camera: PinholeCamera, *,
    scale_range: tuple[float, float] = (0.80, 1.10), search_px: int | None = None, depth_edge_m: float = 0.3,
    border_px: int | None = None, points_per_frame: int = 2000,
) -> ColourRegistration:
    """The similarity that best registers 7-Scenes colour images to their depth images, estimated from the images
    alone (no poses): the colour gradient magnitude (normalized per frame) read at the registered positions of the
    depth discontinuities (Sobel of the hole-closed depth above ``depth_edge_m`` per px, ``border_px`` left out, at
    most ``points_per_frame`` of them per frame, seeded), summed over the frames, is largest. Grid search, coarse
    (scale step 0.01, shifts within ``±search_px`` in steps of 2 px, on blurred gradients) then fine (0.0025, 1 px).
    ``search_px`` and ``border_px`` default to 1/20 and 1/16 of the image width (32 and 40 px at 640×480).

    Why a scale: the Kinect v1's colour and depth cameras are not registered in 7-Scenes (PROVENANCE.md), and the
    K it ships (f = 585 px) is the depth camera's; the colour camera's focal length is about 525 px (the OpenNI
    defaults), so its image is about 0.9 times the depth image's scale about the centre. A shift alone (this
    function's predecessor) had several maxima on redkitchen; the similarity has one (scale 0.90 on frames 0-149).
    A registration from the sensor's calibration would be the proper one; 7-Scenes ships none. Apply with
    :func:`register_colour`."""
    search_px = max(2, round(camera.width / 20)) if search_px is None else search_px
    border_px = round(camera.width / 16) if border_px is None else border_px
    if not 0.0 < scale_range[0] < scale_range[1] or search_px < 2 or border_px < 1:
        raise DatasetError(f"need 0 < scale_range[0] < scale_range[1], search_px >= 2 and border_px >= 1, got "
                           f"{scale_range}, {search_px}, {border_px}")
    rng = np.random.default_rng(0)
    du, dv, idx, sharp, blurred = [], [], [], [], []
    for k, (rgb, depth_mm) in enumerate(frames):
        depth = cv2.morphologyEx(depth_mm.astype(np.float32) / 1000.0, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
        edges = np.hypot(cv2.Sobel(depth, cv2.CV_32F, 1, 0), cv2.Sobel(depth, cv2.CV_32F, 0, 1)) > depth_edge_m
        edges[:border_px], edges[-border_px:], edges[:, :border_px], edges[:, -border_px:] = False, False, False, False
        v, u = np.nonzero(edges)
        if len(u) > points_per_frame:
            keep = rng.choice(len(u), points_per_frame, replace=False)
            u, v = u[keep], v[keep]
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32)
        grad = np.hypot(cv2.Sobel(grey, cv2.CV_32F, 1, 0), cv2.Sobel(grey, cv2.CV_32F, 0, 1))
        grad /= grad.mean() + 1e-6
        du.append(u - camera.cx)
        dv.append(v - camera.cy)
        idx.append(np.full(len(u), k))
        sharp.append(grad)
        blurred.append(cv2.GaussianBlur(grad, (0, 0), 2.0))
    if not sharp:
        raise DatasetError("colour_registration needs at least one frame")
    U, V, F = np.concatenate(du), np.concatenate(dv), np.concatenate(idx)
    if len(U) == 0:
        raise DatasetError("colour_registration: no depth discontinuities in these frames")
    h, w = sharp[0].shape

    def best(grads: NDArray[np.float32], scales: NDArray[np.float64], shifts: NDArray[np.float64]
             ) -> tuple[float, float, float]:
        flat = grads.reshape(-1)
        top = (-np.inf, 1.0, 0.0, 0.0)
        for s in scales:
            ub, vb = camera.cx + s * U, camera.cy + s * V
            # flat indices of every shift in y at once: (n_dy, N)
            rows = np.clip(np.rint(vb[None, :] + shifts[1][:, None]), 0, h - 1).astype(np.intp)
            base = F[None, :] * (h * w) + rows * w
            for dx in shifts[0]:
                cols = np.clip(np.rint(ub + dx), 0, w - 1).astype(np.intp)
                scores = flat[base + cols[None, :]].sum(axis=1)
                k = int(np.argmax(scores))
                if scores[k] > top[0]:
                    top = (float(scores[k]), float(s), float(dx), float(shifts[1][k]))
        return top[1], top[2], top[3]

    coarse_shift = np.arange(-search_px, search_px + 1, 2.0)
    s0, dx0, dy0 = best(np.stack(blurred), np.arange(scale_range[0], scale_range[1] + 1e-9, 0.01),
                        np.stack([coarse_shift, coarse_shift]))
    fine = np.arange(-2.0, 2.5, 1.0)
    s1, dx1, dy1 = best(np.stack(sharp), s0 + np.arange(-0.01, 0.0101, 0.0025), np.stack([dx0 + fine, dy0 + fine]))
    return ColourRegistration(round(s1, 4), dx1, dy1)


def register_colour(image: NDArray[Any], registration: ColourRegistration, camera: PinholeCamera) -> NDArray[Any]:
    """``image`` (a 7-Scenes colour image) resampled onto the depth image's pixels (bilinear; borders repeat)."""
    h, w = image.shape[:2]
    return cast(NDArray[Any], cv2.warpAffine(image, registration.matrix(camera), (w, h),
                                             flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                             borderMode=cv2.BORDER_REPLICATE))


def convert_7scenes(
    src: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    first: int = 0,
    count: int | None = None,
    rate_hz: float = 30.0,
    start_ns: int = DEFAULT_START_NS,
    overwrite: bool = False,
    progress: bool = False,
) -> Path:
    """Write frames ``first .. first+count`` (by position in the folder; default all) of ``src`` as a bag at
    ``out``. Returns the bag path. The bag appears at ``out`` only when complete."""
    if rate_hz <= 0:
        raise DatasetError(f"rate_hz must be > 0, got {rate_hz}")
    data = SevenScenes(src)
    indices = data.indices[first : None if count is None else first + count]
    if not indices:
        raise DatasetError(f"no frames selected (first={first}, count={count}, {len(data.indices)} available)")
    types = rosbags_types()
    sensor_qos = [make_qos(reliable=True, depth=10)]
    with BagWriter(out, overwrite=overwrite) as bag:
        for topic, msgtype in (
            (COLOR_TOPIC, "sensor_msgs/msg/Image"),
            (COLOR_INFO_TOPIC, "sensor_msgs/msg/CameraInfo"),
            (DEPTH_TOPIC, "sensor_msgs/msg/Image"),
            (DEPTH_INFO_TOPIC, "sensor_msgs/msg/CameraInfo"),
            (GT_POSE_TOPIC, "geometry_msgs/msg/PoseStamped"),
        ):
            bag.add_topic(topic, msgtype, offered_qos=sensor_qos)
        for i, index in enumerate(track(indices, desc="7-Scenes to MCAP", enabled=progress, unit="frame")):
            frame = data.frame(index)
            t_ns = start_ns + round(i * 1e9 / rate_hz)
            header: dict[str, Any] = dict(stamp_ns=t_ns, frame_id=OPTICAL_FRAME, types=types)
            info = camera_info_from_camera(data.camera, **header)
            bag.write_message(COLOR_TOPIC, t_ns, numpy_to_image(frame.rgb, "rgb8", **header))
            bag.write_message(COLOR_INFO_TOPIC, t_ns, info)
            bag.write_message(DEPTH_TOPIC, t_ns, numpy_to_image(frame.depth_mm, "16UC1", **header))
            bag.write_message(DEPTH_INFO_TOPIC, t_ns, info)
            bag.write_message(
                GT_POSE_TOPIC, t_ns, matrix_to_pose_stamped(data.T_map_cam(frame), stamp_ns=t_ns, frame_id=MAP_FRAME,
                                                            types=types)
            )
    log.info("wrote %d frames of %s to %s", len(indices), src, out)
    return Path(out)
