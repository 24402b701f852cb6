"""Active camera relocalization, rACR (paper: "Fast and robust active camera relocalization in the wild", §3).
ROS-free core, one module per step:

* :mod:`~lightfast.racr.initialization` — §3.2, Eq. 4–8: hand–eye ``X = T_cam_hand`` (OpenCV, Tsai) and the
  real scale ``s`` of a monocular VSE;
* :mod:`~lightfast.racr.fast_alignment` — §3.4.1–3.4.2, Eq. 9, 12–15: scale-aware point-cloud alignment
  (robust rigid ICP step alternating with the closed-form scale σ_p);
* :mod:`~lightfast.racr.adjustment` — §3.1 and §3.5, Eq. 1–3: the hand motion ``M̂_B`` and the stop rule
  ``‖M̂_B − I₄‖_F ≤ η``.

Errors derive from :class:`~lightfast.racr.errors.RacrError`.
"""
from __future__ import annotations

from lightfast.racr.adjustment import (
    AdjustmentConfig,
    AdjustmentStep,
    adjustment_step,
    camera_pose_in_reference,
    hand_motion,
    motion_gap,
)
from lightfast.racr.errors import (
    AdjustmentError,
    AlignmentError,
    DegenerateMotionError,
    InitializationError,
    RacrError,
)
from lightfast.racr.fast_alignment import FastAlignmentConfig, FastAlignmentResult, ReferenceCloud, fast_align
from lightfast.racr.initialization import (
    HandEyeResult,
    InitializationConfig,
    hand_eye_rotation,
    hand_eye_translation,
    initialize,
    real_scale,
    relative_motions,
)

__all__ = [
    "AdjustmentConfig",
    "AdjustmentError",
    "AdjustmentStep",
    "AlignmentError",
    "DegenerateMotionError",
    "FastAlignmentConfig",
    "FastAlignmentResult",
    "HandEyeResult",
    "InitializationConfig",
    "InitializationError",
    "RacrError",
    "ReferenceCloud",
    "adjustment_step",
    "camera_pose_in_reference",
    "fast_align",
    "hand_eye_rotation",
    "hand_eye_translation",
    "hand_motion",
    "initialize",
    "motion_gap",
    "real_scale",
    "relative_motions",
]
