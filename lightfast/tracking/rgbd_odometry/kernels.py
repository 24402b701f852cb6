"""Residuals and Jacobians of Eq. 7 (paper §III-D) per source pixel, summed into Gauss–Newton normal equations.

For every source pixel ``x`` with valid live depth, ``p = π⁻¹(x, D_s(x))`` (source camera, m) and ``q = T p`` (target
camera, m), ``T = T_target_source``:

* association: ``y = π(q)`` must fall inside the target image and the target depth at ``round(y)`` must be valid
  and within ``depth_outlier_trunc_m`` of ``q_z`` (occlusion / outlier test) — used by both terms, as in the paper;
* E_C = Σ ρ_C(r_C), ``r_C = I_t(y) - I_s(x)`` on grey intensities in [0, 1] (Rec. 601), ``I_t`` and its Sobel
  gradient bilinearly interpolated;
* E_G = Σ ρ_G(r_G), ``r_G = n_t · (q - v_t)`` with the target vertex ``v_t`` and normal ``n_t`` (from the target
  depth by central differences) at ``round(y)`` — point-to-plane with projective association [10], in metres;
  or, with ``geometric_term="depth-difference"``, ``r_G = D_t(y) - q_z`` with ``D_t`` and its Sobel gradient (the
  Jacobian) bilinearly interpolated, where all four pixels around ``y`` have a gradient (depth in their 3×3
  neighbourhood, no discontinuity): the depth term of Kerl et al., ICRA 2013 (Open3D's hybrid odometry reads the
  nearest pixel, a staircase in ``y`` that Gauss–Newton cycles on; docs/daylight.md). Not the paper's form,
  offered for real depth sensors: the normals of Kinect v1 depth (quantised, noisy) make the point-to-plane
  residual a poor measure there. The simulated daylight recordings keep the paper's form;
* ρ are Huber norms (``intensity_huber_delta``, ``geometric_huber_delta_m``) realised as IRLS weights, the
  geometric one multiplied by w_G.

Jacobians are taken with respect to a left increment ``ξ = (ρ, φ)`` (m, rad) of ``T``. Output of :func:`linearize`:
``JᵀWJ`` (6×6), ``JᵀWr`` (6,), the numbers of associated and of inlier pixels and the Huber cost per associated
pixel.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from lightfast.tracking.rgbd_odometry.config import TrackingConfig
from lightfast.tracking.rgbd_odometry.pyramid import _Level


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
        u0 = int(u)
        v0 = int(v)
        a = u - u0
        c = v - v0
        w00 = (1.0 - a) * (1.0 - c)
        w01 = a * (1.0 - c)
        w10 = (1.0 - a) * c
        w11 = a * c
        if use_depth:
            if depth_difference:  # the four pixels around y: a gradient (so depth, no discontinuity) at each
                if not (np.isfinite(depth_grad[v0, u0, 0]) and np.isfinite(depth_grad[v0, u0 + 1, 0])
                        and np.isfinite(depth_grad[v0 + 1, u0, 0]) and np.isfinite(depth_grad[v0 + 1, u0 + 1, 0])):
                    continue
            elif not np.isfinite(geometry[iv, iu, 4]):
                continue
        count += 1
        inlier = True
        if use_color:
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
            if depth_difference:  # r = D_t(y) - q_z (bilinear); dr/dq = ∇D_t ∂π/∂q - e_z
                r = (w00 * geometry[v0, u0, 0] + w01 * geometry[v0, u0 + 1, 0]
                     + w10 * geometry[v0 + 1, u0, 0] + w11 * geometry[v0 + 1, u0 + 1, 0]) - qz
                ga = (w00 * depth_grad[v0, u0, 0] + w01 * depth_grad[v0, u0 + 1, 0]
                      + w10 * depth_grad[v0 + 1, u0, 0] + w11 * depth_grad[v0 + 1, u0 + 1, 0]) * fx * zi
                gc = (w00 * depth_grad[v0, u0, 1] + w01 * depth_grad[v0, u0 + 1, 1]
                      + w10 * depth_grad[v0 + 1, u0, 1] + w11 * depth_grad[v0 + 1, u0 + 1, 1]) * fy * zi
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


def linearize(
    src: _Level, tgt: _Level, T: NDArray[np.float64], cfg: TrackingConfig, use_color: bool, use_depth: bool
) -> _Terms:
    """The normal equations (H, b, cost, inliers) of one pyramid level at ``T = T_tgt_src``: the photometric term
    (``use_color``) and the geometric term (``use_depth``) of ``cfg``, weighted as the solver weights them."""
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

