"""The objective of rACR's fine alignment (paper §3.4.1, Eq. 9–11) at fixed correspondences, pairs and weights.

``_Problem`` evaluates, as a function of ``(R_p, t_p, σ_p)`` (``p_ref ≈ R_p (σ_p p) + t_p``, metres):

* **E_g (Eq. 9):** point-to-plane residuals ``n_refᵀ(R_p σ_p p + t_p − p_ref)`` (m) of a fixed sample of current
  points against their nearest reference points within ``correspondence_radius_m`` (``_build_problem``,
  re-matched every outer iteration);
* **E_p (Eq. 10):** reference points projected into the current keyframes at ``T̃_K^u = T_p ⟨R_K^u, σ_p t_K^u⟩``
  (§3.4.1); the pairwise differences ``D^u(π(T̃_K^u, p_ref)) − D^v(π(T̃_K^v, p_ref))``, ``u < v`` (image units),
  times DSO's gradient-dependent weight (``_gradient_weight``). Points and pairs are fixed at the start
  (``_photometric_setup``: the self-occlusion z-buffer over every reference point, then the strongest gradients).
  Current images are compared only with each other, never with the reference image, so E_p is as insensitive to
  a lighting change between the two observations as E_g.
* **Eq. 11:** ``α · mean ρ(r_g/δ_g) + (1 − α) · mean ρ(r_p/δ_p)``, Huber ``ρ``, each term divided by its robust
  scale ``δ`` (the paper adds raw sums; docs/racr.md says why), minimised by IRLS: weights ``min(1, δ/|r|)``
  frozen for one LM solve.

Jacobian columns: ``(ω, v)`` of a left perturbation of ``T_p`` about the centroid of the reference points in use
(reference frame), then ``log σ_p`` about the centroid of the current points (current frame); analytic, including
the derivative of the gradient weight.
"""
from __future__ import annotations

from typing import cast

import numpy as np
from numpy.typing import NDArray

from lightfast.racr.errors import AlignmentError
from lightfast.racr.fast_alignment import ReferenceCloud
from lightfast.racr.fine.config import FineAlignmentConfig
from lightfast.racr.fine.keyframes import _camera_points, _pairs, _select_by_gradient, _Views

Array = NDArray[np.float64]

def _huber_sqrt_weight(z: Array) -> Array:
    """``sqrt(w)`` of IRLS for the Huber norm on residuals already divided by their threshold."""
    a = np.abs(z)
    return np.where(a <= 1.0, 1.0, 1.0 / np.sqrt(np.maximum(a, 1e-300)))


def _gradient_weight(
    s: Array, ku: NDArray[np.intp], mu: NDArray[np.intp], kv: NDArray[np.intp], mv: NDArray[np.intp], c: float
) -> Array | float:
    """DSO's gradient-dependent weight of a photometric residual between the samples ``s[ku, mu]`` and
    ``s[kv, mv]`` (``(K, M, 3)``: intensity, ∂I/∂u, ∂I/∂v): ``sqrt(c² / (c² + ‖∇I_u‖² + ‖∇I_v‖²))``, i.e. the
    residual counted in units of its expected spread ``≈ ‖∇I‖ · misregistration``. Without it, a pose that moves
    every projection off its edge (where a sub-pixel misregistration costs most) into flatter texture lowers the
    cost — along the motions that a near-planar scene leaves photo-consistent (in-plane shift, scale about the
    plane) the truth is then a local *maximum* of E_p (docs/racr.md). Its derivative is part of the Jacobians
    (:meth:`_Problem.raw`). ``c = 0``: 1 (unweighted)."""
    if c <= 0.0:
        return 1.0
    g2 = s[ku, mu, 1] ** 2 + s[ku, mu, 2] ** 2 + s[kv, mv, 1] ** 2 + s[kv, mv, 2] ** 2
    return c / np.sqrt(c * c + g2)


def _huber_rho(z: Array) -> Array:
    a = np.abs(z)
    return np.where(a <= 1.0, 0.5 * z * z, a - 0.5)


class _Problem:
    """Eq. 11 at fixed correspondences (E_g), pairs and visibility (E_p) and IRLS weights, as a function of
    ``(R_p, t_p, σ_p)``. Jacobian columns: ``(ω, v)`` of a left perturbation of T_p about ``pivot_ref`` (reference
    frame), then ``log σ_p`` about ``pivot_cur`` (current frame)."""

    def __init__(
        self,
        config: FineAlignmentConfig,
        views: _Views,
        R_K: Array,
        t_K: Array,
        p_geo: Array,
        q: Array,
        n: Array,
        P_ref: Array,
        pairs: tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]],
    ) -> None:
        self.config, self.views, self.R_K, self.t_K = config, views, R_K, t_K
        self.p_geo, self.q, self.n, self.P_ref = p_geo, q, n, P_ref
        self.pu, self.pv, self.pm = pairs
        self.pivot_ref = np.mean(np.vstack([q, P_ref]), axis=0)
        self.pivot_cur = np.mean(p_geo, axis=0)
        self.delta_g, self.delta_p = config.geometric_huber_m, config.photometric_huber
        self.w_geo = np.ones(len(q))
        self.w_pho = np.ones(len(self.pu))
        self.gradient_c = config.gradient_weight * views.median_gradient

    def raw(self, R: Array, t: Array, sigma: float, cols: slice | None) -> tuple[Array, Array, Array, Array]:
        """Geometric (m) and photometric (image units, gradient-weighted: :func:`_gradient_weight`) residuals and,
        for ``cols`` of the 7, their Jacobians (including the derivative of the gradient weight)."""
        x = sigma * self.p_geo @ R.T + t
        r_g = np.einsum("ij,ij->i", x - self.q, self.n)
        Rt = np.einsum("ij,kjl->kil", R, self.R_K)
        tt = sigma * self.t_K @ R.T + t
        c = _camera_points(self.P_ref, Rt, tt)
        u, v, ok = self.views.project(c)
        s = self.views.sample(u, v)
        pu, pv, pm = self.pu, self.pv, self.pm
        both = ok[pu, pm] & ok[pv, pm]
        cw = self.gradient_c
        w = _gradient_weight(s, pu, pm, pv, pm, cw)
        d_p = np.where(both, s[pu, pm, 0] - s[pv, pm, 0], 0.0)
        r_p = d_p * w
        if cols is None:
            return r_g, r_p, np.empty((0, 0)), np.empty((0, 0))
        J_g = np.empty((len(r_g), 7))
        if cols.start < 6:
            J_g[:, :3] = np.cross(x - self.pivot_ref, self.n)
            J_g[:, 3:6] = self.n
        if cols.stop > 6:
            J_g[:, 6] = sigma * np.einsum("ij,ij->i", (self.p_geo - self.pivot_cur) @ R.T, self.n)
        Jk = self._chain_params(c, s[..., 1:3] * ok[..., None], Rt, sigma, cols)
        # cw > 0: w is an array
        J_p = (Jk[pu, pm] - Jk[pv, pm]) * cast(Array, w)[:, None] if cw > 0.0 else Jk[pu, pm] - Jk[pv, pm]
        if cw > 0.0:  # ∂w/∂x = −½ w / (c² + G) · ∂G/∂x with G = ‖∇I_u‖² + ‖∇I_v‖²
            Jq = self._chain_params(c, s[..., 3:5] * ok[..., None], Rt, sigma, cols)
            dw = -0.5 * w**3 / (cw * cw)  # = −½ w / (c² + G)
            J_p += (d_p * dw)[:, None] * (Jq[pu, pm] + Jq[pv, pm])
        return r_g, r_p, J_g[:, cols], J_p

    def _chain_params(self, c: Array, grad: Array, Rt: Array, sigma: float, cols: slice) -> Array:
        """``(K, M, n_cols)``: the derivative of an image quantity with pixel gradient ``grad`` ``(K, M, 2)``,
        sampled at the projections of ``P_ref``, with respect to ``cols`` of the 7 parameters."""
        g = self.views.chain(c, grad)
        Jk = np.empty(g.shape[:2] + (7,))
        if cols.start < 6:
            w = np.matmul(g, Rt.transpose(0, 2, 1))  # R̃ g: gradient w.r.t. the reference-frame point
            Jk[..., :3] = np.cross(w, self.P_ref - self.pivot_ref)
            Jk[..., 3:6] = -w
        if cols.stop > 6:
            d = np.einsum("kji,kj->ki", self.R_K, self.t_K - self.pivot_cur)  # R_Kᵀ(t_K − pivot)
            Jk[..., 6] = -sigma * np.matmul(g, d[:, :, None])[..., 0]
        return Jk[..., cols]

    def set_scales(self, delta_g: float, delta_p: float) -> None:
        """The Huber thresholds (and normalising scales) of the two terms."""
        self.delta_g, self.delta_p = delta_g, delta_p

    def robust_scales(self, R: Array, t: Array, sigma: float) -> tuple[float, float]:
        """``huber_k`` robust standard deviations (1.4826 · MAD) of each term's residuals, floored by the
        configured thresholds."""
        r_g, r_p, _, _ = self.raw(R, t, sigma, None)
        k = self.config.huber_k
        s_g = k * 1.4826 * float(np.median(np.abs(r_g))) if len(r_g) else 0.0
        s_p = k * 1.4826 * float(np.median(np.abs(r_p))) if len(r_p) else 0.0
        return max(self.config.geometric_huber_m, s_g), max(self.config.photometric_huber, s_p)

    @property
    def c_geo(self) -> float:
        return float(np.sqrt(self.config.alpha / max(len(self.q), 1)) / self.delta_g)

    @property
    def c_pho(self) -> float:
        return float(np.sqrt((1.0 - self.config.alpha) / max(len(self.pu), 1)) / self.delta_p)

    def reweight(self, R: Array, t: Array, sigma: float) -> None:
        r_g, r_p, _, _ = self.raw(R, t, sigma, None)
        self.w_geo = _huber_sqrt_weight(r_g / self.delta_g)
        self.w_pho = _huber_sqrt_weight(r_p / self.delta_p)

    def weighted(self, R: Array, t: Array, sigma: float, cols: slice, jac: bool) -> tuple[Array, Array | None]:
        r_g, r_p, J_g, J_p = self.raw(R, t, sigma, cols if jac else None)
        a_g, a_p = self.c_geo * self.w_geo, self.c_pho * self.w_pho
        r = np.concatenate([a_g * r_g, a_p * r_p])
        if not jac:
            return r, None
        return r, np.vstack([a_g[:, None] * J_g, a_p[:, None] * J_p])

    def cost(self, R: Array, t: Array, sigma: float) -> float:
        """The normalised Eq. 11 with Huber norms (module notes)."""
        r_g, r_p, _, _ = self.raw(R, t, sigma, None)
        a = self.config.alpha
        e_g = float(np.mean(_huber_rho(r_g / self.delta_g))) if len(r_g) else 0.0
        e_p = float(np.mean(_huber_rho(r_p / self.delta_p))) if len(r_p) else 0.0
        return a * e_g + (1.0 - a) * e_p


def _photometric_setup(
    config: FineAlignmentConfig,
    reference: ReferenceCloud,
    views: _Views,
    R_K: Array,
    t_K: Array,
    R: Array,
    t: Array,
    sigma: float,
) -> tuple[Array, tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]], int]:
    """E_p's points and pairs at the starting estimate: every reference point projected into every keyframe
    (``T̃_K = T_p ⟨R_K, σ_p t_K⟩``), the self-occlusion z-buffer over all of them, then the strongest-gradient
    points seen by at least two keyframes. Returns ``(P_ref, (u, v, m), occluded)``."""
    Rt = np.einsum("ij,kjl->kil", R, R_K)
    tt = sigma * t_K @ R.T + t
    c = _camera_points(reference.points_m, Rt, tt)
    vis, occluded = views.visible(c, config.occlusion_cell_px)
    sel = _select_by_gradient(c, views, vis, config.max_photometric_points)
    pairs = _pairs(vis[:, sel])
    if len(pairs[0]) < config.min_photometric_residuals:
        raise AlignmentError(
            f"only {len(pairs[0])} pairwise photometric residuals (min_photometric_residuals="
            f"{config.min_photometric_residuals}): the keyframes do not see the reference cloud together"
        )
    return reference.points_m[sel], pairs, occluded


def _build_problem(
    config: FineAlignmentConfig,
    reference: ReferenceCloud,
    p_geo_all: Array,
    views: _Views,
    R_K: Array,
    t_K: Array,
    R: Array,
    t: Array,
    sigma: float,
    P_ref: Array,
    pairs: tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]],
) -> _Problem:
    """E_g's correspondences at the current estimate (nearest reference point within
    ``correspondence_radius_m``) with E_p's fixed points and pairs."""
    x = sigma * p_geo_all @ R.T + t
    dist, idx = reference.tree.query(x, distance_upper_bound=config.correspondence_radius_m)
    src = np.flatnonzero(np.isfinite(dist))
    if len(src) < config.min_geometric_residuals:
        raise AlignmentError(
            f"only {len(src)} current points lie within {config.correspondence_radius_m} m of the reference "
            f"(min_geometric_residuals={config.min_geometric_residuals}): not registered at the initial guess"
        )
    return _Problem(
        config, views, R_K, t_K, p_geo_all[src], reference.points_m[idx[src]], reference.normals[idx[src]],
        P_ref, pairs,
    )
