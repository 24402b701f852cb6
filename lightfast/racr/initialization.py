"""rACR initialization (paper §3.2, Eq. 4–8): hand–eye transform X and the real scale s of a monocular VSE.

Conventions (the paper's ``M_A X = X M_B``, Fig. 3, with frames made explicit):

* A *hand motion* ``M_B = T_hand_hand'`` is the new hand pose expressed in the hand frame before the motion
  (metres, from the platform); the platform executes it as ``T_base_hand' = T_base_hand · M_B``.
* The matching *camera motion* is ``M_A = T_cam_cam'`` (from the VSE: ``T_vse_cam⁻¹ · T_vse_cam'``); its
  translation ``t_VSE`` is in the VSE's unknown monocular units, the real one is ``t_A = s · t_VSE`` (§3.3).
* ``X = T_cam_hand`` (the hand frame seen from the camera). Then ``M_A = X M_B X⁻¹``, i.e. ``M_A X = X M_B``:
  rotation ``R_A R_X = R_X R_B`` (Eq. 4) and translation ``t_A + (R_A − I) t_X = R_X t_B`` (Eq. 5).

1. ``R_X`` from the rotations alone (Eq. 4) with OpenCV's ``calibrateHandEye`` (Tsai–Lenz by default). OpenCV
   takes absolute poses, so the motion pairs are laid out as a star: pose 0 is the identity for hand and camera,
   pose k is ``M_B^k`` (``T_base_gripper``) and ``M_A^k`` (camera pose in the VSE world, passed as its inverse
   ``T_target_cam``); OpenCV returns ``T_gripper_cam = X⁻¹``. Only its rotation is used (the VSE translations
   have no scale yet).
2. ``s`` by Eq. 8. With ``k`` the rotation axis of ``R_A`` (``kᵀ(R_A − I) = 0``), Eq. 6 gives
   ``s kᵀt_VSE = kᵀ R_X t_B``. **Note:** the paper prints Eq. 8 as ``s = kᵀt_VSE / kᵀ(R_X t_B)``, the reciprocal
   of what its own Eq. 6 (``t_A = s t_VSE``) implies; this module implements the form consistent with Eq. 6,
   ``s = kᵀ(R_X t_B) / kᵀt_VSE``, so that ``t_A = s · t_VSE`` and ``P = s · P_VSE`` (§3.3). Over several
   motions ``s`` is the least-squares solution of ``s a_k = b_k`` (``a_k = kᵀt_VSE``, ``b_k = kᵀR_X t_B``).
   Only motions that translate along their rotation axis (``|b_k| ≥ min_axial_translation_m``) carry s.
3. ``t_X`` from Eq. 6, ``(R_A − I) t_X = R_X t_B − s t_VSE``, stacked over all motions, by linear least squares.

Degenerate input raises :class:`~lightfast.racr.errors.DegenerateMotionError`: fewer than two motions that rotate
by ``min_rotation_deg`` (pure translations), rotation axes closer than ``min_axis_separation_deg`` (parallel
axes leave R_X and t_X undetermined), no motion with translation along its axis (Eq. 8 undefined), or an R_X
that does not satisfy Eq. 4 (RMS residual above ``max_rotation_residual_deg``): OpenCV 4.x's Tsai solver silently
returns the identity for small rotations (docs/racr.md); Horaud and Park have no such limit.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, cast

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.config import Config, param
from lightfast.geometry import is_rotation, make_transform, project_to_so3, so3_log
from lightfast.racr.errors import DegenerateMotionError, InitializationError

__all__ = [
    "HAND_EYE_METHODS",
    "HandEyeResult",
    "InitializationConfig",
    "hand_eye_rotation",
    "hand_eye_translation",
    "initialize",
    "real_scale",
    "relative_motions",
]

logger = logging.getLogger(__name__)

Array = NDArray[np.float64]

#: OpenCV hand–eye solvers by name (the paper cites Tsai–Lenz [14]). Daniilidis' dual-quaternion method is left
#: out: it solves rotation and translation jointly, and the VSE translations have no scale yet.
HAND_EYE_METHODS = ("tsai", "park", "horaud", "andreff")
_CV_METHOD_NAMES = {
    "tsai": "CALIB_HAND_EYE_TSAI",
    "park": "CALIB_HAND_EYE_PARK",
    "horaud": "CALIB_HAND_EYE_HORAUD",
    "andreff": "CALIB_HAND_EYE_ANDREFF",
}
_RIGID_ATOL = 1e-4  # rotation blocks of incoming motions (float32 messages) are projected to SO(3) within this


@dataclass(frozen=True)
class InitializationConfig(Config):
    """Options of the hand–eye and real-scale initialization (paper §3.2, Eq. 4–8)."""

    method: str = param("tsai", description="OpenCV calibrateHandEye method for R_X (Eq. 4).", choices=HAND_EYE_METHODS)
    min_motions: int = param(2, description="Fewest motion pairs accepted (the paper: at least two).", min=2)
    min_rotation_deg: float = param(
        2.0, description="A motion whose hand rotates less than this counts as a pure translation, deg.", min=0.0
    )
    min_axis_separation_deg: float = param(
        5.0,
        description="At least two rotating motions must have rotation axes this far apart (else parallel axes), deg.",
        min=0.0,
        max=90.0,
    )
    max_angle_mismatch_deg: float = param(
        3.0,
        description="Camera and hand rotation angles of a motion may differ by at most this (Eq. 4 keeps angles), deg.",
        min=0.0,
    )
    min_axial_translation_m: float = param(
        1e-3,
        description="Eq. 8 uses a motion only if its hand translation along the rotation axis reaches this, m.",
        min=0.0,
    )
    max_rotation_residual_deg: float = param(
        2.0,
        description="Reject R_X whose RMS Eq. 4 residual over the motions exceeds this (a failed solve), deg.",
        min=0.0,
    )


@dataclass(frozen=True)
class HandEyeResult:
    """Outcome of :func:`initialize`: ``X = T_cam_hand`` and the real scale ``s`` (metres per VSE unit).

    Residuals over the motion pairs: ``rotation_residual_deg`` is the RMS angle of ``(R_X R_B)ᵀ R_A R_X`` (Eq. 4),
    ``translation_residual_m`` the RMS norm of ``s t_VSE + (R_A − I) t_X − R_X t_B`` (Eq. 5/6).
    ``motion_scales`` holds ``b_k / a_k`` of Eq. 8 per motion (NaN where a motion carries no scale).
    """

    T_cam_hand: Array
    scale_m_per_vse: float
    rotation_residual_deg: float
    translation_residual_m: float
    motion_scales: Array = field(repr=False)
    motions_used_for_scale: int


def _check_config(config: InitializationConfig | None) -> InitializationConfig:
    if config is None:
        return InitializationConfig()
    if not isinstance(config, InitializationConfig):
        raise InitializationError(f"config must be an InitializationConfig, got {type(config).__name__}")
    return config


def _motions(M: ArrayLike, name: str) -> Array:
    """Validate a stack of rigid motions ``(n, 4, 4)``; rotation blocks are projected onto SO(3)."""
    try:
        a = np.array(M, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InitializationError(f"{name} must be an array of 4x4 transforms: {exc}") from None
    if a.ndim == 2 and a.shape == (4, 4):
        a = a[None]
    if a.ndim != 3 or a.shape[1:] != (4, 4):
        raise InitializationError(f"{name} must have shape (n, 4, 4), got {a.shape}")
    if not np.all(np.isfinite(a)):
        bad = np.flatnonzero(~np.all(np.isfinite(a), axis=(1, 2)))
        raise InitializationError(f"{name} has non-finite entries (motions {bad.tolist()})")
    if not np.allclose(a[:, 3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise InitializationError(f"{name}: the bottom row of every transform must be [0, 0, 0, 1]")
    ok = np.atleast_1d(is_rotation(a[:, :3, :3], atol=_RIGID_ATOL))
    if not np.all(ok):
        bad_motions = np.flatnonzero(~ok).tolist()
        raise InitializationError(f"{name}: the rotation blocks of motions {bad_motions} are not rotations")
    a[:, :3, :3] = project_to_so3(a[:, :3, :3])
    return a


def _pair(cam_motions_vse: ArrayLike, hand_motions_m: ArrayLike, min_motions: int) -> tuple[Array, Array]:
    M_A = _motions(cam_motions_vse, "cam_motions_vse")
    M_B = _motions(hand_motions_m, "hand_motions_m")
    if len(M_A) != len(M_B):
        raise InitializationError(f"got {len(M_A)} camera motions but {len(M_B)} hand motions; they must pair up")
    if len(M_A) < min_motions:
        raise DegenerateMotionError(
            f"hand-eye calibration needs at least {min_motions} platform motions (paper §3.2), got {len(M_A)}"
        )
    return M_A, M_B


def _axis_angle(R: Array) -> tuple[Array, Array]:
    """Unit rotation axes ``(n, 3)`` (zero where the angle is 0) and angles in degrees ``(n,)``."""
    phi = so3_log(R)
    theta = np.linalg.norm(phi, axis=-1)
    axis = np.divide(phi, theta[..., None], out=np.zeros_like(phi), where=theta[..., None] > 0.0)
    return axis, np.degrees(theta)


def _rotating(R_A: Array, R_B: Array, config: InitializationConfig) -> NDArray[np.bool_]:
    """Motions that rotate enough for Eq. 4; checks Eq. 4's angle invariant and the axis spread."""
    axis_B, angle_B = _axis_angle(R_B)
    _, angle_A = _axis_angle(R_A)
    mismatch = np.abs(angle_A - angle_B)
    bad = np.flatnonzero(mismatch > config.max_angle_mismatch_deg)
    if bad.size:
        k = int(bad[np.argmax(mismatch[bad])])
        raise InitializationError(
            f"motion {k}: the camera rotates {angle_A[k]:.3f} deg but the hand {angle_B[k]:.3f} deg; "
            f"M_A X = X M_B keeps rotation angles, so these motions do not correspond "
            f"(max_angle_mismatch_deg={config.max_angle_mismatch_deg})"
        )
    rotating = angle_B >= config.min_rotation_deg
    if np.count_nonzero(rotating) < 2:
        raise DegenerateMotionError(
            f"only {int(np.count_nonzero(rotating))} of {len(R_B)} motions rotate by at least "
            f"{config.min_rotation_deg} deg (largest: {float(angle_B.max()):.3f} deg); pure translations do not "
            "determine the hand-eye rotation: give at least two motions with rotation about non-parallel axes"
        )
    axes = axis_B[rotating]
    cos = np.clip(np.abs(axes @ axes.T), 0.0, 1.0)
    spread_deg = float(np.degrees(np.arccos(cos.min())))
    if spread_deg < config.min_axis_separation_deg:
        raise DegenerateMotionError(
            f"the rotation axes of all rotating motions are parallel within {spread_deg:.3f} deg "
            f"(min_axis_separation_deg={config.min_axis_separation_deg}); R_X and t_X are then undetermined: "
            "rotate about at least two different axes"
        )
    return rotating


def hand_eye_rotation(
    cam_motions_vse: ArrayLike, hand_motions_m: ArrayLike, *, config: InitializationConfig | None = None
) -> Array:
    """``R_X = R_cam_hand`` (3×3) from paired motions by Eq. 4 with OpenCV ``calibrateHandEye``.

    ``cam_motions_vse`` ``(n, 4, 4)`` are ``M_A = T_cam_cam'`` (translation in any consistent unit: unused),
    ``hand_motions_m`` ``(n, 4, 4)`` are ``M_B = T_hand_hand'``. Only motions that rotate by at least
    ``min_rotation_deg`` are passed to OpenCV.
    """
    config = _check_config(config)
    M_A, M_B = _pair(cam_motions_vse, hand_motions_m, config.min_motions)
    rotating = _rotating(M_A[:, :3, :3], M_B[:, :3, :3], config)
    return _solve_rotation(M_A[rotating], M_B[rotating], config)


def _rotation_residuals_deg(M_A: Array, M_B: Array, R_X: Array) -> Array:
    """Angle of ``(R_X R_B)ᵀ R_A R_X`` per motion: the Eq. 4 residual, degrees."""
    R_lhs = M_A[:, :3, :3] @ R_X
    R_rhs = R_X @ M_B[:, :3, :3]
    return np.degrees(np.linalg.norm(so3_log(project_to_so3(np.swapaxes(R_rhs, 1, 2) @ R_lhs)), axis=-1))


def _solve_rotation(M_A: Array, M_B: Array, config: InitializationConfig) -> Array:
    """OpenCV's R_X, checked against Eq. 4 (OpenCV's solvers can fail without raising)."""
    R_X = _opencv_rotation(M_A, M_B, config.method)
    rms = float(np.sqrt(np.mean(_rotation_residuals_deg(M_A, M_B, R_X) ** 2)))
    if not rms <= config.max_rotation_residual_deg:
        hint = (
            " OpenCV 4.x's Tsai solver discards motions that rotate less than about 17 deg and then returns the "
            "identity: rotate more, or use method='horaud' or 'park'."
            if config.method == "tsai"
            else ""
        )
        raise DegenerateMotionError(
            f"OpenCV calibrateHandEye ({config.method}) found no R_X consistent with the motions (RMS Eq. 4 "
            f"residual {rms:.3f} deg > max_rotation_residual_deg={config.max_rotation_residual_deg}).{hint}"
        )
    return R_X


def _opencv_rotation(M_A: Array, M_B: Array, method: str) -> Array:
    if not hasattr(cv2, "calibrateHandEye"):
        raise InitializationError(
            f"OpenCV {cv2.__version__} has no calibrateHandEye (the 5.0 wheels lack it, opencv#29565); "
            "install opencv-python-headless<5"
        )
    eye = np.eye(4)
    T_base_gripper = [eye, *M_B]
    T_target_cam = [eye, *[_rigid_inverse(M) for M in M_A]]  # camera k' in the world of camera 0, inverted
    args: tuple[Any, Any, Any, Any] = (
        [T[:3, :3] for T in T_base_gripper],
        [T[:3, 3:4] for T in T_base_gripper],
        [T[:3, :3] for T in T_target_cam],
        [T[:3, 3:4] for T in T_target_cam],
    )
    try:
        R_hand_cam, _ = cv2.calibrateHandEye(*args, method=getattr(cv2, _CV_METHOD_NAMES[method]))
    except cv2.error as exc:
        raise InitializationError(f"OpenCV calibrateHandEye ({method}) failed: {exc}") from None
    R_hand_cam = np.asarray(R_hand_cam, dtype=np.float64)
    if R_hand_cam.shape != (3, 3) or not np.all(np.isfinite(R_hand_cam)):
        raise InitializationError(f"OpenCV calibrateHandEye ({method}) returned no rotation")
    return project_to_so3(R_hand_cam).T


def _rigid_inverse(T: Array) -> Array:
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def real_scale(
    cam_motions_vse: ArrayLike,
    hand_motions_m: ArrayLike,
    R_cam_hand: ArrayLike,
    *,
    config: InitializationConfig | None = None,
) -> tuple[float, Array]:
    """Real scale ``s`` (metres per VSE unit, ``t_A = s t_VSE``) by Eq. 8, and the per-motion ratios.

    For every motion that rotates by at least ``min_rotation_deg`` and whose hand translation has at least
    ``min_axial_translation_m`` along the rotation axis ``k`` of ``R_A``: ``a = kᵀt_VSE``, ``b = kᵀ R_X t_B``;
    ``s = Σ a b / Σ a²``. Returns ``(s, ratios)`` with ``ratios[k] = b/a`` (NaN for motions not used).
    """
    config = _check_config(config)
    M_A, M_B = _pair(cam_motions_vse, hand_motions_m, 1)
    R_X = _rotation(R_cam_hand, "R_cam_hand")
    axis_A, _ = _axis_angle(M_A[:, :3, :3])
    _, angle_B = _axis_angle(M_B[:, :3, :3])
    a = np.einsum("ij,ij->i", axis_A, M_A[:, :3, 3])
    b = np.einsum("ij,ij->i", axis_A, M_B[:, :3, 3] @ R_X.T)
    use = (angle_B >= config.min_rotation_deg) & (np.abs(b) >= config.min_axial_translation_m)
    if not np.any(use):
        raise DegenerateMotionError(
            "Eq. 8 needs a rotating motion whose hand translation has a component of at least "
            f"{config.min_axial_translation_m} m along its rotation axis (a screw motion); the largest is "
            f"{float(np.max(np.abs(b), initial=0.0)):.4g} m. Pure rotations and planar motions do not fix the scale"
        )
    denom = float(a[use] @ a[use])
    if not denom > 0.0:
        raise InitializationError(
            "the camera does not translate along the rotation axes although the hand does: the VSE motions do "
            "not match the platform motions"
        )
    s = float(a[use] @ b[use]) / denom
    ratios = np.full(len(M_A), np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios[use] = b[use] / a[use]
    if not (np.isfinite(s) and s > 0.0):
        raise InitializationError(
            f"Eq. 8 gives a non-positive scale s={s:.4g}: the camera translates against the hand along the rotation "
            "axes; check that both motion stacks use the same convention (M = T_old_new)"
        )
    return s, ratios


def _rotation(R: ArrayLike, name: str) -> Array:
    a = np.asarray(R, dtype=np.float64)
    if a.shape != (3, 3) or not np.all(np.isfinite(a)) or not is_rotation(a, atol=_RIGID_ATOL):
        raise InitializationError(f"{name} must be a finite 3x3 rotation matrix")
    return project_to_so3(a)


def hand_eye_translation(
    cam_motions_vse: ArrayLike, hand_motions_m: ArrayLike, R_cam_hand: ArrayLike, scale_m_per_vse: float
) -> Array:
    """``t_X = t_cam_hand`` (m) from Eq. 6, ``(R_A − I) t_X = R_X t_B − s t_VSE``, by linear least squares."""
    M_A, M_B = _pair(cam_motions_vse, hand_motions_m, 1)
    R_X = _rotation(R_cam_hand, "R_cam_hand")
    if not (np.isfinite(scale_m_per_vse) and scale_m_per_vse > 0.0):
        raise InitializationError(f"scale_m_per_vse must be positive and finite, got {scale_m_per_vse!r}")
    A = (M_A[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (M_B[:, :3, 3] @ R_X.T - scale_m_per_vse * M_A[:, :3, 3]).reshape(-1)
    sv = np.linalg.svd(A, compute_uv=False)
    if sv[-1] <= 1e-9 * max(sv[0], 1.0):
        raise DegenerateMotionError(
            "Eq. 6 does not determine t_X: the camera rotations share one axis (or none rotates); rotate about at "
            "least two different axes"
        )
    t_X, *_ = np.linalg.lstsq(A, rhs, rcond=None)
    return cast(Array, t_X)  # float64 in, float64 out


def initialize(
    cam_motions_vse: ArrayLike, hand_motions_m: ArrayLike, *, config: InitializationConfig | None = None
) -> HandEyeResult:
    """Initialization of §3.2: ``X = T_cam_hand`` and ``s`` from ≥ 2 paired motions.

    ``cam_motions_vse`` ``(n, 4, 4)``: camera motions ``M_A = T_cam_cam'`` from the VSE (translation in VSE
    units); ``hand_motions_m`` ``(n, 4, 4)``: the platform's hand motions ``M_B = T_hand_hand'`` (metres).
    Raises :class:`DegenerateMotionError` for motions that cannot determine X or s, :class:`InitializationError`
    for invalid or inconsistent input.
    """
    config = _check_config(config)
    M_A, M_B = _pair(cam_motions_vse, hand_motions_m, config.min_motions)
    rotating = _rotating(M_A[:, :3, :3], M_B[:, :3, :3], config)
    R_X = _solve_rotation(M_A[rotating], M_B[rotating], config)
    s, ratios = real_scale(M_A, M_B, R_X, config=config)
    t_X = hand_eye_translation(M_A, M_B, R_X, s)
    angles = _rotation_residuals_deg(M_A, M_B, R_X)
    trans_res = s * M_A[:, :3, 3] + (M_A[:, :3, :3] - np.eye(3)) @ t_X - M_B[:, :3, 3] @ R_X.T
    result = HandEyeResult(
        T_cam_hand=make_transform(R_X, t_X),
        scale_m_per_vse=s,
        rotation_residual_deg=float(np.sqrt(np.mean(angles**2))),
        translation_residual_m=float(np.sqrt(np.mean(np.sum(trans_res**2, axis=1)))),
        motion_scales=ratios,
        motions_used_for_scale=int(np.count_nonzero(np.isfinite(ratios))),
    )
    logger.debug(
        "hand-eye from %d motions (%s): s=%.6g, residuals %.3g deg / %.3g m",
        len(M_A),
        config.method,
        s,
        result.rotation_residual_deg,
        result.translation_residual_m,
    )
    return result


def relative_motions(T_world_body: ArrayLike) -> Array:
    """Consecutive motions ``T_k_k+1 = T_world_k⁻¹ T_world_k+1`` ``(n-1, 4, 4)`` of a pose sequence ``(n, 4, 4)``.

    Works for camera poses in VSE units and hand poses in metres alike (the translation unit is kept).
    """
    T = _motions(T_world_body, "T_world_body")
    if len(T) < 2:
        raise InitializationError("relative_motions needs at least two poses")
    R = T[:, :3, :3]
    out = np.zeros((len(T) - 1, 4, 4))
    out[:, :3, :3] = np.swapaxes(R[:-1], 1, 2) @ R[1:]
    out[:, :3, 3] = np.einsum("nji,nj->ni", R[:-1], T[1:, :3, 3] - T[:-1, :3, 3])
    out[:, 3, 3] = 1.0
    return out
