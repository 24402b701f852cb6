"""Fine-grained scale-aware alignment of rACR (paper §3.4.1 Eq. 10–11 and §3.4.3 Eq. 16–18).

Starting from the fast alignment (:mod:`lightfast.racr.fast_alignment`), the fine alignment minimises the full
objective of Eq. 11, ``α E_g + (1 − α) E_p`` (α = 0.2, §5.4), over the relative pose ``T_p = T_ref_cur`` and scale
``σ_p`` (``p_ref ≈ R_p (σ_p p) + t_p``, Eq. 9):

* **E_g (Eq. 9), geometric:** point-to-plane residuals ``r = n_refᵀ(R_p σ_p p + t_p − p_ref)`` of a fixed sample
  of current points against their nearest reference points (within ``correspondence_radius_m``, re-matched every
  outer iteration), as in the fast alignment.
* **E_p (Eq. 10), photometric:** reference points ``p_ref`` are projected into the current keyframes, whose
  poses in the reference frame are ``T̃_K^u = T_p ⟨R_K^u, σ_p t_K^u⟩`` (§3.4.1), and the keyframe intensities at
  the projections must agree pairwise, ``D^u(π(T̃_K^u, p_ref)) − D^v(π(T̃_K^v, p_ref))`` for ``u < v``, under the
  Huber norm. Only current images are compared with each other — never with the reference image — so the term
  is as insensitive to a lighting change between the two observations as E_g (the point of the paper, §4), and
  it does not use the current cloud's depths: where the VSE's points are noisy or biased (monocular depth,
  scale drift between keyframes) but its keyframe poses are good, E_p is what pulls σ_p and T_p to the truth.
  **Self-occlusion (§3.4.3):** among the reference points that fall into the same keyframe pixel
  (``occlusion_cell_px``), only the one nearest to the camera keeps its photometric terms — a vectorised z-buffer
  (``np.minimum.at`` over pixel ids, :func:`nearest_per_pixel`) over *every* reference point, no pixel loop.

The optimisation follows §3.4.3:

1. **Eq. 16:** refine the current keyframe poses ``T_K^u`` (current-cloud frame) by the photometric error of the
   *current* points (the text says "of current point cloud" and defines ``p_m`` as current points; the printed
   Eq. 16 shows ``p_ref`` with un-tilded poses, which mixes frames): the pairwise terms of Eq. 16 on the blurred
   images plus, for every point and keyframe, an anchor ``D^u(π(T_K^u, p_m)) − I_m`` to the point's own VSE
   intensity ``I_m`` on the raw image (DSO's host-to-target residual). Its Huber threshold is
   ``photometric_huber`` itself, nearly an ℓ1 norm at image noise: each keyframe then stays on its own points
   (which project onto their host pixels whatever their depth error) instead of being pulled by other keyframes'
   biased depths (measured: 1 mm instead of 7 mm camera error with a ±2 % per-keyframe depth bias).
2. **Eq. 17 / Eq. 18:** ``T_p`` (6 parameters, left perturbation about the centroid of the reference points in
   use) and ``σ_p`` (as ``log σ_p``, scaled about the centroid of the current points, which decouples it from
   ``t_p``) with the keyframes fixed, until ``‖ΔT_p − I₄‖_F ≤ τ_T`` and ``|Δσ_p| ≤ τ_σ`` (the fast alignment's
   tolerances) or ``max_outer_iterations``. Every outer iteration re-matches E_g and refreshes the robust weights.
   ``estimate_scale=False`` solves Eq. 17 alone with ``σ_p = sigma_init`` fixed: the paper's ablation rACR-S (§5.4).

Solver: SciPy ``least_squares(method="lm")`` — MINPACK's Levenberg–Marquardt, the paper's LM — with analytic
Jacobians and ``x_scale="jac"``: rotation (rad), translation (m) and log-scale differ in sensitivity by orders of
magnitude, and MINPACK's Jacobian-column scaling makes the damping act on comparable units. MINPACK's LM takes
no robust loss, so the Huber norm is applied by iteratively reweighted least squares (weights ``min(1, δ/|r|)``
frozen for one LM solve, refreshed every outer iteration, whose fixed point is the Huber minimiser); the outer
loop is needed anyway for the re-matching. ``method="trf"`` (same residuals and weights, robust to nothing
more) is kept as a cross-check: it decomposes the Jacobian by SVD and measured 3–4× slower at 50 k points.
Cost: about 1.5 s CPU per fine alignment with 50 k reference and 50 k current points, five 320×240 keyframes
(``benchmarks/results/racr_fine_alignment.md``; the paper: ~5 s).

Deviations from the paper, stated
---------------------------------
* **Weighting.** Eq. 11 adds E_g (m²) and E_p (intensity²) as raw sums, so α = 0.2 only means something in the
  paper's units and point counts (with images in 0–255 and clouds in metres, E_p dominates by orders of
  magnitude). Here each term is a *mean* of Huber norms of its residuals divided by a robust scale ``δ``,
  ``α · mean ρ(r_g/δ_g) + (1 − α) · mean ρ(r_p/δ_p)``, with ``δ = huber_k · 1.4826 · MAD`` of the term's
  residuals at the start (floored by ``geometric_huber_m`` / ``photometric_huber``): α is then a unit-free
  trade-off between two terms measured in their own noise. With fixed thresholds instead, a noisy current cloud
  (all its residuals far beyond δ_g) outweighed E_p at α = 0.2 and the result was worse than the fast alignment.
* **Eq. 16 needs the anchors.** With the current points fixed, pairwise photo-consistency alone leaves the rigid
  motions of the whole keyframe rig that slide a near-planar scene along itself almost free (measured: 0.2°
  keyframe pose errors grew to ~0.9° under LM); the anchors to the VSE intensities remove that. Without
  ``intensities`` Eq. 16 is skipped.
* **Joint scale update by default.** ``scale_update="alternate"`` runs Eq. 17 and Eq. 18 as separate LM solves,
  as the paper does; the alternation converges linearly (measured: the camera error halves per outer iteration,
  12 iterations to reach what the joint solve reaches in 5–6), so the default ``"joint"`` solves Eq. 17 and 18
  together in one 7-parameter LM — the same objective and minimiser, in less than half the time.
* E_g uses a Huber norm and point-to-plane residuals, like the fast alignment's robust step; Eq. 9 is
  point-to-point squared.
* **Gradient-dependent weight (DSO's, which the paper builds on).** Every pairwise residual of E_p is multiplied
  by ``c / sqrt(c² + ‖∇D^u‖² + ‖∇D^v‖²)`` at its two projections, ``c = gradient_weight ×`` the median gradient
  magnitude of the blurred keyframes (so it follows the images' contrast: 0.013 per px on the test relief, 0.003
  on the simulated scenes). Unweighted, residuals grow with the gradient, and the E_p points are the
  strongest-gradient ones at the start, so a pose that moves the projections off their edges lowers E_p: started
  at the truth, the fine alignment walked 7–11 mm away on the simulated scenes S05/S07 (0.5–1 mm weighted), and
  from a good fast alignment it made the estimate worse (S05 0.3 → 9 mm). Eq. 16 is left unweighted: its anchors
  to the VSE intensities already hold each keyframe on its own points, and the keyframe tests pass without it.
* **Subsets.** A fixed random sample of ``max_geometric_points`` current points for E_g, the
  ``max_photometric_points`` reference points with the strongest keyframe gradients (among those seen by at
  least two keyframes) for E_p, and likewise ``max_keyframe_points`` current points for Eq. 16 (DSO-like
  gradient selection: flat texture carries no photometric information). The z-buffer runs once, at the start,
  over every reference point: the pose changes of a fine alignment (millimetres) do not change which point is
  nearest in a pixel.
* Keyframe images are blurred by ``image_blur_px`` (Gaussian σ) for E_p and the pairwise terms, which widens the
  photometric basin to the fast alignment's error; both sides of every pairwise residual are blurred alike.
* **When it does not pay.** On an accurate current cloud the fast alignment (measured ~1–2 mm, 0.06° camera
  error) is better than E_p's own precision with 320×240 px keyframes (~2–4 mm, 0.2°: interpolation and
  occlusion-edge effects of real images); the fine alignment pays off when the cloud is the weak part (per-keyframe
  depth bias: 31 mm → 6 mm), which is the situation the paper designs it for.
* **What E_p cannot fix.** Pairwise photo-consistency holds whenever the reference points lie *on* the current
  surface, so E_p constrains the reference surface against the images, not motions that slide a surface along
  itself: on a textured plane an in-plane shift leaves E_p unchanged, exactly as it leaves E_g unchanged
  (``test_fine_alignment.py`` shows it). Fixing that would take a comparison with the reference *image*, which a
  lighting change breaks; the paper does not do it and neither does this module.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import cast

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from lightfast.camera import PinholeCamera
from lightfast.config import Config, ConfigError, param
from lightfast.geometry import is_rotation, project_to_so3, so3_exp
from lightfast.racr.errors import AlignmentError
from lightfast.racr.fast_alignment import (
    FastAlignmentConfig,
    ReferenceCloud,
    SimilarityEstimate,
    _cloud,
    _initial_pose,
)

__all__ = [
    "LM_METHODS",
    "SCALE_UPDATES",
    "FineAlignmentConfig",
    "FineAlignmentResult",
    "Keyframe",
    "fine_align",
    "nearest_per_pixel",
]

logger = logging.getLogger(__name__)

Array = NDArray[np.float64]

LM_METHODS = ("lm", "trf")
SCALE_UPDATES = ("alternate", "joint")
_MIN_KEYFRAMES = 2


@dataclass(frozen=True)
class FineAlignmentConfig(Config):
    """Options of the fine-grained alignment (paper §3.4.3). Distances are metres in the reference frame,
    intensities are in the keyframe images' units (defaults assume images in [0, 1])."""

    alpha: float = param(0.2, description="alpha of Eq. 11: weight of E_g (1 - alpha on E_p); 1 = geometry only.",
                         min=0.0, max=1.0)
    photometric_huber: float = param(
        0.002, description="Floor of the photometric Huber threshold (and normalising scale), image units.", min=1e-9
    )
    geometric_huber_m: float = param(
        0.0005, description="Floor of the point-to-plane Huber threshold (and normalising scale), m.", min=1e-9
    )
    correspondence_radius_m: float = param(
        0.02, description="E_g pairs a current point with its nearest reference point within this distance, m.",
        min=1e-6,
    )
    max_geometric_points: int = param(3000, description="Current points sampled for E_g; 0 = all.", min=0)
    max_photometric_points: int = param(
        3000, description="Reference points (strongest keyframe gradient) carrying E_p; 0 = all visible.", min=0
    )
    max_keyframe_points: int = param(
        2000, description="Current points (strongest gradient) carrying Eq. 16; 0 = all visible.", min=0
    )
    max_keyframes: int = param(6, description="Most recent keyframes used (all pairs u < v).", min=2, max=64)
    refine_keyframes: bool = param(True, description="Eq. 16 before Eq. 17-18 (False: the paper's rACR-P).")
    intensity_anchors: bool = param(
        True, description="Eq. 16 also ties each current point's projections to its VSE intensity (if given)."
    )
    keyframe_iterations: int = param(1, description="Reweighting rounds of Eq. 16.", min=1, max=100)
    image_blur_px: float = param(1.0, description="Gaussian sigma applied to keyframe images, px (0 = none).",
                                 min=0.0, max=20.0)
    border_px: float = param(2.0, description="Projections closer than this to the image border are unused, px.",
                             min=1.0)
    occlusion_cell_px: int = param(
        1, description="Z-buffer cell of the self-occlusion rule: nearest point per cell of this size, px.", min=1
    )
    max_outer_iterations: int = param(
        6, description="Cap on outer iterations (re-match E_g, reweight, solve Eq. 17-18).", min=1, max=10000
    )
    lm_max_nfev: int = param(8, description="Function evaluations per Levenberg-Marquardt solve.", min=2)
    lm_ftol: float = param(1e-4, description="Relative cost reduction that ends a Levenberg-Marquardt solve.",
                           min=1e-15, max=0.5)
    method: str = param("lm", description="SciPy least_squares method.", choices=LM_METHODS)
    scale_update: str = param(
        "joint", description="Eq. 17 then Eq. 18 as separate LM solves (the paper), or one joint LM solve.",
        choices=SCALE_UPDATES,
    )
    estimate_scale: bool = param(
        True, description="Optimise sigma_p (Eq. 18); False keeps sigma_init fixed and solves Eq. 17 only (rACR-S).",
    )
    pose_tolerance: float = param(1e-4, description="tau_T: stop when ||dT_p - I4||_F <= this.", min=0.0)
    scale_tolerance: float = param(1e-5, description="tau_sigma: ... and |d sigma_p| <= this.", min=0.0)
    min_photometric_residuals: int = param(
        50, description="Fewer pairwise photometric residuals than this is an error (keyframes miss the scene).",
        min=1,
    )
    min_geometric_residuals: int = param(30, description="Fewer E_g correspondences than this is an error.", min=7)
    max_scale_change: float = param(
        0.3, description="|log(sigma_p / sigma_init)| above this is divergence.", min=1e-6, max=5.0
    )
    seed: int = param(0, description="Seed of the E_g sample.", min=0)
    huber_k: float = param(
        1.345, description="Huber thresholds = this many robust std. deviations (MAD at the start) of each term, "
        "floored by photometric_huber / geometric_huber_m; 0 = the floors as fixed thresholds.", min=0.0,
    )
    gradient_weight: float = param(
        2.5, description="c of the gradient-dependent weight of every photometric residual (DSO's), "
        "sqrt(c^2 / (c^2 + |grad D^u|^2 + |grad D^v|^2)) at its projections, as a multiple of the median gradient "
        "magnitude (per px) of the blurred keyframes; 0 = unweighted.",
        min=0.0,
    )

    def check(self) -> None:
        if self.correspondence_radius_m < self.geometric_huber_m:
            raise ConfigError("FineAlignmentConfig.correspondence_radius_m must be at least geometric_huber_m")


@dataclass(frozen=True)
class Keyframe:
    """A current keyframe (§3.4.1): image ``D^u`` ``(H, W)`` (float, any fixed units), its camera pose
    ``T_cur_cam`` = T_K^u in the current-cloud frame (camera-to-cloud, real scale s applied, §3.3) and its
    pinhole camera."""

    image: Array
    T_cur_cam: Array
    camera: PinholeCamera

    def __post_init__(self) -> None:
        if not isinstance(self.camera, PinholeCamera):
            raise AlignmentError(f"keyframe camera must be a PinholeCamera, got {type(self.camera).__name__}")
        try:
            img = np.array(self.image, dtype=np.float64)
            T = np.array(self.T_cur_cam, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise AlignmentError(f"keyframe image and pose must be numeric arrays: {exc}") from None
        if img.shape != self.camera.shape:
            raise AlignmentError(f"keyframe image shape {img.shape} does not match its camera {self.camera.shape}")
        if not np.all(np.isfinite(img)):
            raise AlignmentError("keyframe image has non-finite pixels")
        if T.shape != (4, 4) or not np.all(np.isfinite(T)) or not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]):
            raise AlignmentError(f"keyframe T_cur_cam must be a finite 4x4 rigid transform, got shape {T.shape}")
        if not is_rotation(T[:3, :3], atol=1e-4):
            raise AlignmentError("keyframe T_cur_cam must be rigid ([R t; 0 0 0 1] with R a rotation)")
        T[:3, :3] = project_to_so3(T[:3, :3])
        img.flags.writeable = False
        T.flags.writeable = False
        object.__setattr__(self, "image", img)
        object.__setattr__(self, "T_cur_cam", T)

    @classmethod
    def coerce(cls, value: Keyframe | Sequence[object]) -> Keyframe:
        """A :class:`Keyframe` from itself or an ``(image, T_cur_cam, camera)`` tuple."""
        if isinstance(value, Keyframe):
            return value
        try:
            image, T, camera = value
        except (TypeError, ValueError):
            raise AlignmentError("a keyframe must be a Keyframe or an (image, T_cur_cam, camera) tuple") from None
        return cls(image, T, camera)  # type: ignore[arg-type]


@dataclass(frozen=True)
class FineAlignmentResult(SimilarityEstimate):
    """Outcome of :func:`fine_align`: ``T_ref_cur`` = T_p (rigid 4×4), ``sigma`` = σ_p and the refined keyframe
    poses ``T_cur_keyframes`` ``(K, 4, 4)`` (current-cloud frame, Eq. 16; unchanged with ``refine_keyframes``
    off).

    ``cost_initial`` / ``cost_final`` are the normalised Eq. 11 objective (see the module notes) at the start and at
    the end, both on the final correspondences and visibility; ``geometric_rmse_m`` and ``photometric_rmse`` are the
    plain RMS residuals of the two terms at the end; ``occluded`` counts the reference-point projections the
    self-occlusion rule removed (summed over keyframes).
    """

    T_ref_cur: Array
    sigma: float
    T_cur_keyframes: Array
    iterations: int
    converged: bool
    cost_initial: float
    cost_final: float
    geometric_rmse_m: float
    photometric_rmse: float
    geometric_residuals: int
    photometric_residuals: int
    keyframe_residuals: int
    occluded: int
    keyframes_used: int
    pose_change: float
    scale_change: float
    seconds: float = field(compare=False)


def nearest_per_pixel(pixel: ArrayLike, depth: ArrayLike) -> NDArray[np.bool_]:
    """The self-occlusion rule of §3.4.3: among points that fall into the same pixel (any integer id, e.g.
    ``v * width + u``), keep only the one with the smallest ``depth`` (ties: the lowest index).

    A vectorised z-buffer: ``np.minimum.at`` of the depths into a buffer over the (compacted) pixel ids, then the
    same for the indices of the points that reach the minimum."""
    pix = np.asarray(pixel)
    z = np.asarray(depth, dtype=np.float64)
    if pix.shape != z.shape or pix.ndim != 1:
        raise AlignmentError(f"pixel and depth must be 1-d arrays of one length, got {pix.shape} and {z.shape}")
    if len(pix) == 0:
        return np.zeros(0, dtype=bool)
    if not np.issubdtype(pix.dtype, np.integer):
        raise AlignmentError(f"pixel ids must be integers, got {pix.dtype}")
    lo, hi = int(pix.min()), int(pix.max())
    if hi - lo < 8 * len(pix) + (1 << 20):
        ids, size = pix - lo, hi - lo + 1
    else:
        uniq, ids = np.unique(pix, return_inverse=True)
        size = len(uniq)
    zbuf = np.full(size, np.inf)
    np.minimum.at(zbuf, ids, z)
    nearest = np.flatnonzero(z <= zbuf[ids])
    first = np.full(size, len(pix), dtype=np.intp)
    np.minimum.at(first, ids[nearest], nearest)
    keep = np.zeros(len(pix), dtype=bool)
    keep[nearest[first[ids[nearest]] == nearest]] = True
    return keep


class _Views:
    """The keyframes prepared for vectorised sampling: for each, the (blurred) intensity and its central-difference
    gradient — with ``squared_gradient`` also the gradient of ``‖∇I‖²`` (for the Jacobian of the gradient-dependent
    weight, :func:`_gradient_weight`) — all keyframes stacked into one ``(Σ H·W, 3 or 5)`` table, plus per-keyframe
    intrinsics shaped ``(K, 1)``. Points are handled as ``(K, M, …)`` arrays: point ``m`` seen by keyframe ``k``."""

    def __init__(self, keyframes: Sequence[Keyframe], blur_px: float, border_px: float, *,
                 squared_gradient: bool = False) -> None:
        tables, offsets = [], [0]
        for kf in keyframes:
            img = kf.image
            if blur_px > 0.0:
                img = cast(Array, cv2.GaussianBlur(img, (0, 0), blur_px, borderType=cv2.BORDER_REFLECT))
            gy, gx = np.gradient(img)
            cols = [img, gx, gy]
            if squared_gradient:
                qy, qx = np.gradient(gx * gx + gy * gy)
                cols += [qx, qy]
            tables.append(np.stack(cols, axis=-1).reshape(-1, len(cols)))
            offsets.append(offsets[-1] + img.size)
        self.table = np.ascontiguousarray(np.concatenate(tables), dtype=np.float64)
        cams = [kf.camera for kf in keyframes]
        col = np.array

        self.offset = col(offsets[:-1], dtype=np.intp)[:, None]
        self.width = col([c.width for c in cams], dtype=np.intp)[:, None]
        self.height = col([c.height for c in cams], dtype=np.intp)[:, None]
        self.fx = col([c.fx for c in cams])[:, None]
        self.fy = col([c.fy for c in cams])[:, None]
        self.cx = col([c.cx for c in cams])[:, None]
        self.cy = col([c.cy for c in cams])[:, None]
        self.border = border_px
        #: median gradient magnitude (intensity per px) over every pixel of the (blurred) keyframes: the image's own
        #: contrast scale, to which the gradient-dependent weight's ``c`` is relative
        self.median_gradient = float(np.median(np.hypot(self.table[:, 1], self.table[:, 2])))

    def __len__(self) -> int:
        return len(self.offset)

    def project(self, c: Array) -> tuple[Array, Array, NDArray[np.bool_]]:
        """Pixel coordinates ``u, v`` ``(K, M)`` of camera points ``c`` ``(K, M, 3)`` and whether they are usable:
        in front of the camera and at least ``border_px`` inside the image."""
        z = c[..., 2]
        front = z > 1e-9
        zi = np.where(front, 1.0 / np.where(front, z, 1.0), 0.0)
        u = self.fx * c[..., 0] * zi + self.cx
        v = self.fy * c[..., 1] * zi + self.cy
        b = self.border
        ok = front & (u >= b) & (u <= self.width - 1.0 - b) & (v >= b) & (v <= self.height - 1.0 - b)
        return u, v, ok

    def sample(self, u: Array, v: Array) -> Array:
        """Bilinear (I, ∂I/∂u, ∂I/∂v[, ∂‖∇I‖²/∂u, ∂‖∇I‖²/∂v]) ``(K, M, 3 or 5)`` at ``u, v`` ``(K, M)`` (clamped to
        the image). In float64 on purpose: ``cv2.remap`` quantises sub-pixel positions to 1/32 px, making the
        residuals piecewise constant."""
        u = np.clip(u, 0.0, self.width - 1.000001)
        v = np.clip(v, 0.0, self.height - 1.000001)
        u0 = u.astype(np.intp)
        v0 = v.astype(np.intp)
        a = (u - u0)[..., None]
        b = (v - v0)[..., None]
        i = (self.offset + v0 * self.width + u0).ravel()
        t = self.table
        shape = u.shape + (t.shape[1],)
        t00, t01 = np.take(t, i, axis=0).reshape(shape), np.take(t, i + 1, axis=0).reshape(shape)
        i += np.repeat(self.width[:, 0], u.shape[1]) if u.ndim == 2 else self.width[:, 0]
        t10, t11 = np.take(t, i, axis=0).reshape(shape), np.take(t, i + 1, axis=0).reshape(shape)
        top = t00 + a * (t01 - t00)
        return top + b * (t10 + a * (t11 - t10) - top)

    def chain(self, c: Array, grad: Array) -> Array:
        """``∂I/∂c`` ``(K, M, 3)``: the image gradient ``grad`` ``(K, M, 2)`` through the projection at ``c``."""
        zi = 1.0 / np.maximum(c[..., 2], 1e-9)
        gu = grad[..., 0] * self.fx * zi
        gv = grad[..., 1] * self.fy * zi
        return np.stack([gu, gv, -(gu * c[..., 0] + gv * c[..., 1]) * zi], axis=-1)

    def visible(self, c: Array, cell_px: int) -> tuple[NDArray[np.bool_], int]:
        """The usable projections of camera points ``c`` ``(K, M, 3)`` that survive the self-occlusion rule
        (nearest point per ``cell_px`` cell of each keyframe). Returns the ``(K, M)`` mask and how many usable
        projections the z-buffer removed."""
        u, v, ok = self.project(c)
        k_idx, m_idx = np.nonzero(ok)
        cells_u = (self.width[:, 0] // cell_px + 2)[k_idx]
        cu = np.floor((u[k_idx, m_idx] + 0.5) / cell_px).astype(np.int64)
        cv = np.floor((v[k_idx, m_idx] + 0.5) / cell_px).astype(np.int64)
        cell = (cv * cells_u + cu) * len(self) + k_idx  # unique across keyframes
        keep = nearest_per_pixel(cell, c[k_idx, m_idx, 2])
        mask = np.zeros(ok.shape, dtype=bool)
        mask[k_idx[keep], m_idx[keep]] = True
        return mask, int(len(k_idx) - np.count_nonzero(keep))


def _camera_points(P: Array, R_world_cam: Array, t_world_cam: Array) -> Array:
    """``(K, M, 3)``: points ``P`` ``(M, 3)`` in each camera ``⟨R, t⟩`` ``(K, 3, 3)``, ``(K, 3)`` (camera-to-world)."""
    return np.matmul(P[None, :, :] - t_world_cam[:, None, :], R_world_cam)


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
    plane) the truth is then a local *maximum* of E_p (module notes). Its derivative is part of the Jacobians
    (:meth:`_Problem.raw`). ``c = 0``: 1 (unweighted)."""
    if c <= 0.0:
        return 1.0
    g2 = s[ku, mu, 1] ** 2 + s[ku, mu, 2] ** 2 + s[kv, mv, 1] ** 2 + s[kv, mv, 2] ** 2
    return c / np.sqrt(c * c + g2)


def _huber_rho(z: Array) -> Array:
    a = np.abs(z)
    return np.where(a <= 1.0, 0.5 * z * z, a - 0.5)


def _pairs(visible: NDArray[np.bool_]) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """``(u, v, m)`` for every point ``m`` visible in both keyframes ``u < v`` (``visible`` is ``(K, M)``)."""
    us, vs, ms = [], [], []
    K = visible.shape[0]
    for u in range(K):
        for v in range(u + 1, K):
            m = np.flatnonzero(visible[u] & visible[v])
            us.append(np.full(len(m), u, dtype=np.intp))
            vs.append(np.full(len(m), v, dtype=np.intp))
            ms.append(m)
    return np.concatenate(us), np.concatenate(vs), np.concatenate(ms)


def _select_by_gradient(c: Array, views: _Views, visible: NDArray[np.bool_], count: int) -> NDArray[np.intp]:
    """Indices of up to ``count`` points seen by ≥ 2 keyframes, strongest summed gradient magnitude first."""
    u, v, _ = views.project(c)
    g = views.sample(u, v)
    score = np.where(visible, np.hypot(g[..., 1], g[..., 2]), 0.0).sum(axis=0)
    candidates = np.flatnonzero(visible.sum(axis=0) >= _MIN_KEYFRAMES)
    if 0 < count < len(candidates):
        candidates = candidates[np.argsort(-score[candidates], kind="stable")[:count]]
    return np.sort(candidates)


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

    delta = config.photometric_huber  # fixed, near ℓ1 at image noise (module notes)
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


def _intensities(intensities: ArrayLike | None, n: int) -> Array | None:
    if intensities is None:
        return None
    try:
        a = np.asarray(intensities, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise AlignmentError(f"intensities must be an (n,) array: {exc}") from None
    if a.shape != (n,):
        raise AlignmentError(f"intensities must have shape ({n},) like points_cur, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise AlignmentError("intensities has non-finite values")
    return a


def fine_align(
    points_cur: ArrayLike,
    reference: ReferenceCloud | ArrayLike,
    keyframes: Sequence[Keyframe | Sequence[object]],
    *,
    T_ref_cur_init: ArrayLike,
    sigma_init: float,
    intensities: ArrayLike | None = None,
    config: FineAlignmentConfig | None = None,
) -> FineAlignmentResult:
    """Fine-grained alignment (§3.4.3): Eq. 16, then Eq. 17–18 (jointly by default), from the fast alignment's result.

    ``points_cur`` ``(n, 3)``: the current cloud P (real scale applied, §3.3); ``intensities`` ``(n,)``: each
    point's intensity in its host keyframe, as a direct VSE keeps it (needed by Eq. 16, which is skipped without
    it). ``reference``: a prepared :class:`ReferenceCloud` (reuse it) or the reference points ``(m, 3)`` in
    metres. ``keyframes``: the current keyframes as :class:`Keyframe` or ``(image (H, W), T_cur_cam (4, 4),
    PinholeCamera)`` tuples, at least two; the last ``max_keyframes`` are used. ``T_ref_cur_init`` (rigid 4×4) and
    ``sigma_init`` come from :func:`~lightfast.racr.fast_alignment.fast_align`.

    Returns ``converged=False`` when ``max_outer_iterations`` is reached. Raises :class:`AlignmentError` for
    invalid input, keyframes that do not see the reference together (fewer than ``min_photometric_residuals``),
    no geometric overlap, or a scale that moves more than ``max_scale_change`` (in log) from ``sigma_init``.
    """
    start = time.perf_counter()
    if config is None:
        config = FineAlignmentConfig()
    elif not isinstance(config, FineAlignmentConfig):
        raise AlignmentError(f"config must be a FineAlignmentConfig, got {type(config).__name__}")
    if not isinstance(reference, ReferenceCloud):
        reference = ReferenceCloud.from_config(reference, FastAlignmentConfig())
    p_all = _cloud(points_cur, "points_cur", config.min_geometric_residuals)
    I_all = _intensities(intensities, len(p_all))
    R, t = _initial_pose(T_ref_cur_init)
    sigma0 = float(sigma_init)
    if not (np.isfinite(sigma0) and sigma0 > 0.0):
        raise AlignmentError(f"sigma_init={sigma_init!r} must be positive and finite")
    sigma = sigma0
    kfs = [Keyframe.coerce(k) for k in keyframes][-config.max_keyframes :]
    if len(kfs) < _MIN_KEYFRAMES:
        raise AlignmentError(f"fine alignment needs at least {_MIN_KEYFRAMES} keyframes, got {len(kfs)}")
    views = _Views(kfs, config.image_blur_px, config.border_px, squared_gradient=config.gradient_weight > 0.0)
    R_K = np.stack([k.T_cur_cam[:3, :3] for k in kfs])
    t_K = np.stack([k.T_cur_cam[:3, 3] for k in kfs])

    rng = np.random.default_rng(config.seed)
    p_geo_all = p_all
    if 0 < config.max_geometric_points < len(p_all):
        p_geo_all = p_all[rng.choice(len(p_all), config.max_geometric_points, replace=False)]

    kf_residuals = 0
    if config.refine_keyframes and I_all is not None and config.intensity_anchors:
        raw_views = _Views(kfs, 0.0, config.border_px)
        R_K, t_K, kf_residuals = _refine_keyframes(p_all, I_all, views, raw_views, R_K, t_K, config)

    problem: _Problem | None = None
    scales: tuple[float, float] | None = None
    converged = False
    pose_change = scale_change = float("inf")
    iterations = 0
    R0, t0 = R.copy(), t.copy()
    P_ref, pairs, occluded = _photometric_setup(config, reference, views, R_K, t_K, R, t, sigma)
    for iterations in range(1, config.max_outer_iterations + 1):
        problem = _build_problem(config, reference, p_geo_all, views, R_K, t_K, R, t, sigma, P_ref, pairs)
        if scales is None:
            scales = problem.robust_scales(R, t, sigma) if config.huber_k > 0 else (
                config.geometric_huber_m, config.photometric_huber)
        problem.set_scales(*scales)
        problem.reweight(R, t, sigma)
        R_prev, t_prev, sigma_prev = R, t, sigma
        if not config.estimate_scale:  # rACR-S: Eq. 17 only
            R, t = _pose_step(problem, R, t, sigma)
        elif config.scale_update == "joint":
            R, t, sigma = _joint_step(problem, R, t, sigma)
        else:
            R, t = _pose_step(problem, R, t, sigma)
            problem.reweight(R, t, sigma)
            t, sigma = _scale_step(problem, R, t, sigma)
        if not (np.isfinite(sigma) and abs(np.log(sigma / sigma0)) <= config.max_scale_change):
            raise AlignmentError(
                f"the scale diverged to sigma_p={sigma:.4g} from {sigma0:.4g} at iteration {iterations} "
                f"(max_scale_change={config.max_scale_change})"
            )
        dRot = R_prev.T @ R
        pose_change = float(np.sqrt(np.sum((dRot - np.eye(3)) ** 2) + np.sum((t - t_prev) ** 2)))
        scale_change = abs(sigma - sigma_prev)
        logger.debug(
            "fine alignment iteration %d: cost %.5g, ||dT - I|| %.2e, d sigma %.2e, sigma_p %.6f",
            iterations, problem.cost(R, t, sigma), pose_change, scale_change, sigma,
        )
        if pose_change <= config.pose_tolerance and scale_change <= config.scale_tolerance:
            converged = True
            break
    assert problem is not None
    cost_initial = problem.cost(R0, t0, sigma0)
    cost_final = problem.cost(R, t, sigma)
    r_g, r_p, _, _ = problem.raw(R, t, sigma, None)
    inl_g = np.abs(r_g) <= 3.0 * config.geometric_huber_m
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    T_K = np.tile(np.eye(4), (len(kfs), 1, 1))
    T_K[:, :3, :3], T_K[:, :3, 3] = R_K, t_K
    result = FineAlignmentResult(
        T_ref_cur=T,
        sigma=float(sigma),
        T_cur_keyframes=T_K,
        iterations=iterations,
        converged=converged,
        cost_initial=cost_initial,
        cost_final=cost_final,
        geometric_rmse_m=float(np.sqrt(np.mean(r_g[inl_g] ** 2))) if np.any(inl_g) else float("nan"),
        photometric_rmse=float(np.sqrt(np.mean(r_p**2))) if len(r_p) else float("nan"),
        geometric_residuals=len(r_g),
        photometric_residuals=len(r_p),
        keyframe_residuals=kf_residuals,
        occluded=occluded,
        keyframes_used=len(kfs),
        pose_change=pose_change,
        scale_change=scale_change,
        seconds=time.perf_counter() - start,
    )
    logger.debug(
        "fine alignment: %s after %d iterations, sigma_p=%.6f, cost %.4g -> %.4g, %d + %d residuals, %.0f ms",
        "converged" if converged else "not converged",
        iterations,
        sigma,
        cost_initial,
        cost_final,
        len(r_g),
        len(r_p),
        1e3 * result.seconds,
    )
    return result


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
