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
point-to-plane method cannot be combined with the intensity term. Engine (b) was therefore chosen: a vectorised
NumPy Gauss–Newton on SE(3) that implements Eq. 7 literally. It is ~10× slower than Open3D (measured on the
shared, loaded 2-core machine: ~0.4 s per frame at 320×240, ~1.3 s at 640×480, against Open3D's 0.04–0.2 s);
``benchmarks/tracking_7scenes.py`` compares accuracy and speed of both on 7-Scenes.

The cost, as implemented
------------------------
For every source pixel ``x`` with valid live depth, ``p = π⁻¹(x, D_s(x))`` and ``q = T p`` (target camera):

* association: ``y = π(q)`` must fall inside the target image and the target depth at ``round(y)`` must be valid
  and within ``depth_outlier_trunc_m`` of ``q_z`` (occlusion / outlier test) — used by both terms, as in the paper;
* E_C = Σ ρ_C(r_C), ``r_C = I_t(y) - I_s(x)`` on grey intensities in [0, 1] (Rec. 601), ``I_t`` and its Sobel
  gradient bilinearly interpolated;
* E_G = Σ ρ_G(r_G), ``r_G = n_t · (q - v_t)`` with the target vertex ``v_t`` and normal ``n_t`` (from the target
  depth by central differences) at ``round(y)`` — point-to-plane with projective association [10], in metres;
* ρ are Huber norms (``intensity_huber_delta``, ``geometric_huber_delta_m``) realised as IRLS weights;
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

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.config import Config, ConfigError, param
from lightfast.errors import LightfastError
from lightfast.geometry import se3_exp

__all__ = [
    "TRACKING_MODES",
    "AlignResult",
    "SequenceTrack",
    "TrackingConfig",
    "TrackingError",
    "align",
    "track_sequence",
]

#: Tracking variants of paper §IV: the proposed method and its baselines.
TRACKING_MODES = ("proposed", "refl-f2m", "depth-only", "no-color-f2m")
_GREY = np.array([0.299, 0.587, 0.114], dtype=np.float32)
_MIN_CORRESPONDENCES = 50


class TrackingError(LightfastError, ValueError):
    """Inputs that cannot be aligned: wrong shapes or sizes, no valid depth, nothing to optimise."""


@dataclass(frozen=True)
class TrackingConfig(Config):
    """Options of the direct RGB-D alignment of paper §III-D (Eq. 7)."""

    mode: str = param(
        "proposed",
        description="Tracking variant (paper §IV); align() only distinguishes depth-only (E_C off) from the rest.",
        choices=TRACKING_MODES,
    )
    geometric_weight: float = param(10.0, description="w_G of Eq. 7 (geometric vs photometric term).", min=0.0)
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
    step_tolerance: float = param(
        1e-6, description="Stop a level when the update norm |xi| falls below this.", min=0.0
    )
    min_inlier_ratio: float = param(
        0.2, description="Below this inlier ratio the result is flagged as not converged.", min=0.0, max=1.0
    )

    def check(self) -> None:
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


@dataclass(frozen=True)
class _Level:
    camera: PinholeCamera
    grey: NDArray[np.float32]  # (H, W)
    depth: NDArray[np.float32]  # (H, W), 0 = invalid
    # source role: valid pixels
    points: NDArray[np.float32]  # (N, 3)
    point_grey: NDArray[np.float32]  # (N,)
    # target role
    grey_grad: NDArray[np.float32]  # (H, W, 3): I, dI/du, dI/dv
    geometry: NDArray[np.float32]  # (H, W, 7): depth, vertex xyz, normal xyz (NaN where undefined)


def _to_grey(rgb: NDArray[np.generic], name: str) -> NDArray[np.float32]:
    a = np.asarray(rgb)
    if a.ndim == 3 and a.shape[2] == 3:
        grey = a.astype(np.float32) @ _GREY
    elif a.ndim == 2:
        grey = a.astype(np.float32)
    else:
        raise TrackingError(f"{name} must be (H, W, 3) RGB or (H, W) grey, got shape {a.shape}")
    if a.dtype == np.uint8:
        grey *= np.float32(1.0 / 255.0)
    elif not np.issubdtype(a.dtype, np.floating):
        raise TrackingError(f"{name} must be uint8 or float in [0, 1], got dtype {a.dtype}")
    if not np.all(np.isfinite(grey)):
        raise TrackingError(f"{name} holds non-finite values")
    return grey


def _check_depth(depth_m: ArrayLike, name: str, cfg: TrackingConfig) -> NDArray[np.float32]:
    d = np.asarray(depth_m)
    if d.ndim != 2:
        raise TrackingError(f"{name} must be a (H, W) depth image in metres, got shape {d.shape}")
    if not np.issubdtype(d.dtype, np.floating):
        raise TrackingError(f"{name} must be float metres, got dtype {d.dtype} (convert millimetres first)")
    d = d.astype(np.float32)
    valid = np.isfinite(d) & (d >= cfg.min_depth_m) & (d <= cfg.max_depth_m)
    return np.where(valid, d, np.float32(0.0))


def _downsample_grey(grey: NDArray[np.float32]) -> NDArray[np.float32]:
    h, w = grey.shape[0] // 2, grey.shape[1] // 2
    return grey[: 2 * h, : 2 * w].reshape(h, 2, w, 2).mean(axis=(1, 3), dtype=np.float32)


def _downsample_depth(depth: NDArray[np.float32], discontinuity: float) -> NDArray[np.float32]:
    h, w = depth.shape[0] // 2, depth.shape[1] // 2
    blocks = depth[: 2 * h, : 2 * w].reshape(h, 2, w, 2)
    valid = blocks > 0
    count = valid.sum(axis=(1, 3))
    total = blocks.sum(axis=(1, 3))
    hi = np.where(valid, blocks, -np.inf).max(axis=(1, 3))
    lo = np.where(valid, blocks, np.inf).min(axis=(1, 3))
    ok = (count > 0) & (hi - lo <= discontinuity)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok, total / np.maximum(count, 1), 0.0).astype(np.float32)


def _vertex_normal_map(depth: NDArray[np.float32], camera: PinholeCamera) -> tuple[NDArray[np.float32], ...]:
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(np.float32)
    z = np.where(depth > 0, depth, np.float32(np.nan))
    V = np.stack([(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z], axis=-1)
    du = np.full_like(V, np.nan)
    dv = np.full_like(V, np.nan)
    du[:, 1:-1] = V[:, 2:] - V[:, :-2]
    dv[1:-1] = V[2:] - V[:-2]
    n = np.cross(du, dv)
    with np.errstate(invalid="ignore", divide="ignore"):
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        flip = np.sum(n * V, axis=-1) > 0  # orient towards the camera
    n[flip] *= -1.0
    return V, n


def _prepare(rgb: ArrayLike, depth_m: ArrayLike, camera: PinholeCamera, cfg: TrackingConfig, role: str) -> list[_Level]:
    grey = _to_grey(np.asarray(rgb), f"{role}_rgb")
    depth = _check_depth(depth_m, f"{role}_depth_m", cfg)
    if grey.shape != camera.shape or depth.shape != camera.shape:
        raise TrackingError(
            f"{role} images must match the camera size {camera.shape} (H, W): colour {grey.shape}, "
            f"depth {depth.shape}"
        )
    if not np.any(depth > 0):
        raise TrackingError(
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
            raise TrackingError(
                f"image too small for {cfg.pyramid_levels} pyramid levels: level {level} is {grey.shape}"
            )
        V, N = _vertex_normal_map(depth, cam)
        valid = depth > 0
        gu = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE) * np.float32(0.125)
        gv = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REPLICATE) * np.float32(0.125)
        levels.append(
            _Level(
                camera=cam,
                grey=grey,
                depth=depth,
                points=V[valid],
                point_grey=grey[valid],
                grey_grad=np.ascontiguousarray(np.stack([grey, gu, gv], axis=-1)),
                geometry=np.ascontiguousarray(np.concatenate([depth[..., None], V, N], axis=-1)),
            )
        )
    return levels


# --------------------------------------------------------------------------------------------------------------
# Gauss–Newton


def _huber_weight(r: NDArray[np.float32], delta: float) -> NDArray[np.float32]:
    """IRLS weight of the Huber norm: 1 inside ``delta``, ``delta / |r|`` outside."""
    return np.float32(delta) / np.maximum(np.abs(r), np.float32(delta))


def _huber(r: NDArray[np.float32], delta: float) -> NDArray[np.float32]:
    a = np.abs(r)
    d = np.float32(delta)
    return np.where(a <= d, np.float32(0.5) * r * r, d * (a - np.float32(0.5) * d))


@dataclass
class _Terms:
    H: NDArray[np.float64]
    b: NDArray[np.float64]
    count: int
    inliers: int
    cost: float


_REMAP_COLS = 1024  # cv2.remap needs maps smaller than 32767 in each dimension: sample along (rows, 1024)


def _sample(image: NDArray[np.float32], u: NDArray[np.float32], v: NDArray[np.float32], nearest: bool) -> NDArray:
    """``image`` (H, W, C) at pixel positions ``(u, v)`` (N,), bilinear or nearest; 0 outside the image."""
    n = len(u)
    m = -(-n // _REMAP_COLS) * _REMAP_COLS
    mu = np.zeros(m, dtype=np.float32)
    mv = np.zeros(m, dtype=np.float32)
    mu[:n] = u
    mv[:n] = v
    out = cv2.remap(
        image,
        mu.reshape(-1, _REMAP_COLS),
        mv.reshape(-1, _REMAP_COLS),
        cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0.0,
    )
    return out.reshape(m, image.shape[2])[:n]


def _cross(a: NDArray[np.float32], b: NDArray[np.float32]) -> NDArray[np.float32]:
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )


def _normal_equations(
    J: NDArray[np.float32], w: NDArray[np.float32], r: NDArray[np.float32]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Weighted Gauss–Newton blocks ``(Jᵀ W J, Jᵀ W r)``, accumulated in float64."""
    J64 = J.astype(np.float64)
    Jw = J64 * w.astype(np.float64)[:, None]
    return Jw.T @ J64, Jw.T @ r.astype(np.float64)


def _linearize(
    src: _Level, tgt: _Level, T: NDArray[np.float64], cfg: TrackingConfig, use_color: bool, use_depth: bool
) -> _Terms:
    cam = tgt.camera
    q = src.points @ T[:3, :3].T.astype(np.float32) + T[:3, 3].astype(np.float32)
    z = q[:, 2]
    front = z > 1e-6
    zi = np.float32(1.0) / np.where(front, z, np.float32(1.0))
    u = cam.fx * q[:, 0] * zi + cam.cx
    v = cam.fy * q[:, 1] * zi + cam.cy
    keep = front & (u >= 0.0) & (u <= cam.width - 1.001) & (v >= 0.0) & (v <= cam.height - 1.001)
    # projective association (nearest pixel) with an occlusion / outlier test on depth
    geo = _sample(tgt.geometry, u, v, nearest=True)
    keep &= (geo[:, 0] > 0) & (np.abs(geo[:, 0] - z) <= cfg.depth_outlier_trunc_m)
    if use_depth:
        keep &= np.isfinite(geo[:, 4])
    sel = np.flatnonzero(keep)
    H = np.zeros((6, 6))
    b = np.zeros(6)
    count = len(sel)
    if count == 0:
        return _Terms(H, b, 0, 0, 0.0)
    q, u, v, zi, geo = q[sel], u[sel], v[sel], zi[sel], geo[sel]
    inl = np.ones(count, dtype=bool)
    cost = 0.0
    if use_color:
        s = _sample(tgt.grey_grad, u, v, nearest=False)
        r = s[:, 0] - src.point_grey[sel]
        a = s[:, 1] * np.float32(cam.fx) * zi
        c = s[:, 2] * np.float32(cam.fy) * zi
        d = -(a * q[:, 0] + c * q[:, 1]) * zi
        grad = np.stack([a, c, d], axis=1)
        J = np.concatenate([grad, _cross(q, grad)], axis=1)
        Hc, bc = _normal_equations(J, _huber_weight(r, cfg.intensity_huber_delta), r)
        H += Hc
        b += bc
        cost += float(np.sum(_huber(r, cfg.intensity_huber_delta), dtype=np.float64))
        inl &= np.abs(r) <= cfg.intensity_huber_delta
    if use_depth:
        n = geo[:, 4:7]
        r = np.einsum("ij,ij->i", n, q - geo[:, 1:4])
        J = np.concatenate([n, _cross(q, n)], axis=1)
        Hg, bg = _normal_equations(J, _huber_weight(r, cfg.geometric_huber_delta_m), r)
        H += cfg.geometric_weight * Hg
        b += cfg.geometric_weight * bg
        cost += cfg.geometric_weight * float(np.sum(_huber(r, cfg.geometric_huber_delta_m), dtype=np.float64))
        inl &= np.abs(r) <= cfg.geometric_huber_delta_m
    return _Terms(H, b, count, int(np.count_nonzero(inl)), cost / count)


def _align_pyramids(
    src: list[_Level],
    tgt: list[_Level],
    init: NDArray[np.float64],
    cfg: TrackingConfig,
    use_color: bool,
    use_depth: bool,
) -> AlignResult:
    T = init.copy()
    total_iterations = 0
    level_converged = False
    terms = _Terms(np.zeros((6, 6)), np.zeros(6), 0, 0, math.inf)
    for level in reversed(range(cfg.pyramid_levels)):
        n_iter = cfg.iterations[cfg.pyramid_levels - 1 - level]
        level_converged = False
        for _ in range(n_iter):
            terms = _linearize(src[level], tgt[level], T, cfg, use_color, use_depth)
            if terms.count < _MIN_CORRESPONDENCES:
                break
            try:
                xi = np.linalg.solve(terms.H, -terms.b)
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
    final = terms if total_iterations else _linearize(src[0], tgt[0], T, cfg, use_color, use_depth)
    n_valid = max(len(src[0].points), 1)
    inlier_ratio = final.inliers / n_valid
    converged = level_converged and final.count >= _MIN_CORRESPONDENCES and inlier_ratio >= cfg.min_inlier_ratio
    residual = final.cost if final.count else math.inf
    return AlignResult(T, bool(converged), total_iterations, float(inlier_ratio), float(residual))


def _resolve_terms(cfg: TrackingConfig, use_color: bool | None, use_depth: bool | None) -> tuple[bool, bool]:
    color = cfg.mode != "depth-only" if use_color is None else bool(use_color)
    depth = True if use_depth is None else bool(use_depth)
    if not (color or depth):
        raise TrackingError("align needs at least one of use_color / use_depth")
    return color, depth


def _check_init(init: ArrayLike | None) -> NDArray[np.float64]:
    T = np.eye(4) if init is None else np.asarray(init, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise TrackingError(f"init_T_target_source must be a finite 4x4 matrix, got shape {T.shape}")
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
    return _align_pyramids(src, tgt, init, cfg, color, depth)


def track_sequence(
    frames: Iterable[tuple[ArrayLike, ArrayLike]],
    camera: PinholeCamera,
    *,
    config: TrackingConfig | None = None,
    T_world_first: ArrayLike | None = None,
    use_color: bool | None = None,
    use_depth: bool | None = None,
) -> SequenceTrack:
    """Frame-to-frame tracking (the f2f step of §III-D) over ``(rgb, depth_m)`` frames; each frame is aligned to
    its predecessor starting from identity, and the relative motions are chained from ``T_world_first``."""
    cfg = TrackingConfig() if config is None else config
    color, depth = _resolve_terms(cfg, use_color, use_depth)
    T_world = _check_init(T_world_first)
    poses = []
    results: list[AlignResult] = []
    seconds: list[float] = []
    prev: list[_Level] | None = None
    for i, (rgb, depth_m) in enumerate(frames):
        t0 = time.perf_counter()
        cur = _prepare(rgb, depth_m, camera, cfg, f"frame {i}")
        if prev is not None:
            res = _align_pyramids(cur, prev, np.eye(4), cfg, color, depth)
            T_world = T_world @ res.T_target_source
            results.append(res)
            seconds.append(time.perf_counter() - t0)
        poses.append(T_world.copy())
        prev = cur
    if not poses:
        raise TrackingError("track_sequence got no frames")
    return SequenceTrack(np.stack(poses), tuple(results), np.asarray(seconds))
