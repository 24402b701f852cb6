"""Point–triangle proximity on a reflectance mesh: closest points, the triangles touching a point, surface lookups.

Used by :mod:`lightfast.daylight.ray_origins` (which surfaces touch a vertex, paper §III-B, Eq. 1) and to read the
radiosity at arbitrary surface points (:mod:`lightfast.daylight.radiosity_export`). The closest point on a triangle
follows Ericson, *Real-Time Collision Detection* (2005), §5.1.5 (Voronoi regions of the vertices, edges and face);
candidate triangles come from a k-d tree of the query points and a bounding ball per triangle, so no pair farther
apart than a triangle's radius plus the search radius is ever tested. Open mesh edges need no special case: the
closest point of a point beyond a boundary edge is on that edge.
"""
from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from lightfast.daylight.errors import MeshError
from lightfast.daylight.mesh import ReflectanceMesh

_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]


def closest_points_on_triangles(p: _F64, a: _F64, b: _F64, c: _F64) -> tuple[_F64, _F64]:
    """Row-wise closest point of each ``p`` on triangle ``(a, b, c)`` (all (n, 3)): ``(points, barycentric (n, 3))``
    with ``point = w0 a + w1 b + w2 c`` (Ericson §5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    bp, cp = p - b, p - c

    def dot(x: _F64, y: _F64) -> _F64:
        return np.einsum("ij,ij->i", x, y)

    d1, d2 = dot(ab, ap), dot(ac, ap)
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        denom = 1.0 / (va + vb + vc)
    v_in, w_in = vb * denom, vc * denom
    one, zero = np.ones_like(d1), np.zeros_like(d1)
    regions = [
        (d1 <= 0) & (d2 <= 0),  # vertex a
        (d3 >= 0) & (d4 <= d3),  # vertex b
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),  # edge ab
        (d6 >= 0) & (d5 <= d6),  # vertex c
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),  # edge ac
        (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),  # edge bc
    ]
    w1 = np.select(regions, [zero, one, t_ab, zero, zero, 1.0 - t_bc], default=v_in)
    w2 = np.select(regions, [zero, zero, zero, one, t_ac, t_bc], default=w_in)
    w1, w2 = np.nan_to_num(w1), np.nan_to_num(w2)  # degenerate triangles: fall back to a corner
    bary = np.stack([1.0 - w1 - w2, w1, w2], axis=1)
    return bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c, bary


def candidate_chunks(mesh: ReflectanceMesh, points: _F64, radius_m: float, *, chunk: int = 100_000
                     ) -> Iterator[tuple[_I64, _I64]]:
    """``(point index, face index)`` of every pair whose distance may be at most ``radius_m`` (the point lies in the
    triangle's bounding ball, centred on its centroid, grown by ``radius_m``), ``chunk`` faces at a time."""
    tree = cKDTree(points)
    for start in range(0, mesh.num_faces, chunk):
        stop = min(mesh.num_faces, start + chunk)
        tri = mesh.vertices_m[mesh.faces[start:stop]]
        centre = tri.mean(axis=1)
        ball = np.sqrt(np.max(np.sum((tri - centre[:, None, :]) ** 2, axis=2), axis=1)) + float(radius_m)
        found = tree.query_ball_point(centre, ball)
        counts = np.fromiter(map(len, found), dtype=np.int64, count=len(found))
        yield (np.fromiter(itertools.chain.from_iterable(found), dtype=np.int64, count=int(counts.sum())),
               np.repeat(np.arange(start, stop, dtype=np.int64), counts))


def candidate_pairs(mesh: ReflectanceMesh, points: _F64, radius_m: float) -> tuple[_I64, _I64]:
    """All pairs of :func:`candidate_chunks` at once."""
    chunks = list(candidate_chunks(mesh, points, radius_m))
    return (np.concatenate([c[0] for c in chunks]) if chunks else np.zeros(0, dtype=np.int64),
            np.concatenate([c[1] for c in chunks]) if chunks else np.zeros(0, dtype=np.int64))


@dataclass(frozen=True)
class Touching:
    """Pairs (point, face) closer than a radius: the face's closest point to the point, as barycentrics."""

    point: _I64  # (K,)
    face: _I64  # (K,)
    barycentric: _F64  # (K, 3) of the closest point
    distance_m: _F64  # (K,)


def touching_faces(mesh: ReflectanceMesh, points: _F64, radius_m: ArrayLike, *,
                   own_vertex: _I64 | None = None, own_face: _I64 | None = None) -> Touching:
    """Faces within ``radius_m`` (scalar or per point) of each point, except a point's own faces: those with
    ``own_vertex[i]`` as a corner (a mesh vertex's one-ring) or ``own_face[i]`` itself."""
    tol = np.broadcast_to(np.asarray(radius_m, dtype=np.float64), (len(points),))
    faces = mesh.faces
    parts: list[tuple[_I64, _I64, _F64, _F64]] = []
    for pi, fi in candidate_chunks(mesh, points, float(tol.max(initial=0.0))):
        keep = np.ones(len(pi), dtype=bool)
        if own_vertex is not None:
            keep &= ~np.any(faces[fi] == own_vertex[pi][:, None], axis=1)
        if own_face is not None:
            keep &= fi != own_face[pi]
        pi, fi = pi[keep], fi[keep]
        tri = mesh.vertices_m[faces[fi]]
        q, bary = closest_points_on_triangles(points[pi], tri[:, 0], tri[:, 1], tri[:, 2])
        dist = np.linalg.norm(points[pi] - q, axis=1)
        near = dist <= tol[pi]
        parts.append((pi[near], fi[near], bary[near], dist[near]))
    if not parts:
        return Touching(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0))
    return Touching(*(np.concatenate([part[k] for part in parts]) for k in range(4)))


@dataclass(frozen=True)
class SurfacePoints:
    """Where query points meet the mesh: the closest point on a front-facing triangle."""

    face: _I64  # (N,)
    barycentric: _F64  # (N, 3)
    distance_m: _F64  # (N,)

    def interpolate(self, mesh: ReflectanceMesh, per_vertex: NDArray[np.floating]) -> _F64:
        """Barycentric interpolation of a per-vertex array (V, ...) at the points."""
        corners = mesh.faces[self.face]  # (N, 3)
        values = np.asarray(per_vertex, dtype=np.float64)[corners]  # (N, 3, ...)
        w = self.barycentric.reshape(self.barycentric.shape + (1,) * (values.ndim - 2))
        return np.sum(w * values, axis=1)


def closest_surface_points(mesh: ReflectanceMesh, points_m: ArrayLike, normals: ArrayLike, *,
                           max_distance_m: float = 0.01, min_normal_cos: float = 0.0) -> SurfacePoints:
    """For each point, the closest point of the triangles within ``max_distance_m`` whose normal agrees with the
    point's (``n_f · n > min_normal_cos``: the side of a thin part the point is on). Boundary (open) edges are
    fine. Raises :class:`MeshError` naming the points with no such triangle."""
    p = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if p.shape != n.shape or not np.all(np.isfinite(p)) or not np.all(np.isfinite(n)):
        raise MeshError(f"points and normals must be finite (N, 3) arrays, got {p.shape} and {n.shape}")
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    N = len(p)
    face = np.full(N, -1, dtype=np.int64)
    bary = np.zeros((N, 3))
    dist = np.full(N, np.inf)
    if N == 0:
        return SurfacePoints(face, bary, dist)
    pi, fi = candidate_pairs(mesh, p, max_distance_m)
    facing = np.einsum("ij,ij->i", mesh.face_normals[fi], n[pi]) > min_normal_cos
    pi, fi = pi[facing], fi[facing]
    tri = mesh.vertices_m[mesh.faces[fi]]
    _, w = closest_points_on_triangles(p[pi], tri[:, 0], tri[:, 1], tri[:, 2])
    q = np.einsum("kj,kjc->kc", w, tri)
    d = np.linalg.norm(p[pi] - q, axis=1)
    order = np.lexsort((fi, d, pi))  # per point, the nearest (ties: lowest face index)
    first = np.ones(len(order), dtype=bool)
    first[1:] = pi[order][1:] != pi[order][:-1]
    best = order[first]
    ok = d[best] <= max_distance_m
    best = best[ok]
    face[pi[best]], bary[pi[best]], dist[pi[best]] = fi[best], w[best], d[best]
    missing = np.flatnonzero(face < 0)
    if len(missing):
        raise MeshError(f"{len(missing)} of {N} points are farther than {max_distance_m:g} m from a mesh surface "
                        f"facing their normal (e.g. point {missing[0]} at {np.round(p[missing[0]], 4).tolist()})")
    return SurfacePoints(face, bary, dist)
