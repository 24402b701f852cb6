"""Trajectory metrics for the tracking evaluation of paper §III-D / §IV: absolute trajectory error (ATE).

``ate_rmse`` follows Sturm et al. (TUM RGB-D benchmark): the estimated camera positions are rigidly aligned to the
ground truth with the closed-form least-squares SE(3) fit of Umeyama (1991) / Horn (no scale), then the RMSE of the
remaining position differences is reported in metres.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.tracking.errors import MetricsError

__all__ = ["align_umeyama", "ate_rmse"]


def _positions(T: ArrayLike, name: str) -> NDArray[np.float64]:
    a = np.asarray(T, dtype=np.float64)
    if a.ndim == 3 and a.shape[1:] == (4, 4):
        a = a[:, :3, 3]
    if a.ndim != 2 or a.shape[1] != 3:
        raise MetricsError(f"{name} must be poses (N, 4, 4) or positions (N, 3), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise MetricsError(f"{name} holds non-finite values")
    return a


def align_umeyama(src: ArrayLike, dst: ArrayLike) -> NDArray[np.float64]:
    """The rigid transform ``T_dst_src`` (4×4) minimizing ``sum |dst_i - T src_i|²`` over points ``(N, 3)``."""
    p = _positions(src, "src")
    q = _positions(dst, "dst")
    if p.shape != q.shape or len(p) < 3:
        raise MetricsError(f"need two equally long point sets of >= 3 points, got {p.shape} and {q.shape}")
    mp, mq = p.mean(axis=0), q.mean(axis=0)
    cov = (q - mq).T @ (p - mp) / len(p)
    U, _, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0.0:
        S[2, 2] = -1.0
    R = U @ S @ Vt
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = mq - R @ mp
    return T


def ate_rmse(T_est: ArrayLike, T_gt: ArrayLike) -> float:
    """ATE RMSE in metres of estimated vs ground-truth poses ``(N, 4, 4)`` (or positions ``(N, 3)``), after the
    best rigid alignment of the estimate onto the ground truth."""
    p = _positions(T_est, "T_est")
    q = _positions(T_gt, "T_gt")
    T = align_umeyama(p, q)
    err = q - (p @ T[:3, :3].T + T[:3, 3])
    return float(np.sqrt(np.mean(np.sum(err * err, axis=1))))
