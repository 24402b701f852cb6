"""Compare the normalized radiosity of a lighting map with an independent renderer (Radiance) at surface points.

Used by the CI test and ``benchmarks/radiance_validation.py`` (issue: validation against Radiance). Irradiance
is compared, ``E = B̂/ρ`` per vertex interpolated barycentrically at each point, after one best-fit global scale
per light component (the method's brightness scales absorb any global factor).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.daylight.lighting_map import LightingMap, LightingMapConfig, prepare_lighting_map
from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.daylight.proximity import closest_surface_points

if TYPE_CHECKING:
    from lightfast.daylight.sun import Site
    from lightfast.sim.radiance_oracle import Component


@dataclass(frozen=True)
class Agreement:
    """Ours vs reference at N points (RGB irradiance), after scaling ours by ``scale``."""

    ours: NDArray[np.float64]  # (N, 3)
    reference: NDArray[np.float64]  # (N, 3)
    scale: float
    median_relative_error: float
    pearson_r: float
    points_m: NDArray[np.float64] | None = None  # (N, 3) where, if known
    normals: NDArray[np.float64] | None = None  # (N, 3)
    #: the reference's own Monte Carlo noise: median over points of its standard error / its value (NaN: unknown)
    reference_noise: float = float("nan")

    @classmethod
    def of(cls, ours: ArrayLike, reference: ArrayLike) -> Agreement:
        o = np.asarray(ours, dtype=np.float64)
        r = np.asarray(reference, dtype=np.float64)
        scale = float(np.sum(o * r) / np.sum(o * o)) if np.any(o) else 1.0
        rel = np.abs(scale * o - r) / np.maximum(np.abs(r), 1e-12)
        pearson = float(np.corrcoef(o.reshape(-1), r.reshape(-1))[0, 1])
        return cls(o, r, scale, float(np.median(rel)), pearson)


def irradiance_at_points(lmap: LightingMap, radiosity: NDArray[np.float32], points_m: ArrayLike,
                         normals: ArrayLike) -> NDArray[np.float64]:
    """Irradiance ``B̂/ρ`` interpolated at surface points: barycentric on the closest triangle (within 1 cm)
    facing the point's normal, so points on open mesh edges are fine (:class:`MeshError`, a ``ValueError``, for
    points off the surface)."""
    mesh = lmap.mesh
    e_v = radiosity / np.maximum(mesh.reflectance, 1e-6)
    return closest_surface_points(mesh, points_m, normals, max_distance_m=0.01).interpolate(mesh, e_v)


#: The sun through a south window, 35° up and 20° west of south (map = ENU).
SUN_DIRECTION = np.array([-np.sin(np.radians(20)) * np.cos(np.radians(35)),
                          -np.cos(np.radians(20)) * np.cos(np.radians(35)), np.sin(np.radians(35))])
TARGET_MEDIAN, TARGET_R = 0.10, 0.98


def snap_to_vertices(lmap: LightingMap, points_m: ArrayLike, normals: ArrayLike
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Move surface points to the nearest vertex of the triangle they lie on (keeping the face normal), so that
    a comparison happens where the method's radiosity is defined, not inside triangles."""
    p = np.asarray(points_m, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    hits = lmap.caster.intersect(p + 1e-3 * n, -n, t_far_m=0.01)
    if not np.all(hits.hit):
        raise ValueError(f"{int(np.sum(~hits.hit))} points are not on the mesh surface")
    corners = lmap.mesh.faces[hits.triangle_id]  # (N, 3)
    d2 = np.sum((lmap.mesh.vertices_m[corners] - p[:, None, :]) ** 2, axis=2)
    nearest = corners[np.arange(len(p)), np.argmin(d2, axis=1)]
    return lmap.mesh.vertices_m[nearest].copy(), n


def compare_with_radiance(mesh: ReflectanceMesh, *, points: int, seed: int, repeats: int,
                          config: LightingMapConfig, sun_direction: ArrayLike = SUN_DIRECTION,
                          site: Site | None = None, junction_points: int = 0, sun_disk_samples: int = 19,
                          at_vertices: bool = True, lmap: LightingMap | None = None,
                          progress: bool = False, timeout_s: float = 3600.0) -> dict[str, Agreement]:
    """Prepare a lighting map of ``mesh`` (or take ``lmap``) and compare its sky, ground and sun irradiance with
    Radiance (see :mod:`lightfast.sim.radiance_oracle`) at ``points`` surface points away from creases, snapped to
    mesh vertices unless ``at_vertices`` is False (then our values are interpolated inside triangles, which blurs
    shadow edges over a triangle), followed by ``junction_points`` mesh vertices on a crease (where parts meet:
    issue 21), ours at the vertex and Radiance's 2 mm into the vertex's own face
    (:func:`~lightfast.sim.validation_rooms.sample_crease_vertices`).
    ``sun_direction``: unit vector to the sun in the mesh frame; ``site`` only names where the map is prepared (the
    normalized components do not depend on it). With ``repeats >= 2`` each agreement carries Radiance's own noise."""
    from lightfast.daylight.sun import FREIBURG
    from lightfast.daylight.sun_update import sun_radiosity
    from lightfast.sim.radiance_oracle import radiance_irradiance, radiance_irradiance_with_error
    from lightfast.sim.validation_rooms import sample_crease_vertices, sample_surface_points

    if lmap is None:
        lmap = prepare_lighting_map(mesh, site or FREIBURG, config, progress=progress)
    pts, nrm = sample_surface_points(mesh, points, seed=seed, edge_clearance=at_vertices)
    if at_vertices:
        pts, nrm = snap_to_vertices(lmap, pts, nrm)
    crease_ids = np.zeros(0, dtype=np.int64)
    if junction_points:  # crease vertices: ours at the vertex, Radiance's just inside the vertex's own face
        crease_ids, jp, jn = sample_crease_vertices(mesh, junction_points, seed=seed + 1)
        pts, nrm = np.concatenate([pts, jp]), np.concatenate([nrm, jn])
    regular = len(pts) - len(crease_ids)
    sun = np.asarray(sun_direction, dtype=np.float64)
    ours: dict[Component, NDArray[np.float32]] = {
        "sky": lmap.sky_radiosity, "ground": lmap.ground_radiosity, "sun": sun_radiosity(lmap, sun)}
    out: dict[str, Agreement] = {}
    for component, radiosity in ours.items():
        kwargs = {"component": component, "repeats": repeats, "sun_direction": sun if component == "sun" else None,
                  "sun_disk_samples": sun_disk_samples if component == "sun" else 1, "timeout_s": timeout_s}
        noise = float("nan")
        if repeats >= 2:
            ref, se = radiance_irradiance_with_error(mesh, pts, nrm, **kwargs)  # type: ignore[arg-type]
            noise = float(np.median(se.mean(axis=1) / np.maximum(ref.mean(axis=1), 1e-12)))
        else:
            ref = radiance_irradiance(mesh, pts, nrm, **kwargs)  # type: ignore[arg-type]
        e_crease = radiosity[crease_ids] / np.maximum(mesh.reflectance[crease_ids], 1e-6)
        e_ours = np.concatenate([irradiance_at_points(lmap, radiosity, pts[:regular], nrm[:regular]), e_crease])
        out[component] = replace(Agreement.of(e_ours, ref), points_m=pts, normals=nrm, reference_noise=noise)
    return out
