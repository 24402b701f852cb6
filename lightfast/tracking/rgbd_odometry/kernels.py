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
  geometric one multiplied by w_G; or (``robust_norm="t-distribution"``) Student's t on each term's residuals over
  a scale fitted to them at every step (Kerl et al., ICRA 2013), w_G then weighing the normalised terms.

One pass (:func:`_residuals`) computes every associated point's residuals and Jacobians, a second one
(:func:`_normal_equations`) weighs them: the t-distribution's scale needs all residuals before any weight.

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


_BUF = 14  # per associated point: r_C, ∂r_C/∂ξ (6), r_G, ∂r_G/∂ξ (6)


@numba.njit(cache=True, nogil=True, fastmath=False)
def _residuals(
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
    buf: NDArray[np.float64],
) -> int:
    """The residuals and Jacobians of Eq. 7 at ``T`` of every associated source point into ``buf`` (rows
    ``[r_C, J_C, r_G, J_G]``, ``_BUF`` columns; a term not used is left 0); returns the number of associated points.
    See the module docstring."""
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    height, width = geometry.shape[0], geometry.shape[1]
    umax, vmax = width - 1.001, height - 1.001
    count = 0
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
        row = buf[count]
        count += 1
        if not (use_color and use_depth):
            row[:] = 0.0
        if use_color:
            s0 = (w00 * grey_grad[v0, u0, 0] + w01 * grey_grad[v0, u0 + 1, 0]
                  + w10 * grey_grad[v0 + 1, u0, 0] + w11 * grey_grad[v0 + 1, u0 + 1, 0])
            gu = (w00 * grey_grad[v0, u0, 1] + w01 * grey_grad[v0, u0 + 1, 1]
                  + w10 * grey_grad[v0 + 1, u0, 1] + w11 * grey_grad[v0 + 1, u0 + 1, 1])
            gv = (w00 * grey_grad[v0, u0, 2] + w01 * grey_grad[v0, u0 + 1, 2]
                  + w10 * grey_grad[v0 + 1, u0, 2] + w11 * grey_grad[v0 + 1, u0 + 1, 2])
            ga = gu * fx * zi
            gc = gv * fy * zi
            gd = -(ga * qx + gc * qy) * zi
            row[0] = s0 - point_grey[i]
            row[1], row[2], row[3] = ga, gc, gd
            row[4] = qy * gd - qz * gc
            row[5] = qz * ga - qx * gd
            row[6] = qx * gc - qy * ga
        if use_depth:
            if depth_difference:  # r = D_t(y) - q_z (bilinear); dr/dq = ∇D_t ∂π/∂q - e_z
                r = (w00 * geometry[v0, u0, 0] + w01 * geometry[v0, u0 + 1, 0]
                     + w10 * geometry[v0 + 1, u0, 0] + w11 * geometry[v0 + 1, u0 + 1, 0]) - qz
                ga = (w00 * depth_grad[v0, u0, 0] + w01 * depth_grad[v0, u0 + 1, 0]
                      + w10 * depth_grad[v0 + 1, u0, 0] + w11 * depth_grad[v0 + 1, u0 + 1, 0]) * fx * zi
                gc = (w00 * depth_grad[v0, u0, 1] + w01 * depth_grad[v0, u0 + 1, 1]
                      + w10 * depth_grad[v0 + 1, u0, 1] + w11 * depth_grad[v0 + 1, u0 + 1, 1]) * fy * zi
                jx, jy, jz = ga, gc, -(ga * qx + gc * qy) * zi - 1.0
            else:  # r = n_t · (q - v_t)
                nx, ny, nz = geometry[iv, iu, 4], geometry[iv, iu, 5], geometry[iv, iu, 6]
                r = nx * (qx - geometry[iv, iu, 1]) + ny * (qy - geometry[iv, iu, 2]) + nz * (qz - geometry[iv, iu, 3])
                jx, jy, jz = nx, ny, nz
            row[7] = r
            row[8], row[9], row[10] = jx, jy, jz
            row[11] = qy * jz - qz * jy
            row[12] = qz * jx - qx * jz
            row[13] = qx * jy - qy * jx
    return count


@numba.njit(cache=True, nogil=True)
def _t_scale(buf: NDArray[np.float64], count: int, col: int, dof: float) -> float:
    """Scale σ of Student's t-distribution with ``dof`` degrees of freedom fitted to the residuals
    ``buf[:count, col]`` by the fixed point σ² = mean(w r²), w = (ν + 1) / (ν + r²/σ²) (Kerl et al., ICRA 2013,
    Eq. 10–11), started at the root mean square."""
    if count == 0:
        return 1.0
    s2 = 0.0
    for i in range(count):
        s2 += buf[i, col] * buf[i, col]
    s2 = max(s2 / count, 1e-18)
    for _ in range(20):
        acc = 0.0
        for i in range(count):
            r2 = buf[i, col] * buf[i, col]
            acc += r2 * (dof + 1.0) / (dof + r2 / s2)
        new = max(acc / count, 1e-18)
        done = abs(new - s2) <= 1e-3 * s2
        s2 = new
        if done:
            break
    return np.sqrt(s2)


@numba.njit(cache=True, nogil=True, inline="always")
def _add_term(out: NDArray[np.float64], row: NDArray[np.float64], col: int, delta: float, weight: float,
              t_sigma: float, dof: float) -> tuple[float, bool]:
    """Add ``weight · ρ(r)`` of the residual ``row[col]`` with Jacobian ``row[col + 1:col + 7]`` to ``out`` (the upper
    triangle of JᵀWJ in ``out[:21]``, JᵀWr in ``out[21:]``) as an IRLS weight: Huber with threshold ``delta`` when
    ``t_sigma`` ≤ 0, else Student's t (scale ``t_sigma``, ``dof``) on ``r / t_sigma``. Returns (cost, |r| ≤ delta)."""
    r = row[col]
    ar = abs(r)
    if t_sigma > 0.0:
        z2 = (r / t_sigma) ** 2
        w = weight * (dof + 1.0) / (dof + z2) / (t_sigma * t_sigma)
        cost = weight * 0.5 * (dof + 1.0) * np.log1p(z2 / dof)
    elif ar <= delta:
        w = weight
        cost = weight * 0.5 * r * r
    else:
        w = weight * delta / ar
        cost = weight * delta * (ar - 0.5 * delta)
    k = 0
    for m in range(6):
        wj = w * row[col + 1 + m]
        for n in range(m, 6):
            out[k] += wj * row[col + 1 + n]
            k += 1
        out[21 + m] += wj * r
    return cost, ar <= delta


@numba.njit(cache=True, nogil=True)
def _normal_equations(buf: NDArray[np.float64], count: int, use_color: bool, use_depth: bool, delta_c: float,
                      delta_g: float, w_g: float, t_dof: float) -> tuple[NDArray[np.float64], int, float]:
    """Sum the weighted terms of ``buf[:count]`` (:func:`_add_term`; Student's t with scales fitted per term when
    ``t_dof`` > 0, else Huber): returns (out, inlier count, summed cost)."""
    sigma_c = _t_scale(buf, count, 0, t_dof) if (t_dof > 0.0 and use_color) else 0.0
    sigma_g = _t_scale(buf, count, 7, t_dof) if (t_dof > 0.0 and use_depth) else 0.0
    out = np.zeros(27)
    inliers = 0
    cost = 0.0
    for i in range(count):
        inlier = True
        if use_color:
            c, ok = _add_term(out, buf[i], 0, delta_c, 1.0, sigma_c, t_dof)
            cost += c
            inlier &= ok
        if use_depth:
            c, ok = _add_term(out, buf[i], 7, delta_g, w_g, sigma_g, t_dof)
            cost += c
            inlier &= ok
        if inlier:
            inliers += 1
    return out, inliers, cost


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
    buf = np.empty((len(src.points), _BUF))
    count = _residuals(
        src.points, src.point_grey, np.ascontiguousarray(T, dtype=np.float64), intrinsics, tgt.grey_grad,
        tgt.geometry, tgt.depth_grad if depth_difference and use_depth else _NO_DEPTH_GRAD, use_color, use_depth,
        depth_difference, cfg.depth_outlier_trunc_m, buf,
    )
    t_dof = cfg.t_dof if cfg.robust_norm == "t-distribution" else 0.0
    out, inliers, cost = _normal_equations(buf, count, use_color, use_depth, cfg.intensity_huber_delta,
                                           cfg.geometric_huber_delta_m, cfg.geometric_weight, t_dof)
    H = np.zeros((6, 6))
    H[_TRIU] = out[:21]
    H = H + np.triu(H, 1).T
    return _Terms(H, out[21:].copy(), int(count), int(inliers), float(cost) / max(int(count), 1))

