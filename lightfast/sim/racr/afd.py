"""AFD, the paper's accuracy metric (rACR paper §5.1, after ACR [1]): the average feature-point displacement
between the final and the reference image, computed here from the simulator's truth.

A regular grid of :data:`AFD_GRID` (columns, rows) pixels of the reference image is cast onto the scene mesh
(:func:`afd_grid_points`: the fixed scene points, world frame, metres); the points are projected with the
reference camera ``T_world_camref`` and the final camera ``T_world_cam`` (optical frames, pinhole intrinsics), and
the mean pixel distance over the points visible in both (in the image, in front, and with a ray caster not
occluded) is the AFD in pixels (:func:`afd` → :class:`AfdResult`). Success: AFD < :data:`AFD_SUCCESS_PX` = 3 px.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.geometry import inverse
from lightfast.raycast import RayCaster

__all__ = ["AFD_GRID", "AFD_SUCCESS_PX", "AfdResult", "afd", "afd_grid_points"]

F64 = NDArray[np.float64]

#: AFD grid (columns, rows) of reference pixels, and the success threshold (paper: AFD < 3).
AFD_GRID = (24, 18)
AFD_SUCCESS_PX = 3.0


@dataclass(frozen=True)
class AfdResult:
    """Average feature-point displacement (px) over the grid points visible in both images; ``success`` if
    ``afd_px < 3``. ``afd_px`` is inf when no grid point is visible in the final image."""

    afd_px: float
    n_points: int
    n_visible: int
    success: bool


def afd_grid_points(caster: RayCaster, camera: PinholeCamera, T_world_camref: ArrayLike, *,
                    grid: tuple[int, int] = AFD_GRID) -> tuple[F64, F64]:
    """The fixed scene points of the AFD: cast a regular ``grid`` (columns, rows) of reference pixels (cell
    centres) onto the scene. Returns ``(points_world (N, 3), pixels_ref (N, 2))`` for the pixels that hit."""
    T = np.asarray(T_world_camref, float)
    cols, rows = grid
    us = (np.arange(cols) + 0.5) * camera.width / cols - 0.5
    vs = (np.arange(rows) + 0.5) * camera.height / rows - 0.5
    U, V = np.meshgrid(us, vs)
    uv = np.stack([U.ravel(), V.ravel()], axis=1)
    d = camera.backproject(uv, np.ones(len(uv))) @ T[:3, :3].T
    hits = caster.intersect(T[:3, 3], d)
    return hits.points()[hits.hit], uv[hits.hit]


def afd(points_world: ArrayLike, T_world_camref: ArrayLike, T_world_cam: ArrayLike, camera: PinholeCamera, *,
        caster: RayCaster | None = None, occlusion_tol_m: float = 2e-3) -> AfdResult:
    """AFD between the reference camera ``T_world_camref`` and the final camera ``T_world_cam`` (see the module
    docstring). With ``caster``, points hidden from the final camera are left out."""
    P = np.asarray(points_world, float).reshape(-1, 3)

    def project(T: F64) -> tuple[F64, NDArray[np.bool_]]:
        Ti = inverse(np.asarray(T, float))
        pc = P @ Ti[:3, :3].T + Ti[:3, 3]
        uv, front = camera.project(pc)
        return uv, front & camera.in_image(uv)

    uv_r, ok_r = project(np.asarray(T_world_camref, float))
    uv_f, ok_f = project(np.asarray(T_world_cam, float))
    ok = ok_r & ok_f
    if caster is not None and np.any(ok):
        c = np.asarray(T_world_cam, float)[:3, 3]
        k = np.flatnonzero(ok)
        dvec = P[k] - c
        dist = np.linalg.norm(dvec, axis=1)
        hits = caster.intersect(np.broadcast_to(c, dvec.shape), dvec)
        ok[k] = hits.distance_m >= dist - occlusion_tol_m
    n_vis = int(np.count_nonzero(ok))
    if n_vis == 0:
        return AfdResult(math.inf, len(P), 0, False)
    val = float(np.mean(np.linalg.norm(uv_f[ok] - uv_r[ok], axis=1)))
    return AfdResult(val, len(P), n_vis, val < AFD_SUCCESS_PX)
