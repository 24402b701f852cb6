"""Teach & repeat of colour-constant stereo VT&R (paper §IV-B, IV-C) on a synthetic textured scene.

Scene: a 12 m straight "corridor" (a textured ground plane 1 m below the camera, two textured walls at x = ±3 m,
a far wall at z = 40 m) ray-cast per pixel (2× supersampled, linear radiance, exposure, Gaussian read noise,
8-bit) for a rectified stereo pair (320×240, f = 250 px, 24 cm baseline like the Bumblebee XB3). Surfaces have
multi-scale luminance and chroma texture (log-reflectance per channel).

Lighting. Per surface point the illuminant is a black body in Wien's approximation seen through the narrow-band
channels at the peak wavelengths of :class:`~lightfast.vtr.ColorConstantConfig` (615/530/460 nm), i.e. the model
of the paper's §III (Eq. 5): log E_c = log I − C2 / (λ_c T) − 5 log λ_c. A shadow-like pattern fixed to the
surfaces lowers the colour temperature T (at constant Planck intensity I) from ``T_lit`` to ``T_dim``; the teach
and the repeat have *different* patterns ("shadows opposite to the map's") and different ``T_lit``/``T_dim``.

Why the physics says greyscale fails and F_v/F_r do not (checked in
:func:`test_lighting_change_cancels_in_color_constant_images_only`): F = log R2 − α log R1 − β log R3 with β from
Eq. 10 has zero weight on 1/T (the temperature constraint of Eq. 7), so at constant I the pattern cancels in F_v
and F_r exactly (up to the paper's rounding of β: ≤ 0.01 log units); greyscale sees the pattern as a gain of
0.3–0.45 (shadows of −0.8 to −1.2 in log, against a luminance texture of 0.3): features and descriptors on shadow
edges change with the pattern. What this test does *not* show: real shadows change the illuminant *intensity*
too (skylight vs sun + sky), which F_v keeps with weight 1 − α − β = −0.06 and F_r with −0.6 (see
:mod:`lightfast.vtr.color_constant`); a realistic sun/sky shadow pattern is not part of this test (measured
separately: with it greyscale still fails, fused localizes most frames with fewer F_v inliers and F_r adds few).
"""
from __future__ import annotations

import hashlib
import itertools
import json
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

from lightfast.vtr import (
    ColorConstantConfig,
    MapCorruptError,
    MapError,
    MapExistsError,
    MapNotFoundError,
    MapStore,
    MapVersionError,
    PriorSupport,
    RepeatConfig,
    RepeatPipeline,
    RepeatResult,
    SourceFrontEnd,
    StereoCamera,
    StereoConfig,
    TeachConfig,
    TeachPipeline,
    VtrError,
    VtrInputError,
    color_constant,
    estimate_pose_stereo,
    source_weights,
)

W, H, F, B = 320, 240, 250.0, 0.24
K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (H - 1) / 2], [0.0, 0.0, 1.0]])
P_LEFT = np.c_[K, np.zeros(3)]
P_RIGHT = np.c_[K, [-F * B, 0.0, 0.0]]
C2_UM_K = 14388.0  # second radiation constant, µm·K
PEAK_UM = np.array([0.615, 0.530, 0.460])  # R, G, B: the peak wavelengths of ColorConstantConfig, µm
SUPERSAMPLE = 2  # 2 halves the aliasing of far texture but quadruples the rendering time
EXPOSURE = 360.0  # 8-bit levels per unit radiance (lit mean ~ 125)
NOISE_SIGMA = 0.7  # read noise, 8-bit levels
SKY_RGB = (2.0, 2.0, 2.2)  # above the walls: saturated, no features

TEACH_Z = np.round(np.arange(0.0, 10.81, 0.6), 3)  # teach frames along the path, m
REPEAT_Z = np.round(np.arange(0.2, 10.5, 0.5), 3)  # repeat frames, m
REPEAT_X, REPEAT_YAW_DEG = 0.3, 2.0  # lateral offset and heading change of the repeat path
STAMP_STEP_NS = 100_000_000
#: (pattern seed, T_lit, T_dim) per lighting condition; "changed" is the repeat under another illuminant pattern
LIGHTING = {"teach": (1, 5500.0, 4400.0), "changed": (2, 4800.0, 3900.0)}
#: Tolerances of the localized pose relative to the taught path (true keyframe pose → true camera pose)
TOL_MEDIAN_M, TOL_MAX_M, TOL_ROT_DEG = 0.03, 0.10, 0.5


# --------------------------------------------------------------------------------------------------------------
# Scene


def wien_gains(T_K: np.ndarray | float) -> np.ndarray:
    """(…, 3) R, G, B responses of a Wien source of temperature ``T_K`` at unit Planck intensity through
    narrow-band channels at ``PEAK_UM``, relative to green at 5500 K."""
    T = np.asarray(T_K, float)[..., None]
    e = PEAK_UM**-5 * np.exp(-C2_UM_K / (PEAK_UM * T))
    return e / (PEAK_UM[1] ** -5 * np.exp(-C2_UM_K / (PEAK_UM[1] * 5500.0)))


def smooth_noise(rng: np.random.Generator, h: int, w: int, scales: tuple[tuple[int, float], ...]) -> np.ndarray:
    out = np.zeros((h, w), np.float32)
    for s, a in scales:
        n = rng.normal(size=(h // s + 3, w // s + 3)).astype(np.float32)
        out += a * cv2.resize(n, ((w // s + 3) * s, (h // s + 3) * s), interpolation=cv2.INTER_CUBIC)[:h, :w]
    return out / out.std()


class Plane:
    """A textured rectangle origin + [0, size_u]·eu + [0, size_v]·ev with 2 cm texels."""

    def __init__(self, origin, eu, ev, size_u: float, size_v: float, seed: int, texel: float = 0.02) -> None:
        self.o, self.eu, self.ev = (np.asarray(x, float) for x in (origin, eu, ev))
        self.n = np.cross(self.eu, self.ev)
        self.texel, self.w, self.h, self.seed = texel, int(size_u / texel), int(size_v / texel), seed
        rng = np.random.default_rng(seed)
        scales = ((2, 1.0), (6, 0.7), (20, 0.5))
        lum = smooth_noise(rng, self.h, self.w, scales)
        chroma = np.stack([smooth_noise(rng, self.h, self.w, scales) for _ in range(3)], -1)
        chroma -= chroma.mean(-1, keepdims=True)
        self.albedo = np.exp(np.log(0.35) + 0.30 * lum[..., None] + 0.25 * chroma).astype(np.float32)

    def pattern(self, seed: int, scale_m: float = 0.4, soft: float = 0.3) -> np.ndarray:
        """Shadow-like pattern in [0, 1] fixed to the surface (1: lit)."""
        s = max(1, int(scale_m / self.texel))
        n = smooth_noise(np.random.default_rng(seed * 1000 + self.seed), self.h, self.w, ((s, 1.0), (3 * s, 0.7)))
        return np.clip(n / soft + 0.5, 0.0, 1.0)

    def radiance(self, seed: int, T_lit: float, T_dim: float) -> np.ndarray:
        """Albedo × illuminant, 1/T interpolated between T_lit (pattern 1) and T_dim (pattern 0)."""
        s = self.pattern(seed)
        T = 1.0 / (s / T_lit + (1.0 - s) / T_dim)
        return (self.albedo * wien_gains(T)).astype(np.float32)


def _sample(tex: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Bilinear samples (n, 3) of ``tex`` at texel coordinates (a, b) (cv2.remap on a padded 2-D block)."""
    n, cols = a.size, 1024
    rows = -(-n // cols)
    pad = rows * cols - n
    ma = np.pad(a.astype(np.float32), (0, pad)).reshape(rows, cols)
    mb = np.pad(b.astype(np.float32), (0, pad)).reshape(rows, cols)
    out = cv2.remap(tex, ma, mb, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(-1, 3)[:n]


class Scene:
    """The corridor of the module docstring, rendered for a rectified stereo camera of ``width`` × ``height`` px,
    focal length ``f_px`` and baseline ``B`` (left camera: principal point at the image centre, ``P_left``,
    ``P_right``); also used by ``benchmarks/vtr_localization.py`` at 640×480."""

    def __init__(self, width: int = W, height: int = H, f_px: float = F, supersample: int = SUPERSAMPLE) -> None:
        self.width, self.height, self.supersample = width, height, supersample
        self.K = np.array([[f_px, 0.0, (width - 1) / 2], [0.0, f_px, (height - 1) / 2], [0.0, 0.0, 1.0]])
        self.P_left = np.c_[self.K, np.zeros(3)]
        self.P_right = np.c_[self.K, [-f_px * B, 0.0, 0.0]]
        self.planes = [
            Plane((-4, 1.0, -2), (1, 0, 0), (0, 0, 1), 8, 42, 1),  # ground, 1 m below the camera (y down)
            Plane((-3, -2.5, -2), (0, 0, 1), (0, 1, 0), 42, 3.5, 2),  # left wall
            Plane((3, -2.5, -2), (0, 0, 1), (0, 1, 0), 42, 3.5, 3),  # right wall
            Plane((-4, -2.5, 40), (1, 0, 0), (0, 1, 0), 8, 3.5, 4),  # far wall
        ]
        self.textures = {name: [p.radiance(*args) for p in self.planes] for name, args in LIGHTING.items()}
        ss, Km = supersample, self.K
        u, v = np.meshgrid(np.arange(width * ss) + 0.5, np.arange(height * ss) + 0.5)
        # pixel rays (x, y, 1) in the camera frame
        self.ray_x = ((u / ss - 0.5 - Km[0, 2]) / Km[0, 0]).reshape(-1).astype(np.float32)
        self.ray_y = ((v / ss - 0.5 - Km[1, 2]) / Km[1, 1]).reshape(-1).astype(np.float32)

    def _ray_dot(self, a: np.ndarray) -> np.ndarray:
        """ray_world · axis = ray_cam · (Rᵀ axis) per pixel (no big matrix product: a threaded BLAS call crawls
        on a loaded machine)."""
        a = np.asarray(a, np.float32)
        return a[0] * self.ray_x + a[1] * self.ray_y + a[2]

    def render(self, lighting: str, T_world_cam: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        R, o = T_world_cam[:3, :3], T_world_cam[:3, 3]
        n_px = self.ray_x.shape[0]
        best = np.full(n_px, np.inf, np.float32)
        img = np.broadcast_to(np.asarray(SKY_RGB, np.float32), (n_px, 3)).copy()
        for p, tex in zip(self.planes, self.textures[lighting], strict=True):
            dn, du, dv = (self._ray_dot(R.T @ axis) for axis in (p.n, p.eu, p.ev))
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.float32((p.o - o) @ p.n) / dn
            a = (np.float32((o - p.o) @ p.eu) + t * du) * np.float32(1.0 / p.texel)
            b = (np.float32((o - p.o) @ p.ev) + t * dv) * np.float32(1.0 / p.texel)
            ok = (t > 0) & (t < best) & (a >= 0) & (a <= p.w - 1) & (b >= 0) & (b <= p.h - 1)
            if ok.any():
                img[ok] = _sample(tex, a[ok], b[ok])
                best[ok] = t[ok]
        ss = self.supersample
        img = img.reshape(self.height * ss, self.width * ss, 3)
        img = cv2.resize(img, (self.width, self.height), interpolation=cv2.INTER_AREA) * EXPOSURE
        img += rng.normal(0.0, NOISE_SIGMA, img.shape).astype(np.float32)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)

    def stereo(self, lighting: str, T_world_left: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
        T_right = T_world_left.copy()
        T_right[:3, 3] += T_world_left[:3, :3] @ np.array([B, 0.0, 0.0])
        return self.render(lighting, T_world_left, rng), self.render(lighting, T_right, rng)


def pose(x: float, z: float, yaw_deg: float = 0.0) -> np.ndarray:
    """Camera (optical frame: x right, y down, z forward) at (x, 0, z), turned by ``yaw_deg`` about y."""
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
    T[:3, 3] = (x, 0.0, z)
    return T


def rotation_deg(T: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(T[:3, :3]) - 1) / 2, -1, 1))))


# --------------------------------------------------------------------------------------------------------------
# Fixtures: one teach, the repeat frames' features per lighting, the repeat runs per (lighting, mode)


@dataclass
class Taught:
    path: Path
    teach_map: object
    features: list  # per teach frame: dict source -> StereoFeatures
    kf_pose: list  # true world pose of each keyframe


@pytest.fixture(scope="module")
def scene() -> Scene:
    return Scene()


@pytest.fixture(scope="module")
def taught(scene: Scene, tmp_path_factory) -> Taught:
    path = tmp_path_factory.mktemp("vtr") / "map"
    rng = np.random.default_rng(10)
    teach = TeachPipeline(path, TeachConfig(keyframe_distance_m=1.0))
    feats = []
    for i, z in enumerate(TEACH_Z):
        left, right = scene.stereo("teach", pose(0.0, z), rng)
        features = teach.front.process(left, right, P_LEFT, P_RIGHT)
        feats.append(features)
        teach.step_features(i * STAMP_STEP_NS, features, P_LEFT, P_RIGHT, (W, H))
    teach_map = teach.finish()
    kf_pose = [pose(0.0, TEACH_Z[kf.stamp_ns // STAMP_STEP_NS]) for kf in teach_map.keyframes]
    return Taught(path, teach_map, feats, kf_pose)


@pytest.fixture(scope="module")
def repeat_features(scene: Scene) -> dict[str, list]:
    """Front-end output (all three sources) of the repeat frames under the teach and the changed lighting."""
    front = SourceFrontEnd(("grey", "fv", "fr"), StereoConfig(), ColorConstantConfig())
    rng = np.random.default_rng(20)
    out = {}
    for lighting in ("teach", "changed"):
        out[lighting] = [front.process(*scene.stereo(lighting, pose(REPEAT_X, z, REPEAT_YAW_DEG), rng), P_LEFT,
                                       P_RIGHT) for z in REPEAT_Z]
    return out


@pytest.fixture(scope="module")
def black_features():
    """Front-end output of a black stereo pair (no landmarks: the search and the VO find nothing)."""
    front = SourceFrontEnd(("grey", "fv", "fr"), StereoConfig(), ColorConstantConfig())
    black = front.process(np.zeros((H, W, 3), np.uint8), np.zeros((H, W, 3), np.uint8), P_LEFT, P_RIGHT)
    front.close()
    return black


def _repeat_config(mode: str, **kw) -> RepeatConfig:
    return RepeatConfig(mode=mode, **({"match_radius_px": 25.0} | kw))  # 25 px at 320×240 ~ 50 px at 640×480


@pytest.fixture(scope="module")
def runs(taught: Taught, repeat_features):
    cache: dict[tuple[str, str], list[RepeatResult]] = {}

    def run(lighting: str, mode: str) -> list[RepeatResult]:
        if (lighting, mode) not in cache:
            # every mode starts at keyframe 0 (its window; the whole-map search is tested separately)
            rp = RepeatPipeline(taught.teach_map, _repeat_config(mode, initial_keyframe=0))
            cache[(lighting, mode)] = [rp.step_features(i * STAMP_STEP_NS, f, P_LEFT, P_RIGHT)
                                       for i, f in enumerate(repeat_features[lighting])]
        return cache[(lighting, mode)]

    return run


def pose_errors(taught: Taught, results: list[RepeatResult]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Translation (m) and rotation (deg) errors of the localized frames relative to the taught path, and the mask
    of localized frames."""
    t_err, r_err, loc = [], [], []
    for z, res in zip(REPEAT_Z, results, strict=True):
        loc.append(res.localized)
        if not res.localized:
            continue
        truth = np.linalg.inv(taught.kf_pose[res.keyframe_index]) @ pose(REPEAT_X, z, REPEAT_YAW_DEG)
        t_err.append(float(np.linalg.norm(res.T_kf_cam[:3, 3] - truth[:3, 3])))
        r_err.append(rotation_deg(np.linalg.inv(truth) @ res.T_kf_cam))
    return np.array(t_err), np.array(r_err), np.array(loc)


def summary(results: list[RepeatResult]) -> str:
    srcs = results[0].inliers_per_source.keys()
    med = {s: int(np.median([r.inliers_per_source[s] for r in results])) for s in srcs}
    return f"localized {sum(r.localized for r in results)}/{len(results)}, median inliers {med}"


# --------------------------------------------------------------------------------------------------------------
# Pose solver (shared by VO and localization)


def _stereo_measurements(P_ref: np.ndarray, T_ref_cur: np.ndarray, rng: np.random.Generator, noise_px: float):
    T_cur_ref = np.linalg.inv(T_ref_cur)
    p = P_ref @ T_cur_ref[:3, :3].T + T_cur_ref[:3, 3]
    uv = p[:, :2] / p[:, 2:] * F + K[:2, 2] + rng.normal(0, noise_px, (len(p), 2))
    d = F * B / p[:, 2] + rng.normal(0, noise_px / 3, len(p))
    return uv, d


def test_stereo_pose_solver_recovers_motion_among_outliers():
    rng = np.random.default_rng(3)
    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    n, n_out = 300, 150  # half of the correspondences are wrong
    P_ref = np.c_[rng.uniform(-3, 3, n), rng.uniform(-1.5, 1, n), rng.uniform(2, 15, n)]
    T_ref_cur = pose(0.2, 0.5, 3.0)
    uv, d = _stereo_measurements(P_ref, T_ref_cur, rng, 0.3)
    uv[:n_out] = rng.uniform([0, 0], [W, H], (n_out, 2))
    d[:n_out] = rng.uniform(1, 40, n_out)
    est = estimate_pose_stereo(P_ref, uv, d, camera, min_inliers=6)
    assert est.success
    assert np.linalg.norm(est.T_ref_cur[:3, 3] - T_ref_cur[:3, 3]) < 0.01
    assert rotation_deg(np.linalg.inv(T_ref_cur) @ est.T_ref_cur) < 0.1
    assert est.inliers[n_out:].mean() > 0.95 and est.inliers[:n_out].sum() <= 3
    assert est.position_std_m < 0.01 and est.rms_px < 1.0
    # only far points (150-200 m): the rotation is found, the position is not constrained -> flagged by its std
    P_far = np.c_[rng.uniform(-50, 50, 60), rng.uniform(-15, 5, 60), rng.uniform(150, 200, 60)]
    uv, d = _stereo_measurements(P_far, T_ref_cur, rng, 0.3)
    far = estimate_pose_stereo(P_far, uv, d, camera, min_inliers=6)
    assert far.position_std_m > 1.0, far.position_std_m
    # too few correspondences: a failure, not an exception
    assert not estimate_pose_stereo(P_ref[:4], uv[:4], d[:4], camera, min_inliers=6).success


def test_near_first_sampling_and_refined_hypotheses_fix_the_translation_far_points_leave_open():
    """A forward step of 0.8 m seen by 12 landmarks 3-6 m away and 80 at 30-60 m (the teach VO of the simulated
    routes: most inliers far, reference depths from one stereo pair). Far points fit nearly any translation, so
    the most-inliers hypothesis of an early-stopped RANSAC often rests on them alone and misses the near points;
    sampling near points first, running every hypothesis and refining the 16 best (the VO's options) finds the
    consensus that holds the near points too."""
    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    T_ref_cur = pose(0.05, 0.8, 2.0)
    errors: dict[str, list[float]] = {"plain": [], "vo": []}
    for seed in range(20):
        rng = np.random.default_rng(seed)
        P = np.r_[np.c_[rng.uniform(-2, 2, 12), rng.uniform(0.5, 1.2, 12), rng.uniform(3, 6, 12)],
                  np.c_[rng.uniform(-30, 30, 80), rng.uniform(-8, 1, 80), rng.uniform(30, 60, 80)]]
        uv_ref = P[:, :2] / P[:, 2:] * F + K[:2, 2]
        z_ref = F * B / (F * B / P[:, 2] + rng.normal(0, 0.3, len(P)))  # 0.3 px disparity noise
        P_ref = np.c_[(uv_ref - K[:2, 2]) / F * z_ref[:, None], z_ref]
        uv, d = _stereo_measurements(P, T_ref_cur, rng, 0.7)
        options = {"plain": {}, "vo": {"min_iterations": 500, "quality": -d, "ordered_fraction": 0.5,
                                       "refine_top": 16}}
        for name, opts in options.items():
            est = estimate_pose_stereo(P_ref, uv, d, camera, min_inliers=10, **opts)
            assert est.success
            errors[name].append(float(np.linalg.norm(est.T_ref_cur[:3, 3] - T_ref_cur[:3, 3])))
    plain, vo = np.array(errors["plain"]), np.array(errors["vo"])
    assert np.sum(plain > 0.1) >= 4 and np.sum(vo > 0.05) == 0, (plain.round(3), vo.round(3))
    assert np.median(vo) < 0.5 * np.median(plain)


def test_a_prior_keeps_its_consensus_unless_another_has_clearly_more_inliers():
    """Two consensus sets 1 m apart along the optical axis (as far points leave a valley of poses whose inlier
    counts differ by their sampling noise): without a prior the larger one wins; with a prior at the smaller one
    that one is kept while the larger has fewer than √n more inliers, not when it has twice as many, nor when the
    larger lies within the prior's own uncertainty or the prior's consensus is below its minimum."""
    rng = np.random.default_rng(11)
    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    T_a, T_b = pose(0.1, 0.3, 1.0), pose(0.1, 1.3, 1.0)
    prior = T_a.copy()
    prior[:3, 3] += [0.05, -0.03, 0.1]
    for n_b, kept in ((44, True), (80, False)):
        P, uv, d = _consensus_groups(rng, (T_a, 40), (T_b, n_b))
        runs = {"none": {}, "prior": {"prior": PriorSupport(prior, 1.0)},
                "uncertain prior": {"prior": PriorSupport(prior, 1.0, np.eye(3), 3.0)},  # 1 m std: cannot tell
                "weak": {"prior": PriorSupport(prior, 1.0, min_inliers=60)},
                "off": {"prior": PriorSupport(prior, 0.0)}}
        for name, opts in runs.items():
            est = estimate_pose_stereo(P, uv, d, camera, threshold_px=3.0, min_inliers=6, **opts)
            want = T_a if name == "prior" and kept else T_b
            assert est.success and np.linalg.norm(est.T_ref_cur[:3, 3] - want[:3, 3]) < 0.05, (n_b, name)
            group_in = est.inliers[:40] if want is T_a else est.inliers[40:]
            assert group_in.mean() > 0.95, (n_b, name, group_in.mean())


def _consensus_groups(rng: np.random.Generator, *groups: tuple[np.ndarray, int]):
    """Reference points 3-12 m away and their stereo measurements, concatenated: per ``(T_ref_cur, n)`` of
    ``groups`` ``n`` points seen from ``T_ref_cur`` (consensus sets of distinct poses)."""
    parts = []
    for T_ref_cur, n in groups:
        P_ref = np.c_[rng.uniform(-3, 3, n), rng.uniform(-1.5, 1, n), rng.uniform(3, 12, n)]
        parts.append((P_ref, *_stereo_measurements(P_ref, T_ref_cur, rng, 0.3)))
    return tuple(np.concatenate(x) for x in zip(*parts, strict=True))


def test_a_prior_with_a_coherent_consensus_of_its_own_is_kept_against_a_larger_disjoint_one():
    """A shadow moved since the teach: 80 matches coherent with a pose 1 m off along the optical axis, disjoint from
    the 40 at the prior (the ground the teach saw). By the counts the 80 win; with ``exclusive_inliers`` 30 the
    prior's 40 of its own keep it, with 50 they do not, nor when the other pose lies within the prior's own
    uncertainty."""
    rng = np.random.default_rng(5)
    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    T_a, T_b = pose(0.1, 0.3, 1.0), pose(0.1, 1.3, 1.0)
    P, uv, d = _consensus_groups(rng, (T_a, 40), (T_b, 80))
    prior = T_a.copy()
    prior[:3, 3] += [0.05, -0.03, 0.1]
    for name, support, want in (
            ("counts", PriorSupport(prior, 1.0), T_b),
            ("30 of its own", PriorSupport(prior, 1.0, exclusive_inliers=30), T_a),
            ("50 of its own", PriorSupport(prior, 1.0, exclusive_inliers=50), T_b),
            ("uncertain prior", PriorSupport(prior, 1.0, np.eye(3), 3.0, exclusive_inliers=30), T_b)):
        est = estimate_pose_stereo(P, uv, d, camera, threshold_px=3.0, min_inliers=6, prior=support)
        assert est.success and np.linalg.norm(est.T_ref_cur[:3, 3] - want[:3, 3]) < 0.05, name


def _few_correct_matches(rng: np.random.Generator, T_ref_cur: np.ndarray, n: int, n_in: int):
    """``n`` reference points and stereo measurements of which only the first ``n_in`` belong together; the others
    are keypoints (with their disparities) of other landmarks, as wrong matches."""
    P_ref = np.c_[rng.uniform(-3, 3, n), rng.uniform(-1.5, 1, n), rng.uniform(2, 12, n)]
    uv, d = _stereo_measurements(P_ref, T_ref_cur, rng, 0.3)
    out = slice(n_in, n)
    uv[out], d[out] = uv[out][rng.permutation(n - n_in)], d[out][rng.permutation(n - n_in)]
    return P_ref, uv, d


def _successes_by_fraction(seed0: int, sampler: Callable[[np.random.Generator], Callable[[float], dict]]
                           ) -> dict[float, int]:
    """Over 20 seeded trials of 12 correct matches among 200 (:func:`_few_correct_matches`): how often 1000 RANSAC
    hypotheses find them with fraction 0 (uniform) and 0.5 of the sampler whose options ``sampler(rng)(fraction)``
    gives (drawn after the matches); every success is checked to be at the right pose with ≤ 2 wrong inliers."""
    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    T_ref_cur = pose(0.1, 0.3, 1.0)
    n_in = 12
    found = {0.0: 0, 0.5: 0}
    for trial in range(20):
        rng = np.random.default_rng(seed0 + trial)
        P_ref, uv, d = _few_correct_matches(rng, T_ref_cur, 200, n_in)
        options = sampler(rng)
        for fraction in found:
            est = estimate_pose_stereo(P_ref, uv, d, camera, threshold_px=3.0, iterations=1000, min_inliers=6,
                                       seed=trial, **options(fraction))
            if est.success:
                assert np.linalg.norm(est.T_ref_cur[:3, 3] - T_ref_cur[:3, 3]) < 0.05
                assert est.inliers[n_in:].sum() <= 2
                found[fraction] += 1
    return found


def test_distance_consistent_sampling_finds_a_few_inliers_among_many_matches():
    """12 correct matches among 200 (the whole-map search under changed lighting): 1000 uniform hypotheses rarely
    find them; with half the hypotheses from distance-consistent triples nearly always, at the right pose."""
    found = _successes_by_fraction(100, lambda rng: lambda fraction: {"consistent_fraction": fraction})
    assert found[0.0] <= 6 and found[0.5] >= 16, found  # measured: 0 and 18 of 20


def test_prosac_sampling_draws_the_most_distinctive_matches_first():
    """PROSAC's schedule: hypothesis t holds the n-th best match and two better ones, n growing; with few matches
    no set size gets more hypotheses than it has distinct triples."""
    from lightfast.vtr.pose_estimation import _ProsacTriples

    quality = np.random.default_rng(5).permutation(10).astype(float)  # match i has rank quality[i]
    sampler = _ProsacTriples(quality)
    triples = np.concatenate([sampler.sample(7, np.random.default_rng(1)) for _ in range(3)])
    ranks = quality[triples]  # ranks of the drawn matches, the newest first
    n = ranks[:, 0] + 1
    assert ranks[0, 0] == 2 and np.all(np.diff(n) >= 0)  # the 3rd best first, then growing sets
    assert np.all(ranks[:, 1:] < ranks[:, :1])  # the two others are better than the newest
    assert n[9] == 5 and n[19] == 6 and n[20] == 7  # sizes 4, 5, 6 get C(3, 2), C(4, 2), C(5, 2) hypotheses
    big = _ProsacTriples(np.arange(164.0))
    assert big.sample(1000, np.random.default_rng(2)).max() < 40  # T_N = 200 000: 1000 hypotheses stay in the top


def test_prosac_sampling_finds_a_few_inliers_among_many_matches():
    """12 correct matches among 200 whose descriptor distances are lower on average (overlapping): half the
    hypotheses by PROSAC find them nearly always, 1000 uniform ones rarely."""

    def prosac(rng: np.random.Generator) -> Callable[[float], dict]:
        distance = np.r_[rng.normal(40, 12, 12), rng.normal(60, 12, 188)]  # Hamming-like, overlapping
        return lambda fraction: {"quality": distance, "ordered_fraction": fraction}

    found = _successes_by_fraction(200, prosac)
    assert found[0.0] <= 6 and found[0.5] >= 16, found
    P_ref, uv, d = _few_correct_matches(np.random.default_rng(0), pose(0.1, 0.3, 1.0), 200, 12)
    with pytest.raises(VtrInputError, match="quality"):
        estimate_pose_stereo(P_ref, uv, d, StereoCamera.from_projections(P_LEFT, P_RIGHT), quality=np.ones(199),
                             ordered_fraction=0.5)


def test_radius_pairs_equal_the_kd_tree_pairs():
    """The grid search of guided matching finds exactly the pairs within the radius (scipy's k-d tree as the
    reference), with points outside the image, NaN predictions and an empty side."""
    from scipy.spatial import cKDTree

    from lightfast.vtr.landmark_matching import radius_pairs

    rng = np.random.default_rng(4)
    a = np.c_[rng.uniform(-80, 720, 3000), rng.uniform(-80, 560, 3000)]
    a[:10] = np.nan
    b = np.c_[rng.uniform(0, 640, 800), rng.uniform(0, 480, 800)]
    for radius in (1e-4, 0.5, 12.0, 40.0, 1000.0):  # 1e-4: cells of extent / 1000, not of the radius
        ia, ib = radius_pairs(a, b, radius)
        ref = cKDTree(a[10:]).sparse_distance_matrix(cKDTree(b), radius, output_type="ndarray")
        assert set(zip(ia.tolist(), ib.tolist(), strict=True)) == set(
            zip((ref["i"] + 10).tolist(), ref["j"].tolist(), strict=True)), radius
    assert radius_pairs(a, b[:0], 40.0)[0].size == 0
    ia, ib = radius_pairs(b[:5], b[:5], 1e-4)  # each point pairs with itself only
    assert sorted(zip(ia.tolist(), ib.tolist(), strict=True)) == [(k, k) for k in range(5)]


# --------------------------------------------------------------------------------------------------------------
# Teach


def test_teach_map_keyframes_edges_and_sources(taught: Taught):
    m = taught.teach_map
    assert m.sources == ("grey", "fv", "fr") and m.feature == "orb"
    # 10.8 m at one keyframe per metre: with 0.6 m frames every 1.2 m (9 + the start), the last frame closes the map
    assert 9 <= len(m) <= 12
    for kf in m.keyframes:
        counts = kf.counts()
        assert counts["grey"] > 300 and counts["fv"] > 150 and counts["fr"] > 150, counts
    # the VO edges against the truth (frame-to-frame ORB VO at 320×240: ~1 % noise per step): each edge
    # (1.2 m, two VO steps) within 4 cm and 0.3 deg, the path length within 1.5 %
    for e in m.edges:
        truth = np.linalg.inv(taught.kf_pose[e.parent]) @ taught.kf_pose[e.child]
        err_m = np.linalg.norm(e.T_parent_child[:3, 3] - truth[:3, 3])
        err_deg = rotation_deg(np.linalg.inv(truth) @ e.T_parent_child)
        assert err_m < 0.04 and err_deg < 0.3, (e.parent, err_m, err_deg)
    assert abs(m.length_m - TEACH_Z[-1]) < 0.015 * TEACH_Z[-1], m.length_m
    # reloading gives the same map
    again = MapStore.load(taught.path)
    assert len(again) == len(m)
    for a, b in zip(again.keyframes, m.keyframes, strict=True):
        for s in m.sources:
            np.testing.assert_array_equal(a.landmarks[s].descriptors, b.landmarks[s].descriptors)
            np.testing.assert_array_equal(a.landmarks[s].points, b.landmarks[s].points)


def test_map_nearest_and_window(taught: Taught):
    m = taught.teach_map
    assert m.nearest(-5.0) == 0 and m.nearest(1e6) == len(m) - 1
    for k in range(len(m)):
        assert m.nearest(float(m.distance_m[k])) == k
        assert m.nearest(float(m.distance_m[k]) + 0.1) == k
    assert list(m.window(0, 2)) == [0, 1, 2]
    assert list(m.window(5, 2)) == [3, 4, 5, 6, 7]
    assert list(m.window(len(m) - 1, 1)) == [len(m) - 2, len(m) - 1]
    with pytest.raises(VtrInputError):
        m.window(len(m), 1)
    np.testing.assert_allclose(m.T_a_b(2, 5), np.linalg.inv(m.T_map_kf[2]) @ m.T_map_kf[5], atol=1e-12)


# --------------------------------------------------------------------------------------------------------------
# Repeat


def test_lighting_change_cancels_in_color_constant_images_only():
    """The physics of the test's lighting change (module docstring), on one textured patch under the lit and the
    dim illuminant of both conditions (unquantized): F_v and F_r change by a uniform offset only (spatial spread
    below 1 % of their texture contrast), log greyscale by −0.5 to −1.2, up to 4× its texture contrast."""
    rng = np.random.default_rng(0)
    albedo = np.exp(np.log(0.35) + 0.30 * rng.normal(size=(32, 32, 1)) + 0.25 * rng.normal(size=(32, 32, 3)))
    images = {}
    for name, (_, t_lit, t_dim) in LIGHTING.items():
        for which, T in (("lit", t_lit), ("dim", t_dim)):
            images[(name, which)] = albedo * wien_gains(T) * 100.0  # float rgb within (1, 255)
    ref = images[("teach", "lit")]
    cfg = ColorConstantConfig()
    for s in ("fv", "fr"):
        alpha, beta = source_weights(s, cfg)
        f_ref = color_constant(ref, alpha, beta, cfg)
        texture = float(np.std(f_ref.values))
        for key, rgb in images.items():
            f = color_constant(rgb, alpha, beta, cfg)
            both = f.valid & f_ref.valid
            assert both.mean() > 0.95
            diff = f.values[both] - f_ref.values[both]
            assert np.ptp(diff) < 0.01 * texture, (key, s, np.ptp(diff), texture)
    log_grey = {k: np.log(v @ [0.299, 0.587, 0.114]) for k, v in images.items()}
    texture = float(np.std(log_grey[("teach", "lit")]))
    steps = {k: float(np.mean(v - log_grey[("teach", "lit")])) for k, v in log_grey.items()}
    assert steps[("teach", "dim")] < -0.8 and steps[("changed", "dim")] < -1.1, steps
    assert -steps[("changed", "dim")] > 3.0 * texture, (steps, texture)


def test_repeat_under_teach_lighting_all_modes_localize(taught: Taught, runs):
    for mode in ("fused", "grey"):
        results = runs("teach", mode)
        t_err, r_err, loc = pose_errors(taught, results)
        assert loc.mean() >= 0.95, (mode, summary(results))
        assert np.median(t_err) < TOL_MEDIAN_M and t_err.max() < TOL_MAX_M, (mode, np.median(t_err), t_err.max())
        assert r_err.max() < TOL_ROT_DEG, (mode, r_err.max())
        assert not any(r.failure or r.searched_map for r in results), mode
    # the lateral offset of the repeat path is recovered (camera x in the keyframe frame)
    xs = [r.T_kf_cam[0, 3] for r in runs("teach", "fused") if r.localized]
    assert abs(np.median(xs) - REPEAT_X) < 0.02


def test_fused_localizes_under_illuminant_change_where_grey_fails(taught: Taught, runs):
    fused, grey, mcmanus = (runs("changed", m) for m in ("fused", "grey", "mcmanus"))
    t_err, r_err, loc = pose_errors(taught, fused)
    print("changed lighting:", "fused", summary(fused), "| grey", summary(grey), "| mcmanus", summary(mcmanus))
    assert loc.mean() >= 0.9, summary(fused)
    assert np.median(t_err) < TOL_MEDIAN_M and t_err.max() < TOL_MAX_M, (np.median(t_err), t_err.max())
    assert r_err.max() < TOL_ROT_DEG, r_err.max()
    # the colour-constant sources carry the localization, greyscale adds almost nothing (a tenth of their inliers)
    med = {s: np.median([r.inliers_per_source[s] for r in fused if r.localized]) for s in ("grey", "fv", "fr")}
    assert med["fv"] >= 20 and med["fr"] >= 20 and med["grey"] < 0.1 * min(med["fv"], med["fr"]), med
    # greyscale alone (legacy) never localizes correctly: none of its localizations is within the fused mode's
    # tolerance; they are wrong consensus sets among random matches (measured with the row-search stereo matching:
    # 9 of 21, 0.39-0.76 m off; none with descriptor matching, which triangulates fewer landmarks)
    g_err, _, g_loc = pose_errors(taught, grey)
    assert g_loc.mean() <= 0.5 and np.all(g_err > TOL_MAX_M), (summary(grey), g_err)
    # McManus et al. (colour-constant only when grey fails, one source): localizes, no better than fused
    _, _, m_loc = pose_errors(taught, mcmanus)
    assert m_loc.mean() >= 0.8 and m_loc.sum() <= loc.sum() + 1, summary(mcmanus)


def test_failure_after_distance_on_vo_then_whole_map_search(taught: Taught, repeat_features):
    """§IV-C with a short failure distance: greyscale under the changed lighting never localizes in its window,
    distance on VO accumulates, the failure is declared past the limit and the whole map is searched every frame;
    fused relocalizes from a kidnapped start (frames from the middle of the path) by the whole-map search."""
    # the stricter matching of earlier defaults: with ratio 0.9 and 3 px grey localizes once here (frame 6, 0.3 m off)
    grey = RepeatPipeline(taught.teach_map, _repeat_config("grey", max_distance_on_vo_m=1.2, initial_keyframe=0,
                                                           ratio=0.8, ransac_threshold_px=2.0))
    results = [grey.step_features(i, f, P_LEFT, P_RIGHT) for i, f in enumerate(repeat_features["changed"][:8])]
    assert not any(r.localized for r in results)
    d = [r.distance_on_vo_m for r in results]
    assert all(b >= a for a, b in itertools.pairwise(d))
    assert d[-1] == pytest.approx(REPEAT_Z[7] - REPEAT_Z[0], abs=0.1)  # VO distance = distance driven
    assert all(r.failure for r in results)  # never localized (the start window fails), then past the limit
    assert [r.searched_map for r in results] == [False] * 3 + [True] * 5  # > 1.2 m on VO from frame 3 on
    # kidnapped fused repeat: starts at frame 12 (z = 4.95 m), the whole map is searched on the first frame
    fused = RepeatPipeline(taught.teach_map, _repeat_config("fused"))
    first = fused.step_features(0, repeat_features["changed"][12], P_LEFT, P_RIGHT)
    assert first.searched_map and first.relocalized and first.localized and first.failure
    truth_z = REPEAT_Z[12]
    kf_z = taught.kf_pose[first.keyframe_index][2, 3]
    assert abs(kf_z + first.T_kf_cam[2, 3] - truth_z) < 0.1
    assert abs(kf_z - truth_z) <= 0.6  # the nearest keyframe along the path


@pytest.mark.parametrize("radius", [0, 2])
def test_whole_map_search_with_keyframe_windows(taught: Taught, repeat_features, radius: int):
    """The kidnapped search tries every keyframe with its ``search_window_radius`` neighbours, unguided, then
    verifies distinct places by guided matching in ``window_radius`` windows, and relocalizes."""
    from lightfast.vtr.localization import MapLocalizer

    config = _repeat_config("fused", search_window_radius=radius)
    rp = RepeatPipeline(taught.teach_map, config)
    windows, guided = [], []
    localize = MapLocalizer.localize

    def spy(self, features, camera, ref, window, prior, *args, **kwargs):
        (windows if prior is None else guided).append((ref, tuple(window)))
        return localize(self, features, camera, ref, window, prior, *args, **kwargs)

    n = len(taught.teach_map)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(MapLocalizer, "localize", spy)
        first = rp.step_features(0, repeat_features["changed"][12], P_LEFT, P_RIGHT)
    assert [w for _, w in windows] == [tuple(range(max(0, k - radius), min(n, k + radius + 1))) for k in range(n)]
    assert 1 <= len(guided) <= config.search_verify_places + 1
    assert all(w == tuple(taught.teach_map.window(k, config.window_radius)) for k, w in guided)
    assert first.searched_map and first.relocalized and first.localized
    kf_z = taught.kf_pose[first.keyframe_index][2, 3]
    assert abs(kf_z + first.T_kf_cam[2, 3] - REPEAT_Z[12]) < 0.1


def test_whole_map_search_matches_each_keyframe_once_with_the_windows_matches(taught: Taught, repeat_features):
    """In the search every keyframe's landmarks are matched to the frame once and combined per window; the matches
    of every window are exactly those of matching the window's landmarks at once (as outside the search)."""
    import lightfast.vtr.descriptor_matching as stereo_module
    from lightfast.vtr.localization import MapLocalizer

    # without the guided verification of the places found (its matching is not the search's)
    localizer = MapLocalizer(taught.teach_map, _repeat_config("fused", search_window_radius=2, search_verify_places=0))
    features = repeat_features["changed"][12]
    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    seen, distance_calls = [], []
    correspondences, distances = MapLocalizer.correspondences, stereo_module.descriptor_distances

    def spy(self, feats, source, cam, ref, window, prior):
        out = correspondences(self, feats, source, cam, ref, window, prior)
        seen.append((feats, source, ref, window, out))
        return out

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(MapLocalizer, "correspondences", spy)
        mp.setattr(stereo_module, "descriptor_distances", lambda *a: distance_calls.append(1) or distances(*a))
        found = localizer.search(features, camera)
    n = len(taught.teach_map)
    assert found.success and len(distance_calls) == n * len(localizer.sources)
    assert len(seen) == n * len(localizer.sources) and sum(len(out[0]) for *_, out in seen) > 100
    for feats, source, ref, window, out in seen:  # outside a search: the landmarks of the window matched at once
        direct = localizer.correspondences(feats, source, camera, ref, window, None)
        assert all(np.array_equal(a, b) for a, b in zip(out, direct, strict=True)), (ref, source)


def _with_look_alike(teach_map, gap_m: float = 20.0):
    """The taught route followed, ``gap_m`` further on, by a second stretch that looks exactly like it (the same
    keyframes' landmarks): a repetitive route in its purest form."""
    from lightfast.vtr.map_store import Edge, Keyframe, TeachMap

    kfs, n = list(teach_map.keyframes), len(teach_map.keyframes)
    jump = np.eye(4)
    jump[2, 3] = gap_m
    copies = [Keyframe(n + k.index, k.stamp_ns + 10**12, k.landmarks) for k in kfs]
    edges = [*teach_map.edges, Edge(n - 1, n, jump),
             *(Edge(n + e.parent, n + e.child, e.T_parent_child) for e in teach_map.edges)]
    return TeachMap(tuple(kfs + copies), tuple(edges), teach_map.sources, teach_map.feature, teach_map.descriptor_dim,
                    teach_map.P_left, teach_map.P_right, teach_map.image_size)


def test_whole_map_search_refuses_a_place_with_a_look_alike(taught: Taught, repeat_features):
    """Issue 19: the search accepted a place 107 m off on 6 matches. A place is accepted only with
    search_min_inliers and search_margin times the inliers of the best place farther than search_distinct_m: on a
    route that repeats itself the best place is refused (and the robot keeps searching), on the original route the
    same frame relocalizes."""
    from lightfast.vtr.visual_odometry import VoResult

    features = repeat_features["teach"][12]
    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    twice = _with_look_alike(taught.teach_map)
    for teach_map, accepted in ((taught.teach_map, True), (twice, False)):
        rp = RepeatPipeline(teach_map, _repeat_config("fused"))
        res = rp._localize_step(0, VoResult(np.eye(4), True, 0, 0, False, first=True), features, camera, None)
        assert res.searched_map and res.localized == accepted, (accepted, res.inliers_per_source)
        assert rp.refused_places == (0 if accepted else 1)
        loc = rp.localizer.search(features, camera)
        assert loc.success and (loc.runner_up_inliers >= loc.inliers / 1.5) == (not accepted)
        rp.close()


def test_overlapping_search_windows_are_the_same_place_not_a_look_alike(taught: Taught, repeat_features):
    """With windows of 4 keyframes on each side, windows centred more than search_distinct_m (3 m) from the best
    one share its keyframes and localize the camera at the same place with nearly as many inliers. Distinct places
    are told by where the camera is put along the path, not by the window's centre: the place is not refused."""
    from lightfast.vtr.localization import MapLocalizer

    localizer = MapLocalizer(taught.teach_map, _repeat_config("fused", search_window_radius=4, search_distinct_m=3.0))
    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    found, localize = [], MapLocalizer.localize

    def spy(self, *args, **kwargs):
        loc = localize(self, *args, **kwargs)
        if loc.success:
            found.append(loc)
        return loc

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(MapLocalizer, "localize", spy)
        best = localizer.search(repeat_features["teach"][12], camera)
    tm = taught.teach_map
    at = tm.along_path_m(best.ref_index, best.T_ref_cam)
    assert best.success and abs(at - (REPEAT_Z[12] - TEACH_Z[0])) < 0.1
    same_place = [f for f in found if abs(tm.distance_m[f.ref_index] - tm.distance_m[best.ref_index]) > 3.0
                  and abs(tm.along_path_m(f.ref_index, f.T_ref_cam) - at) < 0.2]
    assert max(f.inliers for f in same_place) >= best.inliers / 1.5  # the window-centre rule refused the place
    assert best.runner_up_inliers < best.inliers / 1.5, (best.inliers, best.runner_up_inliers)


def test_a_weak_place_of_the_search_needs_the_next_frame(taught: Taught, repeat_features):
    """A place of the whole-map search below search_accept_inliers is held, not accepted: the next frame's search
    must find it again where the VO motion puts it. Found again: relocalized; the next frame elsewhere (a look-alike
    won once, or the robot was moved): still lost, that place held instead."""
    from lightfast.vtr.visual_odometry import VoResult

    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    feats = repeat_features["teach"]
    motion = np.linalg.inv(pose(REPEAT_X, REPEAT_Z[12], REPEAT_YAW_DEG)) @ pose(REPEAT_X, REPEAT_Z[13],
                                                                                REPEAT_YAW_DEG)
    first = VoResult(np.eye(4), True, 0, 0, False, first=True)
    step = VoResult(motion, True, 50, 50, True)
    for accept_at, next_frame, expected in ((10**6, 13, True), (10**6, 16, False), (0, 13, True)):
        rp = RepeatPipeline(taught.teach_map, _repeat_config("fused", search_accept_inliers=accept_at))
        a = rp._localize_step(0, first, feats[12], camera, None)
        assert a.searched_map and a.localized == (accept_at == 0) and rp.held_places == (accept_at != 0), a
        if accept_at == 0:  # strong enough at once: nothing held, the next frame tracks locally
            rp.close()
            continue
        b = rp._localize_step(STAMP_STEP_NS, step, feats[next_frame], camera, None)
        assert b.searched_map and b.localized == expected and b.relocalized == expected, (next_frame, b)
        assert rp.held_places == (1 if expected else 2)
        if expected:
            kf_z = taught.kf_pose[b.keyframe_index][2, 3]
            assert abs(kf_z + b.T_kf_cam[2, 3] - REPEAT_Z[13]) < 0.1
        rp.close()


def test_a_held_place_is_found_again_by_a_windowed_localization_from_it(taught: Taught, repeat_features):
    """At dusk the unguided search misses the right place on most frames, while a windowed localization from the
    held place, moved by the VO motion, finds it. Planted: the search of the frame after the held place finds
    nothing. With search_track_held the place is found again by guided matching from it (relocalized without a
    search, pose within 0.1 m); without it the robot stays lost. When the images are not where the held place
    predicts (frame 16's: the robot 1.5 m farther, as from a look-alike's place), guided matching finds nothing
    within the gate: still lost."""
    from dataclasses import replace as dc_replace

    from lightfast.vtr.visual_odometry import VoResult

    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    feats = repeat_features["teach"]
    motion = np.linalg.inv(pose(REPEAT_X, REPEAT_Z[12], REPEAT_YAW_DEG)) @ pose(REPEAT_X, REPEAT_Z[13],
                                                                                REPEAT_YAW_DEG)
    for track, next_frame, expected in ((True, 13, True), (False, 13, False), (True, 16, False)):
        rp = RepeatPipeline(taught.teach_map, _repeat_config("fused", search_accept_inliers=10**6,
                                                             search_track_held=track))
        a = rp._localize_step(0, VoResult(np.eye(4), True, 0, 0, False, first=True), feats[12], camera, None)
        assert a.searched_map and not a.localized and rp.held_places == 1, a
        search = rp.localizer.search
        rp.localizer.search = lambda *args, search=search, **kw: dc_replace(search(*args, **kw), success=False)
        b = rp._localize_step(STAMP_STEP_NS, VoResult(motion, True, 50, 50, True), feats[next_frame], camera, None)
        assert b.localized == b.relocalized == expected and b.searched_map != expected, (track, next_frame, b)
        if expected:
            kf_z = taught.kf_pose[b.keyframe_index][2, 3]
            assert abs(kf_z + b.T_kf_cam[2, 3] - REPEAT_Z[13]) < 0.1
        rp.close()


def test_a_weak_place_is_held_over_a_frame_whose_search_finds_nothing(taught: Taught, repeat_features,
                                                                       black_features):
    """At dusk every other frame's search may find too little. A weak place held at frame 12 is found again by
    frame 14's search after a black frame 13 (no landmarks) when search_hold_frames is 2 or more, with the two VO
    steps between them; with 1 (the next frame only) frame 14's place is held anew instead."""
    from lightfast.vtr.visual_odometry import VoResult

    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    feats = repeat_features["teach"]
    truth = [pose(REPEAT_X, z, REPEAT_YAW_DEG) for z in REPEAT_Z]
    steps = [VoResult(np.linalg.inv(truth[i - 1]) @ truth[i], True, 50, 50, True) for i in (13, 14)]
    for hold, expected in ((3, True), (2, True), (1, False)):
        rp = RepeatPipeline(taught.teach_map, _repeat_config("fused", search_accept_inliers=10**6,
                                                             search_hold_frames=hold))
        a = rp._localize_step(0, VoResult(np.eye(4), True, 0, 0, False, first=True), feats[12], camera, None)
        dark = rp._localize_step(STAMP_STEP_NS, steps[0], black_features, camera, None)
        b = rp._localize_step(2 * STAMP_STEP_NS, steps[1], feats[14], camera, None)
        assert not a.localized and not dark.localized and b.relocalized == expected, (hold, b)
        assert rp.held_places == (1 if expected else 2)
        if expected:
            kf_z = taught.kf_pose[b.keyframe_index][2, 3]
            assert abs(kf_z + b.T_kf_cam[2, 3] - REPEAT_Z[14]) < 0.1
        rp.close()


def _off_along_z(search, z_std: float):
    """``search`` (a whole-map search) with its place moved 1.5 m along the camera's optical axis and a covariance
    of ``z_std`` (m) along it (5 cm across)."""
    from dataclasses import replace as dc_replace

    def off_search(*args, **kwargs):
        loc = search(*args, **kwargs)
        T = loc.T_ref_cam.copy()
        T[:3, 3] += T[:3, 2] * 1.5
        return dc_replace(loc, T_ref_cam=T, covariance=np.diag([0.05**2, 0.05**2, z_std**2] + [1e-6] * 3))

    return off_search


def test_a_search_place_off_along_the_optical_axis_is_mended_by_the_next_localization(taught: Taught,
                                                                                      repeat_features):
    """A place of the whole-map search found on far landmarks may be metres off along the optical axis, and its
    covariance says so. Planted: the search's place 1.5 m too far along z with a 1.5 m standard deviation there. The
    next frame's correct localization lies beyond the 0.5 m gate radius: with search_gate_sigmas (3) it is admitted
    and the pose mended; with 0, or when the place claims 5 cm along z, it is refused and the pose stays off
    (prior_gate_sigmas off, which would admit this strong localization as well)."""
    from lightfast.vtr.visual_odometry import VoResult

    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    feats = repeat_features["teach"]
    motion = np.linalg.inv(pose(REPEAT_X, REPEAT_Z[12], REPEAT_YAW_DEG)) @ pose(REPEAT_X, REPEAT_Z[13],
                                                                                REPEAT_YAW_DEG)
    for sigmas, z_std, mended in ((3.0, 1.5, True), (0.0, 1.5, False), (3.0, 0.05, False)):
        rp = RepeatPipeline(taught.teach_map, _repeat_config("fused", search_accept_inliers=0,
                                                             search_gate_sigmas=sigmas, prior_gate_sigmas=0.0,
                                                             localization_cov_scale=1.0))
        rp.localizer.search = _off_along_z(rp.localizer.search, z_std)
        a = rp._localize_step(0, VoResult(np.eye(4), True, 0, 0, False, first=True), feats[12], camera, None)
        b = rp._localize_step(STAMP_STEP_NS, VoResult(motion, True, 50, 50, True), feats[13], camera, None)
        kf_z = taught.kf_pose[b.keyframe_index][2, 3]
        error_m = abs(kf_z + b.T_kf_cam[2, 3] - REPEAT_Z[13])
        assert a.relocalized and b.localized == mended, (sigmas, z_std, b)
        assert error_m < 0.1 if mended else error_m > 1.2, (sigmas, z_std, error_m)
        rp.close()


def test_a_search_place_stays_open_until_a_strong_localization_confirms_it(taught: Taught, repeat_features):
    """A weak localization admitted next to a search place does not confirm it: the gate admitted it because it lay
    near that place. Planted: the search's place 1.5 m too far along z (1.5 m standard deviation there), then at
    frame 13 a weak localization (15 inliers, 1 m along z) at the prior itself. Frame 14's correct localization lies
    1.5 m from the prior: with search_confirm_inliers 30 the search gate is still open and admits it (pose mended);
    with 0 the weak one closed it and the pose stays off (prior_gate_sigmas off)."""
    from dataclasses import replace as dc_replace

    from lightfast.vtr.visual_odometry import VoResult

    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    feats = repeat_features["teach"]
    truth = [pose(REPEAT_X, z, REPEAT_YAW_DEG) for z in REPEAT_Z]
    steps = [VoResult(np.linalg.inv(truth[i - 1]) @ truth[i], True, 50, 50, True) for i in (13, 14)]
    weak_cov = np.diag([0.05**2, 0.05**2, 1.0**2] + [1e-6] * 3)
    for confirm, mended in ((30, True), (0, False)):
        rp = RepeatPipeline(taught.teach_map, _repeat_config(
            "fused", search_accept_inliers=0, search_gate_sigmas=3.0, prior_gate_sigmas=0.0,
            localization_cov_scale=1.0, search_confirm_inliers=confirm))
        search, localize = rp.localizer.search, rp.localizer.localize

        def weak_at_prior(features, camera, ref, window, prior, more=None, gate=None, localize=localize):
            loc = localize(features, camera, ref, window, prior, more, gate)
            return dc_replace(loc, T_ref_cam=prior.copy(), success=True, gated=False, inliers_per_source={"grey": 15},
                              covariance=weak_cov)

        rp.localizer.search = _off_along_z(search, 1.5)
        a = rp._localize_step(0, VoResult(np.eye(4), True, 0, 0, False, first=True), feats[12], camera, None)
        rp.localizer.localize = weak_at_prior
        b = rp._localize_step(STAMP_STEP_NS, steps[0], feats[13], camera, None)
        rp.localizer.localize = localize
        c = rp._localize_step(2 * STAMP_STEP_NS, steps[1], feats[14], camera, None)
        kf_z = taught.kf_pose[c.keyframe_index][2, 3]
        error_m = abs(kf_z + c.T_kf_cam[2, 3] - REPEAT_Z[14])
        assert a.relocalized and b.localized and c.localized == mended, (confirm, c)
        assert error_m < 0.1 if mended else error_m > 1.2, (confirm, error_m)
        rp.close()


def test_two_strong_localizations_admitted_far_from_the_prior_replace_it(taught: Taught, repeat_features):
    """Fused with an overconfident wrong prior, correct localizations pull the pose back only part of the way. Planted:
    the search's place 1.5 m too far along z (1.5 m standard deviation there, search_gate_sigmas off), and every
    windowed localization 1.5 m uncertain along z as well. Frame 13's correct localization is admitted by the
    Mahalanobis widening beyond the gate's radius and fused (halfway); frame 14's agrees with it after the VO motion
    and is admitted beyond the radius too: with confirm_admitted it replaces the prior (pose mended), without it is
    fused again and the pose stays more than 0.2 m off."""
    from dataclasses import replace as dc_replace

    from lightfast.vtr.visual_odometry import VoResult

    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    feats = repeat_features["teach"]
    truth = [pose(REPEAT_X, z, REPEAT_YAW_DEG) for z in REPEAT_Z]
    steps = [VoResult(np.linalg.inv(truth[i - 1]) @ truth[i], True, 50, 50, True) for i in (13, 14)]
    wide = np.diag([0.05**2, 0.05**2, 1.5**2] + [1e-6] * 3)
    for admitted, mended in ((True, True), (False, False)):
        rp = RepeatPipeline(taught.teach_map, _repeat_config(
            "fused", search_accept_inliers=0, search_gate_sigmas=0.0, prior_gate_sigmas=3.0,
            localization_cov_scale=1.0, confirm_admitted=admitted))
        search, localize = rp.localizer.search, rp.localizer.localize

        def uncertain(*args, localize=localize, **kwargs):
            return dc_replace(localize(*args, **kwargs), covariance=wide)

        rp.localizer.search, rp.localizer.localize = _off_along_z(search, 1.5), uncertain
        a = rp._localize_step(0, VoResult(np.eye(4), True, 0, 0, False, first=True), feats[12], camera, None)
        b = rp._localize_step(STAMP_STEP_NS, steps[0], feats[13], camera, None)
        c = rp._localize_step(2 * STAMP_STEP_NS, steps[1], feats[14], camera, None)
        errors_m = [abs(taught.kf_pose[r.keyframe_index][2, 3] + r.T_kf_cam[2, 3] - REPEAT_Z[i])
                    for r, i in ((b, 13), (c, 14))]
        assert a.relocalized and b.localized and c.localized, (admitted, b, c)
        assert 0.3 < errors_m[0] < 1.2, errors_m  # fused halfway
        assert errors_m[1] < 0.1 if mended else errors_m[1] > 0.2, (admitted, errors_m)
        rp.close()


def test_a_vo_step_gone_astray_along_the_optical_axis_is_mended_when_the_step_says_so(taught: Taught,
                                                                                     repeat_features):
    """A VO step 0.8 m too long along the optical axis puts the prior beyond the 0.63 m gate radius of the correct
    localization. When the step's own covariance says it is 0.5 m uncertain along that axis (a step resting on far
    points), the gate admits the localization (1.6 sigma) and the pose is mended; when the step claims 1 cm, or
    without prior_gate_sigmas, the localization is refused and the pose stays 0.8 m off (search_gate_sigmas off: the
    first frame is a place of the search)."""
    from lightfast.vtr.visual_odometry import VoResult

    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    feats = repeat_features["teach"]
    true_motion = np.linalg.inv(pose(REPEAT_X, REPEAT_Z[12], REPEAT_YAW_DEG)) @ pose(REPEAT_X, REPEAT_Z[13],
                                                                                     REPEAT_YAW_DEG)
    astray = true_motion.copy()
    astray[2, 3] += 0.8
    first = VoResult(np.eye(4), True, 0, 0, False, first=True)
    for z_std, sigmas, mended in ((0.5, 3.0, True), (0.01, 3.0, False), (0.5, 0.0, False)):
        step = VoResult(astray, True, 50, 50, True, covariance=np.diag([0.01**2, 0.01**2, z_std**2] + [1e-8] * 3))
        rp = RepeatPipeline(taught.teach_map, _repeat_config("fused", search_accept_inliers=0, vo_cov_scale=1.0,
                                                             prior_gate_sigmas=sigmas, search_gate_sigmas=0.0))
        assert rp._localize_step(0, first, feats[12], camera, None).localized
        b = rp._localize_step(STAMP_STEP_NS, step, feats[13], camera, None)
        kf_z = taught.kf_pose[b.keyframe_index][2, 3]
        error_m = abs(kf_z + b.T_kf_cam[2, 3] - REPEAT_Z[13])
        assert b.localized == mended and (error_m < 0.1 if mended else error_m > 0.7), (z_std, sigmas, error_m)
        rp.close()


def test_vo_rejects_a_step_whose_translation_jumps_from_the_last_one(taught: Taught):
    """Consecutive teach frames are 0.6 m apart along z: the step is kept after a step within 1 m of it (0.6 m, 1.5 m
    forward, 0.6 m sideways), rejected (a failure) after one 2 m forward or 0.6 m backwards, and kept again with the
    check off. A wrong reference does not lock the VO out: it is dropped after STALE_FRAMES failures."""
    from lightfast.vtr.visual_odometry import VisualOdometry, VisualOdometryConfig

    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    prev, cur = taught.features[5]["grey"], taught.features[6]["grey"]
    vo = VisualOdometry()
    for last, kept in ((None, True), ((0, 0, 0.6), True), ((0, 0, 1.5), True), ((0.6, 0, 0), True),
                       ((0, 0, 2.0), False), ((0, 0, -0.6), False)):
        r = vo.estimate(prev, cur, camera, last_translation_m=last)
        assert r.success == kept and r.num_inliers > 50, (last, r)
        if kept:
            assert abs(r.T_prev_cur[2, 3] - 0.6) < 0.03
    off = VisualOdometry(VisualOdometryConfig(max_step_change_m=0.0))
    assert off.estimate(prev, cur, camera, last_translation_m=(0, 0, 2.0)).success
    # a wrong reference (2.5 m) cannot lock the VO out: it is stale after STALE_FRAMES failures
    from lightfast.vtr.visual_odometry import STALE_FRAMES

    vo.process(taught.features[5]["grey"], camera)
    vo._velocity[2, 3], vo._failed = 2.5, 0
    results = [vo.process(taught.features[i]["grey"], camera) for i in range(6, 8 + STALE_FRAMES)]
    assert [r.success for r in results] == [False] * STALE_FRAMES + [True] * 2
    assert abs(results[-1].T_prev_cur[2, 3] - 0.6) < 0.03


def test_a_dark_stretch_follows_the_taught_path_at_the_last_speed(taught: Taught, repeat_features, black_features):
    """Four localized frames, then four black ones (no landmarks) whose VO fails with a wrong constant-velocity
    prediction (0.5 m sideways): with follow_path_on_vo_failure the prior moves along the taught path at the
    localized frames' 0.5 m per frame and ends within 0.1 m of the truth; repeating the VO prediction ends > 1 m
    off."""
    from lightfast.vtr.visual_odometry import VoResult

    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    truth = [pose(REPEAT_X, z, REPEAT_YAW_DEG) for z in REPEAT_Z]
    wrong = np.eye(4)
    wrong[:3, 3] = [0.5, 0.0, 0.0]
    for follow, within in ((True, True), (False, False)):
        rp = RepeatPipeline(taught.teach_map, _repeat_config("fused", initial_keyframe=0,
                                                             follow_path_on_vo_failure=follow))
        for i in range(4, 12):
            if i == 4:
                vo = VoResult(np.eye(4), False, 0, 0, False, first=True)
            elif i < 8:
                vo = VoResult(np.linalg.inv(truth[i - 1]) @ truth[i], True, 100, 100, True)
            else:
                vo = VoResult(wrong, False, 0, 0, False)
            frame = repeat_features["teach"][i] if i < 8 else black_features
            r = rp._localize_step(i * STAMP_STEP_NS, vo, frame, camera, None)
            assert r.localized == (i < 8), (follow, i)
        true_kf_cam = np.linalg.inv(taught.kf_pose[r.keyframe_index]) @ truth[11]
        error_m = float(np.linalg.norm(r.T_kf_cam[:3, 3] - true_kf_cam[:3, 3]))
        assert (error_m < 0.1) if within else (error_m > 1.0), (follow, error_m)
        rp.close()


def test_repeat_step_on_images_and_mcmanus_lazy_sources(taught: Taught, scene: Scene):
    """The node-facing call (images in) in every mode; mcmanus computes F_v/F_r only when grey fails."""
    rng = np.random.default_rng(30)
    frames = [scene.stereo("teach", pose(REPEAT_X, z, REPEAT_YAW_DEG), rng) for z in (1.0, 1.3)]
    for mode in ("fused", "grey", "mcmanus"):
        rp = RepeatPipeline(taught.teach_map, _repeat_config(mode))
        for i, (left, right) in enumerate(frames):
            res = rp.step(i * STAMP_STEP_NS, left, right, P_LEFT, P_RIGHT)
            assert res.localized, (mode, res)
            assert set(res.inliers_per_source) == ({"grey"} if mode == "grey" else {"grey", "fv", "fr"})
            assert "front_end" in res.timing_s and res.covariance is not None
            if mode == "mcmanus":
                assert res.inliers_per_source["fv"] == res.inliers_per_source["fr"] == 0
        rp.close()
    # black frames: no features, no crash, no localization
    rp = RepeatPipeline(taught.teach_map, _repeat_config("fused"))
    black = np.zeros((H, W, 3), np.uint8)
    res = rp.step(0, black, black, P_LEFT, P_RIGHT)
    assert not res.localized and res.failure and res.T_kf_cam is None
    with pytest.raises(VtrInputError):
        rp.step(1, black, black[:, :-1], P_LEFT, P_RIGHT)


# --------------------------------------------------------------------------------------------------------------
# Map store: corrupt maps and interrupted teaches


def _copy_map(taught: Taught, dst: Path) -> Path:
    MapStore.save(taught.teach_map, dst)
    return dst


def test_corrupt_or_missing_map_is_refused(taught: Taught, tmp_path: Path):
    with pytest.raises(MapNotFoundError):
        MapStore.load(tmp_path / "nothing")
    # truncated keyframe file
    p = _copy_map(taught, tmp_path / "truncated")
    kf = p / "keyframes" / "kf_000003.npz"
    kf.write_bytes(kf.read_bytes()[: kf.stat().st_size // 2])
    with pytest.raises(MapCorruptError, match="checksum"):
        MapStore.load(p)
    # a truncated file whose checksum was "fixed" is still refused (unreadable npz)
    m = json.loads((p / "manifest.json").read_text())
    m["keyframes"][3]["sha256"] = hashlib.sha256(kf.read_bytes()).hexdigest()
    (p / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(MapCorruptError, match="npz"):
        MapStore.load(p)
    # wrong version, wrong format
    p = _copy_map(taught, tmp_path / "version")
    m = json.loads((p / "manifest.json").read_text())
    (p / "manifest.json").write_text(json.dumps(m | {"version": 99}))
    with pytest.raises(MapVersionError, match="version 99"):
        MapStore.load(p)
    (p / "manifest.json").write_text(json.dumps(m | {"format": "something-else"}))
    with pytest.raises(MapVersionError):
        MapStore.load(p)
    # missing manifest (e.g. a teach that never finished)
    p = _copy_map(taught, tmp_path / "no_manifest")
    (p / "manifest.json").unlink()
    with pytest.raises(MapNotFoundError, match="manifest"):
        MapStore.load(p)
    # inconsistent counts, missing keyframe file, broken JSON
    p = _copy_map(taught, tmp_path / "counts")
    m = json.loads((p / "manifest.json").read_text())
    m["keyframes"][1]["counts"]["fv"] += 1
    (p / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(MapCorruptError, match="counts"):
        MapStore.load(p)
    m["keyframes"][1]["counts"]["fv"] -= 1
    m["num_keyframes"] += 1
    (p / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(MapCorruptError, match="num_keyframes"):
        MapStore.load(p)
    p = _copy_map(taught, tmp_path / "missing_kf")
    (p / "keyframes" / "kf_000002.npz").unlink()
    with pytest.raises(MapCorruptError, match="missing"):
        MapStore.load(p)
    (p / "manifest.json").write_text("{ not json")
    with pytest.raises(MapCorruptError, match="unreadable"):
        MapStore.load(p)
    # an npz with the wrong array shape (checksum updated): refused by the shape check
    p = _copy_map(taught, tmp_path / "shape")
    kf = p / "keyframes" / "kf_000000.npz"
    with np.load(kf, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["fv_points"] = arrays["fv_points"][:, :2]
    np.savez(kf.with_suffix(""), **arrays)  # np.savez appends .npz
    m = json.loads((p / "manifest.json").read_text())
    m["keyframes"][0]["sha256"] = hashlib.sha256(kf.read_bytes()).hexdigest()
    (p / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(MapCorruptError, match="points"):
        MapStore.load(p)
    assert issubclass(MapCorruptError, MapError) and issubclass(MapError, VtrError)
    assert zipfile.is_zipfile(_copy_map(taught, tmp_path / "ok") / "keyframes" / "kf_000000.npz")


def test_interrupted_teach_leaves_previous_map(taught: Taught, tmp_path: Path):
    path = _copy_map(taught, tmp_path / "map")
    before = MapStore.load(path)
    with pytest.raises(MapExistsError):
        TeachPipeline(path)
    teach = TeachPipeline(path, TeachConfig(keyframe_distance_m=0.5), overwrite=True)
    for i, f in enumerate(taught.features[:12]):  # 3.3 m: several keyframes written to the staging directory
        teach.step_features(i * STAMP_STEP_NS, f, P_LEFT, P_RIGHT, (W, H))
    assert teach.num_keyframes >= 5
    staging = teach._writer.staging_path
    assert staging.is_dir() and len(list((staging / "keyframes").glob("*.npz"))) == teach.num_keyframes
    # the "crash": the teach never finishes; the map at the path is the previous one, complete and valid
    after = MapStore.load(path)
    assert len(after) == len(before) and [k.stamp_ns for k in after.keyframes] == [k.stamp_ns for k in before.keyframes]
    # the keyframes written before the crash can be recovered into a new map
    recovered = MapStore.load(MapStore.recover(staging, tmp_path / "recovered"))
    assert len(recovered) == teach.num_keyframes and recovered.metadata["recovered_from"] == str(staging)
    # an aborted teach removes its staging directory and leaves the previous map
    teach.abort()
    assert not staging.exists() and len(MapStore.load(path)) == len(before)
    # a first teach interrupted before finish(): no map at all
    fresh = TeachPipeline(tmp_path / "fresh")
    for i, f in enumerate(taught.features[:5]):
        fresh.step_features(i * STAMP_STEP_NS, f, P_LEFT, P_RIGHT, (W, H))
    with pytest.raises(MapNotFoundError):
        MapStore.load(tmp_path / "fresh")
    # finishing replaces the map in one step
    m2 = fresh.finish()
    assert len(MapStore.load(tmp_path / "fresh")) == len(m2) >= 2
    with pytest.raises(VtrError):
        fresh.step_features(99, taught.features[0], P_LEFT, P_RIGHT, (W, H))


def test_teach_refuses_a_camera_change(taught: Taught, tmp_path: Path):
    teach = TeachPipeline(tmp_path / "cam")
    teach.step_features(0, taught.features[0], P_LEFT, P_RIGHT, (W, H))
    P2 = P_RIGHT.copy()
    P2[0, 3] *= 1.1
    with pytest.raises(VtrInputError, match="camera"):
        teach.step_features(1, taught.features[1], P_LEFT, P2, (W, H))
    teach.abort()
    with pytest.raises(VtrError, match="no frames"):
        TeachPipeline(tmp_path / "empty").finish()


def test_the_search_verifies_its_place_by_guided_matching(taught: Taught, repeat_features):
    """Unguided matching keeps a landmark only when its descriptor is the frame's nearest; under changed lighting
    the right place gathers few inliers that way. Verified by guided matching from its own pose
    (search_verify_places), the same place has more inliers and stays right; without verification the search
    returns the unguided localization."""
    from lightfast.vtr.localization import MapLocalizer

    camera = StereoCamera.from_projections(P_LEFT, P_RIGHT)
    features = repeat_features["changed"][12]
    places = {}
    for verify in (0, 3):
        localizer = MapLocalizer(taught.teach_map, _repeat_config("fused", search_verify_places=verify))
        places[verify] = localizer.search(features, camera)
    tm = taught.teach_map
    for loc in places.values():
        assert loc.success
        assert abs(tm.along_path_m(loc.ref_index, loc.T_ref_cam) - (REPEAT_Z[12] - TEACH_Z[0])) < 0.1
    assert places[3].inliers > places[0].inliers, (places[3].inliers, places[0].inliers)
