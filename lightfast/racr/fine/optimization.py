"""The Levenberg–Marquardt solves of rACR's fine alignment (paper §3.4.3, Eq. 16–18).

* **Eq. 16** (``_refine_keyframes``): the current keyframe poses ``T_K^u`` (camera-to-current-cloud, metres)
  from the photometric error of the fixed *current* points: the pairwise terms on the blurred images plus, per
  point and keyframe, an anchor ``D^u(π(T_K^u, p_m)) − I_m`` to the point's VSE intensity on the raw image (DSO's
  host-to-target residual), Huber threshold ``photometric_huber``, right perturbation ``T_K exp(ξ)`` per keyframe.
  The paper's text defines ``p_m`` as current points while its printed Eq. 16 shows ``p_ref``; this follows the
  text. Without intensities Eq. 16 is skipped.
* **Eq. 17** (``_pose_step``): ``T_p`` (6 parameters) with ``σ_p`` fixed. **Eq. 18** (``_scale_step``): ``σ_p``
  as ``log σ_p`` scaled about the current points' centroid (decoupled from ``t_p``) with ``R_p`` fixed.
  ``_joint_step``: both in one 7-parameter solve (the default, ``scale_update="joint"``).

Solver (``_lm``): SciPy ``least_squares(method="lm")`` — MINPACK's Levenberg–Marquardt, the paper's LM — with
analytic Jacobians and ``x_scale="jac"`` (rotation in rad, translation in m and log-scale differ in sensitivity by
orders of magnitude); ``method="trf"`` is kept as a cross-check. MINPACK's LM takes no robust loss, so the Huber
norms enter as IRLS weights (:mod:`lightfast.racr.fine.objective`).
"""
from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from lightfast.geometry import project_to_so3, so3_exp
from lightfast.racr.errors import AlignmentError
from lightfast.racr.fine.config import FineAlignmentConfig
from lightfast.racr.fine.keyframes import _camera_points, _pairs, _select_by_gradient, _Views
from lightfast.racr.fine.objective import _huber_sqrt_weight, _Problem

logger = logging.getLogger(__name__)

Array = NDArray[np.float64]

def _lm(fun: Callable[[Array, bool], tuple[Array, Array | None]], n: int, config: FineAlignmentConfig) -> Array:
    """One Levenberg–Marquardt solve from zero; ``fun(x, jac)`` returns the residuals and, if asked, the Jacobian.
    MINPACK evaluates trial points without the Jacobian and asks for it at accepted points only."""

    def jacobian(x: Array) -> Array:
        J = fun(x, True)[1]
        assert J is not None
        return J

    res = least_squares(
        lambda x: fun(x, False)[0],
        np.zeros(n),
        jac=jacobian,
        method=config.method,
        x_scale="jac",
        ftol=config.lm_ftol,
        xtol=1e-8,
        gtol=1e-10,
        max_nfev=config.lm_max_nfev,
    )
    if not np.all(np.isfinite(res.x)):
        raise AlignmentError("the Levenberg-Marquardt step is not finite")
    return res.x


def _pose_step(problem: _Problem, R: Array, t: Array, sigma: float) -> tuple[Array, Array]:
    """Eq. 17: T_p by LM with σ_p fixed."""
    c = problem.pivot_ref

    def state(x: Array) -> tuple[Array, Array]:
        dR = so3_exp(x[:3])
        return dR @ R, dR @ (t - c) + c + x[3:]

    x = _lm(lambda x, jac: problem.weighted(*state(x), sigma, slice(0, 6), jac), 6, problem.config)
    R_new, t_new = state(x)
    return project_to_so3(R_new), t_new


def _scale_step(problem: _Problem, R: Array, t: Array, sigma: float) -> tuple[Array, float]:
    """Eq. 18: σ_p (as ``log σ_p``, scaled about ``pivot_cur``) by LM with R_p fixed."""
    t_pivot = t + sigma * R @ problem.pivot_cur  # the reference-frame image of pivot_cur, held fixed

    def state(x: Array) -> tuple[Array, float]:
        s = sigma * float(np.exp(x[0]))
        return t_pivot - s * R @ problem.pivot_cur, s

    x = _lm(lambda x, jac: problem.weighted(R, *state(x), slice(6, 7), jac), 1, problem.config)
    return state(x)


def _joint_step(problem: _Problem, R: Array, t: Array, sigma: float) -> tuple[Array, Array, float]:
    """Eq. 17 and 18 in one LM solve over (T_p, log σ_p) — the ``joint`` option."""
    c = problem.pivot_ref
    t_pivot = t + sigma * R @ problem.pivot_cur

    def state(x: Array) -> tuple[Array, Array, float]:
        dR = so3_exp(x[:3])
        R_new = dR @ R
        s = sigma * float(np.exp(x[6]))
        return R_new, dR @ (t_pivot - c) + c + x[3:6] - s * R_new @ problem.pivot_cur, s

    x = _lm(lambda x, jac: problem.weighted(*state(x), slice(0, 7), jac), 7, problem.config)
    R_new, t_new, s_new = state(x)
    return project_to_so3(R_new), t_new, s_new


def _refine_keyframes(
    points_cur: Array,
    intensities: Array | None,
    views: _Views,
    raw_views: _Views | None,
    R_K: Array,
    t_K: Array,
    config: FineAlignmentConfig,
) -> tuple[Array, Array, int]:
    """Eq. 16: the keyframe poses (current-cloud frame) from the photometric error of the fixed current points —
    pairwise terms ``D^u(π(T_K^u, p_m)) − D^v(π(T_K^v, p_m))`` on the blurred images plus the anchors
    ``D^u(π(T_K^u, p_m)) − I_m`` on the raw images. Right perturbation ``T_K exp(ξ)`` per keyframe.

    Without ``intensities`` (or ``raw_views``) the poses are returned unchanged: pairwise photo-consistency alone
    leaves the rigid motions of the whole keyframe rig that slide the scene along itself (in-plane motions of a
    near-planar scene) almost free, and LM wanders along them (tests: 0.2° pose errors grew to ~0.9°).
    Returns ``(R_K, t_K, residuals)``."""
    if intensities is None or raw_views is None:
        logger.debug("Eq. 16 skipped: the current points carry no intensities")
        return R_K, t_K, 0
    K = len(views)
    c_all = _camera_points(points_cur, R_K, t_K)
    vis, _ = views.visible(c_all, config.occlusion_cell_px)
    sel = _select_by_gradient(c_all, views, vis, config.max_keyframe_points)
    P, I_m = points_cur[sel], intensities[sel]
    vis = vis[:, sel]
    pu, pv, pm = _pairs(vis)
    au, am = np.nonzero(vis)
    n_pair, n_res = len(pu), len(pu) + len(au)
    if n_res < config.min_photometric_residuals:
        logger.debug("Eq. 16 skipped: %d photometric residuals on current points", n_res)
        return R_K, t_K, n_res
    rows_p, rows_a = np.arange(n_pair), n_pair + np.arange(len(au))

    def evaluate(Rs: Array, ts: Array, jac: bool) -> tuple[Array, Array | None]:
        c = _camera_points(P, Rs, ts)
        u, v, ok = views.project(c)
        s = views.sample(u, v)
        sr = raw_views.sample(u, v)
        both = ok[pu, pm] & ok[pv, pm]
        a_in = ok[au, am]
        r = np.concatenate([
            np.where(both, s[pu, pm, 0] - s[pv, pm, 0], 0.0),
            np.where(a_in, sr[au, am, 0] - I_m[am], 0.0),
        ])
        if not jac:
            return r, None
        J = np.zeros((n_res, 6 * K))
        for grad, rows, k_idx, m_idx, sign, valid in (
            (s, rows_p, pu, pm, 1.0, both),
            (s, rows_p, pv, pm, -1.0, both),
            (sr, rows_a, au, am, 1.0, a_in),
        ):
            g = _chain_rows(views, c, grad, k_idx, m_idx) * (sign * valid)[:, None]
            cc = c[k_idx, m_idx]
            cols = 6 * k_idx[:, None] + np.arange(6)
            J[rows[:, None], cols] += np.concatenate([np.cross(g, cc), -g], axis=1)
        return r, J

    def state(x: Array) -> tuple[Array, Array]:
        xi = x.reshape(K, 6)
        Rs = np.einsum("kij,kjl->kil", R_K, so3_exp(xi[:, :3]))
        return Rs, t_K + np.einsum("kij,kj->ki", R_K, xi[:, 3:])

    delta = config.photometric_huber  # fixed, near ℓ1 at image noise (docs/racr.md)
    for _ in range(config.keyframe_iterations):
        r0, _ = evaluate(R_K, t_K, jac=False)
        w = _huber_sqrt_weight(r0 / delta) / (delta * np.sqrt(n_res))

        def fun(x: Array, jac: bool, w: Array = w) -> tuple[Array, Array | None]:
            r, J = evaluate(*state(x), jac=jac)
            return w * r, None if J is None else w[:, None] * J

        R_K, t_K = state(_lm(fun, 6 * K, config))
        R_K = np.stack([project_to_so3(R) for R in R_K])
    return R_K, t_K, n_res


def _chain_rows(views: _Views, c: Array, s: Array, k_idx: NDArray[np.intp], m_idx: NDArray[np.intp]) -> Array:
    """``∂I/∂c`` ``(n, 3)`` for the listed (keyframe, point) entries of ``(K, M, …)`` arrays."""
    cc = c[k_idx, m_idx]
    zi = 1.0 / np.maximum(cc[:, 2], 1e-9)
    gu = s[k_idx, m_idx, 1] * views.fx[k_idx, 0] * zi
    gv = s[k_idx, m_idx, 2] * views.fy[k_idx, 0] * zi
    return np.stack([gu, gv, -(gu * cc[:, 0] + gv * cc[:, 1]) * zi], axis=1)
