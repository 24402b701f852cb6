"""Patch decomposition (§III-E): region merging of scattered normals, planarity kept at corners."""
from __future__ import annotations

import numpy as np
import pytest

from lightfast.daylight.errors import MeshError
from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.daylight.patches import build_patches


def _grid(n: int, size_m: float, jitter_m: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A triangulated square in the z=0 plane, its vertices lifted by ``jitter_m`` noise (scattered normals)."""
    u = np.linspace(0.0, size_m, n + 1)
    xx, yy = np.meshgrid(u, u, indexing="ij")
    v = np.stack([xx.ravel(), yy.ravel(), jitter_m * rng.normal(size=xx.size)], 1)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + n + 1, i.ravel() + n + 2
    f = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])
    return v, f


def _mesh(v: np.ndarray, f: np.ndarray) -> ReflectanceMesh:
    return ReflectanceMesh(v, f, np.full((len(v), 3), 0.5))


def test_merge_gathers_a_noisy_plane_into_one_patch_per_cell() -> None:
    rng = np.random.default_rng(0)
    v, f = _grid(20, 0.099, 0.0005, rng)  # one 10-cm cell; face normals scatter (median 9°, p95 20°)
    mesh = _mesh(v, f)
    spread = np.degrees(np.arccos(np.clip(mesh.face_normals[:, 2], -1, 1)))
    assert np.percentile(spread, 90) > 8.0  # the normals really do scatter over several 10° bins
    assert build_patches(mesh, normal_merge_deg=0.0).count > 5
    merged = build_patches(mesh, normal_merge_deg=30.0)
    assert merged.count == 1
    assert merged.normal[0] @ [0.0, 0.0, 1.0] > 0.99
    assert merged.area_m2.sum() == pytest.approx(mesh.face_areas_m2.sum())


def test_merge_keeps_perpendicular_planes_apart() -> None:
    rng = np.random.default_rng(1)
    v1, f1 = _grid(8, 0.09, 0.0, rng)  # floor z=0
    v2 = v1[:, [0, 2, 1]] + [0.0, 0.005, 0.0]  # wall y≈0.005, in the same cell
    f2 = f1[:, [0, 2, 1]] + len(v1)
    mesh = _mesh(np.concatenate([v1, v2]), np.concatenate([f1, f2]))
    patches = build_patches(mesh, normal_merge_deg=30.0)
    assert patches.count == 2
    normals = {tuple(np.round(np.abs(n), 3)) for n in patches.normal}
    assert normals == {(0.0, 0.0, 1.0), (0.0, 1.0, 0.0)}


def test_merge_angle_is_validated() -> None:
    v, f = _grid(2, 0.1, 0.0, np.random.default_rng(2))
    with pytest.raises(MeshError, match="normal_merge_deg"):
        build_patches(_mesh(v, f), normal_merge_deg=95.0)
