"""The normalized radiosity of a lighting map at a time, for people and checkers (paper §III-B, Eq. 1–2; §III-E).

``lightfast daylight radiosity MAP [--time T] [--points FILE] -o OUT`` computes B̂_sun for the sun position of
time T at the map's site (the chunked update of :mod:`lightfast.daylight.sun_update`, run to the end) beside the
map's B̂_sky and B̂_grd, and writes

* ``OUT.npz`` (format ``lightfast-radiosity``, :data:`FORMAT_VERSION`; written atomically, read with
  ``allow_pickle=False``): ``sun``, ``sky``, ``ground`` (V, 3) float32 normalized radiosity per vertex and linear
  RGB channel, the mesh (``vertices_m``, ``faces``, ``normals``, ``reflectance``), ``sun_direction_map`` and a
  JSON ``metadata`` string (time, sun azimuth and elevation, site, mesh SHA-256, units, PLY scales and white);
  with points, ``points_m``, ``points_normal``, ``points_irradiance`` and ``points_radiosity`` (N, 3, 3):
  component (sun, sky, ground) × channel;
* ``OUT.ply``: the mesh with 8-bit vertex colours any mesh viewer shows, the tone-mapped radiosity
  ``B = s_sun B̂_sun + s_sky B̂_sky + s_grd B̂_grd`` (:func:`tone_map`);
* with points, ``OUT.points.csv``: one row per point.

Units (docs/daylight.md): B̂ is W/m² per unit brightness — per W/m² of solar normal irradiance for the sun, per
W/(m² sr) of sky or ground radiance — so ``s_x`` in those units gives B in W/m². Points (:func:`load_points`) are
surface points with the normal of the side they are on; their values are interpolated barycentrically on the
closest triangle facing that normal (open mesh edges are fine): radiosity B̂, and irradiance E = B̂/ρ (0 where ρ
is 0).
"""
from __future__ import annotations

import csv
import datetime as dt
import io
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lightfast.daylight.errors import MeshError, RadiosityFileError
from lightfast.daylight.lighting_map import LightingMap
from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.daylight.proximity import SurfacePoints, closest_surface_points
from lightfast.daylight.sun import SunPosition, sun_position
from lightfast.daylight.sun_update import SunChunk, SunUpdate
from lightfast.io import load_npz, write_bytes_atomic, write_text_atomic
from lightfast.progress import track

FORMAT_NAME = "lightfast-radiosity"
FORMAT_VERSION = 1
COMPONENTS = ("sun", "sky", "ground")
#: Default brightness scales of the PLY colours (a clear day): solar normal irradiance 800 W/m², sky and ground
#: radiance 30 W/(m² sr).
DEFAULT_SCALES = (800.0, 30.0, 30.0)
#: The PLY's white is this percentile of the vertices' brightest channel unless given.
WHITE_PERCENTILE = 99.0
#: Points farther than this from a surface facing their normal are refused.
MAX_POINT_DISTANCE_M = 0.01


@dataclass(frozen=True)
class RadiosityAtTime:
    """B̂_sun, B̂_sky, B̂_grd (V, 3) of a lighting map at ``when``."""

    when: dt.datetime
    sun: SunPosition
    radiosity: dict[str, NDArray[np.float32]]  # component -> (V, 3)


def _sun_chunks(update: SunUpdate) -> Iterator[SunChunk | None]:
    while not update.done:
        yield update.step()


def radiosity_at(lmap: LightingMap, when: dt.datetime, *, progress: bool = False) -> RadiosityAtTime:
    """The map's B̂ of every component at ``when`` (timezone-aware); B̂_sun is zero with the sun below the horizon."""
    sun = sun_position(lmap.site, when)
    chunk = 50_000
    update = SunUpdate(lmap, sun.direction_map, chunk_vertices=chunk)
    total = SunUpdate.estimate_steps(lmap.num_vertices, chunk, lmap.config.iterations)
    b_sun = np.zeros((lmap.num_vertices, 3), dtype=np.float32)
    for out in track(_sun_chunks(update), desc="sun radiosity", total=total, enabled=progress, unit="step"):
        if out is not None:
            b_sun[out.first_vertex : out.first_vertex + len(out.radiosity)] = out.radiosity
    comps = {"sun": b_sun, "sky": np.asarray(lmap.sky_radiosity, dtype=np.float32),
             "ground": np.asarray(lmap.ground_radiosity, dtype=np.float32)}
    return RadiosityAtTime(when, sun, comps)


def combined(result: RadiosityAtTime, scales: tuple[float, float, float] = DEFAULT_SCALES) -> NDArray[np.float64]:
    """``B = Σ s_x B̂_x`` (V, 3), W/m² for scales in the units of the module docstring."""
    return sum((float(s) * result.radiosity[c].astype(np.float64) for c, s in zip(COMPONENTS, scales, strict=True)),
               np.zeros_like(result.radiosity["sky"], dtype=np.float64))


def auto_white(linear: NDArray[np.float64]) -> float:
    """The white point of :func:`tone_map` when none is given: the 99th percentile of the brightest channel."""
    peak = np.max(linear, axis=1)
    white = float(np.percentile(peak, WHITE_PERCENTILE)) if len(peak) else 0.0
    return white if white > 0 else 1.0


def tone_map(linear: NDArray[np.float64], white: float) -> NDArray[np.uint8]:
    """8-bit sRGB colours: ``B / white`` clipped to [0, 1], the sRGB transfer function, rounded."""
    x = np.clip(np.asarray(linear, dtype=np.float64) / float(white), 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.round(255.0 * srgb).astype(np.uint8)


def load_points(path: str | os.PathLike[str]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A points file: one point per line, ``x y z nx ny nz`` (metres in the map frame, and the normal of the
    surface side the point is on), separated by spaces, tabs or commas; blank lines and ``#`` comments ignored."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise RadiosityFileError(f"cannot read points file {path}: {exc}") from None
    rows = []
    for number, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].replace(",", " ").strip()
        if not line:
            continue
        try:
            values = [float(x) for x in line.split()]
        except ValueError:
            values = []
        if len(values) != 6 or not np.all(np.isfinite(values)) or np.linalg.norm(values[3:]) == 0.0:
            raise RadiosityFileError(f"{path}:{number}: expected 'x y z nx ny nz' (finite, non-zero normal), got "
                                     f"{line[:60]!r}")
        rows.append(values)
    if not rows:
        raise RadiosityFileError(f"{path}: no points (one 'x y z nx ny nz' per line)")
    a = np.asarray(rows, dtype=np.float64)
    return a[:, :3], a[:, 3:] / np.linalg.norm(a[:, 3:], axis=1, keepdims=True)


@dataclass(frozen=True)
class PointValues:
    """Radiosity B̂ and irradiance E = B̂/ρ at points, (N, 3 components, 3 channels) each."""

    points_m: NDArray[np.float64]
    normals: NDArray[np.float64]
    surface: SurfacePoints
    radiosity: NDArray[np.float64]
    irradiance: NDArray[np.float64]


def locate_points(mesh: ReflectanceMesh, points_m: NDArray[np.float64], normals: NDArray[np.float64]
                  ) -> SurfacePoints:
    """Where the points meet the mesh (:class:`RadiosityFileError` for points off its surface)."""
    try:
        return closest_surface_points(mesh, points_m, normals, max_distance_m=MAX_POINT_DISTANCE_M)
    except MeshError as exc:
        raise RadiosityFileError(f"points: {exc}") from None


def at_points(mesh: ReflectanceMesh, result: RadiosityAtTime, points_m: NDArray[np.float64],
              normals: NDArray[np.float64], surface: SurfacePoints | None = None) -> PointValues:
    """Interpolate every component at surface points (module docstring)."""
    surface = surface if surface is not None else locate_points(mesh, points_m, normals)
    rho = np.maximum(mesh.reflectance, 0.0)
    b = np.stack([result.radiosity[c] for c in COMPONENTS], axis=1).astype(np.float64)  # (V, 3, 3)
    e = np.where(rho[:, None, :] > 0, b / np.where(rho > 0, rho, 1.0)[:, None, :], 0.0)
    return PointValues(points_m, normals, surface, surface.interpolate(mesh, b), surface.interpolate(mesh, e))


def write_colored_ply(path: str | os.PathLike[str], mesh: ReflectanceMesh, rgb: NDArray[np.uint8],
                      comments: list[str]) -> None:
    """Binary little-endian PLY: positions, normals and 8-bit ``red green blue`` per vertex; atomic."""
    vdtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4"),
                       ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    vert = np.empty(mesh.num_vertices, dtype=vdtype)
    for i, k in enumerate(("x", "y", "z")):
        vert[k] = mesh.vertices_m[:, i]
    for i, k in enumerate(("nx", "ny", "nz")):
        vert[k] = mesh.vertex_normals[:, i]
    for i, k in enumerate(("red", "green", "blue")):
        vert[k] = rgb[:, i]
    face = np.empty(mesh.num_faces, dtype=np.dtype([("n", "u1"), ("idx", "<i4", (3,))]))
    face["n"] = 3
    face["idx"] = mesh.faces
    header = "\n".join([
        "ply", "format binary_little_endian 1.0", *(f"comment {c}" for c in comments),
        f"element vertex {mesh.num_vertices}", "property float x", "property float y", "property float z",
        "property float nx", "property float ny", "property float nz", "property uchar red", "property uchar green",
        "property uchar blue", f"element face {mesh.num_faces}", "property list uchar int vertex_indices",
        "end_header"]) + "\n"
    write_bytes_atomic(path, header.encode("ascii") + vert.tobytes() + face.tobytes())


def write_radiosity(out: str | os.PathLike[str], lmap: LightingMap, result: RadiosityAtTime, *,
                    scales: tuple[float, float, float] = DEFAULT_SCALES, white: float | None = None,
                    points: PointValues | None = None, map_path: str = "") -> dict[str, Path]:
    """Write ``OUT.npz``, ``OUT.ply`` (and ``OUT.points.csv`` with points); returns the paths by kind."""
    base = Path(out)
    if base.suffix in (".npz", ".ply"):
        base = base.with_suffix("")
    mesh = lmap.mesh
    linear = combined(result, scales)
    white = auto_white(linear) if white is None else float(white)
    sun = result.sun
    meta = {
        "format": FORMAT_NAME, "version": FORMAT_VERSION, "time": result.when.isoformat(),
        "sun": {"azimuth_deg": float(sun.azimuth_deg), "elevation_deg": float(sun.elevation_deg),
                "above_horizon": bool(sun.above_horizon)},
        "lighting_map": map_path, "mesh_sha256": mesh.content_hash, "site": lmap.site.to_dict(),
        "units": "W/m2 per unit brightness: sun per W/m2 of normal irradiance, sky and ground per W/(m2 sr) of "
                 "radiance; linear RGB",
        "components": list(COMPONENTS),
        "ply": {"scales": dict(zip(COMPONENTS, map(float, scales), strict=True)), "white_w_m2": white,
                "colour": "8-bit sRGB of clip(B / white, 0, 1), B = sum of scale * component"},
    }
    arrays: dict[str, NDArray] = {
        "format": np.array(FORMAT_NAME), "version": np.array(FORMAT_VERSION), "metadata": np.array(json.dumps(meta)),
        **{c: result.radiosity[c].astype(np.float32) for c in COMPONENTS},
        "vertices_m": mesh.vertices_m, "faces": mesh.faces.astype(np.int32),
        "normals": mesh.vertex_normals.astype(np.float32), "reflectance": mesh.reflectance.astype(np.float32),
        "sun_direction_map": np.asarray(sun.direction_map, dtype=np.float64),
    }
    if points is not None:
        arrays |= {"points_m": points.points_m, "points_normal": points.normals,
                   "points_face": points.surface.face.astype(np.int32),
                   "points_distance_m": points.surface.distance_m,
                   "points_radiosity": points.radiosity.astype(np.float32),
                   "points_irradiance": points.irradiance.astype(np.float32)}
    buf = io.BytesIO()
    np.savez_compressed(buf, allow_pickle=False, **arrays)  # strings are unicode arrays: no pickle needed
    paths = {"npz": base.with_name(base.name + ".npz"), "ply": base.with_name(base.name + ".ply")}
    write_bytes_atomic(paths["npz"], buf.getvalue())
    write_colored_ply(paths["ply"], mesh, tone_map(linear, white), [
        f"lightfast radiosity at {result.when.isoformat()}, sun elevation {float(sun.elevation_deg):.2f} deg",
        "colour: 8-bit sRGB of clip(B / white, 0, 1), B = " + " + ".join(
            f"{s:g} {c}" for c, s in zip(COMPONENTS, scales, strict=True)) + f", white {white:.6g} W/m2"])
    if points is not None:
        paths["csv"] = base.with_name(base.name + ".points.csv")
        write_text_atomic(paths["csv"], _points_csv(points))
    return paths


def _points_csv(points: PointValues) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    channels = [f"{q}_{c}_{ch}" for q in ("E", "B") for c in COMPONENTS for ch in "rgb"]
    w.writerow(["x", "y", "z", "nx", "ny", "nz", "distance_m", *channels])
    for i in range(len(points.points_m)):
        values = [*points.irradiance[i].reshape(-1), *points.radiosity[i].reshape(-1)]
        w.writerow([*(f"{x:.6f}" for x in points.points_m[i]), *(f"{x:.6f}" for x in points.normals[i]),
                    f"{points.surface.distance_m[i]:.3g}", *(f"{x:.6g}" for x in values)])
    return buf.getvalue()


def load_radiosity(path: str | os.PathLike[str]) -> tuple[dict[str, NDArray], dict]:
    """The arrays and metadata of an ``OUT.npz``; :class:`RadiosityFileError` for another format or version."""
    a = load_npz(path, error=RadiosityFileError, what="the radiosity file")
    if "format" not in a or str(a["format"]) != FORMAT_NAME:
        raise RadiosityFileError(f"{path} is not a lightfast radiosity file")
    if int(a["version"]) != FORMAT_VERSION:
        raise RadiosityFileError(f"{path}: radiosity file version {int(a['version'])} is not supported (this "
                                 f"lightfast reads version {FORMAT_VERSION})")
    return a, json.loads(str(a["metadata"]))
