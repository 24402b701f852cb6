"""Simulated robotic platform and VSE (visual SLAM engine) stand-in for rACR (paper §3.1–3.3, §3.6), ROS-free.

Both hold the *truth* (true hand and camera poses, hand–eye X, the VSE's scale and drift) and hand out only what
the real devices would: reported hand poses, images, a scaled point cloud and VSE poses; the truth is exposed as
``true_*`` / ``truth_*`` attributes for the evaluation and tests only. Frames as in
:mod:`lightfast.racr.initialization`: ``world`` (the scene, metres, z up), ``base`` (fixed in the world),
``X = T_cam_hand``, ``T_world_cam = T_world_hand · X⁻¹``; a hand motion ``M_B = T_hand_hand'`` is executed as
``T_world_hand' = T_world_hand · M_B`` and moves the camera by ``M_A = T_cam_cam' = X M_B X⁻¹``.

:class:`PlatformSimulator` executes a commanded ``M = ⟨R, t⟩`` (``φ = log R``, θ = |φ|) with mechanical error::

    φ_true = (1 + b_r) φ + ε_r,   ε_r ~ N(0, σ_r² I₃),  σ_r = f_r θ + floor_r      (rad, per axis)
    t_true = (1 + b_t) t + ε_t,   ε_t ~ N(0, σ_t² I₃),  σ_t = f_t |t| + floor_t    (m, per axis)
    duration = settle_s + seconds_per_cm · 100 |t| + seconds_per_deg · θ_deg      (s, axes one after the other)

(``f`` = ``*_noise_frac``, ``floor`` = ``*_noise_floor_*``, ``b`` = ``*_bias_frac``; 1.5 s/cm is the paper's
platform, 0.5 s/° an assumption). The encoders report the commanded motion (``reported_hand_pose`` =
``T_base_hand``); the error accumulates in the true pose only. Non-rigid commands or ones over
``max_translation_m`` / ``max_rotation_deg`` raise :class:`PlatformError` and do not move the platform.

:class:`VseStandIn` plays a monocular direct SLAM engine (DSO, §3.3): VSE frame = the camera frame of its first
observation (or ``T_world_vse``), ``p_vse = (T_world_vse⁻¹ p_world) / s`` with ``s`` = ``scale_m_per_vse`` (m per
VSE unit, what Eq. 8 recovers). :meth:`VseStandIn.observe` renders ``n_keyframes`` keyframes at and around the
camera pose and returns a semi-dense cloud (DSO-like gradient point selection, true depth with noise and outliers,
intensity = grey / 255 in [0, 1]) and poses under a random-walk similarity drift per metre travelled. The renderer
is duck-typed (:class:`Renderer`, e.g. :class:`lightfast.sim.racr.render.RacrRenderer`): ``render(T_world_cam,
camera, lighting, sensor=, rng=)`` → ``image`` (H, W, 3) uint8 and ``depth_m`` (H, W) float (0: nothing hit).
Model details: docs/racr_simulator.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol, cast

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.config import Config, param
from lightfast.geometry import inverse, is_rotation, make_transform, project_to_so3, so3_exp, so3_log
from lightfast.sim.errors import PlatformError

__all__ = [
    "MotionRecord",
    "PlatformConfig",
    "PlatformSimulator",
    "Renderer",
    "VseConfig",
    "VseKeyframe",
    "VseObservation",
    "VseStandIn",
    "VseTruth",
    "motion_duration_s",
]

Array = NDArray[np.float64]


# ----------------------------------------------------------------------------------------------------------------
# platform


@dataclass(frozen=True)
class PlatformConfig(Config):
    """Mechanical error, speed and limits of the simulated robotic platform (see the module docstring)."""

    rotation_noise_frac: float = param(
        0.01, description="Per-axis std of the rotation error relative to the commanded angle.", min=0.0, max=1.0
    )
    rotation_noise_floor_deg: float = param(
        0.005, description="Per-axis std of the rotation error added to every non-zero motion, deg.", min=0.0
    )
    translation_noise_frac: float = param(
        0.01, description="Per-axis std of the translation error relative to the commanded length.", min=0.0, max=1.0
    )
    translation_noise_floor_m: float = param(
        5e-5, description="Per-axis std of the translation error added to every non-zero motion, m.", min=0.0
    )
    rotation_bias_frac: float = param(
        0.005, description="Systematic relative over- (+) or undershoot (-) of every rotation.", min=-0.5, max=0.5
    )
    translation_bias_frac: float = param(
        0.005, description="Systematic relative over- (+) or undershoot (-) of every translation.", min=-0.5, max=0.5
    )
    seconds_per_cm: float = param(1.5, description="Travel time per cm of translation (paper §3.6: 1.5 s).", min=0.0)
    seconds_per_deg: float = param(0.5, description="Travel time per degree of rotation (assumed), s.", min=0.0)
    settle_s: float = param(0.0, description="Fixed time added to every non-zero motion, s.", min=0.0)
    max_translation_m: float = param(0.5, description="Longest translation accepted in one command, m.", min=0.0)
    max_rotation_deg: float = param(90.0, description="Largest rotation accepted in one command, deg.", min=0.0,
                                    max=180.0)


def motion_duration_s(M_hand: ArrayLike, config: PlatformConfig | None = None) -> float:
    """Simulated time to execute the hand motion ``M_hand`` (4×4): ``settle + s/cm · |t| + s/deg · θ``; 0 for the
    identity."""
    cfg = config or PlatformConfig()
    M = np.asarray(M_hand, dtype=np.float64)
    length_m = float(np.linalg.norm(M[:3, 3]))
    angle_deg = math.degrees(float(np.linalg.norm(so3_log(project_to_so3(M[:3, :3])))))
    if length_m == 0.0 and angle_deg == 0.0:
        return 0.0
    return cfg.settle_s + cfg.seconds_per_cm * 100.0 * length_m + cfg.seconds_per_deg * angle_deg


@dataclass(frozen=True)
class MotionRecord:
    """One executed command: what was commanded (= what the encoders saw), what truly happened, when, how long."""

    M_commanded: Array
    M_true: Array
    start_s: float
    duration_s: float


def _rigid(T: ArrayLike, name: str, *, atol: float = 1e-6) -> Array:
    try:
        a = np.array(T, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise PlatformError(f"{name} must be a 4x4 rigid transform: {exc}") from None
    if a.shape != (4, 4):
        raise PlatformError(f"{name} must be a 4x4 rigid transform, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise PlatformError(f"{name} has non-finite entries")
    if not np.allclose(a[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9) or not is_rotation(a[:3, :3], atol=atol):
        raise PlatformError(f"{name} is not a rigid transform (rotation block not orthonormal or bad bottom row)")
    a[:3, :3] = project_to_so3(a[:3, :3])
    return a


class PlatformSimulator:
    """A robotic platform carrying a camera at the hand–eye transform ``X = T_cam_hand``.

    Args:
        T_world_hand: the true initial hand pose.
        T_cam_hand: the hand–eye transform X (truth; rACR must estimate it).
        config: mechanical error, speed and limits.
        T_world_base: the platform base in the world (the reported poses are in the base frame); identity if None.
        seed: seed of the mechanical-error generator.
    """

    def __init__(self, T_world_hand: ArrayLike, T_cam_hand: ArrayLike, *, config: PlatformConfig | None = None,
                 T_world_base: ArrayLike | None = None, seed: int = 0) -> None:
        self.config = config or PlatformConfig()
        self._T_world_hand = _rigid(T_world_hand, "T_world_hand")
        self._X = _rigid(T_cam_hand, "T_cam_hand")
        self._T_world_base = np.eye(4) if T_world_base is None else _rigid(T_world_base, "T_world_base")
        self._T_base_hand_reported = inverse(self._T_world_base) @ self._T_world_hand
        self._rng = np.random.default_rng(seed)
        self.clock_s = 0.0
        self.motions: list[MotionRecord] = []

    # --- what a real platform reports ------------------------------------------------------------------------

    @property
    def reported_hand_pose(self) -> Array:
        """``T_base_hand`` as the encoders report it (product of the commanded motions)."""
        return self._T_base_hand_reported.copy()

    # --- truth (evaluation only) ---------------------------------------------------------------------------------

    @property
    def true_hand_pose(self) -> Array:
        """The true ``T_world_hand`` (truth)."""
        return self._T_world_hand.copy()

    @property
    def true_camera_pose(self) -> Array:
        """The true ``T_world_cam = T_world_hand · X⁻¹`` (truth)."""
        return self._T_world_hand @ inverse(self._X)

    @property
    def truth_T_cam_hand(self) -> Array:
        """The true hand–eye transform X (truth)."""
        return self._X.copy()

    @property
    def truth_T_world_base(self) -> Array:
        return self._T_world_base.copy()

    # --- motion ------------------------------------------------------------------------------------------------

    def perturb(self, M_hand: ArrayLike) -> Array:
        """The motion the mechanics really perform for the command ``M_hand`` (draws from the error model)."""
        cfg = self.config
        M = _rigid(M_hand, "M_hand", atol=1e-4)
        phi = so3_log(M[:3, :3])
        theta = float(np.linalg.norm(phi))
        t = M[:3, 3]
        length = float(np.linalg.norm(t))
        if theta == 0.0 and length == 0.0:
            return np.eye(4)
        sr = cfg.rotation_noise_frac * theta + math.radians(cfg.rotation_noise_floor_deg)
        st = cfg.translation_noise_frac * length + cfg.translation_noise_floor_m
        phi_true = (1.0 + cfg.rotation_bias_frac) * phi + self._rng.normal(0.0, sr, 3)
        t_true = (1.0 + cfg.translation_bias_frac) * t + self._rng.normal(0.0, st, 3)
        return make_transform(so3_exp(phi_true), t_true)

    def execute(self, M_hand: ArrayLike) -> float:
        """Execute the hand motion ``M_hand = T_hand_hand'`` with mechanical error; returns its simulated duration
        in seconds (also added to :attr:`clock_s`). Raises :class:`PlatformError` for garbage or too large
        motions, without moving."""
        M = _rigid(M_hand, "M_hand", atol=1e-4)
        angle_deg = math.degrees(float(np.linalg.norm(so3_log(M[:3, :3]))))
        length = float(np.linalg.norm(M[:3, 3]))
        if length > self.config.max_translation_m:
            raise PlatformError(f"refused: translation {length:.4f} m exceeds max_translation_m="
                                f"{self.config.max_translation_m}")
        if angle_deg > self.config.max_rotation_deg:
            raise PlatformError(f"refused: rotation {angle_deg:.3f} deg exceeds max_rotation_deg="
                                f"{self.config.max_rotation_deg}")
        M_true = self.perturb(M)
        duration = motion_duration_s(M, self.config)
        self.motions.append(MotionRecord(M.copy(), M_true, self.clock_s, duration))
        self._T_world_hand = self._T_world_hand @ M_true
        self._T_world_hand[:3, :3] = project_to_so3(self._T_world_hand[:3, :3])
        self._T_base_hand_reported = self._T_base_hand_reported @ M
        self._T_base_hand_reported[:3, :3] = project_to_so3(self._T_base_hand_reported[:3, :3])
        self.clock_s += duration
        return duration


# ----------------------------------------------------------------------------------------------------------------
# VSE stand-in


class Renderer(Protocol):
    """What :class:`VseStandIn` needs from a renderer."""

    def render(self, T_world_cam: ArrayLike, camera: PinholeCamera, lighting: Any, *, sensor: Any = None,
               rng: np.random.Generator | None = None) -> Any: ...


@dataclass(frozen=True)
class VseConfig(Config):
    """Behaviour of the VSE stand-in (see the module docstring)."""

    n_keyframes: int = param(4, description="Keyframes rendered per observation (current pose + neighbours).",
                             min=1, max=16)
    keyframe_baseline_m: float = param(0.03, description="Sideways offset of the neighbouring keyframes, m.",
                                       min=0.0)
    keyframe_rotation_deg: float = param(1.5, description="Rotation of the neighbouring keyframes, deg.", min=0.0)
    image_scale: float = param(1.0, description="Keyframe image size relative to the camera's.", min=0.05, max=1.0)
    gradient_threshold: float = param(
        12.0, description="Least Sobel gradient magnitude of a selected pixel, grey levels per pixel.", min=0.0
    )
    block_px: int = param(4, description="One point per block of this many pixels squared, at most.", min=1)
    max_points: int = param(60000, description="Most points in one observation's cloud.", min=1)
    depth_noise_rel: float = param(0.002, description="Relative depth noise (std) of the points.", min=0.0)
    pixel_noise_px: float = param(0.2, description="Pixel position noise (std) of the points, px.", min=0.0)
    outlier_fraction: float = param(0.005, description="Fraction of points with a gross depth error.", min=0.0,
                                    max=1.0)
    drift_rotation_deg_per_m: float = param(0.5, description="Rotation drift (std) per metre of camera path, deg.",
                                            min=0.0)
    drift_translation_per_m: float = param(0.01, description="Translation drift (std) per metre of path (m/m).",
                                           min=0.0)
    drift_scale_per_m: float = param(0.01, description="Relative scale drift (std) per metre of path.", min=0.0)
    pose_noise_deg: float = param(0.02, description="Independent rotation jitter (std) of every VSE pose, deg.",
                                  min=0.0)
    pose_noise_m: float = param(2e-4, description="Independent translation jitter (std) of every VSE pose, m.",
                                min=0.0)


@dataclass(frozen=True, eq=False)
class VseKeyframe:
    """A keyframe as the VSE publishes it: grey image, its camera and its pose ``T_vse_cam`` (VSE units)."""

    image: NDArray[np.uint8]
    camera: PinholeCamera
    T_vse_cam: Array


@dataclass(frozen=True, eq=False)
class VseObservation:
    """What the VSE publishes after an observation (no truth in here).

    ``points_vse`` (N, 3) float32 in the VSE frame and units; ``intensity`` (N,) float32 grey value in [0, 1];
    ``keyframes``; ``T_vse_cam`` the current camera pose (the first keyframe's); ``stamp_s`` the platform clock.
    """

    points_vse: NDArray[np.float32]
    intensity: NDArray[np.float32]
    keyframes: tuple[VseKeyframe, ...]
    T_vse_cam: Array
    stamp_s: float = 0.0


@dataclass(eq=False)
class VseTruth:
    """The VSE stand-in's truth (evaluation and tests only).

    ``T_world_vse`` (the true VSE frame), ``scale_m_per_vse`` (s), ``drift`` (4×4 similarity ``[s_D R_D, t_D]``
    from the true scaled VSE frame to the reported one), and for the last observation the true world points
    ``points_world`` (N, 3) (before noise) and true keyframe poses ``T_world_keyframes`` (K, 4, 4).
    """

    T_world_vse: Array
    scale_m_per_vse: float
    drift: Array = field(default_factory=lambda: np.eye(4))
    points_world: Array = field(default_factory=lambda: np.zeros((0, 3)))
    T_world_keyframes: Array = field(default_factory=lambda: np.zeros((0, 4, 4)))


def _sim_apply(S: Array, T: Array) -> Array:
    """Apply the similarity ``S = [s R, t]`` to the pose ``T``: ``⟨R_S R_T, s R_S t_T + t_S⟩`` (a rigid pose)."""
    scale = float(np.cbrt(np.linalg.det(S[:3, :3])))
    R = S[:3, :3] / scale
    out = np.eye(4)
    out[:3, :3] = R @ T[:3, :3]
    out[:3, 3] = scale * (R @ T[:3, 3]) + S[:3, 3]
    return out


def _gray(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    return image if image.ndim == 2 else cast(NDArray[np.uint8],
                                              cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY))


def select_semidense(gray: NDArray[np.uint8], *, threshold: float, block_px: int) -> NDArray[np.int64]:
    """DSO-like point selection: per ``block_px``² block the pixel of largest Sobel gradient magnitude if it
    exceeds ``threshold`` (grey levels per pixel). Returns flat pixel indices (row-major)."""
    g = gray.astype(np.float32)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    mag = np.sqrt(gx * gx + gy * gy)
    mag[:1] = mag[-1:] = 0.0
    mag[:, :1] = mag[:, -1:] = 0.0
    H, W = mag.shape
    b = int(block_px)
    Hb, Wb = H // b, W // b
    blocks = mag[: Hb * b, : Wb * b].reshape(Hb, b, Wb, b).transpose(0, 2, 1, 3).reshape(Hb, Wb, b * b)
    arg = np.argmax(blocks, axis=2)
    best = np.take_along_axis(blocks, arg[..., None], axis=2)[..., 0]
    bi, bj = np.nonzero(best > threshold)
    a = arg[bi, bj]
    rows = bi * b + a // b
    cols = bj * b + a % b
    return rows * W + cols


class VseStandIn:
    """Monocular SLAM stand-in: renders keyframes around the true camera, publishes a scaled, noisy, drifting
    semi-dense cloud and poses in its own frame (see the module docstring).

    Args:
        renderer: renders ``(T_world_cam, camera, lighting)`` (see :class:`Renderer`).
        camera: the camera's intrinsics (keyframes use ``camera.scaled(image_scale)``).
        lighting: the session's lighting (passed to the renderer as is).
        sensor: the session's camera sensor (fixed exposure), passed to the renderer.
        scale_m_per_vse: the monocular scale s (truth): metres per VSE unit.
        config: :class:`VseConfig`.
        T_world_vse: the VSE frame in the world; default: the camera frame of the first observation.
        seed: seed of the noise, drift and render noise.
    """

    def __init__(self, renderer: Renderer, camera: PinholeCamera, lighting: Any, *, sensor: Any = None,
                 scale_m_per_vse: float = 1.0, config: VseConfig | None = None,
                 T_world_vse: ArrayLike | None = None, seed: int = 0) -> None:
        if not (math.isfinite(scale_m_per_vse) and scale_m_per_vse > 0.0):
            raise ValueError(f"scale_m_per_vse must be finite and > 0, got {scale_m_per_vse}")
        self.renderer = renderer
        self.config = config or VseConfig()
        self.camera = camera
        self.kf_camera = camera.scaled(self.config.image_scale) if self.config.image_scale != 1.0 else camera
        self.lighting = lighting
        self.sensor = sensor
        self._rng = np.random.default_rng(seed)
        self._T_world_vse: Array | None = None if T_world_vse is None else _rigid(T_world_vse, "T_world_vse")
        self._scale = float(scale_m_per_vse)
        self._drift = np.eye(4)
        self._last_position: Array | None = None
        self.truth: VseTruth | None = None
        if self._T_world_vse is not None:
            self.truth = VseTruth(self._T_world_vse.copy(), self._scale)

    # --- internals ---------------------------------------------------------------------------------------------

    def _start(self, T_world_cam: Array) -> None:
        if self._T_world_vse is None:
            self._T_world_vse = T_world_cam.copy()
        if self.truth is None:
            self.truth = VseTruth(self._T_world_vse.copy(), self._scale)

    def _advance_drift(self, T_world_cam: Array) -> None:
        """Random-walk the drift similarity by the camera path length since the last call."""
        c = T_world_cam[:3, 3]
        if self._last_position is not None:
            path = float(np.linalg.norm(c - self._last_position))
            if path > 0.0:
                cfg = self.config
                k = path  # the std of each increment is proportional to the path travelled
                dphi = self._rng.normal(0.0, math.radians(cfg.drift_rotation_deg_per_m) * k, 3)
                dt = self._rng.normal(0.0, cfg.drift_translation_per_m * k, 3) / self._scale
                ds = math.exp(self._rng.normal(0.0, cfg.drift_scale_per_m * k))
                step = np.eye(4)
                step[:3, :3] = ds * so3_exp(dphi)
                step[:3, 3] = dt
                self._drift = step @ self._drift
        self._last_position = c.copy()
        assert self.truth is not None
        self.truth.drift = self._drift.copy()

    def _true_vse_pose(self, T_world_cam: Array) -> Array:
        """The true camera pose in the scaled VSE frame (translation in VSE units)."""
        assert self._T_world_vse is not None
        T = inverse(self._T_world_vse) @ T_world_cam
        T[:3, 3] /= self._scale
        return T

    def _jitter(self) -> Array:
        cfg = self.config
        return make_transform(so3_exp(self._rng.normal(0.0, math.radians(cfg.pose_noise_deg), 3)),
                              self._rng.normal(0.0, cfg.pose_noise_m, 3) / self._scale)

    def _reported(self, T_world_cam: Array) -> Array:
        return _sim_apply(self._drift, self._true_vse_pose(T_world_cam) @ self._jitter())

    def _keyframe_poses(self, T_world_cam: Array) -> list[Array]:
        cfg = self.config
        poses = [T_world_cam]
        n = cfg.n_keyframes - 1
        for i in range(n):
            a = 2.0 * math.pi * (i + 0.5) / max(n, 1) + self._rng.uniform(-0.3, 0.3)
            t = cfg.keyframe_baseline_m * np.array([math.cos(a), math.sin(a), self._rng.uniform(-0.3, 0.3)])
            phi = self._rng.normal(size=3)
            phi *= math.radians(cfg.keyframe_rotation_deg) / max(float(np.linalg.norm(phi)), 1e-12)
            poses.append(T_world_cam @ make_transform(so3_exp(phi), t))
        return poses

    # --- public ------------------------------------------------------------------------------------------------

    @property
    def scale_m_per_vse(self) -> float:
        """The monocular scale s (truth)."""
        return self._scale

    def pose(self, T_world_cam: ArrayLike) -> Array:
        """Track the camera at the true pose ``T_world_cam`` without new keyframes: the VSE's ``T_vse_cam``."""
        T = _rigid(T_world_cam, "T_world_cam")
        self._start(T)
        self._advance_drift(T)
        return self._reported(T)

    def observe(self, T_world_cam: ArrayLike, *, stamp_s: float = 0.0) -> VseObservation:
        """Render keyframes around the true camera pose and publish the semi-dense cloud and poses."""
        T = _rigid(T_world_cam, "T_world_cam")
        self._start(T)
        self._advance_drift(T)
        cfg = self.config
        cam = self.kf_camera
        rng = self._rng
        keyframes: list[VseKeyframe] = []
        pts_all: list[Array] = []
        inten_all: list[NDArray[np.float32]] = []
        truth_all: list[Array] = []
        true_poses = self._keyframe_poses(T)
        for T_wk in true_poses:
            out = self.renderer.render(T_wk, cam, self.lighting, sensor=self.sensor,
                                       rng=np.random.default_rng(rng.integers(1 << 62)))
            if out.image is None:
                raise ValueError("the renderer returned no image: give the VSE stand-in a sensor")
            gray = _gray(out.image)
            depth = np.asarray(out.depth_m, dtype=np.float64)
            idx = select_semidense(gray, threshold=cfg.gradient_threshold, block_px=cfg.block_px)
            z = depth.reshape(-1)[idx]
            ok = z > 0.0
            idx, z = idx[ok], z[ok]
            W = cam.width
            uv = np.stack([idx % W, idx // W], axis=1).astype(np.float64)
            p_true_cam = cam.backproject(uv, z)
            # measurement: noisy pixel and depth, rare gross outliers
            uv_n = uv + rng.normal(0.0, cfg.pixel_noise_px, uv.shape)
            zf = 1.0 + rng.normal(0.0, cfg.depth_noise_rel, len(z))
            out_mask = rng.random(len(z)) < cfg.outlier_fraction
            zf[out_mask] = 1.0 + rng.uniform(-0.15, 0.15, int(out_mask.sum()))
            p_cam = cam.backproject(uv_n, z * zf)
            T_vse_k = self._reported(T_wk)  # drift and jitter
            s_d = float(np.cbrt(np.linalg.det(self._drift[:3, :3])))
            p_vse = (p_cam * (s_d / self._scale)) @ T_vse_k[:3, :3].T + T_vse_k[:3, 3]
            pts_all.append(p_vse)
            inten_all.append(gray.reshape(-1)[idx].astype(np.float32) / 255.0)
            truth_all.append(p_true_cam @ T_wk[:3, :3].T + T_wk[:3, 3])
            keyframes.append(VseKeyframe(gray, cam, T_vse_k))
        pts = np.concatenate(pts_all) if pts_all else np.zeros((0, 3))
        inten = np.concatenate(inten_all) if inten_all else np.zeros(0, np.float32)
        truth_pts = np.concatenate(truth_all) if truth_all else np.zeros((0, 3))
        if len(pts) > cfg.max_points:
            keep = np.sort(rng.choice(len(pts), cfg.max_points, replace=False))
            pts, inten, truth_pts = pts[keep], inten[keep], truth_pts[keep]
        assert self.truth is not None
        self.truth.points_world = truth_pts
        self.truth.T_world_keyframes = np.stack(true_poses)
        return VseObservation(pts.astype(np.float32), inten.astype(np.float32), tuple(keyframes),
                              keyframes[0].T_vse_cam.copy(), float(stamp_s))
