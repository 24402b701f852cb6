"""The regime of a daylight recording, frame by frame at the TRUE pose: does colour (and the relit reference) matter?

Evaluation code: reads the true poses, mesh (``<recording>/mesh.ply``), sun (``truth.csv``) and window (``../scenes/
<scene>.openings.yaml``), which no method sees. Matrices and gradients at the tracker's working level (``TrackerConfig
().f2f_finest_level``: 160×120 of 320×240, where f2f and f2m stop), sun and depth at full resolution. Per frame:

* ``geo_ratio``, ``geo_weak``: λ_min/λ_max and the number of eigenvalues below :data:`WEAK_EIGEN_RATIO`·λ_max of the
  point-to-plane information JᵀJ (6×6) of E_G, J = (n, p × n) per level pixel with tracker depth: p the back-
  projected live depth (camera frame, m), n the true mesh normal on that pixel's ray (dropped if the mesh depth
  differs by more than ``depth_outlier_trunc_m``). Increment (ρ, φ): translation (m), rotation about the camera
  centre (rad), the tracker's left increment; rotation columns divided by the median depth d̄ (m per d̄·φ);
* ``photo_ratio``: the same for E_C, the tracker's photometric Jacobian (``kernels.linearize``, source = target =
  the live level at identity: Sobel gradients of grey in [0, 1], noise included); ``photo_weak_ratio``: λ_min of E_C's
  matrix within E_G's weak eigenvectors over its λ_max; ``photo_weak_signal_ratio``: the same after subtracting the
  sensor noise's expected E_C matrix (camera.yaml's noise model through the response; none: 0);
  ``photo_noise_share``: the noise's expected share of E_C's gradient energy; ``eq7_ratio``: λ_min/λ_max of
  J_CᵀJ_C + w_G J_GᵀJ_G, Eq. 7's Gauss–Newton matrix at the solution (Huber weights 1);
* ``depth_valid``: share of pixels with recorded depth; ``sunlit``: share whose surface (true mesh, pixel-centre ray)
  faces the sun and whose shadow ray to the sun centre leaves through the window; ``sunlit_no_depth``: share of the
  sunlit pixels without depth; ``sunlit_no_depth_image``: as a share of the image;
* ``motion_cm``, ``motion_deg``: camera-centre displacement and rotation angle from the previous true pose;
  ``cv_err_cm``, ``cv_err_deg``: error of the constant-velocity prediction T_{i-1}·(T_{i-2}⁻¹T_{i-1}) against T_i;
* ``illum_share``: Σ|∇log S|² / (Σ|∇log S|² + Σ|∇log ρ|²), ρ the true reflectance (grey) at the pixel's surface,
  S = x/ρ the shading, x the live grey linearised by the inverse response (saturated: x = 1; x < :data:`DARK_EXPOSURE`
  or no surface: left out): log-gradient energy a reflectance reference (refl-f2m) cannot explain, noise included;
* ``sun_edge_share``: share of the tracker's grey gradient energy at sun-patch edges (sunlit and shaded in 3×3).

:func:`analyze_recording` reads a ``lightfast sim daylight`` recording; :func:`summarize` gives medians, 10/90 %
percentiles and shares of frames (weak geometry, colour matters / fills the weak directions, sunlit depth loss).
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.daylight.crf import CameraResponse, load_crf
from lightfast.daylight.mesh import ReflectanceMesh, load_ply
from lightfast.daylight.openings import load_openings, openings_array, through_openings
from lightfast.eval.daylight import recording_frames, scene_of, sequence_files
from lightfast.eval.errors import DaylightEvalError
from lightfast.geometry import rotation_angle_deg
from lightfast.progress import track
from lightfast.raycast import RayCaster
from lightfast.tracking.errors import TrackingInputError
from lightfast.tracking.pipeline import TrackerConfig
from lightfast.tracking.rgbd_odometry import prepare_frame
from lightfast.tracking.rgbd_odometry.kernels import linearize

__all__ = ["FrameRegime", "RegimeScene", "analyze_frame", "analyze_recording", "conditioning",
           "load_scene", "motion_errors", "point_to_plane_information", "regime_check", "summarize",
           "table_markdown", "weak_direction_information"]

#: An eigenvalue below this share of λ_max is a weak direction: 10× less information than the best one in std.
WEAK_EIGEN_RATIO = 1e-2
#: Photometric λ_min/λ_max at least this: colour constrains every direction (same scale as a weak direction).
PHOTO_STRONG_RATIO = 1e-2
#: More than this share of the image sunlit without depth: E_G loses a large, bright (textured by light) area.
SUNLIT_LOSS_IMAGE_SHARE = 0.10
#: Linear exposure below which log-shading is not formed: 5 % of the auto-exposure's median (0.18), noise-dominated.
DARK_EXPOSURE = 0.01
#: Shadow-ray origins move this far along the surface normal (m): clear of the own triangle at float32 precision.
SHADOW_OFFSET_M = 1e-3
#: A frame is shadow-dominated when sun-patch edges hold at least this share of its grey gradient energy.
SHADOW_DOMINATED_SHARE = 0.5
#: A recording is in the paper's regime when at least this share of its frames are regime frames (weak geometry and
#: shadow-dominated) and at least this share lose a large sunlit area of depth (:func:`regime_check`).
REGIME_FRAME_SHARE = 0.20
_GREY = np.array([0.299, 0.587, 0.114])  # Rec. 601, as the tracker's grey
_NAN = math.nan


@dataclass(frozen=True)
class FrameRegime:
    """One frame's measures (see the module docstring); shares in [0, 1], NaN where undefined."""

    frame: int
    stamp_ns: int
    geo_ratio: float = _NAN
    geo_weak: float = _NAN
    photo_ratio: float = _NAN
    photo_weak_ratio: float = _NAN
    photo_weak_signal_ratio: float = _NAN
    eq7_ratio: float = _NAN
    photo_noise_share: float = _NAN
    depth_valid: float = _NAN
    sunlit: float = _NAN
    sunlit_no_depth: float = _NAN
    sunlit_no_depth_image: float = _NAN
    motion_cm: float = _NAN
    motion_deg: float = _NAN
    cv_err_cm: float = _NAN
    cv_err_deg: float = _NAN
    illum_share: float = _NAN
    sun_edge_share: float = _NAN
    pixels: int = 0  # working-level pixels in the geometric information


@dataclass(frozen=True, eq=False)
class RegimeScene:
    """The true scene: the reflectance mesh with its BVH and the window openings ((N, 3, 3), None: open scene)."""

    mesh: ReflectanceMesh
    openings: NDArray[np.float64] | None = None
    caster: RayCaster = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "caster", RayCaster(self.mesh.vertices_m, self.mesh.faces))


def _scaled(H: ArrayLike, depth_scale_m: float) -> NDArray[np.float64]:
    """H in (ρ, d̄·φ): the rotation rows and columns divided by ``depth_scale_m``, symmetrized."""
    s = np.array([1.0, 1.0, 1.0] + [1.0 / depth_scale_m] * 3)
    Hs = np.asarray(H, dtype=np.float64) * s[:, None] * s[None, :]
    return np.asarray(0.5 * (Hs + Hs.T))


def conditioning(H: ArrayLike, depth_scale_m: float) -> tuple[float, int]:
    """(λ_min/λ_max, weak directions) of a 6×6 information matrix in (ρ, φ), φ scaled by ``depth_scale_m``."""
    w = np.linalg.eigvalsh(_scaled(H, depth_scale_m))
    if not np.all(np.isfinite(w)) or w[-1] <= 0.0:
        return 0.0, 6
    return float(max(w[0], 0.0) / w[-1]), int(np.count_nonzero(w < WEAK_EIGEN_RATIO * w[-1]))


def weak_direction_information(H_photo: ArrayLike, H_geo: ArrayLike, depth_scale_m: float) -> float:
    """λ_min of ``H_photo`` restricted to the weak eigenvectors of ``H_geo`` over λ_max of ``H_photo`` (both scaled
    as in :func:`conditioning`): how well colour constrains what geometry leaves free; NaN if nothing is weak."""
    Hc, (w, V) = _scaled(H_photo, depth_scale_m), np.linalg.eigh(_scaled(H_geo, depth_scale_m))
    weak = w < WEAK_EIGEN_RATIO * max(w[-1], 0.0) if w[-1] > 0 else np.ones(6, dtype=bool)
    top = float(np.linalg.eigvalsh(Hc)[-1])
    if not weak.any() or top <= 0.0:
        return _NAN if not weak.any() else 0.0
    Vw = V[:, weak]
    return float(max(np.linalg.eigvalsh(Vw.T @ Hc @ Vw)[0], 0.0) / top)


def point_to_plane_information(points_cam: ArrayLike, normals_cam: ArrayLike) -> NDArray[np.float64]:
    """JᵀJ (6×6) of point-to-plane residuals n·(q − v) for a left increment (ρ, φ) at q = p: J = (n, p × n)."""
    p, n = np.asarray(points_cam, dtype=np.float64), np.asarray(normals_cam, dtype=np.float64)
    J = np.hstack([n, np.cross(p, n)])
    return J.T @ J


def motion_errors(poses: ArrayLike) -> NDArray[np.float64]:
    """(N, 4): per pose T_map_cam (N, 4, 4) the motion from the previous pose (cm, deg) and the constant-velocity
    prediction error (cm, deg); NaN where the previous poses are missing."""
    T = np.asarray(poses, dtype=np.float64)
    out = np.full((len(T), 4), np.nan)
    for i in range(1, len(T)):
        step = np.linalg.solve(T[i - 1], T[i])
        out[i, 0], out[i, 1] = 100.0 * np.linalg.norm(step[:3, 3]), float(rotation_angle_deg(step[:3, :3]))
        if i >= 2:
            pred = T[i - 1] @ np.linalg.solve(T[i - 2], T[i - 1])
            err = np.linalg.solve(T[i], pred)
            out[i, 2], out[i, 3] = 100.0 * np.linalg.norm(err[:3, 3]), float(rotation_angle_deg(err[:3, :3]))
    return out


def _cast(scene: RegimeScene, camera: PinholeCamera, T: NDArray[np.float64]
          ) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], Any]:
    """Pixel-centre rays of ``camera`` at ``T``: (hit, z-depth, points (map), facing normals (map), hits)."""
    d_cam = camera.ray_directions()
    d = d_cam @ T[:3, :3].T
    hits = scene.caster.intersect(T[:3, 3], d)
    z = np.where(hits.hit, hits.distance_m * d_cam[..., 2], 0.0)
    return hits.hit, z, hits.points(), hits.normals(facing=d), hits


def _sunlit(scene: RegimeScene, hit: NDArray[np.bool_], points: NDArray[np.float64], normals: NDArray[np.float64],
            sun: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Surface points in direct sun: facing the sun, shadow ray unoccluded and through a window opening."""
    lit = np.zeros(hit.shape, dtype=bool)
    if sun[2] <= 0.0:
        return lit
    facing = hit & (np.einsum("...j,j->...", np.nan_to_num(normals), sun) > 0.0)
    idx = np.nonzero(facing)
    if len(idx[0]) == 0:
        return lit
    org = points[idx] + SHADOW_OFFSET_M * normals[idx]
    ok = ~scene.caster.occluded(org, sun)
    if scene.openings is not None:
        ok &= through_openings(org, np.broadcast_to(sun, org.shape), scene.openings)
    lit[idx] = ok
    return lit


def _block(a: NDArray[Any], factor: int) -> NDArray[np.float64]:
    """Means of ``factor``×``factor`` blocks (the tracker pyramid's grey downsampling)."""
    h, w = a.shape[0] // factor, a.shape[1] // factor
    x = np.asarray(a, dtype=np.float64)[: h * factor, : w * factor]
    return x.reshape(h, factor, w, factor, *x.shape[2:]).mean(axis=(1, 3))


def _sobel_energy(img: NDArray[np.float64]) -> NDArray[np.float64]:
    gu = cv2.Sobel(img, cv2.CV_64F, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE) / 8.0
    gv = cv2.Sobel(img, cv2.CV_64F, 0, 1, ksize=3, borderType=cv2.BORDER_REPLICATE) / 8.0
    return np.asarray(gu * gu + gv * gv)


def _noise_variance(rgb: NDArray[np.uint8], crf: CameraResponse, noise: tuple[float, float], factor: int
                    ) -> NDArray[np.float64]:
    """Expected variance of one Sobel/8 axis of the sensor noise per working-level pixel: Poisson + read noise in
    exposure (``noise`` = electrons per unit exposure, read noise in exposure units) through f', plus 8-bit rounding,
    for grey in [0, 1] averaged over ``factor``² independent pixels; Var(Sobel/8) = 12/64 σ²."""
    x = np.stack([crf.inverse[rgb[..., c], c] for c in range(3)], axis=-1)
    var_v = crf.derivative(x) ** 2 * (x / noise[0] + noise[1] ** 2) + 1.0 / 12.0
    return 12.0 / 64.0 * _block(var_v @ _GREY**2 / 255.0**2, factor) / factor**2


def _noise_information(points: NDArray[np.float64], var: NDArray[np.float64], cam: PinholeCamera
                       ) -> NDArray[np.float64]:
    """E[J_CᵀJ_C] of noise gradients of variance ``var`` per axis: Σ var (a_u a_uᵀ + a_v a_vᵀ), a = ∂(u, v)/∂ξ."""
    x, y, z = points.T
    H, o = np.zeros((6, 6)), np.zeros_like(z)
    for g in (np.stack([cam.fx / z, o, -cam.fx * x / z**2], 1), np.stack([o, cam.fy / z, -cam.fy * y / z**2], 1)):
        A = np.hstack([g, np.cross(points, g)])
        H += (A * var[:, None]).T @ A
    return H


def _illumination_share(rgb: NDArray[np.uint8], crf: CameraResponse, rho: NDArray[np.float64],
                        hit: NDArray[np.bool_], factor: int) -> float:
    x = np.stack([crf.inverse[rgb[..., c], c] for c in range(3)], axis=-1) @ _GREY
    x, r, full = _block(x, factor), _block(rho @ _GREY, factor), _block(hit, factor) >= 1.0
    ok = full & (x >= DARK_EXPOSURE) & (r > 0.0)
    ok_grad = cv2.erode(ok.astype(np.uint8), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT,
                        borderValue=0).astype(bool)  # the Sobel window lies on valid pixels only
    if not ok_grad.any():
        return _NAN
    log_r = np.log(np.where(ok, r, 1.0))
    log_s = np.log(np.where(ok, x, 1.0)) - log_r
    e_s, e_r = float(_sobel_energy(log_s)[ok_grad].sum()), float(_sobel_energy(log_r)[ok_grad].sum())
    return e_s / (e_s + e_r) if e_s + e_r > 0 else _NAN


def analyze_frame(rgb: ArrayLike, depth_m: ArrayLike, camera: PinholeCamera, T_map_cam: ArrayLike,
                  scene: RegimeScene, sun_direction_map: ArrayLike, *, crf: CameraResponse | None = None,
                  noise: tuple[float, float] | None = None, config: TrackerConfig | None = None, frame: int = 0,
                  stamp_ns: int = 0) -> FrameRegime:
    """The measures of one frame at its true pose (motion left NaN: :func:`motion_errors` needs the sequence).

    ``rgb`` (H, W, 3) uint8, ``depth_m`` (H, W) metres (0 = invalid), both at ``camera``'s size; ``T_map_cam`` the
    true pose (optical frame → map, m); ``sun_direction_map`` towards the sun (map frame); ``crf`` the recording's
    response (None: ``illum_share`` NaN) and ``noise`` its sensor noise (see :func:`_noise_energy`; None or no
    ``crf``: ``photo_noise_share`` NaN)."""
    cfg = config if config is not None else TrackerConfig()
    img, depth = np.asarray(rgb), np.asarray(depth_m, dtype=np.float32)
    T = np.asarray(T_map_cam, dtype=np.float64)
    sun = np.asarray(sun_direction_map, dtype=np.float64)
    if img.shape != (camera.height, camera.width, 3) or img.dtype != np.uint8 or depth.shape != camera.shape:
        raise DaylightEvalError(f"frame {frame}: need uint8 RGB and depth of the camera's size {camera.shape}, got "
                                f"{img.shape} {img.dtype} and {depth.shape}")
    if T.shape != (4, 4) or not np.all(np.isfinite(T)) or sun.shape != (3,) or not np.linalg.norm(sun) > 0:
        raise DaylightEvalError(f"frame {frame}: need a finite 4x4 pose and a sun direction (3,)")
    sun = sun / np.linalg.norm(sun)
    # depth and sun, full resolution
    hit, _, points, normals, hits = _cast(scene, camera, T)
    lit = _sunlit(scene, hit, points, normals, sun)
    has_depth = np.isfinite(depth) & (depth > 0)
    n_px, n_lit = hit.size, int(lit.sum())
    res: dict[str, Any] = {
        "depth_valid": float(has_depth.mean()), "sunlit": n_lit / n_px,
        "sunlit_no_depth": float((lit & ~has_depth).sum() / n_lit) if n_lit else _NAN,
        "sunlit_no_depth_image": float((lit & ~has_depth).sum() / n_px)}
    level_index = cfg.f2f_finest_level
    factor = 2 ** level_index
    if crf is not None:
        tri = np.where(hit, hits.triangle_id, 0)
        uv = np.nan_to_num(hits.barycentric_uv.astype(np.float64))
        f, rho_v = scene.mesh.faces[tri], scene.mesh.reflectance
        rho = ((1 - uv[..., :1] - uv[..., 1:]) * rho_v[f[..., 0]] + uv[..., :1] * rho_v[f[..., 1]]
               + uv[..., 1:] * rho_v[f[..., 2]])
        res["illum_share"] = _illumination_share(img, crf, rho, hit, factor)
    try:
        level = prepare_frame(img, depth, camera, config=cfg, name=f"frame {frame}").levels[level_index]
    except TrackingInputError:  # no valid depth: E_G and E_C have no pixels
        return FrameRegime(frame, stamp_ns, **res)
    # sun-patch boundaries against the tracker's grey gradient energy at the working level
    energy = level.grey_grad[..., 1].astype(np.float64) ** 2 + level.grey_grad[..., 2].astype(np.float64) ** 2
    lit_l, shade_l = _block(lit, factor) > 0.0, _block(hit & ~lit, factor) > 0.0
    dil = np.ones((3, 3), np.uint8)
    edge = cv2.dilate(lit_l.astype(np.uint8), dil).astype(bool) & cv2.dilate(shade_l.astype(np.uint8), dil).astype(bool)
    total = float(energy.sum())
    res["sun_edge_share"] = float(energy[edge].sum()) / total if total > 0 else _NAN
    var = np.zeros(energy.shape) if crf is None or noise is None else _noise_variance(img, crf, noise, factor)
    with_depth = level.depth > 0  # E_C's pixels, row-major as level.points
    if crf is not None and noise is not None and energy[with_depth].sum() > 0:
        res["photo_noise_share"] = 2.0 * float(var[with_depth].sum() / energy[with_depth].sum())
    # information matrices at the working level
    cam_l = level.camera
    hit_l, z_l, _, nrm_l, _ = _cast(scene, cam_l, T)
    d_l = level.depth
    use = (d_l > 0) & hit_l & (np.abs(z_l - d_l) <= cfg.depth_outlier_trunc_m)
    if np.count_nonzero(use) < 6:
        return FrameRegime(frame, stamp_ns, **res)
    p = cam_l.backproject_depth(np.where(use, d_l, 0.0))[use]
    n = nrm_l[use] @ T[:3, :3]  # map → camera frame
    H_g = point_to_plane_information(p, n)
    H_c = linearize(level, level, np.eye(4), cfg, True, False).H
    d_med = float(np.median(p[:, 2]))
    res["geo_ratio"], res["geo_weak"] = conditioning(H_g, d_med)
    res["photo_ratio"] = conditioning(H_c, d_med)[0]
    res["eq7_ratio"] = conditioning(H_c + cfg.geometric_weight * H_g, d_med)[0]
    res["photo_weak_ratio"] = weak_direction_information(H_c, H_g, d_med)
    N = _noise_information(level.points.astype(np.float64), var[with_depth], cam_l)
    res["photo_weak_signal_ratio"] = weak_direction_information(H_c - N, H_g, d_med)
    return FrameRegime(frame, stamp_ns, pixels=len(p), **res)


def _sun_directions(seq_dir: Path) -> dict[int, NDArray[np.float64]]:
    try:
        with open(seq_dir / "truth.csv") as fh:
            return {int(r["stamp_ns"]): np.array([float(r[f"sun_dir_{a}"]) for a in "xyz"])
                    for r in csv.DictReader(fh)}
    except (OSError, KeyError, ValueError) as exc:
        raise DaylightEvalError(f"{seq_dir / 'truth.csv'}: no per-frame sun directions ({exc})") from exc


def load_scene(seq_dir: Path) -> RegimeScene:
    """The recording's true mesh and the window openings of its scene (if declared)."""
    mesh_path = seq_dir / "mesh.ply"
    if not mesh_path.is_file():
        raise DaylightEvalError(f"{seq_dir} has no true scene mesh (mesh.ply); make it with `lightfast sim daylight`")
    openings = seq_dir.parent / "scenes" / f"{scene_of(seq_dir)}.openings.yaml"
    arr = openings_array(load_openings(openings)) if openings.is_file() else None
    return RegimeScene(load_ply(mesh_path), arr if arr is not None and len(arr) else None)


def analyze_recording(seq_dir: Path, *, max_frames: int | None = None, progress: bool = False,
                      config: TrackerConfig | None = None) -> list[FrameRegime]:
    """:func:`analyze_frame` over the first ``max_frames`` frames of a recording, with the motion measures."""
    seq_dir = Path(seq_dir)
    files = sequence_files(seq_dir)
    info = json.loads(files["info"].read_text())
    n = int(info["frames"]) if max_frames is None else min(int(info["frames"]), max_frames)
    if n < 1:
        raise DaylightEvalError(f"{seq_dir}: nothing to analyse (max_frames={max_frames})")
    scene, crf, suns = load_scene(seq_dir), load_crf(files["crf"]), _sun_directions(seq_dir)
    cam_doc = yaml.safe_load(files["crf"].read_text())  # the simulator's noise model; load_crf checked the YAML
    noise = None
    if isinstance(cam_doc, dict) and all(k in cam_doc for k in ("full_well_e", "gain", "read_noise_e")):
        e_per_x = float(cam_doc["full_well_e"]) / float(cam_doc["gain"])
        noise = (e_per_x, float(cam_doc["read_noise_e"]) / e_per_x)
    out: list[FrameRegime] = []
    poses = []
    for i, (stamp, rgb, depth, camera, T_gt) in track(enumerate(recording_frames(files["bag"], limit=n)),
                                                      desc=seq_dir.name, total=n, enabled=progress, unit="frame"):
        if stamp not in suns:
            raise DaylightEvalError(f"{seq_dir}: frame {i} (stamp {stamp}) has no row in truth.csv")
        out.append(analyze_frame(rgb, depth, camera, T_gt, scene, suns[stamp], crf=crf, noise=noise,
                                 config=config, frame=i, stamp_ns=stamp))
        poses.append(T_gt)
    if not out:
        raise DaylightEvalError(f"{seq_dir}: no complete frames (colour + depth + camera_info + ground truth)")
    m = motion_errors(np.stack(poses))
    return [replace(f, motion_cm=float(a), motion_deg=float(b), cv_err_cm=float(c), cv_err_deg=float(d))
            for f, (a, b, c, d) in zip(out, m, strict=True)]


#: Rows of :func:`table_markdown` and the quantities of :func:`summarize`: (quantity, label, multiplier, format).
_ROWS = (
    ("geo_ratio", "E_G λmin/λmax", 1.0, ".2g"),
    ("geo_weak", "E_G weak directions", 1.0, ".0f"),
    ("photo_ratio", "E_C λmin/λmax", 1.0, ".2g"),
    ("photo_weak_ratio", "E_C in E_G's weak directions / E_C λmax", 1.0, ".2g"),
    ("photo_weak_signal_ratio", "the same without the sensor noise's expected information", 1.0, ".2g"),
    ("eq7_ratio", "Eq. 7 λmin/λmax", 1.0, ".2g"),
    ("photo_noise_share", "sensor-noise share of E_C gradient energy %", 100.0, ".1f"),
    ("depth_valid", "valid depth %", 100.0, ".1f"),
    ("sunlit", "sunlit %", 100.0, ".1f"),
    ("sunlit_no_depth", "sunlit w/o depth, % of sunlit", 100.0, ".1f"),
    ("sunlit_no_depth_image", "sunlit w/o depth, % of image", 100.0, ".1f"),
    ("motion_cm", "motion cm/frame", 1.0, ".2f"),
    ("motion_deg", "motion deg/frame", 1.0, ".2f"),
    ("cv_err_cm", "const.-velocity error cm", 1.0, ".2f"),
    ("cv_err_deg", "const.-velocity error deg", 1.0, ".2f"),
    ("illum_share", "illumination share of log-gradient energy %", 100.0, ".1f"),
    ("sun_edge_share", "grey gradient energy at sun edges %", 100.0, ".1f"),
)
_QUANTITIES = tuple(r[0] for r in _ROWS)


def summarize(frames: list[FrameRegime]) -> dict[str, Any]:
    """Median and 10/90 % percentiles of every measure (NaN frames left out) and the shares of frames with weak
    geometry (≥ 1 weak direction), where colour matters (weak geometry and ``photo_ratio`` ≥
    :data:`PHOTO_STRONG_RATIO`), where colour fills the weak directions (weak geometry and ``photo_weak_signal_ratio`` ≥
    :data:`PHOTO_STRONG_RATIO`) and with large sunlit depth loss (> :data:`SUNLIT_LOSS_IMAGE_SHARE` of the image)."""
    if not frames:
        raise DaylightEvalError("no frames to summarize")
    doc: dict[str, Any] = {"frames": len(frames), "quantities": {}}
    for q in _QUANTITIES:
        v = np.array([getattr(f, q) for f in frames], dtype=np.float64)
        v = v[np.isfinite(v)]
        doc["quantities"][q] = ({"median": float(np.median(v)), "p10": float(np.percentile(v, 10)),
                                 "p90": float(np.percentile(v, 90)), "n": len(v)} if len(v) else
                                {"median": _NAN, "p10": _NAN, "p90": _NAN, "n": 0})
    weak = np.array([f.geo_weak >= 1 for f in frames])
    photo = np.array([f.photo_ratio >= PHOTO_STRONG_RATIO for f in frames])
    doc["weak_geometry"] = float(weak.mean())
    doc["colour_matters"] = float((weak & photo).mean())
    doc["colour_fills_weak"] = float(np.mean([f.geo_weak >= 1 and f.photo_weak_signal_ratio >= PHOTO_STRONG_RATIO
                                              for f in frames]))
    doc["large_sunlit_depth_loss"] = float(np.mean([f.sunlit_no_depth_image > SUNLIT_LOSS_IMAGE_SHARE
                                                    for f in frames]))
    doc["thresholds"] = {"weak_eigen_ratio": WEAK_EIGEN_RATIO, "photo_strong_ratio": PHOTO_STRONG_RATIO,
                         "sunlit_loss_image_share": SUNLIT_LOSS_IMAGE_SHARE, "dark_exposure": DARK_EXPOSURE}
    return doc


def regime_check(frames: list[FrameRegime]) -> dict[str, Any]:
    """Is a recording in the regime where the paper's relit reference matters (Krawez et al. §I: tracking "may fail in
    frames where shadows induce the dominant image gradients"; §IV-D: depth is lost in direct sun)? Written down
    before the held-out recordings of issue 21 were rendered (benchmarks/results/HELDOUT.md).

    Regime frames: geometry leaves a direction free (``geo_weak`` ≥ 1: depth alone cannot hold the pose) and
    sun-patch edges hold at least :data:`SHADOW_DOMINATED_SHARE` of the grey gradient energy (a reflectance reference
    contradicts the image there, a relit one explains it). In the regime: regime frames and frames with large sunlit
    depth loss (> :data:`SUNLIT_LOSS_IMAGE_SHARE` of the image) each at least :data:`REGIME_FRAME_SHARE` of all
    frames. Returns both shares and ``in_regime``."""
    if not frames:
        raise DaylightEvalError("no frames to check")
    regime = [f.geo_weak >= 1 and f.sun_edge_share >= SHADOW_DOMINATED_SHARE for f in frames]  # NaN: False
    loss = [f.sunlit_no_depth_image > SUNLIT_LOSS_IMAGE_SHARE for f in frames]
    doc = {"regime_frames": float(np.mean(regime)), "large_sunlit_depth_loss": float(np.mean(loss)),
           "frames": len(frames)}
    doc["in_regime"] = bool(doc["regime_frames"] >= REGIME_FRAME_SHARE
                            and doc["large_sunlit_depth_loss"] >= REGIME_FRAME_SHARE)
    return doc


def table_markdown(summaries: dict[str, dict[str, Any]]) -> str:
    """Markdown: one column per recording, ``median [p10, p90]`` per measure, then the frame shares (%)."""
    names = list(summaries)
    lines = ["| measure (median [p10, p90]) | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for q, label, k, fmt in _ROWS:
        cells = []
        for s in names:
            d = summaries[s]["quantities"][q]
            cells.append(f"{k * d['median']:{fmt}} [{k * d['p10']:{fmt}}, {k * d['p90']:{fmt}}]")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    for key, label in (("weak_geometry", "frames with weak geometry %"), ("colour_matters", "frames where colour "
                       "matters %"), ("colour_fills_weak", "frames where colour fills E_G's weak directions %"),
                       ("large_sunlit_depth_loss", "frames with large sunlit depth loss %")):
        lines.append(f"| {label} | " + " | ".join(f"{100 * summaries[s][key]:.1f}" for s in names) + " |")
    lines.append("| frames | " + " | ".join(str(summaries[s]["frames"]) for s in names) + " |")
    return "\n".join(lines) + "\n"
