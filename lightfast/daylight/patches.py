"""Uniformly sized planar patches of the mesh (paper §III-E, after [4]).

Radiosity transport between every pair of vertices costs |V|² rays; the paper groups connected vertices of planar
regions into patches P (about 10×10 cm) and propagates light from patches instead, which costs |V|·|P|. Here a
triangle joins the patch of its (normal direction, 3-D grid cell) pair: triangles of one plane inside one cell
of ``patch_size_m`` form a patch, so patches are planar and at most a cell across.

Each patch carries its area, area-weighted centroid and unit normal, mean reflectance, and a *sample point*: the
centroid of its triangle closest to the area centroid, which always lies on the surface. Two sparse matrices tie
patches and vertices together:

* ``vertex_to_patch`` (P×V): the area-weighted mean over a patch of a per-vertex quantity (rows sum to 1);
* ``patch_to_vertex`` (V×P): interpolation of a smooth per-patch quantity (the indirect irradiance) back to the
  vertices, by inverse-square-distance weights over nearby coplanar patches with a similar normal (rows sum to 1).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from lightfast.daylight.lights import fibonacci_sphere
from lightfast.daylight.mesh import MeshError, ReflectanceMesh


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
    interpolation_neighbours: int = 8,
    min_normal_cos: float = 0.8,
) -> Patches:
    """Group the triangles of ``mesh`` into planar patches of at most ``patch_size_m`` across.

    ``normal_bins`` directions (Fibonacci sphere, ~10° apart for 400) quantize face normals; faces of one bin in one
    grid cell form a patch. ``interpolation_neighbours`` and ``min_normal_cos`` shape :attr:`Patches.patch_to_vertex`.
    """
    if patch_size_m <= 0:
        raise MeshError(f"patch_size_m must be > 0, got {patch_size_m}")
    fn = mesh.face_normals
    fa = mesh.face_areas_m2
    v = mesh.vertices_m
    fc = v[mesh.faces].mean(axis=1)

    # nearest of ``normal_bins`` directions (Euclidean nearest = largest dot product for unit vectors)
    _, normal_bin = cKDTree(fibonacci_sphere(normal_bins)).query(fn)
    cell = np.floor((fc - fc.min(axis=0)) / patch_size_m).astype(np.int64)
    keys = np.stack([normal_bin, cell[:, 0], cell[:, 1], cell[:, 2]], axis=1)
    _, face_patch = np.unique(keys, axis=0, return_inverse=True)
    face_patch = face_patch.reshape(-1).astype(np.int64)
    n_patches = int(face_patch.max()) + 1

    area = np.bincount(face_patch, weights=fa, minlength=n_patches)
    safe_area = np.maximum(area, 1e-300)
    centroid = np.stack([np.bincount(face_patch, weights=fa * fc[:, k], minlength=n_patches) for k in range(3)], 1)
    centroid /= safe_area[:, None]
    normal = np.stack([np.bincount(face_patch, weights=fa * fn[:, k], minlength=n_patches) for k in range(3)], 1)
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
