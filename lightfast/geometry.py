"""Rigid (SE(3)) and similarity (Sim(3)) transforms on NumPy arrays.

Conventions
-----------
* **Transforms.** ``T_a_b`` is a 4×4 ``float64`` matrix that maps points expressed in frame ``b`` to frame ``a``:
  ``p_a = T_a_b @ p_b`` (homogeneous), i.e. ``p_a = R_a_b p_b + t_a_b``. ``t_a_b`` is the origin of frame ``b``
  expressed in frame ``a``, in metres. Transforms chain like their names: ``T_a_c = compose(T_a_b, T_b_c)``.
* **Rotations** are 3×3 ``float64`` matrices with ``R^T R = I`` and ``det R = +1``.
* **Quaternions** are ``(x, y, z, w)`` like ROS ``geometry_msgs/Quaternion``, unit norm. :func:`matrix_to_quat`
  returns the canonical sign ``w >= 0`` (for ``w == 0`` the first non-zero of ``x, y, z`` is positive).
* **Tangent vectors.** A rotation vector ``phi`` (3,) is axis × angle in radians. A twist ``xi = (rho, phi)`` (6,)
  puts the translation part first and the rotation part second; ``se3_exp(xi) = expm([[hat(phi), rho], [0, 0]])``
  so ``rho`` is in metres but is *not* the translation of the result unless ``phi = 0``. A Sim(3) vector
  ``v = (rho, phi, lambda)`` (7,) has log-scale ``lambda`` (scale ``s = exp(lambda)``, dimensionless) and
  ``sim3_exp(v) = expm([[hat(phi) + lambda I, rho], [0, 0]])``.
* **Sim(3) matrices** are ``[[s R, t], [0, 1]]`` with ``s > 0``; they map ``p_a = s R p_b + t``.
* **Batches.** Every function accepts leading batch dimensions (``(..., 3, 3)``, ``(..., 4, 4)``, ``(..., 6)``...)
  and returns arrays with the same leading shape.

The exponential and logarithm maps use closed forms that stay accurate for small angles (Taylor expansions below
a threshold) and near ``pi`` (the rotation logarithm goes through a Shepperd quaternion and ``atan2``).

Invalid input (wrong shape, non-finite values, a matrix that is not a rotation, a quaternion far from unit norm)
raises :class:`GeometryError`, whose message names the offending argument.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.errors import GeometryError

__all__ = [
    "compose",
    "hat",
    "inverse",
    "is_rotation",
    "make_transform",
    "matrix_to_quat",
    "project_to_so3",
    "quat_to_matrix",
    "rotation_angle_deg",
    "se3_exp",
    "se3_log",
    "sim3_exp",
    "sim3_inverse",
    "sim3_log",
    "so3_exp",
    "so3_log",
    "transform_points",
    "translation_distance",
    "vee",
]

Array = NDArray[np.float64]

#: Tolerance of the orthonormality check applied to rotation inputs of the log maps and conversions.
ROTATION_ATOL = 1e-6
#: A quaternion whose norm differs from 1 by more than this raises; closer ones are normalized.
QUAT_NORM_TOL = 1e-3

# Below this angle (radians) the closed forms switch to Taylor series (truncation error there ~1e-16 relative);
# just above it, the K^2 coefficients of the closed forms lose ~eps/t^2 to cancellation, ~eps absolute in the matrices.
_SMALL_ANGLE = 1e-2
_SMALL_LOG_SCALE = 2.0  # |lambda| below this: moments of exp(lambda tau) by power series, above by recursion


# ----------------------------------------------------------------------------------------------------------------
# validation helpers


def _as_float(x: ArrayLike, name: str, tail: tuple[int, ...]) -> Array:
    """``x`` as a float64 array whose trailing dimensions are ``tail``; finite values only."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GeometryError(f"{name} must be a numeric array, got {type(x).__name__}: {exc}") from None
    if a.ndim < len(tail) or a.shape[a.ndim - len(tail) :] != tail:
        want = "(..., " + ", ".join(str(n) for n in tail) + ")"
        raise GeometryError(f"{name} must have shape {want}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise GeometryError(f"{name} contains non-finite values (NaN or inf)")
    return a


def _orthonormality_error(R: Array) -> Array:
    """Max-abs deviation of ``R^T R`` from identity, per matrix (shape ``(...)``)."""
    RtR = np.swapaxes(R, -1, -2) @ R
    return np.max(np.abs(RtR - np.eye(3)), axis=(-2, -1))


def _check_rotation(R: Array, name: str, atol: float) -> None:
    err = _orthonormality_error(R)
    det = np.linalg.det(R)
    bad = (err > atol) | (det <= 0.0)
    if np.any(bad):
        worst = float(np.max(err))
        raise GeometryError(
            f"{name} is not a rotation matrix (max |R^T R - I| = {worst:.3g}, min det = {float(np.min(det)):.3g}, "
            f"atol = {atol:g}); use project_to_so3 to repair a drifted rotation"
        )


def _check_bottom_row(T: Array, name: str) -> None:
    bottom = T[..., 3, :].reshape(-1, 4)
    bad = np.any(np.abs(bottom - [0.0, 0.0, 0.0, 1.0]) > 1e-9, axis=-1)
    if np.any(bad):
        raise GeometryError(f"{name} must have bottom row [0, 0, 0, 1], got {bottom[np.argmax(bad)].tolist()}")


# ----------------------------------------------------------------------------------------------------------------
# SO(3)


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


# ----------------------------------------------------------------------------------------------------------------
# SE(3)


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


def _transform(T: ArrayLike, name: str) -> Array:
    T = _as_float(T, name, (4, 4))
    _check_bottom_row(T, name)
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
    """:func:`se3_exp` of one twist in scalar arithmetic (the per-iteration update of the trackers: ~10× faster than
    the batched array code for a single 4×4). Same coefficients and small-angle series as :func:`_so3_coeffs`."""
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
    """:func:`se3_log` of one 4×4 in scalar arithmetic (~20× faster than the batched array code for one matrix):
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


# ----------------------------------------------------------------------------------------------------------------
# Sim(3)


def _exp_moments(lam: Array, kmax: int) -> list[Array]:
    """``m_k(lam) = integral_0^1 tau^k exp(lam tau) d tau`` for ``k = 0..kmax``, accurate for every ``lam``."""
    small = np.abs(lam) < _SMALL_LOG_SCALE
    # Power series m_k = sum_j lam^j / (j! (k + j + 1)); 30 terms reach 2^30/30! ~ 4e-24.
    terms = 30
    j = np.arange(terms, dtype=np.float64)
    ratios = np.where(small, lam, 0.0)[..., None] / np.maximum(j, 1.0)
    ratios[..., 0] = 1.0
    pow_over_fact = np.cumprod(ratios, axis=-1)  # lam^j / j!
    # Upward recursion m_k = (e^lam - k m_{k-1}) / lam: stable for |lam| >= 2 (error gain k/|lam| <= 2 per step).
    lam_l = np.where(small, 1.0, lam)
    e = np.exp(lam_l)
    m_large = np.expm1(lam_l) / lam_l
    moments = []
    for k in range(kmax + 1):
        if k > 0:
            m_large = (e - k * m_large) / lam_l
        series = np.sum(pow_over_fact / (k + j + 1.0), axis=-1)
        moments.append(np.where(small, series, m_large))
    return moments


def _sim3_coeffs(theta: Array, lam: Array) -> tuple[Array, Array, Array]:
    """Coefficients ``(a, b, c)`` of the Sim(3) left Jacobian ``W = a I + b K + c K^2`` (``K = hat(phi)``).

    ``W = integral_0^1 exp(tau (K + lam I)) d tau``, so ``a = (e^lam - 1)/lam``, ``b = Im(E)/t`` and
    ``c = (a - Re(E))/t^2`` with ``E = (e^z - 1)/z``, ``z = lam + i t``. Small ``t`` uses the Taylor series in ``t``
    whose coefficients are the moments ``m_k(lam)``.
    """
    m0, m1, m2, m3, m4, m5, m6 = _exp_moments(lam, 6)
    small = theta < _SMALL_ANGLE
    t = np.where(small, 1.0, theta)
    t2 = theta * theta
    # E = expm1(z) / z computed without cancellation: Re expm1(z) = expm1(lam) cos t - 2 sin^2(t/2).
    re_num = np.expm1(lam) * np.cos(t) - 2.0 * np.sin(0.5 * t) ** 2
    im_num = np.exp(lam) * np.sin(t)
    den = lam * lam + t * t
    E_re = (re_num * lam + im_num * t) / den
    E_im = (im_num * lam - re_num * t) / den
    b = np.where(small, m1 - t2 * m3 / 6.0 + t2 * t2 * m5 / 120.0, E_im / t)
    c = np.where(small, 0.5 * m2 - t2 * m4 / 24.0 + t2 * t2 * m6 / 720.0, (m0 - E_re) / (t * t))
    return m0, b, c


def _sim3_left_jacobian(phi: Array, lam: Array) -> Array:
    """The Sim(3) left Jacobian ``W`` ``(..., 3, 3)``, see :func:`_sim3_coeffs`."""
    a, b, c = _sim3_coeffs(np.linalg.norm(phi, axis=-1), lam)
    K = _hat(phi)
    return a[..., None, None] * np.eye(3) + b[..., None, None] * K + c[..., None, None] * (K @ K)


def sim3_exp(v: ArrayLike) -> Array:
    """Similarity transform ``(..., 4, 4)`` ``[[s R, W rho], [0, 1]]`` of ``v = (rho, phi, lambda)`` ``(..., 7)``.

    ``s = exp(lambda)``, ``R = so3_exp(phi)`` and ``W`` is the Sim(3) left Jacobian including scale, so that
    ``sim3_exp(v) == expm([[hat(phi) + lambda I, rho], [0, 0]])``.
    """
    v = _as_float(v, "v", (7,))
    rho, phi, lam = v[..., :3], v[..., 3:6], v[..., 6]
    S = np.zeros((*v.shape[:-1], 4, 4))
    S[..., :3, :3] = np.exp(lam)[..., None, None] * _so3_exp(phi)
    S[..., :3, 3] = (_sim3_left_jacobian(phi, lam) @ rho[..., None])[..., 0]
    S[..., 3, 3] = 1.0
    return S


def _sim3_parts(S: Array, name: str) -> tuple[Array, Array, Array]:
    """Scale ``(...)``, rotation ``(..., 3, 3)`` and translation ``(..., 3)`` of a Sim(3) matrix."""
    M = S[..., :3, :3]
    det = np.linalg.det(M)
    if np.any(det <= 0.0):
        raise GeometryError(f"{name} must have a top-left block s R with s > 0 and det > 0, got det {det.min():.3g}")
    s = np.cbrt(det)
    R = M / s[..., None, None]
    _check_rotation(R, f"{name} (rotation block / scale)", ROTATION_ATOL)
    return s, R, S[..., :3, 3]


def sim3_log(S: ArrayLike) -> Array:
    """Sim(3) vector ``(rho, phi, lambda)`` ``(..., 7)`` of ``S = [[s R, t], [0, 1]]`` ``(..., 4, 4)``.

    Inverse of :func:`sim3_exp`; ``s = det(s R)^(1/3)`` and the rotation angle is in ``[0, pi]``.
    """
    S = _transform(S, "S")
    s, R, t = _sim3_parts(S, "S")
    phi = _quat_log(_quat_from_matrix(R))
    lam = np.log(s)
    rho = np.linalg.solve(_sim3_left_jacobian(phi, lam), t[..., None])[..., 0]
    return np.concatenate([rho, phi, lam[..., None]], axis=-1)


def sim3_inverse(S: ArrayLike) -> Array:
    """Inverse ``(..., 4, 4)`` of a similarity transform: ``[[R^T / s, -R^T t / s], [0, 1]]``."""
    S = _transform(S, "S")
    s, R, t = _sim3_parts(S, "S")
    A = np.swapaxes(R, -1, -2) / s[..., None, None]
    out = np.zeros_like(S)
    out[..., :3, :3] = A
    out[..., :3, 3] = -(A @ t[..., None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


# ----------------------------------------------------------------------------------------------------------------
# error metrics


def _rotation_block(R: ArrayLike, name: str) -> Array:
    a = np.asarray(R, dtype=np.float64)
    if a.ndim >= 2 and a.shape[-2:] == (4, 4):
        a = _transform(a, name)[..., :3, :3]
    a = _as_float(a, name, (3, 3))
    _check_rotation(a, name, ROTATION_ATOL)
    return a


def rotation_angle_deg(R: ArrayLike, R_ref: ArrayLike | None = None) -> Array:
    """Rotation angle in degrees ``[0, 180]`` of ``R``, or of ``R_ref^T R`` (the error of ``R`` w.r.t. ``R_ref``).

    Accepts rotations ``(..., 3, 3)`` or rigid transforms ``(..., 4, 4)`` (their rotation blocks); batches
    broadcast. Returns a float array of the leading shape (a NumPy float for single inputs).
    """
    Ra = _rotation_block(R, "R")
    if R_ref is not None:
        Rb = _rotation_block(R_ref, "R_ref")
        Ra = np.swapaxes(Rb, -1, -2) @ Ra
    q = _quat_from_matrix(Ra)
    return np.degrees(2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3])))


def _translation_part(x: ArrayLike, name: str) -> Array:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim >= 2 and a.shape[-2:] == (4, 4):
        return _transform(a, name)[..., :3, 3]
    return _as_float(a, name, (3,))


def translation_distance(a: ArrayLike, b: ArrayLike) -> Array:
    """Euclidean distance (m) between two translations ``(..., 3)`` or the translations of transforms ``(..., 4, 4)``.

    Inputs may mix both forms; batches broadcast. Returns a float array of the leading shape (a NumPy float for
    single inputs).
    """
    return np.linalg.norm(_translation_part(a, "a") - _translation_part(b, "b"), axis=-1)
