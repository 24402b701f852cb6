"""Small meshes with known answers for the daylight tests."""
from __future__ import annotations

import numpy as np

from lightfast.daylight.mesh import ReflectanceMesh, as_mesh, merge_meshes


def quad_grid(origin, u, v, nu: int, nv: int, rho) -> ReflectanceMesh:
    """Tessellated parallelogram ``origin + [0,1]·u + [0,1]·v`` facing ``u × v``."""
    origin, u, v = (np.asarray(x, dtype=float) for x in (origin, u, v))
    i, j = np.meshgrid(np.arange(nu + 1), np.arange(nv + 1), indexing="ij")
    pts = origin + (i[..., None] / nu) * u + (j[..., None] / nv) * v
    idx = np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return as_mesh(pts.reshape(-1, 3), faces, rho)


def closed_box(size=(2.0, 2.0, 2.0), n: int = 8, rho=0.5) -> ReflectanceMesh:
    """A closed box with inward-facing walls, ``n`` × ``n`` quads per wall."""
    sx, sy, sz = size
    X, Y, Z, O = np.array([sx, 0, 0.0]), np.array([0, sy, 0.0]), np.array([0, 0, sz]), np.zeros(3)  # noqa: E741
    walls = [(O, X, Y), (O + Z, Y, X), (O, Z, X), (O + Y, X, Z), (O, Y, Z), (O + X, Z, Y)]
    return merge_meshes([quad_grid(o, u, v, n, n, rho) for o, u, v in walls])


def open_floor(size: float = 2.0, n: int = 8, rho=0.5) -> ReflectanceMesh:
    """A single horizontal square facing up, nothing else."""
    return quad_grid((-size / 2, -size / 2, 0.0), (size, 0, 0), (0, size, 0), n, n, rho)
