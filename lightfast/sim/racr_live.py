"""The simulator side of a live rACR run (paper §3.6, §5.1) for ``racr_platform_sim_node`` and ``racr_vse_node``:
their configurations and a platform that takes time. ROS-free.

* :class:`RacrPlatformSimConfig` = :class:`~lightfast.sim.racr_platform.PlatformConfig` (mechanical error, speed
  1.5 s/cm, limits) plus the scene, the seed and ``time_scale``.
* :class:`RacrVseSimConfig` = :class:`~lightfast.sim.racr_platform.VseConfig` (keyframes, semi-dense selection,
  noise, drift) plus the scene, the session's lighting, the seed and the monocular scale.
* :class:`TimedPlatform` runs a :class:`~lightfast.sim.racr_platform.PlatformSimulator` against a clock: a command
  starts a motion that lasts its simulated duration (``motion_duration_s`` of the platform module) divided by
  ``time_scale`` on the clock; until then the platform reports the pose it started from and is *moving*; then
  :meth:`TimedPlatform.poll` reports the stop once, with the new reported pose. The mechanical error is drawn
  when the motion starts; the true pose is exposed (``true_camera_pose``) for the simulator's ground-truth topic only.

Time: ``time_scale`` > 1 runs the platform faster than real time (e.g. 10: a 1 cm motion of 1.5 simulated seconds
takes 0.15 s), so a demo finishes in reasonable wall time. The simulated time the platform spent moving is
``TimedPlatform.simulated_time_s`` (the paper's measure, §5.3); the alignment itself runs in wall time, so with
``time_scale`` > 1 the parallel scheme gets less alignment per simulated second than on the paper's platform.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.config import ConfigError, param
from lightfast.geometry import inverse, rotation_angle_deg
from lightfast.sim.errors import PlatformError
from lightfast.sim.racr import RacrScene, load_scene
from lightfast.sim.racr_platform import PlatformConfig, PlatformSimulator, VseConfig

__all__ = [
    "LIGHTINGS",
    "FinalPoseResult",
    "MotionStart",
    "RacrPlatformSimConfig",
    "RacrVseSimConfig",
    "TimedPlatform",
    "evaluate_final_pose",
    "load_node_scene",
]

Array = NDArray[np.float64]

#: The lighting variants of a scene a VSE session can run under.
LIGHTINGS = ("reference", "similar", "varied")


def _base_config(cfg: Any, base: type) -> Any:
    return base(**{f.name: getattr(cfg, f.name) for f in dataclasses.fields(base)})


def load_node_scene(scene_path: str) -> RacrScene:
    """The scene of a simulator node's ``scene_path`` parameter (:class:`ConfigError` when it is empty)."""
    if not scene_path:
        raise ConfigError("parameter scene_path is required (a scene directory of `lightfast sim racr`)")
    return load_scene(scene_path)


@dataclass(frozen=True)
class RacrPlatformSimConfig(PlatformConfig):
    """Parameters of ``racr_platform_sim_node``: the platform of :class:`PlatformConfig` plus these."""

    scene_path: str = param("", description="Scene directory written by `lightfast sim racr` (required): the "
                            "platform starts with the camera at the scene's initial pose, with its hand-eye X.",
                            read_only=True)
    seed: int = param(0, description="Seed of the mechanical error.", min=0, read_only=True)
    time_scale: float = param(1.0, description="Simulated seconds per wall second: a motion lasts its simulated "
                              "duration divided by this (1 = real time).", min=0.01, max=10000.0, read_only=True)
    state_rate_hz: float = param(10.0, description="Rate of /platform/pose, /platform/status and the ground-truth "
                                 "camera pose, Hz.", min=0.1, max=1000.0, read_only=True)

    def platform_config(self) -> PlatformConfig:
        return _base_config(self, PlatformConfig)


@dataclass(frozen=True)
class RacrVseSimConfig(VseConfig):
    """Parameters of ``racr_vse_node``: the VSE stand-in of :class:`VseConfig` plus these."""

    scene_path: str = param("", description="Scene directory written by `lightfast sim racr` (required).",
                            read_only=True)
    lighting: str = param("varied", description="Lighting of the session (the reference was taken under "
                          "'reference').", choices=LIGHTINGS, read_only=True)
    seed: int = param(0, description="Seed of the VSE's noise, drift and rendering noise.", min=0, read_only=True)
    scale_m_per_vse: float = param(0.0, description="Monocular scale of the VSE, m per VSE unit (0: the scene's).",
                                   min=0.0, read_only=True)
    republish_s: float = param(1.0, description="Republish the last observation (same stamp) this often, so a "
                               "late subscriber gets it, s.", min=0.05, max=3600.0, read_only=True)

    def vse_config(self) -> VseConfig:
        return _base_config(self, VseConfig)


@dataclass(frozen=True)
class MotionStart:
    """The platform's answer to a command: ``accepted`` (else ``error`` says why and nothing moves), the motion's
    simulated duration and the clock time its stop is due."""

    accepted: bool
    duration_s: float
    stop_due: float
    error: str | None = None


class TimedPlatform:
    """A :class:`PlatformSimulator` whose motions take time on an external clock (see the module docstring)."""

    def __init__(self, platform: PlatformSimulator, *, time_scale: float = 1.0) -> None:
        if not (np.isfinite(time_scale) and time_scale > 0.0):
            raise ValueError(f"time_scale must be > 0, got {time_scale!r}")
        self.platform = platform
        self.time_scale = float(time_scale)
        self._reported = platform.reported_hand_pose
        self._true_camera = platform.true_camera_pose
        self._stop_due: float | None = None
        self._refused_pending = False
        self.simulated_time_s = 0.0
        self.executed = 0
        self.refused = 0

    @property
    def moving(self) -> bool:
        return self._stop_due is not None

    @property
    def reported_hand_pose(self) -> Array:
        """``T_base_hand`` as reported: the pose the current motion started from while moving."""
        return self._reported.copy()

    @property
    def true_camera_pose(self) -> Array:
        """The true camera pose (truth; updated when a motion has ended)."""
        return self._true_camera.copy()

    def command(self, M_hand: ArrayLike, now: float) -> MotionStart:
        """Start the hand motion ``M_hand`` at clock time ``now``. Refused (nothing moves, a stop is reported at
        the next :meth:`poll`) while moving, or when the platform refuses it (garbage, beyond its limits)."""
        if self.moving:
            self.refused += 1
            return MotionStart(False, 0.0, now, "refused: the platform is still executing the previous motion")
        try:
            duration = self.platform.execute(M_hand)
        except PlatformError as exc:
            self.refused += 1
            self._refused_pending = True
            return MotionStart(False, 0.0, now, str(exc))
        self.executed += 1
        self.simulated_time_s += duration
        self._stop_due = now + duration / self.time_scale
        return MotionStart(True, duration, self._stop_due)

    def poll(self, now: float) -> bool:
        """True once when a motion (or a refused command) has ended by ``now``: the platform is at rest, with the
        new reported pose and true camera pose."""
        if self._refused_pending and not self.moving:
            self._refused_pending = False
            return True
        if self._stop_due is None or now < self._stop_due:
            return False
        self._stop_due = None
        self._reported = self.platform.reported_hand_pose
        self._true_camera = self.platform.true_camera_pose
        return True


@dataclass(frozen=True)
class FinalPoseResult:
    """Where a live run left the camera, from the truth (evaluation only): the AFD against the reference image
    (paper §5.2; success if < 3 px), the camera pose error against the reference pose, and — when the run's
    estimates are given — the errors of its real scale s and hand–eye X."""

    afd_px: float
    afd_points: int
    success: bool
    translation_error_m: float
    rotation_error_deg: float
    scale_error_rel: float | None = None
    hand_eye_rotation_error_deg: float | None = None
    hand_eye_translation_error_m: float | None = None


def evaluate_final_pose(scene: RacrScene, T_world_cam: ArrayLike, *, scale_m_per_vse: float | None = None,
                        T_cam_hand: ArrayLike | None = None, vse_scale_m_per_vse: float | None = None
                        ) -> FinalPoseResult:
    """Score the true final camera pose ``T_world_cam`` of a run on ``scene`` (truth: evaluation only). The
    estimated ``scale_m_per_vse`` is compared with ``vse_scale_m_per_vse`` (default: the scene's) and
    ``T_cam_hand`` with the scene's X."""
    T = np.asarray(T_world_cam, dtype=np.float64)
    a = scene.afd(T)
    tr = scene.truth
    d = inverse(tr.T_world_camref) @ T
    scale_err = he_rot = he_t = None
    if scale_m_per_vse is not None:
        s_true = vse_scale_m_per_vse or tr.vse_scale_m_per_vse
        scale_err = float(scale_m_per_vse / s_true - 1.0)
    if T_cam_hand is not None:
        X = np.asarray(T_cam_hand, dtype=np.float64)
        he_rot = float(rotation_angle_deg(X[:3, :3], tr.T_cam_hand[:3, :3]))
        he_t = float(np.linalg.norm(X[:3, 3] - tr.T_cam_hand[:3, 3]))
    return FinalPoseResult(a.afd_px, a.n_visible, a.success, float(np.linalg.norm(d[:3, 3])),
                           float(rotation_angle_deg(d[:3, :3])), scale_err, he_rot, he_t)
