"""Configuration of ``vtr_localizer_node`` (colour-constant stereo VT&R, paper §IV-B, IV-C): one frozen dataclass,
:class:`VtrLocalizerConfig`, from which the node's ROS parameters and ``config/vtr_localizer_node.yaml`` are
generated. It holds the phase (``mode``: teach or repeat), the map directory, the node's frames and queue, and the
core configurations as sections (dotted parameters, e.g. ``repeat.mode``, ``stereo.max_features``):
:class:`~lightfast.vtr.teach.TeachConfig` (``teach``), :class:`~lightfast.vtr.stereo_config.StereoConfig` (``stereo``;
teach only: a repeat uses the front-end options stored in the map, so that the features match),
:class:`~lightfast.vtr.visual_odometry.VisualOdometryConfig` (``vo``; teach and repeat) and
:class:`~lightfast.vtr.repeat_config.RepeatConfig` (``repeat``), each defaulting to the core's own defaults.

The sections are read-only while the node runs (changing them would restart a teach or a repeat); the node-level
options (queue, black-frame level, image publishing, VO drift for the covariance) may change.
"""
from __future__ import annotations

from dataclasses import dataclass

from lightfast.config import param
from lightfast.node_options import SensorInputOptions, StampOptions
from lightfast.vtr.repeat_config import RepeatConfig
from lightfast.vtr.stereo_config import StereoConfig
from lightfast.vtr.teach import TeachConfig
from lightfast.vtr.visual_odometry import VisualOdometryConfig

__all__ = ["PHASES", "VtrLocalizerConfig"]

#: What the node does with the stereo stream: build a map, or localize against one.
PHASES = ("teach", "repeat")
_TEACH, _STEREO, _VO, _REPEAT = TeachConfig(), StereoConfig(), VisualOdometryConfig(), RepeatConfig()


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
    # the core components, as sections -----------------------------------------------------------------------
    teach: TeachConfig = param(_TEACH, read_only=True, description="Teach: keyframe selection, the image sources "
                               "stored per keyframe and the front end's threads.")
    stereo: StereoConfig = param(_STEREO, read_only=True, description="Teach: the stereo front end (features, "
                                 "left-right matching); a repeat uses the map's.")
    vo: VisualOdometryConfig = param(_VO, read_only=True, description="Teach and repeat: the frame-to-frame "
                                     "greyscale stereo VO (matching, RANSAC, rejected motions).")
    repeat: RepeatConfig = param(_REPEAT, read_only=True, description="Repeat: localization against the map "
                                 "(mode fused, grey or mcmanus; windows, RANSAC, gates).")
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
