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
from typing import Final

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.vtr.errors import VtrInputError
from lightfast.vtr.features import StereoFeatures
from lightfast.vtr.stereo_front_end import check_stereo_pair
from lightfast.vtr.vo_prior import mahalanobis_sq

__all__ = [
    "PoseEstimate",
    "PriorSupport",
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


@dataclass(frozen=True)
class PriorSupport:
    """A prior pose ``T_ref_cur`` whose own consensus (the inliers at the prior, refined like the sampled ones) is
    kept over the best sampled consensus when it has ``min_inliers`` and that one has at most ``margin_sigmas`` · √n
    more inliers (n: its count) and lies beyond ``sigmas`` standard deviations of the prior's position
    (``position_cov``, 3×3 in the reference frame; None: the prior is certain). Where the inliers cannot tell poses
    apart — a valley of poses along the viewing direction of far points, where counts ~1 m apart differ by less than
    their sampling noise — and the prior can, the pose it supports wins, not whichever one the sampling found
    (maximum a posteriori: equal likelihoods, the prior decides). With ``exclusive_inliers`` > 0 it also wins,
    whatever the counts, when that many of its inliers are not the other's: two coherent, largely disjoint
    consensus sets mean a second structure in the view (a shadow moved since the teach), and the prior decides."""

    T_ref_cur: NDArray[np.float64]
    margin_sigmas: float = 1.0
    position_cov: NDArray[np.float64] | None = None
    sigmas: float = 3.0
    min_inliers: int = 0
    exclusive_inliers: int = 0

    def keeps(self, count: int, other_count: int = 0, T_ref_other: NDArray[np.float64] | None = None,
              exclusive: int = 0) -> bool:
        """Whether the prior's consensus of ``count`` inliers, ``exclusive`` of them not the other's, wins over
        another of ``other_count`` at ``T_ref_other`` (None: no other)."""
        if count < self.min_inliers:
            return False
        disjoint = 0 < self.exclusive_inliers <= exclusive
        if not disjoint and count < other_count - self.margin_sigmas * math.sqrt(other_count):
            return False
        if T_ref_other is None:
            return True
        d2 = mahalanobis_sq(T_ref_other[:3, 3] - self.T_ref_cur[:3, 3], self.position_cov)
        return d2 is None or d2 > self.sigmas**2


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


@numba.njit(cache=True, nogil=True)
def _exp_se3(delta: NDArray[np.float64]) -> NDArray[np.float64]:  # pragma: no cover (jitted)
    """exp of a twist (ρ, φ) as a 4×4 transform (Rodrigues; the same map as :func:`lightfast.geometry.se3_exp`,
    without its input validation, for the inner loop of the refinement)."""
    rho, phi = delta[:3], delta[3:]
    theta = math.sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])
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


@numba.njit(cache=True, nogil=True)
def _stereo_cost(T: NDArray[np.float64], P: NDArray[np.float64], meas: NDArray[np.float64], fx: float, fy: float,
                 cx: float, cy: float, fb: float, H: NDArray[np.float64], g: NDArray[np.float64],
                 normal: bool) -> float:  # pragma: no cover (jitted)
    """Sum of squared stereo residuals (u, v, d) of ``P`` under ``T`` = T_cur_ref (inf when a point is not in front
    of the camera); with ``normal`` also JᵀJ into ``H`` and Jᵀr into ``g`` for the left perturbation
    T ← exp(δ) T, δ = (ρ, φ): J = ∂(u, v, d)/∂p · [I | −hat(p)]."""
    cost = 0.0
    if normal:
        H[:] = 0.0
        g[:] = 0.0
    J = np.zeros((3, 6))
    for i in range(P.shape[0]):
        x0, y0, z0 = P[i, 0], P[i, 1], P[i, 2]
        Z = T[2, 0] * x0 + T[2, 1] * y0 + T[2, 2] * z0 + T[2, 3]
        if Z <= 1e-6:
            return math.inf
        X = T[0, 0] * x0 + T[0, 1] * y0 + T[0, 2] * z0 + T[0, 3]
        Y = T[1, 0] * x0 + T[1, 1] * y0 + T[1, 2] * z0 + T[1, 3]
        iz = 1.0 / Z
        x, y = X * iz, Y * iz
        r0, r1, r2 = fx * x + cx - meas[i, 0], fy * y + cy - meas[i, 1], fb * iz - meas[i, 2]
        cost += r0 * r0 + r1 * r1 + r2 * r2
        if not normal:
            continue
        J[0, 0], J[0, 2], J[0, 3], J[0, 4], J[0, 5] = fx * iz, -fx * x * iz, -fx * x * y, fx * (1.0 + x * x), -fx * y
        J[1, 1], J[1, 2], J[1, 3], J[1, 4], J[1, 5] = fy * iz, -fy * y * iz, -fy * (1.0 + y * y), fy * x * y, fy * x
        J[2, 2], J[2, 3], J[2, 4] = -fb * iz * iz, -fb * y * iz, fb * x * iz
        for a in range(6):
            g[a] += J[0, a] * r0 + J[1, a] * r1 + J[2, a] * r2
            for b in range(a, 6):
                H[a, b] += J[0, a] * J[0, b] + J[1, a] * J[1, b] + J[2, a] * J[2, b]
    if normal:
        for a in range(6):
            for b in range(a):
                H[a, b] = H[b, a]
    return cost


@numba.njit(cache=True, nogil=True)
def _levenberg_marquardt(T: NDArray[np.float64], P: NDArray[np.float64], meas: NDArray[np.float64], fx: float,
                         fy: float, cx: float, cy: float, fb: float,
                         iterations: int) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:  # pragma: no cover
    """LM on the stereo residuals from ``T`` = T_cur_ref: the refined T_cur_ref, JᵀJ there, and whether every point
    is in front of the camera (jitted: the refinement runs for every RANSAC hypothesis it keeps)."""
    H, g = np.zeros((6, 6)), np.zeros(6)
    H_new, g_new = np.zeros((6, 6)), np.zeros(6)
    cost = _stereo_cost(T, P, meas, fx, fy, cx, cy, fb, H, g, True)
    lam = 1e-3
    for _ in range(iterations):
        if not math.isfinite(cost):
            break
        A = H + lam * np.diag(np.diag(H) + 1e-12)
        L = np.zeros((6, 6))  # Cholesky of the damped (symmetric positive definite) matrix
        ok = True
        for i in range(6):
            for j in range(i + 1):
                v = A[i, j] - np.dot(L[i, :j], L[j, :j])
                if i == j:
                    if v <= 0.0:
                        ok = False
                        break
                    L[i, i] = math.sqrt(v)
                else:
                    L[i, j] = v / L[j, j]
            if not ok:
                break
        if not ok:
            break
        w = np.zeros(6)
        for i in range(6):
            w[i] = (-g[i] - np.dot(L[i, :i], w[:i])) / L[i, i]
        delta = np.zeros(6)
        for i in range(5, -1, -1):
            delta[i] = (w[i] - np.dot(np.ascontiguousarray(L[i + 1:, i]), delta[i + 1:])) / L[i, i]
        T_new = _exp_se3(delta) @ T
        cost_new = _stereo_cost(T_new, P, meas, fx, fy, cx, cy, fb, H_new, g_new, True)
        if cost_new < cost:
            converged = cost - cost_new <= 1e-9 * cost or math.sqrt(np.dot(delta, delta)) < 1e-10
            T, cost = T_new, cost_new
            H[:], g[:] = H_new, g_new
            lam = max(lam / 10.0, 1e-9)
            if converged:
                break
        else:
            lam *= 10.0
            if lam > 1e6:
                break
    return T, H, math.isfinite(cost)


def refine_pose_stereo(
    points_ref: NDArray[np.float64], uvd_cur: NDArray[np.float64], camera: StereoCamera,
    T_ref_cur: NDArray[np.float64], iterations: int = 10,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Levenberg–Marquardt on the stereo reprojection residuals (u, v, d) of the given correspondences
    (``uvd_cur``: left pixel and effective disparity, (N, 3)). Returns the refined ``T_ref_cur`` and the 6×6
    covariance of ξ in ``T_ref_cur · exp(ξ)`` (nominal 1 px noise; infinite if singular)."""
    K, fb = camera.K, camera.fb
    P = np.ascontiguousarray(points_ref, np.float64)
    T, H, front = _levenberg_marquardt(_invert(T_ref_cur), P, np.ascontiguousarray(uvd_cur, np.float64), K[0, 0],
                                       K[1, 1], K[0, 2], K[1, 2], fb, iterations)
    return _invert(T), _covariance(H) if front and P.shape[0] >= 3 else np.full((6, 6), np.inf)


def _covariance(H: NDArray[np.float64]) -> NDArray[np.float64]:
    """σ²(JᵀJ)⁻¹ at the nominal σ (infinite if JᵀJ is singular)."""
    if np.linalg.cond(H) < 1e14:
        return np.asarray(NOMINAL_SIGMA_PX**2 * np.linalg.inv(H), np.float64)
    return np.full((6, 6), np.inf)


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
    """Compile (or load from numba's cache) the jitted RANSAC scoring and refinement now rather than on the first
    frame."""
    _count_inliers(np.eye(4)[None], np.ones((1, 3)), np.ones((1, 3)), 1.0, 1.0, 0.0, 0.0, 1.0, 1.0)
    _levenberg_marquardt(np.eye(4), np.ones((3, 3)), np.ones((3, 3)), 1.0, 1.0, 0.0, 0.0, 1.0, 1)


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
    refine_top: int = 1,
    min_iterations: int = 0,
    prior: PriorSupport | None = None,
) -> PoseEstimate:
    """Pose of the current camera in the reference frame from 3-D reference points and their current stereo
    measurements (left pixel, effective disparity = fb / Z): 3-point 3-D–3-D RANSAC scored by the stereo
    reprojection error, then Levenberg–Marquardt on the inliers (both steps of the module docstring).

    * ``consistent_fraction`` > 0: that share of the hypotheses comes from *distance-consistent* triples
      (:class:`_ConsistentTriples`: pairwise distances of the reference and current points agree within the depth
      uncertainty of a ``consistency_px`` disparity error). At a dozen correct matches among ~200 (the whole-map
      search under changed lighting) a uniform triple is rarely all inliers; nearly every inlier pair passes.
    * ``quality`` (per correspondence, lower is better) and ``ordered_fraction`` > 0: that share follows PROSAC's
      progressive sampling (:class:`_ProsacTriples`), the best-ranked matches first — by descriptor distance where
      most matches are wrong (a repeat at 20:06: 6 of the 20 closest of 164 were among its 12 correct ones), by
      nearness for VO (near points fix the translation).
    * ``min_iterations``: hypotheses drawn before the adaptive stop (on w³) may end the loop. With most points far
      an all-inlier triple of far points fits nearly any translation, so the stop's assumption (any all-inlier
      sample gives the best model) fails.
    * ``refine_top`` > 1: the best ``refine_top`` hypotheses with distinct inlier sets are each refined (inliers
      re-selected, LM, until stable); the one with the most inliers afterwards (then the lowest RMS) wins. The
      most-inliers hypothesis often rests on far points and misses the near ones a slightly worse one holds.
    * ``prior``: the prior's own consensus may win over the sampled ones (:class:`PriorSupport`).

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
    top_counts, top_Ts = np.zeros(0, np.int64), np.zeros((0, 4, 4))  # the refine_top best hypotheses so far
    needed = float(iterations)
    done = 0
    log_fail = math.log(1.0 - confidence)
    while done < min(max(needed, min_iterations), iterations):
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
        if refine_top > 1:
            top_counts, top_Ts = np.concatenate([top_counts, counts]), np.concatenate([top_Ts, Ts])
            keep = np.argsort(-top_counts, kind="stable")[:refine_top]
            top_counts, top_Ts = top_counts[keep], top_Ts[keep]
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best_count, best_T = int(counts[k]), Ts[k]
            w = best_count / m
            p_good = w**3
            needed = 0.0 if p_good >= 1.0 else (log_fail / math.log(1.0 - p_good) if p_good > 0 else math.inf)
    starts: list[NDArray[np.float64]] = []  # the sampled hypotheses to refine
    if best_T is not None and best_count >= need:
        starts = [best_T] if refine_top <= 1 else list(top_Ts[top_counts >= need])
    elif prior is None:
        return failed
    best: tuple[int, float, NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]] | None = None
    seen: list[NDArray[np.bool_]] = []
    for T_cur_ref in starts:
        r, _, front = _stereo_residuals(T_cur_ref, P, meas, K, fb)
        first = ok & front & (np.sum(r * r, axis=1) <= thr2)
        if any(np.array_equal(first, m) for m in seen):
            continue  # the same consensus as a hypothesis already refined
        seen.append(first)
        refined = _refine_consensus(first, P, meas, camera, thr2, ok, _invert(T_cur_ref))
        if refined is not None and (best is None or (refined[0], -refined[1]) > (best[0], -best[1])):
            best = refined
    if prior is not None:
        r, _, front = _stereo_residuals(_invert(prior.T_ref_cur), P, meas, K, fb)
        supported = _refine_consensus(ok & front & (np.sum(r * r, axis=1) <= thr2), P, meas, camera, thr2, ok,
                                      prior.T_ref_cur)
        if supported is not None and prior.keeps(
                supported[0], *((best[0], best[2], int(np.count_nonzero(supported[3] & ~best[3]))) if best else ())):
            best = supported
    if best is None:
        return failed
    count, rms, T_ref_cur, inliers, H = best
    cov = _covariance(H) if np.all(np.isfinite(H)) else np.full((6, 6), np.inf)
    return PoseEstimate(T_ref_cur, inliers, count >= need, rms, cov)


def _refine_consensus(
    inliers: NDArray[np.bool_], P: NDArray[np.float64], meas: NDArray[np.float64], camera: StereoCamera,
    thr2: float, ok: NDArray[np.bool_], T_ref_cur: NDArray[np.float64],
) -> tuple[int, float, NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]] | None:
    """Refine on a hypothesis' inliers (selected at ``T_ref_cur``), re-select them, until the inlier set is stable
    (at most three refinements): (inlier count, RMS px, ``T_ref_cur``, inlier mask, JᵀJ (NaN if a point fell
    behind the camera)), or None when fewer than three remain."""
    K, fb = camera.K, camera.fb
    if np.count_nonzero(inliers) < 3:
        return None
    for k in range(3):
        T, H, in_front = _levenberg_marquardt(_invert(T_ref_cur), np.ascontiguousarray(P[inliers]),
                                              np.ascontiguousarray(meas[inliers]), K[0, 0], K[1, 1], K[0, 2],
                                              K[1, 2], fb, 10)
        T_ref_cur = _invert(T)
        if not in_front:
            H = np.full((6, 6), np.nan)
        if k == 2:
            break
        r, _, front = _stereo_residuals(T, P, meas, K, fb)
        new = ok & front & (np.sum(r * r, axis=1) <= thr2)
        if np.count_nonzero(new) < 3:
            return None
        if np.array_equal(new, inliers):
            break
        inliers = new
    if not np.all(np.isfinite(T_ref_cur)):
        return None
    r, _, _ = _stereo_residuals(_invert(T_ref_cur), P[inliers], meas[inliers], K, fb)
    return int(np.count_nonzero(inliers)), float(np.sqrt(np.mean(np.sum(r * r, axis=1)))), T_ref_cur, inliers, H
