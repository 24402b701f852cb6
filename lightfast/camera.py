"""Pinhole camera model (no distortion) in the ROS optical frame convention (REP-103: x right, y down, z forward),
and :class:`Undistorter`, which turns a lens-distorted image into that model's image.

Pixel coordinates ``uv_px`` follow ROS ``CameraInfo``: the centre of the top-left pixel is (0, 0), ``u`` grows to
the right, ``v`` downwards. Points ``p_cam_m`` are in metres in the camera's optical frame.
Messages convert to and from this model in :mod:`lightfast.ros.convert` (``camera_from_camera_info``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, TypeVar, cast

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.errors import CameraModelError


@dataclass(frozen=True)
class PinholeCamera:
    """An ideal pinhole camera: image size in pixels and intrinsics ``fx, fy, cx, cy`` in pixels."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise CameraModelError(f"image size must be positive, got width={self.width} height={self.height}")
        for name in ("fx", "fy"):
            value = float(getattr(self, name))
            if not np.isfinite(value) or value <= 0.0:
                raise CameraModelError(f"focal length {name} must be finite and > 0, got {value}")
        for name in ("cx", "cy"):
            if not np.isfinite(float(getattr(self, name))):
                raise CameraModelError(f"principal point {name} must be finite, got {getattr(self, name)}")

    @classmethod
    def from_matrix(cls, K: ArrayLike, width: int, height: int) -> PinholeCamera:
        """Build from a 3×3 intrinsic matrix ``K`` (skew must be zero)."""
        K = np.asarray(K, dtype=np.float64)
        if K.shape != (3, 3):
            raise CameraModelError(f"K must be 3x3, got shape {K.shape}")
        if abs(K[0, 1]) > 1e-9 or not np.allclose(K[2], [0.0, 0.0, 1.0]) or abs(K[1, 0]) > 1e-9:
            raise CameraModelError(f"K must be [[fx,0,cx],[0,fy,cy],[0,0,1]], got {K.tolist()}")
        return cls(int(width), int(height), float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))

    @property
    def K(self) -> NDArray[np.float64]:
        """The 3×3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape as ``(height, width)``, the NumPy order."""
        return (self.height, self.width)

    def scaled(self, factor: float) -> PinholeCamera:
        """The same camera for an image resized by ``factor`` (e.g. 0.5 for one pyramid level down).

        Uses the pixel-centre convention: ``c' = (c + 0.5) * factor - 0.5``.
        """
        if factor <= 0:
            raise CameraModelError(f"scale factor must be > 0, got {factor}")
        return PinholeCamera(
            width=max(1, round(self.width * factor)),
            height=max(1, round(self.height * factor)),
            fx=self.fx * factor,
            fy=self.fy * factor,
            cx=(self.cx + 0.5) * factor - 0.5,
            cy=(self.cy + 0.5) * factor - 0.5,
        )

    def project(self, p_cam_m: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Project points ``(..., 3)`` in the optical frame to pixels ``(..., 2)``.

        Returns ``(uv_px, in_front)``; ``in_front`` is False where ``z <= 0`` (those ``uv_px`` are NaN).
        Whether a pixel lies inside the image is :meth:`in_image`.
        """
        p = np.asarray(p_cam_m, dtype=np.float64)
        if p.shape[-1] != 3:
            raise CameraModelError(f"points must have shape (..., 3), got {p.shape}")
        z = p[..., 2]
        in_front = z > 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            inv_z = np.where(in_front, 1.0 / np.where(in_front, z, 1.0), np.nan)
        uv = np.empty(p.shape[:-1] + (2,), dtype=np.float64)
        uv[..., 0] = self.fx * p[..., 0] * inv_z + self.cx
        uv[..., 1] = self.fy * p[..., 1] * inv_z + self.cy
        return uv, in_front

    def in_image(self, uv_px: ArrayLike, *, margin_px: float = 0.0) -> NDArray[np.bool_]:
        """True where pixel coordinates fall inside the image (by at least ``margin_px``)."""
        uv = np.asarray(uv_px, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            return (
                (uv[..., 0] >= -0.5 + margin_px)
                & (uv[..., 0] < self.width - 0.5 - margin_px)
                & (uv[..., 1] >= -0.5 + margin_px)
                & (uv[..., 1] < self.height - 0.5 - margin_px)
            )

    def backproject(self, uv_px: ArrayLike, depth_m: ArrayLike) -> NDArray[np.float64]:
        """Points ``(..., 3)`` in the optical frame at pixels ``uv_px`` ``(..., 2)`` and z-depth ``depth_m``."""
        uv = np.asarray(uv_px, dtype=np.float64)
        z = np.asarray(depth_m, dtype=np.float64)
        if uv.shape[-1] != 2:
            raise CameraModelError(f"pixels must have shape (..., 2), got {uv.shape}")
        out = np.empty(np.broadcast_shapes(uv.shape[:-1], z.shape) + (3,), dtype=np.float64)
        out[..., 0] = (uv[..., 0] - self.cx) / self.fx * z
        out[..., 1] = (uv[..., 1] - self.cy) / self.fy * z
        out[..., 2] = z
        return out

    def pixel_grid(self) -> NDArray[np.float64]:
        """Pixel-centre coordinates ``(height, width, 2)`` as ``(u, v)``."""
        v, u = np.mgrid[0 : self.height, 0 : self.width].astype(np.float64)
        return np.stack([u, v], axis=-1)

    def backproject_depth(self, depth_m: ArrayLike) -> NDArray[np.float64]:
        """Back-project a whole depth image ``(height, width)`` to points ``(height, width, 3)``.

        Invalid depth (NaN, 0 or negative) gives NaN points.
        """
        depth = np.asarray(depth_m, dtype=np.float64)
        if depth.shape != self.shape:
            raise CameraModelError(f"depth image shape {depth.shape} does not match camera {self.shape}")
        depth = np.where(depth > 0.0, depth, np.nan)
        return self.backproject(self.pixel_grid(), depth)

    def ray_directions(self) -> NDArray[np.float64]:
        """Unit ray directions ``(height, width, 3)`` through every pixel centre, in the optical frame."""
        d = self.backproject(self.pixel_grid(), np.ones(self.shape))
        return d / np.linalg.norm(d, axis=-1, keepdims=True)


_Pixel = TypeVar("_Pixel", bound=np.generic)
#: Largest depth difference (m) between the four pixels around a lookup that :meth:`Undistorter.depth` interpolates
#: across (the tracker's own ``depth_discontinuity_m`` default); beyond it a depth edge lies between them.
DEPTH_STEP_M = 0.05

#: Lens models of ``sensor_msgs/CameraInfo.distortion_model`` (ROS ``sensor_msgs/distortion_models.hpp``) that
#: :class:`Undistorter` inverts, with how many coefficients ``D`` each takes (in OpenCV's order, as ROS gives them).
DISTORTION_MODELS: dict[str, tuple[int, ...]] = {"plumb_bob": (4, 5), "rational_polynomial": (8,), "equidistant": (4,)}


class Undistorter:
    """Resample images of a lens-distorted camera into the ideal pinhole image of the same intrinsics ``K``.

    ``camera`` is the pinhole model (``K`` and size) the output has; ``model`` and ``coefficients`` are the lens's
    (:data:`DISTORTION_MODELS`; Brown–Conrady ``plumb_bob`` / ``rational_polynomial``, Kannala–Brandt
    ``equidistant``). Each output pixel is looked up where the lens put its ray (OpenCV's
    ``initUndistortRectifyMap``, ``cv2.fisheye`` for ``equidistant``; written by hand would only repeat it), once
    per image through maps computed here: :meth:`colour` bilinearly, :meth:`depth` bilinearly on smooth surfaces
    and from the nearest pixel across depth edges. Depth registered to this colour camera (e.g. a driver's
    ``aligned_depth_to_color``) lies on the same distorted pixel grid, so the same lookup applies. Output pixels
    whose ray falls outside the input (corners of a pincushion lens) are invalid depth (NaN) and repeat the nearest
    recorded colour (black there would be an edge that never moves, which pulls an alignment towards zero motion).
    """

    def __init__(self, camera: PinholeCamera, model: str, coefficients: ArrayLike) -> None:
        d = np.asarray(coefficients, dtype=np.float64).reshape(-1)
        if model not in DISTORTION_MODELS:
            raise CameraModelError(f"distortion model {model!r} is not one of {sorted(DISTORTION_MODELS)}")
        if d.size not in DISTORTION_MODELS[model]:
            raise CameraModelError(f"the {model} model takes {' or '.join(map(str, DISTORTION_MODELS[model]))} "
                                   f"coefficients, got {d.size}")
        if not np.all(np.isfinite(d)):
            raise CameraModelError(f"distortion coefficients must be finite, got {d.tolist()}")
        self.camera, self.model, self.coefficients = camera, model, tuple(float(x) for x in d)
        size = (camera.width, camera.height)
        if model == "equidistant":
            map_x, map_y = cv2.fisheye.initUndistortRectifyMap(camera.K, d, np.eye(3), camera.K, size, cv2.CV_32FC1)
        else:
            map_x, map_y = cv2.initUndistortRectifyMap(camera.K, d, np.eye(3), camera.K, size, cv2.CV_32FC1)
        if not (np.all(np.isfinite(map_x)) and np.all(np.isfinite(map_y))):
            raise CameraModelError(f"the {model} lens D={d.tolist()} does not map every pixel of {size}")
        self._map_x, self._map_y = map_x, map_y
        self._block_x, self._block_y = map_x - np.float32(0.5), map_y - np.float32(0.5)  # rounding gives the floor
        # fixed-point maps for bilinear lookups: the same values to 1/32 px, remapped about twice as fast
        self._fixed = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2)

    def colour(self, image: NDArray[_Pixel]) -> NDArray[_Pixel]:
        """The pinhole image of a distorted ``(H, W)`` or ``(H, W, C)`` colour or grey ``image`` (same dtype)."""
        img = self._check(image, "colour image")
        return cast(NDArray[_Pixel], cv2.remap(img, self._fixed[0], self._fixed[1], cv2.INTER_LINEAR,
                                               borderMode=cv2.BORDER_REPLICATE))

    def depth(self, depth_m: ArrayLike) -> NDArray[np.float32]:
        """The pinhole depth image (float32 m, NaN invalid) of a distorted depth image (m; NaN or ≤ 0 invalid):
        bilinear where the four pixels around the lookup are valid and span at most :data:`DEPTH_STEP_M`, the
        nearest pixel elsewhere (a mean across a depth edge is a surface that is not there; the nearest pixel alone
        would move every depth by up to half a pixel, a warp the tracker takes for motion)."""
        d = self._check(depth_m, "depth image").astype(np.float32)
        if d.ndim != 2:
            raise CameraModelError(f"depth image must be (H, W), got shape {d.shape}")
        invalid = ~(d > 0.0)
        d[invalid] = np.nan
        nan = float("nan")
        near = cv2.remap(d, self._map_x, self._map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=nan)
        lin = cv2.remap(d, self._map_x, self._map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                        borderValue=nan)  # NaN where any of the four is invalid
        d[invalid] = 0.0  # a block with an invalid pixel is NaN in lin anyway
        quad, corner = np.ones((2, 2), np.uint8), (0, 0)  # the block d[v:v+2, u:u+2]
        span = cv2.dilate(d, quad, anchor=corner) - cv2.erode(d, quad, anchor=corner)
        span_at = cv2.remap(span, self._block_x, self._block_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                            borderValue=float("inf"))  # of the block whose top-left pixel is floor(map)
        return cast(NDArray[np.float32], np.where((span_at <= DEPTH_STEP_M) & np.isfinite(lin), lin, near))

    def _check(self, image: ArrayLike, what: str) -> NDArray[Any]:
        img = np.ascontiguousarray(image)
        if img.shape[:2] != self.camera.shape:
            raise CameraModelError(f"{what} of shape {img.shape} does not match the camera's {self.camera.shape}")
        return img
