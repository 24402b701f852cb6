"""Frame-to-frame stereo visual odometry on greyscale: paper §IV-B ("VO is performed using only the greyscale
images"; Fig. 3, where "the live view is compared to the most recent view, instead of the map").

:class:`VisualOdometry` takes the current frame's grey :class:`~lightfast.vtr.features.StereoFeatures` and the
:class:`~lightfast.vtr.pose_estimation.StereoCamera`; the previous frame's landmarks are the reference. The
constant-velocity prediction (the last successful motion) primes guided matching
(:func:`~lightfast.vtr.landmark_matching.match_landmarks` within ``match_radius_px``); unguided matching is the
fallback when the guided attempt finds fewer than ``min_inliers`` inliers. The motion comes from
:func:`~lightfast.vtr.pose_estimation.estimate_pose_stereo` (3-point RANSAC and Levenberg–Marquardt on the stereo
reprojection error); a motion longer than ``max_translation_m`` is rejected, and so is one whose translation differs
from the last successful motion's by more than ``max_step_change_m`` (a robot's velocity hardly changes between
frames; weak steps at dusk resting on a wrong consensus came out 3.5 m long or 0.5 m backwards between 0.8 m
ones). Most landmarks of an outdoor frame are far and fit nearly any translation, so the RANSAC draws all
``ransac_min_iterations`` hypotheses, half of them from the nearest landmarks first, and refines the
``ransac_refine_top`` best (``docs/vtr.md``, "The VO's RANSAC").

Output per frame: :class:`VoResult` — ``T_prev_cur`` (4×4, current left camera frame → previous one; metres, REP-103
optical axes), matches, inliers, the inliers' RMS reprojection error (px), the motion's nominal covariance (1 px
noise) and success; on a failure ``T_prev_cur`` is the constant-velocity prediction, on the first frame the identity.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.config import Config, param
from lightfast.vtr.errors import VtrInputError
from lightfast.vtr.features import StereoFeatures
from lightfast.vtr.landmark_matching import match_landmarks, max_descriptor_distance
from lightfast.vtr.pose_estimation import StereoCamera, estimate_pose_stereo

__all__ = ["VisualOdometry", "VisualOdometryConfig", "VoResult"]

log = logging.getLogger(__name__)

#: frames after which the last successful motion is too old to be the reference of ``max_step_change_m`` (the check is
#: then off, so that a wrong reference cannot lock the VO out)
STALE_FRAMES = 5


@dataclass(frozen=True)
class VisualOdometryConfig(Config):
    """Options of the frame-to-frame greyscale stereo VO (paper §IV-B, Fig. 3)."""

    ratio: float = param(0.8, description="Lowe ratio test of frame-to-frame descriptor matches.", min=0.0, max=1.0)
    mutual: bool = param(True, description="Keep only mutually nearest frame-to-frame matches.")
    orb_max_distance: float = param(
        80.0, description="ORB: largest Hamming distance of a frame-to-frame match (of 256 bits).", min=0.0
    )
    sift_max_distance: float = param(
        300.0, description="SIFT: largest Euclidean distance of a frame-to-frame match.", min=0.0
    )
    match_radius_px: float = param(
        40.0, description="Guided matching: the previous landmark, moved by the constant-velocity prediction, must "
        "project within this of the current keypoint, px (0: unguided only).", min=0.0
    )
    ransac_threshold_px: float = param(
        2.0, description="RANSAC inlier threshold on the stereo reprojection error (u, v, disparity), px.", min=0.1,
        max=100.0,
    )
    ransac_iterations: int = param(500, description="Most RANSAC hypotheses.", min=10, max=100000)
    ransac_confidence: float = param(0.999, description="RANSAC confidence (adaptive stop).", min=0.5, max=0.999999)
    ransac_min_iterations: int = param(
        500, description="Fewest RANSAC hypotheses before the adaptive stop (an all-inlier triple of far points is "
        "no good hypothesis, so the stop's assumption fails).", min=0, max=100000
    )
    ransac_near_first_fraction: float = param(
        0.5, description="Share of the RANSAC hypotheses sampled progressively from the nearest landmarks (largest "
        "disparity first: they fix the translation).", min=0.0, max=1.0
    )
    ransac_refine_top: int = param(
        16, description="The best RANSAC hypotheses refined (inliers re-selected and refined); the one with the "
        "most inliers after refinement wins.", min=1, max=1000
    )
    min_inliers: int = param(10, description="Fewest inliers for a VO estimate to count as a success.", min=4)
    max_translation_m: float = param(
        5.0, description="A frame-to-frame motion longer than this is rejected as a failure, m.", min=0.0
    )
    max_step_change_m: float = param(
        1.0, description="A frame-to-frame motion whose translation differs from the last successful one's (of the "
        "last 5 frames) by more than this is rejected as a failure (a change of 1 m between consecutive frames is "
        "1 m/s^2 at 1 Hz), m (0: no check).",
        min=0.0,
    )


@dataclass(frozen=True)
class VoResult:
    """One VO step: ``T_prev_cur`` (current left camera frame → previous one, m), matches and inliers, success.

    On the first frame (no previous one) ``T_prev_cur`` is the identity and ``first`` is set; on a failure it is
    the constant-velocity prediction (``success`` False). ``covariance`` (6×6) is that of ξ in ``T_prev_cur ·
    exp(ξ)`` at the nominal 1 px noise (:class:`~lightfast.vtr.pose_estimation.PoseEstimate`; infinite without a
    successful estimate)."""

    T_prev_cur: NDArray[np.float64]
    success: bool
    num_matches: int
    num_inliers: int
    guided: bool
    first: bool = False
    rms_px: float = field(default=float("nan"))
    covariance: NDArray[np.float64] = field(default_factory=lambda: np.full((6, 6), np.inf))


class VisualOdometry:
    """Frame-to-frame stereo VO on the greyscale landmarks (paper §IV-B; Fig. 3 with "the most recent view").

    :meth:`process` takes the current frame's grey :class:`~lightfast.vtr.features.StereoFeatures` and the stereo
    camera; the previous frame's landmarks are the reference. Not thread-safe (keeps the previous frame).
    """

    def __init__(self, config: VisualOdometryConfig | None = None) -> None:
        self.config = config or VisualOdometryConfig()
        self._prev: StereoFeatures | None = None
        self._velocity: NDArray[np.float64] = np.eye(4)  # last successful T_prev_cur (constant-velocity prior)
        self._failed = STALE_FRAMES  # frames since the last successful step (STALE_FRAMES or more: none recent)

    def reset(self) -> None:
        """Forget the previous frame (the next one starts a new VO chain)."""
        self._prev = None
        self._velocity = np.eye(4)
        self._failed = STALE_FRAMES

    @property
    def prediction(self) -> NDArray[np.float64]:
        """The constant-velocity prediction of the next ``T_prev_cur`` (identity before the first success)."""
        return self._velocity.copy()

    def estimate(
        self, prev: StereoFeatures, cur: StereoFeatures, camera: StereoCamera,
        T_prev_cur_prior: NDArray[np.float64] | None = None, *, last_translation_m: ArrayLike | None = None,
    ) -> VoResult:
        """Motion between two frames without touching the state: guided by ``T_prev_cur_prior`` when given
        (and ``match_radius_px > 0``), unguided as the fallback; with ``last_translation_m`` (the last successful
        motion's translation, m) a motion whose translation differs by more than ``max_step_change_m`` is
        rejected."""
        c = self.config
        if prev.kind != cur.kind:
            raise VtrInputError(f"cannot match {prev.kind} features with {cur.kind} features")
        max_d = max_descriptor_distance(cur.kind, c.orb_max_distance, c.sift_max_distance)
        attempts = [True, False] if (T_prev_cur_prior is not None and c.match_radius_px > 0) else [False]
        disparity = camera.effective_disparity(cur)
        last = None if last_translation_m is None else np.asarray(last_translation_m, np.float64).reshape(3)
        result = VoResult(self._velocity.copy(), False, 0, 0, False)
        for guided in attempts:
            i_ref, i_cur, _ = match_landmarks(
                prev.points, prev.descriptors, cur.uv_left, cur.descriptors, cur.kind, K=camera.K,
                T_ref_cur=T_prev_cur_prior if guided else None, radius_px=c.match_radius_px if guided else 0.0,
                ratio=c.ratio, mutual=c.mutual, max_distance=max_d,
            )
            est = estimate_pose_stereo(
                prev.points[i_ref], cur.uv_left[i_cur], disparity[i_cur], camera, threshold_px=c.ransac_threshold_px,
                iterations=c.ransac_iterations, confidence=c.ransac_confidence, min_inliers=c.min_inliers,
                min_iterations=c.ransac_min_iterations, quality=-disparity[i_cur],
                ordered_fraction=c.ransac_near_first_fraction, refine_top=c.ransac_refine_top,
            )
            step_m = float(np.linalg.norm(est.T_ref_cur[:3, 3]))
            success = est.success and step_m <= c.max_translation_m
            if est.success and not success:
                log.debug("VO rejected: %.2f m between frames exceeds %.2f m", step_m, c.max_translation_m)
            change_m = 0.0 if (last is None or c.max_step_change_m <= 0) else float(
                np.linalg.norm(est.T_ref_cur[:3, 3] - last))
            if success and 0 < c.max_step_change_m < change_m:
                success = False
                log.debug("VO rejected: %.2f m between frames, %.2f m from the last motion (%d inliers)", step_m,
                          change_m, est.num_inliers)
            if success:
                return VoResult(est.T_ref_cur, True, len(i_ref), est.num_inliers, guided, rms_px=est.rms_px,
                                covariance=est.covariance)
            result = VoResult(self._velocity.copy(), False, len(i_ref), est.num_inliers, guided)
        return result

    def process(self, features: StereoFeatures, camera: StereoCamera) -> VoResult:
        """One VO step with the current frame's grey landmarks.

        On failure the constant-velocity prediction is returned as ``T_prev_cur`` (``success`` False) and the
        current frame still becomes the reference of the next step."""
        prev, self._prev = self._prev, features
        if prev is None:
            return VoResult(np.eye(4), False, 0, 0, False, first=True)
        result = self.estimate(prev, features, camera, self._velocity,
                               last_translation_m=self._velocity[:3, 3] if self._failed < STALE_FRAMES else None)
        if result.success:
            self._velocity = result.T_prev_cur.copy()
            self._failed = 0
        else:
            self._failed += 1
            log.debug("VO failed (%d matches, %d inliers); propagating the constant-velocity prediction",
                      result.num_matches, result.num_inliers)
        return result
