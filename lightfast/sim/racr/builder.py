"""Triangle-mesh builder of the simulated rACR scenes (paper §5.1: subjects with 3-D micro-structure).

:class:`Builder` collects mesh parts in the world frame (metres, z up, a subject's front facing −y): displaced
rectangles (:meth:`Builder.surface`), surfaces of revolution (:meth:`Builder.lathe`), boxes, hex bolts and bolt
circles. Each part is a regular vertex grid displaced along its normal by a relief
:class:`~lightfast.sim.racr.materials.Canvas` (heights in metres) and a fine roughness, both faded out near the
part's edges so that parts meet without cracks; per-vertex linear RGB albedo comes from a
:data:`~lightfast.sim.racr.materials.Material` and an optional RGBA decal canvas. Detailed surfaces use a vertex
step of ``res`` (the scene's ``resolution_m``, default :data:`DEFAULT_RESOLUTION_M` = 2.5 mm), backdrops a coarser
one (``coarse``). :meth:`Builder.finish` returns the :class:`~lightfast.daylight.mesh.ReflectanceMesh`: vertices
rounded to float32 (what the PLY file holds), albedo clipped to [0.02, 0.95], degenerate triangles dropped.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.sim.racr.materials import Canvas, Material, fbm3

__all__ = ["DEFAULT_RESOLUTION_M", "Builder", "Recipe", "unit"]

F64 = NDArray[np.float64]

#: Default vertex step of detailed surfaces (m).
DEFAULT_RESOLUTION_M = 0.0025


@dataclass
class _Part:
    vertices: F64
    faces: NDArray[np.int64]
    rho: F64


def _grid_faces(nu: int, nv: int, wrap_u: bool) -> NDArray[np.int64]:
    """Two triangles per cell of an ``nu × nv`` vertex grid (u-major); front side is ∂u × ∂v."""
    iu = np.arange(nu if wrap_u else nu - 1)
    i_grid, j_grid = np.meshgrid(iu, np.arange(nv - 1), indexing="ij")
    i, j = i_grid.ravel(), j_grid.ravel()
    i1 = (i + 1) % nu
    a, b, c, d = i * nv + j, i1 * nv + j, i1 * nv + j + 1, i * nv + j + 1
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _lines(a: float, b: float, step: float) -> F64:
    n = max(1, math.ceil((b - a) / step - 1e-9))
    return np.linspace(a, b, n + 1)


def unit(v: ArrayLike) -> F64:
    a = np.asarray(v, dtype=np.float64)
    return a / np.linalg.norm(a)


def _taper(x: F64, length: float, margin: float) -> F64:
    """0 at both ends of [0, length], 1 beyond ``margin`` from them (smoothstep)."""
    if margin <= 0.0:
        return np.ones_like(x)
    t = np.clip(np.minimum(x, length - x) / margin, 0.0, 1.0)
    return t * t * (3 - 2 * t)


class Builder:
    """Collects mesh parts. ``res`` is the vertex step of detailed surfaces, ``coarse`` of backdrops."""

    def __init__(self, res: float, seed: int) -> None:
        self.res = float(res)
        self.coarse = max(5.0 * self.res, 0.012)
        self.base_res = self.res
        self.seed = seed
        self.parts: list[_Part] = []

    def scale_detail(self, factor: float) -> None:
        """Coarsen the detail step for large subjects seen from further away (same pixels per vertex)."""
        self.res = self.base_res * max(1.0, factor)

    def _add(self, P: F64, h: F64, uv: F64, material: Material, decal: Canvas | None, wrap_u: bool,
             nu: int, nv: int) -> None:
        flat = P.reshape(-1, 3)
        rho = material(flat, h.reshape(-1), uv.reshape(-1, 2))
        if decal is not None:
            d = decal.sample(uv[..., 0].reshape(-1), uv[..., 1].reshape(-1))
            a = d[:, 3:4]
            rho = rho * (1 - a) + d[:, :3] * a
        self.parts.append(_Part(flat, _grid_faces(nu, nv, wrap_u), rho))

    def surface(self, origin: Sequence[float], eu: Sequence[float], ev: Sequence[float], size_u: float,
                size_v: float, material: Material, *, step: float | None = None, relief: Canvas | None = None,
                decal: Canvas | None = None, rough_m: float = 0.0, taper_m: float = 0.004) -> None:
        """A flat rectangle ``origin + u eu + v ev`` (front side ``eu × ev``) displaced along its normal by the
        ``relief`` canvas and a fine roughness, both faded out within ``taper_m`` of the edges (no cracks)."""
        step = step or self.res
        o, a, b = np.asarray(origin, float), unit(eu), unit(ev)
        n = np.cross(a, b)
        us, vs = _lines(0.0, size_u, step), _lines(0.0, size_v, step)
        U, V = np.meshgrid(us, vs, indexing="ij")
        h = np.zeros_like(U)
        if relief is not None:
            h += relief.sample(U.ravel(), V.ravel()).reshape(U.shape)
        P0 = o + U[..., None] * a + V[..., None] * b
        if rough_m > 0.0:
            h += rough_m * (fbm3(P0.reshape(-1, 3), 0.01, self.seed + 77, 3).reshape(U.shape) - 0.5)
        h *= _taper(U, size_u, taper_m) * _taper(V, size_v, taper_m)
        P = P0 + h[..., None] * n
        self._add(P, h, np.stack([U, V], -1), material, decal, False, len(us), len(vs))

    def lathe(self, center: ArrayLike, axis: ArrayLike, ref: ArrayLike,
              profile: Sequence[tuple[float, float]], material: Material, *, step: float | None = None,
              n_theta: int | None = None, relief: Canvas | None = None, rough_m: float = 0.0,
              taper_m: float = 0.003) -> None:
        """A surface of revolution of the polyline ``profile`` of ``(r, z)`` points (one smooth section; start a
        new section for a hard edge). Front side: outward when the profile runs counter-clockwise in the (r, z)
        half-plane (e.g. up a cylinder wall, then inwards over its top). ``relief`` is sampled at
        ``u = θ · r_max`` (wrapping) and ``v`` = arc length from the profile's start."""
        step = step or self.res
        c, ax = np.asarray(center, float), unit(axis)
        e1 = unit(np.asarray(ref, float) - np.dot(ref, ax) * ax)
        e2 = np.cross(ax, e1)
        prof = np.asarray(profile, dtype=np.float64)
        seg = np.linalg.norm(np.diff(prof, axis=0), axis=1)
        s_knots = np.concatenate([[0.0], np.cumsum(seg)])
        length = float(s_knots[-1])
        # sample every profile segment on its own so that the profile's corners are kept
        ss = np.unique(np.concatenate([_lines(a, b2, step) for a, b2 in itertools.pairwise(s_knots)
                                       if b2 > a]))
        r = np.interp(ss, s_knots, prof[:, 0])
        z = np.interp(ss, s_knots, prof[:, 1])
        # outward normal in (r, z): (dz, -dr) of the local tangent
        dr, dz = np.gradient(r, ss), np.gradient(z, ss)
        nn = np.hypot(dr, dz)
        nr, nz = dz / np.maximum(nn, 1e-12), -dr / np.maximum(nn, 1e-12)
        rmax = float(prof[:, 0].max())
        if n_theta is None:
            n_theta = max(12, math.ceil(2 * math.pi * rmax / step))
        th = 2 * math.pi * np.arange(n_theta) / n_theta
        T, S = np.meshgrid(th, ss, indexing="ij")
        R, Z = np.meshgrid(th, r, indexing="ij")[1], np.meshgrid(th, z, indexing="ij")[1]
        NR, NZ = np.meshgrid(th, nr, indexing="ij")[1], np.meshgrid(th, nz, indexing="ij")[1]
        U = T * rmax
        h = np.zeros_like(T)
        if relief is not None:
            h += relief.sample(U.ravel(), S.ravel()).reshape(T.shape)
        radial = np.cos(T)[..., None] * e1 + np.sin(T)[..., None] * e2
        P0 = c + R[..., None] * radial + Z[..., None] * ax
        if rough_m > 0.0:
            h += rough_m * (fbm3(P0.reshape(-1, 3), 0.01, self.seed + 78, 3).reshape(T.shape) - 0.5)
        h *= _taper(S, length, taper_m)
        P = P0 + (h * NR)[..., None] * radial + (h * NZ)[..., None] * ax
        self._add(P, h, np.stack([U, S], -1), material, None, True, n_theta, len(ss))

    def box(self, lo: Sequence[float], size: Sequence[float], material: Material, *, step: float | None = None,
            front: dict[str, Any] | None = None, bottom: bool = False, R: F64 | None = None,
            pivot: Sequence[float] | None = None) -> None:
        """An axis-aligned box from corner ``lo`` (faces outward); the front face (−y) may get ``front`` keyword
        arguments for :meth:`surface` (relief, decal, step). Rotated by ``R`` about ``pivot`` when given."""
        x0, y0, z0 = lo
        sx, sy, sz = size
        x1, y1, z1 = x0 + sx, y0 + sy, z0 + sz
        ex, ey, ez = (1.0, 0, 0), (0, 1.0, 0), (0, 0, 1.0)
        first = len(self.parts)
        st = step or self.res
        fr = dict(front or {})
        fr.setdefault("step", st)
        self.surface((x0, y0, z0), ex, ez, sx, sz, fr.pop("material", material), **fr)  # front (-y)
        self.surface((x1, y1, z0), (-1.0, 0, 0), ez, sx, sz, material, step=st)  # back (+y)
        self.surface((x0, y1, z0), (0, -1.0, 0), ez, sy, sz, material, step=st)  # -x
        self.surface((x1, y0, z0), ey, ez, sy, sz, material, step=st)  # +x
        self.surface((x0, y0, z1), ex, ey, sx, sy, material, step=st)  # top
        if bottom:
            self.surface((x0, y1, z0), ex, (0, -1.0, 0), sx, sy, material, step=st)
        if R is not None:
            pv = np.asarray(pivot if pivot is not None else (x0 + sx / 2, y0 + sy / 2, z0), float)
            for p in self.parts[first:]:
                p.vertices = (p.vertices - pv) @ np.asarray(R).T + pv

    def bolt(self, pos: ArrayLike, normal: ArrayLike, radius: float, material: Material, *,
             height: float | None = None, washer: bool = True) -> None:
        """A hex bolt head (and washer) standing on a surface at ``pos`` with outward ``normal``."""
        n = unit(normal)
        ref = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
        hgt = height if height is not None else 0.7 * radius
        z0 = 0.0
        if washer:
            w = 0.25 * radius
            self.lathe(pos, n, ref, [(1.5 * radius, 0.0), (1.5 * radius, w), (0.0, w)], material,
                       step=self.res, n_theta=max(12, int(2 * math.pi * 1.5 * radius / self.res)), taper_m=0.0)
            z0 = w
        self.lathe(np.asarray(pos, float) + z0 * n, n, ref, [(radius, 0.0), (radius, hgt)], material, n_theta=6,
                   step=self.res, taper_m=0.0)
        self.lathe(np.asarray(pos, float) + z0 * n, n, ref, [(radius, hgt), (0.6 * radius, 1.15 * hgt),
                                                             (0.0, 1.15 * hgt)], material, n_theta=6,
                   step=self.res, taper_m=0.0)

    def bolt_circle(self, center: Sequence[float], normal: Sequence[float], ref: Sequence[float], circle_r: float,
                    n: int, radius: float, material: Material) -> None:
        nn = unit(normal)
        e1 = unit(np.asarray(ref, float) - np.dot(ref, nn) * nn)
        e2 = np.cross(nn, e1)
        for k in range(n):
            a = 2 * math.pi * (k + 0.5) / n
            self.bolt(np.asarray(center, float) + circle_r * (math.cos(a) * e1 + math.sin(a) * e2), nn, radius,
                      material)

    def finish(self) -> ReflectanceMesh:
        v = np.concatenate([p.vertices for p in self.parts])
        offs = np.cumsum([0] + [len(p.vertices) for p in self.parts[:-1]])
        f = np.concatenate([p.faces + o for p, o in zip(self.parts, offs, strict=True)])
        rho = np.concatenate([p.rho for p in self.parts])
        # round to what the PLY file holds (float32), drop degenerate triangles
        v = v.astype(np.float32).astype(np.float64)
        rho = np.clip(rho, 0.02, 0.95).astype(np.float32).astype(np.float64)
        area2 = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
        f = f[area2 > 1e-12]
        return ReflectanceMesh(v, f, rho)


#: A subject recipe: ``(builder, rng, seed, outdoor) → (target point (3,) m, base camera distance m, description)``.
Recipe = Callable[[Builder, np.random.Generator, int, bool], tuple[F64, float, str]]
