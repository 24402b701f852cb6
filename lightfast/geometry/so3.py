"""Rotations SO(3): rotation vectors, quaternions and matrices on NumPy arrays (batched).

``so3_exp(phi) = I + sin(t)/t K + (1 - cos t)/t^2 K^2`` (Rodrigues, ``K = hat(phi)``, ``t = |phi|``, radians);
:func:`so3_log` goes through a Shepperd quaternion and ``2 atan2(|v|, w)``, accurate for tiny angles and near
``pi``. Rotations are 3×3 float64 matrices ``R_a_b`` (``p_a = R_a_b p_b``); quaternions are ``(x, y, z, w)`` like
ROS ``geometry_msgs/Quaternion``, canonical sign ``w >= 0`` on output. Below ``_SMALL_ANGLE`` the closed forms
switch to Taylor series. Conventions in :mod:`lightfast.geometry`.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.errors import GeometryError
from lightfast.geometry.checks import (
    QUAT_NORM_TOL,
    ROTATION_ATOL,
    Array,
    _as_float,
    _check_rotation,
    _orthonormality_error,
)

__all__ = [
    "hat",
    "is_rotation",
    "matrix_to_quat",
    "project_to_so3",
    "quat_to_matrix",
    "so3_exp",
    "so3_log",
    "unit_vector",
    "vee",
]

# Below this angle (radians) the closed forms switch to Taylor series (truncation error there ~1e-16 relative);
# just above it, the K^2 coefficients of the closed forms lose ~eps/t^2 to cancellation, ~eps absolute in the matrices.
_SMALL_ANGLE = 1e-2


def unit_vector(v: ArrayLike, name: str, *, error: type[Exception] = GeometryError) -> Array:
    """``v`` normalized; raises ``error`` naming ``name`` unless it is a finite, non-zero 3-vector."""
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise error(f"{name} must be a finite 3-vector, got {v!r}")
    norm = float(np.linalg.norm(a))
    if norm < 1e-12:
        raise error(f"{name} must be non-zero")
    return a / norm


def hat(v: ArrayLike) -> Array:
    """Skew-symmetric matrix ``(..., 3, 3)`` of ``v`` ``(..., 3)``: ``hat(v) @ w == cross(v, w)``."""
    v = _as_float(v, "v", (3,))
    out = np.zeros((*v.shape[:-1], 3, 3))
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    out[..., 0, 1] = -z
    out[..., 0, 2] = y
    out[..., 1, 0] = z
    out[..., 1, 2] = -x
    out[..., 2, 0] = -y
    out[..., 2, 1] = x
    return out


def vee(M: ArrayLike) -> Array:
    """Inverse of :func:`hat`: the vector ``(..., 3)`` of the skew-symmetric part of ``M`` ``(..., 3, 3)``."""
    M = _as_float(M, "M", (3, 3))
    return 0.5 * np.stack(
        [M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], axis=-1
    )


def _hat(v: Array) -> Array:
    """:func:`hat` without validation (internal)."""
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def _so3_coeffs(theta: Array) -> tuple[Array, Array, Array]:
    """``A = sin t / t``, ``B = (1 - cos t) / t^2``, ``C = (t - sin t) / t^3`` with small-angle series."""
    small = theta < _SMALL_ANGLE
    t = np.where(small, 1.0, theta)  # safe denominator; the small branch is taken from the series below
    t2 = theta * theta
    A = np.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, np.sin(t) / t)
    # 1 - cos t = 2 sin^2(t/2) avoids the cancellation of 1 - cos t.
    B = np.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, 2.0 * np.sin(0.5 * t) ** 2 / (t * t))
    C = np.where(small, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0, (t - np.sin(t)) / (t * t * t))
    return A, B, C


def _so3_exp(phi: Array) -> Array:
    theta = np.linalg.norm(phi, axis=-1)
    A, B, _ = _so3_coeffs(theta)
    K = _hat(phi)
    return np.eye(3) + A[..., None, None] * K + B[..., None, None] * (K @ K)


def so3_exp(phi: ArrayLike) -> Array:
    """Rotation matrix ``(..., 3, 3)`` of the rotation vector ``phi`` ``(..., 3)`` (axis × angle, radians).

    Rodrigues' formula ``R = I + sin(t)/t K + (1 - cos t)/t^2 K^2`` with ``K = hat(phi)``, ``t = |phi|``.
    """
    return _so3_exp(_as_float(phi, "phi", (3,)))


def _quat_from_matrix(R: Array) -> Array:
    """Shepperd's method, vectorized: unit quaternion ``(..., 4)`` ``(x, y, z, w)``, canonical sign."""
    r00, r11, r22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    trace = r00 + r11 + r22
    # Four candidate (unnormalized) quaternions, each well conditioned when its pivot is the largest.
    cand = np.empty((*R.shape[:-2], 4, 4))
    # pivot w: 4 w^2 = 1 + trace
    cand[..., 0, :] = np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1], 1.0 + trace], axis=-1
    )
    # pivot x: 4 x^2 = 1 + r00 - r11 - r22
    cand[..., 1, :] = np.stack(
        [1.0 + r00 - r11 - r22, R[..., 0, 1] + R[..., 1, 0], R[..., 0, 2] + R[..., 2, 0], R[..., 2, 1] - R[..., 1, 2]],
        axis=-1,
    )
    # pivot y
    cand[..., 2, :] = np.stack(
        [R[..., 0, 1] + R[..., 1, 0], 1.0 - r00 + r11 - r22, R[..., 1, 2] + R[..., 2, 1], R[..., 0, 2] - R[..., 2, 0]],
        axis=-1,
    )
    # pivot z
    cand[..., 3, :] = np.stack(
        [R[..., 0, 2] + R[..., 2, 0], R[..., 1, 2] + R[..., 2, 1], 1.0 - r00 - r11 + r22, R[..., 1, 0] - R[..., 0, 1]],
        axis=-1,
    )
    pivot = np.argmax(np.stack([trace, r00, r11, r22], axis=-1), axis=-1)
    q = np.take_along_axis(cand, pivot[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return _canonical_quat(q)


def _canonical_quat(q: Array) -> Array:
    """Flip the sign so that ``w > 0``, or for ``w == 0`` the first non-zero of ``x, y, z`` is positive."""
    order = q[..., [3, 0, 1, 2]]
    nonzero = order != 0.0
    first = np.argmax(nonzero, axis=-1)
    lead = np.take_along_axis(order, first[..., None], axis=-1)[..., 0]
    return np.where((lead < 0.0)[..., None], -q, q)


def matrix_to_quat(R: ArrayLike) -> Array:
    """Unit quaternion ``(..., 4)`` in ``(x, y, z, w)`` order of the rotation ``R`` ``(..., 3, 3)``, with ``w >= 0``.

    Shepperd's method: accurate for every rotation, including angles near ``pi``. ``R`` must be a rotation to
    within :data:`ROTATION_ATOL` (raises :class:`GeometryError` otherwise).
    """
    R = _as_float(R, "R", (3, 3))
    _check_rotation(R, "R", ROTATION_ATOL)
    return _quat_from_matrix(R)


def _normalized_quat(q: ArrayLike, name: str) -> Array:
    q = _as_float(q, name, (4,))
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(np.abs(norm - 1.0) > QUAT_NORM_TOL):
        worst = float(np.max(np.abs(norm - 1.0)))
        raise GeometryError(
            f"{name} must be a unit quaternion (x, y, z, w); |norm - 1| = {worst:.3g} exceeds {QUAT_NORM_TOL:g}"
        )
    return q / norm


def quat_to_matrix(q_xyzw: ArrayLike) -> Array:
    """Rotation matrix ``(..., 3, 3)`` of the quaternion ``q_xyzw`` ``(..., 4)`` in ROS ``(x, y, z, w)`` order.

    Quaternions within ``1e-3`` of unit norm are normalized first; others raise :class:`GeometryError`.
    """
    q = _normalized_quat(q_xyzw, "q_xyzw")
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty((*q.shape[:-1], 3, 3))
    out[..., 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    out[..., 0, 1] = 2.0 * (x * y - z * w)
    out[..., 0, 2] = 2.0 * (x * z + y * w)
    out[..., 1, 0] = 2.0 * (x * y + z * w)
    out[..., 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    out[..., 1, 2] = 2.0 * (y * z - x * w)
    out[..., 2, 0] = 2.0 * (x * z - y * w)
    out[..., 2, 1] = 2.0 * (y * z + x * w)
    out[..., 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return out


def _quat_log(q: Array) -> Array:
    """Rotation vector of a canonical unit quaternion (``w >= 0``): angle in ``[0, pi]``."""
    v = q[..., :3]
    w = q[..., 3]
    n = np.linalg.norm(v, axis=-1)
    small = n < _SMALL_ANGLE
    n_safe = np.where(small, 1.0, n)
    # theta = 2 atan2(n, w); phi = theta / n * v. For small n (then w ~ 1): 2 atan(r)/n = 2/w (1 - r^2/3 + r^4/5 ...)
    # with r = n/w, the atan series.
    w_safe = np.where(small, w, 1.0)
    r2 = (n / w_safe) ** 2
    scale_small = 2.0 / w_safe * (1.0 - r2 / 3.0 + r2 * r2 / 5.0 - r2 * r2 * r2 / 7.0)
    scale = np.where(small, scale_small, 2.0 * np.arctan2(n_safe, w) / n_safe)
    return scale[..., None] * v


def so3_log(R: ArrayLike) -> Array:
    """Rotation vector ``(..., 3)`` (axis × angle, angle in ``[0, pi]``) of the rotation ``R`` ``(..., 3, 3)``.

    Computed through a Shepperd quaternion and ``2 atan2(|v|, w)``, so it is accurate both for tiny angles and
    near ``pi`` (where the axis sign is arbitrary: ``phi`` and ``-phi`` are the same rotation).
    """
    R = _as_float(R, "R", (3, 3))
    _check_rotation(R, "R", ROTATION_ATOL)
    return _quat_log(_quat_from_matrix(R))


def is_rotation(R: ArrayLike, *, atol: float = ROTATION_ATOL) -> np.bool_ | NDArray[np.bool_]:
    """Whether ``R`` ``(..., 3, 3)`` is a rotation: ``|R^T R - I| <= atol`` entrywise and ``det R > 0``.

    Returns a NumPy bool for one matrix, a bool array of the leading shape for a batch. Non-finite matrices are
    not rotations; a wrong shape raises :class:`GeometryError`.
    """
    a = np.asarray(R, dtype=np.float64)
    if a.ndim < 2 or a.shape[-2:] != (3, 3):
        raise GeometryError(f"R must have shape (..., 3, 3), got {a.shape}")
    finite = np.all(np.isfinite(a), axis=(-2, -1))
    a = np.where(finite[..., None, None], a, 0.0)
    with np.errstate(invalid="ignore"):
        ok = finite & (_orthonormality_error(a) <= atol) & (np.linalg.det(a) > 0.0)
    return ok[()] if ok.ndim == 0 else ok


def project_to_so3(R: ArrayLike) -> Array:
    """The rotation ``(..., 3, 3)`` nearest to ``R`` in the Frobenius norm (SVD ``U diag(1, 1, det) V^T``)."""
    R = _as_float(R, "R", (3, 3))
    U, _, Vt = np.linalg.svd(R)
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0.0, 1.0, d)
    D = np.ones((*R.shape[:-2], 3))
    D[..., 2] = d
    return (U * D[..., None, :]) @ Vt

