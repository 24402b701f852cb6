"""The self-check of one converged rACR run as the session drives it (issue 19; not in the paper, whose rACR stops
at g ≤ η, §3.5): :class:`SelfCheck` checks the final estimate with :func:`~lightfast.racr.verification.verify`
(and :func:`~lightfast.racr.verification.restart_fits` when the image cannot tell), and after a check failed by the
matches it gives the correction motion that puts the camera where they put it, then checks again once the motion
has stopped and a VSE observation taken after the stop has arrived, up to ``VerificationConfig.corrections`` times.

Poses: the final estimate ``(T_ref_cur, σ_p)`` of the scheme, the VSE scale ``s`` (m per VSE unit) and the
corrections so far ``δ`` place a VSE pose in the reference frame as ``δ · T_p ⟨R_A, σ_p s t_A⟩`` (Eq. 2–3).
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from lightfast.racr.adjustment import _hand_motion, camera_pose_in_reference
from lightfast.racr.errors import RacrError
from lightfast.racr.fast_alignment import FastAlignmentConfig, ReferenceCloud
from lightfast.racr.fine import Keyframe
from lightfast.racr.verification import ReferenceView, Verification, restart_fits, verify

__all__ = ["SelfCheck"]

logger = logging.getLogger(__name__)

Array = NDArray[np.float64]


@dataclass
class SelfCheck:
    """The check of one run's final estimate ``(T_ref_cur, sigma)`` (``scale``: m per VSE unit) against the
    reference ``view``; ``delta``: the corrections made so far, ``corrections`` their count, ``issued`` the stamp of
    the correction motion awaiting its stop, ``stop`` the stamp of that stop."""

    view: ReferenceView
    reference: ReferenceCloud
    fast_config: FastAlignmentConfig
    T_ref_cur: Array
    sigma: float
    scale: float
    delta: Array = field(default_factory=lambda: np.eye(4))
    corrections: int = 0
    issued: float | None = None
    stop: float | None = None

    def camera_in_reference(self, T_vse_cam: Array) -> Array:
        """A VSE pose (VSE units) in the reference frame by the final estimate and the corrections so far."""
        return self.delta @ camera_pose_in_reference(T_vse_cam, self.T_ref_cur, self.sigma * self.scale)

    def check(self, points_vse: Array, T_vse_cam: Array, keyframes: Sequence[Keyframe]) -> Verification:
        """The verdict on the estimate from an observation (cloud, camera pose and keyframes in VSE units)."""
        kfs = [(k.image, self.camera_in_reference(np.array(k.T_cur_cam)), k.camera) for k in keyframes]
        result = verify(self.view, kfs)
        if result.verdict != "ambiguous" or self.corrections > 0:
            return result  # after a correction the geometry's fit is not the estimate any more: it cannot tell
        # the image cannot tell (a strong lighting change): is the geometric fit the best around the estimate?
        try:
            restarts = restart_fits(points_vse * self.scale, self.reference, self.T_ref_cur, self.sigma,
                                    self.camera_in_reference(T_vse_cam), self.view, self.fast_config)
        except RacrError as exc:
            logger.info("restarts around the estimate failed: %s", exc)
            return result
        return replace(result, verdict=restarts.verdict, restarts=restarts)

    def correction(self, verification: Verification, T_vse_cam: Array, T_cam_hand: Array,
                   now: float) -> tuple[Array, Array] | None:
        """After a check: the correction motion ``(M_hand, T_ref_cam)`` (Eq. 3 from the pose the matches give) when
        the check failed with a correction and some are left (then a stop stamped at or after ``now`` is awaited),
        else None."""
        if verification.verdict != "failed" or verification.T_correction is None or \
                self.corrections >= self.view.config.corrections:
            return None
        T_ref_cam = verification.T_correction @ self.camera_in_reference(T_vse_cam)
        self.delta = verification.T_correction @ self.delta
        self.corrections += 1
        self.issued, self.stop = now, None
        return _hand_motion(T_ref_cam, self.view.T_ref_camref, T_cam_hand), T_ref_cam

    def stopped(self, stamp: float) -> None:
        """The platform reported a stop at ``stamp``: it ends the correction motion issued at or before it."""
        if self.issued is not None and stamp >= self.issued:
            self.issued, self.stop = None, stamp

    def ready(self, observation_stamp: float | None) -> bool:
        """The correction motion has stopped and an observation stamped after the stop has arrived."""
        return self.issued is None and self.stop is not None and observation_stamp is not None and \
            observation_stamp > self.stop

    def final(self, verification: Verification) -> Verification:
        """The verdict that ends the run, with the corrections made before it."""
        return replace(verification, corrections=self.corrections) if self.corrections else verification
