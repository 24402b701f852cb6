"""Numba kernels of the frame preparation for Eq. 7 (paper §III-D): the per-pixel maps of one pyramid level.

* :func:`_downsample_depth`: 2×2 block means of the valid depths (m); 0 where none is valid or the block spans a
  depth discontinuity;
* :func:`_geometry_map`: ``(H, W, 7)`` depth (m), vertex ``π⁻¹(x, D(x))`` (camera frame, m) and unit normal facing
  the camera (central differences of the vertex map): the target vertex ``v_t`` and normal ``n_t`` of the
  point-to-plane E_G (KinectFusion [10]);
* :func:`_depth_gradient`: Sobel ``dD/du, dD/dv`` (m/px), the target gradient of the depth-difference E_G;
* :func:`_source_points`: vertices ``(N, 3)`` (camera frame, m) and grey values ``(N,)`` of the source pixels.

Depth images are ``(H, W)`` float32 metres with 0 = invalid; intrinsics ``fx, fy, cx, cy`` in px; undefined map
entries are NaN.
"""
from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray


@numba.njit(cache=True, nogil=True)
def _downsample_depth(depth: NDArray[np.float32], discontinuity: float) -> NDArray[np.float32]:
    """2×2 block means of the valid depths; 0 where no depth is valid or the block spans a discontinuity."""
    h, w = depth.shape[0] // 2, depth.shape[1] // 2
    out = np.zeros((h, w), dtype=np.float32)
    for i in range(h):
        for j in range(w):
            total = 0.0
            count = 0
            lo = np.inf
            hi = -np.inf
            for di in range(2):
                for dj in range(2):
                    d = depth[2 * i + di, 2 * j + dj]
                    if d > 0.0:
                        total += d
                        count += 1
                        lo = min(lo, d)
                        hi = max(hi, d)
            if count > 0 and hi - lo <= discontinuity:
                out[i, j] = total / count
    return out


@numba.njit(cache=True, nogil=True)
def _geometry_map(depth: NDArray[np.float32], fx: float, fy: float, cx: float, cy: float) -> NDArray[np.float32]:
    """(H, W, 7): depth, vertex xyz (camera frame, m) and unit normal xyz facing the camera (from central
    differences of the vertex map; NaN where the depth or a neighbour is missing)."""
    h, w = depth.shape
    out = np.full((h, w, 7), np.nan, dtype=np.float32)
    for i in range(h):
        for j in range(w):
            z = depth[i, j]
            out[i, j, 0] = z
            if z > 0.0:
                out[i, j, 1] = (j - cx) / fx * z
                out[i, j, 2] = (i - cy) / fy * z
                out[i, j, 3] = z
    for i in range(1, h - 1):
        for j in range(1, w - 1):
            if not (depth[i, j] > 0.0):
                continue
            ax = out[i, j + 1, 1] - out[i, j - 1, 1]
            ay = out[i, j + 1, 2] - out[i, j - 1, 2]
            az = out[i, j + 1, 3] - out[i, j - 1, 3]
            bx = out[i + 1, j, 1] - out[i - 1, j, 1]
            by = out[i + 1, j, 2] - out[i - 1, j, 2]
            bz = out[i + 1, j, 3] - out[i - 1, j, 3]
            nx = ay * bz - az * by
            ny = az * bx - ax * bz
            nz = ax * by - ay * bx
            norm = np.sqrt(nx * nx + ny * ny + nz * nz)
            if not (norm > 0.0):  # also NaN: a neighbour without depth
                continue
            if nx * out[i, j, 1] + ny * out[i, j, 2] + nz * out[i, j, 3] > 0.0:
                norm = -norm
            out[i, j, 4] = nx / norm
            out[i, j, 5] = ny / norm
            out[i, j, 6] = nz / norm
    return out


@numba.njit(cache=True, nogil=True)
def _depth_gradient(depth: NDArray[np.float32], discontinuity_m: float) -> NDArray[np.float32]:
    """(H, W, 2): Sobel dD/du, dD/dv (÷8, m/px) where the whole 3×3 neighbourhood has depth and neither derivative
    exceeds ``discontinuity_m``; NaN elsewhere (and on the image border)."""
    h, w = depth.shape
    out = np.full((h, w, 2), np.nan, dtype=np.float32)
    for i in range(1, h - 1):
        for j in range(1, w - 1):
            full = True
            for di in range(-1, 2):
                for dj in range(-1, 2):
                    if not (depth[i + di, j + dj] > 0.0):
                        full = False
            if not full:
                continue
            gu = 0.125 * ((depth[i - 1, j + 1] - depth[i - 1, j - 1]) + 2.0 * (depth[i, j + 1] - depth[i, j - 1])
                          + (depth[i + 1, j + 1] - depth[i + 1, j - 1]))
            gv = 0.125 * ((depth[i + 1, j - 1] - depth[i - 1, j - 1]) + 2.0 * (depth[i + 1, j] - depth[i - 1, j])
                          + (depth[i + 1, j + 1] - depth[i - 1, j + 1]))
            if abs(gu) <= discontinuity_m and abs(gv) <= discontinuity_m:
                out[i, j, 0] = gu
                out[i, j, 1] = gv
    return out



@numba.njit(cache=True, nogil=True, inline="always")
def _kept(i: int, j: int, step: int) -> bool:
    """Pixel (i, j) is a source point at ``step``: every pixel (1), a checkerboard (2), every 2nd row and column (4)."""
    return step == 1 or (step == 2 and (i + j) % 2 == 0) or (step == 4 and i % 2 == 0 and j % 2 == 0)


@numba.njit(cache=True, nogil=True)
def _source_points(geometry: NDArray[np.float32], grey: NDArray[np.float32], step: int
                   ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Vertices (N, 3) and grey values (N,) of the pixels with depth that :func:`_kept` keeps, row-major."""
    h, w = grey.shape
    n = 0
    for i in range(h):
        for j in range(w):
            if geometry[i, j, 0] > 0.0 and _kept(i, j, step):
                n += 1
    points = np.empty((n, 3), dtype=np.float32)
    point_grey = np.empty(n, dtype=np.float32)
    k = 0
    for i in range(h):
        for j in range(w):
            if geometry[i, j, 0] > 0.0 and _kept(i, j, step):
                points[k, 0], points[k, 1], points[k, 2] = geometry[i, j, 1], geometry[i, j, 2], geometry[i, j, 3]
                point_grey[k] = grey[i, j]
                k += 1
    return points, point_grey
