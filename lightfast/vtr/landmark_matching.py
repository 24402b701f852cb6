"""Matching of reference landmarks to the current frame's stereo keypoints: the first step of the pose pipeline of
colour-constant VT&R (paper §IV-B, Fig. 3: "tracked keypoints"), shared by the VO (reference: the previous frame)
and the map localization (reference: the keyframes of a window).

:func:`match_landmarks`: descriptors of reference landmarks (3-D points in a reference frame, metres) are matched to
the current frame's keypoints (left pixels of the rectified image) — nearest neighbour, Lowe's ratio, mutual check
and a largest descriptor distance (:func:`max_descriptor_distance`; :mod:`lightfast.vtr.descriptor_matching`).
With a prior pose ``T_ref_cur`` (current left camera frame → reference frame), the camera matrix ``K`` and
``radius_px > 0`` only pairs whose reference point projects within ``radius_px`` of the current keypoint are
candidates (guided matching: fewer ambiguities across lighting changes, the ratio test runs among spatially
plausible candidates only, and far fewer descriptor distances). The candidate pairs come from a uniform grid over
the current keypoints (:func:`radius_pairs`, numba kernels). Outputs: indices into the reference and the current
sets and the descriptor distances; :func:`~lightfast.vtr.pose_estimation.estimate_pose_stereo` takes it from there.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from lightfast.vtr.descriptor_matching import match_descriptors
from lightfast.vtr.errors import VtrInputError
from lightfast.vtr.pose_estimation import project

__all__ = ["match_landmarks", "max_descriptor_distance", "radius_pairs"]


def max_descriptor_distance(kind: str, orb: float, sift: float) -> float:
    """The configured largest descriptor distance for a descriptor ``kind`` (``"orb"`` or ``"sift"``)."""
    if kind == "orb":
        return orb
    if kind == "sift":
        return sift
    raise VtrInputError(f"unknown descriptor kind {kind!r}")


@numba.njit(cache=True, nogil=True)
def _grid(b: NDArray[np.float64], radius: float
          ) -> tuple[float, float, float, int, int, NDArray[np.int64], NDArray[np.int64]]:
    """``b`` (finite) bucketed in square cells of side ≥ ``radius`` (at most ~1000 per axis): origin, side, cells
    per axis, the point indices ordered by cell and each cell's start in that order (CSR)."""
    x0, y0 = b[:, 0].min(), b[:, 1].min()
    wx, wy = b[:, 0].max() - x0, b[:, 1].max() - y0
    side = max(radius, wx / 1000.0, wy / 1000.0)
    nx, ny = int(wx / side) + 1, int(wy / side) + 1
    cell = np.empty(b.shape[0], np.int64)
    for j in range(b.shape[0]):
        cell[j] = int((b[j, 1] - y0) / side) * nx + int((b[j, 0] - x0) / side)
    order = np.argsort(cell, kind="mergesort")
    start = np.zeros(nx * ny + 1, np.int64)
    for j in range(b.shape[0]):
        start[cell[j] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    return x0, y0, side, nx, ny, order, start


@numba.njit(cache=True, nogil=True)
def _grid_pairs(a: NDArray[np.float64], b: NDArray[np.float64], radius: float, x0: float, y0: float, side: float,
                nx: int, ny: int, order: NDArray[np.int64], start: NDArray[np.int64], count_only: bool,
                out_a: NDArray[np.int64], out_b: NDArray[np.int64]) -> int:
    """Pairs (i, j) with |a[i] − b[j]| ≤ radius, each ``a`` checked against the 3×3 cells of :func:`_grid` (of
    ``b``) around it. Counts them (``count_only``) or writes them to ``out_a``, ``out_b``."""
    r2 = radius * radius
    n = 0
    for i in range(a.shape[0]):
        fx, fy = (a[i, 0] - x0) / side, (a[i, 1] - y0) / side
        if not (fx > -1.0 and fy > -1.0 and fx < nx + 1.0 and fy < ny + 1.0):  # also NaN
            continue
        cx, cy = math.floor(fx), math.floor(fy)
        for gy in range(max(cy - 1, 0), min(cy + 2, ny)):
            for gx in range(max(cx - 1, 0), min(cx + 2, nx)):
                c = gy * nx + gx
                for t in range(start[c], start[c + 1]):
                    j = order[t]
                    dx, dy = a[i, 0] - b[j, 0], a[i, 1] - b[j, 1]
                    if dx * dx + dy * dy <= r2:
                        if not count_only:
                            out_a[n], out_b[n] = i, j
                        n += 1
    return n


def radius_pairs(a: NDArray[np.float64], b: NDArray[np.float64], radius: float
                 ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """All index pairs (i, j) with ‖a[i] − b[j]‖ ≤ ``radius`` for 2-D points (N, 2) and (M, 2), by a uniform grid
    (what ``cKDTree.sparse_distance_matrix`` finds, in another order, ~10× faster for image keypoints)."""
    a = np.ascontiguousarray(a, np.float64)
    b = np.ascontiguousarray(b, np.float64)
    if len(a) == 0 or len(b) == 0 or not radius > 0.0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    grid = _grid(b, radius)  # built once: counted, then written
    none = np.zeros(0, np.int64)
    n = _grid_pairs(a, b, radius, *grid, True, none, none)
    ia, ib = np.empty(n, np.int64), np.empty(n, np.int64)
    _grid_pairs(a, b, radius, *grid, False, ia, ib)
    return ia.astype(np.intp), ib.astype(np.intp)


def match_landmarks(
    points_ref: NDArray[np.float64],
    descriptors_ref: NDArray[np.generic],
    uv_cur: NDArray[np.float32],
    descriptors_cur: NDArray[np.generic],
    kind: str,
    *,
    K: NDArray[np.float64] | None = None,
    T_ref_cur: NDArray[np.float64] | None = None,
    radius_px: float = 0.0,
    ratio: float = 0.8,
    mutual: bool = True,
    max_distance: float = math.inf,
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float32]]:
    """Descriptor matches reference landmark → current keypoint (module docstring).

    Unguided (all pairs, :func:`~lightfast.vtr.descriptor_matching.match_descriptors`) unless ``T_ref_cur``,
    ``K`` and ``radius_px > 0`` are given: then only pairs whose reference point projects (in front of the camera)
    within ``radius_px`` of the current keypoint compete. At most one reference landmark per current keypoint (the
    nearest descriptor) is kept. Returns indices into the reference and current sets and the distances.
    """
    n, m = len(descriptors_ref), len(descriptors_cur)
    empty = (np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0, np.float32))
    if n == 0 or m == 0:
        return empty
    if descriptors_ref.ndim != 2 or descriptors_cur.ndim != 2 or descriptors_ref.shape[1] != descriptors_cur.shape[1]:
        raise VtrInputError(f"descriptor shapes {descriptors_ref.shape} and {descriptors_cur.shape} do not match")
    if T_ref_cur is not None and radius_px > 0.0:
        if K is None:
            raise VtrInputError("guided matching needs the camera matrix K")
        uv_pred, front = project(points_ref, T_ref_cur, K)
        idx_front = np.flatnonzero(front)
        if idx_front.size == 0:
            return empty
        ia, ib = radius_pairs(uv_pred[idx_front], np.asarray(uv_cur, np.float64), radius_px)
        if ia.size == 0:
            return empty
        ia = idx_front[ia]
        i_ref, i_cur, dist = match_descriptors(descriptors_ref, descriptors_cur, kind, ratio=ratio, mutual=mutual,
                                               candidates=(ia, ib), max_distance=max_distance)
    else:
        i_ref, i_cur, dist = match_descriptors(descriptors_ref, descriptors_cur, kind, ratio=ratio, mutual=mutual,
                                               max_distance=max_distance)
    if not mutual and i_cur.size:  # one reference landmark per current keypoint: the nearest descriptor
        order = np.lexsort((dist, i_cur))
        first = order[np.r_[True, i_cur[order][1:] != i_cur[order][:-1]]]
        i_ref, i_cur, dist = i_ref[first], i_cur[first], dist[first]
    return i_ref, i_cur, dist
