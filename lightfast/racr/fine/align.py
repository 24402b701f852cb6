"""The fine-grained alignment's outer loop (paper §3.4.3): Eq. 16, then Eq. 17–18 until convergence.

:func:`fine_align` starts from the fast alignment's ``T_ref_cur_init`` = ``T_p`` (rigid 4×4, current-cloud frame
to reference frame, metres) and ``sigma_init`` = ``σ_p`` (``p_ref ≈ R_p (σ_p p) + t_p``, Eq. 9), and

1. refines the current keyframe poses ``T_K^u`` by Eq. 16 (:mod:`lightfast.racr.fine.optimization`; skipped
   without point intensities or with ``refine_keyframes`` off);
2. fixes E_p's reference points and keyframe pairs (:mod:`lightfast.racr.fine.objective`): the self-occlusion
   z-buffer runs once, at the start, over every reference point;
3. per outer iteration re-matches E_g, refreshes the robust weights and solves Eq. 17 and 18 (jointly by default,
   ``scale_update``) until ``‖ΔT_p − I₄‖_F ≤ τ_T`` and ``|Δσ_p| ≤ τ_σ``, or ``max_outer_iterations``.
   ``estimate_scale=False`` solves Eq. 17 alone with ``σ_p = sigma_init`` (the paper's rACR-S).

Inputs: the current cloud ``(n, 3)`` (real scale s applied, §3.3) with each point's intensity ``(n,)`` in its host
keyframe (image units), the reference cloud (metres, reference frame) and at least two
:class:`~lightfast.racr.fine.keyframes.Keyframe`. Output: :class:`FineAlignmentResult` — ``T_ref_cur``, ``sigma``,
the refined keyframe poses ``T_cur_keyframes`` ``(K, 4, 4)`` (current-cloud frame), the normalised Eq. 11 cost
before and after, residual counts and RMS (m; image units).
"""
from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.racr.errors import AlignmentError
from lightfast.racr.fast_alignment import (
    FastAlignmentConfig,
    ReferenceCloud,
    SimilarityEstimate,
    _cloud,
    _initial_pose,
)
from lightfast.racr.fine.config import FineAlignmentConfig
from lightfast.racr.fine.keyframes import _MIN_KEYFRAMES, Keyframe, _Views
from lightfast.racr.fine.objective import _build_problem, _photometric_setup, _Problem
from lightfast.racr.fine.optimization import _joint_step, _pose_step, _refine_keyframes, _scale_step

__all__ = ["FineAlignmentResult", "fine_align"]

logger = logging.getLogger(__name__)

Array = NDArray[np.float64]

@dataclass(frozen=True)
class FineAlignmentResult(SimilarityEstimate):
    """Outcome of :func:`fine_align`: ``T_ref_cur`` = T_p (rigid 4×4), ``sigma`` = σ_p and the refined keyframe
    poses ``T_cur_keyframes`` ``(K, 4, 4)`` (current-cloud frame, Eq. 16; unchanged with ``refine_keyframes``
    off).

    ``cost_initial`` / ``cost_final`` are the normalised Eq. 11 objective (:mod:`~lightfast.racr.fine.objective`)
    at the start and at the end, both on the final correspondences and visibility; ``geometric_rmse_m`` and
    ``photometric_rmse`` are the plain RMS residuals of the two terms at the end; ``occluded`` counts the
    reference-point projections the self-occlusion rule removed (summed over keyframes).
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
