"""Options and results of the direct RGB-D alignment of paper §III-D (Eq. 7).

:class:`TrackingConfig`: w_G of Eq. 7 (``geometric_weight``), the form of E_G, the image pyramid, the valid depth
range and outlier thresholds (m), the Huber thresholds (grey in [0, 1]; m), the Gauss–Newton budget and the
optional pose prior. :class:`AlignResult`: one alignment, ``T_target_source`` (4×4, metres) mapping source (live)
camera coordinates into target (reference) camera coordinates (REP-103 optical frames), with its convergence,
inlier ratio and cost. :class:`SequenceTrack`: chained f2f alignments as ``T_world_cam`` poses (m) with their times (s).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lightfast.config import Config, ConfigError, param

__all__ = ["GEOMETRIC_TERMS", "ROBUST_NORMS", "TRACKING_MODES", "AlignResult", "SequenceTrack", "TrackingConfig"]

#: Tracking variants of paper §IV: the proposed method and its baselines.
TRACKING_MODES = ("proposed", "refl-f2m", "depth-only", "no-color-f2m")
#: Forms of the geometric term E_G (see :mod:`lightfast.tracking.rgbd_odometry.kernels`).
GEOMETRIC_TERMS = ("point-to-plane", "depth-difference")
#: Robust norms of the residuals (see :mod:`lightfast.tracking.rgbd_odometry.kernels`).
ROBUST_NORMS = ("huber", "t-distribution")


@dataclass(frozen=True)
class TrackingConfig(Config):
    """Options of the direct RGB-D alignment of paper §III-D (Eq. 7)."""

    mode: str = param(
        "proposed",
        description="Tracking variant (paper §IV); align() only distinguishes depth-only (E_C off) from the rest.",
        choices=TRACKING_MODES,
    )
    geometric_weight: float = param(10.0, description="w_G of Eq. 7 (geometric vs photometric term).", min=0.0)
    geometric_term: str = param(
        "point-to-plane", description="Form of E_G: point-to-plane distance to the reference surface (KinectFusion "
        "[10], the paper's) or depth-difference along the reference ray (Kerl et al., DVO; Open3D's hybrid term).",
        choices=GEOMETRIC_TERMS,
    )
    robust_norm: str = param(
        "huber", description="Robust norm of both terms: Huber with the thresholds below, or Student's t with its "
        "scale fitted to each term's residuals at every Gauss-Newton step (Kerl et al., ICRA 2013); then w_G weighs "
        "the two normalised terms.", choices=ROBUST_NORMS,
    )
    t_dof: float = param(5.0, description="Degrees of freedom of the t-distribution (robust_norm t-distribution).",
                         min=0.5)
    pyramid_levels: int = param(3, description="Image pyramid levels (factor 2 each).", min=1, max=6)
    iterations: tuple[int, ...] = param(
        (10, 5, 3), description="Gauss-Newton iterations per pyramid level, coarse to fine.", min=1, max=200
    )
    resolution_scale: float = param(
        1.0, description="Input downscale before the pyramid (0.5: 640x480 -> 320x240).", choices=(1.0, 0.5)
    )
    min_depth_m: float = param(0.2, description="Live/reference depth below this is invalid, m.", min=0.0)
    max_depth_m: float = param(4.0, description="Live/reference depth above this is invalid, m.", min=0.01)
    depth_outlier_trunc_m: float = param(
        0.07, description="Associations whose depths differ by more are outliers (occlusion), m.", min=1e-4
    )
    depth_discontinuity_m: float = param(
        0.05, description="A 2x2 depth block spanning more than this is invalid one pyramid level up, m.", min=1e-4
    )
    intensity_huber_delta: float = param(
        0.1, description="Huber threshold of the photometric residual (grey in [0, 1]).", min=1e-6
    )
    geometric_huber_delta_m: float = param(
        0.02, description="Huber threshold of the point-to-plane residual, m.", min=1e-6
    )
    pose_prior_weight: float = param(
        0.0, description="Weight per associated pixel of a prior at the start pose of the alignment, per m^2 of "
        "translation and rad^2 of rotation, in the units of the Eq. 7 cost; 0 = off (Eq. 7 alone). A plain wall leaves "
        "directions the data does not constrain, where Gauss-Newton walks on noise.", min=0.0,
    )
    step_tolerance: float = param(
        1e-4, description="Stop a level when the update norm |xi| falls below this (1e-4: 0.1 mm / 0.006 deg).",
        min=0.0,
    )
    finest_level: int = param(
        0, description="Pyramid level where the alignment stops: 0 = full resolution, 1 = half, ...", min=0, max=5
    )
    finest_point_step: int = param(
        2, description="Source points at the finest level: every pixel (1), a checkerboard (2) or every second row "
        "and column (4); the reference keeps every pixel.", choices=(1, 2, 4)
    )
    min_inlier_ratio: float = param(
        0.2, description="Below this inlier ratio the result is flagged as not converged.", min=0.0, max=1.0
    )

    def check(self) -> None:
        if self.finest_level >= self.pyramid_levels:
            raise ConfigError(f"finest_level={self.finest_level} must be below pyramid_levels={self.pyramid_levels}")
        if len(self.iterations) != self.pyramid_levels:
            raise ConfigError(
                f"TrackingConfig.iterations has {len(self.iterations)} entries, expected pyramid_levels="
                f"{self.pyramid_levels} (coarse to fine)"
            )
        if self.max_depth_m <= self.min_depth_m:
            raise ConfigError(f"max_depth_m ({self.max_depth_m}) must exceed min_depth_m ({self.min_depth_m})")


@dataclass(frozen=True)
class AlignResult:
    """Outcome of :func:`align`.

    ``T_target_source`` maps source (live) camera coordinates to target (reference) camera coordinates.
    ``converged``: the finest level stopped on ``step_tolerance`` (or its iteration budget with a small last
    step) with enough inliers. ``iterations``: Gauss–Newton steps over all levels. ``inlier_ratio``: share of
    valid live-depth pixels at the finest level that are associated and inside the Huber threshold of their
    term(s). ``residual``: Eq. 7 cost per associated pixel (Huber norms, ``ρ_C + w_G ρ_G``). The last two are
    taken at the last linearisation of the finest level, i.e. before its final (converged, small) step.
    """

    T_target_source: NDArray[np.float64]
    converged: bool
    iterations: int
    inlier_ratio: float
    residual: float


@dataclass(frozen=True)
class SequenceTrack:
    """Frame-to-frame tracking of a sequence: ``poses[i]`` is ``T_world_cam`` of frame ``i`` (``poses[0]`` the
    given start pose), ``results[i-1]`` the alignment of frame ``i`` to its predecessor (None: frame ``i`` repeats
    its predecessor's depth image and was not aligned), ``seconds[i-1]`` its time (pyramid construction included)."""

    poses: NDArray[np.float64]
    results: tuple[AlignResult | None, ...]
    seconds: NDArray[np.float64]
