"""Embree renderer and camera sensor of the simulated rACR scenes (paper §5.1: the images the VSE and ACR see).

:class:`RacrRenderer` renders a :class:`~lightfast.daylight.mesh.ReflectanceMesh` (world frame, metres, linear
RGB albedo) under a :class:`~lightfast.sim.racr.lighting.Lighting` from a camera pose ``T_world_cam`` (optical
frame: x right, y down, z forward; :func:`look_at`): one primary ray per pixel (Embree, batched, threads),
barycentric interpolation of albedo, shading normal and ambient irradiance, one shadow ray per lit pixel towards
the point light or the sun (hard shadows), radiance ``L = ρ/π (E_direct + E_ambient)``; rays that miss see the
sky (outdoor) or the room. Output (:class:`RenderResult`): linear radiance (H, W, 3), z-depth (m), hit and
shadow masks, and the 8-bit image when a sensor is given.

Sky and room light use a per-vertex visibility cache: for :data:`AMBIENT_DIRECTIONS` = 64 fixed Fibonacci
directions each vertex stores whether a ray leaves the scene (ambient occlusion); a vertex's ambient irradiance
is ``Σ_k cos⁺θ_k (V_k L(ω_k) + (1 − V_k) L_bounce) 4π/64`` with the sky radiance (CIE clear sky + ground glow)
or the room radiance ``L``, and a crude one-bounce radiance ``L_bounce`` for blocked directions.

The camera (:class:`SensorModel`): fixed exposure per session (auto-exposed once per lighting at scene generation:
the 98th percentile of the probe's luminance maps to 0.8 of saturation), Gaussian shot noise (full well 8000 e⁻)
and read noise, sRGB transfer, 8 bits. Intrinsics (:func:`camera_for_size`): fx = fy = 525 px at 640 × 480
(Kinect-like), scaled for other sizes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.geometry import look_at
from lightfast.raycast import RayCaster
from lightfast.sim.racr.lighting import Lighting
from lightfast.sim.sky_model import LUMA

__all__ = ["AMBIENT_DIRECTIONS", "RacrRenderer", "RenderResult", "SensorModel", "camera_for_size", "look_at"]

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]

#: Number of fixed directions of the ambient visibility cache.
AMBIENT_DIRECTIONS = 64
_EPS_M = 2e-4


def camera_for_size(width: int, height: int) -> PinholeCamera:
    """Kinect-like intrinsics (fx = fy = 525 px at 640 × 480), scaled to ``width × height``."""
    return PinholeCamera(int(width), int(height), 525.0 * width / 640.0, 525.0 * height / 480.0,
                         width / 2.0 - 0.5, height / 2.0 - 0.5)


@dataclass(frozen=True)
class SensorModel:
    """The camera sensor: normalized exposure ``x = exposure · L`` (x = 1 saturates), Gaussian shot noise on
    ``x · full_well_e`` electrons and read noise, sRGB transfer curve, 8 bits."""

    exposure: float = 1.0
    full_well_e: float = 8000.0
    read_noise_e: float = 4.0

    def capture(self, radiance: F32, rng: np.random.Generator) -> NDArray[np.uint8]:
        x = np.asarray(radiance, np.float32) * np.float32(self.exposure)
        e = np.clip(x, 0.0, 2.0) * np.float32(self.full_well_e)
        sigma = np.sqrt(e + np.float32(self.read_noise_e**2))  # shot (Poisson ~ Gaussian) and read noise
        e += sigma * rng.standard_normal(e.shape, dtype=np.float32)
        x = np.clip(e * np.float32(1.0 / self.full_well_e), 0.0, 1.0)
        v = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
        return np.round(v * 255.0).astype(np.uint8)


@dataclass(frozen=True, eq=False)
class RenderResult:
    """A rendered frame: ``image`` (H, W, 3) uint8 (None without a sensor), linear ``radiance`` (H, W, 3)
    float32, z-depth ``depth_m`` (H, W) float32 (0 where nothing was hit), ``hit`` and ``shadow`` (H, W) bool
    (``shadow``: facing the point light or sun but occluded; evaluation and tests only)."""

    image: NDArray[np.uint8] | None
    radiance: F32
    depth_m: F32
    hit: NDArray[np.bool_]
    shadow: NDArray[np.bool_]


def _fibonacci_sphere(n: int) -> F64:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = math.pi * (1.0 + 5**0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


class RacrRenderer:
    """Embree renderer of a :class:`ReflectanceMesh` under a :class:`Lighting` (see the module docstring)."""

    def __init__(self, mesh: ReflectanceMesh, *, num_threads: int | None = None,
                 ambient_directions: int = AMBIENT_DIRECTIONS) -> None:
        self.mesh = mesh
        self.caster = RayCaster(mesh.vertices_m, mesh.faces, num_threads=num_threads)
        self._faces = mesh.faces
        self._face_normals32 = self.caster.face_normals.astype(np.float32)
        self._vnormals = mesh.vertex_normals.astype(np.float32)
        self._rho = mesh.reflectance.astype(np.float32)
        self._dirs = _fibonacci_sphere(ambient_directions)
        self._vis: NDArray[np.bool_] | None = None
        self._ambient: dict[Any, F32] = {}
        self._rays: dict[PinholeCamera, F64] = {}

    def ambient_visibility(self) -> NDArray[np.bool_]:
        """(V, K) whether direction k escapes from vertex v (only for directions above the vertex's tangent plane;
        others False). Computed once (V · K / 2 occlusion rays)."""
        if self._vis is None:
            n = self._vnormals.astype(np.float64)
            V, K = len(n), len(self._dirs)
            vis = np.zeros((V, K), bool)
            p = self.mesh.vertices_m
            chunk = max(1, 400_000 // K)
            for s in range(0, V, chunk):
                nn, pp = n[s:s + chunk], p[s:s + chunk]
                cos = nn @ self._dirs.T
                vi, ki = np.nonzero(cos > 0.02)
                org = pp[vi] + _EPS_M * nn[vi] + 1e-4 * self._dirs[ki]
                occ = self.caster.occluded(org, self._dirs[ki])
                block = np.zeros((len(nn), K), bool)
                block[vi, ki] = ~occ
                vis[s:s + chunk] = block
            self._vis = vis
        return self._vis

    def vertex_ambient(self, lighting: Lighting) -> F32:
        """Ambient (sky or room) irradiance per vertex (V, 3), cached per lighting."""
        key = lighting.spec
        if key not in self._ambient:
            vis = self.ambient_visibility()
            L = lighting.environment(self._dirs) * (4 * math.pi / len(self._dirs))
            Lb = lighting.bounce_rgb * (4 * math.pi / len(self._dirs))
            n = self._vnormals.astype(np.float64)
            out = np.empty((len(n), 3), np.float32)
            chunk = 100_000
            for s in range(0, len(n), chunk):
                cos = np.clip(n[s:s + chunk] @ self._dirs.T, 0.0, None)
                v = vis[s:s + chunk]
                out[s:s + chunk] = (cos * v) @ L + ((cos * ~v).sum(axis=1))[:, None] * Lb[None, :]
            if len(self._ambient) > 16:
                self._ambient.clear()
            self._ambient[key] = out
        return self._ambient[key]

    def _camera_rays(self, camera: PinholeCamera) -> F64:
        if camera not in self._rays:
            self._rays[camera] = camera.ray_directions().reshape(-1, 3)
        return self._rays[camera]

    def _attributes(self, lighting: Lighting) -> F32:
        """Per-vertex (V, 9) float32: albedo, shading normal, ambient irradiance (cached per lighting)."""
        key = ("attr", lighting.spec)
        if key not in self._ambient:
            self._ambient[key] = np.ascontiguousarray(
                np.concatenate([self._rho, self._vnormals, self.vertex_ambient(lighting)], axis=1))
        return self._ambient[key]

    def render(self, T_world_cam: ArrayLike, camera: PinholeCamera, lighting: Lighting, *,
               sensor: SensorModel | None = None, rng: np.random.Generator | None = None,
               shadows: bool = True) -> RenderResult:
        """Render the view of ``camera`` at ``T_world_cam`` (see the module docstring). ``sensor`` None gives no
        ``image`` (radiance only); ``rng`` drives the sensor noise (default seed 0)."""
        T = np.asarray(T_world_cam, dtype=np.float64)
        R, t = T[:3, :3], T[:3, 3]
        H, W = camera.height, camera.width
        d_cam = self._camera_rays(camera)
        d = np.einsum("ij,kj->ik", d_cam, R)  # (not d_cam @ R.T: BLAS threads are slow for N x 3 @ 3 x 3)
        hits = self.caster.intersect(t, d)
        hi = np.flatnonzero(hits.hit)
        radiance: NDArray[np.float32] = np.zeros((H * W, 3), np.float32)
        shadow = np.zeros(H * W, bool)
        if len(hi):
            tri = hits.triangle_id[hi]
            f = self._faces[tri]
            uv = hits.barycentric_uv[hi]
            u, v = uv[:, 0:1], uv[:, 1:2]
            attr = self._attributes(lighting)
            a = attr[f[:, 0]]
            a += u * (attr[f[:, 1]] - a) + v * (attr[f[:, 2]] - a)
            rho, ns, e_amb = a[:, :3], a[:, 3:6], a[:, 6:9]
            dh = d[hi].astype(np.float32)
            pts = (t + d[hi] * hits.distance_m[hi, None]).astype(np.float32)
            ng = self._face_normals32[tri]
            ng *= np.where(np.einsum("ij,ij->i", ng, dh) > 0, -1.0, 1.0).astype(np.float32)[:, None]
            ns /= np.maximum(np.linalg.norm(ns, axis=1, keepdims=True), 1e-12)
            back = np.einsum("ij,ij->i", ns, dh) > 0
            ns[back] = ng[back]
            direct = np.zeros((len(hi), 3), np.float32)
            occ = np.zeros(len(hi), bool)
            facing = np.zeros(len(hi), bool)
            if lighting.point_position_m is not None:
                ldir = lighting.point_position_m.astype(np.float32) - pts
                r2 = np.einsum("ij,ij->i", ldir, ldir)
                r = np.sqrt(r2)
                ldir /= r[:, None]
                cos = np.einsum("ij,ij->i", ns, ldir)
                facing = (cos > 0) & (np.einsum("ij,ij->i", ng, ldir) > 0)
                k = np.flatnonzero(facing)
                if shadows and len(k):
                    occ[k] = self.caster.occluded(pts[k] + _EPS_M * ng[k], ldir[k], t_far_m=r[k] - 2 * _EPS_M)
                e = np.where(facing & ~occ, cos / r2, 0.0).astype(np.float32)
                direct = e[:, None] * lighting.point_intensity_rgb.astype(np.float32)
            elif lighting.sun_direction is not None and np.any(lighting.sun_irradiance_rgb > 0):
                s = lighting.sun_direction.astype(np.float32)
                cos = ns @ s
                facing = (cos > 0) & (ng @ s > 0)
                k = np.flatnonzero(facing)
                if shadows and len(k):
                    occ[k] = self.caster.occluded(pts[k] + _EPS_M * ng[k], s)
                e = np.where(facing & ~occ, cos, 0.0).astype(np.float32)
                direct = e[:, None] * lighting.sun_irradiance_rgb.astype(np.float32)
            shadow[hi] = facing & occ
            radiance[hi] = rho * np.float32(1.0 / math.pi) * (direct + e_amb)
        mi = np.flatnonzero(~hits.hit)
        if len(mi):
            radiance[mi] = lighting.environment(d[mi])
        depth = np.where(hits.hit, hits.distance_m * d_cam[:, 2].astype(np.float32), 0.0).astype(np.float32)
        radiance = radiance.reshape(H, W, 3)
        image = None
        if sensor is not None:
            image = sensor.capture(radiance, rng if rng is not None else np.random.default_rng(0))
        return RenderResult(image, radiance, depth.reshape(H, W), hits.hit.reshape(H, W), shadow.reshape(H, W))

    def auto_exposure(self, T_world_cam: ArrayLike, camera: PinholeCamera, lighting: Lighting, *,
                      percentile: float = 98.0, target: float = 0.8) -> float:
        """Exposure that maps the ``percentile`` of the scene luminance (a 160-px-wide probe) to ``target``."""
        probe = camera.scaled(min(1.0, 160.0 / camera.width))
        out = self.render(T_world_cam, probe, lighting)
        lum = out.radiance[out.hit] @ LUMA.astype(np.float32)
        if lum.size == 0:
            lum = out.radiance.reshape(-1, 3) @ LUMA.astype(np.float32)
        q = float(np.percentile(lum, percentile)) if lum.size else 1.0
        return float(target / max(q, 1e-12))
