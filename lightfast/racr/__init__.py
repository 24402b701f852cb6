"""Active camera relocalization, rACR (paper: "Fast and robust active camera relocalization in the wild", §3).
ROS-free core, one module per step:

* :mod:`~lightfast.racr.initialization` — §3.2, Eq. 4–8: hand–eye ``X = T_cam_hand`` (OpenCV, Tsai) and the
  real scale ``s`` of a monocular VSE;
* :mod:`~lightfast.racr.fast_alignment` — §3.4.1–3.4.2, Eq. 9, 12–15: scale-aware point-cloud alignment
  (robust rigid ICP step alternating with the closed-form scale σ_p);
* :mod:`~lightfast.racr.fine` — §3.4.3, Eq. 10–11, 16–18: geometric + photometric (keyframe
  photo-consistency) refinement with keyframe-pose refinement and the self-occlusion rule (a subpackage:
  keyframes, objective, LM solves, outer loop);
* :mod:`~lightfast.racr.adjustment` — §3.1 and §3.5, Eq. 1–3: the hand motion ``M̂_B`` and the stop rule
  ``‖M̂_B − I₄‖_F ≤ η``;
* :mod:`~lightfast.racr.scheme` — §3.6: VSE input, the never-stopping alignment thread and the adjustment loop,
  parallel or serial (Table 5); :mod:`~lightfast.racr.alignment_job` — the alignment thread's unit of work;
* :mod:`~lightfast.racr.acr_baseline` — the ACR baseline (Tian et al. 2019) as the paper describes it: SIFT,
  5-point essential matrix, hand–eye taken as identity, translation scale by bisection.

Errors derive from :class:`~lightfast.racr.errors.RacrError`.
"""
from __future__ import annotations

from lightfast.racr.acr_baseline import (
    BISECTION_RULES,
    AcrBaseline,
    AcrConfig,
    AcrStep,
    RelativePose,
    relative_pose,
    sift_matches,
)
from lightfast.racr.adjustment import (
    AdjustmentConfig,
    AdjustmentStep,
    adjustment_step,
    camera_pose_in_reference,
    hand_motion,
    motion_gap,
)
from lightfast.racr.alignment_job import AlignmentJob
from lightfast.racr.errors import (
    AcrError,
    AdjustmentError,
    AlignmentError,
    DegenerateMotionError,
    InitializationError,
    RacrError,
    SchemeError,
)
from lightfast.racr.fast_alignment import (
    FastAlignmentConfig,
    FastAlignmentResult,
    ReferenceCloud,
    fast_align,
    fast_align_best,
)
from lightfast.racr.fine import (
    FineAlignmentConfig,
    FineAlignmentResult,
    Keyframe,
    fine_align,
    nearest_per_pixel,
)
from lightfast.racr.initialization import (
    HandEyeResult,
    InitializationConfig,
    hand_eye_rotation,
    hand_eye_translation,
    initialize,
    real_scale,
    relative_motions,
)
from lightfast.racr.scheme import SCHEME_MODES, SCHEME_STAGES, RacrScheme, SchemeConfig, SchemeStatus

__all__ = [
    "BISECTION_RULES",
    "SCHEME_MODES",
    "SCHEME_STAGES",
    "AcrBaseline",
    "AcrConfig",
    "AcrError",
    "AcrStep",
    "AdjustmentConfig",
    "AdjustmentError",
    "AdjustmentStep",
    "AlignmentError",
    "AlignmentJob",
    "DegenerateMotionError",
    "FastAlignmentConfig",
    "FastAlignmentResult",
    "FineAlignmentConfig",
    "FineAlignmentResult",
    "HandEyeResult",
    "InitializationConfig",
    "InitializationError",
    "Keyframe",
    "RacrError",
    "RacrScheme",
    "ReferenceCloud",
    "RelativePose",
    "SchemeConfig",
    "SchemeError",
    "SchemeStatus",
    "adjustment_step",
    "camera_pose_in_reference",
    "fast_align",
    "fast_align_best",
    "fine_align",
    "hand_eye_rotation",
    "hand_eye_translation",
    "hand_motion",
    "initialize",
    "motion_gap",
    "nearest_per_pixel",
    "real_scale",
    "relative_motions",
    "relative_pose",
    "sift_matches",
]
