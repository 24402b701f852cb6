"""Colour-constant stereo visual teach & repeat (paper: "It's Not Easy Seeing Green", §III–IV). ROS-free.

* :mod:`~lightfast.vtr.color_constant` — colour-constant images F = log R2 − α log R1 − β log R3 (§III Eq. 6–7,
  §IV-A Eq. 10–12): F_v, F_r, the constrained peak image, greyscale, and their 8-bit mapping;
* the per-source stereo front end of §IV-B (Fig. 3–4): :mod:`~lightfast.vtr.stereo_config` (its options),
  :mod:`~lightfast.vtr.features` (keypoints, stereo landmarks, detection), :mod:`~lightfast.vtr.descriptor_matching`
  (descriptor distances, nearest-neighbour matching), :mod:`~lightfast.vtr.stereo_matching` (left–right row search
  or descriptor matching, sub-pixel disparities), :mod:`~lightfast.vtr.stereo_front_end` (triangulation from
  ``camera_info`` projection matrices, :class:`StereoFrontEnd`);
* the pose pipeline shared by VO and localization (§IV-B, Fig. 3): :mod:`~lightfast.vtr.landmark_matching` (guided
  matching), :mod:`~lightfast.vtr.pose_estimation` (3-point RANSAC scored by stereo reprojection,
  Levenberg–Marquardt refinement), :mod:`~lightfast.vtr.visual_odometry` (greyscale frame-to-frame VO);
* :mod:`~lightfast.vtr.map_store` — the teach map (keyframes with the landmarks of every source, VO edges) and its
  versioned, atomically written map directory;
* :mod:`~lightfast.vtr.teach` — the teach phase (§IV-B): :class:`TeachPipeline`;
* the repeat phase (§IV-B, IV-C): :mod:`~lightfast.vtr.repeat_config` (options, modes ``fused``, ``grey``,
  ``mcmanus``), :mod:`~lightfast.vtr.localization` (windowed localization with fused sources),
  :mod:`~lightfast.vtr.map_search` (whole-map search), :mod:`~lightfast.vtr.repeat` (:class:`RepeatPipeline`: VO,
  localization, failure after 20 m on VO);
* :mod:`~lightfast.vtr.localizer_config` — the parameters of ``vtr_localizer_node``: :class:`VtrLocalizerConfig`.
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
from lightfast.vtr.descriptor_matching import descriptor_distances, match_descriptors, pair_distances
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
from lightfast.vtr.features import FeatureExtractor, Features, StereoFeatures
from lightfast.vtr.landmark_matching import match_landmarks
from lightfast.vtr.localization import Localization, MapLocalizer
from lightfast.vtr.localizer_config import PHASES, VtrLocalizerConfig
from lightfast.vtr.map_store import MAP_FORMAT, MAP_VERSION, Edge, Keyframe, Landmarks, MapStore, MapWriter, TeachMap
from lightfast.vtr.pose_estimation import (
    PoseEstimate,
    PriorSupport,
    StereoCamera,
    estimate_pose_stereo,
    refine_pose_stereo,
)
from lightfast.vtr.repeat import RepeatPipeline, RepeatResult
from lightfast.vtr.repeat_config import MODES, RepeatConfig
from lightfast.vtr.stereo_config import FEATURE_CHOICE, FEATURE_TYPES, StereoConfig
from lightfast.vtr.stereo_front_end import StereoFrontEnd, check_projection, check_stereo_pair, triangulate
from lightfast.vtr.stereo_matching import match_stereo, refine_disparity, search_stereo, stereo_candidates
from lightfast.vtr.teach import SourceFrontEnd, TeachConfig, TeachPipeline, TeachResult
from lightfast.vtr.visual_odometry import VisualOdometry, VisualOdometryConfig, VoResult

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
    "PriorSupport",
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
