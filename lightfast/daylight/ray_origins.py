"""Junction-safe origins for the visibility rays of Eq. 1 and of the patch transport (paper §III-B, §III-E).

``G(l, v)`` is traced from a point just off the surface. Offsetting along the normal alone fails where parts meet:
the foot of a jamb lies on the sill, whose plane holds the offset origin, so the sun ray "hits" the sill at t ≈ 0;
a minimum hit distance instead lets rays from a floor vertex at a wall's foot slip behind the wall. Here the origin
is ``o = p + h·d`` with ``d`` a direction into the free space at ``p``, found from the surfaces around ``p``:

* the point's own faces (a vertex's one-ring): ``d·n_f > 0`` for every one, i.e. ``o`` lies on the free side of
  all incident faces, as the offset of PBRT's robust spawned rays (Pharr, Jakob, Humphreys, *Physically Based
  Rendering*, 4th ed., §6.8.6) lies on the side of the surface the ray leaves;
* every other triangle within ``τ`` of ``p`` (another part touching it: the sill under a jamb, the floor at a
  wall's foot, the wall behind a shelf): ``d`` must lie in front of it (``d·n_T > 0``) or leave its extent across
  one of its edges through ``p`` (``d·m_e > 0``, ``m_e`` the edge's outward normal in the triangle's plane).

``d`` maximizes the smallest of these margins (sampled on a Fibonacci sphere, then refined locally); it is the
vertex normal when that already clears every incident face and nothing touches the vertex (most vertices). When
no direction clears every touching surface, a surface lies flat on the point front to front (a box's side on a
wall, its bottom on the floor): the point is *covered* and each of its rays counts as blocked.

``h = min(ray_offset_m, max(0.1 × shortest incident edge, 64 float32 ulps of the coordinates))`` (Embree traces
in float32 around the mesh centre, :mod:`lightfast.raycast`), ``τ = h / 4``; a surface closer than ``2 h`` that
does not touch shrinks ``h`` to half its distance, so that the origin never lies on it or beyond it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lightfast.daylight.lights import fibonacci_sphere
from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.daylight.proximity import Touching, touching_faces

_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]

#: Smallest own-face margin (cosine) for which the vertex normal is kept as the offset direction.
NORMAL_MARGIN = 0.05
#: Margins (cosines) above this are all good enough: the direction then stays as close to the normal as it can.
GOOD_MARGIN = 0.5
#: Below this margin (cosine) no direction clears the touching surfaces: the point is covered.
COVERED_MARGIN = 1e-3
_SPHERE = fibonacci_sphere(256)


@dataclass(frozen=True, eq=False)
class RayOrigins:
    """Per point: where its visibility rays start (``point + offset_m``) and whether it is covered."""

    offset_m: _F64  # (N, 3)
    covered: NDArray[np.bool_]  # (N,)

    @property
    def count(self) -> int:
        return len(self.covered)


def offset_lengths(mesh: ReflectanceMesh, offset_m: float, edge_m: _F64) -> _F64:
    """``h`` for points whose shortest incident edge is ``edge_m``: at most ``offset_m``, else a tenth of that edge,
    but at least 64 float32 ulps of the largest coordinate around the mesh centre."""
    v = mesh.vertices_m
    extent = float(np.max(np.abs(v - 0.5 * (v.min(axis=0) + v.max(axis=0)))))
    floor = 64.0 * float(np.finfo(np.float32).eps) * max(extent, 1.0)
    return np.minimum(float(offset_m), np.maximum(0.1 * edge_m, floor))


def _edge_normals(tri: _F64) -> _F64:
    """(K, 3, 3): for each triangle the outward in-plane normal of the edge opposite each corner."""
    out = np.empty_like(tri)
    for k in range(3):
        c1, c2 = tri[:, (k + 1) % 3], tri[:, (k + 2) % 3]
        e = c2 - c1
        e /= np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-300)
        inward = tri[:, k] - c1
        inward -= np.einsum("ij,ij->i", inward, e)[:, None] * e
        out[:, k] = -inward / np.maximum(np.linalg.norm(inward, axis=1, keepdims=True), 1e-300)
    return out


def _sector_pieces(mesh: ReflectanceMesh, points: _F64, touch: Touching, tol: _F64) -> tuple[_F64, NDArray[np.bool_]]:
    """For each touching pair: its constraint pieces (K, 4, 3) — the face normal, then the outward normals of the
    edges that pass within ``tol`` of the point — and which pieces are used (K, 4)."""
    tri = mesh.vertices_m[mesh.faces[touch.face]]
    fn = mesh.face_normals[touch.face]
    pieces = np.zeros((len(touch.face), 4, 3))
    used = np.zeros((len(touch.face), 4), dtype=bool)
    pieces[:, 0], used[:, 0] = fn, True
    if not len(touch.face):
        return pieces, used
    m = _edge_normals(tri)
    p = points[touch.point]
    for k in range(3):
        c1 = tri[:, (k + 1) % 3]
        through = np.einsum("ij,ij->i", p - c1, m[:, k]) >= -tol[touch.point]  # within tol of the edge's line
        pieces[:, k + 1], used[:, k + 1] = m[:, k], through
    return pieces, used


def _padded(owner: _I64, values: _F64, special: _I64) -> tuple[_F64, NDArray[np.bool_]]:
    """Rows of ``values`` grouped by ``owner`` into (len(special), most rows, ...) with a validity mask."""
    order = np.argsort(owner, kind="stable")
    start = np.searchsorted(owner[order], special)
    count = np.searchsorted(owner[order], special, side="right") - start
    width = int(count.max(initial=0))
    slot = np.arange(width)
    ok = slot[None, :] < count[:, None]
    src = order[np.minimum(start[:, None] + slot[None, :], max(len(order) - 1, 0))] if len(order) else \
        np.zeros((len(special), width), dtype=np.int64)
    out = np.zeros((len(special), width, *values.shape[1:]))
    if width:
        out[ok] = values[src[ok]]
    return out, ok


def _score(dirs: _F64, own: _F64, own_ok: NDArray[np.bool_], pieces: _F64, pieces_ok: NDArray[np.bool_]) -> _F64:
    """Smallest margin of each direction (M, K, 3): own rows need ``d·n > 0``, a touching face any of its used
    pieces (M, G, 4, 3)."""
    s = np.matmul(dirs, own.transpose(0, 2, 1))  # (M, K, O)
    s = np.min(np.where(own_ok[:, None, :], s, np.inf), axis=2, initial=np.inf)
    if pieces.shape[1]:
        M, G = pieces.shape[:2]
        g = np.matmul(dirs, pieces.reshape(M, G * 4, 3).transpose(0, 2, 1)).reshape(M, -1, G, 4)
        g = np.max(np.where(pieces_ok[:, None], g, -np.inf), axis=3)
        s = np.minimum(s, np.min(np.where(pieces_ok[:, None, :, 0], g, np.inf), axis=2))
    return s


def _caps(axes: _F64, angle: float, k: int = 48) -> _F64:
    """(M, k + 1, 3): each axis, then a Fibonacci spiral over the cap of ``angle`` radians around it."""
    i = np.arange(k) + 0.5
    z = 1.0 - (1.0 - np.cos(angle)) * i / k
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    helper = np.where(np.abs(axes[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(axes, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(axes, t1)
    cap = ((r * np.cos(phi))[None, :, None] * t1[:, None] + (r * np.sin(phi))[None, :, None] * t2[:, None]
           + z[None, :, None] * axes[:, None])
    return np.concatenate([axes[:, None], cap], axis=1)


def free_directions(own: _F64, own_ok: NDArray[np.bool_], pieces: _F64, pieces_ok: NDArray[np.bool_],
                    hint: _F64, *, chunk: int = 128) -> tuple[_F64, _F64]:
    """Per point, the unit direction maximizing the smallest margin (module docstring) and that margin: the best
    of 256 directions (Fibonacci sphere, ~13° apart) and the hint, refined over caps of 9°, 2°, 0.4° and 0.08°
    around the best so far. Points are taken in chunks of similar touching-face counts (little padding)."""
    M = len(hint)
    best = np.zeros((M, 3))
    margin = np.zeros(M)
    hint_n = hint / np.maximum(np.linalg.norm(hint, axis=1, keepdims=True), 1e-300)
    order = np.argsort(pieces_ok[:, :, 0].sum(axis=1) if pieces.shape[1] else np.zeros(M), kind="stable")
    for a in range(0, M, chunk):
        sl = order[a : a + chunk]
        g = int(pieces_ok[sl, :, 0].sum(axis=1).max(initial=0)) if pieces.shape[1] else 0
        o = int(own_ok[sl].sum(axis=1).max(initial=0))
        args = (own[sl, :o], own_ok[sl, :o], pieces[sl, :g], pieces_ok[sl, :g])
        dirs = np.concatenate([np.broadcast_to(_SPHERE, (len(sl), *_SPHERE.shape)), hint_n[sl, None]], axis=1)
        rows = np.arange(len(sl))
        for angle in (None, 0.16, 0.035, 0.007, 0.0014):
            if angle is not None:
                dirs = _caps(best[sl], angle)
            s = _score(dirs, *args)
            # margins above GOOD_MARGIN are all fine: among those, stay close to the hint
            pick = np.argmax(np.minimum(s, GOOD_MARGIN) + 1e-3 * np.einsum("mkc,mc->mk", dirs, hint_n[sl]), axis=1)
            best[sl], margin[sl] = dirs[rows, pick], s[rows, pick]
    return best, margin


def _solve(base: _F64, own: _F64, own_ok: NDArray[np.bool_], touch: Touching, pieces: _F64,
           used: NDArray[np.bool_], special: _I64) -> tuple[_F64, NDArray[np.bool_]]:
    """Directions and covered flags of every point (those not in ``special`` keep ``base``); ``own`` and
    ``own_ok`` are the padded own-face normals of the special points."""
    d = base.copy()
    covered = np.zeros(len(base), dtype=bool)
    if not len(special):
        return d, covered
    no_pieces = np.zeros((len(special), 0, 4, 3)), np.zeros((len(special), 0, 4), dtype=bool)
    own_dir, own_margin = free_directions(own, own_ok, *no_pieces, base[special])
    p, p_ok = _padded(touch.point, pieces, special)
    ok_mask, _ = _padded(touch.point, used.astype(np.float64), special)
    p_ok = p_ok[..., None] & (ok_mask > 0.5)
    free = own_margin > COVERED_MARGIN  # else a folded one-ring (no side clears all its faces): keep the normal
    direction, margin = free_directions(own[free], own_ok[free], p[free], p_ok[free], own_dir[free])
    idx = special[free]
    covered[idx] = margin <= COVERED_MARGIN
    d[idx[~covered[idx]]] = direction[~covered[idx]]
    return d, covered


def _near_and_touching(mesh: ReflectanceMesh, points: _F64, h: _F64, tol: _F64, *, own_vertex: _I64 | None = None,
                       own_face: _I64 | None = None) -> tuple[_F64, Touching]:
    """The other faces within ``tol`` of each point (touching), and ``h`` shrunk to half the distance of any other
    face within ``2 h`` (a surface close in front, e.g. a slat hovering over a sill: the origin stays between)."""
    pairs = touching_faces(mesh, points, 2.0 * h, own_vertex=own_vertex, own_face=own_face)
    touching = pairs.distance_m <= tol[pairs.point]
    near = np.full(len(points), np.inf)
    np.minimum.at(near, pairs.point[~touching], 0.5 * pairs.distance_m[~touching])
    keep = touching
    return np.minimum(h, near), Touching(pairs.point[keep], pairs.face[keep], pairs.barycentric[keep],
                                         pairs.distance_m[keep])


def _own_rows(mesh: ReflectanceMesh, special: _I64) -> tuple[_I64, _F64]:
    """``(vertex, row)`` pairs of the own constraints of the ``special`` vertices: the normal of every incident
    face, and for a vertex on the mesh boundary the inward in-plane normal of each boundary edge through it (the
    origin must lie over the vertex's own faces, not beyond the edge of its part). Only the faces around those
    vertices are looked at (every face sharing an edge through a vertex is around it)."""
    is_special = np.zeros(mesh.num_vertices, dtype=bool)
    is_special[special] = True
    around = np.flatnonzero(np.any(is_special[mesh.faces], axis=1))
    faces = mesh.faces[around]
    corner = faces.reshape(-1)
    keep = is_special[corner]
    owner = [corner[keep]]
    rows = [np.repeat(mesh.face_normals[around], 3, axis=0)[keep]]
    edges = np.sort(np.stack([faces[:, [1, 2]], faces[:, [2, 0]], faces[:, [0, 1]]], axis=1), axis=2)  # opposite k
    _, inverse, counts = np.unique(edges.reshape(-1, 2), axis=0, return_inverse=True, return_counts=True)
    boundary = (counts[inverse.reshape(-1)] == 1).reshape(-1, 3)
    if np.any(boundary):
        f, k = np.nonzero(boundary)
        inward = -_edge_normals(mesh.vertices_m[faces[f]])[np.arange(len(f)), k]
        for end in (faces[f, (k + 1) % 3], faces[f, (k + 2) % 3]):
            owner.append(end[is_special[end]])
            rows.append(inward[is_special[end]])
    return np.concatenate(owner), np.concatenate(rows)


def vertex_ray_origins(mesh: ReflectanceMesh, *, offset_m: float) -> RayOrigins:
    """Junction-safe ray origins of every vertex of ``mesh`` (module docstring)."""
    V = mesh.num_vertices
    base = mesh.vertex_normals
    shortest = np.full(V, np.inf)  # shortest incident edge
    margin = np.full(V, np.inf)  # smallest cosine between the vertex normal and an incident face's normal
    for start in range(0, mesh.num_faces, 500_000):  # in blocks: bounded temporaries on maps of millions of faces
        faces = mesh.faces[start : start + 500_000]
        tri = mesh.vertices_m[faces]
        edges = np.linalg.norm(tri - np.roll(tri, -1, axis=1), axis=2)  # edge k: corner k to k + 1
        np.minimum.at(shortest, faces.reshape(-1), np.minimum(edges, np.roll(edges, 1, axis=1)).reshape(-1))
        fn = mesh.face_normals[start : start + 500_000]
        np.minimum.at(margin, faces.reshape(-1), np.einsum("fkc,fc->fk", base[faces], fn).reshape(-1))
    h = offset_lengths(mesh, offset_m, np.where(np.isfinite(shortest), shortest, 0.0))
    tol = 0.25 * h
    h, touch = _near_and_touching(mesh, mesh.vertices_m, h, tol, own_vertex=np.arange(V))
    has_faces = np.isfinite(margin)
    special = np.flatnonzero(has_faces & ((margin < NORMAL_MARGIN) | np.isin(np.arange(V), touch.point)))
    owner, rows = _own_rows(mesh, special)
    own, own_ok = _padded(owner, rows, special)
    d, covered = _solve(base, own, own_ok, touch, *_sector_pieces(mesh, mesh.vertices_m, touch, tol), special)
    return RayOrigins(h[:, None] * d, covered)


def point_ray_origins(mesh: ReflectanceMesh, points_m: _F64, faces: _I64, *, offset_m: float,
                      normals: _F64 | None = None) -> RayOrigins:
    """Junction-safe ray origins of points lying on the given faces (e.g. the patches' sample points): the face
    is the point's own surface, every other triangle within ``τ`` a touching one. Where nothing touches, the
    direction is ``normals`` (e.g. a patch's mean normal) if it clears the face, else the face normal."""
    f = np.asarray(faces, dtype=np.int64)
    tri = mesh.vertices_m[mesh.faces[f]]
    shortest = np.min(np.linalg.norm(tri - np.roll(tri, -1, axis=1), axis=2), axis=1)
    h = offset_lengths(mesh, offset_m, shortest)
    tol = 0.25 * h
    h, touch = _near_and_touching(mesh, points_m, h, tol, own_face=f)
    fn = mesh.face_normals[f]
    base = fn.copy()
    if normals is not None:
        hint = np.asarray(normals, dtype=np.float64)
        ok = np.einsum("ij,ij->i", hint, fn) >= NORMAL_MARGIN
        base[ok] = hint[ok]
    special = np.unique(touch.point)
    own, own_ok = fn[special][:, None], np.ones((len(special), 1), dtype=bool)
    d, covered = _solve(base, own, own_ok, touch, *_sector_pieces(mesh, points_m, touch, tol), special)
    return RayOrigins(h[:, None] * d, covered)
