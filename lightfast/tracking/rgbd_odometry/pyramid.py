"""Frame preparation for the Eq. 7 alignment of paper §III-D: grey and depth image pyramids.

Inputs: colour ``(H, W, 3)`` RGB (uint8, or float in [0, 1]) or ``(H, W)`` grey, turned into grey in [0, 1]
(Rec. 601 weights); depth ``(H, W)`` float metres, invalid (stored as 0) where non-finite or outside
``[min_depth_m, max_depth_m]``; both at the camera's size (px). ``resolution_scale`` 0.5 halves both first; each
further pyramid level halves the previous one by 2×2 block means (depth averaged only where the block is continuous,
:func:`~lightfast.tracking.rgbd_odometry.maps._downsample_depth`), with the camera scaled alike.

Output: an :class:`RGBDFrame`, its levels finest first. A level computes its maps when an alignment first uses them,
in the level's camera frame (REP-103 optical): vertices and normals (m), grey and its Sobel gradient (per px),
the depth gradient (m/px) and the source points (every pixel, a checkerboard or every second row and column at
level 0, ``finest_point_step``; every pixel above). One frame serves as source (live) and as target (reference).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.tracking.errors import TrackingInputError
from lightfast.tracking.rgbd_odometry.config import TrackingConfig
from lightfast.tracking.rgbd_odometry.maps import _depth_gradient, _downsample_depth, _geometry_map, _source_points

__all__ = ["RGBDFrame", "prepare_frame", "repeated_images", "repeated_input"]

_GREY = np.array([0.299, 0.587, 0.114], dtype=np.float32)


@dataclass(frozen=True, eq=False)
class RGBDFrame:
    """A frame prepared by :func:`prepare_frame`: pyramid ``levels`` (finest first) at ``camera``'s input size."""

    levels: tuple[_Level, ...]
    camera: PinholeCamera
    pyramid_levels: int
    resolution_scale: float


class _Level:
    """One pyramid level of a prepared frame. Its vertex, normal and gradient maps and its source points are
    computed when an alignment first uses them: the full-resolution level of a live frame often serves neither
    f2f (which stops at level 1) nor f2m against a half-resolution reference. (Not functools.cached_property: on
    Python 3.11 it computes under one lock per class, which made the f2f and f2m threads of the tracker node wait
    for each other; two threads computing the same map at once both get a correct one.)"""

    def __init__(self, camera: PinholeCamera, grey: NDArray[np.float32], depth: NDArray[np.float32],
                 point_step: int, discontinuity_m: float) -> None:
        self.camera = camera
        self.grey = grey  # (H, W)
        self.depth = depth  # (H, W), 0 = invalid
        self._point_step = point_step
        self._discontinuity_m = discontinuity_m
        self._geometry: NDArray[np.float32] | None = None
        self._depth_grad: NDArray[np.float32] | None = None
        self._source: tuple[NDArray[np.float32], NDArray[np.float32]] | None = None
        self._grey_grad: NDArray[np.float32] | None = None

    @property
    def geometry(self) -> NDArray[np.float32]:
        """(H, W, 7): depth, vertex xyz, normal xyz (NaN where undefined) — the target role."""
        if self._geometry is None:
            cam = self.camera
            self._geometry = _geometry_map(self.depth, cam.fx, cam.fy, cam.cx, cam.cy)
        return self._geometry

    def _source_arrays(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        if self._source is None:
            self._source = _source_points(self.geometry, self.grey, self._point_step)
        return self._source

    @property
    def points(self) -> NDArray[np.float32]:
        """(N, 3) vertices of the source pixels with depth."""
        return self._source_arrays()[0]

    @property
    def point_grey(self) -> NDArray[np.float32]:
        """(N,) grey values of the source points."""
        return self._source_arrays()[1]

    @property
    def grey_grad(self) -> NDArray[np.float32]:
        """(H, W, 3): I, dI/du, dI/dv — the target role."""
        if self._grey_grad is None:
            grey = self.grey
            gu = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE) * np.float32(0.125)
            gv = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REPLICATE) * np.float32(0.125)
            self._grey_grad = np.ascontiguousarray(np.stack([grey, gu, gv], axis=-1))
        return self._grey_grad

    @property
    def depth_grad(self) -> NDArray[np.float32]:
        """(H, W, 2): dD/du, dD/dv in m/px (Sobel), NaN where the 3×3 neighbourhood lacks depth or a derivative
        exceeds the pyramid's discontinuity threshold — the target role of the depth-difference E_G."""
        if self._depth_grad is None:
            self._depth_grad = _depth_gradient(self.depth, self._discontinuity_m)
        return self._depth_grad


def _to_grey(rgb: NDArray[np.generic], name: str) -> NDArray[np.float32]:
    a = np.asarray(rgb)
    if a.ndim == 3 and a.shape[2] == 3:
        grey = a.astype(np.float32) @ _GREY
    elif a.ndim == 2:
        grey = a.astype(np.float32)
    else:
        raise TrackingInputError(f"{name} must be (H, W, 3) RGB or (H, W) grey, got shape {a.shape}")
    if a.dtype == np.uint8:
        grey *= np.float32(1.0 / 255.0)
    elif not np.issubdtype(a.dtype, np.floating):
        raise TrackingInputError(f"{name} must be uint8 or float in [0, 1], got dtype {a.dtype}")
    if not np.all(np.isfinite(grey)):
        raise TrackingInputError(f"{name} holds non-finite values")
    return grey


def _check_depth(depth_m: ArrayLike, name: str, cfg: TrackingConfig) -> NDArray[np.float32]:
    d = np.asarray(depth_m)
    if d.ndim != 2:
        raise TrackingInputError(f"{name} must be a (H, W) depth image in metres, got shape {d.shape}")
    if not np.issubdtype(d.dtype, np.floating):
        raise TrackingInputError(f"{name} must be float metres, got dtype {d.dtype} (convert millimetres first)")
    d = d.astype(np.float32)
    valid = np.isfinite(d) & (d >= cfg.min_depth_m) & (d <= cfg.max_depth_m)
    return np.where(valid, d, np.float32(0.0))


def _downsample_grey(grey: NDArray[np.float32]) -> NDArray[np.float32]:
    """2×2 block means (``INTER_AREA`` at exactly half size)."""
    h, w = grey.shape[0] // 2, grey.shape[1] // 2
    return cast(NDArray[np.float32], cv2.resize(grey[: 2 * h, : 2 * w], (w, h), interpolation=cv2.INTER_AREA))


def _prepare(rgb: ArrayLike, depth_m: ArrayLike, camera: PinholeCamera, cfg: TrackingConfig, role: str) -> RGBDFrame:
    grey = _to_grey(np.asarray(rgb), f"{role}_rgb")
    depth = _check_depth(depth_m, f"{role}_depth_m", cfg)
    if grey.shape != camera.shape or depth.shape != camera.shape:
        raise TrackingInputError(
            f"{role} images must match the camera size {camera.shape} (H, W): colour {grey.shape}, "
            f"depth {depth.shape}"
        )
    if not np.any(depth > 0):
        raise TrackingInputError(
            f"{role}_depth_m has no valid depth in [{cfg.min_depth_m}, {cfg.max_depth_m}] m (all zero / invalid?)"
        )
    cam = camera
    if cfg.resolution_scale != 1.0:
        grey, depth = _downsample_grey(grey), _downsample_depth(depth, cfg.depth_discontinuity_m)
        cam = camera.scaled(0.5)
    levels: list[_Level] = []
    for level in range(cfg.pyramid_levels):
        if level > 0:
            grey, depth = _downsample_grey(grey), _downsample_depth(depth, cfg.depth_discontinuity_m)
            cam = cam.scaled(0.5)
        if min(grey.shape) < 8:
            raise TrackingInputError(
                f"image too small for {cfg.pyramid_levels} pyramid levels: level {level} is {grey.shape}"
            )
        levels.append(_Level(cam, grey, depth, cfg.finest_point_step if level == 0 else 1, cfg.depth_discontinuity_m))
    return RGBDFrame(tuple(levels), camera, cfg.pyramid_levels, cfg.resolution_scale)


def prepare_frame(
    rgb: ArrayLike, depth_m: ArrayLike, camera: PinholeCamera, *, config: TrackingConfig | None = None,
    name: str = "frame",
) -> RGBDFrame:
    """Prepare one RGB-D frame (grey + depth pyramids, vertex and normal maps, image gradients) for
    :func:`align_frames`, as a live (source) frame and as a reference (target) frame alike.

    ``rgb``: ``(H, W, 3)`` RGB uint8 (or float in [0, 1]) or ``(H, W)`` grey; ``depth_m``: ``(H, W)`` float metres
    (0 / NaN / outside ``[min_depth_m, max_depth_m]`` invalid); both at ``camera``'s size. ``name`` appears in errors.
    """
    return _prepare(rgb, depth_m, camera, TrackingConfig() if config is None else config, name)


def repeated_images(colour: ArrayLike, depth: ArrayLike, previous_colour: ArrayLike, previous_depth: ArrayLike) -> str:
    """Which of two images repeats its predecessor exactly: ``"depth"`` (the depth image, whether or not the colour
    repeats too), ``"colour"`` (the colour image alone) or ``""``.

    A repeated image is not a new measurement. A driver that drops a frame may send its last image again, and
    colour and depth streams that are not synchronised pair one image of one stream with two of the other (7-Scenes'
    Kinect v1 recordings do both: docs/daylight.md). Aligning a new colour image against an old one with the new
    depth, or the reverse, fits a motion that one of the two images did not make. A real sensor's noise makes two
    genuine depth images differ, so exact equality is the test."""
    if np.array_equal(depth, previous_depth):
        return "depth"
    return "colour" if np.array_equal(colour, previous_colour) else ""


def repeated_input(frame: RGBDFrame, previous: RGBDFrame) -> str:
    """:func:`repeated_images` of two prepared frames (their level-0 grey and depth images)."""
    a, b = frame.levels[0], previous.levels[0]
    return repeated_images(a.grey, a.depth, b.grey, b.depth)
