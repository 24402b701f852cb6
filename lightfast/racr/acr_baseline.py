"""The ACR baseline (Tian et al. 2019, "Active camera relocalization from a single reference image without hand–eye
calibration"), as the rACR paper describes it (§2.1, §4, §5.2.3): 2D matching only, no point cloud, no hand–eye.

One iteration (:meth:`AcrBaseline.step`) on the current image:

1. **SIFT matching** (OpenCV ``cv2.SIFT_create``) between the current and the reference image, Lowe's ratio test
   (``ratio_test``) on the two nearest neighbours.
2. **Relative pose by the 5-point algorithm** [46] in RANSAC (``cv2.findEssentialMat``), decomposed with the
   cheirality check (``cv2.recoverPose``): the rotation ``R_cur_ref`` of the reference camera seen from the current
   one and the *direction* ``d`` (unit vector, current camera frame) towards the reference camera centre. The
   length of the translation is unknown (two images, no scale).
3. **Hand–eye taken as identity**: the camera motion is executed as the hand motion, ``M_B = ⟨R_cur_ref, λ d⟩``
   (``T_cam_cam'``, :mod:`lightfast.racr.initialization`'s convention), with the step length λ in metres.
4. **Translation scale by bisection** (§5.2.3): λ starts at ``initial_step_m`` and is halved "if the translation
   directions of the estimated relative poses of successive two iterations are opposite, otherwise the
   translation scale remains the same" (``bisection="direction"``): the camera overshot. The previous direction is
   rotated into the current camera frame by the previous motion's rotation before the two are compared.
   ``bisection="feature_displacement"`` halves λ instead when the AFD-like image error (mean displacement of the
   inlier matches between the two images) grew since the last iteration.
5. **Stop** when that mean displacement is at most ``stop_afd_px`` (ACR's criterion is the AFD itself; here it is
   measured on the matches, since ACR has no other correspondences), or when λ fell below ``min_step_m`` and the
   rotation left to do is below ``min_rotation_deg``.

Every image-based estimate depends on the two images looking alike, which is what breaks under a lighting change
(§4): few or wrong matches give a wrong rotation and direction. Too few matches or inliers (< ``min_inliers``, and
never fewer than the 5 the algorithm needs) raise :class:`AcrError`; no motion is produced from them.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.config import Config, param
from lightfast.geometry import project_to_so3, rotation_angle_deg
from lightfast.racr.errors import AcrError

__all__ = [
    "BISECTION_RULES",
    "AcrBaseline",
    "AcrConfig",
    "AcrStep",
    "RelativePose",
    "relative_pose",
    "sift_matches",
]

logger = logging.getLogger(__name__)

Array = NDArray[np.float64]

BISECTION_RULES = ("direction", "feature_displacement")
_MIN_5POINT = 5


@dataclass(frozen=True)
class AcrConfig(Config):
    """Options of the ACR baseline (Tian et al. 2019 as described in the rACR paper, §5.2.3)."""

    ratio_test: float = param(0.75, description="Lowe's ratio: keep a match if d1 < ratio * d2.", min=0.1, max=1.0)
    max_features: int = param(0, description="SIFT features per image (0 = no limit).", min=0)
    min_inliers: int = param(15, description="Fewer RANSAC inliers than this is a failure.", min=_MIN_5POINT)
    ransac_threshold_px: float = param(1.0, description="RANSAC inlier threshold (Sampson distance), px.",
                                       min=1e-3)
    ransac_confidence: float = param(0.999, description="RANSAC confidence.", min=0.5, max=0.999999)
    initial_step_m: float = param(0.05, description="First translation step length (the scale guess), m.",
                                  min=1e-6)
    min_step_m: float = param(2e-4, description="A step shorter than this counts as no translation left, m.",
                              min=0.0)
    min_rotation_deg: float = param(0.02, description="A rotation smaller than this counts as none left, deg.",
                                    min=0.0)
    bisection: str = param(
        "direction", description="Halve the step when the direction reverses (the paper) or the image error grows.",
        choices=BISECTION_RULES,
    )
    stop_afd_px: float = param(0.5, description="Converged when the inliers' mean displacement is at most this, px.",
                               min=0.0)
    seed: int = param(0, description="OpenCV RNG seed set before RANSAC (reproducible estimates).", min=0)


@dataclass(frozen=True)
class RelativePose:
    """The reference camera seen from the current one: rotation ``R_cur_ref`` and unit ``direction_cur`` towards
    its centre (current camera frame; the distance is unknown), from ``inliers`` of ``matches`` SIFT matches whose
    mean image displacement is ``afd_px``."""

    R_cur_ref: Array
    direction_cur: Array
    matches: int
    inliers: int
    afd_px: float
    points_cur: Array
    points_ref: Array


@dataclass(frozen=True)
class AcrStep:
    """One ACR iteration: the hand motion ``M_hand`` (= the camera motion, hand–eye taken as identity; the identity
    when converged), the step length used, whether ACR considers itself converged, and the pose estimate."""

    M_hand: Array
    converged: bool
    step_m: float
    afd_px: float
    pose: RelativePose
    iteration: int


def _gray_u8(image: ArrayLike, name: str) -> NDArray[np.uint8]:
    """8-bit grey for SIFT: uint8 images as they are (RGB averaged by OpenCV), any other dtype read as [0, 1]."""
    try:
        a = np.asarray(image)
    except (TypeError, ValueError) as exc:
        raise AcrError(f"{name} must be an image array: {exc}") from None
    if a.ndim == 3 and a.shape[2] in (3, 4):
        a = cv2.cvtColor(np.ascontiguousarray(a[..., :3]), cv2.COLOR_RGB2GRAY) if a.dtype == np.uint8 else (
            np.asarray(a[..., :3], dtype=np.float64).mean(axis=2))
    if a.ndim != 2 or a.shape[0] < 16 or a.shape[1] < 16:
        raise AcrError(f"{name} must be an (H, W) or (H, W, 3) image of at least 16x16 px, got {a.shape}")
    if a.dtype == np.uint8:
        return np.ascontiguousarray(a)
    try:
        f = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise AcrError(f"{name} must be numeric: {exc}") from None
    if not np.all(np.isfinite(f)):
        raise AcrError(f"{name} has non-finite pixels")
    return np.clip(np.rint(f * 255.0), 0, 255).astype(np.uint8)


class _Features:
    def __init__(self, image: ArrayLike, name: str, sift: cv2.SIFT) -> None:
        keypoints, descriptors = sift.detectAndCompute(_gray_u8(image, name), None)
        self.points = np.array([k.pt for k in keypoints], dtype=np.float64).reshape(-1, 2)
        self.descriptors = descriptors


def _sift(config: AcrConfig) -> cv2.SIFT:
    return cv2.SIFT.create(nfeatures=config.max_features)


def _match(cur: _Features, ref: _Features, config: AcrConfig) -> tuple[Array, Array]:
    if cur.descriptors is None or ref.descriptors is None or len(cur.points) < 2 or len(ref.points) < 2:
        return np.zeros((0, 2)), np.zeros((0, 2))
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(cur.descriptors, ref.descriptors, k=2)
    good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < config.ratio_test * p[1].distance]
    i = np.array([m.queryIdx for m in good], dtype=np.intp)
    j = np.array([m.trainIdx for m in good], dtype=np.intp)
    return cur.points[i], ref.points[j]


def sift_matches(image_cur: ArrayLike, image_ref: ArrayLike, config: AcrConfig | None = None) -> tuple[Array, Array]:
    """SIFT matches passing the ratio test: pixel coordinates ``(n, 2)`` in the current and the reference image
    (OpenCV's convention, pixel centres at integers, the same as :class:`PinholeCamera`)."""
    config = _check(config)
    sift = _sift(config)
    return _match(_Features(image_cur, "image_cur", sift), _Features(image_ref, "image_ref", sift), config)


def relative_pose(points_cur: ArrayLike, points_ref: ArrayLike, camera: PinholeCamera,
                  config: AcrConfig | None = None) -> RelativePose:
    """The 5-point relative pose (RANSAC) of the reference camera seen from the current one, from matched pixels.
    Raises :class:`AcrError` with fewer than ``min_inliers`` matches or inliers."""
    config = _check(config)
    pc = np.ascontiguousarray(points_cur, dtype=np.float64).reshape(-1, 2)
    pr = np.ascontiguousarray(points_ref, dtype=np.float64).reshape(-1, 2)
    if len(pc) != len(pr):
        raise AcrError(f"points_cur and points_ref differ in length: {len(pc)} and {len(pr)}")
    if len(pc) < config.min_inliers:
        raise AcrError(f"only {len(pc)} SIFT matches (min_inliers={config.min_inliers}): the images do not match")
    cv2.setRNGSeed(config.seed)
    E, mask = cv2.findEssentialMat(pc, pr, camera.K, method=cv2.RANSAC, prob=config.ransac_confidence,
                                   threshold=config.ransac_threshold_px)
    if E is None or E.shape != (3, 3):
        raise AcrError(f"the 5-point RANSAC found no essential matrix from {len(pc)} matches")
    ransac_inliers = int(np.count_nonzero(mask))
    if ransac_inliers < config.min_inliers:
        raise AcrError(
            f"only {ransac_inliers} of {len(pc)} matches are 5-point inliers (min_inliers={config.min_inliers})"
        )
    # cheirality over all RANSAC inliers, also the far ones: near the goal the baseline is tiny and every point is
    # "far" for recoverPose's default distance threshold (50 baselines), which would leave no inlier at all
    inl, R, t, mask2, _ = cv2.recoverPose(E, pc, pr, camera.K, distanceThresh=1e9, mask=mask.copy())
    keep = mask2.ravel() > 0
    if int(inl) < config.min_inliers:
        raise AcrError(f"only {int(inl)} of {ransac_inliers} 5-point inliers pass the cheirality check")
    # recoverPose: x_ref = R x_cur + t, i.e. T_ref_cur = [R, t]; the reference centre in the current frame is -Rᵀt
    R_ref_cur = project_to_so3(np.asarray(R, dtype=np.float64))
    centre = -R_ref_cur.T @ np.asarray(t, dtype=np.float64).ravel()
    afd = float(np.mean(np.linalg.norm(pc[keep] - pr[keep], axis=1)))
    return RelativePose(
        R_cur_ref=R_ref_cur.T, direction_cur=centre / np.linalg.norm(centre), matches=len(pc), inliers=int(inl),
        afd_px=afd, points_cur=pc[keep], points_ref=pr[keep],
    )


def _check(config: AcrConfig | None) -> AcrConfig:
    if config is None:
        return AcrConfig()
    if not isinstance(config, AcrConfig):
        raise AcrError(f"config must be an AcrConfig, got {type(config).__name__}")
    return config


class AcrBaseline:
    """The ACR loop's state around one reference image (features computed once): the step length of the bisection
    and the previous estimate. Call :meth:`step` with each new current image, execute ``M_hand`` unless
    ``converged``, repeat."""

    def __init__(self, reference_image: ArrayLike, camera: PinholeCamera, config: AcrConfig | None = None) -> None:
        if not isinstance(camera, PinholeCamera):
            raise AcrError(f"camera must be a PinholeCamera, got {type(camera).__name__}")
        self.config = _check(config)
        self.camera = camera
        self._sift = _sift(self.config)
        self._ref = _Features(reference_image, "reference_image", self._sift)
        if len(self._ref.points) < self.config.min_inliers:
            raise AcrError(f"the reference image has only {len(self._ref.points)} SIFT features")
        self.step_m = self.config.initial_step_m
        self.iterations = 0
        self.halvings = 0
        self._previous: tuple[Array, float, Array] | None = None  # (direction, afd, executed rotation)

    def step(self, image_cur: ArrayLike) -> AcrStep:
        """One ACR iteration on the current image (see the module documentation)."""
        cur = _Features(image_cur, "image_cur", self._sift)
        pc, pr = _match(cur, self._ref, self.config)
        pose = relative_pose(pc, pr, self.camera, self.config)
        self.iterations += 1
        if self._previous is not None:
            d_prev, afd_prev, R_prev = self._previous
            if self.config.bisection == "direction":
                reversed_ = float(pose.direction_cur @ (R_prev.T @ d_prev)) < 0.0
            else:
                reversed_ = pose.afd_px > afd_prev
            if reversed_:
                self.step_m *= 0.5
                self.halvings += 1
        rotation_left = float(rotation_angle_deg(pose.R_cur_ref))
        converged = pose.afd_px <= self.config.stop_afd_px or (
            self.step_m < self.config.min_step_m and rotation_left < self.config.min_rotation_deg
        )
        M = np.eye(4)
        if not converged:
            M[:3, :3] = pose.R_cur_ref
            if self.step_m >= self.config.min_step_m:
                M[:3, 3] = self.step_m * pose.direction_cur
        self._previous = (pose.direction_cur, pose.afd_px, M[:3, :3].copy())
        logger.debug(
            "ACR iteration %d: %d/%d inliers, AFD %.2f px, rotation %.3f deg, step %.4f m%s",
            self.iterations, pose.inliers, pose.matches, pose.afd_px, rotation_left, self.step_m,
            ", converged" if converged else "",
        )
        return AcrStep(M_hand=M, converged=converged, step_m=self.step_m, afd_px=pose.afd_px, pose=pose,
                       iteration=self.iterations)
