"""Ground-truth renderer for indoor daylight: Monte-Carlo light transport, a camera and a depth sensor.

This renderer is the *truth* the daylight method (``lightfast.daylight``: uniform directional light sets and patch
radiosity) is tested against, and shares neither its model nor its code. It renders a
:class:`~lightfast.daylight.mesh.ReflectanceMesh` (Lambertian, per-vertex linear RGB reflectance ρ interpolated
barycentrically) lit through one window (:class:`~lightfast.sim.daylight_scene.WindowGeometry`; or an open scene
without walls) by the outdoor light of :class:`~lightfast.sim.sky_model.SkyState`:

* the **sun** as a limb-darkened disk of radius 0.2666° (``I(μ) ∝ 1 - 0.6 (1 - μ)``) with direct normal
  irradiance DNI,
* a **non-uniform sky** (CIE clear sky type 12 plus an optional CIE overcast component), and a uniform **ground**
  glow below the horizon,
* a **glass pane** in the window: two-pane Fresnel transmittance (n = 1.52, multiple reflections) times 0.96
  absorption per pane along the refracted path (≈ 0.78 at normal incidence, falling off at grazing angles).

Units: radiance L in W m⁻² sr⁻¹, irradiance E in W m⁻², linear RGB. A Lambertian surface with irradiance E has
radiosity B = ρ E and radiance L = ρ E / π.

Irradiance cache (:meth:`GroundTruthRenderer.compute_cache`)
------------------------------------------------------------
Per vertex, the irradiance from everything **except the direct sun** (sky and ground through the window, and all
inter-reflected light), split into four linear components per unit source: ``sun`` (indirect sunlight per W m⁻² of
DNI), ``clear`` and ``overcast`` (per W m⁻² of the component's DHI) and ``ground`` (per W m⁻² sr⁻¹ of ground
radiance). Because transport is linear and per channel, a frame's irradiance is ``Σ_c scale_c ⊙ E_c`` with the
RGB scales of that instant (moving clouds only change the scales).

Estimator: at each vertex, directions from three sampling strategies, combined by multiple importance sampling
(balance heuristic, Veach 1997): ``E(v) ≈ Σ_i L(ω_i) cos⁺θ_i / Σ_s N_s p_s(ω_i)`` with

1. ``hemisphere_samples`` cosine-weighted directions (stratified), ``p = cos θ / π``;
2. ``window_samples`` uniform points on the window's outer rectangle (stratified), ``p = t² / (A cos θ_w)``
   where the direction crosses it;
3. ``sunlit_samples`` points of the directly sunlit surfaces, drawn from a pool of ``sunlit_pool`` points where
   parallel sun rays through the window first hit the room (area density ``|n·s| / (A |n_w·s|)``), with a
   visibility ray; ``p = p_A r² / |cos θ_y|`` at lit points (tested with a shadow ray towards the sun).

Strategy 2 makes sky light through a small window cheap, strategy 3 the light bounced off bright sun patches.
A direction that leaves the room collects the sky/ground radiance (through the glass); one that hits a surface
collects the radiance of the previous pass there: the surface point's triangle vertex is picked at random with
probabilities equal to its barycentric weights (an unbiased stochastic form of barycentric interpolation, so every
sample is a single sparse-matrix entry). The rays are traced once; ``bounces`` Jacobi passes
``B_k = ρ (E_src + M B_{k-1} / π)`` over the resulting sparse gather matrix ``M`` then add one bounce each
(the truncation error after 8 bounces is ≈ ρ̄⁸ < 1 %). ``E_src`` is the escaped sky/ground light, and for the sun
component the direct sun at the vertices (``sun_disk_samples`` stratified disk samples with shadow rays).
Inside a closed room, rays that leave other than through the window and rays that meet the back side of a surface
(only possible from vertices no camera sees, e.g. floor under a box) carry no light.

Denoising: the per-vertex estimates (≈ 4–5 % relative noise per vertex with 32 + 16 + 16 directions) are filtered by
a local *linear* regression over the vertices within ``filter_radius_m`` on the same surface
(:meth:`GroundTruthRenderer.smoothing_matrix`; hidden vertices excluded), which keeps linear gradients and one-sided
neighbourhoods at edges unbiased to first order and brings the median noise to ≈ 2 % (DS1, 32 + 16 + 16) and
≈ 1 % (DS2, 64 + 32 + 32, 12 cm radius); small parts with few same-surface neighbours (book spines, the window
frame, chair legs) keep 5–10 %. The filter blurs irradiance detail finer than its radius (8 cm by default), e.g.
contact shadows right at the foot of furniture. ``benchmarks/daylight_render.py`` measures the noise (two seeds)
and the cache time.

Frames (:meth:`GroundTruthRenderer.render`)
-------------------------------------------
One primary ray per subpixel (``supersample``² per pixel, box filter), per hit the direct sun from stratified,
limb-darkened disk samples with shadow rays — ``sun_samples`` ≥ 8 per pixel, split over its subpixels so that
each subpixel covers distinct annuli of the disk (soft penumbrae: width ≈ distance × 0.0093 rad) — plus the cached
irradiance interpolated barycentrically; ``L = ρ / π (E_sun + E_cache)``. Rays that
leave the room see the sky, the ground or the sun disk through the glass. A separate centre ray per pixel gives the
z-depth.

Camera (:class:`CameraResponse`): normalized sensor exposure ``x = sensitivity · exposure_s · gain · L`` (x = 1 is
saturation), Poisson shot noise on ``x · full_well / gain`` electrons plus Gaussian read noise, clipping to
[0, 1], then the monotonic, saturating response ``f(x) = 255 (1 + a) t(x) / (t(x) + a)`` with the sRGB transfer
curve ``t`` (linear toe) and shoulder ``a = 3``, and rounding to 8 bits.

Depth (:class:`DepthSensor`): a structured-light model (Asus Xtion / Kinect v1). Measured is not the colour
camera's view but the depth camera's, registered to the colour image with a factory calibration that is slightly
off, and a few milliseconds earlier than the colour image (the two sensors are not synchronized):

* **Pose**: the depth image is cast from ``T_map_depth = T_map_camera(t - time_offset_s) · T_reg`` with the
  fixed residual registration error ``T_reg`` (``registration_rotation_deg`` about a fixed axis,
  ``registration_translation_m``), at the colour camera's intrinsics.
* **Projector shadow**: the IR projector sits ``projector_baseline_m`` beside the depth camera; surface points it
  cannot see (behind an occluding edge, from its side) get no depth.
* **Disparity**: ``d = f b / z`` plus Gaussian noise that is *spatially correlated* (the disparity comes from a
  block correlation: white noise blurred over ``correlation_px`` pixels at 640 px width, rescaled to
  ``disparity_noise_px`` rms), plus a fixed *systematic distortion* pattern (``distortion_px`` at the image
  corners, growing with the squared distance from the centre, tilted per device), then 1/8-pixel quantization:
  the depth error grows with z² (random ≈ 1.6 mm at 1 m, 4 cm at 5 m; systematic up to ≈ 2 % of z² / m at the
  corners).
* **Loss**: no depth outside 0.5–5 m, where nothing is hit, and where the direct sun irradiance on the surface
  exceeds a threshold (the projector pattern drowns in sunlight, paper §IV-C), with a linear ramp of loss
  probability.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.progress import track
from lightfast.raycast import RayCaster
from lightfast.sim.daylight_scene import WindowGeometry
from lightfast.sim.sky_model import LUMA, SUN_ANGULAR_RADIUS_RAD, SkyState, float3

__all__ = [
    "COMPONENTS",
    "CacheSettings",
    "CameraResponse",
    "DepthSensor",
    "GlassModel",
    "GroundTruthRenderer",
    "IrradianceCache",
    "RenderOutput",
    "frame_scales",
]

#: Cache components, each per unit source (see the module docstring).
COMPONENTS = ("sun", "clear", "overcast", "ground")
#: Limb-darkening coefficient of the solar disk (visible light).
LIMB_DARKENING = 0.6
_EPS_M = 1e-4  # ray origin offset along the normal (m)

F64 = NDArray[np.float64]


# ----------------------------------------------------------------------------------------------------------------
# glass, camera, depth sensor


@dataclass(frozen=True)
class GlassModel:
    """Window glazing: ``panes`` clear panes of refractive index ``n`` (Fresnel reflection with inter-reflections
    per pane and between panes, each polarization separately) and ``absorption`` transmittance per pane at normal
    incidence (scaled to the refracted path length)."""

    panes: int = 2
    n: float = 1.52
    absorption: float = 0.96

    def transmittance(self, cos_theta: ArrayLike) -> F64:
        """Transmittance for light crossing the window at ``cos_theta`` from its normal (0 at grazing)."""
        c = np.clip(np.abs(np.asarray(cos_theta, dtype=np.float64)), 1e-6, 1.0)
        s = np.sqrt(1.0 - c**2)
        st = s / self.n
        ct = np.sqrt(1.0 - st**2)
        rs = ((c - self.n * ct) / (c + self.n * ct)) ** 2
        rp = ((ct - self.n * c) / (ct + self.n * c)) ** 2
        total = np.zeros_like(c)
        for r in (rs, rp):
            t1 = (1.0 - r) / (1.0 + r)  # one lossless pane with inter-reflections
            total += 0.5 * t1 / (self.panes - (self.panes - 1) * t1)
        return total * self.absorption ** (self.panes / ct)


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


# ----------------------------------------------------------------------------------------------------------------
# cache and frame records


@dataclass(frozen=True)
class CacheSettings:
    """Monte-Carlo sample counts of the irradiance cache (see the module docstring)."""

    hemisphere_samples: int = 32
    window_samples: int = 16
    sunlit_samples: int = 16
    sunlit_pool: int = 8192
    sun_disk_samples: int = 16
    bounces: int = 8
    filter_radius_m: float = 0.08
    chunk_vertices: int = 4096
    seed: int = 0


@dataclass(frozen=True, eq=False)
class IrradianceCache:
    """Per-vertex irradiance (W m⁻² per unit source, (V, 3) float32) of each of :data:`COMPONENTS`, excluding the
    direct sun; ``sun_direct`` (V,) is the direct sun irradiance per unit DNI at each vertex (glass included)."""

    sun_direction: tuple[float, float, float]
    irradiance: dict[str, NDArray[np.float32]]
    sun_direct: NDArray[np.float32]
    settings: CacheSettings
    stats: dict[str, float] = field(default_factory=dict)

    def combine(self, state: SkyState) -> NDArray[np.float32]:
        """The frame's cached irradiance (V, 3) in W m⁻² for the scales of ``state``."""
        scales = frame_scales(state)
        out = np.zeros_like(self.irradiance["sun"])
        for name in COMPONENTS:
            out += self.irradiance[name] * scales[name].astype(np.float32)
        return out


def frame_scales(state: SkyState) -> dict[str, F64]:
    """The RGB scale of each cache component for ``state``: DNI, clear DHI, overcast DHI, ground radiance."""
    return {
        "sun": np.asarray(state.sun_dni_rgb, dtype=np.float64) if state.sun_up else np.zeros(3),
        "clear": np.asarray(state.clear_dhi_rgb, dtype=np.float64),
        "overcast": np.asarray(state.overcast_dhi_rgb, dtype=np.float64),
        "ground": state.ground_radiance_rgb,
    }


@dataclass(frozen=True, eq=False)
class RenderOutput:
    """One rendered frame: linear ``radiance`` (H, W, 3) W m⁻² sr⁻¹, true z-``depth_m`` (H, W) (0: no hit),
    ``sun_irradiance_wm2`` (H, W) direct sun irradiance (luminance) on the seen surface, and ``hit`` (H, W)."""

    radiance: NDArray[np.float32]
    depth_m: NDArray[np.float32]
    sun_irradiance_wm2: NDArray[np.float32]
    hit: NDArray[np.bool_]


# ----------------------------------------------------------------------------------------------------------------
# sampling helpers


def _frames(n: F64) -> tuple[F64, F64]:
    """Two unit tangents completing unit normals ``n`` (..., 3) to right-handed frames (Duff et al. 2017)."""
    sign = np.where(n[..., 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    t1 = np.stack([1.0 + sign * n[..., 0] ** 2 * a, sign * b, -sign * n[..., 0]], axis=-1)
    t2 = np.stack([b, sign + n[..., 1] ** 2 * a, -n[..., 1]], axis=-1)
    return t1, t2


def _stratified_2d(rng: np.random.Generator, n_points: int, k: int) -> tuple[F64, F64]:
    """``k`` Latin-hypercube samples in [0, 1)² for each of ``n_points``: shapes (n_points, k)."""
    base = (np.arange(k) + rng.random((n_points, k))) / k
    perm = np.argsort(rng.random((n_points, k)), axis=1)
    other = (perm + rng.random((n_points, k))) / k
    return base, other


def _sun_disk_directions(sun: F64, annuli: NDArray[np.int64], n_annuli: int, theta0: F64,
                         rng: np.random.Generator) -> tuple[F64, F64]:
    """Stratified directions inside the solar disk, ``annuli.shape + (3,)``, and their limb-darkening weights
    (normalized to mean 1 over the disk). The disk is cut into ``n_annuli`` equal-area annuli; a sample of annulus
    ``a`` lies uniformly in it (random radius within the annulus) at the angle ``theta0 + a × golden angle``.
    With a uniformly random ``theta0`` every sample is uniform over its annulus, so any set of distinct annuli is an
    unbiased, stratified sample of the disk (the subpixels of a pixel share ``theta0`` and split the annuli)."""
    e1, e2 = _frames(sun[None, :])
    e1, e2 = e1[0], e2[0]
    r = np.sqrt((annuli + rng.random(annuli.shape)) / n_annuli)
    theta = 2 * math.pi * ((theta0 + annuli * 0.6180339887) % 1.0)
    tan_a = math.tan(SUN_ANGULAR_RADIUS_RAD)
    off = (r * np.cos(theta))[..., None] * e1 + (r * np.sin(theta))[..., None] * e2
    d = sun + tan_a * off
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    mu = np.sqrt(np.clip(1.0 - r**2, 0.0, 1.0))
    w = (1.0 - LIMB_DARKENING * (1.0 - mu)) / (1.0 - LIMB_DARKENING / 3.0)
    return d, w


# ----------------------------------------------------------------------------------------------------------------
# the renderer


class GroundTruthRenderer:
    """Monte-Carlo ground-truth renderer of a reflectance mesh lit through ``window`` (``None``: open scene, light
    reaches every surface directly from the sky). Built once per scene; the BVH build is the constructor's cost."""

    def __init__(self, mesh: ReflectanceMesh, window: WindowGeometry | None, *, glass: GlassModel | None = None,
                 num_threads: int | None = None) -> None:
        self.mesh = mesh
        self.window = window
        self.glass = glass if glass is not None else GlassModel()
        self.caster = RayCaster(mesh.vertices_m, mesh.faces, num_threads=num_threads)
        self._faces = mesh.faces
        self._face_normals = mesh.face_normals
        self._rho = mesh.reflectance.astype(np.float32)
        self._smoothing: dict[float, sp.csr_matrix] = {}
        self._hidden: NDArray[np.bool_] | None = None
        self._rays_cache: dict[tuple[PinholeCamera, int], tuple[F64, F64]] = {}
        if window is not None:
            self._wc = np.array(window.center_m, dtype=np.float64)
            self._wn = np.array(window.normal, dtype=np.float64)
            self._wu = np.array(window.axis_u, dtype=np.float64)
            self._wv = np.array(window.axis_v, dtype=np.float64)
            self._inside = window.glass_signed_distance(mesh.vertices_m) < 0.0
        else:
            self._inside = np.zeros(mesh.num_vertices, dtype=bool)

    # --- window geometry ---------------------------------------------------------------------------------------

    def _crossing(self, points: F64, dirs: F64, margin_m: float = 0.0) -> tuple[NDArray[np.bool_], F64, F64]:
        """Whether rays ``points + t dirs`` (unit dirs, broadcastable) cross the window's outer rectangle at
        ``t >= 0``: (mask, t, cos to the window normal)."""
        assert self.window is not None
        basis = np.stack([self._wn, self._wu, self._wv], axis=1)  # (3, 3): columns n, u, v
        pr = (points - self._wc) @ basis  # point in window coordinates
        dr = dirs @ basis
        cw = dr[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -pr[..., 0] / cw
            ok = (cw > 1e-9) & (t >= -1e-6)
            ok &= np.abs(pr[..., 1] + t * dr[..., 1]) <= self.window.half_u_m + margin_m
            ok &= np.abs(pr[..., 2] + t * dr[..., 2]) <= self.window.half_v_m + margin_m
        return ok, np.where(ok, t, 0.0), cw

    def _glass(self, inside: NDArray[np.bool_], dirs: F64) -> F64:
        """Glass transmittance for rays leaving from points (inside flags) along unit ``dirs``."""
        if self.window is None:
            return np.ones(dirs.shape[:-1])
        return np.where(inside, self.glass.transmittance(dirs @ self._wn), 1.0)

    def _sun_enters(self, sun: F64) -> bool:
        return bool(sun[2] > 0.0 and (self.window is None or sun @ self._wn > 1e-6))

    # --- direct sun --------------------------------------------------------------------------------------------

    def direct_sun(self, points: F64, normals: F64, inside: NDArray[np.bool_], sun: ArrayLike, n_samples: int,
                   rng: np.random.Generator, *, group: NDArray[np.int64] | None = None, n_groups: int = 1,
                   theta0: F64 | None = None) -> F64:
        """Direct sun irradiance per unit DNI (N,) at ``points`` with front ``normals``: stratified limb-darkened
        disk samples with shadow rays, glass transmittance for points inside the glass.

        Without ``group`` every point takes ``n_samples`` samples over the whole disk. With ``group`` (N,) in
        ``[0, n_groups)``, ``n_samples`` is the budget of a *set* of ``n_groups`` points (the subpixels of one
        pixel, sharing ``theta0``): point ``g`` takes the annuli ``g, g + n_groups, ...`` of ``n_samples``, so each
        point is unbiased and the set together is stratified over the disk.
        """
        s = np.asarray(sun, dtype=np.float64)
        n = len(points)
        out = np.zeros(n)
        if n == 0 or not self._sun_enters(s):
            return out
        # cheap pre-test with the disk's central direction: facing the sun within the disk radius, window
        cos0 = normals @ s
        cand = cos0 > -0.005
        if self.window is not None:
            cand &= self._crossing(points, s[None, :], margin_m=0.05)[0]  # disk spread < 5 cm over 10 m
        idx = np.flatnonzero(cand)
        if len(idx) == 0:
            return out
        if group is None:
            annuli = np.broadcast_to(np.arange(n_samples), (len(idx), n_samples))
            t0 = rng.random((len(idx), 1))
        else:
            per = max(1, n_samples // n_groups)
            annuli = group[idx, None] + n_groups * np.arange(per)
            n_samples = per * n_groups
            t0 = (theta0[idx] if theta0 is not None else rng.random(len(idx)))[:, None]
        d, w = _sun_disk_directions(s, annuli, n_samples, t0, rng)
        p, nrm = points[idx], normals[idx]
        cos = np.einsum("nkj,nj->nk", d, nrm)
        live = cos > 0.0
        if self.window is not None:
            live &= self._crossing(p[:, None, :], d, margin_m=1e-3)[0]
        li = np.nonzero(live)
        org = p[li[0]] + _EPS_M * nrm[li[0]]
        visible = ~self.caster.occluded(org, d[li])
        contrib = np.zeros_like(cos)
        contrib[li] = visible * cos[li] * w[li]
        if self.window is not None:
            contrib *= np.where(inside[idx, None], self.glass.transmittance(d @ self._wn), 1.0)
        out[idx] = contrib.mean(axis=1)
        return out

    # --- the irradiance cache ----------------------------------------------------------------------------------

    def _sunlit_pool(self, sun: F64, n: int, rng: np.random.Generator) -> dict[str, F64] | None:
        """Points where parallel sun rays through the window first hit the room: triangle, barycentrics,
        position, front normal and area density ``|n·s| / (A |n_w·s|)``."""
        if self.window is None or not self._sun_enters(sun) or n <= 0:
            return None
        w = self.window
        a, b = _stratified_2d(rng, 1, n)
        q = (self._wc + ((2 * a[0] - 1) * w.half_u_m)[:, None] * self._wu
             + ((2 * b[0] - 1) * w.half_v_m)[:, None] * self._wv + 0.01 * sun)
        hits = self.caster.intersect(q, np.broadcast_to(-sun, q.shape))
        pts = hits.points()
        nrm = hits.normals(facing=np.broadcast_to(-sun, q.shape))
        cos_y = np.where(hits.hit, np.abs(nrm @ sun), 0.0)
        density = cos_y / (w.area_m2 * float(sun @ self._wn))
        return {"hit": hits.hit, "tri": hits.triangle_id, "uv": hits.barycentric_uv.astype(np.float64),
                "points": np.where(hits.hit[:, None], pts, 0.0), "normals": np.where(hits.hit[:, None], nrm, 0.0),
                "density": density}

    def _lit(self, points: F64, normals_facing: F64, sun: F64) -> NDArray[np.bool_]:
        """Whether surface points (normals towards the viewer) are hit by the central sun ray through the
        window (the support of the sunlit-pool density)."""
        assert self.window is not None
        cand = (normals_facing @ sun > 0.0) & self._crossing(points, sun[None, :])[0]
        out = np.zeros(len(points), dtype=bool)
        idx = np.flatnonzero(cand)
        if len(idx):
            org = points[idx] + _EPS_M * normals_facing[idx]
            out[idx] = ~self.caster.occluded(org, np.broadcast_to(sun, org.shape))
        return out

    def compute_cache(self, state: SkyState, settings: CacheSettings | None = None, *,
                      progress: bool = False) -> IrradianceCache:
        """Compute the :class:`IrradianceCache` for the sun position and sky distributions of ``state`` (its
        brightness values do not matter)."""
        cfg = settings or CacheSettings()
        t_start = time.perf_counter()
        rng = np.random.default_rng(cfg.seed)
        mesh = self.mesh
        V = mesh.num_vertices
        sun = np.asarray(state.sun_direction, dtype=np.float64)
        sun = sun / np.linalg.norm(sun)
        sun_in = self._sun_enters(sun)
        pos, nrm = mesh.vertices_m, mesh.vertex_normals
        window = self.window
        n_c = cfg.hemisphere_samples
        n_w = cfg.window_samples if window is not None else 0
        pool = self._sunlit_pool(sun, cfg.sunlit_pool, rng) if sun_in else None
        n_s = cfg.sunlit_samples if pool is not None else 0
        n_all = n_c + n_w + n_s
        area = window.area_m2 if window is not None else 1.0
        sun_cos_w = float(sun @ self._wn) if window is not None else 1.0

        # direct sun at the vertices (per unit DNI)
        sun_direct = np.zeros(V)
        t0 = time.perf_counter()
        if sun_in:
            chunks = range(0, V, 8 * cfg.chunk_vertices)
            for c0 in track(chunks, desc="cache: direct sun", total=len(chunks), enabled=progress, unit="chunk"):
                sl = slice(c0, min(c0 + 8 * cfg.chunk_vertices, V))
                sun_direct[sl] = self.direct_sun(pos[sl], nrm[sl], self._inside[sl], sun, cfg.sun_disk_samples, rng)
        t_direct = time.perf_counter() - t0

        escaped = {k: np.zeros(V) for k in ("clear", "overcast", "ground")}
        rows: list[NDArray[np.int32]] = []
        cols: list[NDArray[np.int32]] = []
        vals: list[NDArray[np.float32]] = []
        n_rays = 0
        t0 = time.perf_counter()
        chunks = range(0, V, cfg.chunk_vertices)
        for c0 in track(chunks, desc="cache: gather rays", total=len(chunks), enabled=progress, unit="chunk"):
            c1 = min(c0 + cfg.chunk_vertices, V)
            m = c1 - c0
            p, n = pos[c0:c1], nrm[c0:c1]
            t1, t2 = _frames(n)
            dirs = np.empty((m, n_all, 3))
            # 1. cosine-weighted hemisphere
            u1, u2 = _stratified_2d(rng, m, n_c)
            r, phi = np.sqrt(u1), 2 * math.pi * u2
            dirs[:, :n_c] = ((r * np.cos(phi))[..., None] * t1[:, None] + (r * np.sin(phi))[..., None] * t2[:, None]
                             + np.sqrt(np.clip(1 - u1, 0, 1))[..., None] * n[:, None])
            # 2. window rectangle
            if n_w:
                assert window is not None  # n_w > 0 only with a window
                a, b = _stratified_2d(rng, m, n_w)
                q = (self._wc + ((2 * a - 1) * window.half_u_m)[..., None] * self._wu
                     + ((2 * b - 1) * window.half_v_m)[..., None] * self._wv)
                dv = q - p[:, None]
                dirs[:, n_c:n_c + n_w] = dv / np.linalg.norm(dv, axis=-1, keepdims=True)
            # 3. sunlit pool
            if n_s:
                assert pool is not None  # n_s > 0 only with a sunlit pool
                pick = rng.integers(0, len(pool["hit"]), size=(m, n_s))
                ys = pool["points"][pick]
                dv = ys - p[:, None]
                dist_s = np.linalg.norm(dv, axis=-1)
                dirs[:, n_c + n_w:] = dv / np.maximum(dist_s, 1e-12)[..., None]
            cos_v = np.einsum("mkj,mj->mk", dirs, n)
            origin = p + _EPS_M * n
            # trace strategies 1 and 2
            n_cw = n_c + n_w
            hits = self.caster.intersect(np.broadcast_to(origin[:, None], (m, n_cw, 3)), dirs[:, :n_cw])
            n_rays += m * n_cw
            hit = np.zeros((m, n_all), dtype=bool)
            tri = np.full((m, n_all), -1, dtype=np.int64)
            uv = np.zeros((m, n_all, 2))
            hit_n = np.zeros((m, n_all, 3))
            hit_p = np.zeros((m, n_all, 3))
            hit[:, :n_cw] = hits.hit
            tri[:, :n_cw] = hits.triangle_id
            uv[:, :n_cw] = np.nan_to_num(hits.barycentric_uv.astype(np.float64))
            dist = np.zeros((m, n_all))
            dist[:, :n_cw] = np.where(hits.hit, hits.distance_m, 0.0)
            fn = self._face_normals[np.maximum(hits.triangle_id, 0)]
            back = np.einsum("mkj,mkj->mk", fn, dirs[:, :n_cw]) > 0  # the ray meets a triangle's back side
            hit_n[:, :n_cw] = np.where(back[..., None], -fn, fn)  # towards the vertex
            back &= hits.hit
            hit_p[:, :n_cw] = origin[:, None] + dirs[:, :n_cw] * dist[:, :n_cw, None]
            lit = np.zeros((m, n_all), dtype=bool)
            if n_s:
                assert pool is not None
                ok = pool["hit"][pick] & (cos_v[:, n_cw:] > 0)
                pn = pool["normals"][pick]
                ok &= np.einsum("mkj,mkj->mk", pn, dirs[:, n_cw:]) < 0  # the lit side faces the vertex
                oi = np.nonzero(ok)
                vis = ~self.caster.occluded(origin[oi[0]], dirs[:, n_cw:][oi], t_far_m=np.maximum(
                    dist_s[oi] - 2e-3, 0.0))
                n_rays += len(oi[0])
                ok[oi] = vis
                sub = (slice(None), slice(n_cw, None))
                hit[sub] = ok
                tri[sub] = np.where(ok, pool["tri"][pick], -1)
                uv[sub] = pool["uv"][pick]
                dist[sub] = dist_s
                hit_n[sub] = pn
                hit_p[sub] = ys
                lit[sub] = ok
                # lit test of strategy-1/2 hits (the pool density's support)
                hi = np.nonzero(hit[:, :n_cw])
                lit_cw = self._lit(hit_p[:, :n_cw][hi], hit_n[:, :n_cw][hi], sun)
                n_rays += int(np.count_nonzero(lit_cw))
                lit[:, :n_cw][hi] = lit_cw
            # MIS pdfs of every direction under every strategy
            denom = n_c * np.maximum(cos_v, 0.0) / math.pi
            if n_w:
                cross, t_w, cw = self._crossing(p[:, None, :], dirs)
                denom += n_w * np.where(cross, t_w**2 / (area * np.maximum(cw, 1e-12)), 0.0)
            if n_s:
                cos_y = np.abs(np.einsum("mkj,mkj->mk", hit_n, dirs))
                dens = np.abs(np.einsum("mkj,j->mk", hit_n, sun)) / (area * sun_cos_w)
                denom += n_s * np.where(lit & (cos_y > 1e-9), dens * dist**2 / np.maximum(cos_y, 1e-12), 0.0)
            weight = np.where(cos_v > 0, np.maximum(cos_v, 0.0) / np.maximum(denom, 1e-300), 0.0)
            # the back sides of surfaces (only seen from hidden vertices, e.g. under a box) are unlit
            weight[:, :n_cw][back] = 0.0
            # escaped rays (strategies 1, 2): sky and ground through the glass; in a room, only through the window
            esc = ~hit[:, :n_cw] & (weight[:, :n_cw] > 0)
            if window is not None:
                esc &= cross[:, :n_cw] if n_w else self._crossing(p[:, None, :], dirs[:, :n_cw])[0]
            ei = np.nonzero(esc)
            if len(ei[0]):
                d_esc = dirs[:, :n_cw][ei]
                wt = weight[:, :n_cw][ei] * self._glass(self._inside[c0:c1][ei[0]], d_esc)
                up = d_esc[:, 2] > 0
                owner = ei[0]
                escaped["clear"][c0:c1] += np.bincount(owner, wt * state.clear_sky_normalized(d_esc), minlength=m)
                escaped["overcast"][c0:c1] += np.bincount(owner, wt * state.overcast_sky_normalized(d_esc),
                                                          minlength=m)
                escaped["ground"][c0:c1] += np.bincount(owner, wt * ~up, minlength=m)
            # surface hits: one vertex per sample, chosen with the barycentric probabilities
            hi = np.nonzero(hit & (weight > 0))
            if len(hi[0]):
                u_, v_ = uv[hi][:, 0], uv[hi][:, 1]
                xi = rng.random(len(u_))
                corner = np.where(xi < 1 - u_ - v_, 0, np.where(xi < 1 - v_, 1, 2))
                rows.append((hi[0] + c0).astype(np.int32))
                cols.append(self._faces[tri[hi], corner].astype(np.int32))
                vals.append((weight[hi] / math.pi).astype(np.float32))
        t_rays = time.perf_counter() - t0

        t0 = time.perf_counter()
        if rows:
            M = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(V, V))
        else:
            M = sp.csr_matrix((V, V), dtype=np.float32)
        rho = self._rho
        src: NDArray[np.float32] = np.zeros((V, 4, 3), dtype=np.float32)
        src[:, 0] = sun_direct[:, None]
        src[:, 1] = escaped["clear"][:, None]
        src[:, 2] = escaped["overcast"][:, None]
        src[:, 3] = escaped["ground"][:, None]
        src = src.reshape(V, 12)
        rho12 = np.tile(rho, (1, 4))
        B = rho12 * src
        E_ind = np.zeros_like(B)
        for _ in range(cfg.bounces):
            E_ind = np.asarray(M @ B, dtype=np.float32)
            B = rho12 * (src + E_ind)
        t_bounce = time.perf_counter() - t0
        total = E_ind.reshape(V, 4, 3).copy()
        total[:, 1:] += src.reshape(V, 4, 3)[:, 1:]  # sky and ground seen directly; the direct sun is per pixel
        t0 = time.perf_counter()
        if cfg.filter_radius_m > 0:
            S = self.smoothing_matrix(cfg.filter_radius_m)
            total = np.maximum(np.asarray(S @ total.reshape(V, 12), dtype=np.float32), 0.0).reshape(V, 4, 3)
        t_filter = time.perf_counter() - t0
        irr = {name: np.ascontiguousarray(total[:, i]) for i, name in enumerate(COMPONENTS)}
        stats = {
            "seconds_total": time.perf_counter() - t_start,
            "seconds_direct_sun": t_direct,
            "seconds_rays": t_rays,
            "seconds_bounces": t_bounce,
            "seconds_filter": t_filter,
            "rays_gather": float(n_rays),
            "matrix_nnz": float(M.nnz),
            "vertices": float(V),
        }
        return IrradianceCache(float3(sun), irr, sun_direct.astype(np.float32), cfg, stats)

    def smoothing_matrix(self, radius_m: float) -> sp.csr_matrix:
        """The sparse (V, V) denoising filter of the irradiance cache: at each vertex, a weighted local *linear*
        fit ``E ≈ a + b du + c dv`` in the tangent plane over the vertices within ``radius_m`` on the same surface
        (normals within 18°, each within 5 mm of the other's tangent plane, so corners, furniture edges and the two
        sides of thin objects stay apart), with Gaussian weights (σ = radius / 2); the filtered value is ``a``. A
        linear fit keeps linear gradients and one-sided neighbourhoods (edges, corners) unbiased to first order.
        It depends on the geometry only and is built once per radius."""
        key = round(float(radius_m), 6)
        cached = self._smoothing.get(key)
        if cached is not None:
            return cached
        from scipy.spatial import cKDTree

        pos, nrm = self.mesh.vertices_m, self.mesh.vertex_normals
        V = len(pos)
        hidden = self.hidden_vertices()
        pairs = cKDTree(pos).query_pairs(radius_m, output_type="ndarray")
        i, j = pairs[:, 0], pairs[:, 1]
        dp = pos[j] - pos[i]
        ok = np.einsum("ij,ij->i", nrm[i], nrm[j]) > 0.95
        ok &= ~hidden[i] & ~hidden[j]
        ok &= np.abs(np.einsum("ij,ij->i", dp, nrm[i])) < 5e-3
        ok &= np.abs(np.einsum("ij,ij->i", dp, nrm[j])) < 5e-3
        i, j = i[ok], j[ok]
        rows = np.concatenate([i, j, np.arange(V)])
        cols = np.concatenate([j, i, np.arange(V)])
        d = pos[cols] - pos[rows]
        t1, t2 = _frames(nrm)
        du = np.einsum("ij,ij->i", d, t1[rows])
        dv = np.einsum("ij,ij->i", d, t2[rows])
        sigma = 0.5 * radius_m
        w = np.exp(-(du**2 + dv**2) / (2 * sigma**2))
        basis = np.stack([np.ones_like(du), du, dv], axis=1)
        A = np.zeros((V, 3, 3))
        for a in range(3):
            for b in range(a, 3):
                A[:, a, b] = A[:, b, a] = np.bincount(rows, w * basis[:, a] * basis[:, b], minlength=V)
        reg = 1e-3 * A[:, 0, 0] * sigma**2  # keeps thin strips (collinear neighbours) solvable
        A[:, 1, 1] += reg
        A[:, 2, 2] += reg
        g = np.linalg.solve(A, np.broadcast_to(np.array([1.0, 0.0, 0.0]), (V, 3))[..., None])[..., 0]
        vals = w * np.einsum("ij,ij->i", g[rows], basis)
        M = sp.csr_matrix((vals.astype(np.float32), (rows, cols)), shape=(V, V))
        self._smoothing[key] = M
        return M

    def hidden_vertices(self, *, n_rays: int = 8, seed: int = 12345) -> NDArray[np.bool_]:
        """Vertices that no camera in the room can see: at least 3 of ``n_rays`` cosine rays meet a back side or
        (with a window) leave the room elsewhere than through the window — e.g. floor under a box, wall parts
        behind a corner. The cache filter ignores them. Cached."""
        if self._hidden is not None:
            return self._hidden
        rng = np.random.default_rng(seed)
        pos, nrm = self.mesh.vertices_m, self.mesh.vertex_normals
        V = len(pos)
        bad = np.zeros(V, dtype=np.int64)
        for c0 in range(0, V, 65536):
            sl = slice(c0, min(c0 + 65536, V))
            p, n = pos[sl], nrm[sl]
            t1, t2 = _frames(n)
            u1, u2 = _stratified_2d(rng, len(p), n_rays)
            r, phi = np.sqrt(u1), 2 * math.pi * u2
            d = ((r * np.cos(phi))[..., None] * t1[:, None] + (r * np.sin(phi))[..., None] * t2[:, None]
                 + np.sqrt(np.clip(1 - u1, 0, 1))[..., None] * n[:, None])
            hits = self.caster.intersect(np.broadcast_to((p + _EPS_M * n)[:, None], d.shape), d)
            fn = self._face_normals[np.maximum(hits.triangle_id, 0)]
            b = hits.hit & (np.einsum("mkj,mkj->mk", fn, d) > 0)
            if self.window is not None:
                b |= ~hits.hit & ~self._crossing(p[:, None, :], d)[0]
            bad[sl] = b.sum(axis=1)
        self._hidden = bad >= 3
        return self._hidden

    # --- frames ------------------------------------------------------------------------------------------------

    def _interp(self, values: NDArray[np.float32], tri: NDArray[np.int64], uv: NDArray[np.float32]
                ) -> NDArray[np.float32]:
        f = self._faces[tri]
        u, v = uv[:, 0:1], uv[:, 1:2]
        return (1 - u - v) * values[f[:, 0]] + u * values[f[:, 1]] + v * values[f[:, 2]]

    def _camera_rays(self, camera: PinholeCamera, k: int) -> tuple[F64, F64]:
        """Unit optical-frame rays of the k × k subpixels (H·W·k², 3), pixel-major, and of the pixel centres."""
        key = (camera, k)
        if key not in self._rays_cache:
            H, W = camera.height, camera.width
            offs = (np.arange(k) + 0.5) / k - 0.5
            vv, uu = np.mgrid[0:H, 0:W].astype(np.float64)
            du, dv = np.meshgrid(offs, offs, indexing="xy")
            px = (uu[..., None] + du.ravel() - camera.cx) / camera.fx  # (H, W, k²)
            py = (vv[..., None] + dv.ravel() - camera.cy) / camera.fy
            d = np.stack([px, py, np.ones_like(px)], axis=-1).reshape(-1, 3)
            dc = np.stack([(uu - camera.cx) / camera.fx, (vv - camera.cy) / camera.fy, np.ones_like(uu)],
                          axis=-1).reshape(-1, 3)
            self._rays_cache[key] = (d / np.linalg.norm(d, axis=1, keepdims=True),
                                     dc / np.linalg.norm(dc, axis=1, keepdims=True))
        return self._rays_cache[key]

    def render(self, T_map_camera: ArrayLike, camera: PinholeCamera, cache: IrradianceCache, state: SkyState, *,
               supersample: int = 2, sun_samples: int = 8, rng: np.random.Generator | None = None,
               cached_irradiance: NDArray[np.float32] | None = None) -> RenderOutput:
        """Render the linear radiance and true depth seen by ``camera`` at pose ``T_map_camera`` (optical
        frame → map). ``cached_irradiance`` (from :meth:`IrradianceCache.combine`) saves the per-frame sum when
        the scales do not change; the sun direction is taken from ``state`` (per frame, exact)."""
        rng = rng if rng is not None else np.random.default_rng(0)
        T = np.asarray(T_map_camera, dtype=np.float64)
        R, t = T[:3, :3], T[:3, 3]
        H, W, k = camera.height, camera.width, int(supersample)
        E_cache = cached_irradiance if cached_irradiance is not None else cache.combine(state)
        sun = np.asarray(state.sun_direction, dtype=np.float64)
        sun = sun / np.linalg.norm(sun)
        dni = np.asarray(state.sun_dni_rgb, dtype=np.float64)
        d_cam, dc = self._camera_rays(camera, k)
        d = d_cam @ R.T
        hits = self.caster.intersect(t, d)
        radiance = np.zeros((len(d), 3))
        sun_e = np.zeros(len(d))
        hi = np.flatnonzero(hits.hit)
        if len(hi):
            tri = hits.triangle_id[hi]
            uv = hits.barycentric_uv[hi].astype(np.float64)
            pts = t + d[hi] * hits.distance_m[hi, None].astype(np.float64)
            nrm = self._face_normals[tri]
            nrm = np.where((np.einsum("ij,ij->i", nrm, d[hi]) > 0)[:, None], -nrm, nrm)
            both = self._interp(np.concatenate([self._rho, E_cache], axis=1), tri, uv.astype(np.float32))
            rho, e_c = both[:, :3], both[:, 3:]
            inside = (self.window.glass_signed_distance(pts) < 0.0) if self.window is not None else np.zeros(
                len(hi), bool)
            group = np.broadcast_to(np.arange(k * k), (H * W, k * k)).reshape(-1)[hi]
            theta0 = np.repeat(rng.random(H * W), k * k)[hi]
            e_s = self.direct_sun(pts, nrm, inside, sun, max(sun_samples, k * k), rng, group=group,
                                  n_groups=k * k, theta0=theta0)
            radiance[hi] = rho / math.pi * (e_s[:, None] * dni + e_c)
            sun_e[hi] = e_s * float(LUMA @ dni)
        mi = np.flatnonzero(~hits.hit)
        if len(mi):  # looking out of the window (or into the open sky)
            dm = d[mi]
            inside_cam = (self.window is not None and float(self.window.glass_signed_distance(t[None])[0]) < 0.0)
            tau = self._glass(np.full(len(mi), inside_cam), dm)
            L = state.radiance(dm)
            if self._sun_enters(sun):
                in_disk = dm @ sun > math.cos(SUN_ANGULAR_RADIUS_RAD)
                L = L + in_disk[:, None] * dni / (math.pi * SUN_ANGULAR_RADIUS_RAD**2)
            radiance[mi] = tau[:, None] * L
        radiance = radiance.reshape(H, W, k * k, 3).mean(axis=2)
        sun_e = sun_e.reshape(H, W, k * k).mean(axis=2)
        # depth along the pixel centre rays
        if k == 1:
            dist_c, hit_c = hits.distance_m.reshape(H, W), hits.hit.reshape(H, W)
        else:
            hc = self.caster.intersect(t, dc @ R.T)
            dist_c, hit_c = hc.distance_m.reshape(H, W), hc.hit.reshape(H, W)
        z_per_m = (dc[:, 2] if k > 1 else d_cam[:, 2]).reshape(H, W)  # z component of the unit ray
        z = np.where(hit_c, dist_c * z_per_m, 0.0)
        return RenderOutput(radiance.astype(np.float32), z.astype(np.float32), sun_e.astype(np.float32), hit_c)
