"""Direct RGB-D camera tracking: the joint photometric + geometric alignment of paper §III-D, Eq. 7.

The paper estimates each camera pose as

    T* = argmin_T  E_C(T) + w_G E_G(T)                                   (Eq. 7)

with E_C the dense photometric error of Steinbrücker et al. [8] and E_G the geometric (point-to-plane, projective
data association) error of KinectFusion [10], w_G = 10; the live depth image drives both the geometric term and
the projective data association. Tracking first aligns the live frame to the previous frame (f2f, gives T≈) and
then to a rendered reference colour + depth image (f2m) initialised with T≈.

Inputs: colour ``(H, W, 3)`` RGB (uint8, or float in [0, 1]) or ``(H, W)`` grey and depth ``(H, W)`` float metres,
in the REP-103 optical frame of one :class:`~lightfast.camera.PinholeCamera` (intrinsics in px). Output:
``T_target_source`` (4×4, metres) mapping source (live) camera coordinates into target (reference) ones.

Modules: :mod:`.config` (options, results), :mod:`.pyramid` (frame preparation), :mod:`.maps` (numba kernels of
the per-level maps), :mod:`.kernels` (residuals, Jacobians and normal equations of Eq. 7), :mod:`.solver`
(Gauss–Newton on SE(3), coarse to fine: :func:`align`, :func:`align_frames`, :func:`track_sequence`).

Units fix the meaning of w_G: with intensities in [0, 1] and residuals in metres, w_G = 10 weights a 1 cm
point-to-plane error (10·1e-4) like a 3 % intensity error (9e-4). The paper does not state its units; this is the
assumption made here. Why an own Gauss–Newton rather than Open3D's hybrid odometry, the depth-difference form of
E_G and the pose prior: docs/daylight.md, "Direct RGB-D tracking".
"""
from __future__ import annotations

from lightfast.tracking.rgbd_odometry.config import (
    GEOMETRIC_TERMS,
    TRACKING_MODES,
    AlignResult,
    SequenceTrack,
    TrackingConfig,
)
from lightfast.tracking.rgbd_odometry.pyramid import RGBDFrame, prepare_frame, repeated_images, repeated_input
from lightfast.tracking.rgbd_odometry.solver import (
    MOTION_PRIOR_MAX_GAP_S,
    MOTION_PRIORS,
    MotionPrior,
    align,
    align_frames,
    predict_motion,
    track_sequence,
    warm_up,
)

__all__ = [
    "GEOMETRIC_TERMS",
    "MOTION_PRIORS",
    "MOTION_PRIOR_MAX_GAP_S",
    "TRACKING_MODES",
    "AlignResult",
    "MotionPrior",
    "RGBDFrame",
    "SequenceTrack",
    "TrackingConfig",
    "align",
    "align_frames",
    "predict_motion",
    "prepare_frame",
    "repeated_images",
    "repeated_input",
    "track_sequence",
    "warm_up",
]

