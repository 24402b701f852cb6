"""Colour-constant stereo visual teach & repeat (paper: "It's Not Easy Seeing Green", §III–IV). ROS-free.

* :mod:`lightfast.vtr.color_constant` — colour-constant images F = log R2 − α log R1 − β log R3 (§III Eq. 6–7,
  §IV-A Eq. 10–12): F_v, F_r, the constrained peak image, greyscale, and their 8-bit mapping;
* :mod:`lightfast.vtr.stereo` — the per-source stereo front end of §IV-B (Fig. 3–4): features, left–right matching
  on rectified images, triangulation from ``camera_info`` projection matrices.
"""
from __future__ import annotations

from lightfast.vtr.color_constant import (
    SOURCES,
    ColorConstantConfig,
    ColorConstantImage,
    SourceImage,
    color_constant,
    constrained_weights,
    fixed_range,
    greyscale,
    illuminant_exponent,
    image_sources,
    source_weights,
    temperature_beta,
    to_uint8,
)
from lightfast.vtr.errors import VtrError, VtrInputError
from lightfast.vtr.stereo import (
    FEATURE_CHOICE,
    FEATURE_TYPES,
    FeatureExtractor,
    Features,
    StereoConfig,
    StereoFeatures,
    StereoFrontEnd,
    check_projection,
    check_stereo_pair,
    descriptor_distances,
    match_descriptors,
    match_stereo,
    pair_distances,
    refine_disparity,
    stereo_candidates,
    triangulate,
)

__all__ = [
    "FEATURE_CHOICE",
    "FEATURE_TYPES",
    "SOURCES",
    "ColorConstantConfig",
    "ColorConstantImage",
    "FeatureExtractor",
    "Features",
    "SourceImage",
    "StereoConfig",
    "StereoFeatures",
    "StereoFrontEnd",
    "VtrError",
    "VtrInputError",
    "check_projection",
    "check_stereo_pair",
    "color_constant",
    "constrained_weights",
    "descriptor_distances",
    "fixed_range",
    "greyscale",
    "illuminant_exponent",
    "image_sources",
    "match_descriptors",
    "match_stereo",
    "pair_distances",
    "refine_disparity",
    "source_weights",
    "stereo_candidates",
    "temperature_beta",
    "to_uint8",
    "triangulate",
]
