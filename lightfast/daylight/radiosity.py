"""Normalized radiosity by radiosity transport (paper §III-B, Eq. 1–2, with the patch variant of §III-E).

Units: a light set of unit brightness (see :mod:`lightfast.daylight.lights`) gives the *normalized* irradiance
``E`` (W/m² per unit sky/ground radiance or per unit solar normal irradiance) and radiosity ``B̂ = ρ·E`` per
colour channel; the paper's radiosity for brightness ``s_x`` is ``s_x·B̂_x``.

Direct light, Eq. 1, per vertex v and light l (direction ``d_l`` towards the light, weight ``w_l``)::

    E⁰(v) = Σ_l w_l · max(0, n(v)·d_l) · G(l, v)            B⁰(v) = ρ(v) · E⁰(v)

with G(l, v) = 1 when the ray from v towards l escapes the scene (Embree occlusion rays). Rays start from
junction-safe origins (:mod:`lightfast.daylight.ray_origins`): off the vertex into the free side of its own faces
and of every surface touching it, so that a vertex where parts meet is neither lit through nor shadowed by them.

Inter-reflections, Eq. 2. The paper iterates ``B^{k+1}(v_i) = ρ(v_i) Σ_j B^k(v_j) F(v_i, v_j) G(v_i, v_j)`` with
B_l = B_l^K; read literally B^K would hold the K-th bounce alone, so this is implemented as the Jacobi iteration of
the radiosity equation, ``B^{k+1} = B⁰ + ρ·F·G·B^k``, whose K-th iterate holds the first K bounces. As in §III-E the
light is gathered from patches, not vertices, which makes the cost |V|·|P| instead of |V|². Going one step further
(|V|·|P| bits and rays are 2.9 GB and ~10¹⁰ rays at the paper's 2.1 M vertices and 11 k patches), the transport is
solved between patches — the |P|² gather factors below, visibility from one ray per patch pair — and the indirect
irradiance, which is smooth, is interpolated from the patches to the vertices (:mod:`lightfast.daylight.patches`).
Direct light stays exact per vertex, so sharp sun shadows keep the mesh's resolution.

Gather factor (point-to-patch form factor, the "disk" approximation that stays finite for near patches)::

    K_pq = A_q cosθ_p cosθ_q / (π r² + A_q) · G(p, q)

and each row is rescaled so that Σ_q K_pq equals the fraction of p's hemisphere covered by the scene (measured with
cosine-distributed rays), which makes the discrete transport conserve energy: in a closed box Σ_q K_pq = 1.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lightfast.daylight.errors import RadiosityError
from lightfast.daylight.lights import LightSet
from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.daylight.openings import through_openings
from lightfast.daylight.patches import Patches
from lightfast.daylight.ray_origins import RayOrigins, point_ray_origins, vertex_ray_origins
from lightfast.progress import track
from lightfast.raycast import RayCaster

log = logging.getLogger(__name__)


def direct_irradiance(
    mesh: ReflectanceMesh,
    caster: RayCaster,
    lights: LightSet,
    *,
    vertices: slice = slice(None),
    offset_m: float = 1e-3,
    max_rays: int = 1 << 21,
    openings: NDArray[np.float64] | None = None,
    origins: RayOrigins | None = None,
) -> NDArray[np.float64]:
    """Eq. 1 without ρ: the direct irradiance ``E⁰`` of the vertices in ``vertices`` under ``lights``.

    ``openings`` (N, 3, 3), see :mod:`lightfast.daylight.openings`: when given (N > 0), a ray that escapes the mesh
    brings light only if it crosses one of them. ``origins``: the vertices' ray origins (all of the mesh's
    vertices), by default :func:`~lightfast.daylight.ray_origins.vertex_ray_origins` with ``offset_m``."""
    normals = mesh.vertex_normals[vertices]
    out = np.zeros(len(normals))
    if len(lights.directions) == 0 or len(normals) == 0:
        return out
    if origins is None:
        origins = vertex_ray_origins(mesh, offset_m=offset_m)
    points = mesh.vertices_m[vertices] + origins.offset_m[vertices]
    open_ = ~origins.covered[vertices]  # a covered vertex (a surface lies on it) receives no direct light
    d = lights.directions
    w = lights.weights
    block = max(1, max_rays // len(d))
    for start in range(0, len(points), block):
        n = normals[start : start + block]
        cos = n @ d.T  # (b, M)
        vi, li = np.nonzero((cos > 0.0) & open_[start : start + block, None])
        if len(vi) == 0:
            continue
        starts = points[start + vi]
        blocked = caster.occluded(starts, d[li], t_near_m=0.0)
        if openings is not None and len(openings):
            free = np.flatnonzero(~blocked)
            blocked[free] = ~through_openings(starts[free], d[li[free]], openings)
        contrib = np.where(blocked, 0.0, w[li] * cos[vi, li])
        out[start : start + block] += np.bincount(vi, weights=contrib, minlength=len(n))
    return out


def _cosine_hemisphere(normals: NDArray[np.float64], n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """``n`` stratified cosine-distributed directions around each normal, (P, n, 3)."""
    side = int(np.ceil(np.sqrt(n)))
    u = (np.arange(side)[:, None] + rng.random((len(normals), side, side))) / side  # (P, side, side)
    v = (np.arange(side)[None, :] + rng.random((len(normals), side, side))) / side
    u = u.reshape(len(normals), -1)[:, :n]
    v = v.reshape(len(normals), -1)[:, :n]
    r = np.sqrt(u)
    phi = 2 * np.pi * v
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1 - u))], axis=-1)
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(normals, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normals, t1)
    return local[..., :1] * t1[:, None] + local[..., 1:2] * t2[:, None] + local[..., 2:] * normals[:, None]


@dataclass(frozen=True, eq=False)
class PatchTransport:
    """Patch-to-patch light transport: visibility, scene coverage and the gather factors ``K`` (P×P)."""

    visible: NDArray[np.bool_]  # (P, P) symmetric
    coverage: NDArray[np.float64]  # (P,) fraction of each patch's (cosine-weighted) hemisphere hitting the scene
    gather: NDArray[np.float32]  # (P, P) K_pq

    @classmethod
    def compute(
        cls,
        patches: Patches,
        caster: RayCaster,
        *,
        hemisphere_rays: int = 256,
        offset_m: float = 1e-3,
        seed: int = 0,
        progress: bool = False,
        max_rays: int = 1 << 21,
        openings: NDArray[np.float64] | None = None,
        origins: RayOrigins | None = None,
    ) -> PatchTransport:
        """Trace the visibility of every facing patch pair (one ray each) and each patch's hemisphere coverage
        (with ``openings``, a ray that escapes elsewhere than through one counts as covered). The rays start at
        the sample points moved by ``origins`` (:func:`patch_ray_origins`), by default ``offset_m`` along the patch
        normals; a patch whose sample point is covered (a surface lies on it) exchanges no light."""
        P = patches.count
        covered = np.zeros(P, dtype=bool) if origins is None else origins.covered
        pts = patches.sample_point_m + (offset_m * patches.normal if origins is None else origins.offset_m)
        visible = np.zeros((P, P), dtype=bool)
        rows_per_block = max(1, max_rays // max(P, 1))
        blocks = range(0, P, rows_per_block)
        for start in track(blocks, desc="patch visibility", total=len(blocks), enabled=progress, unit="block"):
            rows = slice(start, min(P, start + rows_per_block))
            cols = slice(start + 1, P)  # each unordered pair once: column > row
            front_p, front_q, _ = _pair_geometry(pts, patches.normal, rows, cols)
            bi, q = np.nonzero((front_p > 0) & (front_q > 0) & _upper(rows, cols) & ~covered[rows, None]
                               & ~covered[None, cols])
            if len(bi) == 0:
                continue
            p_idx = bi + rows.start
            q_idx = q + cols.start
            dvec = pts[q_idx] - pts[p_idx]
            dist = np.linalg.norm(dvec, axis=1)
            blocked = caster.occluded(pts[p_idx], dvec, t_far_m=np.maximum(dist - 2 * offset_m, 0.0))
            visible[p_idx[~blocked], q_idx[~blocked]] = True
        visible |= visible.T
        coverage = cls._coverage(patches, caster, hemisphere_rays, pts, seed, openings)
        coverage[covered] = 1.0
        return cls.from_visibility(patches, visible, coverage)

    @staticmethod
    def _coverage(patches: Patches, caster: RayCaster, n: int, pts: NDArray[np.float64], seed: int,
                  openings: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        if n <= 0:
            return np.ones(patches.count)
        rng = np.random.default_rng(seed)
        dirs = _cosine_hemisphere(patches.normal, n, rng)  # (P, n, 3)
        origins = np.broadcast_to(pts[:, None, :], dirs.shape)
        hits = caster.intersect(origins, dirs).hit.copy()
        if openings is not None and len(openings):
            esc = ~hits
            hits[esc] = ~through_openings(origins[esc], dirs[esc], openings)
        return hits.mean(axis=1)

    @classmethod
    def from_visibility(
        cls, patches: Patches, visible: NDArray[np.bool_], coverage: NDArray[np.float64], *, block: int = 512,
        normalize: bool = True,
    ) -> PatchTransport:
        """Gather factors from geometry, visibility and coverage (deterministic; used again when loading a map).

        ``normalize=False`` keeps the raw disk-approximation factors (for checking them)."""
        P = patches.count
        gather = np.zeros((P, P), dtype=np.float32)
        area = patches.area_m2.astype(np.float32)[None, :]
        for start in range(0, P, block):
            rows = slice(start, min(P, start + block))
            front_p, front_q, r2 = _pair_geometry(patches.sample_point_m, patches.normal, rows, slice(0, P))
            # K = A_q cosθ_p cosθ_q / (π r² + A_q) with cosθ = front / r, computed in place
            np.maximum(front_p, 0, out=front_p)
            np.maximum(front_q, 0, out=front_q)
            front_p *= front_q
            front_p *= area
            denom = np.float32(np.pi) * r2
            denom += area
            denom *= r2
            front_p[~visible[rows] | (r2 <= 0)] = 0.0
            np.divide(front_p, denom, out=gather[rows], where=denom > 0)
        if normalize:
            sums = gather.sum(axis=1, dtype=np.float64)
            scale = np.where(sums > 0, coverage / np.where(sums > 0, sums, 1.0), 0.0)
            gather *= scale[:, None].astype(np.float32)
        return cls(visible=visible, coverage=np.asarray(coverage, dtype=np.float64), gather=gather)


def patch_ray_origins(mesh: ReflectanceMesh, patches: Patches, *, offset_m: float) -> RayOrigins:
    """Junction-safe origins of the patches' rays, relative to their sample points (the centroid of one of their
    faces, :mod:`lightfast.daylight.ray_origins`)."""
    fc = mesh.vertices_m[mesh.faces].mean(axis=1)
    d2 = np.sum((fc - patches.sample_point_m[patches.face_patch]) ** 2, axis=1)
    order = np.lexsort((d2, patches.face_patch))
    first = np.ones(len(order), dtype=bool)
    first[1:] = patches.face_patch[order][1:] != patches.face_patch[order][:-1]
    sample_face = np.empty(patches.count, dtype=np.int64)
    sample_face[patches.face_patch[order][first]] = order[first]
    return point_ray_origins(mesh, patches.sample_point_m, sample_face, offset_m=offset_m, normals=patches.normal)


def _upper(rows: slice, cols: slice) -> NDArray[np.bool_]:
    r = np.arange(rows.start, rows.stop)[:, None]
    c = np.arange(cols.start, cols.stop)[None, :]
    return c > r


def _pair_geometry(points: NDArray[np.float64], normals: NDArray[np.float64], rows: slice, cols: slice
                   ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
    """For patch pairs (p in rows, q in cols), with matrix products only: ``n_p·(c_q − c_p)`` (q in front of p),
    ``−n_q·(c_q − c_p)`` (p in front of q) and ``|c_q − c_p|²``, as float32 (rows × cols).

    Coordinates are centred first so that float32 keeps ~1e-6 m² of precision in ``|c|² + |c'|² − 2 c·c'``."""
    c = (points - points.mean(axis=0)).astype(np.float32)
    n = normals.astype(np.float32)
    cp, cq, np_, nq = c[rows], c[cols], n[rows], n[cols]
    front_p = np_ @ cq.T
    front_p -= np.einsum("ij,ij->i", np_, cp)[:, None]
    front_q = cp @ nq.T
    front_q -= np.einsum("ij,ij->i", nq, cq)[None, :]
    r2 = cp @ cq.T
    r2 *= -2.0
    r2 += np.einsum("ij,ij->i", cp, cp)[:, None]
    r2 += np.einsum("ij,ij->i", cq, cq)[None, :]
    np.maximum(r2, 0.0, out=r2)
    return front_p, front_q, r2


class PatchRadiositySolver:
    """Eq. 2 on patches as a Jacobi iteration ``B ← ρ·(E⁰ + K·B)``, one :meth:`step` at a time.

    ``reflectance`` is (P, k) (k = 3 colour channels, or 3·C for C light sets at once) and ``direct`` (P,) or (P, k).

    ``iterations`` fixes the number of steps (the paper uses K = 10); ``None`` iterates until the largest change is
    below ``tolerance`` times the largest radiosity (at most ``max_iterations``).
    """

    def __init__(
        self,
        transport: PatchTransport,
        reflectance: NDArray[np.float64],
        direct: NDArray[np.float64],
        *,
        iterations: int | None = None,
        tolerance: float = 1e-5,
        max_iterations: int = 500,
        rows_per_step: int | None = None,
    ) -> None:
        self.rho = np.asarray(reflectance, dtype=np.float64)
        e0 = np.asarray(direct, dtype=np.float64)
        if e0.ndim == 1:
            e0 = np.repeat(e0[:, None], self.rho.shape[1], axis=1)
        self.transport = transport
        self.source = self.rho * e0
        self.radiosity = self.source.copy()
        self.iterations = iterations
        self.tolerance = tolerance
        self.max_iterations = max_iterations
        self.steps = 0
        self.converged = not np.any(self.source)  # no light: nothing to propagate
        P = self.source.shape[0]
        size = P if rows_per_step is None else max(1, int(rows_per_step))
        self._blocks = [slice(r, min(P, r + size)) for r in range(0, P, size)]
        self._block = 0
        self._next = np.empty_like(self.source)

    @property
    def done(self) -> bool:
        if self.iterations is not None:
            return self.steps >= self.iterations or self.converged
        return self.converged

    @property
    def blocks_per_iteration(self) -> int:
        return len(self._blocks)

    def step(self) -> None:
        """One block of ``rows_per_step`` patch rows of the current Jacobi iteration (the whole iteration by
        default); the iteration counts, and is checked for convergence, when its last block is done."""
        sl = self._blocks[self._block]
        gathered = (self.transport.gather[sl] @ self.radiosity.astype(np.float32)).astype(np.float64)
        self._next[sl] = self.source[sl] + self.rho[sl] * gathered
        self._block += 1
        if self._block < len(self._blocks):
            return
        self._block = 0
        new = self._next.copy()
        change = float(np.max(np.abs(new - self.radiosity)))
        self.radiosity = new
        self.steps += 1
        if change <= self.tolerance * max(float(np.max(new)), 1e-300):
            self.converged = True
        elif self.iterations is None and self.steps >= self.max_iterations:
            raise RadiosityError(f"patch radiosity did not converge in {self.max_iterations} iterations")

    def solve(self) -> NDArray[np.float64]:
        while not self.done:
            self.step()
        log.debug("patch radiosity after %d iterations", self.steps)
        return self.radiosity


def vertex_radiosity(
    mesh: ReflectanceMesh,
    patches: Patches,
    transport: PatchTransport,
    direct_v: NDArray[np.float64],
    *,
    iterations: int | None = None,
) -> NDArray[np.float64]:
    """Normalized vertex radiosity ``B̂`` from the direct irradiance of every vertex.

    ``direct_v`` is (V,) for one light set, giving (V, 3), or (V, C) for C light sets solved together (one matrix
    product per iteration for all of them), giving (V, C, 3).
    """
    single = np.ndim(direct_v) == 1
    e_v = np.asarray(direct_v, dtype=np.float64).reshape(mesh.num_vertices, -1)  # (V, C)
    C = e_v.shape[1]
    e_p = patches.vertex_to_patch @ e_v  # (P, C)
    rho_p = np.tile(patches.reflectance, (1, C))  # (P, 3C): channel-major per component
    b_p = PatchRadiositySolver(transport, rho_p, np.repeat(e_p, 3, axis=1), iterations=iterations).solve()
    indirect_v = patches.patch_to_vertex @ indirect_patch_irradiance(transport, b_p)  # (V, 3C)
    out = mesh.reflectance[:, None, :] * (e_v[:, :, None] + indirect_v.reshape(-1, C, 3))
    return out[:, 0] if single else out


def indirect_patch_irradiance(transport: PatchTransport, patch_radiosity: NDArray[np.float64]) -> NDArray[np.float64]:
    """Irradiance each patch gathers from all others, (P, 3)."""
    return (transport.gather @ patch_radiosity.astype(np.float32)).astype(np.float64)
