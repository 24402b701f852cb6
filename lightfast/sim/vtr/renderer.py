"""The spectral renderer of the simulated VT&R route (paper: Paton et al.; unlike the narrow-band Planckian model
of §III, Eq. 2–5, light is integrated over wavelength against broad camera sensitivities).

Input: a :class:`~lightfast.sim.vtr.scene.RouteScene`, camera poses ``T_map_camera`` (4×4, optical frames: x right,
y down, z forward; metres), a :class:`~lightfast.camera.PinholeCamera` and an
:class:`~lightfast.sim.vtr.light.Illumination`. Output per view, a :class:`RenderOutput`: the raw linear camera
response (H, W, 3; before exposure, white balance and noise), depth (m along the optical axis), surface kind, sun
term, map-frame hit points (m) and sky visibility.

Per pixel (all views in one batch): an Embree primary ray, Lambertian shading with four illuminants,

* sun: ``E_dn(λ) · max(n·s, 0) · V_sun``, ``V_sun`` from one Embree shadow ray per pixel towards a point of the
  0.53° sun disk (soft edges);
* sky: ``E_sky(λ) · v_sky``, ``v_sky`` the cosine-weighted sky fraction of the hemisphere (per vertex, interpolated);
* bounce: ``v_foliage · ρ_leaf(λ) E_glob(λ)`` under canopies (leaf reflectance plus transmittance ≈ 2 ρ_leaf, half
  the crown lit) and ``v_other · 0.5 ρ_env(λ) E_glob(λ)`` from terrain, rocks and trunks, with ``E_glob`` the
  global horizontal irradiance and ``ρ_env`` the mean of the sand, grass, soil, rock and litter spectra;

so shadows are lit by bluish skylight (plus some green under trees). Sky pixels see ``E_sky / π`` times a gradient
(clear: brighter towards the horizon; overcast: CIE overcast ``(1 + 2 sin el)``). The spectral integral is exact on
the 10 nm grid, as matrix products: with per-pixel basis weights ``W`` (pixels × basis, from
:func:`~lightfast.sim.vtr.shading.shade_kernel`) and ``A_k = (ρ_basis ⊙ E_k(λ)) · S(λ) Δλ / π`` (basis × channels),
the raw response is ``Σ_k w_k ⊙ (W · A_k)``, identical to integrating each pixel's spectrum against the
sensitivities without the pixels × wavelengths array. No inter-reflection beyond the bounce term, no atmospheric
perspective, no Bayer mosaic, no motion blur.
"""
from __future__ import annotations

import functools
import math
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.raycast import RayCaster
from lightfast.sim.vtr.light import Illumination
from lightfast.sim.vtr.scene import RouteScene
from lightfast.sim.vtr.shading import MipTexture, shade_kernel
from lightfast.sim.vtr.spectra import BASIS, CAMERA_SENSITIVITY, DLAMBDA_NM, camera_sensitivities, material_spectra

__all__ = [
    "BUMP_SLOPE",
    "RenderOutput",
    "SpectralRenderer",
]

_B = {name: i for i, name in enumerate(BASIS)}

#: Largest micro-relief facet slope (tan of the tilt) per surface kind: ground, rock, trunk, foliage (see
#: :mod:`lightfast.sim.vtr.shading`).
BUMP_SLOPE = (0.5, 0.6, 0.5, 0.0)

_F32 = NDArray[np.float32]
_F64 = NDArray[np.float64]


@functools.cache
def _openblas_thread_controls() -> list[tuple[object, object]]:
    """``(get, set)`` thread-count functions of every OpenBLAS loaded in this process (Linux; else none)."""
    import ctypes

    try:
        with open("/proc/self/maps") as fh:
            libs = sorted({line.split()[-1] for line in fh if "openblas" in line.lower() and "/" in line})
    except OSError:
        return []
    names = [("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
             ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
             ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
             ("openblas_get_num_threads", "openblas_set_num_threads")]
    out = []
    for path in libs:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for get, set_ in names:
            if hasattr(lib, get) and hasattr(lib, set_):
                out.append((getattr(lib, get), getattr(lib, set_)))
                break
    return out


class _SingleThreadedBlas:
    """Run OpenBLAS single-threaded inside the block (restored afterwards). The renderer's matrix products are
    tall and thin (pixels × ≤ 15 by ≤ 15 × 12); on a loaded 2-core machine OpenBLAS's worker threads make them
    much slower than one thread (docs/vtr.md, "The simulated route")."""

    def __enter__(self) -> None:
        self._saved = []
        for get, set_ in _openblas_thread_controls():
            n = int(get())  # type: ignore[operator]
            self._saved.append((set_, n))
            if n != 1:
                set_(1)  # type: ignore[operator]

    def __exit__(self, *exc: object) -> None:
        for set_, n in self._saved:
            if n != 1:
                set_(n)  # type: ignore[operator]


@dataclass(frozen=True, eq=False)
class RenderOutput:
    """One rendered view. ``raw`` (H, W, 3) float32: linear camera response (R, G, B; before exposure, white
    balance and noise); ``depth_m`` (H, W): z in the optical frame (inf on sky); ``kind`` (H, W) int8 (-1 sky);
    ``sun`` (H, W): ``max(n·s, 0) · V_sun`` (0 in shadow); ``points`` (H, W, 3) float32 map-frame hit points (NaN
    on sky); ``sky_vis`` (H, W): interpolated ``v_sky``."""

    raw: _F32
    depth_m: _F32
    kind: NDArray[np.int8]
    sun: _F32
    points: _F32
    sky_vis: _F32


class SpectralRenderer:
    """Spectral renderer of a :class:`RouteScene` (see the module docstring). ``texture=False`` renders every
    surface with the base spectrum of its stretch / kind (no variation), for tests."""

    SUN_RADIUS_RAD = math.radians(0.2666)

    def __init__(self, scene: RouteScene, *, texture: bool = True, sensitivity: str = CAMERA_SENSITIVITY,
                 fine_texel_m: float = 0.015, coarse_texel_m: float = 0.124,
                 bump_slope: tuple[float, float, float, float] = BUMP_SLOPE) -> None:
        self.scene = scene
        caster = getattr(scene, "_caster", None)
        self.caster: RayCaster = caster if caster is not None else RayCaster(scene.vertices, scene.faces)
        self.textured = texture
        self.basis = material_spectra()  # (M, Λ)
        self.sens = camera_sensitivities(sensitivity)  # (Λ, 3)
        self.texture = MipTexture(scene.config.texture_size, scene.config.seed) if texture else None
        self.fine_texel_m = fine_texel_m
        self.bump_slope = np.asarray(bump_slope, dtype=np.float64) if texture else np.zeros(4)
        if self.bump_slope.shape != (4,) or np.any(self.bump_slope < 0):
            raise ValueError(f"bump_slope must be 4 slopes >= 0 (ground, rock, trunk, foliage), got {bump_slope}")
        self.coarse_texel_m = coarse_texel_m
        fn = self.caster.face_normals
        self._face_normals = fn.astype(np.float32)
        self._faces = np.ascontiguousarray(scene.faces, dtype=np.int64)
        self._smooth_kind = np.array([True, False, True, False])
        self._vdata = np.ascontiguousarray(np.concatenate(
            [scene.vertex_normals, scene.vertex_attr, scene.vertex_vis], axis=1), dtype=np.float32)
        env = [_B[n] for n in ("sand_light", "grass_green", "soil_brown", "rock_grey", "leaf_litter")]
        self.rho_env = self.basis[env].mean(axis=0)
        self.rho_leaf = self.basis[_B["leaf_green"]]
        self._dirs: dict[tuple, _F32] = {}
        self._no_tex = np.full((1, 4), 0.5, np.float32)
        self._no_off = np.zeros(1, np.int64)
        cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        self._threads = max(1, cpus)

    # -------------------------------------------------------------------------------------------- spectra

    def illuminant_spectra(self, light: Illumination) -> _F64:
        """The four illuminant spectra ``(4, Λ)``: sun (normal), sky (horizontal), foliage and other bounce."""
        glob = light.global_horizontal
        return np.stack([light.direct_normal, light.sky_horizontal, 1.0 * self.rho_leaf * glob,
                         0.5 * self.rho_env * glob])

    def response_matrix(self, light: Illumination) -> _F32:
        """``A`` (M, 4·3): raw response of each basis reflectance under each illuminant, ``(ρ ⊙ E_k) S Δλ / π``."""
        E = self.illuminant_spectra(light)  # (4, Λ)
        A = np.einsum("ml,kl,lc->mkc", self.basis, E, self.sens) * (DLAMBDA_NM / math.pi)
        return A.reshape(len(self.basis), 12).astype(np.float32)

    # -------------------------------------------------------------------------------------------- rendering

    def _camera_dirs(self, camera: PinholeCamera) -> _F32:
        key = (camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy)
        if key not in self._dirs:
            self._dirs[key] = camera.ray_directions().reshape(-1, 3).astype(np.float32)
        return self._dirs[key]

    def render(self, poses: Sequence[ArrayLike], camera: PinholeCamera, light: Illumination,
               rng: np.random.Generator) -> list[RenderOutput]:
        """Render views ``T_map_camera`` (optical frames) of ``camera`` under ``light`` in one batch."""
        with _SingleThreadedBlas():
            return self._render(poses, camera, light, rng)

    def _render(self, poses: Sequence[ArrayLike], camera: PinholeCamera, light: Illumination,
                rng: np.random.Generator) -> list[RenderOutput]:
        dc = self._camera_dirs(camera)
        hw = dc.shape[0]
        nv = len(poses)
        Ts = [np.asarray(T, dtype=np.float64) for T in poses]
        D = np.concatenate([dc @ T[:3, :3].T.astype(np.float32) for T in Ts])
        centres = np.array([T[:3, 3] for T in Ts])
        orig = np.repeat(centres, hw, axis=0)
        hits = self.caster.intersect(orig, D, t_near_m=0.05)
        N = nv * hw
        raw = np.zeros((N, 3), np.float32)
        kind_img = np.full(N, -1, np.int8)
        sun_img = np.zeros(N, np.float32)
        sky_img = np.zeros(N, np.float32)
        pts_img = np.full((N, 3), np.nan, np.float32)
        depth = np.full(N, np.inf, np.float32)
        hit = hits.hit.reshape(-1)
        hi = np.flatnonzero(hit)
        # sky
        si = np.flatnonzero(~hit)
        if len(si):
            sky_rgb = (light.sky_horizontal @ self.sens * (DLAMBDA_NM / math.pi)).astype(np.float32)
            el = np.arcsin(np.clip(D[si, 2], 0.0, 1.0))
            if light.weather == "cloudy":
                grad = 3.0 * (1.0 + 2.0 * np.sin(el)) / 7.0
            else:
                grad = (1.0 + 1.2 * np.exp(-el / 0.15)) / 1.2
            raw[si] = grad[:, None] * sky_rgb
        if len(hi):
            t = np.ascontiguousarray(hits.distance_m.reshape(-1)[hi])
            d = np.ascontiguousarray(D[hi])
            tri = hits.triangle_id.reshape(-1)[hi]
            uv = np.ascontiguousarray(hits.barycentric_uv.reshape(-1, 2)[hi])
            kind = self.scene.face_kind[tri]
            depth[hi] = t * np.tile(dc[:, 2], nv)[hi]
            nh = len(hi)
            p = np.empty((nh, 3))
            ng = np.empty((nh, 3), np.float32)
            n = np.empty((nh, 3), np.float32)
            vv = np.empty((nh, 3), np.float32)
            W = np.zeros((nh, len(self.basis)), np.float32)
            tex = self.texture
            view = (hi // hw).astype(np.int64)

            def shade(sl: slice) -> None:  # the compiled kernel releases the GIL: one chunk per thread
                shade_kernel(centres, view[sl], t[sl], d[sl], tri[sl], uv[sl], self._faces, self._face_normals,
                              self.scene.face_kind, self._vdata, self._smooth_kind,
                              tex.flat if tex else self._no_tex, tex.offsets if tex else self._no_off,
                              tex.size if tex else 1, tex.n_levels if tex else 1, self.textured,
                              1.0 / self.fine_texel_m, 1.0 / self.coarse_texel_m, float(camera.fx),
                              self.bump_slope, p[sl], ng[sl], n[sl], vv[sl], W[sl])

            step = -(-nh // self._threads)
            slices = [slice(k, min(k + step, nh)) for k in range(0, nh, step)]
            if len(slices) > 1 and nh > 20000:
                with ThreadPoolExecutor(len(slices)) as pool:
                    list(pool.map(shade, slices))
            else:
                shade(slice(0, nh))
            # sun: cosine and one shadow ray per pixel to a point of the sun disk
            s = light.sun_direction_map
            s32 = s.astype(np.float32)
            sunw = np.zeros(nh, np.float32)
            if light.direct_normal.max() > 0.0 and s[2] > -0.01:
                cos = n @ s32
                cand = np.flatnonzero((cos > 0) & (ng @ s32 > 0))
                if len(cand):
                    a = np.array([1.0, 0.0, 0.0]) if abs(s[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
                    e1 = np.cross(s, a)
                    e1 /= np.linalg.norm(e1)
                    e2 = np.cross(s, e1)
                    rr = self.SUN_RADIUS_RAD * np.sqrt(rng.random(len(cand)))
                    ph = rng.uniform(0.0, 2.0 * math.pi, len(cand))
                    sd = s + (rr * np.cos(ph))[:, None] * e1 + (rr * np.sin(ph))[:, None] * e2
                    occ = self.caster.occluded(p[cand] + 0.02 * ng[cand], sd, t_near_m=1e-3)
                    sunw[cand] = np.where(occ, np.float32(0.0), cos[cand])
            # spectral integration: (pixels × basis) · (basis × [illuminant, channel]); A integrates over λ
            R = (W @ self.response_matrix(light)).reshape(-1, 4, 3)
            out = R[:, 0] * sunw[:, None]
            out += R[:, 1] * vv[:, 0:1]
            out += R[:, 2] * vv[:, 1:2]
            out += R[:, 3] * vv[:, 2:3]
            raw[hi] = out
            kind_img[hi] = kind
            sun_img[hi] = sunw
            sky_img[hi] = vv[:, 0]
            pts_img[hi] = p
        H, Wd = camera.height, camera.width
        outs = []
        for k in range(nv):
            sl = slice(k * hw, (k + 1) * hw)
            outs.append(RenderOutput(raw[sl].reshape(H, Wd, 3), depth[sl].reshape(H, Wd),
                                     kind_img[sl].reshape(H, Wd), sun_img[sl].reshape(H, Wd),
                                     pts_img[sl].reshape(H, Wd, 3), sky_img[sl].reshape(H, Wd)))
        return outs
