"""The simulated stereo camera of the VT&R route: rig geometry, auto-exposure, noise and 8-bit output (paper:
Paton et al., §V: a Point Grey Bumblebee XB3 on the rover).

:class:`StereoRig`: an ideal rectified pair like the XB3 (3.8 mm lens, 3.75 µm pixels at 1280 × 960):
``fx = fy = 1013.33 · width / 1280`` px (506.67 px at 640 × 480, 64.5° horizontal field of view), principal point
at the image centre, 24 cm baseline; mounted 1.25 m above the ground, 0.3 m ahead of the robot's centre, pitched
down 12°. Frames: robot base (x forward, y left, z up; metres), optical (x right, y down, z forward). Left
``P = [K | 0]``, right ``P = [K | (-fx·b, 0, 0)ᵀ]``; :meth:`StereoRig.camera_poses` maps ``T_map_base`` to
``(T_map_left, T_map_right)``.

:class:`SensorModel`, input the raw linear response ``R`` (H, W, 3) of
:class:`~lightfast.sim.vtr.renderer.SpectralRenderer`: normalized sensor signal ``x = k · R`` with
``k = quantum_scale · exposure_s · gain``; shot noise (Gaussian approximation of Poisson on
``x · full_well_e / gain`` electrons), read noise (``read_noise_e``), sensor saturation at ``x = 1``, a fixed white
balance (a white surface under CIE D65 gives equal channels, like a manually white-balanced machine-vision
camera), clipping, a pure power-law gamma ``x^(1/gamma)`` (default 2.2, so shadows keep detail; ``gamma=1`` is a
linear camera; a power law scales every log-channel by ``1/gamma``, so colour-constant images stay invariant up to
that scale), 8-bit quantization → ``rgb8`` (H, W, 3) uint8.

:class:`AutoExposure`, like a real camera: per frame, the ``k`` that brings the mean of ``min(k·Y, 1)`` (Y:
white-balanced luma) to ``target_mean``, approached geometrically from the previous frame's ``k``
(``adaptation``), split into exposure time (s, ≤ ``max_exposure_s``) and analog gain (≤ ``max_gain``).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.sim.vtr.spectra import CAMERA_SENSITIVITY, WAVELENGTHS_NM, camera_sensitivities

__all__ = [
    "AutoExposure",
    "SensorModel",
    "StereoRig",
]

_F64 = NDArray[np.float64]


@dataclass(frozen=True)
class StereoRig:
    """A rectified stereo pair like a Bumblebee XB3 on the robot (see the module docstring).

    Robot base frame: x forward, y left, z up, at the ground under the robot's centre. The left camera is at
    ``(forward_m, baseline_m / 2, height_m)``, the right one ``baseline_m`` to the right along the left optical x
    axis; both look forward, pitched down by ``pitch_down_deg``."""

    width: int = 640
    height: int = 480
    focal_px_at_1280: float = 1013.33  # 3.8 mm lens / 3.75 µm pixels
    baseline_m: float = 0.24
    height_m: float = 1.25
    forward_m: float = 0.3
    pitch_down_deg: float = 12.0

    @property
    def fx(self) -> float:
        return self.focal_px_at_1280 * self.width / 1280.0

    @property
    def camera(self) -> PinholeCamera:
        """The (identical) intrinsics of both rectified images."""
        return PinholeCamera(self.width, self.height, self.fx, self.fx, (self.width - 1) / 2.0,
                             (self.height - 1) / 2.0)

    @property
    def P_left(self) -> _F64:
        return np.hstack([self.camera.K, np.zeros((3, 1))])

    @property
    def P_right(self) -> _F64:
        P = self.P_left.copy()
        P[0, 3] = -self.fx * self.baseline_m
        return P

    @property
    def T_base_left(self) -> _F64:
        """Pose of the left optical frame (x right, y down, z forward) in the robot base frame."""
        r0 = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        p = math.radians(self.pitch_down_deg)
        ry = np.array([[math.cos(p), 0.0, math.sin(p)], [0.0, 1.0, 0.0], [-math.sin(p), 0.0, math.cos(p)]])
        T = np.eye(4)
        T[:3, :3] = ry @ r0
        T[:3, 3] = (self.forward_m, self.baseline_m / 2.0, self.height_m)
        return T

    @property
    def T_left_right(self) -> _F64:
        """Pose of the right optical frame in the left one: a pure translation by the baseline along x."""
        T = np.eye(4)
        T[0, 3] = self.baseline_m
        return T

    def camera_poses(self, T_map_base: ArrayLike) -> tuple[_F64, _F64]:
        """``(T_map_left, T_map_right)`` for a robot base pose."""
        T_ml = np.asarray(T_map_base, dtype=np.float64) @ self.T_base_left
        return T_ml, T_ml @ self.T_left_right


@dataclass(frozen=True)
class SensorModel:
    """Exposure, noise and output of the simulated camera (see the module docstring)."""

    sensitivity: str = CAMERA_SENSITIVITY
    quantum_scale: float = 15.0  # normalized signal per (raw response unit · second) at gain 1
    full_well_e: float = 10000.0
    read_noise_e: float = 12.0
    min_exposure_s: float = 2e-5
    max_exposure_s: float = 0.05
    max_gain: float = 15.85  # 24 dB
    target_mean: float = 0.22
    adaptation: float = 0.6
    gamma: float = 2.2
    white_point: str = "D65"

    @functools.cached_property
    def wb_gains(self) -> _F64:
        """Fixed white-balance gains (R, G, B): a perfect white under :attr:`white_point` gives equal channels,
        green gain 1."""
        import colour

        sd = colour.SDS_ILLUMINANTS[self.white_point]
        e = np.interp(WAVELENGTHS_NM, sd.wavelengths, sd.values)
        r = e @ camera_sensitivities(self.sensitivity)
        return r[1] / r

    def split_exposure(self, k: float) -> tuple[float, float, float]:
        """Exposure time and analog gain for the wanted normalized exposure ``k``: ``(exposure_s, gain, k_eff)``."""
        t = min(max(k / self.quantum_scale, self.min_exposure_s), self.max_exposure_s)
        gain = min(max(k / (self.quantum_scale * t), 1.0), self.max_gain)
        return t, gain, self.quantum_scale * t * gain

    def capture(self, raw: ArrayLike, exposure_s: float, gain: float, rng: np.random.Generator
                ) -> NDArray[np.uint8]:
        """The 8-bit rgb8 image of a raw response image ``(H, W, 3)`` (see the module docstring)."""
        raw = np.asarray(raw, dtype=np.float32)
        k = np.float32(self.quantum_scale * exposure_s * gain)
        x = raw * k
        shot = rng.standard_normal(x.shape, dtype=np.float32)
        shot *= np.sqrt(np.maximum(x, 0.0) * np.float32(gain / self.full_well_e))
        x += shot
        x += rng.standard_normal(x.shape, dtype=np.float32) * np.float32(gain * self.read_noise_e / self.full_well_e)
        np.clip(x, 0.0, 1.0, out=x)  # full well / ADC range
        x *= self.wb_gains.astype(np.float32)
        np.clip(x, 0.0, 1.0, out=x)
        if self.gamma != 1.0:
            np.power(x, np.float32(1.0 / self.gamma), out=x)
        return np.rint(x * 255.0).astype(np.uint8)


class AutoExposure:
    """Per-frame auto-exposure (see the module docstring); :meth:`update` returns ``(exposure_s, gain)``."""

    def __init__(self, sensor: SensorModel) -> None:
        self.sensor = sensor
        self.k: float | None = None
        self._luma = np.array([0.25, 0.5, 0.25]) * sensor.wb_gains

    def target(self, raw: ArrayLike) -> float:
        """The normalized exposure that brings the mean clipped luma of ``raw`` (H, W, 3) to the target."""
        y = (np.asarray(raw, dtype=np.float32)[::3, ::3] @ self._luma.astype(np.float32)).ravel()
        mean = float(np.mean(y))
        if not mean > 0.0:
            return self.sensor.quantum_scale * self.sensor.max_exposure_s * self.sensor.max_gain
        k = self.sensor.target_mean / mean
        for _ in range(4):  # saturated pixels pull the mean down: iterate on the clipped mean
            m = float(np.mean(np.minimum(k * y, 1.0)))
            k *= self.sensor.target_mean / max(m, 1e-9)
        return k

    def update(self, raw: ArrayLike) -> tuple[float, float]:
        k_t = self.target(raw)
        k = k_t if self.k is None else self.k ** (1.0 - self.sensor.adaptation) * k_t ** self.sensor.adaptation
        exposure, gain, self.k = self.sensor.split_exposure(k)
        return exposure, gain
