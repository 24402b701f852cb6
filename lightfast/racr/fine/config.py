"""Options of rACR's fine-grained alignment (paper §3.4.3, Eq. 11 and 16–18): :class:`FineAlignmentConfig`.

Distances are metres in the reference frame, intensities are in the keyframe images' units (the defaults assume
images in [0, 1]), pixel quantities are keyframe pixels. ``alpha`` is Eq. 11's α (0.2, the paper's §5.4);
``pose_tolerance`` / ``scale_tolerance`` are τ_T / τ_σ of the convergence test (the fast alignment's).
``refine_keyframes=False`` is the paper's ablation rACR-P, ``estimate_scale=False`` its rACR-S. ``racr_node``
exposes every field as a ``fine.*`` parameter (:mod:`lightfast.racr.node_config`).
"""
from __future__ import annotations

from dataclasses import dataclass

from lightfast.config import Config, ConfigError, param

__all__ = ["LM_METHODS", "SCALE_UPDATES", "FineAlignmentConfig"]

LM_METHODS = ("lm", "trf")
SCALE_UPDATES = ("alternate", "joint")


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
