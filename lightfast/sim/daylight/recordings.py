"""Rendering the simulated daylight RGB-D recordings (Krawez et al., RA-L 2021, §IV-A) and writing their files.

:func:`generate_daylight_set` renders the sequences of :mod:`lightfast.sim.daylight.sequences` with the independent
ground-truth renderer (:mod:`lightfast.sim.daylight.renderer`, never the method's radiosity code), along a
hand-held trajectory (:mod:`lightfast.sim.daylight.trajectory`), at 30 Hz and 320 × 240 by default. Exposure time
and gain are fixed per sequence, "appropriate to the illumination" as in the paper: the median luminance of probe
renders along the trajectory maps to a normalized exposure of 0.18, so sunlit areas saturate. Output in ``OUT``::

    scenes/DS1.ply, DS1.site.yaml, DS1.json   the true scene mesh (linear RGB reflectance) and site, shared
    scenes/DS1.openings.yaml        the window as a user would measure it (outer rectangle + 2 cm)
    scenes/DS1.map.ply              the method's map: a TSDF reconstruction of a simulated night-time depth scan
                                    (:mod:`lightfast.sim.map_reconstruction`, as in the paper, §IV-B)
    DS1.T1/bag/                     rosbag2 MCAP: /camera/color/image_raw (rgb8), /camera/color/camera_info,
                                    /camera/depth/image_raw (16UC1, millimetres, 0 = invalid),
                                    /camera/depth/camera_info, /ground_truth/pose (PoseStamped T_map_camera in
                                    frame ``map``); images in ``camera_color_optical_frame``; stamps = true UTC
    DS1.T1/mesh.ply, site.yaml      hard links to (or copies of) the shared scene files (true mesh, site)
    DS1.T1/camera.yaml              the true camera: CRF (model and 256-sample forward/inverse tables), exposure
                                    time, gain, sensitivity, noise, depth sensor, intrinsics
    DS1.T1/truth.csv                per frame: sun position, cloud transmittance, DNI/DHI/GHI and the RGB scales
                                    of sun, clear sky, overcast sky and ground actually used
    DS1.T1/sequence.json            parameters, their hash and timings; written last (marks completion)

A sequence whose ``sequence.json`` holds the same parameter hash and whose files exist is skipped. docs/daylight.md
says which files to give to ``lightfast daylight prepare``.
"""
from __future__ import annotations

import csv
import datetime as dt
import hashlib
import io
import json
import logging
import os
import shutil
import time
from collections.abc import Sequence
from dataclasses import asdict, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from lightfast.camera import PinholeCamera
from lightfast.daylight.errors import OpeningsError
from lightfast.daylight.mesh import save_ply
from lightfast.daylight.openings import load_openings, save_openings
from lightfast.daylight.sun import Site
from lightfast.io import write_text_atomic
from lightfast.progress import track
from lightfast.sim.daylight.irradiance_cache import CacheSettings, IrradianceCache
from lightfast.sim.daylight.renderer import GroundTruthRenderer
from lightfast.sim.daylight.rooms import make_scene
from lightfast.sim.daylight.scene import DaylightScene, window_opening
from lightfast.sim.daylight.sensors import CameraResponse, DepthSensor
from lightfast.sim.daylight.sequences import (
    DEFAULT_CACHE,
    HELDOUT_SEQUENCES,
    SEQUENCES,
    SequenceSpec,
    camera_for_size,
    sky_states,
)
from lightfast.sim.daylight.trajectory import depth_camera_poses, hand_held_trajectory
from lightfast.sim.map_reconstruction import ReconstructionSettings, reconstruct_map
from lightfast.sim.sky_model import LUMA, SkyState, luminance
from lightfast.topics import (
    COLOR_INFO_TOPIC,
    COLOR_TOPIC,
    DEPTH_INFO_TOPIC,
    DEPTH_TOPIC,
    GT_POSE_TOPIC,
    MAP_FRAME,
    OPTICAL_FRAME,
)

__all__ = [
    "FORMAT_VERSION",
    "MAP_FORMAT_VERSION",
    "generate_daylight_set",
    "reconstruction_settings",
]

log = logging.getLogger(__name__)

#: Bump when the output of the same parameters changes.
FORMAT_VERSION = 3  # 2: gaze angular rates limited (the look-at gaze whipped at up to 900°/s near targets);
# 3: depth from the depth camera (time offset, registration error, projector shadow, correlated + systematic error)
#: Bump when the reconstructed map of the same scene changes.
MAP_FORMAT_VERSION = 4  # 2, 3: zero-area slivers (also after float32 rounding), non-manifold edges removed; 4: planes
_BY_NAME = {s.name: s for s in SEQUENCES + HELDOUT_SEQUENCES}


def _spec_params(spec: SequenceSpec) -> dict[str, Any]:
    """The spec's part of a recording's parameter hash; a field added later is left out at its default, so the
    recordings made before it keep their hash."""
    doc = asdict(spec)
    defaults = {f.name: f.default for f in fields(SequenceSpec)}
    for name in ("sunlit_gaze_share", "floor_in_gaze"):
        if doc[name] == defaults[name]:
            del doc[name]
    return doc


# ----------------------------------------------------------------------------------------------------------------
# files


def _camera_yaml(resp: CameraResponse, depth: DepthSensor, camera: PinholeCamera) -> str:
    values = np.arange(256, dtype=np.float64)
    xs = np.linspace(0.0, 1.0, 256)
    doc = {
        "description": (
            "True camera of this simulated sequence. Normalized exposure x = sensitivity * exposure_s * gain * L "
            "with L the linear RGB radiance in W m^-2 sr^-1 (L = B / pi for radiosity B = rho * E); the sensor "
            "saturates at x = 1. Pixel value = round(f(x + noise)), f(x) = 255 (1 + a) t / (t + a) with a = shoulder "
            "and t = the sRGB transfer curve of x (12.92 x below x = 0.0031308, else 1.055 x^(1/2.4) - 0.055). "
            "Noise: Poisson on x * full_well_e / gain electrons plus Gaussian read noise "
            "(electrons). inverse_crf[v] = f^-1(v) for v = 0..255 (normalized exposure); forward_crf[i] = f(i/255)."),
        "crf_model": "srgb-shoulder",
        **resp.to_dict(),
        "exposure_to_value_per_radiance": resp.sensitivity * resp.exposure_s * resp.gain,
        "inverse_crf": [float(x) for x in resp.inverse_crf(values)],
        "forward_crf": [float(x) for x in resp.crf(xs)],
        "depth_sensor": asdict(depth),
        "depth_encoding": "16UC1 millimetres, 0 = invalid",
        "intrinsics": {"width": camera.width, "height": camera.height, "fx": camera.fx, "fy": camera.fy,
                       "cx": camera.cx, "cy": camera.cy},
    }
    return yaml.safe_dump(doc, sort_keys=False, width=120)


def _truth_csv(rows: list[dict[str, float]]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]))
    writer.writeheader()
    for r in rows:
        writer.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()


def _link_or_copy(src: Path, dst: Path) -> None:
    if dst.exists() or dst.is_symlink():
        dst.unlink()
    try:
        os.link(src, dst)
    except OSError:
        shutil.copyfile(src, dst)


def _params_hash(params: dict) -> str:
    return hashlib.sha256(json.dumps(params, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _complete(seq_dir: Path, digest: str) -> bool:
    meta = seq_dir / "sequence.json"
    if not meta.is_file():
        return False
    try:
        if json.loads(meta.read_text()).get("params_hash") != digest:
            return False
    except (OSError, ValueError):
        return False
    return all((seq_dir / name).exists() for name in ("bag/metadata.yaml", "mesh.ply", "site.yaml",
                                                      "camera.yaml", "truth.csv"))


# ----------------------------------------------------------------------------------------------------------------
# generation


def _auto_exposure(renderer: GroundTruthRenderer, cache: IrradianceCache, states: list[SkyState],
                   poses: NDArray[np.float64], base: CameraResponse, *, target_x: float = 0.18,
                   max_exposure_s: float = 0.03) -> CameraResponse:
    """Fixed exposure for the sequence: the median luminance of 8 low-resolution probe renders maps to
    ``target_x``; gain above 1 only when the exposure time would exceed ``max_exposure_s``."""
    probe = camera_for_size(80, 60)
    lum = []
    for i in np.linspace(0, len(poses) - 1, 8).astype(int):
        out = renderer.render(poses[i], probe, cache, states[i], supersample=1, sun_samples=4,
                              rng=np.random.default_rng(i))
        lum.append(luminance(out.radiance)[out.hit])
    med = float(np.median(np.concatenate(lum))) if lum else 1.0
    need = target_x / (base.sensitivity * max(med, 1e-6))  # exposure_s * gain
    gain = max(1.0, need / max_exposure_s)
    exposure = round(need / gain, 5)
    return replace(base, exposure_s=max(exposure, 1e-5), gain=round(gain, 3))


def _generate_sequence(spec: SequenceSpec, scene: DaylightScene, renderer: GroundTruthRenderer, seq_dir: Path,
                       scene_files: dict[str, Path], params: dict, digest: str, *, frames: int, camera: PinholeCamera,
                       rate_hz: float, supersample: int, sun_samples: int, cache_settings: CacheSettings,
                       progress: bool) -> dict:
    from lightfast.bag.writer import BagWriter, make_qos
    from lightfast.ros.convert import camera_info_from_camera, matrix_to_pose_stamped, numpy_to_image
    from lightfast.ros.msgtypes import rosbags_types

    t_start = time.perf_counter()
    site = scene.site
    start = dt.datetime.fromisoformat(spec.start_local).replace(tzinfo=site.zone)
    start_ns = round(start.timestamp()) * 1_000_000_000
    times_ns = start_ns + np.round(np.arange(frames) * 1e9 / rate_hz).astype(np.int64)
    rng_light = np.random.default_rng([spec.seed, 1])
    states, rows = sky_states(site, times_ns, clouds=spec.clouds, rng=rng_light)
    mid = states[len(states) // 2]
    cache = renderer.compute_cache(mid, cache_settings, progress=progress)
    t_cache = time.perf_counter() - t_start
    # trajectory targets: visible surfaces, and sunlit ones
    mesh = scene.mesh
    vis = ~renderer.hidden_vertices()
    pos = mesh.vertices_m
    inside = vis & (pos[:, 2] > 0.05) & (pos[:, 2] < 2.3) & (pos[:, 1] > 0.0)
    rng_sel = np.random.default_rng([spec.seed, 2])
    surface = pos[inside][rng_sel.choice(int(inside.sum()), size=min(5000, int(inside.sum())), replace=False)]
    floor = vis & (pos[:, 2] <= 0.05) & (pos[:, 1] > 0.0) if spec.floor_in_gaze else np.zeros_like(inside)
    lit = (inside | floor) & (cache.sun_direct > 0.3)
    sunlit = pos[lit][rng_sel.choice(int(lit.sum()), size=min(2000, int(lit.sum())), replace=False)] \
        if lit.any() else None
    poses = hand_held_trajectory(scene, frames, rate_hz, np.random.default_rng([spec.seed, 3]),
                                 sunlit_points=sunlit, surface_points=surface,
                                 sunlit_share=spec.sunlit_gaze_share)
    resp = _auto_exposure(renderer, cache, states, poses, CameraResponse())
    depth_sensor = DepthSensor()
    T_map_depth = depth_camera_poses(poses, rate_hz, depth_sensor)
    types = rosbags_types()
    qos = [make_qos(reliable=True, depth=10)]
    seq_dir.mkdir(parents=True, exist_ok=True)
    bag_path = seq_dir / "bag"
    t_render = 0.0
    sat = []
    valid = []
    with BagWriter(bag_path, overwrite=True) as bag:
        for topic, msgtype in ((COLOR_TOPIC, "sensor_msgs/msg/Image"), (COLOR_INFO_TOPIC, "sensor_msgs/msg/CameraInfo"),
                               (DEPTH_TOPIC, "sensor_msgs/msg/Image"), (DEPTH_INFO_TOPIC, "sensor_msgs/msg/CameraInfo"),
                               (GT_POSE_TOPIC, "geometry_msgs/msg/PoseStamped")):
            bag.add_topic(topic, msgtype, offered_qos=qos)
        for i in track(range(frames), desc=f"{spec.name} frames", total=frames, enabled=progress, unit="frame"):
            t0 = time.perf_counter()
            rng = np.random.default_rng([spec.seed, 100, i])
            out = renderer.render(poses[i], camera, cache, states[i], supersample=supersample,
                                  sun_samples=sun_samples, rng=rng)
            rgb = resp.capture(out.radiance, rng)
            z_true = depth_sensor.true_depth(renderer.caster, T_map_depth[i], camera)
            depth_m = depth_sensor.measure(z_true, out.sun_irradiance_wm2, rng)
            depth_mm = np.round(depth_m * 1000.0).astype(np.uint16)
            t_render += time.perf_counter() - t0
            sat.append(float(np.mean(rgb == 255)))
            valid.append(float(np.mean(depth_mm > 0)))
            t_ns = int(times_ns[i])
            header: dict[str, Any] = dict(stamp_ns=t_ns, frame_id=OPTICAL_FRAME, types=types)
            info = camera_info_from_camera(camera, **header)
            bag.write_message(COLOR_TOPIC, t_ns, numpy_to_image(rgb, "rgb8", **header))
            bag.write_message(COLOR_INFO_TOPIC, t_ns, info)
            bag.write_message(DEPTH_TOPIC, t_ns, numpy_to_image(depth_mm, "16UC1", **header))
            bag.write_message(DEPTH_INFO_TOPIC, t_ns, info)
            bag.write_message(GT_POSE_TOPIC, t_ns, matrix_to_pose_stamped(poses[i], stamp_ns=t_ns,
                                                                          frame_id=MAP_FRAME, types=types))
    _link_or_copy(scene_files["mesh"], seq_dir / "mesh.ply")
    _link_or_copy(scene_files["site"], seq_dir / "site.yaml")
    write_text_atomic(seq_dir / "camera.yaml", _camera_yaml(resp, depth_sensor, camera))
    write_text_atomic(seq_dir / "truth.csv", _truth_csv(rows))
    speeds = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1) * rate_hz
    summary = {
        "sequence": asdict(spec),
        "start_utc": dt.datetime.fromtimestamp(start_ns / 1e9, tz=dt.UTC).isoformat(),
        "frames": frames,
        "rate_hz": rate_hz,
        "params": params,
        "params_hash": digest,
        "format_version": FORMAT_VERSION,
        "exposure_s": resp.exposure_s,
        "gain": resp.gain,
        "sun_elevation_deg": [rows[0]["sun_elevation_deg"], rows[-1]["sun_elevation_deg"]],
        "sun_azimuth_deg": [rows[0]["sun_azimuth_deg"], rows[-1]["sun_azimuth_deg"]],
        "cloud_transmittance_range": [min(r["cloud_transmittance"] for r in rows),
                                      max(r["cloud_transmittance"] for r in rows)],
        "speed_mps_median": float(np.median(speeds)) if len(speeds) else 0.0,
        "saturated_fraction_mean": float(np.mean(sat)),
        "valid_depth_fraction_mean": float(np.mean(valid)),
        "cache_stats": cache.stats,
        "seconds_cache": t_cache,
        "ms_per_frame": 1000.0 * t_render / frames,
        "seconds_total": time.perf_counter() - t_start,
        "luma_weights": LUMA.tolist(),
    }
    write_text_atomic(seq_dir / "sequence.json", json.dumps(summary, indent=1) + "\n")
    return summary


def reconstruction_settings(resolution_m: float) -> ReconstructionSettings:
    """The simulated scan for a scene mesh of ``resolution_m``: 2 cm voxels for the full-size scenes; coarse
    voxels and small depth images for the coarse test scenes."""
    if resolution_m <= 0.05:
        return ReconstructionSettings()
    return ReconstructionSettings(voxel_m=resolution_m, width=80, height=60)


def _scene_files(out: Path, scene: DaylightScene, *, progress: bool = False) -> dict[str, Path]:
    """Write (or keep) the shared mesh PLY, the method's reconstructed map PLY and the site YAML of ``scene``
    under ``out/scenes``."""
    d = out / "scenes"
    mesh_path, site_path, meta_path = d / f"{scene.name}.ply", d / f"{scene.name}.site.yaml", d / f"{scene.name}.json"
    map_path = d / f"{scene.name}.map.ply"
    recon = reconstruction_settings(scene.resolution_m)
    meta = {"mesh_hash": scene.mesh.content_hash, "vertices": scene.mesh.num_vertices,
            "faces": scene.mesh.num_faces, "resolution_m": scene.resolution_m, "site": scene.site.to_yaml(),
            "map": {"format_version": MAP_FORMAT_VERSION, "reconstruction": asdict(recon),
                    "depth_sensor": asdict(DepthSensor())}}
    meta = json.loads(json.dumps(meta))  # tuples as lists, as read back
    try:
        same = (json.loads(meta_path.read_text()) == meta and mesh_path.is_file() and site_path.is_file()
                and map_path.is_file())
    except (OSError, ValueError):
        same = False
    if not same:
        if meta_path.exists():
            meta_path.unlink()  # incomplete or stale: the marker goes first
        d.mkdir(parents=True, exist_ok=True)
        save_ply(scene.mesh, mesh_path)
        scene.site.to_yaml(site_path)
        log.info("%s: reconstructing the method's map from a simulated depth scan", scene.name)
        save_ply(reconstruct_map(scene, recon, progress=progress), map_path)
        write_text_atomic(meta_path, json.dumps(meta, indent=1) + "\n")
    openings_path = d / f"{scene.name}.openings.yaml"
    openings = (window_opening(scene.window),)
    try:
        current = load_openings(openings_path)
    except OpeningsError:
        current = ()
    if current != openings:
        save_openings(openings_path, openings)
    return {"mesh": mesh_path, "site": site_path, "map": map_path, "openings": openings_path}


def generate_daylight_set(
    out_dir: str | os.PathLike[str],
    *,
    sequences: Sequence[str | SequenceSpec] | None = None,
    frames: int = 600,
    width: int = 320,
    height: int = 240,
    progress: bool = False,
    rate_hz: float = 30.0,
    resolution_m: float | None = None,
    supersample: int = 2,
    sun_samples: int = 8,
    cache_settings: CacheSettings | None = None,
    site: Site | None = None,
    force: bool = False,
) -> list[Path]:
    """Render the daylight sequences (default all 12 of :data:`SEQUENCES`; also the held-out ones of
    :data:`HELDOUT_SEQUENCES` by name, or any :class:`SequenceSpec`) into ``out_dir``; returns the sequence
    directories. Complete sequences with the same parameters are skipped (``force`` re-renders them).

    ``resolution_m`` is the scene mesh resolution (default 2 cm); ``cache_settings`` overrides the per-scene
    :data:`DEFAULT_CACHE`; ``site`` overrides Freiburg. Small values (e.g. ``frames=3, width=64, height=48,
    resolution_m=0.15``) give tiny test recordings.
    """
    specs: list[SequenceSpec] = []
    unknown: list[str] = []
    for s in sequences or SEQUENCES:
        if isinstance(s, SequenceSpec):
            specs.append(s)
        elif s in _BY_NAME:
            specs.append(_BY_NAME[s])
        else:
            unknown.append(s)
    if unknown:
        raise ValueError(f"unknown sequence(s) {unknown}; choose from {list(_BY_NAME)}")
    if frames < 1 or width < 8 or height < 8:
        raise ValueError(f"need frames >= 1 and an image of at least 8x8, got {frames} frames {width}x{height}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    camera = camera_for_size(width, height)
    results: list[Path] = []
    scenes: dict[str, tuple[DaylightScene, dict[str, Path]]] = {}
    renderers: dict[str, GroundTruthRenderer] = {}
    skipped_scenes: dict[str, float] = {}  # scenes of complete recordings: their files are still brought up to date
    for spec in specs:
        res = resolution_m if resolution_m is not None else 0.02
        cfg = cache_settings or DEFAULT_CACHE[spec.scene]
        cfg = replace(cfg, seed=spec.seed)
        params = {
            "format_version": FORMAT_VERSION, "spec": _spec_params(spec), "frames": frames, "width": width,
            "height": height, "rate_hz": rate_hz, "resolution_m": res, "supersample": supersample,
            "sun_samples": sun_samples, "cache": asdict(cfg),
            "site": (site.to_yaml() if site is not None else "default"),
        }
        digest = _params_hash(params)
        seq_dir = out / spec.name
        if not force and _complete(seq_dir, digest):
            log.info("%s: complete, skipped", spec.name)
            results.append(seq_dir)
            skipped_scenes.setdefault(spec.scene, res)
            continue
        if spec.scene not in scenes:
            kw: dict[str, Any] = {"resolution_m": res}
            if site is not None:
                kw["site"] = site
            scene = make_scene(spec.scene, **kw)
            scenes[spec.scene] = (scene, _scene_files(out, scene, progress=progress))
            renderers[spec.scene] = GroundTruthRenderer(scene.mesh, scene.window)
        scene, files = scenes[spec.scene]
        meta = seq_dir / "sequence.json"
        if meta.exists():
            meta.unlink()  # incomplete or stale: the marker goes first
        summary = _generate_sequence(spec, scene, renderers[spec.scene], seq_dir, files, params, digest,
                                     frames=frames, camera=camera, rate_hz=rate_hz, supersample=supersample,
                                     sun_samples=sun_samples, cache_settings=cfg, progress=progress)
        log.info("%s: %d frames, cache %.1f s, %.0f ms/frame, exposure %.2f ms gain %.2f", spec.name, frames,
                 summary["seconds_cache"], summary["ms_per_frame"], 1e3 * summary["exposure_s"], summary["gain"])
        results.append(seq_dir)
    for scene_name, res in skipped_scenes.items():
        if scene_name not in scenes:  # the map (format, reconstruction settings) may have changed meanwhile
            kw = {"resolution_m": res} if site is None else {"resolution_m": res, "site": site}
            _scene_files(out, make_scene(scene_name, **kw), progress=progress)
    return results
