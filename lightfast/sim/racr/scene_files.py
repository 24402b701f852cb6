"""Scene directories of the simulated rACR scenes (paper §5.1), written by ``lightfast sim racr OUT``
(:func:`generate_racr_set`) and read by the evaluation and the simulator nodes (:func:`load_scene`).

Per scene ``OUT/S01/`` (built under a temporary name and renamed when complete)::

    scene.yaml      simulator setup: format, scene info, camera intrinsics, lighting variants (resolved: light
                    position or sun azimuth/elevation, exposure), the initial pose offset T_camref_cam0, the
                    platform and VSE configurations; ``truth:`` holds X = T_cam_hand, T_world_base and the VSE's
                    monocular scale (rACR must not read this section, nor this file)
    mesh.ply        the scene mesh with linear RGB albedo (truth geometry, simulator only)
    reference/      THE REFERENCE OBSERVATION, the only input rACR reads (format ``lightfast-racr-reference``,
                    version 1, written atomically):
                      reference.yaml  format, version, scene name, lighting, frame, intrinsics, T_ref_camref
                      points.npz      points_m (N, 3) float32 (frame ``reference``, metres), intensity (N,)
                                      float32 grey value in [0, 1] (np.load(allow_pickle=False))
                      image.png       the reference image, 8-bit RGB
    truth.yaml      evaluation truth: T_world_camref, T_world_cam0, T_world_ref (the reference cloud's frame),
                    X, the VSE scale, the AFD grid (pixels and world points)
    preview/        PNGs for a human: the reference view under the varied lighting, the initial view under the
                    similar and the varied lighting
    scene.json      manifest, written last: parameter hash, format version, SHA-256 of every file, statistics

Transforms are 4 × 4 ``T_target_source`` in metres. A scene directory whose manifest matches the parameters and
whose files match their hashes is reused (:func:`scene_complete`).
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from lightfast.daylight.errors import MeshError
from lightfast.daylight.mesh import ReflectanceMesh, load_ply, save_ply
from lightfast.io import atomic_directory, write_bytes_atomic, write_text_atomic
from lightfast.progress import track
from lightfast.racr.reference import (
    REFERENCE_VERSION,
    camera_from_dict,
    camera_to_dict,
    load_reference,
    matrix_from,
    matrix_to_list,
    png_bytes,
    write_reference,
    yaml_text,
)
from lightfast.sim.errors import RacrSimError
from lightfast.sim.racr.afd import AFD_GRID, AFD_SUCCESS_PX
from lightfast.sim.racr.builder import DEFAULT_RESOLUTION_M
from lightfast.sim.racr.lighting import LightingSpec
from lightfast.sim.racr.scenes import RacrScene, RacrSceneSpec, SceneTruth, build_scene, scene_specs
from lightfast.sim.racr_platform import PlatformConfig, VseConfig

__all__ = ["FORMAT_VERSION", "generate_racr_set", "load_scene", "scene_complete", "write_scene"]

log = logging.getLogger(__name__)

F64 = NDArray[np.float64]

#: Version of the scene directory layout (scene.yaml, truth.yaml, manifest); bump when outputs change.
FORMAT_VERSION = 1


def _readable(root: Path) -> None:
    """Temporary files and directories are private (0600/0700); give the published tree the usual modes."""
    for p in [root, *root.rglob("*")]:
        p.chmod(0o755 if p.is_dir() else 0o644)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _scene_doc(scene: RacrScene) -> dict[str, Any]:
    tr = scene.truth
    from lightfast.geometry import rotation_angle_deg

    return {
        "format": "lightfast-racr-scene", "format_version": FORMAT_VERSION,
        "name": scene.spec.name, "kind": scene.spec.kind, "description": scene.description,
        "resolution_m": scene.resolution_m,
        "mesh": {"file": "mesh.ply", "vertices": scene.mesh.num_vertices, "triangles": scene.mesh.num_faces},
        "camera": camera_to_dict(scene.camera),
        "lighting": {k: v.to_dict() for k, v in scene.lightings.items()},
        "initial_offset": {
            "description": "true initial camera pose relative to the reference camera (simulator setup)",
            "T_camref_cam0": matrix_to_list(tr.T_camref_cam0),
            "translation_m": float(np.linalg.norm(tr.T_camref_cam0[:3, 3])),
            "rotation_deg": float(rotation_angle_deg(tr.T_camref_cam0)),
        },
        "platform": scene.platform_config.to_dict(),
        "vse": scene.vse_config.to_dict(),
        "reference": "reference",
        "spec": scene.spec.to_dict(),
        "truth": {
            "note": "simulator truth: rACR must not read this section",
            "T_cam_hand": matrix_to_list(tr.T_cam_hand), "T_world_base": matrix_to_list(tr.T_world_base),
            "vse_scale_m_per_vse": tr.vse_scale_m_per_vse,
        },
    }


def _truth_doc(scene: RacrScene) -> dict[str, Any]:
    tr = scene.truth
    return {
        "format": "lightfast-racr-truth", "format_version": FORMAT_VERSION, "scene": scene.spec.name,
        "T_world_camref": matrix_to_list(tr.T_world_camref), "T_world_cam0": matrix_to_list(tr.T_world_cam0),
        "T_camref_cam0": matrix_to_list(tr.T_camref_cam0), "T_world_ref": matrix_to_list(tr.T_world_ref),
        "T_cam_hand": matrix_to_list(tr.T_cam_hand), "T_world_base": matrix_to_list(tr.T_world_base),
        "vse_scale_m_per_vse": tr.vse_scale_m_per_vse, "target_m": [float(x) for x in tr.target_m],
        "afd": {"grid": list(AFD_GRID), "success_px": AFD_SUCCESS_PX,
                "pixels_ref": [[float(x) for x in r] for r in tr.afd_pixels_ref],
                "points_world": [[float(x) for x in r] for r in tr.afd_points_world]},
    }


def write_scene(scene: RacrScene, path: str | os.PathLike[str], *, params_hash: str = "",
                previews: bool = True, stats: dict[str, Any] | None = None) -> Path:
    """Write the scene directory (see the module docstring) under a temporary name and move it into place."""
    if scene.reference is None:
        raise RacrSimError(f"scene {scene.spec.name}: no reference observation to write")
    path = Path(path)
    with atomic_directory(path, overwrite=True) as tmp:
        save_ply(scene.mesh, tmp / "mesh.ply")
        write_text_atomic(tmp / "scene.yaml", "# lightfast rACR simulated scene (simulator setup; rACR reads only "
                                              "reference/)\n" + yaml_text(_scene_doc(scene)))
        write_text_atomic(tmp / "truth.yaml", "# lightfast rACR scene truth: evaluation only\n"
                          + yaml_text(_truth_doc(scene)))
        write_reference(scene.reference, tmp / "reference")
        if previews:
            tr = scene.truth
            for name, T, lt in (("reference_varied", tr.T_world_camref, "varied"),
                                ("initial_similar", tr.T_world_cam0, "similar"),
                                ("initial_varied", tr.T_world_cam0, "varied")):
                img = scene.render(T, lt, seed=3).image
                assert img is not None
                write_bytes_atomic(tmp / "preview" / f"{name}.png", png_bytes(img, error=RacrSimError))
        files = sorted(p for p in tmp.rglob("*") if p.is_file())
        manifest = {
            "format": "lightfast-racr-scene-manifest", "format_version": FORMAT_VERSION,
            "scene": scene.spec.name, "params_hash": params_hash,
            "files": {str(p.relative_to(tmp)): {"sha256": _sha256(p), "bytes": p.stat().st_size} for p in files},
            "stats": stats or {},
        }
        write_text_atomic(tmp / "scene.json", json.dumps(manifest, indent=1) + "\n")
        _readable(tmp)
    return path


def scene_complete(path: str | os.PathLike[str], params_hash: str | None = None) -> bool:
    """True when ``path`` holds a complete scene directory: manifest present (with ``params_hash`` if given) and
    every listed file present with its size and SHA-256."""
    path = Path(path)
    try:
        man = json.loads((path / "scene.json").read_text())
        if man.get("format_version") != FORMAT_VERSION:
            return False
        if params_hash is not None and man.get("params_hash") != params_hash:
            return False
        files = man["files"]
        for rel, info in files.items():
            p = path / rel
            if not p.is_file() or p.stat().st_size != info["bytes"] or _sha256(p) != info["sha256"]:
                return False
        return {"scene.yaml", "truth.yaml", "mesh.ply", "reference/reference.yaml"} <= set(files)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return False


def load_scene(path: str | os.PathLike[str], *, verify: bool = True) -> RacrScene:
    """Load a scene directory written by :func:`write_scene` (simulator and evaluation side)."""
    path = Path(path)
    if verify and not scene_complete(path):
        raise RacrSimError(f"{path}: not a complete rACR scene directory (missing or half-written; regenerate it "
                           "with `lightfast sim racr`)")
    try:
        doc = yaml.safe_load((path / "scene.yaml").read_text())
        tdoc = yaml.safe_load((path / "truth.yaml").read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise RacrSimError(f"{path}: cannot read scene files: {exc}") from None
    if not isinstance(doc, dict) or doc.get("format") != "lightfast-racr-scene" or \
            doc.get("format_version") != FORMAT_VERSION:
        raise RacrSimError(f"{path}/scene.yaml: not a lightfast-racr-scene version {FORMAT_VERSION}")
    try:
        mesh = load_ply(path / "mesh.ply")
    except MeshError as exc:
        raise RacrSimError(f"{path}: {exc}") from None
    try:
        spec = RacrSceneSpec.from_dict(doc["spec"])
        afd_doc = tdoc["afd"]
        def mat(x: Any, name: str, shape: tuple[int, ...] = (4, 4)) -> F64:
            return matrix_from(x, name, shape, error=RacrSimError)

        truth = SceneTruth(
            mat(tdoc["T_world_camref"], "T_world_camref"), mat(tdoc["T_camref_cam0"], "T_camref_cam0"),
            mat(doc["truth"]["T_cam_hand"], "T_cam_hand"), mat(doc["truth"]["T_world_base"], "T_world_base"),
            mat(tdoc["T_world_ref"], "T_world_ref"), float(doc["truth"]["vse_scale_m_per_vse"]),
            np.asarray(afd_doc["points_world"], float).reshape(-1, 3),
            np.asarray(afd_doc["pixels_ref"], float).reshape(-1, 2), mat(tdoc["target_m"], "target_m", (3,)))
        lightings = {k: LightingSpec.from_dict(v) for k, v in doc["lighting"].items()}
        camera = camera_from_dict(doc["camera"], str(path), error=RacrSimError)
        platform, vse = PlatformConfig(**doc["platform"]), VseConfig(**doc["vse"])
        resolution = float(doc["resolution_m"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise RacrSimError(f"{path}: malformed scene.yaml or truth.yaml: {type(exc).__name__}: {exc}") from None
    ref = load_reference(path / str(doc.get("reference", "reference")), scene=spec.name)
    return RacrScene(spec, ReflectanceMesh(mesh.vertices_m, mesh.faces, mesh.reflectance), camera, lightings, truth,
                     platform, vse, ref, str(doc.get("description", "")), resolution)


def _params_hash(spec: RacrSceneSpec, width: int, height: int, resolution_m: float) -> str:
    doc = {"format_version": FORMAT_VERSION, "reference_version": REFERENCE_VERSION, "spec": spec.to_dict(),
           "width": width, "height": height, "resolution_m": resolution_m,
           "platform": PlatformConfig().to_dict(), "vse": VseConfig().to_dict()}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:16]


def generate_racr_set(out_dir: str | os.PathLike[str], *, scenes: Sequence[str] | None = None, count: int | None = None,
                      width: int = 640, height: int = 480, resolution_m: float = DEFAULT_RESOLUTION_M, seed: int = 0,
                      force: bool = False, progress: bool = False, previews: bool = True) -> list[Path]:
    """Write the scene directories (default all 20; ``scenes`` names or the first ``count``) into ``out_dir``.
    Complete directories with the same parameters are reused unless ``force``. Returns the scene directories."""
    specs = scene_specs(seed)
    by_name = {s.name: s for s in specs}
    if scenes:
        unknown = [n for n in scenes if n not in by_name]
        if unknown:
            raise RacrSimError(f"unknown scene(s) {unknown}; choose from S01..S20")
        chosen = [by_name[n] for n in scenes]
    else:
        chosen = list(specs[: count if count is not None else len(specs)])
    if width < 16 or height < 16:
        raise RacrSimError(f"image size must be at least 16x16, got {width}x{height}")
    if not resolution_m > 0:
        raise RacrSimError(f"resolution must be > 0, got {resolution_m}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    dirs: list[Path] = []
    for spec in track(chosen, desc="rACR scenes", enabled=progress, unit="scene"):
        d = out / spec.name
        digest = _params_hash(spec, width, height, resolution_m)
        if not force and scene_complete(d, digest):
            log.info("%s: complete, reused", spec.name)
            dirs.append(d)
            continue
        t0 = time.perf_counter()
        scene = build_scene(spec, width=width, height=height, resolution_m=resolution_m)
        t1 = time.perf_counter()
        stats = {"vertices": scene.mesh.num_vertices, "triangles": scene.mesh.num_faces,
                 "reference_points": len(scene.reference.points_m) if scene.reference else 0,
                 "seconds_build": round(t1 - t0, 3)}
        write_scene(scene, d, params_hash=digest, previews=previews, stats=stats)
        log.info("%s: %s, %d triangles, %.1f s", spec.name, scene.description, scene.mesh.num_faces,
                 time.perf_counter() - t0)
        dirs.append(d)
    return dirs
