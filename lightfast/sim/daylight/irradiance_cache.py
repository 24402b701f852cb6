"""The ground-truth renderer's irradiance cache: Monte-Carlo indirect light per mesh vertex, denoised.

Per vertex of the room mesh (map frame, metres), the irradiance (W m⁻², linear RGB) from everything **except the
direct sun** (sky and ground through the window, and all inter-reflected light), split into four linear components
per unit source (:data:`COMPONENTS`): ``sun`` (indirect sunlight per W m⁻² of DNI), ``clear`` and ``overcast`` (per
W m⁻² of the component's DHI) and ``ground`` (per W m⁻² sr⁻¹ of ground radiance). Transport is linear and per
channel, so a frame's irradiance is ``Σ_c scale_c ⊙ E_c`` with the RGB scales of that instant
(:func:`frame_scales`; moving clouds only change the scales).

Estimator (:meth:`CacheTracer.compute_cache`): at each vertex, directions from three strategies combined by multiple
importance sampling (balance heuristic, Veach 1997), ``E(v) ≈ Σ_i L(ω_i) cos⁺θ_i / Σ_s N_s p_s(ω_i)``: (1)
cosine-weighted hemisphere directions, ``p = cos θ / π``; (2) uniform points on the window's outer rectangle,
``p = t² / (A cos θ_w)``; (3) points of the directly sunlit surfaces, drawn from a pool where parallel sun rays
through the window first hit the room (area density ``|n·s| / (A |n_w·s|)``), with a visibility ray,
``p = p_A r² / |cos θ_y|``. An escaping direction collects the sky/ground radiance through the glass; a hit
collects the previous pass's radiance at one vertex of the hit triangle, drawn with the barycentric weights as
probabilities (one sparse-matrix entry per sample). The rays are traced once; ``bounces`` Jacobi passes
``B_k = ρ (E_src + M B_{k-1} / π)`` over the gather matrix ``M`` add one bounce each (truncation error after 8
bounces ≈ ρ̄⁸ < 1 %). Rays that leave a closed room other than through the window, and rays that meet a back side,
carry no light.

Denoising (:meth:`CacheTracer.smoothing_matrix`): a local *linear* regression over the vertices within
``filter_radius_m`` on the same surface (:meth:`CacheTracer.hidden_vertices` excluded), unbiased to first order for
linear gradients and one-sided neighbourhoods; it blurs detail finer than its radius (e.g. contact shadows at the
foot of furniture). docs/daylight.md has the details; ``benchmarks/daylight_render.py`` measures noise and time.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.progress import track
from lightfast.sim.daylight.direct_sun import EPS_M, GlassModel, RoomTracer, frames
from lightfast.sim.daylight.scene import WindowGeometry
from lightfast.sim.sky_model import SkyState, float3

__all__ = [
    "COMPONENTS",
    "CacheSettings",
    "CacheTracer",
    "IrradianceCache",
    "frame_scales",
]

#: Cache components, each per unit source (see the module docstring).
COMPONENTS = ("sun", "clear", "overcast", "ground")

F64 = NDArray[np.float64]


# ----------------------------------------------------------------------------------------------------------------
# cache records


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


def _stratified_2d(rng: np.random.Generator, n_points: int, k: int) -> tuple[F64, F64]:
    """``k`` Latin-hypercube samples in [0, 1)² for each of ``n_points``: shapes (n_points, k)."""
    base = (np.arange(k) + rng.random((n_points, k))) / k
    perm = np.argsort(rng.random((n_points, k)), axis=1)
    other = (perm + rng.random((n_points, k))) / k
    return base, other


# ----------------------------------------------------------------------------------------------------------------
# the irradiance cache


class CacheTracer(RoomTracer):
    """A :class:`~lightfast.sim.daylight.direct_sun.RoomTracer` that computes :class:`IrradianceCache` s (with the
    cache filter and the hidden vertices, both cached per scene)."""

    def __init__(self, mesh: ReflectanceMesh, window: WindowGeometry | None, *, glass: GlassModel | None = None,
                 num_threads: int | None = None) -> None:
        super().__init__(mesh, window, glass=glass, num_threads=num_threads)
        self._smoothing: dict[float, sp.csr_matrix] = {}
        self._hidden: NDArray[np.bool_] | None = None

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
            org = points[idx] + EPS_M * normals_facing[idx]
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
            t1, t2 = frames(n)
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
            origin = p + EPS_M * n
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
        t1, t2 = frames(nrm)
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
            t1, t2 = frames(n)
            u1, u2 = _stratified_2d(rng, len(p), n_rays)
            r, phi = np.sqrt(u1), 2 * math.pi * u2
            d = ((r * np.cos(phi))[..., None] * t1[:, None] + (r * np.sin(phi))[..., None] * t2[:, None]
                 + np.sqrt(np.clip(1 - u1, 0, 1))[..., None] * n[:, None])
            hits = self.caster.intersect(np.broadcast_to((p + EPS_M * n)[:, None], d.shape), d)
            fn = self._face_normals[np.maximum(hits.triangle_id, 0)]
            b = hits.hit & (np.einsum("mkj,mkj->mk", fn, d) > 0)
            if self.window is not None:
                b |= ~hits.hit & ~self._crossing(p[:, None, :], d)[0]
            bad[sl] = b.sum(axis=1)
        self._hidden = bad >= 3
        return self._hidden
