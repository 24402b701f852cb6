"""Self-check of a converged relocalization: does the reference image agree with the estimate? (issue 19; not in
the paper, whose rACR reports convergence whenever g ≤ η, §3.5; docs/racr.md describes the checks.)

The geometric alignment (§3.4) can converge to a wrong pose on a repetitive relief (sliding along a facade by its
period), and g ≤ η then holds at the wrong place. The checks use evidence the alignment did not, in this order:

1. SIFT matches between the reference image and the current VSE keyframes (:func:`verify`): each reference keypoint
   is lifted to 3-D with the reference cloud (the nearest projected point within ``depth_radius_px``) and projected
   into the keyframe with the estimate (``T_ref_cam = T_p ⟨R_A, σ_p s t_A⟩``, Eq. 2–3); it *agrees* within
   ``verify_px`` (keypoint noise). One correction of the estimate is fitted to all keyframes' matches (from the
   estimate and from the best keyframe's PnP pose); with ``min_other_pose`` matches within ``verify_px``, more than
   the estimate, and moving them beyond ``verify_px``, the convergence is ``failed`` (fewer than ``min_agreeing``
   agree, or half of them fit that pose too: a near miss) or ``ambiguous`` (disjoint matches fit both: a repetitive
   texture). Else ``min_agreeing`` agreeing matches verify.
2. The image as a whole, when matches cannot tell (:func:`image_shift`): each keyframe is warped into the reference
   view by the estimate (the homography of the plane at the reference's median depth) and its gradient magnitude
   (edges of the relief stay edges whichever side the light comes from) is phase-correlated with the reference's.
   ``shift_min_keyframes`` keyframes agreeing within ``agree_px`` on a shift beyond ``agree_px``: ``failed`` (chance
   peaks scatter over the image). A shift near zero does not verify: it cannot resolve the success criterion's px.
3. The geometry, when neither image cue can tell (:func:`restart_fits`): the fast alignment restarted from the
   estimate shifted across the view by ``basin_shifts_depth`` of the scene's depth. A fit that moves the points by
   more than ``agree_px`` in the reference image is another fit: clearly better (fitness ×1/``basin_fitness_ratio``)
   ``failed``, comparable ``ambiguous``, none ``verified`` by the geometry.

A check failed by the matches carries the correction ``δ`` they give (within ``max_correction_deg``), which the
session moves the camera by before checking again (``corrections``). Inputs: the reference cloud (m, reference
frame), its camera and pose, the reference image; keyframes (image in [0, 1], ``T_ref_cam`` m, camera).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.optimize import least_squares

from lightfast.camera import PinholeCamera
from lightfast.config import Config, ConfigError, param
from lightfast.geometry import inverse, make_transform, rotation_angle_deg, so3_exp, transform_points
from lightfast.racr.acr_baseline import AcrConfig, sift_matches
from lightfast.racr.errors import AlignmentError
from lightfast.racr.fast_alignment import FastAlignmentConfig, ReferenceCloud, fast_align

__all__ = ["VERDICTS", "ImageShift", "ReferenceView", "Restarts", "Verification", "VerificationConfig", "image_shift",
           "restart_fits", "verify"]

Array = NDArray[np.float64]
VERDICTS = ("verified", "failed", "ambiguous")


@dataclass(frozen=True)
class VerificationConfig(Config):
    """Options of the convergence self-check (module docstring)."""

    enabled: bool = param(True, description="Check a convergence against the reference image before reporting it "
                          "(failed or ambiguous instead of converged when the image disagrees or cannot tell).")
    agree_px: float = param(4.0, description="A reference feature agrees with the estimate when it reprojects this "
                            "close to its match in a keyframe, px (the success criterion is AFD < 3 px, plus about "
                            "1 px of keypoint noise).", min=0.5, max=50.0)
    verify_px: float = param(2.0, description="A match verifies a convergence only when it reprojects this close "
                             "to its prediction, px (keypoint noise: SIFT locates a feature to about 0.5 px). An "
                             "estimate a few cm off still puts some right matches within agree_px, near where the "
                             "error moves the image least.", min=0.5, max=50.0)
    min_agreeing: int = param(6, description="Matches (over all keyframes) within verify_px of their prediction that "
                              "verify a convergence (a wrong match lands that close by chance with a probability "
                              "below 1e-3: six cannot be chance).", min=3)
    min_other_pose: int = param(12, description="Matches agreeing with another camera pose (a keyframe's PnP, or "
                                "the estimate corrected by all keyframes' matches) that make a convergence failed "
                                "(more than min_agreeing: a fit finds a few wrong matches to agree by chance).", min=6)
    depth_radius_px: int = param(2, description="A reference keypoint takes the depth of the nearest reference point "
                                 "projected within this many pixels (a semi-dense cloud).", min=0, max=10)
    shift_min_keyframes: int = param(2, description="Keyframes whose image shifts against the reference (phase "
                                     "correlation after warping by the estimate) agree within agree_px on more than "
                                     "agree_px: the convergence is failed.", min=2)
    basin_shifts_depth: tuple[float, ...] = param(
        (0.05, 0.1, 0.2, 0.4), description="When the image cannot tell (a strong lighting change): the fast "
        "alignment is started again from the estimate shifted along the camera's x and y axes by these fractions of "
        "the current cloud's median depth (0.4: the view moves by about a third of its width).")
    basin_fitness_ratio: float = param(0.9, description="A restart that settles elsewhere (its fit moves the points "
                                       "by more than agree_px in the reference image) is a look-alike when its "
                                       "fitness is at least this share of the estimate's (ambiguous), and a better "
                                       "fit when the estimate's is at most this share of its (failed).", min=0.01,
                                       max=1.0)
    max_correction_deg: float = param(20.0, description="A correction that turns the camera by more than this is "
                                      "not made (rACR starts a few degrees from the reference; the matches then fit "
                                      "a look-alike elsewhere in the image, not a slide of the alignment), deg.",
                                      min=0.0, max=180.0)
    corrections: int = param(2, description="After a check failed by the matches, the camera is moved where they put "
                             "it and checked again, at most this many times; verified then, the run converged (0: a "
                             "failed check ends the run).", min=0, max=10)

    def check(self) -> None:
        if self.verify_px > self.agree_px:
            raise ConfigError(f"VerificationConfig.verify_px={self.verify_px} exceeds agree_px={self.agree_px}: a "
                              "match would verify where it does not even agree")


@dataclass(frozen=True)
class Restarts:
    """What :func:`restart_fits` found: how many restarts ran, and for the nearest look-alike (comparable fitness)
    and the best clearly better fit elsewhere their mean displacement of the points in the reference image (px) and
    fitness relative to the estimate's (NaN: none)."""

    ran: int
    look_alike_px: float = float("nan")
    look_alike_ratio: float = float("nan")
    better_px: float = float("nan")
    better_ratio: float = float("nan")

    @property
    def verdict(self) -> str:
        """``failed`` with a clearly better fit elsewhere, ``ambiguous`` with a look-alike or when no restart ran,
        else ``verified``."""
        if np.isfinite(self.better_ratio):
            return "failed"
        return "ambiguous" if np.isfinite(self.look_alike_px) or self.ran == 0 else "verified"


@dataclass(frozen=True)
class ImageShift:
    """What :func:`image_shift` measured: the median shift (px, x and y) of the keyframes' images against the
    reference after warping by the estimate, how many keyframes agree with it within ``agree_px``, of how many."""

    shift_px: tuple[float, float]
    agreeing: int
    keyframes: int

    @property
    def norm_px(self) -> float:
        return float(np.hypot(*self.shift_px))


@dataclass(frozen=True)
class Verification:
    """The verdict, the matches it rests on and, for a ``failed`` image check, the mean displacement (px) between
    where the estimate and where the images put the reference features; ``restarts``: the geometric check, when the
    image could not tell (None otherwise)."""

    verdict: str
    matches: int
    agreeing: int
    other_pose_inliers: int = 0
    disagreement_px: float = float("nan")
    shift: ImageShift | None = None
    restarts: Restarts | None = None
    #: for a check failed by the matches: the correction ``δ`` (4×4, reference frame) they give, ``δ · T_ref_cam``
    #: being where they put a camera the estimate puts at ``T_ref_cam`` (None otherwise)
    T_correction: Array | None = field(default=None, compare=False)
    #: correction motions made before this check (the session's; 0: the check of the alignment's own convergence)
    corrections: int = 0

    def describe(self) -> str:
        text = self._describe()
        return text if self.corrections == 0 else f"{text} (after {self.corrections} correction motions)"

    def _describe(self) -> str:
        r = self.restarts
        image = f"the reference image could not tell: {self.agreeing} of {self.matches} matches agree"
        if r is not None and self.verdict == "verified":
            return f"verified by the geometry: {r.ran} restarts find no other fit as good ({image})"
        if self.verdict == "verified":
            return f"verified by {self.agreeing} of {self.matches} reference-image matches"
        if r is not None and self.verdict == "failed":
            return (f"a restart found a better fit {r.better_px:.1f} px away (fitness x{r.better_ratio:.2f}): "
                    f"converged to a local minimum ({image})")
        if r is not None and np.isfinite(r.look_alike_px):
            return (f"a look-alike fit {r.look_alike_px:.1f} px away is as good (fitness x{r.look_alike_ratio:.2f}; "
                    f"{image})")
        sh = self.shift
        if self.verdict == "failed" and sh is not None:  # failed by the image shift (a PnP failure has none)
            return (f"the reference image is shifted {sh.norm_px:.1f} px from where the estimate puts it "
                    f"({sh.agreeing} of {sh.keyframes} keyframes agree; {image})")
        if self.verdict == "failed":
            return (f"the reference image disagrees: {self.other_pose_inliers} matches put the camera elsewhere "
                    f"(features {self.disagreement_px:.1f} px from where the estimate puts them; {self.agreeing} "
                    "agree)")
        if sh is None and r is None and self.verdict == "ambiguous":  # decided by the matches: two poses fit
            return (f"the reference image fits two poses: {self.agreeing} of {self.matches} matches agree with the "
                    f"estimate, {self.other_pose_inliers} with a pose {self.disagreement_px:.1f} px away")
        return f"unverified: {self.agreeing} of {self.matches} reference-image matches agree (too few to tell)"


class ReferenceView:
    """The reference image with a depth per pixel from the reference cloud (for lifting keypoints to 3-D)."""

    def __init__(self, points_m: ArrayLike, T_ref_camref: ArrayLike, image: ArrayLike, camera: PinholeCamera,
                 config: VerificationConfig | None = None) -> None:
        self.config = config or VerificationConfig()
        self.camera = camera
        self.image = np.asarray(image)
        self.T_ref_camref = np.asarray(T_ref_camref, dtype=np.float64)
        pts = np.asarray(points_m, np.float64).reshape(-1, 3)
        p_cam = (inverse(self.T_ref_camref) @ np.c_[pts, np.ones(len(pts))].T).T
        uv, ok = camera.project(p_cam[:, :3])
        u, v = np.rint(uv[ok, 0]).astype(np.intp), np.rint(uv[ok, 1]).astype(np.intp)
        inside = (u >= 0) & (u < camera.width) & (v >= 0) & (v < camera.height)
        depth = np.full(camera.shape, np.inf)
        np.minimum.at(depth, (v[inside], u[inside]), p_cam[ok][inside, 2])
        r = self.config.depth_radius_px
        self.depth_m = ndimage.grey_erosion(depth, size=(2 * r + 1, 2 * r + 1)) if r > 0 else depth

    def lift(self, uv_px: Array) -> tuple[Array, NDArray[np.bool_]]:
        """Reference-frame points (n, 3) of reference pixels with a depth, and which had one."""
        u = np.clip(np.rint(uv_px[:, 0]).astype(np.intp), 0, self.camera.width - 1)
        v = np.clip(np.rint(uv_px[:, 1]).astype(np.intp), 0, self.camera.height - 1)
        d = self.depth_m[v, u]
        ok = np.isfinite(d)
        p_cam = self.camera.backproject(uv_px[ok], d[ok])
        return (self.T_ref_camref @ np.c_[p_cam, np.ones(len(p_cam))].T).T[:, :3], ok


def verify(view: ReferenceView, keyframes: Sequence[tuple[ArrayLike, ArrayLike, PinholeCamera]]) -> Verification:
    """The verdict on an estimate from keyframes ``(image in [0, 1] or uint8, T_ref_cam, camera)`` (module
    docstring)."""
    cfg = view.config
    matches = agreeing = pnp_inliers = 0
    pnp_start: Array | None = None  # the best keyframe's PnP pose, as a correction of the estimate
    matched: list[_Matches] = []
    agree: list[NDArray[np.bool_]] = []
    for image, T_ref_cam, cam in keyframes:
        p_kf, p_ref = sift_matches(image, view.image, AcrConfig())
        X_ref, ok = view.lift(p_ref)
        p_kf = p_kf[ok]
        matches += len(p_kf)
        if len(p_kf) == 0:
            continue
        m = _Matches(p_kf, X_ref, inverse(np.asarray(T_ref_cam, dtype=np.float64)), cam)
        matched.append(m)
        uv, front = cam.project(transform_points(m.T_cam_ref, X_ref))
        err = np.where(front, np.linalg.norm(uv - p_kf, axis=1), np.inf)
        agree.append(err <= cfg.verify_px)
        agreeing += int(np.count_nonzero(agree[-1]))
        if len(p_kf) < cfg.min_other_pose:
            continue
        found, rvec, tvec, inliers = cv2.solvePnPRansac(
            X_ref.astype(np.float64), p_kf.astype(np.float64), cam.K, None, reprojectionError=cfg.agree_px,
            iterationsCount=500, confidence=0.999, flags=cv2.SOLVEPNP_EPNP)
        if found and inliers is not None and len(inliers) > max(pnp_inliers, cfg.min_other_pose - 1):
            pnp_inliers = len(inliers)
            # this keyframe's PnP pose T_cam_ref is the estimate's corrected by δ: T_cam_ref δ⁻¹
            pnp_start = inverse(make_transform(cv2.Rodrigues(rvec)[0], tvec.ravel())) @ m.T_cam_ref
    # the pooled fit started at the estimate and at the PnP pose: the one with more matches within verify_px
    starts = [None] if pnp_start is None else [None, pnp_start]
    support, moved, correction, inlier = max((_corrected_pose(view, matched, start) for start in starts),
                                              key=lambda fit: fit[0])
    if support >= cfg.min_other_pose and support > agreeing and moved > cfg.verify_px:
        # the estimate's agreeing matches fit the other pose too (a near miss: a few right matches land within
        # verify_px of it), or they are too few: the matches put the camera elsewhere
        if agreeing < cfg.min_agreeing or np.count_nonzero(inlier & np.concatenate(agree)) * 2 >= agreeing:
            if correction is not None and rotation_angle_deg(correction[:3, :3]) > cfg.max_correction_deg:
                correction = None  # a look-alike elsewhere in the image, not a slide of the alignment
            return Verification("failed", matches, agreeing, support, moved, T_correction=correction)
        # the estimate and a pose far from it both fit the matches: a repetitive texture
        return Verification("ambiguous", matches, agreeing, support, moved)
    if agreeing >= cfg.min_agreeing:
        return Verification("verified", matches, agreeing, support, moved)
    shift = image_shift(view, keyframes)
    if shift.agreeing >= cfg.shift_min_keyframes and shift.norm_px > cfg.agree_px:
        return Verification("failed", matches, agreeing, support, moved, shift=shift)
    return Verification("ambiguous", matches, agreeing, support, moved, shift=shift)


@dataclass(frozen=True)
class _Matches:
    """One keyframe's matches: keypoints (n, 2) px, their reference points (n, 3) m, the estimate's
    ``T_cam_ref`` and the keyframe's camera."""

    p_kf: Array
    X_ref: Array
    T_cam_ref: Array
    camera: PinholeCamera


def _corrected_pose(view: ReferenceView, matched: Sequence[_Matches],
                    start: Array | None = None) -> tuple[int, float, Array | None, NDArray[np.bool_]]:
    """The pose the matches of all keyframes together put the estimate at: one rigid correction ``δ`` of the
    reference frame (every keyframe's pose is the estimate's, so they share its error), ``T_cam_ref δ⁻¹``, fitted by
    robust least squares (Cauchy at ``agree_px``, then at ``verify_px``) from ``start`` (default identity). Returns the
    matches within ``verify_px`` at the corrected pose, the mean displacement (px) of those features between
    the estimate's and the corrected pose's projections, ``δ`` and which matches (concatenated) are within
    ``verify_px`` ((0, NaN, None, none) without matches). Unlike a PnP per keyframe it pools the keyframes'
    matches, which alone are too few (an estimate a few cm off along a facade)."""
    cfg = view.config
    n = sum(len(m.p_kf) for m in matched)
    if n < cfg.min_agreeing:
        return 0, float("nan"), None, np.zeros(n, dtype=bool)
    T_ref_camref = view.T_ref_camref
    T_camref_ref = inverse(T_ref_camref)

    def project(xi: Array) -> list[Array]:
        delta_inv = T_ref_camref @ make_transform(so3_exp(-xi[:3]), np.zeros(3)) @ make_transform(
            np.eye(3), -xi[3:]) @ T_camref_ref  # (T_ref_camref exp(xi) T_camref_ref)^-1, xi in the reference camera
        out = []
        for m in matched:
            p = transform_points(m.T_cam_ref @ delta_inv, m.X_ref)
            out.append((m.camera.K[:2, :2] @ (p[:, :2] / np.maximum(p[:, 2:3], 1e-9)).T).T + m.camera.K[:2, 2])
        return out

    def residuals(xi: Array) -> Array:
        return np.concatenate([(uv - m.p_kf).ravel() for uv, m in zip(project(xi), matched, strict=True)])

    xi = np.zeros(6)
    if start is not None:  # δ = T_ref_camref · Tr(t) · R(ω) · T_camref_ref
        d = T_camref_ref @ start @ T_ref_camref
        xi = np.r_[cv2.Rodrigues(d[:3, :3])[0].ravel(), d[:3, 3]]
    for f_scale in (cfg.agree_px, cfg.verify_px):
        xi = least_squares(residuals, xi, loss="cauchy", f_scale=f_scale,
                           x_scale=np.r_[np.full(3, 0.01), np.full(3, 0.05)]).x
    uv_fit = np.concatenate(project(xi))
    uv_est = np.concatenate(project(np.zeros(6)))
    p_kf = np.concatenate([m.p_kf for m in matched])
    inlier = np.linalg.norm(uv_fit - p_kf, axis=1) <= cfg.verify_px
    if not inlier.any():
        return 0, float("nan"), None, inlier
    delta = T_ref_camref @ make_transform(np.eye(3), xi[3:]) @ make_transform(so3_exp(xi[:3]), np.zeros(3)) \
        @ T_camref_ref
    return (int(np.count_nonzero(inlier)), float(np.mean(np.linalg.norm(uv_fit[inlier] - uv_est[inlier], axis=1))),
            delta, inlier)


def _gradient_magnitude(image: ArrayLike) -> NDArray[np.float32]:
    img = np.asarray(image, dtype=np.float32)
    g = cv2.GaussianBlur(img.mean(axis=2) if img.ndim == 3 else img, (0, 0), 1.0)
    m = np.hypot(cv2.Sobel(g, cv2.CV_32F, 1, 0), cv2.Sobel(g, cv2.CV_32F, 0, 1))
    return (m / max(float(m.mean()), 1e-12)).astype(np.float32)


def image_shift(view: ReferenceView, keyframes: Sequence[tuple[ArrayLike, ArrayLike, PinholeCamera]]) -> ImageShift:
    """The shift of the keyframes' images against the reference image where the estimate (each keyframe's
    ``T_ref_cam``) puts them (module docstring): each keyframe is warped into the reference camera by the homography
    of the plane at the reference's median depth, then phase-correlated (gradient magnitudes, Hanning window, the
    reference masked to where the keyframe reaches)."""
    cfg = view.config
    ref = _gradient_magnitude(view.image)
    h, w = ref.shape
    window = cv2.createHanningWindow((w, h), cv2.CV_32F)
    finite = np.isfinite(view.depth_m)
    depth = float(np.median(view.depth_m[finite])) if finite.any() else 1.0
    K_ref_inv = np.linalg.inv(view.camera.K)
    shifts = []
    for image, T_ref_cam, cam in keyframes:
        T = inverse(np.asarray(T_ref_cam, dtype=np.float64)) @ view.T_ref_camref  # reference camera -> keyframe
        H = cam.K @ (T[:3, :3] + np.outer(T[:3, 3], [0.0, 0.0, 1.0 / depth])) @ K_ref_inv
        kf = _gradient_magnitude(image)
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        warped = cv2.warpPerspective(kf, H, (w, h), flags=flags)
        reach = cv2.warpPerspective(np.ones_like(kf), H, (w, h), flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP)
        (dx, dy), _ = cv2.phaseCorrelate(ref * reach, warped, window)
        shifts.append((dx, dy))
    if not shifts:
        return ImageShift((float("nan"), float("nan")), 0, 0)
    xy = np.asarray(shifts, dtype=np.float64)
    med = np.median(xy, axis=0)
    agreeing = int(np.count_nonzero(np.linalg.norm(xy - med, axis=1) <= cfg.agree_px))
    return ImageShift((float(med[0]), float(med[1])), agreeing, len(shifts))


def restart_fits(points_cur: ArrayLike, reference: ReferenceCloud, T_ref_cur: Array, sigma: float,
                 T_ref_cam: Array, view: ReferenceView, fast_config: FastAlignmentConfig) -> Restarts:
    """Restart the fast alignment from the estimate (``T_ref_cur``, ``sigma``) shifted along the current camera's x
    and y axes (``T_ref_cam``) by ``basin_shifts_depth`` times the current cloud's median depth, and compare each
    fit with the estimate's own (the alignment restarted at the estimate): its displacement of the current points in
    the reference image (``view``'s camera) and its fitness (module docstring). Raises
    :class:`~lightfast.racr.errors.AlignmentError` when the alignment fails at the estimate itself."""
    config = view.config
    pts = np.asarray(points_cur, dtype=np.float64)
    here = fast_align(pts, reference, T_ref_cur_init=T_ref_cur, sigma_init=sigma, config=fast_config)
    sample = pts[np.random.default_rng(0).choice(len(pts), min(len(pts), 2000), replace=False)]
    T_camref_ref = inverse(view.T_ref_camref)
    x_here = here.transform(sample)
    uv_here, ok_here = view.camera.project(transform_points(T_camref_ref, x_here))
    z_cam = transform_points(inverse(T_ref_cam), x_here)[:, 2]
    depth = float(np.median(z_cam[z_cam > 0])) if np.any(z_cam > 0) else 0.0
    found = Restarts(0)
    for d in config.basin_shifts_depth:
        for axis in (T_ref_cam[:3, 0], T_ref_cam[:3, 1]):
            for sign in (1.0, -1.0):
                start = np.array(T_ref_cur, dtype=np.float64)
                start[:3, 3] += sign * d * depth * axis
                try:
                    r = fast_align(pts, reference, T_ref_cur_init=start, sigma_init=sigma, config=fast_config)
                except AlignmentError:
                    continue
                found = replace(found, ran=found.ran + 1)
                if not r.converged or here.fitness <= 0.0:
                    continue
                uv, ok = view.camera.project(transform_points(T_camref_ref, r.transform(sample)))
                both = ok & ok_here
                px = float(np.mean(np.linalg.norm(uv[both] - uv_here[both], axis=1))) if both.any() else np.inf
                ratio = r.fitness / here.fitness
                if px <= config.agree_px:
                    continue  # the same fit
                if ratio * config.basin_fitness_ratio >= 1.0:
                    if np.isnan(found.better_ratio) or ratio > found.better_ratio:
                        found = replace(found, better_px=px, better_ratio=ratio)
                elif ratio >= config.basin_fitness_ratio:
                    if np.isnan(found.look_alike_px) or px < found.look_alike_px:
                        found = replace(found, look_alike_px=px, look_alike_ratio=ratio)
    return found
