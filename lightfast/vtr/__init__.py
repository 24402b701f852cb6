"""Colour-constant stereo visual teach & repeat (paper: "It's Not Easy Seeing Green", §III–IV). ROS-free.

* :mod:`lightfast.vtr.color_constant` — colour-constant images F = log R2 − α log R1 − β log R3 (§III Eq. 6–7,
  §IV-A Eq. 10–12): F_v, F_r, the constrained peak image, greyscale, and their 8-bit mapping;
* :mod:`lightfast.vtr.stereo` — the per-source stereo front end of §IV-B (Fig. 3–4): features, left–right matching
  on rectified images, triangulation from ``camera_info`` projection matrices;
* :mod:`lightfast.vtr.visual_odometry` — greyscale stereo VO and the pose solver shared with localization (§IV-B,
  Fig. 3): guided matching, 3-point RANSAC scored by stereo reprojection, Levenberg–Marquardt refinement;
* :mod:`lightfast.vtr.map_store` — the teach map (keyframes with the landmarks of every source, VO edges) and its
  versioned, atomically written map directory;
* :mod:`lightfast.vtr.teach` — the teach phase (§IV-B): :class:`TeachPipeline`;
* :mod:`lightfast.vtr.repeat` — the repeat phase (§IV-B, IV-C): VO, windowed localization with fused sources,
  failure after 20 m on VO and whole-map search; modes ``fused``, ``grey``, ``mcmanus``: :class:`RepeatPipeline`;
* :mod:`lightfast.vtr.localizer_config` — the parameters of ``vtr_localizer_node``: :class:`VtrLocalizerConfig`.
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
from lightfast.vtr.errors import (
    MapCorruptError,
    MapError,
    MapExistsError,
    MapNotFoundError,
    MapVersionError,
    VtrError,
    VtrInputError,
    VtrStateError,
)
from lightfast.vtr.localizer_config import PHASES, VtrLocalizerConfig
from lightfast.vtr.map_store import MAP_FORMAT, MAP_VERSION, Edge, Keyframe, Landmarks, MapStore, MapWriter, TeachMap
from lightfast.vtr.repeat import MODES, Localization, MapLocalizer, RepeatConfig, RepeatPipeline, RepeatResult
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
    search_stereo,
    stereo_candidates,
    triangulate,
)
from lightfast.vtr.teach import SourceFrontEnd, TeachConfig, TeachPipeline, TeachResult
from lightfast.vtr.visual_odometry import (
    PoseEstimate,
    StereoCamera,
    VisualOdometry,
    VisualOdometryConfig,
    VoResult,
    estimate_pose_stereo,
    match_landmarks,
    refine_pose_stereo,
)

__all__ = [
    "FEATURE_CHOICE",
    "FEATURE_TYPES",
    "MAP_FORMAT",
    "MAP_VERSION",
    "MODES",
    "PHASES",
    "SOURCES",
    "ColorConstantConfig",
    "ColorConstantImage",
    "Edge",
    "FeatureExtractor",
    "Features",
    "Keyframe",
    "Landmarks",
    "Localization",
    "MapCorruptError",
    "MapError",
    "MapExistsError",
    "MapLocalizer",
    "MapNotFoundError",
    "MapStore",
    "MapVersionError",
    "MapWriter",
    "PoseEstimate",
    "RepeatConfig",
    "RepeatPipeline",
    "RepeatResult",
    "SourceFrontEnd",
    "SourceImage",
    "StereoCamera",
    "StereoConfig",
    "StereoFeatures",
    "StereoFrontEnd",
    "TeachConfig",
    "TeachMap",
    "TeachPipeline",
    "TeachResult",
    "VisualOdometry",
    "VisualOdometryConfig",
    "VoResult",
    "VtrError",
    "VtrInputError",
    "VtrLocalizerConfig",
    "VtrStateError",
    "check_projection",
    "check_stereo_pair",
    "color_constant",
    "constrained_weights",
    "descriptor_distances",
    "estimate_pose_stereo",
    "fixed_range",
    "greyscale",
    "illuminant_exponent",
    "image_sources",
    "match_descriptors",
    "match_landmarks",
    "match_stereo",
    "pair_distances",
    "refine_disparity",
    "refine_pose_stereo",
    "search_stereo",
    "source_weights",
    "stereo_candidates",
    "temperature_beta",
    "to_uint8",
    "triangulate",
]
