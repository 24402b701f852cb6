"""Camera tracking (paper §III-D): direct RGB-D alignment (Eq. 7) and trajectory metrics. ROS-free."""
from __future__ import annotations

from lightfast.tracking.errors import TrackingError
from lightfast.tracking.metrics import OwnErrors, align_umeyama, ate_rmse, motion_rmse, own_errors
from lightfast.tracking.rgbd_odometry import (
    AlignResult,
    RGBDFrame,
    SequenceTrack,
    TrackingConfig,
    align,
    align_frames,
    prepare_frame,
    repeated_images,
    repeated_input,
    track_sequence,
)

__all__ = [
    "AlignResult",
    "OwnErrors",
    "RGBDFrame",
    "SequenceTrack",
    "TrackingConfig",
    "TrackingError",
    "align",
    "align_frames",
    "align_umeyama",
    "ate_rmse",
    "motion_rmse",
    "own_errors",
    "prepare_frame",
    "repeated_images",
    "repeated_input",
    "track_sequence",
]
