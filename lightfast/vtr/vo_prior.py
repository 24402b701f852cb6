"""The VO prior of a localization: paper §IV-B ("The VO estimate is fed to the localizer as a prior").

The repeat keeps a belief of the camera pose in its reference keyframe's frame — the pose ``T_ref_cam`` and a 6×6
covariance of ``ξ = (ρ, φ)`` in ``T_ref_cam · exp(ξ)`` (camera frame, m and rad, the convention of
:class:`~lightfast.vtr.localization.Localization`). Between localizations the VO motion ``M = T_prev_cur`` carries
it: ``ξ_cur = Ad(M⁻¹) ξ_prev`` plus VO noise growing with the distance driven and the step's own (scaled) covariance
(:func:`propagate_covariance`: a step resting on far landmarks is uncertain along the optical axis); a
change of reference keyframe adds the uncertainty of a teach edge (:func:`add_keyframe_noise`). An accepted windowed
localization is then fused with the prior in information form (:func:`fuse`, one Gauss–Newton step of the two
quadratic terms), instead of replacing it: a localization resting on far landmarks constrains the camera's position
along its optical axis poorly, and the prior holds what the image cannot (measured on the development route:
``docs/vtr.md``). The localization's covariance is its nominal one (1 px noise) times ``cov_scale²``: the nominal
covariance ignores landmark depth noise and the window's chained teach edges and is far too small.
A windowed localization is accepted only where :class:`PriorGate` admits it: near the prior's position, or within
some standard deviations of the prior's and the localization's position uncertainty together (an innovation gate).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lightfast.geometry import hat, inverse, se3_exp, se3_log

__all__ = ["PriorGate", "add_keyframe_noise", "adjoint", "fuse", "mahalanobis_sq", "propagate_covariance"]

Array = NDArray[np.float64]


def adjoint(T: Array) -> Array:
    """Adjoint of a rigid transform acting on twists ``(ρ, φ)``: ``T exp(ξ) T⁻¹ = exp(Ad(T) ξ)``."""
    R = T[:3, :3]
    A = np.zeros((6, 6))
    A[:3, :3] = R
    A[:3, 3:] = hat(T[:3, 3]) @ R
    A[3:, 3:] = R
    return A


def _diagonal(position_std_m: float, rotation_std_rad: float) -> Array:
    return np.diag([position_std_m**2] * 3 + [rotation_std_rad**2] * 3)


def propagate_covariance(P: Array, T_prev_cur: Array, step_m: float, position_noise_per_m: float,
                         rotation_noise_deg_per_m: float, step_covariance: Array | None = None) -> Array:
    """The covariance of ``T_ref_cur = T_ref_prev · T_prev_cur`` from that of ``T_ref_prev``, with VO noise of
    ``position_noise_per_m`` m and ``rotation_noise_deg_per_m`` degrees (standard deviations) per metre driven, plus
    the VO step's own covariance ``step_covariance`` (of ξ in ``T_prev_cur · exp(ξ)``) when given and finite."""
    A = adjoint(inverse(T_prev_cur))
    Q = _diagonal(position_noise_per_m * step_m, math.radians(rotation_noise_deg_per_m) * step_m)
    if step_covariance is not None and np.all(np.isfinite(step_covariance)):
        Q = Q + 0.5 * (step_covariance + step_covariance.T)
    return A @ P @ A.T + Q


def mahalanobis_sq(offset: Array, cov: Array | None) -> float | None:
    """Squared Mahalanobis distance ``offsetᵀ cov⁻¹ offset``; None without a usable covariance (missing, not finite
    or singular)."""
    if cov is None or not np.all(np.isfinite(cov)):
        return None
    try:
        return float(offset @ np.linalg.solve(cov, offset))
    except np.linalg.LinAlgError:
        return None


def add_keyframe_noise(P: Array, position_std_m: float, rotation_std_deg: float) -> Array:
    """``P`` re-expressed in another keyframe's frame through one teach edge of the given uncertainty."""
    return P + _diagonal(position_std_m, math.radians(rotation_std_deg))


def fuse(T_loc: Array, C_loc: Array, T_prior: Array, P_prior: Array) -> tuple[Array, Array]:
    """The localization ``(T_loc, C_loc)`` fused with the prior ``(T_prior, P_prior)`` (same frame):
    ``(T, C)`` minimizing ``‖ξ‖²_{C_loc} + ‖ξ − δ‖²_{P_prior}`` with ``T_prior = T_loc · exp(δ)``,
    ``T = T_loc · exp(ξ)``. Returns the localization unchanged if either covariance is not finite and positive
    definite."""
    try:
        info_loc, info_prior = np.linalg.inv(C_loc), np.linalg.inv(P_prior)
        C = np.linalg.inv(info_loc + info_prior)
    except np.linalg.LinAlgError:
        return T_loc, C_loc
    if not (np.all(np.isfinite(C)) and np.all(np.linalg.eigvalsh(0.5 * (C + C.T)) > 0.0)):
        return T_loc, C_loc
    xi = C @ info_prior @ se3_log(inverse(T_loc) @ T_prior)
    return T_loc @ se3_exp(xi), C


@dataclass(frozen=True)
class PriorGate:
    """Where a windowed localization may put the camera relative to its VO prior: within ``radius_m`` of the prior's
    position, or within ``sigmas`` standard deviations of the prior's own position uncertainty ``position_cov``
    (3×3, m², in the reference keyframe's frame; a Mahalanobis distance; with ``measurement_cov_scale`` the
    localization's own uncertainty is added): a VO step resting on far points is uncertain along the optical axis,
    and the localization that mends it lies there."""

    radius_m: float = math.inf
    position_cov: NDArray[np.float64] | None = None
    sigmas: float = 0.0
    #: fewest inliers of a localization admitted by the Mahalanobis test (beyond ``radius_m``)
    min_inliers_beyond_radius: int = 0
    #: > 0: the Mahalanobis test adds the localization's own position covariance × this² to ``position_cov`` (the
    #: innovation covariance of a Kalman filter's validation gate, Bar-Shalom & Fortmann 1988)
    measurement_cov_scale: float = 0.0

    def admits(self, offset_m: NDArray[np.float64], inliers: int | None = None,
               measurement_cov: NDArray[np.float64] | None = None) -> bool:
        """Whether a localization ``offset_m`` (3,) from the prior's position, with ``inliers`` and its own position
        covariance ``measurement_cov`` (3×3, m², nominal; read with ``measurement_cov_scale`` > 0), passes."""
        if float(np.linalg.norm(offset_m)) <= self.radius_m:
            return True
        if self.sigmas <= 0.0 or (inliers is not None and inliers < self.min_inliers_beyond_radius):
            return False
        cov = self.position_cov
        if cov is not None and measurement_cov is not None and self.measurement_cov_scale > 0.0:
            cov = cov + self.measurement_cov_scale**2 * measurement_cov
        d2 = mahalanobis_sq(offset_m, cov)
        return d2 is not None and d2 <= self.sigmas**2
