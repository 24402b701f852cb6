"""The simulated VT&R route's scene: parameters, mesh with per-vertex data, centreline, terrain, and the robot's
pose on it (paper: Paton et al., §V: a route through sand and rock, grass and woods, like the CSA Mars Emulation
Terrain and the field beside it).

Frames and units: a z-up map frame (ENU: x east, y north; metres; the route starts at the origin); arc length
``s`` (m) along the centreline; headings in radians from +x, counter-clockwise.

* :class:`RouteConfig`: the parameters of :func:`lightfast.sim.vtr.build.build_route_scene` (lengths in m,
  densities per m² for each of the :data:`STRETCHES`, sky-visibility samples per vertex, texture size in texels);
* :class:`Heightfield`: the terrain ``h(x, y) = Σ a_i sin(k_i · (x, y) + φ_i)`` (m; ``k_i`` in rad/m) and its
  gradient;
* :class:`RouteScene`: the triangle mesh (vertices (V, 3) in m, faces (F, 3)), per-triangle kinds
  (:data:`KIND_GROUND`, :data:`KIND_ROCK`, :data:`KIND_TRUNK`, :data:`KIND_FOLIAGE`), per-vertex normals,
  material attributes and cosine-weighted hemisphere fractions (sky, foliage, other), the centreline table every
  0.25 m with its stretch weights, and the height field; saved as a pickle-free ``.npz``
  (:data:`SCENE_FORMAT_VERSION`);
* :func:`base_pose`: the robot base pose ``T_map_base`` (4×4; x forward, y left, z up) at arc length ``s`` with a
  lateral offset (m, left positive) and a yaw offset (rad), on the terrain and aligned with its slope.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.io import write_bytes_atomic

__all__ = [
    "KIND_FOLIAGE",
    "KIND_GROUND",
    "KIND_ROCK",
    "KIND_TRUNK",
    "SCENE_FORMAT_VERSION",
    "STRETCHES",
    "Heightfield",
    "RouteConfig",
    "RouteScene",
    "base_pose",
]

#: Surface kinds (per triangle).
KIND_GROUND, KIND_ROCK, KIND_TRUNK, KIND_FOLIAGE = 0, 1, 2, 3
#: Stretch (region) names of a route, in the order of the per-vertex region weights.
STRETCHES = ("sand_rock", "grass", "wood")

#: Bump when the scene or the rendering of the same parameters changes.
SCENE_FORMAT_VERSION = 1

_F32 = NDArray[np.float32]
_F64 = NDArray[np.float64]


@dataclass(frozen=True)
class RouteConfig:
    """Parameters of :func:`~lightfast.sim.vtr.build.build_route_scene` (see :mod:`lightfast.sim.vtr.build`).
    Densities are per m² and per stretch (sand_rock, grass, wood)."""

    length_m: float = 300.0
    seed: int = 2014
    stretches: tuple[tuple[str, float], ...] = (("sand_rock", 0.4), ("grass", 0.3), ("wood", 0.3))
    corridor_half_width_m: float = 20.0
    grid_m: float = 0.25
    outer_margin_m: float = 100.0
    outer_grid_m: float = 2.0
    extension_m: float = 25.0  # straight continuation of the corridor beyond both route ends
    max_curvature_per_m: float = 1.0 / 25.0
    total_turn_deg: float = 270.0  # the route curls round (mean curvature; capped at half the maximum)
    terrain_rms_m: float = 0.3
    path_clearance_m: float = 1.2
    tree_clearance_m: float = 2.2
    rock_density: tuple[float, float, float] = (0.12, 0.006, 0.015)
    tree_density: tuple[float, float, float] = (0.0, 0.003, 0.03)
    tree_band_m: float = 12.0  # trees also this far beyond the corridor
    sky_samples: int = 24
    texture_size: int = 2048

    def __post_init__(self) -> None:
        if not self.length_m > 0.0:
            raise ValueError(f"length_m must be > 0, got {self.length_m}")
        if not self.stretches or any(name not in STRETCHES or not frac > 0 for name, frac in self.stretches):
            raise ValueError(f"stretches must be (name, fraction > 0) pairs with names in {STRETCHES}, "
                             f"got {self.stretches}")
        if not 0.0 < self.grid_m <= self.outer_grid_m:
            raise ValueError("need 0 < grid_m <= outer_grid_m")
        if self.sky_samples < 1:
            raise ValueError("sky_samples must be >= 1")

    def to_dict(self) -> dict:
        d = asdict(self)
        d["stretches"] = [list(s) for s in self.stretches]
        d["rock_density"] = list(self.rock_density)
        d["tree_density"] = list(self.tree_density)
        return d

    @classmethod
    def for_tests(cls, length_m: float = 30.0, seed: int = 7, **kw: object) -> RouteConfig:
        """A small, quick scene: a short route, a narrow coarse corridor, a small texture."""
        base: dict[str, Any] = dict(length_m=length_m, seed=seed, corridor_half_width_m=10.0, grid_m=0.5,
                                    outer_margin_m=40.0, outer_grid_m=4.0, extension_m=10.0, sky_samples=12,
                                    texture_size=256)
        base.update(kw)
        return cls(**base)


@dataclass(frozen=True, eq=False)
class Heightfield:
    """``h(x, y) = Σ a_i sin(k_i · (x, y) + φ_i)`` (metres)."""

    k: _F64  # (n, 2) wave vectors, rad/m
    amplitude: _F64  # (n,)
    phase: _F64  # (n,)

    @classmethod
    def random(cls, rng: np.random.Generator, rms_m: float, n: int = 24) -> Heightfield:
        lam = np.exp(rng.uniform(math.log(8.0), math.log(80.0), n))
        ang = rng.uniform(0.0, 2.0 * math.pi, n)
        k = (2.0 * math.pi / lam)[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        amp = lam**0.8
        amp *= rms_m / math.sqrt(0.5 * float(np.sum(amp**2))) if rms_m > 0 else 0.0
        return cls(k, amp, rng.uniform(0.0, 2.0 * math.pi, n))

    def __call__(self, xy: ArrayLike) -> _F64:
        p = np.asarray(xy, dtype=np.float64)
        return np.sin(p @ self.k.T + self.phase) @ self.amplitude

    def gradient(self, xy: ArrayLike) -> _F64:
        p = np.asarray(xy, dtype=np.float64)
        return (np.cos(p @ self.k.T + self.phase) * self.amplitude) @ self.k


@dataclass(eq=False)
class RouteScene:
    """A triangle mesh with per-triangle kinds and per-vertex data, plus the route (see the module docstring).

    ``vertex_attr`` (V, 4): ground: region weights (sand_rock, grass, wood) and the dirt-track weight; objects:
    ``(tint, texture offset, 0, 0)``. ``vertex_vis`` (V, 3): cosine-weighted hemisphere fractions (sky, foliage,
    other occluders). ``stations`` (n, 4): centreline ``s, x, y, heading_rad`` every 0.25 m (the route is
    ``0 <= s <= length_m``; the table extends beyond both ends); ``station_regions`` (n, 3)."""

    config: RouteConfig
    vertices: _F64
    faces: NDArray[np.int64]
    face_kind: NDArray[np.int8]
    vertex_attr: _F32
    vertex_normals: _F32
    vertex_vis: _F32
    stations: _F64
    station_regions: _F32
    heightfield: Heightfield
    stats: dict = field(default_factory=dict)

    @property
    def length_m(self) -> float:
        return float(self.config.length_m)

    def height(self, xy: ArrayLike) -> _F64:
        return self.heightfield(xy)

    def centreline(self, s: ArrayLike) -> tuple[_F64, _F64]:
        """Centreline ``(xy (..., 2), heading_rad (...))`` at arc lengths ``s`` (linear interpolation)."""
        s = np.asarray(s, dtype=np.float64)
        st = self.stations
        x = np.interp(s, st[:, 0], st[:, 1])
        y = np.interp(s, st[:, 0], st[:, 2])
        return np.stack([x, y], axis=-1), np.interp(s, st[:, 0], st[:, 3])

    def stretch_at(self, s: ArrayLike) -> NDArray[np.int64]:
        """Index into :data:`STRETCHES` of the dominant stretch at arc lengths ``s``."""
        s = np.asarray(s, dtype=np.float64)
        idx = np.clip(np.searchsorted(self.stations[:, 0], s), 0, len(self.stations) - 1)
        return np.argmax(self.station_regions[idx], axis=-1)

    @property
    def content_hash(self) -> str:
        import hashlib

        h = hashlib.sha256()
        for a in (self.vertices, self.faces, self.face_kind, self.vertex_attr):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()[:16]

    # ------------------------------------------------------------------------------------------------ files

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the scene as a NumPy ``.npz`` (no pickles), atomically."""
        import io

        buf = io.BytesIO()
        np.savez(buf, format_version=np.array(SCENE_FORMAT_VERSION), config=np.array(json.dumps(
            self.config.to_dict())), vertices=self.vertices, faces=self.faces, face_kind=self.face_kind,
            vertex_attr=self.vertex_attr, vertex_normals=self.vertex_normals, vertex_vis=self.vertex_vis,
            stations=self.stations, station_regions=self.station_regions, height_k=self.heightfield.k,
            height_amplitude=self.heightfield.amplitude, height_phase=self.heightfield.phase,
            stats=np.array(json.dumps(self.stats)))
        write_bytes_atomic(path, buf.getvalue())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> RouteScene:
        with np.load(path, allow_pickle=False) as z:
            if int(z["format_version"]) != SCENE_FORMAT_VERSION:
                raise ValueError(f"{path}: scene format {int(z['format_version'])}, expected {SCENE_FORMAT_VERSION}")
            cfg = json.loads(str(z["config"]))
            cfg["stretches"] = tuple((str(n), float(f)) for n, f in cfg["stretches"])
            cfg["rock_density"] = tuple(cfg["rock_density"])
            cfg["tree_density"] = tuple(cfg["tree_density"])
            return cls(RouteConfig(**cfg), z["vertices"], z["faces"], z["face_kind"], z["vertex_attr"],
                       z["vertex_normals"], z["vertex_vis"], z["stations"], z["station_regions"],
                       Heightfield(z["height_k"], z["height_amplitude"], z["height_phase"]),
                       json.loads(str(z["stats"])))


def base_pose(scene: RouteScene, s: float, lateral_m: float = 0.0, yaw_offset_rad: float = 0.0) -> _F64:
    """Robot base pose ``T_map_base`` (4×4) at arc length ``s`` with a lateral offset (left positive), on the
    terrain and aligned with its slope; heading along the offset path plus ``yaw_offset_rad``."""
    xy, _ = scene.centreline(s)
    ds = 0.2
    (xa, _), (xb, _) = scene.centreline(s - ds), scene.centreline(s + ds)
    ha = math.atan2(xb[1] - xa[1], xb[0] - xa[0])
    nrm = np.array([-math.sin(ha), math.cos(ha)])
    p = xy + lateral_m * nrm
    psi = ha + yaw_offset_rad
    g = scene.heightfield.gradient(p[None])[0]
    fwd2 = np.array([math.cos(psi), math.sin(psi)])
    left2 = np.array([-math.sin(psi), math.cos(psi)])
    x = np.array([fwd2[0], fwd2[1], g @ fwd2])
    y = np.array([left2[0], left2[1], g @ left2])
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = (p[0], p[1], float(scene.height(p[None])[0]))
    return T
