"""Simulated stereo recordings for colour-constant visual teach & repeat (paper: Paton et al., §V–VI, Table I):
``lightfast sim vtr OUT``.

A robot drives the route of :mod:`lightfast.sim.vtr.build` once to teach it and then repeats it at other times of
day and in other weather, like the paper's field trial at the CSA Mars Emulation Terrain (site :data:`MET_SITE`,
local time America/Toronto). :data:`TABLE_I` holds all 28 rows of the paper's Table I, :data:`DEFAULT_RUNS` the
default teach + 10 repeats spanning both days (listed in docs/vtr.md, "The simulated route"); :func:`load_schedule`
reads any list of ``{name, date, start, weather[, kind]}`` from YAML.

:func:`drive_route` (:class:`DriveConfig`): base poses ``T_map_base`` (4×4; map frame ENU, metres) along the
centreline at ``speed_mps`` (±8 % slow variation), one stereo pair every ``1 / rate_hz`` s; the teach run on the
centreline (±3 cm wander), each repeat with its own constant lateral offset (within ±``lateral_offset_max_m``)
plus a slow wander, ±1° heading wander, the body following the terrain slope and 0.25° (rms) vibration per frame.

:func:`generate_vtr_set` writes ``OUT/scene/`` (scene.npz, scene.json, route.csv, site.yaml, camera.yaml) and per
run ``RUN/bag/`` (rosbag2 MCAP: /stereo/{left,right}/image_raw (rgb8), /stereo/{left,right}/camera_info
(rectified, ``P_right[0,3] = -fx · baseline``), /ground_truth/pose (PoseStamped ``T_map_left-optical``, frame
"map"); stamps are true UTC from the local start time), ``RUN/truth.csv`` (per frame: route position, camera pose,
sun azimuth/elevation in degrees, weather, irradiances in W/m², exposure time in s, gain) and ``RUN/run.json``
(written last), and ``runs.json`` (the file layout in detail: docs/vtr.md). A method under test may read only the
bag's image and ``camera_info`` topics and ``scene/camera.yaml``; everything else is for evaluation. Each run
directory is built under a temporary name and moved into place when complete; a run whose ``run.json`` holds the
same parameter hash is skipped (``force`` re-renders it).
"""
from __future__ import annotations

import csv
import datetime as dt
import hashlib
import io
import json
import logging
import math
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import yaml
from numpy.typing import NDArray

from lightfast.daylight.sun import Site, sun_position
from lightfast.geometry import matrix_to_quat, so3_exp
from lightfast.io import atomic_directory, write_text_atomic
from lightfast.progress import track
from lightfast.sim.vtr.build import build_route_scene
from lightfast.sim.vtr.camera import AutoExposure, SensorModel, StereoRig
from lightfast.sim.vtr.light import Atmosphere, daylight_illumination
from lightfast.sim.vtr.renderer import SpectralRenderer
from lightfast.sim.vtr.scene import SCENE_FORMAT_VERSION, STRETCHES, RouteConfig, RouteScene, base_pose
from lightfast.sim.vtr.spectra import BASIS, WAVELENGTHS_NM, camera_sensitivities, spectrum_cct
from lightfast.topics import GT_POSE_TOPIC, MAP_FRAME

if TYPE_CHECKING:
    from lightfast.ros.msgtypes import MessageTypes

__all__ = [
    "DEFAULT_RUNS",
    "LEFT_FRAME",
    "LEFT_IMAGE_TOPIC",
    "LEFT_INFO_TOPIC",
    "MET_SITE",
    "RIGHT_FRAME",
    "RIGHT_IMAGE_TOPIC",
    "RIGHT_INFO_TOPIC",
    "TABLE_I",
    "DriveConfig",
    "RunSpec",
    "drive_route",
    "generate_vtr_set",
    "load_schedule",
]

log = logging.getLogger(__name__)

LEFT_IMAGE_TOPIC = "/stereo/left/image_raw"
RIGHT_IMAGE_TOPIC = "/stereo/right/image_raw"
LEFT_INFO_TOPIC = "/stereo/left/camera_info"
RIGHT_INFO_TOPIC = "/stereo/right/camera_info"
LEFT_FRAME = "stereo_left_optical_frame"
RIGHT_FRAME = "stereo_right_optical_frame"
#: Topics of every run's bag, in writing order (with ``GT_POSE_TOPIC``).
TOPICS = (LEFT_IMAGE_TOPIC, RIGHT_IMAGE_TOPIC, LEFT_INFO_TOPIC, RIGHT_INFO_TOPIC, GT_POSE_TOPIC)

#: Bump when the output of the same parameters changes (2: micro-relief shading in the renderer).
FORMAT_VERSION = 2

#: The CSA Mars Emulation Terrain, Saint-Hubert (Montreal), Quebec; map frame = ENU.
MET_SITE = Site(latitude_deg=45.5175, longitude_deg=-73.3925, altitude_m=25.0, timezone="America/Toronto",
                temperature_c=15.0)


@dataclass(frozen=True)
class RunSpec:
    """One drive of the route: name, local date and start time at the site, weather, teach or repeat."""

    name: str
    date: str  # YYYY-MM-DD
    start: str  # HH:MM (local)
    weather: str  # "sunny" | "cloudy"
    kind: str = "repeat"  # "teach" | "repeat"
    paper_repeat: int | None = None
    summary: str = ""

    def __post_init__(self) -> None:
        if not self.name or "/" in self.name or self.name.startswith("."):
            raise ValueError(f"bad run name {self.name!r}")
        if self.weather not in ("sunny", "cloudy"):
            raise ValueError(f"run {self.name}: weather must be sunny or cloudy, got {self.weather!r}")
        if self.kind not in ("teach", "repeat"):
            raise ValueError(f"run {self.name}: kind must be teach or repeat, got {self.kind!r}")
        self.start_local(MET_SITE)  # validates date and time

    def start_local(self, site: Site) -> dt.datetime:
        try:
            return dt.datetime.fromisoformat(f"{self.date}T{self.start}").replace(tzinfo=site.zone)
        except ValueError:
            raise ValueError(f"run {self.name}: bad date/start {self.date!r} {self.start!r} "
                             "(expected YYYY-MM-DD and HH:MM)") from None


def _table_i() -> tuple[RunSpec, ...]:
    rows = [("teach", "2014-05-12", "10:50", "Sunny")]
    day1 = ["11:40", "12:53", "13:35", "14:00", "16:06", "17:27", "18:14", "19:00", "19:29", "20:06"]
    day2 = ["06:20", "07:05", "08:00", "09:00", "10:00", "11:00", "12:00", "13:00", "14:00", "15:10", "16:00",
            "17:00", "18:00", "19:00", "20:00", "20:30"]
    for i, t in enumerate(day1, 1):
        rows.append((f"repeat{i:02d}", "2014-05-12", t, "Sunset" if i == 10 else "Sunny"))
    for i, t in enumerate(day2, 11):
        rows.append((f"repeat{i:02d}", "2014-05-13", t, {25: "Sunset", 26: "Dark"}.get(i, "Cloudy")))
    rows.append(("repeat27", "2014-05-15", "08:50", "Sunny"))
    out = []
    for name, date, start, summary in rows:
        weather = "cloudy" if date == "2014-05-13" else "sunny"
        kind = "teach" if name == "teach" else "repeat"
        number = None if kind == "teach" else int(name[6:])
        out.append(RunSpec(name, date, start, weather, kind, number, summary))
    return tuple(out)


#: Every row of the paper's Table I (teach and repeats 1–27).
TABLE_I: tuple[RunSpec, ...] = _table_i()
_BY_NAME = {r.name: r for r in TABLE_I}
#: The default schedule: teach + 10 repeats spanning both days (see the module docstring).
DEFAULT_RUNS: tuple[str, ...] = ("teach", "repeat01", "repeat04", "repeat06", "repeat07", "repeat10", "repeat11",
                                 "repeat15", "repeat19", "repeat24", "repeat27")


def load_schedule(path: str | os.PathLike[str]) -> list[RunSpec]:
    """A schedule YAML: a list of mappings with ``name, date, start, weather`` and optionally ``kind``."""
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"{path}: cannot read schedule: {exc}") from None
    if not isinstance(data, list) or not data:
        raise ValueError(f"{path}: expected a non-empty list of runs")
    runs = []
    for item in data:
        if not isinstance(item, dict):
            raise ValueError(f"{path}: each run must be a mapping, got {item!r}")
        unknown = set(item) - {"name", "date", "start", "weather", "kind", "summary"}
        if unknown:
            raise ValueError(f"{path}: unknown key(s) {sorted(unknown)} in {item!r}")
        try:
            runs.append(RunSpec(str(item["name"]), str(item["date"]), str(item["start"]), str(item["weather"]),
                                str(item.get("kind", "teach" if item["name"] == "teach" else "repeat")),
                                summary=str(item.get("summary", ""))))
        except KeyError as exc:
            raise ValueError(f"{path}: run {item!r} lacks {exc}") from None
    names = [r.name for r in runs]
    if len(set(names)) != len(names):
        raise ValueError(f"{path}: duplicate run names")
    return runs


# ================================================================================================================
# driving


@dataclass(frozen=True)
class DriveConfig:
    """How the robot drives a run (see the module docstring). ``max_frames`` truncates runs (for tests)."""

    speed_mps: float = 0.8
    rate_hz: float = 2.0
    speed_variation: float = 0.08
    lateral_offset_max_m: float = 0.3
    lateral_wander_m: float = 0.12
    teach_wander_m: float = 0.03
    yaw_wander_deg: float = 1.0
    vibration_deg: float = 0.25
    start_m: float = 1.0
    end_margin_m: float = 1.0
    max_frames: int | None = None

    def __post_init__(self) -> None:
        if not (0.0 < self.speed_mps <= 5.0 and 0.0 < self.rate_hz <= 100.0):
            raise ValueError(f"need 0 < speed_mps <= 5 and 0 < rate_hz <= 100, got {self.speed_mps}, {self.rate_hz}")
        if self.max_frames is not None and self.max_frames < 1:
            raise ValueError("max_frames must be >= 1")


@dataclass(frozen=True, eq=False)
class Drive:
    """A run's trajectory: per frame ``time_s``, arc length ``s_m``, ``lateral_m`` and ``T_map_base`` (n, 4, 4)."""

    time_s: NDArray[np.float64]
    s_m: NDArray[np.float64]
    lateral_m: NDArray[np.float64]
    T_map_base: NDArray[np.float64] = field(repr=False)


def _wander(x: NDArray[np.float64], rng: np.random.Generator, periods: tuple[float, float]) -> NDArray[np.float64]:
    p = np.exp(rng.uniform(math.log(periods[0]), math.log(periods[1]), 3))
    a = rng.uniform(0.5, 1.0, 3)
    ph = rng.uniform(0.0, 2.0 * math.pi, 3)
    return np.sin(2.0 * math.pi * x[:, None] / p + ph) @ a / a.sum()


def drive_route(scene: RouteScene, cfg: DriveConfig, *, teach: bool, seed: int | Sequence[int]) -> Drive:
    """The robot's base poses for one run (deterministic in ``seed``)."""
    rng = np.random.default_rng(seed)
    end = scene.length_m - cfg.end_margin_m
    if end <= cfg.start_m:
        raise ValueError(f"route of {scene.length_m} m is too short to drive")
    dt_s = 1.0 / cfg.rate_hz
    n_max = int((end - cfg.start_m) / (cfg.speed_mps * dt_s * (1.0 - cfg.speed_variation))) + 2
    t = cast(NDArray[np.float64], np.arange(n_max) * dt_s)
    v = cfg.speed_mps * (1.0 + cfg.speed_variation * _wander(t, rng, (20.0, 90.0)))
    s = cfg.start_m + np.concatenate([[0.0], np.cumsum(v[:-1] * dt_s)])
    n = int(np.searchsorted(s, end, side="right"))
    if cfg.max_frames is not None:
        n = min(n, cfg.max_frames)
    t, s = t[:n], s[:n]
    if teach:
        lat = cfg.teach_wander_m * _wander(s, rng, (8.0, 30.0))
    else:
        lat = rng.uniform(-1.0, 1.0) * cfg.lateral_offset_max_m + cfg.lateral_wander_m * _wander(s, rng, (8.0, 30.0))
    yaw = math.radians(cfg.yaw_wander_deg) * _wander(s, rng, (4.0, 12.0))
    vib = np.radians(cfg.vibration_deg) * rng.standard_normal((n, 3)) * np.array([1.0, 1.0, 0.5])
    T = np.empty((n, 4, 4))
    for i in range(n):
        T[i] = base_pose(scene, float(s[i]), float(lat[i]), float(yaw[i]))
        T[i, :3, :3] = T[i, :3, :3] @ so3_exp(vib[i])
    return Drive(t, s, lat, T)


# ================================================================================================================
# files


def _params_hash(params: dict) -> str:
    return hashlib.sha256(json.dumps(params, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _complete(run_dir: Path, digest: str) -> bool:
    try:
        meta = json.loads((run_dir / "run.json").read_text())
    except (OSError, ValueError):
        return False
    return meta.get("params_hash") == digest and all(
        (run_dir / name).exists() for name in ("bag/metadata.yaml", "truth.csv"))


def _csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.9g}" if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()


def _camera_yaml(rig: StereoRig, sensor: SensorModel) -> str:
    doc = {
        "description": (
            "Calibration of the simulated rectified stereo pair (what a real user could measure) and the simulated "
            "sensor. Pixel value = round(255 * clip(wb * clip(x + noise, 0, 1), 0, 1) ** (1 / gamma)) with "
            "x = quantum_scale * exposure_s * gain * R, R = sum over wavelength of L(lambda) S_c(lambda) dlambda "
            "(L spectral radiance in W m^-2 sr^-1 nm^-1, S_c the sensitivities below)."),
        "width": rig.width, "height": rig.height,
        "fx": rig.fx, "fy": rig.fx, "cx": rig.camera.cx, "cy": rig.camera.cy,
        "baseline_m": rig.baseline_m,
        "P_left": rig.P_left.tolist(), "P_right": rig.P_right.tolist(),
        "T_base_left": rig.T_base_left.tolist(),
        "gamma": sensor.gamma,
        "sensor": {k: v for k, v in asdict(sensor).items()},
        "white_balance_gains_rgb": [float(x) for x in sensor.wb_gains],
        "spectral_sensitivity_source": f"colour-science MSDS_CAMERA_SENSITIVITIES[{sensor.sensitivity!r}]",
        "wavelengths_nm": WAVELENGTHS_NM.tolist(),
        "spectral_sensitivities_rgb": np.round(camera_sensitivities(sensor.sensitivity), 6).tolist(),
    }
    return yaml.safe_dump(doc, sort_keys=False, width=120)


def _scene_files(out: Path, route: RouteConfig, rig: StereoRig, sensor: SensorModel, site: Site,
                 progress: bool) -> RouteScene:
    """Load the scene from ``out/scene`` if it was built with ``route``, else build and write it."""
    d = out / "scene"
    digest = _params_hash({"route": route.to_dict(), "scene_format": SCENE_FORMAT_VERSION})
    if (d / "scene.json").is_file():
        try:
            meta = json.loads((d / "scene.json").read_text())
            if meta.get("params_hash") == digest:
                scene = RouteScene.load(d / "scene.npz")
                log.info("scene: loaded %s", d / "scene.npz")
                return scene
            log.info("scene: parameters changed, rebuilding")
        except Exception as exc:  # an unreadable scene is rebuilt
            log.info("scene: rebuilding (%s)", exc)
    t0 = time.perf_counter()
    scene = build_route_scene(route, progress=progress)
    scene.save(d / "scene.npz")
    s = np.arange(0.0, route.length_m + 1e-9, 0.5)
    xy, heading = scene.centreline(s)
    z = scene.height(xy)
    stretch = scene.stretch_at(s)
    rows = [{"s_m": float(s[i]), "x_m": float(xy[i, 0]), "y_m": float(xy[i, 1]), "z_m": float(z[i]),
             "heading_deg": float(np.degrees(heading[i])), "stretch": STRETCHES[int(stretch[i])]}
            for i in range(len(s))]
    write_text_atomic(d / "route.csv", _csv(rows))
    site.to_yaml(d / "site.yaml")
    write_text_atomic(d / "camera.yaml", _camera_yaml(rig, sensor))
    meta = {"params_hash": digest, "route": route.to_dict(), "stats": scene.stats,
            "content_hash": scene.content_hash, "basis_spectra": list(BASIS),
            "seconds_build": round(time.perf_counter() - t0, 3)}
    write_text_atomic(d / "scene.json", json.dumps(meta, indent=1) + "\n")
    log.info("scene: built in %.1f s (%s)", meta["seconds_build"], scene.stats)
    return scene


# ================================================================================================================
# generation


def _weather_series(spec: RunSpec, t: NDArray[np.float64], rng: np.random.Generator
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Cloud transmittance (of the clear-sky global light) and direct transmittance per frame (cloudy only)."""
    if spec.weather == "sunny":
        return np.ones_like(t), np.ones_like(t)
    cloud = 0.35 * (1.0 + 0.2 * _wander(t, rng, (60.0, 400.0)))
    direct = 0.02 * (1.0 + 0.8 * _wander(t, rng, (30.0, 200.0)))
    return cloud, np.maximum(direct, 0.0)


def _right_info(types: MessageTypes, rig: StereoRig, stamp_ns: int) -> Any:
    from lightfast.ros.convert import camera_info_from_camera

    msg = camera_info_from_camera(rig.camera, stamp_ns=stamp_ns, frame_id=RIGHT_FRAME, types=types)
    msg.p = types.float64_array(rig.P_right.reshape(-1))
    return msg


def _generate_run(spec: RunSpec, scene: RouteScene, renderer: SpectralRenderer, run_dir: Path, *, params: dict,
                  digest: str, rig: StereoRig, sensor: SensorModel, drive: DriveConfig, atmosphere: Atmosphere,
                  site: Site, seed: int, progress: bool) -> dict:
    from lightfast.bag.writer import BagWriter, make_qos
    from lightfast.ros.convert import camera_info_from_camera, matrix_to_pose_stamped, numpy_to_image
    from lightfast.ros.msgtypes import rosbags_types

    t_start = time.perf_counter()
    run_seed = int(hashlib.sha256(spec.name.encode()).hexdigest()[:8], 16)
    trj = drive_route(scene, drive, teach=spec.kind == "teach", seed=[seed, run_seed, 1])
    n = len(trj.time_s)
    start = spec.start_local(site)
    start_ns = round(start.timestamp()) * 1_000_000_000
    stamps = start_ns + np.round(trj.time_s * 1e9).astype(np.int64)
    sun = sun_position(site, stamps)
    sun_elevation_deg = cast(NDArray[np.float64], sun.elevation_deg)  # an array of times: arrays of angles
    sun_azimuth_deg = cast(NDArray[np.float64], sun.azimuth_deg)
    cloud, direct_t = _weather_series(spec, trj.time_s, np.random.default_rng([seed, run_seed, 2]))
    camera = rig.camera
    types = rosbags_types()
    qos = [make_qos(reliable=True, depth=10)]
    ae = AutoExposure(sensor)
    rows: list[dict] = []
    t_render = 0.0
    cct = {}
    with atomic_directory(run_dir, overwrite=True) as tmp:
        with BagWriter(tmp / "bag") as bag:
            for topic, msgtype in ((LEFT_IMAGE_TOPIC, "sensor_msgs/msg/Image"),
                                   (RIGHT_IMAGE_TOPIC, "sensor_msgs/msg/Image"),
                                   (LEFT_INFO_TOPIC, "sensor_msgs/msg/CameraInfo"),
                                   (RIGHT_INFO_TOPIC, "sensor_msgs/msg/CameraInfo"),
                                   (GT_POSE_TOPIC, "geometry_msgs/msg/PoseStamped")):
                bag.add_topic(topic, msgtype, offered_qos=qos)
            for i in track(range(n), desc=f"{spec.name} frames", total=n, enabled=progress, unit="frame"):
                t0 = time.perf_counter()
                el = float(sun_elevation_deg[i])
                light = daylight_illumination(sun.direction_map[i], el, spec.weather,
                                              cloud_transmittance=float(cloud[i]),
                                              direct_transmittance=float(direct_t[i]), atmosphere=atmosphere)
                T_l, T_r = rig.camera_poses(trj.T_map_base[i])
                out_l, out_r = renderer.render([T_l, T_r], camera, light, np.random.default_rng([seed, run_seed,
                                                                                                 3, i]))
                exposure, gain = ae.update(out_l.raw)
                rng = np.random.default_rng([seed, run_seed, 4, i])
                img_l = sensor.capture(out_l.raw, exposure, gain, rng)
                img_r = sensor.capture(out_r.raw, exposure, gain, rng)
                t_render += time.perf_counter() - t0
                t_ns = int(stamps[i])
                bag.write_message(LEFT_IMAGE_TOPIC, t_ns, numpy_to_image(img_l, "rgb8", stamp_ns=t_ns,
                                                                         frame_id=LEFT_FRAME, types=types))
                bag.write_message(RIGHT_IMAGE_TOPIC, t_ns, numpy_to_image(img_r, "rgb8", stamp_ns=t_ns,
                                                                          frame_id=RIGHT_FRAME, types=types))
                bag.write_message(LEFT_INFO_TOPIC, t_ns, camera_info_from_camera(camera, stamp_ns=t_ns,
                                                                                 frame_id=LEFT_FRAME, types=types))
                bag.write_message(RIGHT_INFO_TOPIC, t_ns, _right_info(types, rig, t_ns))
                bag.write_message(GT_POSE_TOPIC, t_ns, matrix_to_pose_stamped(T_l, stamp_ns=t_ns,
                                                                              frame_id=MAP_FRAME, types=types))
                if i in (0, n - 1):
                    key = "first" if i == 0 else "last"
                    cct[f"sun_cct_k_{key}"] = spectrum_cct(light.direct_normal) if light.direct_normal.max() > 0 \
                        else None
                    cct[f"sky_cct_k_{key}"] = spectrum_cct(light.sky_horizontal)
                q = matrix_to_quat(T_l[:3, :3])
                rows.append({
                    "frame": i, "stamp_ns": t_ns, "time_s": float(trj.time_s[i]), "s_m": float(trj.s_m[i]),
                    "lateral_m": float(trj.lateral_m[i]),
                    "stretch": STRETCHES[int(scene.stretch_at(trj.s_m[i]))],
                    "x_m": float(T_l[0, 3]), "y_m": float(T_l[1, 3]), "z_m": float(T_l[2, 3]),
                    "qx": float(q[0]), "qy": float(q[1]), "qz": float(q[2]), "qw": float(q[3]),
                    "sun_azimuth_deg": float(sun_azimuth_deg[i]), "sun_elevation_deg": el,
                    "weather": spec.weather, "cloud_transmittance": float(cloud[i]),
                    "direct_transmittance": float(direct_t[i]),
                    "direct_normal_vis_wm2": float(light.direct_normal.sum() * 10.0),
                    "sky_horizontal_vis_wm2": float(light.sky_horizontal.sum() * 10.0),
                    "exposure_s": float(exposure), "gain": float(gain),
                    "saturated_fraction": float(np.mean(np.any(img_l == 255, axis=2))),
                    "mean_value": float(img_l.mean()),
                })
        write_text_atomic(tmp / "truth.csv", _csv(rows))
        summary = {
            "run": asdict(spec),
            "start_local": start.isoformat(),
            "start_utc": dt.datetime.fromtimestamp(start_ns / 1e9, tz=dt.UTC).isoformat(),
            "frames": n,
            "rate_hz": drive.rate_hz,
            "distance_m": float(trj.s_m[-1] - trj.s_m[0]) if n > 1 else 0.0,
            "params": params,
            "params_hash": digest,
            "format_version": FORMAT_VERSION,
            "topics": list(TOPICS),
            "image_size": [rig.width, rig.height],
            "sun_elevation_deg": [float(sun_elevation_deg[0]), float(sun_elevation_deg[-1])],
            "sun_azimuth_deg": [float(sun_azimuth_deg[0]), float(sun_azimuth_deg[-1])],
            **cct,
            "exposure_s_range": [min(r["exposure_s"] for r in rows), max(r["exposure_s"] for r in rows)],
            "gain_range": [min(r["gain"] for r in rows), max(r["gain"] for r in rows)],
            "lateral_m_range": [float(trj.lateral_m.min()), float(trj.lateral_m.max())],
            "saturated_fraction_mean": float(np.mean([r["saturated_fraction"] for r in rows])),
            "ms_per_frame": 1000.0 * t_render / n,
            "ms_per_frame_note": f"stereo pair {rig.width}x{rig.height}: render both views, exposure, noise",
            "seconds_total": time.perf_counter() - t_start,
            "method_may_read": ["bag: /stereo/*/image_raw, /stereo/*/camera_info", "../scene/camera.yaml"],
            "truth_only": ["bag: /ground_truth/pose", "truth.csv", "run.json", "../scene/*"],
        }
        write_text_atomic(tmp / "run.json", json.dumps(summary, indent=1) + "\n")
    return summary


def _resolve_runs(runs: Sequence[str | RunSpec] | None) -> list[RunSpec]:
    if runs is None:
        runs = DEFAULT_RUNS
    out = []
    for r in runs:
        if isinstance(r, RunSpec):
            out.append(r)
        elif r in _BY_NAME:
            out.append(_BY_NAME[r])
        else:
            raise ValueError(f"unknown run {r!r}; choose from {[s.name for s in TABLE_I]} or pass a RunSpec")
    names = [r.name for r in out]
    if len(set(names)) != len(names):
        raise ValueError(f"duplicate run names in {names}")
    return out


def generate_vtr_set(
    out_dir: str | os.PathLike[str],
    *,
    runs: Sequence[str | RunSpec] | None = None,
    route: RouteConfig | None = None,
    rig: StereoRig | None = None,
    sensor: SensorModel | None = None,
    drive: DriveConfig | None = None,
    atmosphere: Atmosphere | None = None,
    site: Site = MET_SITE,
    seed: int = 0,
    progress: bool = False,
    force: bool = False,
) -> list[Path]:
    """Render the runs (default :data:`DEFAULT_RUNS`) into ``out_dir``; returns the run directories. Complete runs
    with the same parameters are skipped (``force`` re-renders them). See the module docstring."""
    route = route or RouteConfig()
    rig = rig or StereoRig()
    sensor = sensor or SensorModel()
    drive = drive or DriveConfig()
    atmosphere = atmosphere or Atmosphere()
    specs = _resolve_runs(runs)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    scene: RouteScene | None = None
    renderer: SpectralRenderer | None = None
    results = []
    index = []
    for spec in specs:
        params = {"format_version": FORMAT_VERSION, "scene_format": SCENE_FORMAT_VERSION, "run": asdict(spec),
                  "route": route.to_dict(), "rig": asdict(rig), "sensor": asdict(sensor), "drive": asdict(drive),
                  "atmosphere": asdict(atmosphere), "site": site.to_yaml(), "seed": seed}
        digest = _params_hash(params)
        run_dir = out / spec.name
        if not force and _complete(run_dir, digest):
            log.info("%s: complete, skipped", spec.name)
            summary = json.loads((run_dir / "run.json").read_text())
        else:
            if scene is None:
                scene = _scene_files(out, route, rig, sensor, site, progress)
                renderer = SpectralRenderer(scene)
            (run_dir / "run.json").unlink(missing_ok=True)  # incomplete or stale
            assert renderer is not None
            summary = _generate_run(spec, scene, renderer, run_dir, params=params, digest=digest, rig=rig,
                                    sensor=sensor, drive=drive, atmosphere=atmosphere, site=site, seed=seed,
                                    progress=progress)
            log.info("%s: %d frames, %.0f ms/frame, sun %.1f..%.1f deg", spec.name, summary["frames"],
                     summary["ms_per_frame"], *summary["sun_elevation_deg"])
        results.append(run_dir)
        index.append({"name": spec.name, "dir": spec.name, "kind": spec.kind, "date": spec.date,
                      "start": spec.start, "weather": spec.weather, "paper_repeat": spec.paper_repeat,
                      "frames": summary["frames"], "params_hash": summary["params_hash"]})
    write_text_atomic(out / "runs.json", json.dumps({"format_version": FORMAT_VERSION, "runs": index},
                                                    indent=1) + "\n")
    return results
