"""The lighting map: everything the daylight nodes need about a scene's light transport, made once (paper Fig. 2,
green box) by ``lightfast daylight prepare MESH.ply SITE.yaml OUT``.

It holds the mesh with reflectance and its own vertex normals (from the PLY, else area-weighted face normals: the
ones every component uses), the site, the patches, the patch transport (visibility as a bit array, §III-E), the
vertices' junction-safe ray origins (:mod:`lightfast.daylight.ray_origins`) and the normalized sky and ground
radiosities B̂_sky, B̂_grd per vertex and colour channel (§III-B). The sun's B̂_sun depends on the time and is
computed by :mod:`lightfast.daylight.sun_update` with the same normals and ray origins.

On disk a lighting map is a directory, written atomically (it appears complete or not at all)::

    OUT/metadata.json      format name and version, mesh SHA-256, counts, configuration, site, creation time
    OUT/mesh.ply           the mesh it was made for (lightfast's PLY with float reflectance)
    OUT/lighting_map.npz   arrays (NumPy, loaded with allow_pickle=False)

Loading refuses a map of another format version (:class:`LightingMapVersionError`; version 1 maps lacked the
normals and ray origins), or whose mesh hash does not match the mesh (its own copy, or the one the caller passes),
with a one-line :class:`LightingMapError`.
"""
from __future__ import annotations

import datetime as dt
import json
import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from lightfast.config import Config, ConfigError, config_from_mapping, param
from lightfast.daylight.errors import LightingMapError, LightingMapVersionError, MeshError
from lightfast.daylight.lights import LightSet, sky_and_ground, sun_disk
from lightfast.daylight.mesh import ReflectanceMesh, load_ply, save_ply
from lightfast.daylight.openings import Opening, openings_array
from lightfast.daylight.patches import Patches, build_patches
from lightfast.daylight.radiosity import PatchTransport, direct_irradiance, patch_ray_origins, vertex_radiosity
from lightfast.daylight.ray_origins import RayOrigins, vertex_ray_origins
from lightfast.daylight.sun import Site
from lightfast.io import atomic_directory, load_npz, read_json_mapping, write_text_atomic
from lightfast.progress import track
from lightfast.raycast import RayCaster

log = logging.getLogger(__name__)

FORMAT_NAME = "lightfast-lighting-map"
FORMAT_VERSION = 2  # 2: the mesh's vertex normals and the vertices' ray origins are stored
UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class LightingMapConfig(Config):
    """How a lighting map is made. Stored in its metadata."""

    patch_size_m: float = param(0.1, description="Edge length of the planar patches of §III-E, in metres.",
                                min=0.005, max=10.0)
    normal_merge_deg: float = param(30.0, description="Inside a patch cell, face-normal bins within this angle of "
                                    "a region's dominant bin form one patch (absorbs the normal scatter of "
                                    "reconstructed meshes; 0 keeps every 10° bin apart).", min=0.0, max=89.0)
    sky_directions: int = param(2048, description="Directional lights over the whole sphere (Fibonacci); those "
                                "above the horizon form the sky, the others the ground.", min=8, max=1_000_000)
    sun_samples: int = param(8, description="Directions inside the solar disk (area sun, paper Fig. 4).",
                             min=1, max=1024)
    sun_angular_diameter_deg: float = param(0.533, description="Angular diameter of the solar disk in degrees.",
                                            min=0.0, max=5.0)
    hemisphere_rays: int = param(256, description="Cosine-distributed rays per patch measuring how much of its "
                                 "hemisphere the scene covers (normalizes the gather factors).", min=0, max=65536)
    iterations: int = param(0, description="Jacobi iterations of Eq. 2 (the paper uses 10); 0 iterates until the "
                            "radiosity converges.", min=0, max=10000)
    ray_offset_m: float = param(1e-3, description="Ray origins start at most this far off the surface, in metres "
                                "(a tenth of the shortest incident edge where that is less; into the free side of "
                                "every surface touching the point).", min=0.0, max=0.1)
    vertex_chunk: int = param(50_000, description="Vertices per batch of direct-light rays while preparing.",
                              min=1, max=100_000_000)


@dataclass(eq=False)
class LightingMap:
    """A scene's precomputed light transport and normalized sky and ground radiosity."""

    mesh: ReflectanceMesh
    site: Site
    config: LightingMapConfig
    patches: Patches
    transport_source: PatchTransport | Callable[[], PatchTransport]  # the transport, or how to build it on demand
    sky_radiosity: NDArray[np.float32]  # (V, 3) B̂_sky
    ground_radiosity: NDArray[np.float32]  # (V, 3) B̂_grd
    #: (N, 3, 3) window openings (corner, edge u, edge v; :mod:`lightfast.daylight.openings`); none: every ray
    #: that leaves the mesh brings outdoor light
    openings: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3, 3)))
    #: the vertices' ray origins (Eq. 1 visibility); none: computed from the mesh on first use
    vertex_origins: RayOrigins | None = None

    def __post_init__(self) -> None:
        _ = self.mesh.vertex_normals  # computed once here, not inside the first bounded sun-update step

    @cached_property
    def ray_origins(self) -> RayOrigins:
        """Where the vertices' visibility rays start (stored in the map; :mod:`lightfast.daylight.ray_origins`)."""
        if self.vertex_origins is not None:
            return self.vertex_origins
        return vertex_ray_origins(self.mesh, offset_m=self.config.ray_offset_m)

    @cached_property
    def transport(self) -> PatchTransport:
        """The patch transport of Eq. 2. A loaded map builds it from the visibility bits on first use (only the sun
        update needs it; relighting does not pay for it)."""
        src = self.transport_source
        return src if isinstance(src, PatchTransport) else src()

    @cached_property
    def caster(self) -> RayCaster:
        return RayCaster(self.mesh.vertices_m, self.mesh.faces)

    @property
    def num_vertices(self) -> int:
        return self.mesh.num_vertices

    def sun_lights(self, direction_to_sun: NDArray[np.float64]) -> LightSet:
        """The sun light set for a sun direction (map frame); empty when the sun is below the horizon."""
        return sun_disk(direction_to_sun, self.config.sun_samples,
                        angular_diameter_deg=self.config.sun_angular_diameter_deg, horizon_up=tuple(UP))

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write the map directory atomically."""
        path = Path(path)
        p = self.patches
        arrays: dict[str, NDArray[Any]] = {
            "face_patch": p.face_patch.astype(np.int32),
            "patch_area_m2": p.area_m2,
            "patch_centroid_m": p.centroid_m,
            "patch_normal": p.normal,
            "patch_reflectance": p.reflectance,
            "patch_sample_point_m": p.sample_point_m,
            "visibility_bits": np.packbits(self.transport.visible, axis=None),
            "coverage": self.transport.coverage,
            "sky_radiosity": self.sky_radiosity.astype(np.float32),
            "ground_radiosity": self.ground_radiosity.astype(np.float32),
            "openings": np.asarray(self.openings, dtype=np.float64).reshape(-1, 3, 3),
            "vertex_normals": self.mesh.vertex_normals.astype(np.float32),
            "ray_offset_m": self.ray_origins.offset_m.astype(np.float32),
            "ray_covered": self.ray_origins.covered,
        }
        for name, mat in (("vertex_to_patch", p.vertex_to_patch), ("patch_to_vertex", p.patch_to_vertex)):
            csr = sp.csr_matrix(mat)
            arrays[f"{name}_data"] = csr.data.astype(np.float32)
            arrays[f"{name}_indices"] = csr.indices.astype(np.int32)
            arrays[f"{name}_indptr"] = csr.indptr.astype(np.int64)
            arrays[f"{name}_shape"] = np.asarray(csr.shape, dtype=np.int64)
        meta = {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "mesh_sha256": self.mesh.content_hash,
            "created_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "counts": {"vertices": self.mesh.num_vertices, "faces": self.mesh.num_faces, "patches": p.count,
                       "openings": len(self.openings)},
            "config": self.config.to_dict(),
            "site": self.site.to_dict(),
        }
        try:
            with atomic_directory(path, overwrite=overwrite) as tmp:
                save_ply(self.mesh, tmp / "mesh.ply")
                with open(tmp / "lighting_map.npz", "wb") as fh:
                    np.savez(fh, allow_pickle=True, **arrays)  # the default, explicit: **arrays are arrays only
                write_text_atomic(tmp / "metadata.json", json.dumps(meta, indent=2) + "\n")
        except FileExistsError as exc:
            raise LightingMapError(str(exc)) from None
        return path

    @classmethod
    def load(cls, path: str | os.PathLike[str], *, mesh: ReflectanceMesh | None = None) -> LightingMap:
        """Load a map; ``mesh`` (optional) must be the mesh the map was made for."""
        path = Path(path)
        meta_path = path / "metadata.json"
        if not meta_path.is_file():
            raise LightingMapError(f"no lighting map at {path} (missing metadata.json)")
        meta = read_json_mapping(meta_path, error=LightingMapError, what="the lighting map's metadata")
        if meta.get("format") != FORMAT_NAME:
            raise LightingMapError(f"{path} is not a lighting map (format {meta.get('format')!r})")
        if meta.get("version") != FORMAT_VERSION:
            raise LightingMapVersionError(
                f"{path}: lighting map format version {meta.get('version')} is not supported (this lightfast reads "
                f"version {FORMAT_VERSION}); prepare it again with `lightfast daylight prepare`"
            )
        try:
            own_mesh = load_ply(path / "mesh.ply")
        except MeshError as exc:
            raise LightingMapError(f"{path}: {exc}") from None
        expected = meta.get("mesh_sha256")
        for candidate, what in ((own_mesh, "its mesh.ply"), (mesh, "the given mesh")):
            if candidate is not None and candidate.content_hash != expected:
                raise LightingMapError(
                    f"{path} was made for another mesh: {what} has hash {candidate.content_hash[:12]}…, the map "
                    f"expects {str(expected)[:12]}…"
                )
        try:
            # maps from before the normal merge grouped faces by normal bin alone
            config = config_from_mapping(LightingMapConfig, {"normal_merge_deg": 0.0, **meta["config"]})
            site = config_from_mapping(Site, meta["site"])
        except (ConfigError, KeyError, TypeError) as exc:  # TypeError: a section of the wrong shape
            raise LightingMapError(f"{path}: bad metadata: {exc!r}") from None
        a = load_npz(path / "lighting_map.npz", error=LightingMapError, what="the lighting map's arrays")
        try:
            return cls._from_arrays(own_mesh, site, config, a, meta)
        except (KeyError, ValueError, IndexError, TypeError) as exc:
            raise LightingMapError(f"{path}: inconsistent lighting map arrays or metadata ({exc!r})") from None

    @classmethod
    def _from_arrays(cls, mesh: ReflectanceMesh, site: Site, config: LightingMapConfig, a: dict[str, np.ndarray],
                     meta: dict) -> LightingMap:
        P = int(meta["counts"]["patches"])
        V = mesh.num_vertices
        if meta["counts"]["vertices"] != V or a["sky_radiosity"].shape != (V, 3) or len(a["patch_area_m2"]) != P:
            raise ValueError("array sizes do not match the mesh and patch counts")

        def csr(name: str) -> sp.csr_matrix:
            shape = tuple(int(x) for x in a[f"{name}_shape"])
            return sp.csr_matrix(
                (a[f"{name}_data"].astype(np.float64), a[f"{name}_indices"], a[f"{name}_indptr"]), shape=shape
            )

        patches = Patches(
            face_patch=a["face_patch"].astype(np.int64),
            area_m2=a["patch_area_m2"],
            centroid_m=a["patch_centroid_m"],
            normal=a["patch_normal"],
            reflectance=a["patch_reflectance"],
            sample_point_m=a["patch_sample_point_m"],
            vertex_to_patch=sp.csc_matrix(csr("vertex_to_patch")),
            patch_to_vertex=csr("patch_to_vertex"),
        )
        bits, coverage = a["visibility_bits"], a["coverage"]
        if len(bits) != -(-P * P // 8) or coverage.shape[0] != P:
            raise ValueError("visibility bits or coverage do not match the patch count")

        def transport() -> PatchTransport:
            visible = np.unpackbits(bits, count=P * P).reshape(P, P).astype(bool)
            return PatchTransport.from_visibility(patches, visible, coverage)

        normals, offset, covered = a["vertex_normals"], a["ray_offset_m"], a["ray_covered"]
        if normals.shape != (V, 3) or offset.shape != (V, 3) or covered.shape != (V,) or covered.dtype != np.bool_:
            raise ValueError("vertex normals or ray origins do not match the mesh")
        if not (np.all(np.isfinite(normals)) and np.all(np.isfinite(offset))):
            raise ValueError("vertex normals or ray origins are not finite")
        mesh = ReflectanceMesh(mesh.vertices_m, mesh.faces, mesh.reflectance, normals.astype(np.float64))
        openings = openings_array(a["openings"]) if "openings" in a else np.zeros((0, 3, 3))
        return cls(mesh, site, config, patches, transport, a["sky_radiosity"], a["ground_radiosity"], openings,
                   RayOrigins(offset.astype(np.float64), covered))


def _stored(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a`` rounded to float32, the precision the map stores it in."""
    return a.astype(np.float32).astype(np.float64)


def _direct_in_chunks(mesh: ReflectanceMesh, caster: RayCaster, lights: LightSet, config: LightingMapConfig,
                      openings: NDArray[np.float64], origins: RayOrigins, *, desc: str, progress: bool
                      ) -> NDArray[np.float64]:
    out = np.empty(mesh.num_vertices)
    starts = range(0, mesh.num_vertices, config.vertex_chunk)
    for s in track(starts, desc=desc, total=len(starts), enabled=progress, unit="chunk"):
        sl = slice(s, min(mesh.num_vertices, s + config.vertex_chunk))
        out[sl] = direct_irradiance(mesh, caster, lights, vertices=sl, offset_m=config.ray_offset_m,
                                    openings=openings, origins=origins)
    return out


def prepare_lighting_map(
    mesh: ReflectanceMesh,
    site: Site,
    config: LightingMapConfig | None = None,
    *,
    openings: Sequence[Opening] | None = None,
    progress: bool = False,
) -> LightingMap:
    """Build the lighting map of ``mesh`` at ``site``: patches, transport, B̂_sky and B̂_grd. With ``openings``
    (the room's windows), light enters only through them (see :mod:`lightfast.daylight.openings`)."""
    config = config or LightingMapConfig()
    windows = openings_array(openings)
    try:
        mesh.validate_topology()
    except MeshError as exc:
        raise LightingMapError(f"cannot prepare a lighting map: {exc}") from None
    # the map's mesh carries its normals explicitly, rounded as they are stored (float32): prepared and loaded maps
    # use bit-identical normals and ray origins
    mesh = ReflectanceMesh(mesh.vertices_m, mesh.faces, mesh.reflectance, _stored(mesh.vertex_normals))
    caster = RayCaster(mesh.vertices_m, mesh.faces)
    patches = build_patches(mesh, patch_size_m=config.patch_size_m, normal_merge_deg=config.normal_merge_deg)
    log.info("%d vertices, %d faces, %d patches", mesh.num_vertices, mesh.num_faces, patches.count)
    found = vertex_ray_origins(mesh, offset_m=config.ray_offset_m)
    origins = RayOrigins(_stored(found.offset_m), found.covered)
    log.info("ray origins: %d vertices covered by a touching surface", int(np.count_nonzero(origins.covered)))
    transport = PatchTransport.compute(patches, caster, hemisphere_rays=config.hemisphere_rays,
                                       offset_m=config.ray_offset_m, progress=progress, openings=windows,
                                       origins=patch_ray_origins(mesh, patches, offset_m=config.ray_offset_m))
    sky, ground = sky_and_ground(config.sky_directions, up=tuple(UP))
    direct = np.stack([_direct_in_chunks(mesh, caster, lights, config, windows, origins,
                                         desc=f"{lights.name} light", progress=progress)
                       for lights in (sky, ground)], axis=1)
    both = vertex_radiosity(mesh, patches, transport, direct, iterations=config.iterations or None)
    lmap = LightingMap(mesh, site, config, patches, transport, both[:, 0].astype(np.float32),
                       both[:, 1].astype(np.float32), windows, origins)
    lmap.__dict__["caster"] = caster  # reuse the BVH just built
    return lmap
