"""Procedural construction of the simulated VT&R route (paper: Paton et al., §V: a route through sand and rock,
grass and woods that loops back to its start, taught in bright sun with strong shadows).

:func:`build_route_scene` (deterministic in ``RouteConfig.seed``) → :class:`~lightfast.sim.vtr.scene.RouteScene`
in the z-up ENU map frame (metres). A smooth centreline of ``length_m``, starting at the origin in a random
direction, snakes (curvature noise, 40–160 m periods) while curling round by ``total_turn_deg`` (default 270°;
curvature ≤ ``max_curvature_per_m``), so the sun falls from every side along it; it is divided into stretches of
sand-and-rock, grass and woods (default 40 / 30 / 30 %, blended over 6 m). The terrain is a height field (random
plane waves, 8–80 m wavelengths, ``terrain_rms_m``), triangulated at ``grid_m`` within ``corridor_half_width_m``
of the centreline and at ``outer_grid_m`` out to ``outer_margin_m`` (the horizon backdrop). On it: rocks and
boulders (displaced, flattened, half-buried icospheres, radius 0.15–1.6 m, power-law sizes; dense on
sand-and-rock) and trees (tapered 8-sided trunks, crowns of 15–60 leaf clusters so that their shadows are dappled;
dense in the woods, sparse on grass). Nothing but small texture lies within ``path_clearance_m`` (rocks) /
``tree_clearance_m`` (trunks) of the centreline, so a robot with small lateral offsets can drive it; canopies
overhang the path above 3 m.

Per vertex: the area-weighted normal (on the fine grid, exact from the height field), material attributes (ground:
stretch weights and a dirt-track weight; objects: tint and texture offset) and the cosine-weighted fractions of
the hemisphere around the normal that see the sky, foliage or other geometry (``sky_samples`` Embree rays per
vertex; the renderer's sky and bounce terms). :func:`flat_test_scene`: a flat square with an optional wall, for
tests.
"""
from __future__ import annotations

import functools
import math
import time

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from lightfast.progress import track
from lightfast.raycast import RayCaster
from lightfast.sim.vtr.scene import (
    KIND_FOLIAGE,
    KIND_GROUND,
    KIND_ROCK,
    KIND_TRUNK,
    STRETCHES,
    Heightfield,
    RouteConfig,
    RouteScene,
)

__all__ = [
    "build_route_scene",
    "flat_test_scene",
]

_F32 = NDArray[np.float32]
_F64 = NDArray[np.float64]


@functools.cache
def _icosphere(subdiv: int) -> tuple[_F64, NDArray[np.int64]]:
    t = (1.0 + 5.0**0.5) / 2.0
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
             (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
             (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    v = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in verts]
    for _ in range(subdiv):
        cache: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int, cache: dict[tuple[int, int], int] = cache) -> int:
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = v[a] + v[b]
                v.append(m / np.linalg.norm(m))
                cache[key] = len(v) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    V = np.array(v)
    F = np.array(faces, dtype=np.int64)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    inward = np.sum(n * V[F].mean(axis=1), axis=1) < 0
    F[inward] = F[inward][:, ::-1]
    return V, F


def _grid(x0: float, y0: float, nx: int, ny: int, step: float, keep: NDArray[np.bool_]
          ) -> tuple[_F64, NDArray[np.int64]]:
    """Vertices (V, 2) and CCW (from above) faces of the kept cells ``keep (ny, nx)`` of a regular grid."""
    jj, ii = np.nonzero(keep)
    if not len(ii):
        return np.zeros((0, 2)), np.zeros((0, 3), np.int64)
    w = nx + 1
    i00 = jj * w + ii
    corners = np.stack([i00, i00 + 1, i00 + w + 1, i00 + w], axis=1)
    used, inv = np.unique(corners.ravel(), return_inverse=True)
    c = inv.reshape(-1, 4)
    faces = np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]])
    xy = np.stack([x0 + (used % w) * step, y0 + (used // w) * step], axis=1)
    return xy, faces


class _Parts:
    """Accumulates mesh parts (vertices, faces, kind, per-vertex attributes)."""

    def __init__(self) -> None:
        self.v: list[_F64] = []
        self.f: list[NDArray[np.int64]] = []
        self.k: list[NDArray[np.int8]] = []
        self.a: list[_F32] = []
        self.n = 0

    def add(self, vertices: _F64, faces: NDArray[np.int64], kind: int, attr: ArrayLike) -> None:
        attr = np.broadcast_to(np.asarray(attr, dtype=np.float32), (len(vertices), 4))
        self.v.append(vertices)
        self.f.append(faces + self.n)
        self.k.append(np.full(len(faces), kind, np.int8))
        self.a.append(np.array(attr))
        self.n += len(vertices)

    def arrays(self) -> tuple[_F64, NDArray[np.int64], NDArray[np.int8], _F32]:
        return np.concatenate(self.v), np.concatenate(self.f), np.concatenate(self.k), np.concatenate(self.a)


def _vertex_normals(v: _F64, f: NDArray[np.int64]) -> _F32:
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # area-weighted
    vn = np.zeros_like(v)
    for j in range(3):
        np.add.at(vn, f[:, j], fn)
    length = np.linalg.norm(vn, axis=1, keepdims=True)
    vn = np.divide(vn, length, out=np.tile([0.0, 0.0, 1.0], (len(v), 1)), where=length > 0)
    return vn.astype(np.float32)


def _hemisphere_visibility(caster: RayCaster, v: _F64, n: _F32, face_kind: NDArray[np.int8], samples: int,
                           rng: np.random.Generator, progress: bool, chunk: int = 40000) -> _F32:
    """Per vertex: cosine-weighted fractions of the hemisphere around its normal that see the sky, foliage, or
    other geometry (directions below the horizon count as other)."""
    i = np.arange(samples) + 0.5
    r = np.sqrt(i / samples)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - r * r)], axis=1)  # (K, 3)
    out = np.zeros((len(v), 3), np.float32)
    starts = range(0, len(v), chunk)
    for s0 in track(starts, desc="sky visibility", total=len(starts), enabled=progress, unit="chunk"):
        sl = slice(s0, min(s0 + chunk, len(v)))
        nn = n[sl].astype(np.float64)
        a = np.where(np.abs(nn[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = np.cross(nn, a)
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        t2 = np.cross(nn, t1)
        rot = rng.uniform(0.0, 2.0 * math.pi, len(nn))
        c, s = np.cos(rot)[:, None], np.sin(rot)[:, None]
        lx = c * local[None, :, 0] - s * local[None, :, 1]
        ly = s * local[None, :, 0] + c * local[None, :, 1]
        d = lx[..., None] * t1[:, None] + ly[..., None] * t2[:, None] + local[None, :, 2, None] * nn[:, None]
        o = v[sl][:, None, :] + 0.02 * nn[:, None, :]
        hits = caster.intersect(np.broadcast_to(o, d.shape), d, t_near_m=1e-3)
        up = d[..., 2] > 0.0
        sky = ~hits.hit & up
        fol = hits.hit & (face_kind[np.where(hits.hit, hits.triangle_id, 0)] == KIND_FOLIAGE)
        out[sl, 0] = sky.mean(axis=1)
        out[sl, 1] = fol.mean(axis=1)
        out[sl, 2] = 1.0 - out[sl, 0] - out[sl, 1]
    return out


def _smooth_noise(x: _F64, rng: np.random.Generator, periods: tuple[float, float], n: int = 4) -> _F64:
    """Sum of ``n`` random sinusoids of ``x`` with periods in ``periods``, normalized to [-1, 1]."""
    p = np.exp(rng.uniform(math.log(periods[0]), math.log(periods[1]), n))
    a = rng.uniform(0.5, 1.0, n)
    ph = rng.uniform(0.0, 2.0 * math.pi, n)
    return np.sin(2.0 * math.pi * np.asarray(x)[..., None] / p + ph) @ a / a.sum()


def _centreline(cfg: RouteConfig, rng: np.random.Generator) -> tuple[_F64, _F32]:
    ds = 0.25
    ext = cfg.extension_m
    s = np.arange(-ext, cfg.length_m + ext + ds / 2, ds)
    bias = min(math.radians(cfg.total_turn_deg) / cfg.length_m, 0.5 * cfg.max_curvature_per_m)
    kappa = bias + 0.5 * cfg.max_curvature_per_m * np.clip(1.5 * _smooth_noise(s, rng, (40.0, 160.0)), -1.0, 1.0)
    kappa[(s < 0) | (s > cfg.length_m)] = 0.0
    cum = np.cumsum(kappa) * ds
    heading = rng.uniform(0.0, 2.0 * math.pi) + cum - np.interp(0.0, s, cum)  # random heading at s = 0
    dx = np.cos(heading) * ds
    dy = np.sin(heading) * ds
    x = np.cumsum(dx)
    y = np.cumsum(dy)
    x -= np.interp(0.0, s, x)
    y -= np.interp(0.0, s, y)
    # stretches: one-hot by arc length, blended over 6 m
    fr = np.array([f for _, f in cfg.stretches], dtype=np.float64)
    bounds = np.concatenate([[0.0], np.cumsum(fr) / fr.sum() * cfg.length_m])
    idx = np.clip(np.searchsorted(bounds, s, side="right") - 1, 0, len(fr) - 1)
    onehot = np.zeros((len(s), len(STRETCHES)))
    onehot[np.arange(len(s)), [STRETCHES.index(cfg.stretches[i][0]) for i in idx]] = 1.0
    k = round(3.0 / ds)
    kern = np.hanning(2 * k + 1)
    kern /= kern.sum()
    reg = np.stack([np.convolve(np.pad(onehot[:, j], k, mode="edge"), kern, mode="valid")
                    for j in range(len(STRETCHES))], axis=1)
    return np.stack([s, x, y, heading], axis=1), reg.astype(np.float32)


def _rock_mesh(rng: np.random.Generator, radius: float) -> _F64:
    V, _ = _icosphere(2 if radius > 0.4 else 1)
    axes = rng.normal(size=(4, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    freq = rng.uniform(1.5, 4.0, 4)
    amp = rng.uniform(0.05, 0.15, 4)
    ph = rng.uniform(0.0, 2.0 * math.pi, 4)
    disp = 1.0 + np.cos((V @ axes.T) * freq + ph) @ amp
    scale = np.array([rng.uniform(0.8, 1.25), rng.uniform(0.8, 1.25), rng.uniform(0.45, 0.8)]) * radius
    yaw = rng.uniform(0.0, 2.0 * math.pi)
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return (V * disp[:, None] * scale) @ R.T


def _tree_parts(rng: np.random.Generator, base: _F64, parts: _Parts, tint: float, tex: float) -> None:
    H = rng.uniform(5.0, 12.0)
    r0 = rng.uniform(0.12, 0.35)
    crown_base = max(3.2, rng.uniform(0.35, 0.5) * H)
    sides = 8
    ang = np.arange(sides) * 2.0 * math.pi / sides
    ring_z = np.array([-0.3, crown_base, 0.85 * H])
    ring_r = np.array([r0 * 1.1, r0 * 0.8, r0 * 0.35])
    V = np.concatenate([np.stack([base[0] + r * np.cos(ang), base[1] + r * np.sin(ang),
                                  np.full(sides, base[2] + z)], axis=1) for z, r in zip(ring_z, ring_r, strict=True)])
    F = []
    for ring in range(len(ring_z) - 1):
        for j in range(sides):
            a0, a1 = ring * sides + j, ring * sides + (j + 1) % sides
            b0, b1 = a0 + sides, a1 + sides
            F += [(a0, a1, b1), (a0, b1, b0)]
    parts.add(V, np.array(F, dtype=np.int64), KIND_TRUNK, (tint, tex, 0.0, 0.0))
    # crown: leaf clusters in an ellipsoid
    Rc = rng.uniform(1.5, 3.5)
    hz = (H - crown_base) / 2.0
    centre = base + np.array([0.0, 0.0, crown_base + hz])
    cl_r = rng.uniform(0.5, 0.9)
    n = int(np.clip(0.35 * (Rc * Rc * hz) / cl_r**3, 15, 60))
    ico_v, ico_f = _icosphere(0)
    vs, fs = [], []
    for i in range(n):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        p = centre + u * rng.uniform(0.45, 1.0) ** 0.5 * np.array([Rc, Rc, hz])
        sc = cl_r * rng.uniform(0.7, 1.2, 3) * np.array([1.0, 1.0, 0.75])
        vs.append(ico_v * sc + p)
        fs.append(ico_f + 12 * i)
    parts.add(np.concatenate(vs), np.concatenate(fs), KIND_FOLIAGE, (tint, tex + 0.5, 0.0, 0.0))


def _place(rng: np.random.Generator, kd: cKDTree, reg: _F32, lo: _F64, hi: _F64, densities: tuple,
           d_min: float, d_max: float) -> tuple[_F64, NDArray[np.int64]]:
    """Random positions with per-stretch density whose distance to the centreline is in ``[d_min, d_max]``."""
    dens = np.asarray(densities, dtype=np.float64)
    if dens.max() <= 0.0:
        return np.zeros((0, 2)), np.zeros(0, np.int64)
    area = float(np.prod(hi - lo))
    n = rng.poisson(dens.max() * area)
    p = lo + rng.random((n, 2)) * (hi - lo)
    d, j = kd.query(p)
    keep = rng.random(n) < (reg[j] @ dens) / dens.max()
    keep &= (d >= d_min) & (d <= d_max)
    return p[keep], j[keep]


def build_route_scene(config: RouteConfig = RouteConfig(), *, progress: bool = False) -> RouteScene:  # noqa: B008
    """Build the route scene of ``config`` (deterministic in ``config.seed``; see the module docstring)."""
    t0 = time.perf_counter()
    cfg = config
    rng = np.random.default_rng([cfg.seed, 1])
    stations, reg = _centreline(cfg, rng)
    hf = Heightfield.random(np.random.default_rng([cfg.seed, 2]), cfg.terrain_rms_m)
    kd = cKDTree(stations[:, 1:3])
    D = cfg.corridor_half_width_m
    lo = stations[:, 1:3].min(axis=0) - D - 2.0
    hi = stations[:, 1:3].max(axis=0) + D + 2.0
    parts = _Parts()

    def ground_attr(xy: _F64) -> _F32:
        d, j = kd.query(xy)
        track = np.exp(-((d / 0.9) ** 2)) * (1.0 - reg[j, 0])
        return np.concatenate([reg[j], track[:, None]], axis=1).astype(np.float32)

    # fine corridor grid, then the coarse backdrop (slightly lower, beyond the corridor)
    g = cfg.grid_m
    nx, ny = math.ceil((hi[0] - lo[0]) / g), math.ceil((hi[1] - lo[1]) / g)
    cx = lo[0] + (np.arange(nx) + 0.5) * g
    cy = lo[1] + (np.arange(ny) + 0.5) * g
    dist = kd.query(np.stack(np.meshgrid(cx, cy), axis=-1).reshape(-1, 2))[0].reshape(ny, nx)
    xy, f = _grid(lo[0], lo[1], nx, ny, g, dist < D + 0.75 * cfg.outer_grid_m)
    parts.add(np.column_stack([xy, hf(xy)]), f, KIND_GROUND, ground_attr(xy))
    n_fine = len(xy)
    G = cfg.outer_grid_m
    olo, ohi = lo - cfg.outer_margin_m, hi + cfg.outer_margin_m
    nx, ny = math.ceil((ohi[0] - olo[0]) / G), math.ceil((ohi[1] - olo[1]) / G)
    cx = olo[0] + (np.arange(nx) + 0.5) * G
    cy = olo[1] + (np.arange(ny) + 0.5) * G
    dist = kd.query(np.stack(np.meshgrid(cx, cy), axis=-1).reshape(-1, 2))[0].reshape(ny, nx)
    xy, f = _grid(olo[0], olo[1], nx, ny, G, dist > D)
    parts.add(np.column_stack([xy, hf(xy) - 0.03]), f, KIND_GROUND, ground_attr(xy))
    # rocks
    rng_r = np.random.default_rng([cfg.seed, 3])
    pos, j = _place(rng_r, kd, reg, lo, hi, cfg.rock_density, 0.0, D - 0.5)
    r_min, r_max, a = 0.15, 1.6, 1.2
    radii = r_min * (1.0 - rng_r.random(len(pos)) * (1.0 - (r_max / r_min) ** -a)) ** (-1.0 / a)
    d = kd.query(pos)[0] if len(pos) else np.zeros(0)
    ok = d >= cfg.path_clearance_m + radii * 1.25
    n_rocks = 0
    for p, r, jj in zip(pos[ok], radii[ok], j[ok], strict=True):
        V = _rock_mesh(rng_r, float(r))
        z = hf(p[None])[0] - 0.3 * V[:, 2].max()
        V = V + np.array([p[0], p[1], z])
        red = float(np.clip(reg[jj, 0] * rng_r.uniform(0.2, 1.0) + rng_r.uniform(-0.2, 0.2), 0.0, 1.0))
        parts.add(V, _icosphere(2 if r > 0.4 else 1)[1], KIND_ROCK, (red, rng_r.random(), 0.0, 0.0))
        n_rocks += 1
    # trees
    rng_t = np.random.default_rng([cfg.seed, 4])
    pos, j = _place(rng_t, kd, reg, lo - cfg.tree_band_m, hi + cfg.tree_band_m, cfg.tree_density,
                    cfg.tree_clearance_m + 0.4, D + cfg.tree_band_m)
    trunks: list[_F64] = []
    for p in pos:
        if trunks and np.min(np.linalg.norm(np.array(trunks) - p, axis=1)) < 2.0:
            continue
        trunks.append(p)
        _tree_parts(rng_t, np.array([p[0], p[1], hf(p[None])[0]]), parts, rng_t.random(), rng_t.random())
    vertices, faces, kinds, attr = parts.arrays()
    t_geom = time.perf_counter() - t0
    normals = _vertex_normals(vertices, faces)
    # the fine grid's normals from the height field (exact, no seam artefacts)
    gr = hf.gradient(vertices[:n_fine, :2])
    nz = np.column_stack([-gr, np.ones(n_fine)])
    normals[:n_fine] = nz / np.linalg.norm(nz, axis=1, keepdims=True)
    caster = RayCaster(vertices, faces)
    vis = _hemisphere_visibility(caster, vertices, normals, kinds, cfg.sky_samples,
                                 np.random.default_rng([cfg.seed, 5]), progress)
    stats = {"vertices": len(vertices), "triangles": len(faces), "rocks": n_rocks,
             "trees": len(trunks), "seconds_geometry": round(t_geom, 3),
             "seconds_total": round(time.perf_counter() - t0, 3)}
    scene = RouteScene(cfg, vertices, faces, kinds, attr, normals, vis, stations, reg, hf, stats)
    scene._caster = caster  # type: ignore[attr-defined]
    return scene


def flat_test_scene(*, material: str = "sand_rock", wall: bool = True, size_m: float = 40.0,
                    grid_m: float = 1.0) -> RouteScene:
    """A flat square of ground of one stretch (``material``) with an optional 3 m high, 8 m long wall along the
    x axis at y = 4 m (north of the origin), for tests: its shadow falls on the ground when the sun is south."""
    cfg = RouteConfig.for_tests(length_m=size_m / 2.0, stretches=((material, 1.0),), terrain_rms_m=0.0)
    parts = _Parts()
    n = round(size_m / grid_m)
    half = size_m / 2.0
    xy, f = _grid(-half, -half, n, n, grid_m, np.ones((n, n), bool))
    reg = np.zeros(4, np.float32)
    reg[STRETCHES.index(material)] = 1.0
    parts.add(np.column_stack([xy, np.zeros(len(xy))]), f, KIND_GROUND, reg)
    if wall:
        x0, x1, y0, y1, h = -4.0, 4.0, 4.0, 4.3, 3.0
        V = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0],
                      [x0, y0, h], [x1, y0, h], [x1, y1, h], [x0, y1, h]], dtype=np.float64)
        F = np.array([[0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7],
                      [4, 5, 6], [4, 6, 7]], dtype=np.int64)
        parts.add(V, F, KIND_ROCK, (0.0, 0.0, 0.0, 0.0))
    vertices, faces, kinds, attr = parts.arrays()
    normals = _vertex_normals(vertices, faces)
    caster = RayCaster(vertices, faces)
    vis = _hemisphere_visibility(caster, vertices, normals, kinds, 64, np.random.default_rng(0), False)
    s = np.arange(-half, half + 0.125, 0.25)
    stations = np.column_stack([s, s, np.zeros_like(s), np.zeros_like(s)])
    sreg = np.tile(reg[:3], (len(s), 1))
    scene = RouteScene(cfg, vertices, faces, kinds, attr, normals, vis, stations, sreg,
                       Heightfield(np.zeros((0, 2)), np.zeros(0), np.zeros(0)))
    scene._caster = caster  # type: ignore[attr-defined]
    return scene
