"""Stereo pose solver of colour-constant VT&R, shared by VO and map localization: paper §IV-B (Fig. 3), the steps
after the matching. Fig. 3: "Tracked keypoints are sent to an outlier rejection algorithm to filter out inliers and
obtain an initial pose estimate. This pose estimate is used to prime a non linear numerical solver".

* **Outlier rejection** (:func:`estimate_pose_stereo`): RANSAC with the 3-point 3-D–3-D minimal solver
  (Kabsch/Horn on the reference points vs the current stereo points; the scheme of the VT&R system the paper builds
  on, Furgale & Barfoot [6]), hypotheses drawn and solved in NumPy batches — uniformly, from distance-consistent
  triples, or by PROSAC's progressive sampling by match quality — and scored (jitted) by the **stereo reprojection
  error** of every correspondence: the reference point projected into the current left image (u, v) and its
  predicted disparity d, against the measured (u, v, d); inlier when the norm of the three residuals is below
  ``threshold_px``. The disparity term rejects matches whose depth disagrees (random matches that happen to
  reproject), and it makes the pose along the optical axis observable.
* **Nonlinear refinement** (:func:`refine_pose_stereo`): Levenberg–Marquardt on the same residuals of the inliers
  (analytic Jacobian, SE(3) left perturbation), inliers re-selected with the refined pose, refined once more. The
  6×6 covariance σ²(JᵀJ)⁻¹ with a nominal σ = 1 px is returned; :attr:`PoseEstimate.position_std_m` (the largest
  standard deviation of the camera position) tells a well-constrained pose from a degenerate one (e.g. all inliers
  far away: rotation known, translation not).

Frames and units: ``T_ref_cur`` (4×4) maps points of the current left camera frame into the reference frame
(REP-103 optical axes, metres); pixels are those of the rectified left image. :class:`StereoCamera` holds the left
intrinsics ``K = P_left[:, :3]`` (landmarks are expressed in the left camera frame, so ``K`` projects them),
``fb`` = fx·baseline = Tx_left − Tx_right (px·m) and the principal-point offset ``dcx`` = cx_left − cx_right; the
*effective* disparity of a keypoint is ``disparity − dcx`` = fb / Z. :func:`project` gives the pixels of reference
points seen from a pose.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Final, cast

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.vtr.errors import VtrInputError
from lightfast.vtr.features import StereoFeatures
from lightfast.vtr.stereo_front_end import check_stereo_pair

__all__ = [
    "PoseEstimate",
    "StereoCamera",
    "estimate_pose_stereo",
    "project",
    "refine_pose_stereo",
    "warm_up",
]

#: Nominal measurement noise of keypoints and disparities for the pose covariance, px.
NOMINAL_SIGMA_PX: Final = 1.0
_BATCH: Final = 64  # RANSAC hypotheses scored per vectorized batch


@dataclass(frozen=True)
class StereoCamera:
    """The rectified stereo camera as the pose solver needs it (module docstring): ``K`` (3×3, px),
    ``fb`` = fx·baseline (px·m) and ``dcx`` = cx_left − cx_right (px)."""

    K: NDArray[np.float64]
    fb: float
    dcx: float

    @classmethod
    def from_projections(cls, P_left: ArrayLike, P_right: ArrayLike) -> StereoCamera:
        Pl, Pr = check_stereo_pair(P_left, P_right)
        return cls(np.ascontiguousarray(Pl[:, :3]), float(Pl[0, 3] - Pr[0, 3]), float(Pl[0, 2] - Pr[0, 2]))

    def effective_disparity(self, features: StereoFeatures) -> NDArray[np.float64]:
        """fb / Z of every landmark of ``features`` (its raw disparity minus ``dcx``)."""
        return features.disparity.astype(np.float64) - self.dcx


@dataclass(frozen=True)
class PoseEstimate:
    """Result of :func:`estimate_pose_stereo`.

    ``T_ref_cur`` (4×4, current camera frame → reference frame, m); the inlier mask over the correspondences;
    success (enough inliers); RMS stereo reprojection error of the inliers (px); ``covariance`` (6×6) of ξ in
    ``T_ref_cur · exp(ξ)``, ξ = (ρ [m], φ [rad]) in the current camera frame, for a nominal 1 px noise (infinite
    when the inliers do not constrain the pose).
    """

    T_ref_cur: NDArray[np.float64]
    inliers: NDArray[np.bool_]
    success: bool
    rms_px: float
    covariance: NDArray[np.float64] = field(default_factory=lambda: np.full((6, 6), np.inf))

    @property
    def num_inliers(self) -> int:
        return int(np.count_nonzero(self.inliers))

    @property
    def position_std_m(self) -> float:
        """Largest standard deviation of the camera position (m; the square root of the largest eigenvalue of
        the translation block of the covariance)."""
        c = self.covariance[:3, :3]
        if not np.all(np.isfinite(c)):
            return math.inf
        return float(math.sqrt(max(0.0, float(np.linalg.eigvalsh(0.5 * (c + c.T))[-1]))))


def _invert(T: NDArray[np.float64]) -> NDArray[np.float64]:
    R, t = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ t
    return out


def project(
    points_ref: NDArray[np.float64], T_ref_cur: NDArray[np.float64], K: NDArray[np.float64], min_depth_m: float = 0.05
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Pixels (N, 2) of reference points seen from the camera at ``T_ref_cur``, and the mask of points in front
    of it (depth ≥ ``min_depth_m``); pixels of the others are meaningless."""
    T_cur_ref = _invert(T_ref_cur)
    p = points_ref @ T_cur_ref[:3, :3].T + T_cur_ref[:3, 3]
    z = p[:, 2]
    front = z >= min_depth_m
    zs = np.where(front, z, 1.0)
    uv = np.stack([K[0, 0] * p[:, 0] / zs + K[0, 2], K[1, 1] * p[:, 1] / zs + K[1, 2]], axis=1)
    return uv, front


def _exp_se3(delta: NDArray[np.float64]) -> NDArray[np.float64]:
    """exp of a twist (ρ, φ) as a 4×4 transform (Rodrigues; the same map as :func:`lightfast.geometry.se3_exp`,
    without its input validation, for the inner loop of the refinement)."""
    rho, phi = delta[:3], delta[3:]
    theta = math.sqrt(float(phi @ phi))
    Kx = np.array([[0.0, -phi[2], phi[1]], [phi[2], 0.0, -phi[0]], [-phi[1], phi[0], 0.0]])
    if theta < 1e-6:
        A, Bc, C = 1.0, 0.5, 1.0 / 6.0
    else:
        A = math.sin(theta) / theta
        Bc = (1.0 - math.cos(theta)) / theta**2
        C = (theta - math.sin(theta)) / theta**3
    K2 = Kx @ Kx
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + A * Kx + Bc * K2
    T[:3, 3] = (np.eye(3) + Bc * Kx + C * K2) @ rho
    return T


def _stereo_residuals(
    T_cur_ref: NDArray[np.float64], P: NDArray[np.float64], meas: NDArray[np.float64], K: NDArray[np.float64],
    fb: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Residuals (N, 3) predicted − measured (u, v, d) of reference points ``P`` under ``T_cur_ref``, the
    points in the current frame (N, 3) and the mask of points in front of the camera."""
    p = P @ T_cur_ref[:3, :3].T + T_cur_ref[:3, 3]
    z = p[:, 2]
    front = z > 1e-6
    zs = np.where(front, z, 1.0)
    pred = np.stack([K[0, 0] * p[:, 0] / zs + K[0, 2], K[1, 1] * p[:, 1] / zs + K[1, 2], fb / zs], axis=1)
    return pred - meas, p, front


def _normal_equations(
    p: NDArray[np.float64], r: NDArray[np.float64], K: NDArray[np.float64], fb: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """JᵀJ and Jᵀr of the stereo residuals for the left perturbation T_cur_ref ← exp(δ) T_cur_ref, δ = (ρ, φ)."""
    X, Y, Z = p[:, 0], p[:, 1], p[:, 2]
    iz = 1.0 / Z
    x, y = X * iz, Y * iz
    fx, fy = K[0, 0], K[1, 1]
    n = p.shape[0]
    # J = ∂(u, v, d)/∂p · [I | −hat(p)] in closed form, rows (u, v, d) of every point stacked: (3n, 6)
    J = np.zeros((n, 3, 6))
    J[:, 0, 0] = fx * iz
    J[:, 0, 2] = -fx * x * iz
    J[:, 0, 3] = -fx * x * y
    J[:, 0, 4] = fx * (1.0 + x * x)
    J[:, 0, 5] = -fx * y
    J[:, 1, 1] = fy * iz
    J[:, 1, 2] = -fy * y * iz
    J[:, 1, 3] = -fy * (1.0 + y * y)
    J[:, 1, 4] = fy * x * y
    J[:, 1, 5] = fy * x
    J[:, 2, 2] = -fb * iz * iz
    J[:, 2, 3] = -fb * y * iz
    J[:, 2, 4] = fb * x * iz
    Jf = J.reshape(-1, 6)
    return Jf.T @ Jf, Jf.T @ r.reshape(-1)


def refine_pose_stereo(
    points_ref: NDArray[np.float64], uvd_cur: NDArray[np.float64], camera: StereoCamera,
    T_ref_cur: NDArray[np.float64], iterations: int = 10,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Levenberg–Marquardt on the stereo reprojection residuals (u, v, d) of the given correspondences
    (``uvd_cur``: left pixel and effective disparity, (N, 3)). Returns the refined ``T_ref_cur`` and the 6×6
    covariance of ξ in ``T_ref_cur · exp(ξ)`` (nominal 1 px noise; infinite if singular)."""
    K, fb = camera.K, camera.fb
    T = _invert(T_ref_cur)  # T_cur_ref
    r, p, front = _stereo_residuals(T, points_ref, uvd_cur, K, fb)
    cost = float(np.sum(r[front] ** 2)) if front.all() else math.inf
    lam = 1e-3
    for _ in range(iterations):
        if not front.all():
            break
        H, g = _normal_equations(p, r, K, fb)
        try:
            delta = -np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-12), g)
        except np.linalg.LinAlgError:
            break
        T_new = _exp_se3(cast(NDArray[np.float64], delta)) @ T  # float64 normal equations
        r_new, p_new, front_new = _stereo_residuals(T_new, points_ref, uvd_cur, K, fb)
        cost_new = float(np.sum(r_new**2)) if front_new.all() else math.inf
        if cost_new < cost:
            converged = cost - cost_new <= 1e-9 * cost or float(np.linalg.norm(delta)) < 1e-10
            T, r, p, front, cost = T_new, r_new, p_new, front_new, cost_new
            lam = max(lam / 10.0, 1e-9)
            if converged:
                break
        else:
            lam *= 10.0
            if lam > 1e6:
                break
    cov = np.full((6, 6), np.inf)
    if front.all() and points_ref.shape[0] >= 3:
        H, _ = _normal_equations(p, r, K, fb)
        if np.linalg.cond(H) < 1e14:
            cov = NOMINAL_SIGMA_PX**2 * np.linalg.inv(H)
    return _invert(T), cov


class _ConsistentTriples:
    """Index triples of correspondences whose pairwise 3-D distances agree between the reference points ``P`` and
    the current stereo points ``Q`` (see :func:`estimate_pose_stereo`). The tolerance of a pair is
    ``consistency_px · (s_i + s_j) + 5 cm`` with ``s = (Z_Q² + |P|²) / fb`` the depth error per pixel of disparity of
    both points (the reference point's depth approximated by its distance from the reference camera)."""

    def __init__(self, P: NDArray[np.float64], Q: NDArray[np.float64], fb: float, consistency_px: float) -> None:
        s = (Q[:, 2] ** 2 + np.einsum("ij,ij->i", P, P)) / fb
        dP = np.linalg.norm(P[:, None] - P[None], axis=2)
        dQ = np.linalg.norm(Q[:, None] - Q[None], axis=2)
        self.ok = np.abs(dP - dQ) <= consistency_px * (s[:, None] + s[None]) + 0.05
        np.fill_diagonal(self.ok, False)
        self.pairs = np.argwhere(np.triu(self.ok, 1))

    def sample(self, h: int, rng: np.random.Generator) -> NDArray[np.intp]:
        """Up to ``h`` triples (fewer when a drawn consistent pair has no common consistent third point)."""
        if len(self.pairs) == 0:
            return np.empty((0, 3), np.intp)
        ij = self.pairs[rng.integers(0, len(self.pairs), size=h)]
        common = self.ok[ij[:, 0]] & self.ok[ij[:, 1]]
        k = np.argmax(rng.random(common.shape) * common, axis=1)
        keep = common[np.arange(h), k]
        return np.column_stack([ij[keep], k[keep]])


class _ProsacTriples:
    """PROSAC's progressive sampling (Chum & Matas, CVPR 2005, §2.2) of index triples: correspondences ordered by
    ``quality`` (lower is better, e.g. the descriptor distance); hypothesis ``t`` draws the ``n``-th best and two
    of the ``n − 1`` better ones, ``n`` growing from 3 by the paper's schedule ``T_n = T_N · C(n, 3) / C(N, 3)``
    (``T'_{n+1} = T'_n + ⌈T_{n+1} − T_n⌉``, ``T_N`` = 200 000 as in the paper), so the first hypotheses come from the
    most distinctive matches. Unlike the paper, a set size gets at most as many hypotheses as it has distinct
    triples with its newest match, C(n − 1, 2): with few matches the schedule would otherwise draw the same few
    triples hundreds of times. The hypothesis count continues across :meth:`sample` calls."""

    T_N: Final = 200_000

    def __init__(self, quality: NDArray[np.float64]) -> None:
        self.order = np.argsort(quality, kind="stable")
        N = len(self.order)
        n = np.arange(3, N + 1, dtype=np.float64)
        T_n = self.T_N * np.exp(_log_comb3(n) - _log_comb3(np.float64(N)))  # T_n for n = 3..N
        steps = np.minimum(np.ceil(np.diff(T_n, prepend=T_n[0])), (n - 1.0) * (n - 2.0) / 2.0)
        steps[0] = 1.0
        self.T_prime = np.cumsum(steps)  # T'_n: the hypothesis after which n grows to n + 1
        self.drawn = 0

    def sample(self, h: int, rng: np.random.Generator) -> NDArray[np.intp]:
        t = self.drawn + 1 + np.arange(h)
        self.drawn += h
        n = 3 + np.minimum(np.searchsorted(self.T_prime, t, side="left"), len(self.T_prime) - 1)  # current set size
        others = (rng.random((h, 2)) * (n - 1)[:, None]).astype(np.intp)  # two of the n - 1 better ones
        return self.order[np.column_stack([n - 1, others])]


def _log_comb3(n: NDArray[np.float64] | np.float64) -> NDArray[np.float64]:
    """log C(n, 3)."""
    return np.log(n) + np.log(n - 1.0) + np.log(n - 2.0) - math.log(6.0)


@numba.njit(cache=True, nogil=True)
def _count_inliers(Ts: NDArray[np.float64], P: NDArray[np.float64], meas: NDArray[np.float64], fx: float, fy: float,
                   cx: float, cy: float, fb: float, thr2: float) -> NDArray[np.int64]:  # pragma: no cover (jitted)
    """Per hypothesis T_cur_ref (H, 4, 4): how many reference points P (N, 3) project in front of the current camera
    with a squared stereo reprojection error (u, v, d) against ``meas`` (N, 3) of at most ``thr2``."""
    counts = np.zeros(Ts.shape[0], np.int64)
    for h in range(Ts.shape[0]):
        T = Ts[h]
        c = 0
        for i in range(P.shape[0]):
            x, y, z = P[i, 0], P[i, 1], P[i, 2]
            pz = T[2, 0] * x + T[2, 1] * y + T[2, 2] * z + T[2, 3]
            if pz <= 1e-6:
                continue
            px = T[0, 0] * x + T[0, 1] * y + T[0, 2] * z + T[0, 3]
            py = T[1, 0] * x + T[1, 1] * y + T[1, 2] * z + T[1, 3]
            eu = fx * px / pz + cx - meas[i, 0]
            ev = fy * py / pz + cy - meas[i, 1]
            ed = fb / pz - meas[i, 2]
            if eu * eu + ev * ev + ed * ed <= thr2:
                c += 1
        counts[h] = c
    return counts


def warm_up() -> None:
    """Compile (or load from numba's cache) the jitted RANSAC scoring now rather than on the first frame."""
    _count_inliers(np.eye(4)[None], np.ones((1, 3)), np.ones((1, 3)), 1.0, 1.0, 0.0, 0.0, 1.0, 1.0)


def _kabsch_batch(P: NDArray[np.float64], Q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rigid transforms (H, 4, 4) with Q ≈ R P + t for batches of point triples P, Q (H, 3, 3) (rows = points)."""
    cp, cq = P.mean(axis=1, keepdims=True), Q.mean(axis=1, keepdims=True)
    Hm = np.swapaxes(P - cp, 1, 2) @ (Q - cq)  # (H, 3, 3) = Σ p qᵀ
    U, _, Vt = np.linalg.svd(Hm)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, 1, 2) @ np.swapaxes(U, 1, 2)))
    D = np.ones((P.shape[0], 3))
    D[:, 2] = np.where(d == 0, 1.0, d)
    R = np.swapaxes(Vt, 1, 2) @ (D[:, :, None] * np.swapaxes(U, 1, 2))
    T = np.zeros((P.shape[0], 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = cq[:, 0] - (R @ cp[:, 0, :, None])[..., 0]
    T[:, 3, 3] = 1.0
    return T


def estimate_pose_stereo(
    points_ref: ArrayLike,
    uv_cur: ArrayLike,
    disparity_cur: ArrayLike,
    camera: StereoCamera,
    *,
    threshold_px: float = 2.0,
    iterations: int = 500,
    confidence: float = 0.999,
    min_inliers: int = 6,
    seed: int = 0,
    consistent_fraction: float = 0.0,
    consistency_px: float = 0.35,
    quality: ArrayLike | None = None,
    ordered_fraction: float = 0.0,
) -> PoseEstimate:
    """Pose of the current camera in the reference frame from 3-D reference points and their current stereo
    measurements (left pixel, effective disparity = fb / Z): 3-point 3-D–3-D RANSAC scored by the stereo
    reprojection error, then Levenberg–Marquardt on the inliers (both steps of the module docstring).

    With ``consistent_fraction`` > 0 that share of the hypotheses is drawn from *distance-consistent* triples
    (:class:`_ConsistentTriples`: a rigid motion keeps the distances between points, so the three reference points
    and the three current stereo points must have pairwise distances that agree within the stereo depth
    uncertainty of a ``consistency_px`` disparity error), the rest uniformly as before. At low inlier ratios —
    the whole-map search under changed lighting, a dozen correct matches among ~200 — a uniform triple is all
    inliers with probability w³ (1000 hypotheses find 12 of 164 a third of the time); about a quarter of all pairs
    but nearly every inlier pair pass the test, which makes an all-inlier triple tens of times likelier. Scoring
    and the adaptive stop (on w³, conservative) are unchanged.

    With ``quality`` (per correspondence, lower is better: the descriptor distance) and ``ordered_fraction`` > 0,
    that share of the hypotheses follows PROSAC's progressive sampling (:class:`_ProsacTriples`): the first ones
    come from the most distinctive matches, where the correct ones concentrate when most matches are wrong (in the
    whole-map search of a repeat at 20:06, 6 of the 20 closest of 164 matches were among its 12 correct ones).

    ``success`` needs at least ``max(min_inliers, 3)`` inliers. A failed estimate has ``T_ref_cur`` = identity
    and an empty inlier mask. Deterministic for a given ``seed``. Never raises for degenerate data (too few
    points, no consensus); raises :class:`VtrInputError` for inconsistent shapes.
    """
    P = np.ascontiguousarray(np.asarray(points_ref, np.float64).reshape(-1, 3))
    uv = np.asarray(uv_cur, np.float64).reshape(-1, 2)
    d = np.asarray(disparity_cur, np.float64).reshape(-1)
    n = P.shape[0]
    if uv.shape[0] != n or d.shape[0] != n:
        raise VtrInputError(f"{n} reference points but {uv.shape[0]} pixels and {d.shape[0]} disparities")
    failed = PoseEstimate(np.eye(4), np.zeros(n, bool), False, float("nan"))
    need = max(min_inliers, 3)
    ok = np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(uv), axis=1) & np.isfinite(d) & (d > 1e-6)
    idx = np.flatnonzero(ok)
    if idx.size < need:
        return failed
    K, fb = camera.K, camera.fb
    meas = np.column_stack([uv, d])
    # current stereo points (left camera frame) for the 3-D–3-D minimal solver
    z = fb / d[idx]
    Q = np.column_stack([(uv[idx, 0] - K[0, 2]) * z / K[0, 0], (uv[idx, 1] - K[1, 2]) * z / K[1, 1], z])
    Pv, Mv = P[idx], meas[idx]
    m = idx.size
    rng = np.random.default_rng(seed)
    consistent = _ConsistentTriples(Pv, Q, fb, consistency_px) if consistent_fraction > 0 else None
    ordered = None
    if quality is not None and ordered_fraction > 0:
        q = np.asarray(quality, np.float64).reshape(-1)
        if q.shape[0] != n:
            raise VtrInputError(f"{n} correspondences but {q.shape[0]} quality values")
        ordered = _ProsacTriples(q[idx])
    thr2 = threshold_px * threshold_px
    best_count, best_T = 0, None
    needed = float(iterations)
    done = 0
    log_fail = math.log(1.0 - confidence)
    while done < min(needed, iterations):
        h = min(_BATCH, iterations - done)
        done += h
        n_ord = round(h * ordered_fraction) if ordered is not None else 0
        n_cons = min(round(h * consistent_fraction), h - n_ord) if consistent is not None else 0
        s = rng.integers(0, m, size=(h - n_cons - n_ord, 3))
        if n_cons:
            assert consistent is not None
            s = np.concatenate([consistent.sample(n_cons, rng), s])
        if n_ord:
            assert ordered is not None
            s = np.concatenate([ordered.sample(n_ord, rng), s])
        distinct = (s[:, 0] != s[:, 1]) & (s[:, 0] != s[:, 2]) & (s[:, 1] != s[:, 2])
        s = s[distinct]
        if s.shape[0] == 0:
            continue
        Ps, Qs = Pv[s], Q[s]
        area = np.linalg.norm(np.cross(Ps[:, 1] - Ps[:, 0], Ps[:, 2] - Ps[:, 0]), axis=1)
        s, Ps, Qs = s[area > 1e-6], Ps[area > 1e-6], Qs[area > 1e-6]
        if s.shape[0] == 0:
            continue
        Ts = _kabsch_batch(Ps, Qs)  # T_cur_ref hypotheses
        counts = _count_inliers(Ts, Pv, Mv, K[0, 0], K[1, 1], K[0, 2], K[1, 2], fb, thr2)
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best_count, best_T = int(counts[k]), Ts[k]
            w = best_count / m
            p_good = w**3
            needed = 0.0 if p_good >= 1.0 else (log_fail / math.log(1.0 - p_good) if p_good > 0 else math.inf)
    if best_T is None or best_count < need:
        return failed
    T_ref_cur = _invert(best_T)
    inliers = np.zeros(n, bool)
    cov = np.full((6, 6), np.inf)
    for _ in range(3):  # select inliers, refine on them; until the inlier set is stable
        r, _, front = _stereo_residuals(_invert(T_ref_cur), P, meas, K, fb)
        new = ok & front & (np.sum(r * r, axis=1) <= thr2)
        if np.count_nonzero(new) < 3:
            return failed
        if np.array_equal(new, inliers):
            break
        inliers = new
        T_ref_cur, cov = refine_pose_stereo(P[inliers], meas[inliers], camera, T_ref_cur)
    r, _, _ = _stereo_residuals(_invert(T_ref_cur), P[inliers], meas[inliers], K, fb)
    rms = float(np.sqrt(np.mean(np.sum(r * r, axis=1))))
    count = int(np.count_nonzero(inliers))
    if not np.all(np.isfinite(T_ref_cur)):
        return failed
    return PoseEstimate(T_ref_cur, inliers, count >= need, rms, cov)
