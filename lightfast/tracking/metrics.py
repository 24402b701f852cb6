"""Trajectory metrics for the tracking evaluation of paper §III-D / §IV: ATE, RPE and each estimate's own error.

``ate_rmse`` follows Sturm et al. (TUM RGB-D benchmark): the estimated camera positions are rigidly aligned to the
ground truth with the closed-form least-squares SE(3) fit of Umeyama (1991) / Horn (no scale), then the RMSE of the
remaining position differences is reported in metres.

``motion_rmse`` is the translational RPE of Sturm et al.: the RMSE of the translation of the motions over ``delta``
frames of one trajectory against another's.

``own_errors`` compares several estimates of one trajectory with each other (the ground truth may be one of them): the
N-cornered hat of clock metrology (Gray & Allan, 28th Frequency Control Symposium, 1974: three clocks compared in
pairs give each clock's own variance), here on the pairwise ATE (or another distance, e.g. ``motion_rmse``). If the
estimates' errors are independent, ``d(i, j)² = σ_i² + σ_j²``; with more than three estimates the σ² are the
non-negative least-squares fit over all pairs. An error that all estimates but one share counts as that one's own:
against a ground truth, σ of the ground truth is its own error plus whatever every tracker gets wrong alike.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import nnls

from lightfast.tracking.errors import MetricsError

__all__ = ["OwnErrors", "align_umeyama", "ate_rmse", "motion_rmse", "own_errors"]


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


def motion_rmse(T_est: ArrayLike, T_gt: ArrayLike, delta: int = 1) -> float:
    """RMSE in metres of the translation error of the motions over ``delta`` frames of poses ``(N, 4, 4)``."""
    a, b = np.asarray(T_est, dtype=np.float64), np.asarray(T_gt, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 3 or a.shape[1:] != (4, 4) or not 1 <= delta < len(a):
        raise MetricsError(f"need two equally long pose sequences (N, 4, 4) with N > delta={delta}, got {a.shape} "
                           f"and {b.shape}")
    err = np.linalg.inv(np.linalg.inv(b[:-delta]) @ b[delta:]) @ (np.linalg.inv(a[:-delta]) @ a[delta:])
    return float(np.sqrt(np.mean(np.sum(err[:, :3, 3] ** 2, axis=1))))


@dataclass(frozen=True)
class OwnErrors:
    """:func:`own_errors`: ``own_m`` per estimate (m), ``pairwise_m`` the distance of each pair (m, keyed by the two
    names in the input order) and ``misfit_m2`` the root mean square of the fit's residuals in m² (0 when the
    pairwise distances are exactly those of independent errors)."""

    own_m: dict[str, float]
    pairwise_m: dict[tuple[str, str], float]
    misfit_m2: float


def own_errors(trajectories: Mapping[str, ArrayLike],
               distance: Callable[[ArrayLike, ArrayLike], float] = ate_rmse) -> OwnErrors:
    """Each estimate's own error (m) from the pairwise ``distance`` (default the ATE) of three or more equally long
    estimates of one trajectory (poses ``(N, 4, 4)``; positions ``(N, 3)`` for the ATE): the N-cornered hat (module
    docstring)."""
    names = list(trajectories)
    if len(names) < 3:
        raise MetricsError(f"own_errors needs at least 3 estimates, got {len(names)}")
    pairs = [(a, b) for i, a in enumerate(names) for b in names[i + 1:]]
    pairwise = {(a, b): distance(trajectories[a], trajectories[b]) for a, b in pairs}
    A = np.zeros((len(pairs), len(names)))
    for row, (a, b) in enumerate(pairs):
        A[row, names.index(a)] = A[row, names.index(b)] = 1.0
    d2 = np.array([pairwise[p] ** 2 for p in pairs])
    var, _ = nnls(A, d2)
    misfit = float(np.sqrt(np.mean((A @ var - d2) ** 2)))
    return OwnErrors({k: float(np.sqrt(v)) for k, v in zip(names, var, strict=True)}, pairwise, misfit)
