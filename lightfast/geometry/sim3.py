"""Similarity transforms Sim(3): ``S = [[s R, t], [0, 1]]`` with ``s > 0``, mapping ``p_a = s R p_b + t`` (metres).

A Sim(3) vector ``v = (rho, phi, lambda)`` (7,) has ``rho`` in metres, ``phi`` in radians and the log-scale
``lambda`` (``s = exp(lambda)``, dimensionless); ``sim3_exp(v) = expm([[hat(phi) + lambda I, rho], [0, 0]])``, with
the left Jacobian ``W`` in closed form (series for small angles, moments of ``exp(lambda tau)`` for every scale).
:func:`sim3_log` and :func:`sim3_inverse` recover ``s = det(s R)^(1/3)``. Conventions in :mod:`lightfast.geometry`.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from lightfast.errors import GeometryError
from lightfast.geometry.checks import ROTATION_ATOL, Array, _as_float, _check_rotation, _transform
from lightfast.geometry.so3 import _SMALL_ANGLE, _hat, _quat_from_matrix, _quat_log, _so3_exp

__all__ = ["sim3_exp", "sim3_inverse", "sim3_log"]

_SMALL_LOG_SCALE = 2.0  # |lambda| below this: moments of exp(lambda tau) by power series, above by recursion


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

