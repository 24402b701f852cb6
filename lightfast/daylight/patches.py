"""Uniformly sized planar patches of the mesh (paper §III-E, after [4]).

Radiosity transport between every pair of vertices costs |V|² rays; the paper groups connected vertices of planar
regions into patches P (about 10×10 cm) and propagates light from patches instead, which costs |V|·|P|. Here the
triangles inside one 3-D grid cell of ``patch_size_m`` are grouped by normal direction: face normals are quantized
to a Fibonacci sphere, and within each cell the direction bins are merged greedily into regions — the bin holding
most area seeds a region that takes every bin of the cell within ``normal_merge_deg`` of it, then the largest bin
left seeds the next; stray regions under a tenth of a cell face's area join the nearest larger region in direction.
Patches are thus nearly planar and at most a cell across. The merge matters for reconstructed maps: marching-cubes
face normals scatter by several degrees around the plane's normal, and without it every cell of a wall would split
into a dozen patches.

Each patch carries its area, area-weighted centroid and unit normal, mean reflectance, and a *sample point*: the
centroid of its triangle closest to the area centroid, which always lies on the surface. Two sparse matrices tie
patches and vertices together:

* ``vertex_to_patch`` (P×V): the area-weighted mean over a patch of a per-vertex quantity (rows sum to 1);
* ``patch_to_vertex`` (V×P): interpolation of a smooth per-patch quantity (the indirect irradiance) back to the
  vertices, by inverse-square-distance weights over nearby coplanar patches with a similar normal (rows sum to 1).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from lightfast.daylight.errors import MeshError
from lightfast.daylight.lights import fibonacci_sphere
from lightfast.daylight.mesh import ReflectanceMesh


@dataclass(frozen=True, eq=False)
class Patches:
    """The patch decomposition of a mesh. Arrays index patches 0..P-1."""

    face_patch: NDArray[np.int64]  # (F,) patch of every triangle
    area_m2: NDArray[np.float64]  # (P,)
    centroid_m: NDArray[np.float64]  # (P, 3)
    normal: NDArray[np.float64]  # (P, 3) unit
    reflectance: NDArray[np.float64]  # (P, 3)
    sample_point_m: NDArray[np.float64]  # (P, 3), on the surface
    vertex_to_patch: sp.csc_matrix  # (P, V), column-compressed: sun updates take it a block of vertices at a time
    patch_to_vertex: sp.csr_matrix  # (V, P)

    @property
    def count(self) -> int:
        return len(self.area_m2)


def build_patches(
    mesh: ReflectanceMesh,
    *,
    patch_size_m: float = 0.1,
    normal_bins: int = 400,
    normal_merge_deg: float = 0.0,
    interpolation_neighbours: int = 8,
    min_normal_cos: float = 0.8,
) -> Patches:
    """Group the triangles of ``mesh`` into planar patches of at most ``patch_size_m`` across.

    ``normal_bins`` directions (Fibonacci sphere, ~10° apart for 400) quantize face normals; within a grid cell, bins
    within ``normal_merge_deg`` of a region's seed bin join it, and regions under a tenth of a cell's face area join
    the closest larger one within twice that angle (0: every bin is its own patch).
    ``interpolation_neighbours`` and ``min_normal_cos`` shape :attr:`Patches.patch_to_vertex`.
    """
    if patch_size_m <= 0:
        raise MeshError(f"patch_size_m must be > 0, got {patch_size_m}")
    if not 0.0 <= normal_merge_deg < 90.0:
        raise MeshError(f"normal_merge_deg must be in [0, 90), got {normal_merge_deg}")
    fn = mesh.face_normals
    fa = mesh.face_areas_m2
    v = mesh.vertices_m
    fc = v[mesh.faces].mean(axis=1)

    # nearest of ``normal_bins`` directions (Euclidean nearest = largest dot product for unit vectors)
    directions = fibonacci_sphere(normal_bins)
    _, normal_bin = cKDTree(directions).query(fn)
    cell = np.floor((fc - fc.min(axis=0)) / patch_size_m).astype(np.int64)
    # (normal bin, cell) nodes, in the order of these keys: patches keep it (a map whose faces need no merge gets
    # exactly the patches, and the patch order, of plain binning)
    keys = np.stack([normal_bin, cell[:, 0], cell[:, 1], cell[:, 2]], axis=1)
    node_keys, face_node = np.unique(keys, axis=0, return_inverse=True)
    face_node = face_node.reshape(-1)
    if normal_merge_deg > 0.0:
        _, node_cell = np.unique(node_keys[:, 1:], axis=0, return_inverse=True)
        node_area = cast(NDArray[np.float64], np.bincount(face_node, weights=fa, minlength=len(node_keys)))
        node_region = _merge_bins(node_cell.reshape(-1), directions[node_keys[:, 0]], node_area,
                                  math.cos(math.radians(normal_merge_deg)), min_area=0.1 * patch_size_m**2)
        _, face_patch = np.unique(node_region[face_node], return_inverse=True)
    else:
        face_patch = face_node
    face_patch = face_patch.reshape(-1).astype(np.int64)
    n_patches = int(face_patch.max()) + 1

    # bincount with weights sums float64 (NumPy's stubs type every bincount as integer)
    area = cast(NDArray[np.float64], np.bincount(face_patch, weights=fa, minlength=n_patches))
    safe_area = np.maximum(area, 1e-300)
    centroid = cast(NDArray[np.float64], np.stack(
        [np.bincount(face_patch, weights=fa * fc[:, k], minlength=n_patches) for k in range(3)], 1))
    centroid /= safe_area[:, None]
    normal = cast(NDArray[np.float64], np.stack(
        [np.bincount(face_patch, weights=fa * fn[:, k], minlength=n_patches) for k in range(3)], 1))
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    rho_f = mesh.face_reflectance
    reflectance = np.stack(
        [np.bincount(face_patch, weights=fa * rho_f[:, k], minlength=n_patches) for k in range(3)], 1
    ) / safe_area[:, None]

    # sample point: centroid of the patch's face nearest to the patch centroid
    d2 = np.sum((fc - centroid[face_patch]) ** 2, axis=1)
    order = np.lexsort((d2, face_patch))
    first = np.ones(len(order), dtype=bool)
    first[1:] = face_patch[order][1:] != face_patch[order][:-1]
    sample_point = np.empty((n_patches, 3))
    sample_point[face_patch[order][first]] = fc[order][first]

    # P×V area-weighted averaging: each face gives a third of its area to each of its vertices
    rows = np.repeat(face_patch, 3)
    cols = mesh.faces.reshape(-1)
    vals = np.repeat(fa / 3.0, 3) / safe_area[rows]
    vertex_to_patch = sp.csc_matrix((vals, (rows, cols)), shape=(n_patches, mesh.num_vertices))
    vertex_to_patch.sum_duplicates()

    patch_to_vertex = _interpolation_matrix(
        mesh, sample_point, normal, face_patch, patch_size_m=patch_size_m,
        neighbours=interpolation_neighbours, min_normal_cos=min_normal_cos,
    )
    return Patches(face_patch, area, centroid, normal, reflectance, sample_point, vertex_to_patch, patch_to_vertex)


def _merge_bins(node_cell: NDArray[np.int64], node_dir: NDArray[np.float64], node_area: NDArray[np.float64],
                min_cos: float, min_area: float) -> NDArray[np.int64]:
    """Region id (a seed node's index) of every (cell, normal bin) node.

    Per cell, the unassigned node with most area seeds a region and takes every unassigned node of its cell within
    ``min_cos``; repeat until none is left (vectorized over cells: the loop runs once per region of the most
    fragmented cell). Then a region smaller than ``min_area`` — the stray normals of a noisy surface — joins the
    region of its cell that is at least ``min_area`` large and closest in direction, if that is within twice the
    merge angle; otherwise (a sliver of another surface) it stays apart.
    """
    n = len(node_cell)
    region = np.full(n, -1, dtype=np.int64)
    order = np.lexsort((-node_area, node_cell))  # by cell, largest first
    n_cells = int(node_cell.max()) + 1 if n else 0
    while True:
        left = order[region[order] < 0]
        if not len(left):
            break
        first = np.ones(len(left), dtype=bool)
        first[1:] = node_cell[left][1:] != node_cell[left][:-1]
        seed_of_cell = np.full(n_cells, -1, dtype=np.int64)
        seed_of_cell[node_cell[left[first]]] = left[first]
        seed = seed_of_cell[node_cell[left]]
        join = np.einsum("nc,nc->n", node_dir[left], node_dir[seed]) >= min_cos
        join[first] = True
        region[left[join]] = seed[join]

    seeds = np.unique(region)
    area = np.bincount(region, weights=node_area, minlength=n)[seeds]
    big, small = seeds[area >= min_area], seeds[area < min_area]
    if not len(big) or not len(small):
        return region
    # the big regions of each cell, ranked; try each rank against every small region of the same cell
    big = big[np.argsort(node_cell[big], kind="stable")]
    rank = np.arange(len(big)) - np.searchsorted(node_cell[big], node_cell[big])
    best_cos = np.full(len(small), -2.0)
    best = np.full(len(small), -1, dtype=np.int64)
    for r in range(int(rank.max()) + 1):
        of_cell = np.full(n_cells, -1, dtype=np.int64)
        of_cell[node_cell[big[rank == r]]] = big[rank == r]
        cand = of_cell[node_cell[small]]
        cos = np.where(cand >= 0, np.einsum("nc,nc->n", node_dir[small], node_dir[np.maximum(cand, 0)]), -2.0)
        better = cos > best_cos
        best_cos[better], best[better] = cos[better], cand[better]
    two_angles = 2.0 * min_cos * min_cos - 1.0  # cos(2θ)
    absorbed = best_cos >= two_angles
    target = np.arange(n)
    target[small[absorbed]] = best[absorbed]
    return target[region]


def _interpolation_matrix(
    mesh: ReflectanceMesh,
    sample_point: NDArray[np.float64],
    normal: NDArray[np.float64],
    face_patch: NDArray[np.int64],
    *,
    patch_size_m: float,
    neighbours: int,
    min_normal_cos: float,
) -> sp.csr_matrix:
    """V×P weights: inverse-square distance over the ``neighbours`` nearest patches that are coplanar with the
    vertex (within a quarter patch) and face the same way; a vertex with none takes its own faces' patches."""
    V, P = mesh.num_vertices, len(sample_point)
    k = min(neighbours, P)
    tree = cKDTree(sample_point)
    dist, idx = tree.query(mesh.vertices_m, k=k)
    dist = dist.reshape(V, k)
    idx = idx.reshape(V, k)
    vn = mesh.vertex_normals
    pn = normal[idx]  # (V, k, 3)
    cos = np.einsum("vkc,vc->vk", pn, vn)
    offset = np.abs(np.einsum("vkc,vkc->vk", mesh.vertices_m[:, None, :] - sample_point[idx], pn))
    ok = (cos >= min_normal_cos) & (offset <= 0.25 * patch_size_m) & (dist <= 1.5 * patch_size_m)
    eps2 = (0.05 * patch_size_m) ** 2
    w = np.where(ok, 1.0 / (dist**2 + eps2), 0.0)
    wsum = w.sum(axis=1)
    rows = np.repeat(np.arange(V), k)
    mat = sp.csr_matrix((w.reshape(-1), (rows, idx.reshape(-1))), shape=(V, P))
    # fallback for vertices without a qualifying neighbour: the patches of their own faces, by face area
    lonely = np.flatnonzero(wsum <= 0)
    if len(lonely):
        fa = mesh.face_areas_m2
        fr = np.repeat(np.arange(mesh.num_faces), 3)
        fv = mesh.faces.reshape(-1)
        sel = np.isin(fv, lonely)
        fallback = sp.csr_matrix((np.repeat(fa, 3)[sel], (fv[sel], face_patch[fr[sel]])), shape=(V, P))
        mat = mat + fallback
    mat.sum_duplicates()
    mat.eliminate_zeros()
    norm = np.asarray(mat.sum(axis=1)).reshape(-1)
    isolated = norm <= 0  # vertices of no face: keep a zero row
    return sp.diags(np.where(isolated, 0.0, 1.0 / np.where(isolated, 1.0, norm))) @ mat
