"""Options of the stereo front end of colour-constant VT&R (paper §IV-B, Fig. 3–4): :class:`StereoConfig`.

One frozen dataclass for the per-source stereo front end (:mod:`lightfast.vtr.stereo_front_end`): the feature type
and detector settings (:mod:`lightfast.vtr.features`), the left–right matching of a rectified pair — row search or
descriptor matching — with its epipolar and disparity constraints and the sub-pixel refinement
(:mod:`lightfast.vtr.stereo_matching`), and the depth range of the triangulated landmarks. Units: pixels of the
rectified images (disparity d = u_left − u_right), metres for depths.

Features: the paper uses SURF, which is non-free and absent from the pip OpenCV wheels. ORB is the default, for
speed (a stereo frame needs up to six extractions on 2 cores); SIFT stays selectable (``feature="sift"``) where
robustness to extreme lighting matters more than the frame rate — with SIFT prefer
``ColorConstantConfig(normalization="percentile")`` (see :mod:`lightfast.vtr.color_constant`).
:data:`FEATURE_CHOICE` says why in one sentence; the measurements are in ``docs/vtr.md`` and
``benchmarks/results/vtr_timelapse.md``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from lightfast.config import Config, ConfigError, param

__all__ = ["FEATURE_CHOICE", "FEATURE_TYPES", "STEREO_MATCHING", "StereoConfig"]

FEATURE_TYPES: Final = ("orb", "sift")
STEREO_MATCHING: Final = ("descriptor", "search")

#: Why the default feature type is ORB (measurements in docs/vtr.md).
FEATURE_CHOICE: Final = (
    "ORB: ~8x faster than SIFT here (18-23 ms vs 147-207 ms per image), needed for >= 10 Hz with six extractions "
    "per stereo frame on 2 cores; more correct matches across lighting over all time-lapse pairs, but SIFT is more "
    "robust on the largest lighting changes (greyscale: 5 % vs 28 % of pairs below 6 correct matches)."
)


@dataclass(frozen=True)
class StereoConfig(Config):
    """Options of the stereo front end (paper §IV-B, Fig. 3–4): features, left–right matching, triangulation."""

    feature: str = param("orb", description="Feature type (SURF is non-free in pip OpenCV).", choices=FEATURE_TYPES)
    max_features: int = param(1000, description="Features kept per image (strongest first).", min=10, max=100000)
    orb_fast_threshold: int = param(
        10, description="ORB FAST threshold, 8-bit levels (OpenCV default 20).", min=1, max=255
    )
    orb_levels: int = param(8, description="ORB pyramid levels.", min=1, max=16)
    orb_scale_factor: float = param(1.2, description="ORB pyramid scale factor.", min=1.01, max=2.0)
    sift_contrast_threshold: float = param(
        0.04, description="SIFT contrast threshold (OpenCV default 0.04).", min=0.0, max=1.0
    )
    mask_erosion_px: int = param(
        4, description="Invalid pixels (zero/saturated) are grown by this before detection, px.", min=0, max=64
    )
    min_disparity_px: float = param(0.5, description="Smallest admissible disparity u_l - u_r, px.", min=-1000.0)
    max_disparity_px: float = param(160.0, description="Largest admissible disparity u_l - u_r, px.", min=0.0)
    max_row_diff_px: float = param(
        1.5, description="Epipolar constraint: largest row difference of a match on rectified images, px.", min=0.0
    )
    ratio: float = param(
        0.8, description="Lowe ratio test: best / second-best admissible descriptor distance below this.", min=0.0,
        max=1.0,
    )
    mutual: bool = param(True, description="Keep only mutually nearest admissible left-right pairs.")
    stereo_matching: str = param(
        "search", description="Left-right matching: 'descriptor' detects features in the right image too and "
        "matches descriptors under the epipolar and disparity constraints; 'search' finds each left keypoint along "
        "its row of the right image by ZNCC block matching (no right-image detection).", choices=STEREO_MATCHING,
    )
    search_radius_px: int = param(
        4, description="'search': half size of the ZNCC patch, px.", min=1, max=15
    )
    search_min_zncc: float = param(
        0.8, description="'search': smallest ZNCC of an accepted left-right match.", min=-1.0, max=1.0
    )
    search_uniqueness: float = param(
        0.7, description="'search': (1 - best ZNCC) must be below this times (1 - best ZNCC more than 1 px away).",
        min=0.0, max=1.0,
    )
    orb_max_distance: float = param(
        64.0, description="ORB: largest Hamming distance of a left-right match (of 256 bits).", min=0.0
    )
    sift_max_distance: float = param(
        250.0, description="SIFT: largest Euclidean distance of a left-right match (descriptor norm ~512).", min=0.0
    )
    subpixel: bool = param(
        True, description="Refine disparities by 1-D block matching (parabola + Lucas-Kanade); drop failures."
    )
    subpixel_radius_px: int = param(3, description="Half size of the block-matching patch, px.", min=1, max=15)
    subpixel_search_px: int = param(
        4, description="Block matching searches round(d) +- this many pixels (ORB keypoints of coarse pyramid "
        "levels are off by a few px).", min=1, max=32
    )
    min_depth_m: float = param(0.1, description="Landmarks nearer than this are dropped, m.", min=0.0)
    max_depth_m: float = param(200.0, description="Landmarks farther than this are dropped, m.", min=0.0)

    @property
    def detects_right(self) -> bool:
        """Whether the left–right matching needs features of the right image (``"descriptor"``; not the search)."""
        return self.stereo_matching == "descriptor"

    def check(self) -> None:
        if self.max_disparity_px <= self.min_disparity_px:
            raise ConfigError(
                f"StereoConfig.max_disparity_px ({self.max_disparity_px}) must exceed min_disparity_px "
                f"({self.min_disparity_px})"
            )
        if self.max_depth_m <= self.min_depth_m:
            raise ConfigError(
                f"StereoConfig.max_depth_m ({self.max_depth_m}) must exceed min_depth_m ({self.min_depth_m})"
            )
