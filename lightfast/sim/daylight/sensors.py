"""The simulated RGB-D sensor: a colour camera at a fixed exposure and a structured-light depth camera.

Models the Asus Xtion Pro of Krawez et al. (RA-L 2021) §IV-A (exposure and gain fixed per sequence) and its depth
loss in direct sunlight (§IV-C). Inputs come from :mod:`lightfast.sim.daylight.renderer`: linear radiance
(W m⁻² sr⁻¹), z-depth (m) and the direct sun irradiance on the seen surface (luminance, W m⁻²).

Camera (:class:`CameraResponse`): normalized sensor exposure ``x = sensitivity · exposure_s · gain · L`` (x = 1 is
saturation), Poisson shot noise on ``x · full_well / gain`` electrons plus Gaussian read noise, clipping to
[0, 1], then the monotonic, saturating response ``f(x) = 255 (1 + a) t(x) / (t(x) + a)`` with the sRGB transfer
curve ``t`` (linear toe) and shoulder ``a = 3``, and rounding to 8 bits.

Depth (:class:`DepthSensor`, Asus Xtion / Kinect v1): measured is not the colour camera's view but the depth
camera's, registered to the colour image with a slightly-off factory calibration, and a few milliseconds earlier:

* **Pose**: ``T_map_depth = T_map_camera(t - time_offset_s) · T_reg`` with the fixed residual registration error
  ``T_reg`` (``registration_rotation_deg`` about a fixed axis, ``registration_translation_m``), at the colour
  camera's intrinsics.
* **Projector shadow**: surface points the IR projector (``projector_baseline_m`` beside the depth camera) cannot
  see get no depth.
* **Disparity**: ``d = f b / z`` plus spatially correlated Gaussian noise (white noise blurred over
  ``correlation_px`` pixels at 640 px width, rescaled to ``disparity_noise_px`` rms) and a fixed systematic
  distortion (``distortion_px`` at the image corners, growing with the squared distance from the centre, tilted per
  device), then 1/8-pixel quantization: the error grows with z² (random ≈ 1.6 mm at 1 m, 4 cm at 5 m).
* **Loss**: no depth outside 0.5–5 m, where nothing is hit, and, with a linear ramp of probability, where the
  direct sun irradiance exceeds ``sun_loss_start_wm2`` (the projector pattern drowns in sunlight).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.raycast import RayCaster

__all__ = [
    "CameraResponse",
    "DepthSensor",
]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class CameraResponse:
    """A colour camera at a fixed exposure: linear radiance → 8-bit values (see the module docstring).

    ``sensitivity`` is the normalized exposure per W m⁻² sr⁻¹ and second at unit gain; the normalized exposure
    ``x = sensitivity · exposure_s · gain · L`` saturates the sensor at 1.
    """

    exposure_s: float = 0.01
    gain: float = 1.0
    sensitivity: float = 8.0
    shoulder: float = 3.0
    full_well_e: float = 6000.0
    read_noise_e: float = 3.0

    def exposure(self, radiance: ArrayLike) -> F64:
        """Normalized sensor exposure ``x`` of linear radiance (before noise and clipping)."""
        return np.asarray(radiance, dtype=np.float64) * (self.sensitivity * self.exposure_s * self.gain)

    def crf(self, x: ArrayLike) -> F64:
        """The camera response ``f``: normalized exposure → value in [0, 255] (float, saturating at x >= 1):
        the sRGB transfer curve ``t(x)`` (linear toe, then ``1.055 x^(1/2.4) - 0.055``) compressed by the
        shoulder ``(1 + a) t / (t + a)``."""
        x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
        t = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
        a = self.shoulder
        return 255.0 * (1.0 + a) * t / (t + a)

    def inverse_crf(self, value: ArrayLike) -> F64:
        """``f⁻¹``: 8-bit value (float, [0, 255]) → normalized exposure (255 → 1, the saturation point)."""
        g = np.clip(np.asarray(value, dtype=np.float64) / 255.0, 0.0, 1.0)
        a = self.shoulder
        t = a * g / (1.0 + a - g)
        return np.where(t <= 0.04045, t / 12.92, np.power((t + 0.055) / 1.055, 2.4))

    def capture(self, radiance_rgb: ArrayLike, rng: np.random.Generator) -> NDArray[np.uint8]:
        """Expose, add shot and read noise, apply the response and quantize to uint8."""
        x = self.exposure(radiance_rgb)
        electrons_per_x = self.full_well_e / self.gain
        mean_e = np.clip(x, 0.0, 2.0) * electrons_per_x  # beyond 2 the pixel is saturated anyway
        e = rng.poisson(mean_e).astype(np.float64) + rng.normal(0.0, self.read_noise_e, mean_e.shape)
        return np.round(self.crf(e / electrons_per_x)).astype(np.uint8)

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class DepthSensor:
    """Structured-light depth (Asus Xtion Pro–like): see the module docstring."""

    focal_baseline_px_m: float = 570.0 * 0.075  # disparities in the IR camera's native 640-px pixels
    disparity_noise_px: float = 0.07
    correlation_px: float = 4.0
    distortion_px: float = 0.1
    disparity_step_px: float = 0.125
    min_depth_m: float = 0.5
    max_depth_m: float = 5.0
    sun_loss_start_wm2: float = 60.0
    sun_loss_full_wm2: float = 150.0
    projector_baseline_m: float = 0.075
    registration_rotation_deg: float = 0.3
    registration_translation_m: float = 0.003
    time_offset_s: float = 0.010

    def registration(self) -> F64:
        """The fixed residual registration error ``T_reg`` (depth camera → colour optical frame), (4, 4)."""
        axis = np.array([0.6, -0.7, 0.4])
        axis /= np.linalg.norm(axis)
        a = math.radians(self.registration_rotation_deg)
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        T = np.eye(4)
        T[:3, :3] = np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * K @ K
        T[:3, 3] = self.registration_translation_m * np.array([0.8, 0.5, -0.33]) / np.linalg.norm([0.8, 0.5, -0.33])
        return T

    def distortion(self, height: int, width: int) -> F64:
        """The device's systematic disparity distortion (native px) over an (H, W) image."""
        v, u = np.mgrid[0:height, 0:width]
        x, y = (u - 0.5 * (width - 1)) / (0.5 * width), (v - 0.5 * (height - 1)) / (0.5 * width)
        r2 = (x * x + y * y) / (1.0 + 0.75**2)  # 1 at the corners of a 4:3 image
        pattern = r2 * (1.0 + 0.3 * x - 0.2 * y) - 0.35
        return self.distortion_px * pattern

    def measure(self, depth_m: ArrayLike, sun_irradiance_wm2: ArrayLike, rng: np.random.Generator) -> F64:
        """Measured depth in metres (0 = invalid) from the true z-depth of the depth camera (0 where nothing was
        hit or the projector does not reach) and the direct sun irradiance (luminance, W m⁻²) on the surface."""
        from scipy.ndimage import gaussian_filter

        z = np.asarray(depth_m, dtype=np.float64)
        H, W = z.shape
        fb = self.focal_baseline_px_m
        valid = (z >= self.min_depth_m) & (z <= self.max_depth_m)
        d = fb / np.where(valid, z, 1.0)
        step = self.disparity_step_px
        noise = rng.normal(0.0, 1.0, z.shape)
        sigma_px = self.correlation_px * W / 640.0
        if sigma_px > 0.3:
            noise = gaussian_filter(noise, sigma_px, mode="reflect")
            noise /= max(float(noise.std()), 1e-12)
        d = d + self.disparity_noise_px * noise + self.distortion(H, W)
        d = np.round(d / step) * step
        valid &= d > 0
        out = np.where(valid, fb / np.where(d > 0, d, 1.0), 0.0)
        e = np.asarray(sun_irradiance_wm2, dtype=np.float64)
        span = max(self.sun_loss_full_wm2 - self.sun_loss_start_wm2, 1e-9)
        p_loss = np.clip((e - self.sun_loss_start_wm2) / span, 0.0, 1.0)
        lost = rng.random(z.shape) < p_loss
        return np.where(lost, 0.0, out)

    def true_depth(self, caster: RayCaster, T_map_depth: ArrayLike, camera: PinholeCamera) -> F64:
        """The z-depth (H, W) the depth camera at ``T_map_depth`` can measure: first hits of the pixel-centre rays
        that the projector (``projector_baseline_m`` along the camera's +x) also reaches; 0 elsewhere."""
        T = np.asarray(T_map_depth, dtype=np.float64)
        v, u = np.mgrid[0:camera.height, 0:camera.width]
        rays = np.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones(u.shape)], -1)
        rays = rays.reshape(-1, 3)
        unit = rays / np.linalg.norm(rays, axis=1, keepdims=True)
        hits = caster.intersect(T[:3, 3], unit @ T[:3, :3].T)
        z = np.where(hits.hit, hits.distance_m * unit[:, 2], 0.0)
        hi = np.flatnonzero(hits.hit)
        if len(hi) and self.projector_baseline_m > 0:
            p_cam = unit[hi] * hits.distance_m[hi, None]
            proj = np.array([self.projector_baseline_m, 0.0, 0.0])
            to_p = p_cam - proj
            dist = np.linalg.norm(to_p, axis=1)
            origin = T[:3, :3] @ proj + T[:3, 3]
            blocked = caster.occluded(origin, to_p @ T[:3, :3].T, t_far_m=np.maximum(dist - 2e-3, 0.0))
            z[hi[blocked]] = 0.0
        return z.reshape(camera.height, camera.width)

