"""What ``/racr/status`` says (paper §3.6: the state of a relocalization run): one status from the session's
snapshot (:class:`~lightfast.racr.session.SessionStatus`), the reference, whether a platform listens, and the
latest problem; plus the thinned aligned cloud for display.

Levels follow the session (``ok``/``warn``/``error``); without a reference the stage is ``no_reference`` (ERROR);
without a platform listening to the hand motions the level is at least WARN (but after the run ended). Poses in
status values are ``"x y z qx qy qz qw"`` strings (:func:`pose7`), metres in the reference frame.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from lightfast.geometry import matrix_to_quat
from lightfast.racr.reference import ReferenceObservation
from lightfast.racr.session import SessionStatus
from lightfast.status import Level, Status

__all__ = ["LEVELS", "STAGE_NO_REFERENCE", "pose7", "racr_status", "session_values", "thin_cloud"]

STAGE_NO_REFERENCE = "no_reference"
LEVELS = {"ok": Level.OK, "warn": Level.WARN, "error": Level.ERROR}
#: Stages after which no platform is needed any more.
_ENDED = ("converged", "initialization_failed")


def pose7(T: NDArray[np.float64] | None) -> str:
    """``"x y z qx qy qz qw"`` of a transform (empty for None), for status values."""
    if T is None:
        return ""
    return " ".join(f"{v:.6g}" for v in (*T[:3, 3], *matrix_to_quat(T[:3, :3])))


def session_values(st: SessionStatus, reference: ReferenceObservation | None) -> dict[str, Any]:
    """The ``key: value`` pairs of a session snapshot: stage, initialization, scale, hand–eye, inputs, scheme."""
    he, sch, now = st.hand_eye, st.scheme, st.time_s
    values: dict[str, Any] = {
        "stage": st.stage,
        "reference_scene": "" if reference is None else reference.scene,
        "reference_points": 0 if reference is None else len(reference.points_m),
        "motions_issued": st.motions_issued,
        "init_motions_done": st.init_motions_done,
        "init_motions_total": st.init_motions_total,
        "init_error": st.init_error,
        "scale_m_per_vse": st.scale_m_per_vse,
        "hand_eye_rotation_residual_deg": None if he is None else he.rotation_residual_deg,
        "hand_eye_translation_residual_m": None if he is None else he.translation_residual_m,
        "T_cam_hand": pose7(st.T_cam_hand),
        "vse_poses": st.vse_poses,
        "vse_observations": st.vse_observations,
        "platform_stops": st.platform_stops,
        "vse_age_s": None if st.last_vse_stamp is None else now - st.last_vse_stamp,
        "platform_age_s": None if st.last_platform_stamp is None else now - st.last_platform_stamp,
        "converged": sch is not None and sch.converged,
    }
    if sch is not None:
        values.update({
            "g": sch.g, "sigma_p": sch.sigma, "estimate_kind": sch.estimate_kind, "adjustments": sch.adjustments,
            "observations": sch.observations, "dropped_observations": sch.dropped_observations,
            "fast_alignments": sch.fast_alignments, "fine_alignments": sch.fine_alignments,
            "alignment_failures": sch.alignment_failures, "last_alignment_error": sch.last_alignment_error,
            "T_ref_cur": pose7(sch.T_ref_cur),
        })
    return values


def racr_status(st: SessionStatus | None, *, reference: ReferenceObservation | None, reference_error: str | None,
                platform_subscribed: bool, motion_topic: str, values: dict[str, Any],
                problem: tuple[Level, str, str] | None = None) -> Status:
    """The status of a run: the session's (``st``; None: no reference yet, ``reference_error`` says why), raised
    to WARN while no platform subscribes to ``motion_topic``, and to ``problem`` (level, text, key) when that is
    at least as severe. ``values`` are the node's own pairs; the session's are added."""
    values = {**values, "platform_subscribed": platform_subscribed}
    if st is None:
        level, message = Level.ERROR, reference_error or "loading the reference"
        values["stage"] = STAGE_NO_REFERENCE
    else:
        level, message = LEVELS[st.level], st.message
        if not platform_subscribed and st.stage not in _ENDED:
            level, message = max(level, Level.WARN), f"no platform subscribes to {motion_topic}; {message}"
        values.update(session_values(st, reference))
    if problem is not None:
        p_level, p_text, key = problem
        values["problem"] = key
        if p_level >= level:
            level, message = p_level, p_text
    return Status(level, message, values)


def thin_cloud(points: NDArray[np.floating], intensity: NDArray[np.floating] | None,
               max_points: int) -> tuple[NDArray[np.floating], NDArray[np.floating] | None]:
    """At most ``max_points`` (> 0; 0: all) points spread evenly over the cloud, with their intensities."""
    if 0 < max_points < len(points):
        keep = np.linspace(0, len(points) - 1, max_points).astype(np.int64)
        return points[keep], None if intensity is None else intensity[keep]
    return points, intensity
