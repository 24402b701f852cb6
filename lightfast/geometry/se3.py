"""Rigid transforms SE(3): 4×4 matrices, composition, inverse, point mapping, and the exp / log maps.

``T_a_b`` is a 4×4 float64 matrix mapping points of frame ``b`` into frame ``a`` (``p_a = R_a_b p_b + t_a_b``,
metres); transforms chain like their names, ``compose(T_a_b, T_b_c) = T_a_c``. A twist ``xi = (rho, phi)`` (6,)
has ``rho`` in metres and ``phi`` in radians: ``se3_exp(xi) = [[exp(hat(phi)), V rho], [0, 1]]`` with the SO(3)
left Jacobian ``V``, :func:`se3_log` its inverse (angle in ``[0, pi]``). One twist or one 4×4 (the trackers'
per-iteration update and pose prior) takes a scalar code path with the same coefficients and series. Conventions
in :mod:`lightfast.geometry`.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from lightfast.errors import GeometryError
from lightfast.geometry.checks import ROTATION_ATOL, Array, _as_float, _check_rotation, _transform
from lightfast.geometry.so3 import _SMALL_ANGLE, _hat, _quat_from_matrix, _quat_log, _so3_coeffs, _so3_exp

__all__ = ["compose", "inverse", "make_transform", "se3_exp", "se3_log", "transform_points"]


def make_transform(R: ArrayLike, t: ArrayLike, *, atol: float = ROTATION_ATOL) -> Array:
    """Rigid transform ``(..., 4, 4)`` ``[[R, t], [0, 1]]`` from a rotation ``(..., 3, 3)`` and ``t`` ``(..., 3)`` in m.

    Leading dimensions broadcast. ``R`` must be a rotation within ``atol`` (see :func:`project_to_so3`).
    """
    R = _as_float(R, "R", (3, 3))
    t = _as_float(t, "t", (3,))
    _check_rotation(R, "R", atol)
    batch = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros((*batch, 4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def look_at(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0), *, roll_rad: float = 0.0) -> Array:
    """``T_world_cam`` of an optical camera (x right, y down, z forward) at ``eye`` looking at ``target``, its
    x axis level with respect to ``up`` (any horizontal one when looking along ``up``), then rolled by ``roll_rad``
    about the viewing direction."""
    e = _as_float(eye, "eye", (3,))
    d = _as_float(target, "target", (3,)) - e
    if e.ndim != 1 or d.ndim != 1 or np.linalg.norm(d) < 1e-12:
        raise GeometryError("look_at needs one eye and one target, apart")
    z = d / np.linalg.norm(d)
    x = np.cross(z, _as_float(up, "up", (3,)))
    if np.linalg.norm(x) < 1e-9:  # looking along up
        x = np.cross(z, [0.0, 1.0, 0.0] if abs(z[1]) < 0.9 else [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(roll_rad), math.sin(roll_rad)
    T = np.eye(4)
    T[:3, :3] = np.stack([c * x + s * y, -s * x + c * y, z], axis=1)
    T[:3, 3] = e
    return T


def inverse(T: ArrayLike, *, atol: float = ROTATION_ATOL) -> Array:
    """Inverse ``(..., 4, 4)`` of a rigid transform: ``inverse(T_a_b) = T_b_a = [[R^T, -R^T t], [0, 1]]``.

    The rotation block must be a rotation within ``atol``; use :func:`sim3_inverse` for similarity transforms.
    """
    T = _transform(T, "T")
    R = T[..., :3, :3]
    _check_rotation(R, "T (rotation block)", atol)
    Rt = np.swapaxes(R, -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3:4])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def compose(*Ts: ArrayLike) -> Array:
    """Matrix product of 4×4 transforms left to right: ``compose(T_a_b, T_b_c) = T_a_c``.

    Leading batch dimensions broadcast. Works for rigid and similarity transforms alike.
    """
    if not Ts:
        raise GeometryError("compose needs at least one transform")
    out = _transform(Ts[0], "Ts[0]")
    for i, T in enumerate(Ts[1:], start=1):
        out = out @ _transform(T, f"Ts[{i}]")
    return out


def transform_points(T: ArrayLike, p: ArrayLike) -> Array:
    """Apply ``T_a_b`` ``(4, 4)`` or ``(..., 4, 4)`` to points ``p_b`` ``(..., 3)``: ``p_a = A p_b + t``.

    A single transform is applied to every point; batched transforms broadcast against the points' leading
    dimensions. Works for rigid and similarity transforms (the top-left block is used as is).
    """
    T = _transform(T, "T")
    p = _as_float(p, "p", (3,))
    A = T[..., :3, :3]
    t = T[..., :3, 3]
    if T.ndim == 2:
        return p @ A.T + t
    return np.einsum("...ij,...j->...i", A, p) + t


def _se3_left_jacobian(phi: Array) -> Array:
    """Left Jacobian of SO(3) ``V = I + B K + C K^2`` (maps ``rho`` to the translation of ``se3_exp``)."""
    theta = np.linalg.norm(phi, axis=-1)
    _, B, C = _so3_coeffs(theta)
    K = _hat(phi)
    return np.eye(3) + B[..., None, None] * K + C[..., None, None] * (K @ K)


def se3_exp(xi: ArrayLike) -> Array:
    """Rigid transform ``(..., 4, 4)`` of the twist ``xi = (rho, phi)`` ``(..., 6)`` (rho in m, phi in rad).

    ``T = [[exp(hat(phi)), V rho], [0, 1]]`` with the SO(3) left Jacobian ``V``.
    """
    if isinstance(xi, np.ndarray) and xi.shape == (6,) and xi.dtype == np.float64:  # the trackers' hot path
        values = xi.tolist()
        if all(map(math.isfinite, values)):
            return _se3_exp_one(*values)
    xi = _as_float(xi, "xi", (6,))
    if xi.ndim == 1:
        return _se3_exp_one(*xi.tolist())
    rho, phi = xi[..., :3], xi[..., 3:]
    T = np.zeros((*xi.shape[:-1], 4, 4))
    T[..., :3, :3] = _so3_exp(phi)
    T[..., :3, 3] = (_se3_left_jacobian(phi) @ rho[..., None])[..., 0]
    T[..., 3, 3] = 1.0
    return T


def _se3_exp_one(x: float, y: float, z: float, wx: float, wy: float, wz: float) -> Array:
    """:func:`se3_exp` of one twist in scalar arithmetic (the per-iteration update of the trackers: faster than the
    batched array code for a single 4×4, docs/daylight.md). Same coefficients and small-angle series as
    :func:`_so3_coeffs`."""
    t2 = wx * wx + wy * wy + wz * wz
    if t2 < _SMALL_ANGLE * _SMALL_ANGLE:
        A = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
        B = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
        C = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0
    else:
        t = math.sqrt(t2)
        st = math.sin(t)
        A = st / t
        B = 2.0 * math.sin(0.5 * t) ** 2 / t2
        C = (t - st) / (t2 * t)
    # K = hat(w), K² = w wᵀ − t² I
    k2 = ((wx * wx - t2, wx * wy, wx * wz), (wx * wy, wy * wy - t2, wy * wz), (wx * wz, wy * wz, wz * wz - t2))
    k = ((0.0, -wz, wy), (wz, 0.0, -wx), (-wy, wx, 0.0))
    R = [[(i == j) + A * k[i][j] + B * k2[i][j] for j in range(3)] for i in range(3)]
    V = [[(i == j) + B * k[i][j] + C * k2[i][j] for j in range(3)] for i in range(3)]
    rho = (x, y, z)
    t_ = [V[i][0] * rho[0] + V[i][1] * rho[1] + V[i][2] * rho[2] for i in range(3)]
    return np.array([[*R[0], t_[0]], [*R[1], t_[1]], [*R[2], t_[2]], [0.0, 0.0, 0.0, 1.0]])


def _se3_inv_coeff(theta: Array) -> Array:
    """``D = 1/t^2 - cos(t/2) / (2 t sin(t/2))`` of ``V^{-1}`` (series for small ``t``; finite up to ``t = pi``)."""
    small = theta < _SMALL_ANGLE
    t = np.where(small, 1.0, theta)
    t2 = theta * theta
    return np.where(
        small,
        1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0,
        1.0 / (t * t) - np.cos(0.5 * t) / (2.0 * t * np.sin(0.5 * t)),
    )


def _se3_left_jacobian_inv(phi: Array) -> Array:
    """``V^{-1} = I - K/2 + D K^2`` with ``K = hat(phi)``."""
    D = _se3_inv_coeff(np.linalg.norm(phi, axis=-1))
    K = _hat(phi)
    return np.eye(3) - 0.5 * K + D[..., None, None] * (K @ K)


def se3_log(T: ArrayLike) -> Array:
    """Twist ``xi = (rho, phi)`` ``(..., 6)`` of the rigid transform ``T`` ``(..., 4, 4)``; inverse of :func:`se3_exp`.

    The rotation angle is in ``[0, pi]``.
    """
    if isinstance(T, np.ndarray) and T.shape == (4, 4) and T.dtype == np.float64:  # the trackers' pose prior
        rows = T.tolist()
        if _is_rigid_one(rows):
            return np.array(_se3_log_one(rows))
    T = _transform(T, "T")
    R = T[..., :3, :3]
    _check_rotation(R, "T (rotation block)", ROTATION_ATOL)
    phi = _quat_log(_quat_from_matrix(R))
    rho = (_se3_left_jacobian_inv(phi) @ T[..., :3, 3:4])[..., 0]
    return np.concatenate([rho, phi], axis=-1)


def _is_rigid_one(T: list[list[float]]) -> bool:
    """Scalar form of the checks of :func:`se3_log` (finite, bottom row, rotation within ``ROTATION_ATOL``, det > 0)
    for one 4×4; a ``False`` sends the matrix to the array path, which names what is wrong."""
    if not all(math.isfinite(v) for row in T for v in row):
        return False
    if any(abs(a - b) > 1e-9 for a, b in zip(T[3], (0.0, 0.0, 0.0, 1.0), strict=True)):
        return False
    cols = [[T[i][j] for i in range(3)] for j in range(3)]
    for j in range(3):
        for k in range(j, 3):
            dot = cols[j][0] * cols[k][0] + cols[j][1] * cols[k][1] + cols[j][2] * cols[k][2]
            if abs(dot - (j == k)) > ROTATION_ATOL:
                return False
    a, b, c = cols
    return (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0])) > 0.0


def _se3_log_one(T: list[list[float]]) -> list[float]:
    """:func:`se3_log` of one 4×4 in scalar arithmetic (faster than the batched array code for one matrix):
    the same Shepperd quaternion, ``2 atan2(|v|, w)`` and ``V^{-1}`` coefficients with their small-angle series."""
    (r00, r01, r02, tx), (r10, r11, r12, ty), (r20, r21, r22, tz) = T[0], T[1], T[2]
    trace = r00 + r11 + r22
    pivot = max(range(4), key=(trace, r00, r11, r22).__getitem__)  # first maximum, as np.argmax
    if pivot == 0:
        q = (r21 - r12, r02 - r20, r10 - r01, 1.0 + trace)
    elif pivot == 1:
        q = (1.0 + r00 - r11 - r22, r01 + r10, r02 + r20, r21 - r12)
    elif pivot == 2:
        q = (r01 + r10, 1.0 - r00 + r11 - r22, r12 + r21, r02 - r20)
    else:
        q = (r02 + r20, r12 + r21, 1.0 - r00 - r11 + r22, r10 - r01)
    norm = math.sqrt(sum(c * c for c in q))
    x, y, z, w = (c / norm for c in q)
    if w < 0.0:  # canonical sign
        x, y, z, w = -x, -y, -z, -w
    n = math.sqrt(x * x + y * y + z * z)
    if n < _SMALL_ANGLE:
        r2 = (n / w) ** 2
        scale = 2.0 / w * (1.0 - r2 / 3.0 + r2 * r2 / 5.0 - r2 * r2 * r2 / 7.0)
    else:
        scale = 2.0 * math.atan2(n, w) / n
    wx, wy, wz = scale * x, scale * y, scale * z
    t = math.sqrt(wx * wx + wy * wy + wz * wz)
    if t < _SMALL_ANGLE:
        D = 1.0 / 12.0 + t * t / 720.0 + t**4 / 30240.0
    else:
        D = 1.0 / (t * t) - math.cos(0.5 * t) / (2.0 * t * math.sin(0.5 * t))
    # V^{-1} t = t - K t / 2 + D K (K t), K = hat(w)
    kt = (wy * tz - wz * ty, wz * tx - wx * tz, wx * ty - wy * tx)
    kkt = (wy * kt[2] - wz * kt[1], wz * kt[0] - wx * kt[2], wx * kt[1] - wy * kt[0])
    rho = [c - 0.5 * a + D * b for c, a, b in zip((tx, ty, tz), kt, kkt, strict=True)]
    return [*rho, wx, wy, wz]

