"""Direct RGB-D camera tracking: the joint photometric + geometric alignment of paper §III-D, Eq. 7.

The paper estimates each camera pose as

    T* = argmin_T  E_C(T) + w_G E_G(T)                                   (Eq. 7)

with E_C the dense photometric error of Steinbrücker et al. [8] and E_G the geometric (point-to-plane, projective
data association) error of KinectFusion [10], w_G = 10; the live depth image drives both the geometric term and
the projective data association. Tracking first aligns the live frame to the previous frame (f2f, gives T≈) and
then to a rendered reference colour + depth image (f2m) initialised with T≈. :func:`align` solves Eq. 7 for one
(source = live, target = reference) pair; :func:`track_sequence` chains f2f alignments.

Engine choice
-------------
Open3D's ``t.pipelines.odometry.rgbd_odometry_multi_scale(..., Method.Hybrid)`` was considered first (~38 ms at
640×480 on this machine). Its kernel (``RGBDOdometryJacobianImpl.h``, ``GetJacobianHybrid``) minimises
``0.5 ρ_I(I_t(π(T p)) - I_s) + 0.5 ρ_D(D_t(π(T p)) - [T p]_z)`` with hard-coded ``sqrt_lambda = 0.707`` on both
terms, nearest-pixel lookup, Sobel gradients, and Huber ρ with ``intensity_huber_delta`` / ``depth_huber_delta``.
A geometric weight *can* be emulated there: scaling the depth input by ``s`` (``depth_scale / s``) scales every
3-D point, so the depth residual becomes ``s·r_D``; since Huber satisfies ``ρ_{sδ}(s r) = s² ρ_δ(r)``, passing
``depth_huber_delta·s``, ``depth_outlier_trunc·s``, ``depth_max·s`` and dividing the estimated translation by
``s`` gives exactly ``E_I + s² E_D``, i.e. ``w_G = s²`` → ``s = sqrt(10)`` (the intensity term is invariant under a
uniform scaling of the scene). What cannot be configured is the *form* of the geometric term: Open3D's hybrid
term is the DVO-style depth difference along the optical axis (Kerl et al.), not the point-to-plane distance of
KinectFusion [10] that the paper cites (the two differ by ~1/n_z and in their Jacobians), and Open3D's
point-to-plane method cannot be combined with the intensity term. Engine (b) was therefore chosen: a Gauss–Newton
on SE(3) that implements Eq. 7 literally, its per-pixel linearisation jitted with numba; it runs about as fast as
Open3D's (``benchmarks/tracking_7scenes.py`` compares accuracy and speed of both on 7-Scenes).

The cost, as implemented
------------------------
For every source pixel ``x`` with valid live depth, ``p = π⁻¹(x, D_s(x))`` and ``q = T p`` (target camera):

* association: ``y = π(q)`` must fall inside the target image and the target depth at ``round(y)`` must be valid
  and within ``depth_outlier_trunc_m`` of ``q_z`` (occlusion / outlier test) — used by both terms, as in the paper;
* E_C = Σ ρ_C(r_C), ``r_C = I_t(y) - I_s(x)`` on grey intensities in [0, 1] (Rec. 601), ``I_t`` and its Sobel
  gradient bilinearly interpolated;
* E_G = Σ ρ_G(r_G), ``r_G = n_t · (q - v_t)`` with the target vertex ``v_t`` and normal ``n_t`` (from the target
  depth by central differences) at ``round(y)`` — point-to-plane with projective association [10], in metres;
  or, with ``geometric_term="depth-difference"``, ``r_G = D_t(round(y)) - q_z`` with the Jacobian through the
  target depth's Sobel gradient (the depth term of Kerl et al., ICRA 2013, and of Open3D's hybrid odometry). Not
  the paper's form, offered for real depth sensors: the normals of Kinect v1 depth (quantised, noisy) make the
  point-to-plane residual a poor measure there. On the real 7-Scenes frames, over twelve orderings of the same
  frames (forward / reversed, every 1st / 2nd / 3rd frame; ``benchmarks/tracking_7scenes.py``), this form with
  w_G = 30 (the ratio of Open3D's legacy defaults, λ_dep / λ_img = 0.968 / 0.032) gives a mean ATE of 2.27 /
  2.34 cm at 640×480 / 320×240 against 2.73 / 2.92 cm for point-to-plane with w_G = 10; at w_G = 10 it gives
  3.07 / 2.97 cm. The simulated daylight recordings (noise-free rendered depth) keep the paper's form;
* ρ are Huber norms (``intensity_huber_delta``, ``geometric_huber_delta_m``) realised as IRLS weights;
* optionally a prior ``½ λ N |log(T T₀⁻¹)|²`` at the start pose ``T₀`` (``pose_prior_weight`` λ per associated
  pixel, N of them, so it does not depend on the resolution; off by default here). Not in Eq. 7: the tracker
  (:class:`lightfast.tracking.pipeline.TrackerConfig`) turns it on for f2f, where ``T₀`` is the constant-velocity
  prediction, like the motion prior of Kerl et al. (ICRA 2013). A view of one plain wall, or of a wall and the
  floor, leaves directions that neither term constrains, and there Gauss–Newton followed noise by centimetres per
  frame (simulated DS2: 7 % tracking loss without it, < 1 % with it). Started 2.4 mm from the truth of a textured
  7-Scenes pair it costs 0.06 mm (0.9 mm without the colour term);
* Gauss–Newton with left increments ``T ← exp(ξ) T``, ``ξ = (ρ, φ)`` (see :mod:`lightfast.geometry`), on a
  ``pyramid_levels`` image pyramid (2×2 block means; depth averaged only where the block is continuous),
  coarse to fine, ``iterations`` per level, early stop when ``|ξ| < step_tolerance``.

Units fix the meaning of w_G: with intensities in [0, 1] and residuals in metres, w_G = 10 weights a 1 cm
point-to-plane error (10·1e-4) like a 3 % intensity error (9e-4). The paper does not state its units; this is the
assumption made here.
"""
from __future__ import annotations

import math
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import cast

import cv2
import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.config import Config, ConfigError, param
from lightfast.geometry import se3_exp, se3_log
from lightfast.tracking.errors import TrackingInputError

__all__ = [
    "GEOMETRIC_TERMS",
    "TRACKING_MODES",
    "AlignResult",
    "RGBDFrame",
    "SequenceTrack",
    "TrackingConfig",
    "align",
    "align_frames",
    "prepare_frame",
    "track_sequence",
    "warm_up",
]

#: Tracking variants of paper §IV: the proposed method and its baselines.
TRACKING_MODES = ("proposed", "refl-f2m", "depth-only", "no-color-f2m")
#: Forms of the geometric term E_G (see the module docstring).
GEOMETRIC_TERMS = ("point-to-plane", "depth-difference")
_GREY = np.array([0.299, 0.587, 0.114], dtype=np.float32)
_MIN_CORRESPONDENCES = 50


@dataclass(frozen=True)
class TrackingConfig(Config):
    """Options of the direct RGB-D alignment of paper §III-D (Eq. 7)."""

    mode: str = param(
        "proposed",
        description="Tracking variant (paper §IV); align() only distinguishes depth-only (E_C off) from the rest.",
        choices=TRACKING_MODES,
    )
    geometric_weight: float = param(10.0, description="w_G of Eq. 7 (geometric vs photometric term).", min=0.0)
    geometric_term: str = param(
        "point-to-plane", description="Form of E_G: point-to-plane distance to the reference surface (KinectFusion "
        "[10], the paper's) or depth-difference along the reference ray (Kerl et al., DVO; Open3D's hybrid term).",
        choices=GEOMETRIC_TERMS,
    )
    pyramid_levels: int = param(3, description="Image pyramid levels (factor 2 each).", min=1, max=6)
    iterations: tuple[int, ...] = param(
        (10, 5, 3), description="Gauss-Newton iterations per pyramid level, coarse to fine.", min=1, max=200
    )
    resolution_scale: float = param(
        1.0, description="Input downscale before the pyramid (0.5: 640x480 -> 320x240).", choices=(1.0, 0.5)
    )
    min_depth_m: float = param(0.2, description="Live/reference depth below this is invalid, m.", min=0.0)
    max_depth_m: float = param(4.0, description="Live/reference depth above this is invalid, m.", min=0.01)
    depth_outlier_trunc_m: float = param(
        0.07, description="Associations whose depths differ by more are outliers (occlusion), m.", min=1e-4
    )
    depth_discontinuity_m: float = param(
        0.05, description="A 2x2 depth block spanning more than this is invalid one pyramid level up, m.", min=1e-4
    )
    intensity_huber_delta: float = param(
        0.1, description="Huber threshold of the photometric residual (grey in [0, 1]).", min=1e-6
    )
    geometric_huber_delta_m: float = param(
        0.02, description="Huber threshold of the point-to-plane residual, m.", min=1e-6
    )
    pose_prior_weight: float = param(
        0.0, description="Weight per associated pixel of a prior at the start pose of the alignment, per m^2 of "
        "translation and rad^2 of rotation, in the units of the Eq. 7 cost; 0 = off (Eq. 7 alone). A plain wall leaves "
        "directions the data does not constrain, where Gauss-Newton walks on noise.", min=0.0,
    )
    step_tolerance: float = param(
        1e-4, description="Stop a level when the update norm |xi| falls below this (1e-4: 0.1 mm / 0.006 deg).",
        min=0.0,
    )
    finest_level: int = param(
        0, description="Pyramid level where the alignment stops: 0 = full resolution, 1 = half, ...", min=0, max=5
    )
    finest_point_step: int = param(
        2, description="Source points at the finest level: every pixel (1), a checkerboard (2) or every second row "
        "and column (4); the reference keeps every pixel.", choices=(1, 2, 4)
    )
    min_inlier_ratio: float = param(
        0.2, description="Below this inlier ratio the result is flagged as not converged.", min=0.0, max=1.0
    )

    def check(self) -> None:
        if self.finest_level >= self.pyramid_levels:
            raise ConfigError(f"finest_level={self.finest_level} must be below pyramid_levels={self.pyramid_levels}")
        if len(self.iterations) != self.pyramid_levels:
            raise ConfigError(
                f"TrackingConfig.iterations has {len(self.iterations)} entries, expected pyramid_levels="
                f"{self.pyramid_levels} (coarse to fine)"
            )
        if self.max_depth_m <= self.min_depth_m:
            raise ConfigError(f"max_depth_m ({self.max_depth_m}) must exceed min_depth_m ({self.min_depth_m})")


@dataclass(frozen=True)
class AlignResult:
    """Outcome of :func:`align`.

    ``T_target_source`` maps source (live) camera coordinates to target (reference) camera coordinates.
    ``converged``: the finest level stopped on ``step_tolerance`` (or its iteration budget with a small last
    step) with enough inliers. ``iterations``: Gauss–Newton steps over all levels. ``inlier_ratio``: share of
    valid live-depth pixels at the finest level that are associated and inside the Huber threshold of their
    term(s). ``residual``: Eq. 7 cost per associated pixel (Huber norms, ``ρ_C + w_G ρ_G``). The last two are
    taken at the last linearisation of the finest level, i.e. before its final (converged, small) step.
    """

    T_target_source: NDArray[np.float64]
    converged: bool
    iterations: int
    inlier_ratio: float
    residual: float


@dataclass(frozen=True)
class SequenceTrack:
    """Frame-to-frame tracking of a sequence: ``poses[i]`` is ``T_world_cam`` of frame ``i`` (``poses[0]`` the
    given start pose), ``results[i-1]`` the alignment of frame ``i`` to frame ``i-1``, ``seconds[i-1]`` its time
    (pyramid construction included)."""

    poses: NDArray[np.float64]
    results: tuple[AlignResult, ...]
    seconds: NDArray[np.float64]


# --------------------------------------------------------------------------------------------------------------
# Frame preparation


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


@numba.njit(cache=True, nogil=True)
def _downsample_depth(depth: NDArray[np.float32], discontinuity: float) -> NDArray[np.float32]:
    """2×2 block means of the valid depths; 0 where no depth is valid or the block spans a discontinuity."""
    h, w = depth.shape[0] // 2, depth.shape[1] // 2
    out = np.zeros((h, w), dtype=np.float32)
    for i in range(h):
        for j in range(w):
            total = 0.0
            count = 0
            lo = np.inf
            hi = -np.inf
            for di in range(2):
                for dj in range(2):
                    d = depth[2 * i + di, 2 * j + dj]
                    if d > 0.0:
                        total += d
                        count += 1
                        lo = min(lo, d)
                        hi = max(hi, d)
            if count > 0 and hi - lo <= discontinuity:
                out[i, j] = total / count
    return out


@numba.njit(cache=True, nogil=True)
def _geometry_map(depth: NDArray[np.float32], fx: float, fy: float, cx: float, cy: float) -> NDArray[np.float32]:
    """(H, W, 7): depth, vertex xyz (camera frame, m) and unit normal xyz facing the camera (from central
    differences of the vertex map; NaN where the depth or a neighbour is missing)."""
    h, w = depth.shape
    out = np.full((h, w, 7), np.nan, dtype=np.float32)
    for i in range(h):
        for j in range(w):
            z = depth[i, j]
            out[i, j, 0] = z
            if z > 0.0:
                out[i, j, 1] = (j - cx) / fx * z
                out[i, j, 2] = (i - cy) / fy * z
                out[i, j, 3] = z
    for i in range(1, h - 1):
        for j in range(1, w - 1):
            if not (depth[i, j] > 0.0):
                continue
            ax = out[i, j + 1, 1] - out[i, j - 1, 1]
            ay = out[i, j + 1, 2] - out[i, j - 1, 2]
            az = out[i, j + 1, 3] - out[i, j - 1, 3]
            bx = out[i + 1, j, 1] - out[i - 1, j, 1]
            by = out[i + 1, j, 2] - out[i - 1, j, 2]
            bz = out[i + 1, j, 3] - out[i - 1, j, 3]
            nx = ay * bz - az * by
            ny = az * bx - ax * bz
            nz = ax * by - ay * bx
            norm = np.sqrt(nx * nx + ny * ny + nz * nz)
            if not (norm > 0.0):  # also NaN: a neighbour without depth
                continue
            if nx * out[i, j, 1] + ny * out[i, j, 2] + nz * out[i, j, 3] > 0.0:
                norm = -norm
            out[i, j, 4] = nx / norm
            out[i, j, 5] = ny / norm
            out[i, j, 6] = nz / norm
    return out


@numba.njit(cache=True, nogil=True)
def _depth_gradient(depth: NDArray[np.float32], discontinuity_m: float) -> NDArray[np.float32]:
    """(H, W, 2): Sobel dD/du, dD/dv (÷8, m/px) where the whole 3×3 neighbourhood has depth and neither derivative
    exceeds ``discontinuity_m``; NaN elsewhere (and on the image border)."""
    h, w = depth.shape
    out = np.full((h, w, 2), np.nan, dtype=np.float32)
    for i in range(1, h - 1):
        for j in range(1, w - 1):
            full = True
            for di in range(-1, 2):
                for dj in range(-1, 2):
                    if not (depth[i + di, j + dj] > 0.0):
                        full = False
            if not full:
                continue
            gu = 0.125 * ((depth[i - 1, j + 1] - depth[i - 1, j - 1]) + 2.0 * (depth[i, j + 1] - depth[i, j - 1])
                          + (depth[i + 1, j + 1] - depth[i + 1, j - 1]))
            gv = 0.125 * ((depth[i + 1, j - 1] - depth[i - 1, j - 1]) + 2.0 * (depth[i + 1, j] - depth[i - 1, j])
                          + (depth[i + 1, j + 1] - depth[i - 1, j + 1]))
            if abs(gu) <= discontinuity_m and abs(gv) <= discontinuity_m:
                out[i, j, 0] = gu
                out[i, j, 1] = gv
    return out


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


@numba.njit(cache=True, nogil=True, inline="always")
def _kept(i: int, j: int, step: int) -> bool:
    """Pixel (i, j) is a source point at ``step``: every pixel (1), a checkerboard (2), every 2nd row and column (4)."""
    return step == 1 or (step == 2 and (i + j) % 2 == 0) or (step == 4 and i % 2 == 0 and j % 2 == 0)


@numba.njit(cache=True, nogil=True)
def _source_points(geometry: NDArray[np.float32], grey: NDArray[np.float32], step: int
                   ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Vertices (N, 3) and grey values (N,) of the pixels with depth that :func:`_kept` keeps, row-major."""
    h, w = grey.shape
    n = 0
    for i in range(h):
        for j in range(w):
            if geometry[i, j, 0] > 0.0 and _kept(i, j, step):
                n += 1
    points = np.empty((n, 3), dtype=np.float32)
    point_grey = np.empty(n, dtype=np.float32)
    k = 0
    for i in range(h):
        for j in range(w):
            if geometry[i, j, 0] > 0.0 and _kept(i, j, step):
                points[k, 0], points[k, 1], points[k, 2] = geometry[i, j, 1], geometry[i, j, 2], geometry[i, j, 3]
                point_grey[k] = grey[i, j]
                k += 1
    return points, point_grey


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


# --------------------------------------------------------------------------------------------------------------
# Gauss–Newton


@dataclass
class _Terms:
    H: NDArray[np.float64]
    b: NDArray[np.float64]
    count: int
    inliers: int
    cost: float


@numba.njit(cache=True, nogil=True, inline="always")
def _add_huber_term(out: NDArray[np.float64], J: NDArray[np.float64], r: float, delta: float,
                    weight: float) -> tuple[float, bool]:
    """Add ``weight · ρ_δ`` (Huber, as an IRLS weight) of one residual with Jacobian ``J`` (6,) to ``out``: the
    upper triangle of JᵀWJ in ``out[:21]``, JᵀWr in ``out[21:]``; returns (cost, inside the Huber threshold)."""
    ar = abs(r)
    if ar <= delta:
        w = weight
        cost = weight * 0.5 * r * r
    else:
        w = weight * delta / ar
        cost = weight * delta * (ar - 0.5 * delta)
    k = 0
    for m in range(6):
        wj = w * J[m]
        for n in range(m, 6):
            out[k] += wj * J[n]
            k += 1
        out[21 + m] += wj * r
    return cost, ar <= delta


@numba.njit(cache=True, nogil=True, fastmath=False)
def _accumulate(
    points: NDArray[np.float32],
    point_grey: NDArray[np.float32],
    T: NDArray[np.float64],
    intrinsics: NDArray[np.float64],
    grey_grad: NDArray[np.float32],
    geometry: NDArray[np.float32],
    depth_grad: NDArray[np.float32],
    use_color: bool,
    use_depth: bool,
    depth_difference: bool,
    trunc: float,
    delta_c: float,
    delta_g: float,
    w_g: float,
) -> tuple[NDArray[np.float64], int, int, float]:
    """One Gauss–Newton linearisation of Eq. 7: ``out[:21]`` the upper triangle of ``JᵀWJ``, ``out[21:]``
    ``JᵀWr``; returns (out, associated count, inlier count, summed Huber cost). See the module docstring."""
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    height, width = geometry.shape[0], geometry.shape[1]
    umax, vmax = width - 1.001, height - 1.001
    out = np.zeros(27)
    J = np.empty(6)
    count = 0
    inliers = 0
    cost = 0.0
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        qx = T[0, 0] * px + T[0, 1] * py + T[0, 2] * pz + T[0, 3]
        qy = T[1, 0] * px + T[1, 1] * py + T[1, 2] * pz + T[1, 3]
        qz = T[2, 0] * px + T[2, 1] * py + T[2, 2] * pz + T[2, 3]
        if qz <= 1e-6:
            continue
        zi = 1.0 / qz
        u = fx * qx * zi + cx
        v = fy * qy * zi + cy
        if not (u >= 0.0 and u <= umax and v >= 0.0 and v <= vmax):
            continue
        iu = int(u + 0.5)
        iv = int(v + 0.5)
        d_t = geometry[iv, iu, 0]
        if not (d_t > 0.0) or abs(d_t - qz) > trunc:
            continue
        if use_depth and not np.isfinite(depth_grad[iv, iu, 0] if depth_difference else geometry[iv, iu, 4]):
            continue
        count += 1
        inlier = True
        if use_color:
            u0 = int(u)
            v0 = int(v)
            a = u - u0
            c = v - v0
            w00 = (1.0 - a) * (1.0 - c)
            w01 = a * (1.0 - c)
            w10 = (1.0 - a) * c
            w11 = a * c
            s0 = (w00 * grey_grad[v0, u0, 0] + w01 * grey_grad[v0, u0 + 1, 0]
                  + w10 * grey_grad[v0 + 1, u0, 0] + w11 * grey_grad[v0 + 1, u0 + 1, 0])
            gu = (w00 * grey_grad[v0, u0, 1] + w01 * grey_grad[v0, u0 + 1, 1]
                  + w10 * grey_grad[v0 + 1, u0, 1] + w11 * grey_grad[v0 + 1, u0 + 1, 1])
            gv = (w00 * grey_grad[v0, u0, 2] + w01 * grey_grad[v0, u0 + 1, 2]
                  + w10 * grey_grad[v0 + 1, u0, 2] + w11 * grey_grad[v0 + 1, u0 + 1, 2])
            r = s0 - point_grey[i]
            ga = gu * fx * zi
            gc = gv * fy * zi
            gd = -(ga * qx + gc * qy) * zi
            J[0], J[1], J[2] = ga, gc, gd
            J[3] = qy * gd - qz * gc
            J[4] = qz * ga - qx * gd
            J[5] = qx * gc - qy * ga
            c, ok = _add_huber_term(out, J, r, delta_c, 1.0)
            cost += c
            inlier &= ok
        if use_depth:
            if depth_difference:  # r = D_t(round(y)) - q_z; dr/dq = ∇D_t ∂π/∂q - e_z
                r = d_t - qz
                ga = depth_grad[iv, iu, 0] * fx * zi
                gc = depth_grad[iv, iu, 1] * fy * zi
                J[0], J[1], J[2] = ga, gc, -(ga * qx + gc * qy) * zi - 1.0
            else:  # r = n_t · (q - v_t)
                nx, ny, nz = geometry[iv, iu, 4], geometry[iv, iu, 5], geometry[iv, iu, 6]
                r = nx * (qx - geometry[iv, iu, 1]) + ny * (qy - geometry[iv, iu, 2]) + nz * (qz - geometry[iv, iu, 3])
                J[0], J[1], J[2] = nx, ny, nz
            J[3] = qy * J[2] - qz * J[1]
            J[4] = qz * J[0] - qx * J[2]
            J[5] = qx * J[1] - qy * J[0]
            c, ok = _add_huber_term(out, J, r, delta_g, w_g)
            cost += c
            inlier &= ok
        if inlier:
            inliers += 1
    return out, count, inliers, cost


_TRIU = np.triu_indices(6)
_NO_DEPTH_GRAD = np.full((1, 1, 2), np.nan, dtype=np.float32)  # the point-to-plane term does not read it


def _linearize(
    src: _Level, tgt: _Level, T: NDArray[np.float64], cfg: TrackingConfig, use_color: bool, use_depth: bool
) -> _Terms:
    cam = tgt.camera
    intrinsics = np.array([cam.fx, cam.fy, cam.cx, cam.cy], dtype=np.float64)
    depth_difference = cfg.geometric_term == "depth-difference"
    out, count, inliers, cost = _accumulate(
        src.points, src.point_grey, np.ascontiguousarray(T, dtype=np.float64), intrinsics, tgt.grey_grad,
        tgt.geometry, tgt.depth_grad if depth_difference and use_depth else _NO_DEPTH_GRAD, use_color, use_depth,
        depth_difference, cfg.depth_outlier_trunc_m, cfg.intensity_huber_delta, cfg.geometric_huber_delta_m,
        cfg.geometric_weight,
    )
    H = np.zeros((6, 6))
    H[_TRIU] = out[:21]
    H = H + np.triu(H, 1).T
    return _Terms(H, out[21:].copy(), int(count), int(inliers), float(cost) / max(int(count), 1))


def _align_pyramids(
    src: tuple[_Level, ...],
    tgt: tuple[_Level, ...],
    init: NDArray[np.float64],
    cfg: TrackingConfig,
    use_color: bool,
    use_depth: bool,
    finest_level: int | None = None,
) -> AlignResult:
    """Gauss–Newton coarse to fine over the level pairs ``(src[k], tgt[k])`` from the coarsest down to
    ``finest_level`` (default ``cfg.finest_level``)."""
    finest = cfg.finest_level if finest_level is None else finest_level
    T = init.copy()
    init_inv = np.linalg.inv(init)
    total_iterations = 0
    level_converged = False
    terms = _Terms(np.zeros((6, 6)), np.zeros(6), 0, 0, math.inf)
    for level in reversed(range(finest, cfg.pyramid_levels)):
        n_iter = cfg.iterations[cfg.pyramid_levels - 1 - level]
        level_converged = False
        for _ in range(n_iter):
            terms = _linearize(src[level], tgt[level], T, cfg, use_color, use_depth)
            if terms.count < _MIN_CORRESPONDENCES:
                break
            H, b = terms.H, terms.b
            if cfg.pose_prior_weight > 0.0:  # ½ eᵀΛe, e = log(T init⁻¹): stay put where the data says nothing
                lam = cfg.pose_prior_weight * terms.count  # per associated pixel: resolution-independent
                H = H + lam * np.eye(6)
                b = b + lam * se3_log(T @ init_inv)
            try:
                xi = np.linalg.solve(H, -b)
            except np.linalg.LinAlgError:
                break
            if not np.all(np.isfinite(xi)):
                break
            T = se3_exp(xi) @ T
            total_iterations += 1
            if float(np.linalg.norm(xi)) < cfg.step_tolerance:
                level_converged = True
                break
        else:
            # iteration budget used up: accept if the last step was small relative to the motion scale
            level_converged = terms.count >= _MIN_CORRESPONDENCES and float(np.linalg.norm(xi)) < 1e-3
    # statistics of the last linearisation at the finest level (before its final, small step)
    final = terms if total_iterations else _linearize(src[finest], tgt[finest], T, cfg, use_color, use_depth)
    n_valid = max(len(src[finest].points), 1)
    inlier_ratio = final.inliers / n_valid
    converged = level_converged and final.count >= _MIN_CORRESPONDENCES and inlier_ratio >= cfg.min_inlier_ratio
    residual = final.cost if final.count else math.inf
    return AlignResult(T, bool(converged), total_iterations, float(inlier_ratio), float(residual))


def _resolve_terms(cfg: TrackingConfig, use_color: bool | None, use_depth: bool | None) -> tuple[bool, bool]:
    color = cfg.mode != "depth-only" if use_color is None else bool(use_color)
    depth = True if use_depth is None else bool(use_depth)
    if not (color or depth):
        raise TrackingInputError("align needs at least one of use_color / use_depth")
    return color, depth


def _check_init(init: ArrayLike | None) -> NDArray[np.float64]:
    T = np.eye(4) if init is None else np.asarray(init, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise TrackingInputError(f"init_T_target_source must be a finite 4x4 matrix, got shape {T.shape}")
    return T


def align(
    source_rgb: ArrayLike,
    source_depth_m: ArrayLike,
    target_rgb: ArrayLike,
    target_depth_m: ArrayLike,
    camera: PinholeCamera,
    *,
    init_T_target_source: ArrayLike | None = None,
    config: TrackingConfig | None = None,
    use_color: bool | None = None,
    use_depth: bool | None = None,
) -> AlignResult:
    """Align a live (source) RGB-D frame to a reference (target) one by minimising Eq. 7 of paper §III-D.

    Colour images are ``(H, W, 3)`` RGB (uint8, or float in [0, 1]) or ``(H, W)`` grey; depth images ``(H, W)``
    float metres (0 / NaN / outside ``[min_depth_m, max_depth_m]`` invalid); both at ``camera``'s full size (the
    ``resolution_scale`` is applied here). ``use_color`` (E_C) defaults to ``config.mode != "depth-only"``,
    ``use_depth`` (E_G) to True; the live depth is always used for data association.

    Raises :class:`TrackingError` on mismatched sizes, non-metric depth, or an image without valid depth.
    """
    cfg = TrackingConfig() if config is None else config
    color, depth = _resolve_terms(cfg, use_color, use_depth)
    init = _check_init(init_T_target_source)
    src = _prepare(source_rgb, source_depth_m, camera, cfg, "source")
    tgt = _prepare(target_rgb, target_depth_m, camera, cfg, "target")
    return _align_pyramids(src.levels, tgt.levels, init, cfg, color, depth)


def align_frames(
    source: RGBDFrame,
    target: RGBDFrame,
    *,
    init_T_target_source: ArrayLike | None = None,
    config: TrackingConfig | None = None,
    use_color: bool | None = None,
    use_depth: bool | None = None,
) -> AlignResult:
    """:func:`align` on frames prepared once by :func:`prepare_frame` (a live frame serves as the f2f source,
    then as the f2f target of the next frame, and as the f2m source against the reference).

    The target may be rendered at half the source's resolution (a reference at ``reference_scale`` 0.5): then
    source level ``k ≥ 1`` is aligned to target level ``k − 1``, of the same resolution, and the alignment stops at
    source level 1 (the reference's resolution) whatever ``finest_level`` says. (Pairing level ``k`` with level
    ``k`` instead started the alignment on a quarter-size target whose coarsest level, 40×30 for a 320×240 camera,
    left a plain room corner unconstrained: f2m started at the truth walked 0.4–0.8 m away on the simulated DS2.
    Projecting the full-resolution source level into the half-resolution target as well, four source points per
    target pixel, doubled the cost of f2m for no accuracy: simulated DS1/DS2 `proposed` 2.28 cm / 0.64 % loss
    with it, 2.30 cm / 0.57 % without.)"""
    cfg = TrackingConfig() if config is None else config
    color, depth = _resolve_terms(cfg, use_color, use_depth)
    init = _check_init(init_T_target_source)
    for role, frame in (("source", source), ("target", target)):
        if (frame.pyramid_levels, frame.resolution_scale) != (cfg.pyramid_levels, cfg.resolution_scale):
            raise TrackingInputError(
                f"{role} frame was prepared with pyramid_levels={frame.pyramid_levels}, resolution_scale="
                f"{frame.resolution_scale}; this alignment uses {cfg.pyramid_levels}, {cfg.resolution_scale}"
            )
    if target.camera not in (source.camera, source.camera.scaled(0.5)):
        raise TrackingInputError(f"the target camera must be the source camera or the source camera at half "
                                 f"resolution: source {source.camera}, target {target.camera}")
    if target.camera == source.camera:
        return _align_pyramids(source.levels, target.levels, init, cfg, color, depth)
    # half resolution: same-size levels together; the full-resolution source level has no partner
    levels = (target.levels[0], *target.levels[:-1])
    return _align_pyramids(source.levels, levels, init, cfg, color, depth, max(cfg.finest_level, 1))


def track_sequence(
    frames: Iterable[tuple[ArrayLike, ArrayLike]],
    camera: PinholeCamera,
    *,
    config: TrackingConfig | None = None,
    T_world_first: ArrayLike | None = None,
    use_color: bool | None = None,
    use_depth: bool | None = None,
    constant_velocity: bool = True,
) -> SequenceTrack:
    """Frame-to-frame tracking (the f2f step of §III-D) over ``(rgb, depth_m)`` frames; each frame is aligned to
    its predecessor, starting from the previous relative motion (``constant_velocity``, as ``rgbd_tracker_node``
    does; identity after an alignment that did not converge) or from identity, and the relative motions are
    chained from ``T_world_first``."""
    cfg = TrackingConfig() if config is None else config
    color, depth = _resolve_terms(cfg, use_color, use_depth)
    T_world = _check_init(T_world_first)
    poses = []
    results: list[AlignResult] = []
    seconds: list[float] = []
    prev: RGBDFrame | None = None
    velocity = np.eye(4)
    for i, (rgb, depth_m) in enumerate(frames):
        t0 = time.perf_counter()
        cur = _prepare(rgb, depth_m, camera, cfg, f"frame {i}")
        if prev is not None:
            res = _align_pyramids(cur.levels, prev.levels, velocity, cfg, color, depth)
            T_world = T_world @ res.T_target_source
            velocity = res.T_target_source if constant_velocity and res.converged else np.eye(4)
            results.append(res)
            seconds.append(time.perf_counter() - t0)
        poses.append(T_world.copy())
        prev = cur
    if not poses:
        raise TrackingInputError("track_sequence got no frames")
    return SequenceTrack(np.stack(poses), tuple(results), np.asarray(seconds))


def warm_up(config: TrackingConfig | None = None) -> float:
    """Run every jitted kernel once on a tiny synthetic frame (a slanted plane with a colour ramp) with ``config``'s
    pyramid, so that a node's first live frame does not pay for numba's loading or compiling; returns seconds."""
    cfg = TrackingConfig() if config is None else config
    t0 = time.perf_counter()
    size = max(16, 8 * 2 ** (cfg.pyramid_levels - 1) * (2 if cfg.resolution_scale != 1.0 else 1))
    camera = PinholeCamera(size, size, float(size), float(size), (size - 1) / 2, (size - 1) / 2)
    v, u = np.mgrid[0:size, 0:size].astype(np.float32) / size
    depth = (0.5 * (cfg.min_depth_m + cfg.max_depth_m) * (1.0 + 0.05 * u + 0.03 * v)).astype(np.float32)
    rgb = (np.stack([u, v, 0.5 * (u + v)], axis=-1) * 255).astype(np.uint8)
    frame = prepare_frame(rgb, depth, camera, config=cfg, name="warm-up frame")
    align_frames(frame, frame, config=cfg, use_color=True, use_depth=True)
    return time.perf_counter() - t0
