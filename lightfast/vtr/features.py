"""Keypoints of one image and stereo landmarks of one image source — the data of the colour-constant VT&R front end
(paper §IV-B, Fig. 3–4) — and the feature detection.

* :class:`Features` — keypoints of one 8-bit image: pixels ``uv`` (N, 2) float32 (u right, v down; OpenCV's
  pixel-centre convention) and descriptors (N, D): packed uint8 bits for ORB, float32 for SIFT;
* :class:`StereoFeatures` — the triangulated left–right matches of one image source of a rectified stereo pair:
  left and right pixels, disparity u_left − u_right (px), 3-D points (N, 3) in the left camera frame (metres,
  REP-103 optical axes), the left image's descriptors and the left–right match distance. These are the "3D
  keypoints" that Fig. 3/4 match against the map, and what a keyframe of the teach map stores;
* :class:`FeatureExtractor` — OpenCV ORB or SIFT (options of :class:`~lightfast.vtr.stereo_config.StereoConfig`) on
  an (H, W) uint8 image (greyscale or a colour-constant image of :mod:`lightfast.vtr.color_constant`), with an
  optional validity mask grown by ``mask_erosion_px`` so that no keypoint lies next to a zero or saturated pixel.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from lightfast.vtr.errors import VtrInputError
from lightfast.vtr.stereo_config import StereoConfig

__all__ = ["FeatureExtractor", "Features", "StereoFeatures"]


@dataclass(frozen=True)
class Features:
    """Keypoints of one image: pixel positions ``uv`` (N, 2) float32 (u right, v down; OpenCV's pixel-centre
    convention) and descriptors (N, D): float32 for SIFT, packed uint8 bits for ORB."""

    uv: NDArray[np.float32]
    descriptors: NDArray[np.generic]
    kind: str

    def __len__(self) -> int:
        return int(self.uv.shape[0])


@dataclass(frozen=True)
class StereoFeatures:
    """Triangulated left–right matches of one image source.

    ``points`` (N, 3) are in the left (rectified) camera frame, metres; ``descriptors`` are the left image's;
    ``distance`` the left–right descriptor distance; ``disparity`` = u_left − u_right after refinement.
    """

    source: str
    uv_left: NDArray[np.float32]
    uv_right: NDArray[np.float32]
    disparity: NDArray[np.float32]
    points: NDArray[np.float64]
    descriptors: NDArray[np.generic]
    distance: NDArray[np.float32]
    kind: str

    def __len__(self) -> int:
        return int(self.uv_left.shape[0])


class FeatureExtractor:
    """Detects and describes features in 8-bit images with OpenCV (one detector object, not thread-safe)."""

    def __init__(self, config: StereoConfig | None = None) -> None:
        self.config = config or StereoConfig()
        c = self.config
        self._detector: cv2.Feature2D
        if c.feature == "orb":
            self._detector = cv2.ORB.create(
                nfeatures=c.max_features,
                scaleFactor=c.orb_scale_factor,
                nlevels=c.orb_levels,
                fastThreshold=c.orb_fast_threshold,
            )
        else:
            self._detector = cv2.SIFT.create(nfeatures=c.max_features, contrastThreshold=c.sift_contrast_threshold)

    @property
    def kind(self) -> str:
        return self.config.feature

    def empty(self) -> Features:
        dim, dtype = (32, np.uint8) if self.kind == "orb" else (128, np.float32)
        return Features(np.zeros((0, 2), np.float32), np.zeros((0, dim), dtype), self.kind)

    def detect(self, image: NDArray[np.uint8], valid: NDArray[np.bool_] | None = None) -> Features:
        """Features of an (H, W) uint8 image; with ``valid``, none within ``mask_erosion_px`` of an invalid pixel."""
        img = np.asarray(image)
        if img.ndim != 2 or img.dtype != np.uint8:
            raise VtrInputError(f"feature detection needs an (H, W) uint8 image, got {img.dtype} {img.shape}")
        mask: NDArray[np.uint8] | None = None
        if valid is not None:
            v = np.asarray(valid)
            if v.shape != img.shape:
                raise VtrInputError(f"mask shape {v.shape} differs from the image shape {img.shape}")
            if not v.all():
                mask = v.astype(np.uint8)
                r = self.config.mask_erosion_px
                if r > 0:
                    mask = cast(NDArray[np.uint8],
                                cv2.erode(mask, cv2.getStructuringElement(cv2.MORPH_RECT, (2 * r + 1, 2 * r + 1))))
                if not mask.any():
                    return self.empty()
        kps, desc = self._detector.detectAndCompute(np.ascontiguousarray(img), mask)
        if desc is None or len(kps) == 0:
            return self.empty()
        # an (N, 2) float32 array at run time (the stubs say a sequence of points)
        uv = cast(NDArray[np.float32], cv2.KeyPoint.convert(kps)).astype(np.float32).reshape(-1, 2)
        dtype = np.uint8 if self.kind == "orb" else np.float32
        return Features(uv, np.ascontiguousarray(desc, dtype=dtype), self.kind)
