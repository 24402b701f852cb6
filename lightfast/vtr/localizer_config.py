"""Configuration of ``vtr_localizer_node`` (colour-constant stereo VT&R, paper §IV-B, IV-C): one frozen dataclass,
:class:`VtrLocalizerConfig`, from which the node's ROS parameters and ``config/vtr_localizer_node.yaml`` are
generated. It combines the phase (``mode``: teach or repeat), the map directory, the localization mode of the
repeat (``repeat_mode``: fused, grey, mcmanus) and the relevant options of
:class:`~lightfast.vtr.teach.TeachConfig`, :class:`~lightfast.vtr.stereo.StereoConfig` (teach only: a repeat uses
the front-end options stored in the map) and :class:`~lightfast.vtr.repeat.RepeatConfig`; :meth:`teach_config`,
:meth:`stereo_config` and :meth:`repeat_config` build those. The other options of the core keep their defaults.

The pipeline options are read-only while the node runs (changing them would restart a teach or a repeat); the
node-level ones (queue, black-frame level, image publishing, VO drift for the covariance) may change.
"""
from __future__ import annotations

from dataclasses import dataclass

from lightfast.config import ConfigError, param
from lightfast.node_options import SensorInputOptions, StampOptions
from lightfast.vtr.color_constant import SOURCES
from lightfast.vtr.repeat import MODES, RepeatConfig
from lightfast.vtr.stereo import FEATURE_TYPES, STEREO_MATCHING, StereoConfig
from lightfast.vtr.teach import TeachConfig

__all__ = ["PHASES", "VtrLocalizerConfig"]

#: What the node does with the stereo stream: build a map, or localize against one.
PHASES = ("teach", "repeat")


@dataclass(frozen=True)
class VtrLocalizerConfig(SensorInputOptions, StampOptions):
    """Parameters of ``vtr_localizer_node`` (module docstring)."""

    mode: str = param("repeat", description="teach: build a map at map_path from the stereo stream (finish it with "
                      "the /vtr/finish_teach service); repeat: localize against the map at map_path.",
                      choices=PHASES, read_only=True)
    map_path: str = param("", description="Teach map directory (required): written atomically by a teach, read by "
                          "a repeat.", read_only=True)
    overwrite_map: bool = param(False, description="Teach: replace a map at map_path when the teach finishes (the "
                                "previous map stays untouched until then); false refuses to start over one.",
                                read_only=True)
    odom_frame: str = param("vtr_odom", description="Frame of the VO chain (/vtr/odometry, and the parent of the "
                            "left camera on /tf): the left camera of the first stereo pair.", read_only=True)
    keyframe_frame_prefix: str = param("vtr_keyframe_", description="Frame of a taught keyframe: this prefix and "
                                       "the keyframe's index (/vtr/localization's frame_id; on /tf a child of the "
                                       "left camera).", read_only=True)
    publish_tf: bool = param(True, description="Broadcast odom_frame -> left camera and left camera -> the "
                             "keyframe localized against, on /tf.", read_only=True)
    # teach ----------------------------------------------------------------------------------------------------
    keyframe_distance_m: float = param(1.0, description="Teach: a new keyframe when the camera has moved this far "
                                       "from the last keyframe, m.", min=0.01, max=1000.0, read_only=True)
    keyframe_angle_deg: float = param(10.0, description="Teach: a new keyframe when the camera has turned this much "
                                      "from the last keyframe, deg.", min=0.1, max=180.0, read_only=True)
    teach_sources: tuple[str, ...] = param(("grey", "fv", "fr"), description="Teach: image sources stored per "
                                           "keyframe (grey is needed for VO).", choices=SOURCES, read_only=True)
    feature: str = param("orb", description="Teach: feature type (a repeat uses the map's).", choices=FEATURE_TYPES,
                         read_only=True)
    max_features: int = param(1000, description="Teach: features kept per image, strongest first (a repeat uses the "
                              "map's).", min=10, max=100000, read_only=True)
    orb_levels: int = param(8, description="Teach: ORB pyramid levels (a repeat uses the map's).", min=1, max=16,
                            read_only=True)
    max_disparity_px: float = param(160.0, description="Teach: largest admissible stereo disparity, px (a repeat "
                                    "uses the map's).", min=1.0, max=10000.0, read_only=True)
    stereo_matching: str = param("search", description="Teach: left-right matching, descriptor (features "
                                 "detected in both images) or search (ZNCC along the row of the right image; a "
                                 "repeat uses the map's).", choices=STEREO_MATCHING, read_only=True)
    # repeat ---------------------------------------------------------------------------------------------------
    repeat_mode: str = param("fused", description="Repeat: localization by fused sources (paper), grey (legacy) or "
                             "mcmanus (colour-constant only when grey fails).", choices=MODES, read_only=True)
    window_radius: int = param(2, description="Repeat: keyframes on each side of the nearest one in the "
                               "localization window.", min=0, max=50, read_only=True)
    search_window_radius: int = param(2, description="Repeat: keyframes on each side of every candidate in the "
                                      "whole-map search (0: each keyframe alone).", min=0, max=50, read_only=True)
    min_inliers: int = param(6, description="Repeat: fewest inliers for a successful localization (paper: 6).",
                             min=4, max=10000, read_only=True)
    max_distance_on_vo_m: float = param(20.0, description="Repeat: distance on VO alone after which a localization "
                                        "failure is declared and the whole map searched (paper: 20 m), m.",
                                        min=0.0, max=100000.0, read_only=True)
    match_radius_px: float = param(40.0, description="Repeat: guided map matching radius under the VO prior, px "
                                   "(0: unguided).", min=0.0, max=10000.0, read_only=True)
    match_ratio: float = param(0.9, description="Repeat: Lowe ratio test of keyframe-to-frame matches.", min=0.0,
                               max=1.0, read_only=True)
    ransac_threshold_px: float = param(3.0, description="Repeat: RANSAC inlier threshold on the stereo reprojection "
                                       "error, px.", min=0.1, max=100.0, read_only=True)
    max_position_std_m: float = param(0.5, description="Repeat: a localization needs its camera position "
                                      "constrained to this standard deviation, m.", min=0.0, max=1000.0,
                                      read_only=True)
    prior_gate_m: float = param(0.5, description="Repeat: a windowed localization farther than prior_gate_m + "
                                "prior_gate_per_m * (distance on VO) from the VO prior is rejected, m (0: no gate).",
                                min=0.0, max=1000.0, read_only=True)
    prior_gate_per_m: float = param(0.1, description="Repeat: growth of the prior gate per metre on VO alone, m/m.",
                                    min=0.0, max=10.0, read_only=True)
    initial_keyframe: int = param(-1, description="Repeat: keyframe where the repeat starts (-1: search the whole "
                                  "map for the first localization).", min=-1, read_only=True)
    # both -----------------------------------------------------------------------------------------------------
    workers: int = param(1, description="Threads of the stereo front end (one image source per thread).", min=1,
                         max=8, read_only=True)
    # node -----------------------------------------------------------------------------------------------------
    max_queued_frames: int = param(4, description="Stereo pairs waiting for processing; beyond this the oldest is "
                                   "dropped and counted (raise it for a teach from a bag played fast).", min=1,
                                   max=10000)
    black_level: float = param(4.0, description="A stereo pair whose left or right image has a mean below this "
                               "(8-bit levels) is a black frame: reported and skipped.", min=0.0, max=255.0)
    publish_images: bool = param(True, description="Publish the colour-constant images F_v and F_r of the left "
                                 "camera (computed only while someone subscribes).")
    map_retry_s: float = param(2.0, description="Repeat: while the map cannot be loaded (missing, corrupt), retry "
                               "this often, s.", min=0.05, max=3600.0)
    vo_drift_m_per_m: float = param(0.05, description="Covariance of a repeat pose from VO alone: assumed position "
                                    "drift (1 sigma) per metre on VO since the last localization, m/m.", min=0.0,
                                    max=10.0)
    vo_drift_deg_per_m: float = param(0.5, description="Covariance of a repeat pose from VO alone: assumed heading "
                                      "drift (1 sigma) per metre on VO since the last localization, deg/m.", min=0.0,
                                      max=90.0)

    def check(self) -> None:
        for build in (self.teach_config, self.stereo_config, self.repeat_config):
            try:
                build()
            except ConfigError as exc:
                raise ConfigError(f"VtrLocalizerConfig: {exc}") from None

    def teach_config(self) -> TeachConfig:
        return TeachConfig(keyframe_distance_m=self.keyframe_distance_m, keyframe_angle_deg=self.keyframe_angle_deg,
                           sources=self.teach_sources, workers=self.workers)

    def stereo_config(self) -> StereoConfig:
        """The front end of a teach (a repeat takes the map's, so that the features match)."""
        return StereoConfig(feature=self.feature, max_features=self.max_features, orb_levels=self.orb_levels,
                            max_disparity_px=self.max_disparity_px, stereo_matching=self.stereo_matching)

    def repeat_config(self) -> RepeatConfig:
        return RepeatConfig(
            mode=self.repeat_mode, window_radius=self.window_radius, min_inliers=self.min_inliers,
            search_window_radius=self.search_window_radius,
            max_distance_on_vo_m=self.max_distance_on_vo_m, match_radius_px=self.match_radius_px,
            ratio=self.match_ratio,
            ransac_threshold_px=self.ransac_threshold_px, max_position_std_m=self.max_position_std_m,
            prior_gate_m=self.prior_gate_m, prior_gate_per_m=self.prior_gate_per_m,
            initial_keyframe=self.initial_keyframe, workers=self.workers,
        )
