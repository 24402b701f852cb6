"""rACR adjustment (paper §3.1, Eq. 1–3, and §3.5): the hand motion that moves the camera to the reference pose.

Frames and conventions (see :mod:`lightfast.racr.initialization` for ``X`` and ``M_B``)
------------------------------------------------------------------------------------
* ``T_cur_cam`` = T_A: the current camera pose in the current point-cloud space (VSE pose, real scale s applied,
  §3.3), camera-to-cloud; its translation is in current-cloud units.
* ``T_ref_cur`` = T_p and ``sigma`` = σ_p from the alignment thread (§3.4): ``p_ref = R_p (σ_p p) + t_p``.
* The current camera pose in the reference (world) frame is ``T_ref_cam = T_p ⟨R_A, σ_p t_A⟩`` (the paper's
  T̃_A^i, written as in §3.4.1 for the keyframes T̃_K^u).
* ``T_ref_camref`` = T_A^ref: the reference camera pose in the reference frame (metres).
* ``T_cam_hand`` = X, ``M_B = T_hand_hand'`` is executed as ``T_base_hand' = T_base_hand · M_B`` and moves the
  camera by ``T_cam_cam' = X M_B X⁻¹``.

Eq. 1 (with camera-to-world poses) asks for ``M_B`` minimising ``‖T_ref_cam · X M_B X⁻¹ − T_ref_camref‖_F²``; its
exact minimiser is Eq. 3::

    M̂_B = X⁻¹ · T_ref_cam⁻¹ · T_ref_camref · X = X⁻¹ · ⟨R_A, σ_p t_A⟩⁻¹ · T_p⁻¹ · T_A^ref · X

(the paper writes the same product for world-to-camera poses, ``X⁻¹ T_A^ref [·]⁻¹ T_p⁻¹ X``). Executing a
sequence of these (Eq. 2) approaches the reference; §3.5 stops when ``g = ‖M̂_B − I₄‖ ≤ η`` (η = 1e-4). The norm
is the Frobenius norm of the 4×4 difference, ``g = sqrt(‖R_B − I₃‖_F² + ‖t_B‖²)`` with ``t_B`` in metres; for
small motions ``‖R_B − I₃‖_F ≈ √2·θ`` (θ in radians).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.config import Config, param
from lightfast.geometry import is_rotation, project_to_so3
from lightfast.racr.errors import AdjustmentError

__all__ = [
    "AdjustmentConfig",
    "AdjustmentStep",
    "adjustment_step",
    "camera_pose_in_reference",
    "hand_motion",
    "motion_gap",
]

logger = logging.getLogger(__name__)

Array = NDArray[np.float64]
_RIGID_ATOL = 1e-4


@dataclass(frozen=True)
class AdjustmentConfig(Config):
    """Options of the adjustment thread (paper §3.5)."""

    eta: float = param(
        1e-4,
        description="eta: converged when g = ||M_B - I4||_F <= eta (rotation block unitless, translation in m).",
        min=0.0,
    )


@dataclass(frozen=True)
class AdjustmentStep:
    """One adjustment of §3.5: the hand motion ``M_hand = T_hand_hand'`` to execute, its gap ``g`` and whether
    rACR has converged (``g ≤ η``: then nothing should be executed), plus the camera pose ``T_ref_cam`` used."""

    M_hand: Array
    g: float
    converged: bool
    T_ref_cam: Array


def _rigid(T: ArrayLike, name: str) -> Array:
    try:
        a = np.array(T, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise AdjustmentError(f"{name} must be a 4x4 transform: {exc}") from None
    if a.shape != (4, 4) or not np.all(np.isfinite(a)):
        raise AdjustmentError(f"{name} must be a finite 4x4 transform, got shape {a.shape}")
    if not np.allclose(a[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9) or not is_rotation(a[:3, :3], atol=_RIGID_ATOL):
        raise AdjustmentError(f"{name} must be rigid ([R t; 0 0 0 1] with R a rotation)")
    a[:3, :3] = project_to_so3(a[:3, :3])
    return a


def _inverse(T: Array) -> Array:
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def camera_pose_in_reference(T_cur_cam: ArrayLike, T_ref_cur: ArrayLike, sigma: float) -> Array:
    """``T_ref_cam = T_p ⟨R_A, σ_p t_A⟩``: the current camera in the reference frame (paper's T̃_A, §3.1)."""
    T_A = _rigid(T_cur_cam, "T_cur_cam")
    T_p = _rigid(T_ref_cur, "T_ref_cur")
    if not (np.isfinite(sigma) and sigma > 0.0):
        raise AdjustmentError(f"sigma must be positive and finite, got {sigma!r}")
    scaled = T_A.copy()
    scaled[:3, 3] *= sigma
    return T_p @ scaled


def hand_motion(
    T_cur_cam: ArrayLike, T_ref_cur: ArrayLike, sigma: float, T_ref_camref: ArrayLike, T_cam_hand: ArrayLike
) -> Array:
    """Eq. 3: ``M̂_B = X⁻¹ T_ref_cam⁻¹ T_ref_camref X`` = ``T_hand_hand'`` that puts the camera at the reference."""
    T_ref_cam = camera_pose_in_reference(T_cur_cam, T_ref_cur, sigma)
    return _hand_motion(T_ref_cam, _rigid(T_ref_camref, "T_ref_camref"), _rigid(T_cam_hand, "T_cam_hand"))


def _hand_motion(T_ref_cam: Array, T_ref_camref: Array, X: Array) -> Array:
    M = _inverse(X) @ _inverse(T_ref_cam) @ T_ref_camref @ X
    M[3] = (0.0, 0.0, 0.0, 1.0)
    M[:3, :3] = project_to_so3(M[:3, :3])
    return M


def motion_gap(M_hand: ArrayLike) -> float:
    """``g = ‖M − I₄‖_F`` of §3.5 (rotation block unitless, translation in metres)."""
    M = np.asarray(M_hand, dtype=np.float64)
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise AdjustmentError(f"M_hand must be a finite 4x4 matrix, got shape {M.shape}")
    return float(np.linalg.norm(M - np.eye(4)))


def adjustment_step(
    T_cur_cam: ArrayLike,
    T_ref_cur: ArrayLike,
    sigma: float,
    T_ref_camref: ArrayLike,
    T_cam_hand: ArrayLike,
    *,
    config: AdjustmentConfig | None = None,
) -> AdjustmentStep:
    """One adjustment (§3.5): Eq. 3 from the latest T_A (VSE), T_p, σ_p (alignment) and X (initialization)."""
    if config is None:
        config = AdjustmentConfig()
    elif not isinstance(config, AdjustmentConfig):
        raise AdjustmentError(f"config must be an AdjustmentConfig, got {type(config).__name__}")
    T_ref_cam = camera_pose_in_reference(T_cur_cam, T_ref_cur, sigma)
    M = _hand_motion(T_ref_cam, _rigid(T_ref_camref, "T_ref_camref"), _rigid(T_cam_hand, "T_cam_hand"))
    g = motion_gap(M)
    converged = g <= config.eta
    logger.debug("adjustment: g=%.3g (eta=%.3g)%s", g, config.eta, ", converged" if converged else "")
    return AdjustmentStep(M_hand=M, g=g, converged=converged, T_ref_cam=T_ref_cam)
