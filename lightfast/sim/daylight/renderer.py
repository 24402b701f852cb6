"""The ground-truth daylight renderer: frames of linear radiance and true depth seen by a pinhole camera.

:class:`GroundTruthRenderer` (built once per scene; the BVH build is its constructor's cost) adds the frames to the
direct sun of :mod:`lightfast.sim.daylight.direct_sun` and the irradiance cache of
:mod:`lightfast.sim.daylight.irradiance_cache`. It is the truth of the simulated recordings
(:mod:`lightfast.sim.daylight.recordings`) and shares no model or code with the daylight method
(``lightfast.daylight``, Krawez et al., RA-L 2021).

:meth:`GroundTruthRenderer.render` takes the camera pose ``T_map_camera`` (optical frame → map, metres), a
:class:`~lightfast.camera.PinholeCamera`, the cache and the frame's :class:`~lightfast.sim.sky_model.SkyState`, and
returns a :class:`RenderOutput`. One primary ray per subpixel (``supersample``² per pixel, box filter); per hit the
direct sun from stratified, limb-darkened disk samples with shadow rays — ``sun_samples`` ≥ 8 per pixel, split over
its subpixels so that each subpixel covers distinct annuli of the disk (soft penumbrae: width ≈ distance ×
0.0093 rad) — plus the cached irradiance interpolated barycentrically: ``L = ρ / π (E_sun + E_cache)``
(W m⁻² sr⁻¹, linear RGB). Rays that leave the room see the sky, the ground or the sun disk through the glass. A
separate centre ray per pixel gives the z-depth (metres, 0 where nothing is hit). The camera response and the
depth sensor that turn a frame into 8-bit colour and measured depth are in :mod:`lightfast.sim.daylight.sensors`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.sim.daylight.direct_sun import GlassModel
from lightfast.sim.daylight.irradiance_cache import CacheTracer, IrradianceCache
from lightfast.sim.daylight.scene import WindowGeometry
from lightfast.sim.sky_model import LUMA, SUN_ANGULAR_RADIUS_RAD, SkyState

__all__ = [
    "GroundTruthRenderer",
    "RenderOutput",
]

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class RenderOutput:
    """One rendered frame: linear ``radiance`` (H, W, 3) W m⁻² sr⁻¹, true z-``depth_m`` (H, W) (0: no hit),
    ``sun_irradiance_wm2`` (H, W) direct sun irradiance (luminance) on the seen surface, and ``hit`` (H, W)."""

    radiance: NDArray[np.float32]
    depth_m: NDArray[np.float32]
    sun_irradiance_wm2: NDArray[np.float32]
    hit: NDArray[np.bool_]


class GroundTruthRenderer(CacheTracer):
    """Monte-Carlo ground-truth renderer of a reflectance mesh lit through ``window`` (``None``: open scene, light
    reaches every surface directly from the sky). Built once per scene; the BVH build is the constructor's cost."""

    def __init__(self, mesh: ReflectanceMesh, window: WindowGeometry | None, *, glass: GlassModel | None = None,
                 num_threads: int | None = None) -> None:
        super().__init__(mesh, window, glass=glass, num_threads=num_threads)
        self._rays_cache: dict[tuple[PinholeCamera, int], tuple[F64, F64]] = {}

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
