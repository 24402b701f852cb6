"""Stereo front end of colour-constant VT&R, per image source: paper §IV-B (Fig. 3 and Fig. 4), and the
triangulation of a rectified stereo pair.

:class:`StereoFrontEnd` takes a rectified rgb8 stereo pair (H, W, 3) with its ``camera_info`` projection matrices and
returns, per image source (greyscale, F_v, F_r of :mod:`lightfast.vtr.color_constant`), the
:class:`~lightfast.vtr.features.StereoFeatures`: features detected in the left (and, for descriptor matching, the
right) image (:mod:`lightfast.vtr.features`), matched left to right and refined to sub-pixel disparities
(:mod:`lightfast.vtr.stereo_matching`), and triangulated into 3-D landmarks in the left camera frame (metres) — the
"3D keypoints" that Fig. 3/4 then match against the map.

Triangulation: from the 3×4 projection matrices of the *rectified* pair (``P`` of sensor_msgs/CameraInfo,
[fx 0 cx Tx; 0 fy cy Ty; 0 0 1 0], usually Tx_left = 0 and Tx_right = −fx·B; fx, fy, cy and Ty must agree, cx may
differ: :func:`check_stereo_pair`), the closed-form solution of the linear triangulation for rectified rows,
Z = (Tx_l − Tx_r) / (u_l − u_r − cx_l + cx_r), X = (u_l − cx_l) Z / fx, Y = (v_l − cy) Z / fy, in the left camera
frame (:func:`triangulate`). Landmarks outside [``min_depth_m``, ``max_depth_m``], whose refined disparity left the
admissible range or whose sub-pixel refinement failed are dropped.
"""
from __future__ import annotations

import logging
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.vtr.color_constant import ColorConstantConfig, SourceImage, image_sources
from lightfast.vtr.errors import VtrInputError
from lightfast.vtr.features import FeatureExtractor, Features, StereoFeatures
from lightfast.vtr.stereo_config import StereoConfig
from lightfast.vtr.stereo_matching import match_stereo, refine_disparity, search_stereo

__all__ = ["StereoFrontEnd", "check_projection", "check_stereo_pair", "triangulate"]

log = logging.getLogger(__name__)

# --------------------------------------------------------------------------------------------------------------
# Triangulation


def check_projection(P: ArrayLike, name: str = "P") -> NDArray[np.float64]:
    """A rectified ``camera_info`` projection matrix as (3, 4) float64: finite, [fx 0 cx Tx; 0 fy cy Ty; 0 0 1 0]
    with fx, fy > 0. Raises VtrInputError."""
    m = np.asarray(P, dtype=np.float64)
    if m.size == 12:
        m = m.reshape(3, 4)
    if m.shape != (3, 4):
        raise VtrInputError(f"{name} must be a finite 3x4 projection matrix, got shape {np.shape(P)}")
    v = m.tolist()  # plain floats: these checks run several times per frame
    if not all(math.isfinite(x) for row in v for x in row):
        raise VtrInputError(f"{name} must be a finite 3x4 projection matrix, got non-finite values")
    if not all(math.isclose(a, b, rel_tol=1e-5, abs_tol=1e-8) for a, b in zip(v[2], (0.0, 0.0, 1.0, 0.0),
                                                                             strict=True)) \
            or v[0][1] != 0.0 or v[1][0] != 0.0 or v[0][0] <= 0.0 or v[1][1] <= 0.0:
        raise VtrInputError(f"{name} is not a rectified projection matrix [fx 0 cx Tx; 0 fy cy Ty; 0 0 1 0]: {m}")
    return m


def check_stereo_pair(P_left: ArrayLike, P_right: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Both projection matrices checked (:func:`check_projection`) and consistent with a rectified pair: equal
    fx, fy, cy and Ty (rows align), different Tx (a baseline). Raises VtrInputError."""
    Pl, Pr = check_projection(P_left, "P_left"), check_projection(P_right, "P_right")
    for (r, c), what in (((0, 0), "fx"), ((1, 1), "fy"), ((1, 2), "cy"), ((1, 3), "Ty")):
        a, b = float(Pl[r, c]), float(Pr[r, c])
        if abs(a - b) > 1e-9 + 1e-6 * abs(b):  # np.isclose(a, b, rtol=1e-6, atol=1e-9)
            raise VtrInputError(f"P_left and P_right are not a rectified pair: {what} differs ({a} vs {b})")
    if abs(float(Pl[0, 3]) - float(Pr[0, 3])) <= 1e-12:
        raise VtrInputError("P_left and P_right have the same Tx: no stereo baseline")
    return Pl, Pr


def triangulate(
    P_left: ArrayLike, P_right: ArrayLike, uv_left: ArrayLike, uv_right: ArrayLike
) -> NDArray[np.float64]:
    """Landmarks (N, 3) in the left camera frame, metres, from matched pixels of a rectified pair.

    With P = [f 0 cx Tx; 0 fy cy Ty; 0 0 1 0] for both cameras (X in their shared frame):
    u_l − u_r = (cx_l − cx_r) + (Tx_l − Tx_r)/Z, so Z = (Tx_l − Tx_r) / (u_l − u_r − cx_l + cx_r),
    X = ((u_l − cx_l) Z − Tx_l)/f, Y = ((v_l − cy) Z − Ty)/fy — the exact solution of the linear (DLT) system for
    rectified rows (v_right is not used) — then moved into the left camera frame by adding K⁻¹ P_left[:, 3] =
    (Tx_l/f, Ty/fy, 0), which leaves X_left = (u_l − cx_l) Z/f, Y_left = (v_l − cy) Z/fy. Rows whose effective
    disparity has the wrong sign or is zero (points at or beyond infinity) are NaN.
    """
    return _triangulate(*check_stereo_pair(P_left, P_right), uv_left, uv_right)


def _triangulate(Pl: NDArray[np.float64], Pr: NDArray[np.float64], uv_left: ArrayLike, uv_right: ArrayLike
                 ) -> NDArray[np.float64]:
    """:func:`triangulate` with checked projection matrices."""
    a = np.asarray(uv_left, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(uv_right, dtype=np.float64).reshape(-1, 2)
    if a.shape != b.shape:
        raise VtrInputError(f"uv_left {a.shape} and uv_right {b.shape} differ")
    f, fy, cy = Pl[0, 0], Pl[1, 1], Pl[1, 2]
    d_eff = (a[:, 0] - b[:, 0]) - (Pl[0, 2] - Pr[0, 2])
    fb = Pl[0, 3] - Pr[0, 3]  # = f·B
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(d_eff * np.sign(fb) > 0, fb / d_eff, np.nan)
    x = (a[:, 0] - Pl[0, 2]) * z / f  # in the left camera frame: the Tx_l/f shift cancels
    y = (a[:, 1] - cy) * z / fy
    return np.stack([x, y, z], axis=1)


# --------------------------------------------------------------------------------------------------------------
# Front end


class StereoFrontEnd:
    """Per-source stereo landmarks of a rectified rgb8 stereo pair (paper Fig. 4, up to the map matching)."""

    def __init__(
        self,
        config: StereoConfig | None = None,
        color: ColorConstantConfig | None = None,
        sources: tuple[str, ...] = ("grey", "fv", "fr"),
    ) -> None:
        self.config = config or StereoConfig()
        self.color = color or ColorConstantConfig()
        self.sources = tuple(sources)
        self.extractor = FeatureExtractor(self.config)

    def source_features(self, left: SourceImage, right: SourceImage, P_left: ArrayLike, P_right: ArrayLike
                        ) -> StereoFeatures:
        """Detect, match left to right, refine and triangulate one image source."""
        if left.image.shape != right.image.shape:
            raise VtrInputError(f"left image {left.image.shape} and right image {right.image.shape} differ in size")
        Pl, Pr = check_stereo_pair(P_left, P_right)
        fl = self.extractor.detect(left.image, left.valid)
        fr = self.extractor.detect(right.image, right.valid) if self.config.detects_right else None
        return self.landmarks(left, right, fl, fr, Pl, Pr)

    def landmarks(self, left: SourceImage, right: SourceImage, fl: Features, fr: Features | None,
                  P_left: ArrayLike, P_right: ArrayLike) -> StereoFeatures:
        """:meth:`source_features` after the detection: match the left features ``fl`` of one image source to the
        right features ``fr`` (``"descriptor"``) or search them in the right image (``"search"``, ``fr`` unused),
        refine and triangulate."""
        c = self.config
        if left.image.shape != right.image.shape:
            raise VtrInputError(f"left image {left.image.shape} and right image {right.image.shape} differ in size")
        Pl, Pr = check_stereo_pair(P_left, P_right)
        if c.detects_right:
            if fr is None:
                raise VtrInputError("descriptor left-right matching needs the right image's features")
            il, ir, dist = match_stereo(fl, fr, c)
            uvl, uvr = fl.uv[il], fr.uv[ir]
            disp = (uvl[:, 0] - uvr[:, 0]).astype(np.float32)
        else:
            il, disp, dist = search_stereo(left.image, right.image, fl.uv, c)
            uvl = fl.uv[il]
            if right.valid is not None and len(il):  # the right pixel must be valid, as a right detection's is
                v = np.rint(uvl[:, 1]).astype(np.intp)
                u = np.rint(uvl[:, 0] - disp).astype(np.intp)
                keep = right.valid[v, u]
                il, disp, dist, uvl = il[keep], disp[keep], dist[keep], uvl[keep]
            uvr = np.stack([uvl[:, 0] - disp, uvl[:, 1]], axis=1).astype(np.float32)
        if c.subpixel and len(il):
            # the row search's integer disparity is already the best one: refine around it only (the descriptor
            # matches of coarse ORB levels can be a few pixels off)
            search = c.subpixel_search_px if c.detects_right else min(c.subpixel_search_px, 2)
            disp, refined = refine_disparity(left.image, right.image, uvl, disp, radius=c.subpixel_radius_px,
                                             search=search)
            uvr = np.stack([uvl[:, 0] - disp, uvr[:, 1]], axis=1).astype(np.float32)
        else:
            refined = np.ones(len(il), bool)
        pts = _triangulate(Pl, Pr, uvl, uvr)
        with np.errstate(invalid="ignore"):
            ok = (
                np.all(np.isfinite(pts), axis=1) & (pts[:, 2] >= c.min_depth_m) & (pts[:, 2] <= c.max_depth_m)
                & (disp >= c.min_disparity_px) & (disp <= c.max_disparity_px) & refined
            )
        log.debug("%s: %d left features, %d matches, %d landmarks", left.name, len(fl), len(il), int(ok.sum()))
        return StereoFeatures(
            source=left.name,
            uv_left=uvl[ok],
            uv_right=uvr[ok],
            disparity=disp[ok],
            points=pts[ok],
            descriptors=fl.descriptors[il[ok]],
            distance=dist[ok],
            kind=fl.kind,
        )

    def process(
        self, left_rgb: NDArray[np.generic], right_rgb: NDArray[np.generic], P_left: ArrayLike, P_right: ArrayLike
    ) -> dict[str, StereoFeatures]:
        """Landmarks of every configured source for one rectified (H, W, 3) rgb stereo pair."""
        left_a, right_a = np.asarray(left_rgb), np.asarray(right_rgb)
        if left_a.shape != right_a.shape:
            raise VtrInputError(f"left image {left_a.shape} and right image {right_a.shape} differ in size")
        Pl, Pr = check_stereo_pair(P_left, P_right)
        ls = image_sources(left_a, self.color, self.sources)
        rs = image_sources(right_a, self.color, self.sources)
        return {name: self.source_features(ls[name], rs[name], Pl, Pr) for name in self.sources}
