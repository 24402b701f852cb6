"""Simulated indoor daylight RGB-D recordings like the paper's DS1.T1–T6 and DS2.T1–T6 (Krawez et al., §IV-A, Fig. 6).

Every image is rendered by the independent ground-truth renderer :mod:`lightfast.sim.gt_renderer` (Monte-Carlo
transport, sun disk, CIE sky, glass, camera response and noise), never by the method's radiosity code.

The set (site Freiburg, 48.0° N 7.85° E, map frame = ENU, window facing south; local times):

=========  =====  ======================  =======  ==================================================
sequence   scene  local time              sky      sun (azimuth / elevation, approx.)
=========  =====  ======================  =======  ==================================================
DS1.T1     DS1    2021-01-19 10:00 CET    clear    142° / 13° (winter morning, deep sun patch)
DS1.T2     DS1    2021-01-19 12:30 CET    clear    178° / 22° (winter noon)
DS1.T3     DS1    2021-01-21 14:30 CET    clear    207° / 18° (winter afternoon)
DS1.T4     DS1    2021-01-21 15:50 CET    clear    225° / 10° (low sun, orange light)
DS1.T5     DS1    2021-02-03 11:00 CET    clear    153° / 22°
DS1.T6     DS1    2021-02-03 13:15 CET    clouds   189° / 25° (sun covered and uncovered)
DS2.T1     DS2    2021-07-14 10:00 CEST   clear    102° / 40° (summer morning, grazing from east)
DS2.T2     DS2    2021-07-14 12:00 CEST   clear    136° / 57°
DS2.T3     DS2    2021-07-14 13:30 CEST   clear    178° / 64° (high sun, patch near the window)
DS2.T4     DS2    2021-07-14 15:30 CEST   clear    231° / 55°
DS2.T5     DS2    2021-07-14 17:00 CEST   clear    256° / 41° (grazing from west)
DS2.T6     DS2    2021-07-14 14:30 CEST   clouds   208° / 61°
=========  =====  ======================  =======  ==================================================

Light: clear-sky DNI/DHI (pvlib simplified Solis) per frame for the true sun position; in T6 a smooth random
cloud transmittance ``a(t) ∈ [0.02, 1]`` (clouds passing over seconds) scales the sun's DNI, dims the clear sky by
``1 - 0.2 (1 - a)`` and adds a CIE overcast component with DHI ``0.3 (1 - a) DNI_clear sin(elevation)``, so the
sky gets brighter while the sun is covered.

Camera: 30 Hz, 320 × 240 by default (Asus Xtion intrinsics scaled: fx = fy = 262.5, cx = 159.5, cy = 119.5), a
hand-held-like trajectory (0.2–0.5 m/s, 1.15–1.75 m above the floor, ≥ 0.8 m from the walls, looking at random
surfaces and at sunlit ones, with smooth roll and 2–9 Hz jitter). Exposure time and gain are fixed per sequence
("appropriate to the illumination", as the paper did): the median luminance of probe renders along the
trajectory maps to a normalized exposure of 0.18, so sunlit areas saturate.

Output of :func:`generate_daylight_set` in ``OUT``::

    scenes/DS1.ply, DS1.site.yaml, DS1.json   the true scene mesh (linear RGB reflectance) and site, shared
    scenes/DS1.openings.yaml        the window's opening as a user would measure it (outer rectangle + 2 cm); give
                                    it to ``lightfast daylight prepare --openings``
    scenes/DS1.map.ply              the method's map: a TSDF reconstruction of a simulated night-time depth scan
                                    with recovered reflectance (:mod:`lightfast.sim.map_reconstruction`, as the
                                    paper's maps were made, §IV-A); give this one to ``lightfast daylight prepare``
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

A sequence whose ``sequence.json`` holds the same parameter hash and whose files exist is skipped.
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
import shutil
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
import yaml
from numpy.typing import NDArray
from scipy.interpolate import PchipInterpolator

from lightfast.camera import PinholeCamera
from lightfast.daylight.errors import OpeningsError
from lightfast.daylight.mesh import save_ply
from lightfast.daylight.openings import load_openings, save_openings
from lightfast.daylight.sun import Site, sun_position
from lightfast.geometry import inverse, se3_exp, se3_log
from lightfast.io import write_text_atomic
from lightfast.progress import track
from lightfast.sim.daylight_scene import DaylightScene, make_scene, window_opening
from lightfast.sim.gt_renderer import (
    CacheSettings,
    CameraResponse,
    DepthSensor,
    GroundTruthRenderer,
    IrradianceCache,
    frame_scales,
)
from lightfast.sim.map_reconstruction import ReconstructionSettings, reconstruct_map
from lightfast.sim.sky_model import (
    CLEAR_SKY_RGB,
    LUMA,
    OVERCAST_SKY_RGB,
    SkyState,
    clear_sky_irradiance,
    float3,
    luminance,
    sun_rgb,
)
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
    "SEQUENCES",
    "SequenceSpec",
    "camera_for_size",
    "cloud_transmittance",
    "generate_daylight_set",
    "hand_held_trajectory",
    "sky_states",
]

log = logging.getLogger(__name__)

#: Bump when the output of the same parameters changes.
FORMAT_VERSION = 3  # 2: gaze angular rates limited (the look-at gaze whipped at up to 900°/s near targets);
# 3: depth from the depth camera (time offset, registration error, projector shadow, correlated + systematic error)
#: Bump when the reconstructed map of the same scene changes.
MAP_FORMAT_VERSION = 4  # 2, 3: zero-area slivers (also after float32 rounding), non-manifold edges removed; 4: planes
#: Limits of the gaze's angular rates (before the hand jitter), like a person panning a hand-held camera.
MAX_YAW_RATE_DEG_S = 75.0
MAX_PITCH_RATE_DEG_S = 45.0


@dataclass(frozen=True)
class SequenceSpec:
    """One recording: scene, local start time (ISO, in the site's time zone), clouds or clear, seed."""

    name: str
    scene: str
    start_local: str
    clouds: bool
    seed: int
    description: str


SEQUENCES: tuple[SequenceSpec, ...] = (
    SequenceSpec("DS1.T1", "DS1", "2021-01-19T10:00:00", False, 11, "winter morning, clear"),
    SequenceSpec("DS1.T2", "DS1", "2021-01-19T12:30:00", False, 12, "winter noon, clear"),
    SequenceSpec("DS1.T3", "DS1", "2021-01-21T14:30:00", False, 13, "winter afternoon, clear"),
    SequenceSpec("DS1.T4", "DS1", "2021-01-21T15:50:00", False, 14, "winter late afternoon, low sun, clear"),
    SequenceSpec("DS1.T5", "DS1", "2021-02-03T11:00:00", False, 15, "winter late morning, clear"),
    SequenceSpec("DS1.T6", "DS1", "2021-02-03T13:15:00", True, 16, "winter midday, moving clouds"),
    SequenceSpec("DS2.T1", "DS2", "2021-07-14T10:00:00", False, 21, "summer morning, clear"),
    SequenceSpec("DS2.T2", "DS2", "2021-07-14T12:00:00", False, 22, "summer late morning, clear"),
    SequenceSpec("DS2.T3", "DS2", "2021-07-14T13:30:00", False, 23, "summer noon, high sun, clear"),
    SequenceSpec("DS2.T4", "DS2", "2021-07-14T15:30:00", False, 24, "summer afternoon, clear"),
    SequenceSpec("DS2.T5", "DS2", "2021-07-14T17:00:00", False, 25, "summer late afternoon, clear"),
    SequenceSpec("DS2.T6", "DS2", "2021-07-14T14:30:00", True, 26, "summer afternoon, moving clouds"),
)
_BY_NAME = {s.name: s for s in SEQUENCES}

#: Default irradiance-cache sample counts per scene (DS2 has fewer vertices and no texture to hide noise).
DEFAULT_CACHE = {
    "DS1": CacheSettings(hemisphere_samples=32, window_samples=16, sunlit_samples=16),
    "DS2": CacheSettings(hemisphere_samples=64, window_samples=32, sunlit_samples=32, filter_radius_m=0.12),
}


def camera_for_size(width: int, height: int) -> PinholeCamera:
    """Asus Xtion–like intrinsics (fx = fy = 262.5 px at 320 × 240) scaled to ``width × height``."""
    sx, sy = width / 320.0, height / 240.0
    return PinholeCamera(width, height, 262.5 * sx, 262.5 * sy, 160.0 * sx - 0.5, 120.0 * sy - 0.5)


# ----------------------------------------------------------------------------------------------------------------
# light over time


def _smooth_noise_1d(t: NDArray[np.float64], scale_s: float, rng: np.random.Generator,
                     octaves: int = 3) -> NDArray[np.float64]:
    """Smooth random signal in about [0, 1]: octaves of cubic-interpolated lattice noise with period ``scale_s``."""
    out = np.zeros_like(t)
    norm = 0.0
    for k in range(octaves):
        s = scale_s / 2**k
        n_knots = math.ceil((t.max() - t.min()) / s) + 4
        knots = rng.random(n_knots)
        x = (t - t.min()) / s + 1.0
        out += 0.5**k * PchipInterpolator(np.arange(n_knots), knots)(x)
        norm += 0.5**k
    return out / norm


def cloud_transmittance(times_s: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.float64]:
    """A smooth random sun transmittance ``a(t)`` in [0.02, 1] for clouds drifting past the sun: cloud optical
    depth ``τ = 4 clip((n - 0.38) / 0.2, 0, 1)²`` of smooth noise ``n`` (≈ 5 s time scale), ``a = exp(-τ)``.
    Re-drawn until at least 15 % of the sequence is clear (a > 0.8) and 15 % covered (a < 0.3), when it is long
    enough (≥ 8 s)."""
    a = np.ones_like(times_s)
    for _ in range(100):
        n = _smooth_noise_1d(times_s, 5.0, rng)
        tau = 4.0 * np.clip((n - 0.38) / 0.2, 0.0, 1.0) ** 2
        a = np.maximum(np.exp(-tau), 0.02)
        if times_s.max() - times_s.min() < 8.0 or (np.mean(a > 0.8) >= 0.15 and np.mean(a < 0.3) >= 0.15):
            break
    return a


def sky_states(site: Site, times_ns: NDArray[np.int64], *, clouds: bool,
               rng: np.random.Generator) -> tuple[list[SkyState], list[dict[str, float]]]:
    """The outdoor light of every frame and a truth record per frame (see the module docstring)."""
    pos = sun_position(site, times_ns)
    elevation_deg = cast(NDArray[np.float64], pos.elevation_deg)  # an array of times: arrays of angles
    azimuth_deg = cast(NDArray[np.float64], pos.azimuth_deg)
    t_s = (times_ns - times_ns[0]) * 1e-9
    att = cloud_transmittance(t_s, rng) if clouds else np.ones(len(times_ns))
    states, rows = [], []
    for i, ns in enumerate(times_ns):
        el = float(elevation_deg[i])
        cs = clear_sky_irradiance(el, altitude_m=site.altitude_m)
        a = float(att[i])
        dni = cs.dni_wm2 * a
        dhi_clear = cs.dhi_wm2 * (1.0 - 0.2 * (1.0 - a))
        dhi_over = 0.3 * (1.0 - a) * cs.dni_wm2 * max(0.0, math.sin(math.radians(el)))
        sun_col = sun_rgb(el)
        st = SkyState(
            sun_direction=float3(pos.direction_map[i]),
            sun_dni_rgb=float3(dni * sun_col),
            clear_dhi_rgb=float3(dhi_clear * CLEAR_SKY_RGB),
            overcast_dhi_rgb=float3(dhi_over * OVERCAST_SKY_RGB),
        )
        states.append(st)
        sc = frame_scales(st)
        row: dict[str, float] = {
            "frame": i, "stamp_ns": int(ns),
            "sun_azimuth_deg": float(azimuth_deg[i]), "sun_elevation_deg": el,
            "sun_dir_x": st.sun_direction[0], "sun_dir_y": st.sun_direction[1], "sun_dir_z": st.sun_direction[2],
            "cloud_transmittance": a, "dni_wm2": dni, "dhi_clear_wm2": dhi_clear, "dhi_overcast_wm2": dhi_over,
            "ghi_wm2": float(luminance(st.ghi_rgb)),
        }
        for name, key in (("sun", "sun"), ("clear", "sky_clear"), ("overcast", "sky_overcast"),
                          ("ground", "ground")):
            for c, ch in enumerate("rgb"):
                row[f"{key}_{ch}"] = float(sc[name][c])
        rows.append(row)
    return states, rows


# ----------------------------------------------------------------------------------------------------------------
# trajectory


def _look_at(p: NDArray[np.float64], f: NDArray[np.float64], roll: float) -> NDArray[np.float64]:
    """T_map_camera (optical: x right, y down, z forward) at ``p`` looking along ``f`` with ``roll`` (rad)."""
    z = f / np.linalg.norm(f)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(roll), math.sin(roll)
    x, y = c * x + s * y, -s * x + c * y
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = p
    return T


def _rate_limited(x: NDArray[np.float64], max_step: float) -> NDArray[np.float64]:
    """``x`` followed with at most ``max_step`` change per sample (a first-order slew-rate limiter)."""
    out = np.empty_like(x)
    out[0] = x[0]
    for i in range(1, len(x)):  # sequential by nature; n_frames samples only
        out[i] = out[i - 1] + min(max(x[i] - out[i - 1], -max_step), max_step)
    return out


def hand_held_trajectory(scene: DaylightScene, n_frames: int, rate_hz: float, rng: np.random.Generator, *,
                         sunlit_points: NDArray[np.float64] | None = None,
                         surface_points: NDArray[np.float64] | None = None,
                         wall_margin_m: float = 0.8) -> NDArray[np.float64]:
    """Camera poses ``(n_frames, 4, 4)`` (T_map_camera, optical frame): a smooth walk at 0.2–0.5 m/s through the
    free middle of the room (PCHIP through random waypoints, so it never overshoots them) at 1.15–1.75 m,
    looking at a sequence of targets (random surface points, ~40 % of them sunlit), with smooth roll (±4°) and
    2–9 Hz hand jitter (≈ 0.3° and ≈ 1.5 mm rms). The gaze follows the targets with its yaw and pitch rates limited
    to :data:`MAX_YAW_RATE_DEG_S` and :data:`MAX_PITCH_RATE_DEG_S` (a target passing close by would otherwise whip
    the camera round at hundreds of degrees per second)."""
    W, D, _ = scene.room_size_m
    lo = np.array([wall_margin_m, wall_margin_m, 1.15])
    hi = np.array([W - wall_margin_m, D - wall_margin_m, 1.75])
    t = np.arange(n_frames) / rate_hz
    duration = max(t[-1], 1e-3)
    ph = rng.uniform(0, 2 * math.pi, 4)
    speed = 0.35 + 0.1 * np.sin(2 * math.pi * t / 6.0 + ph[0]) + 0.04 * np.sin(2 * math.pi * t / 2.3 + ph[1])
    s_needed = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) / rate_hz)])

    def free(p: NDArray[np.float64]) -> bool:
        for b in scene.obstacles:
            blo, bhi = np.array(b.lo), np.array(b.hi)
            if np.all(p[:2] > blo[:2] - 0.35) and np.all(p[:2] < bhi[:2] + 0.35) and p[2] < bhi[2] + 0.3:
                return False
        return True

    pts = [lo + rng.random(3) * (hi - lo)]
    length = 0.0
    while length < s_needed[-1] * 1.3 + 1.0 or len(pts) < 4:
        for _ in range(100):
            cand = lo + rng.random(3) * (hi - lo)
            step = np.linalg.norm(cand[:2] - pts[-1][:2])
            if 0.5 < step < 1.5 and free(cand):
                break
        length += float(np.linalg.norm(cand - pts[-1]))
        pts.append(cand)
    P = np.array(pts)
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    path = PchipInterpolator(chord, P, axis=0)
    fine = np.linspace(0.0, chord[-1], 20000)
    fp = path(fine)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(fp, axis=0), axis=1))])
    pos = path(np.interp(s_needed, arc, fine))
    # look targets
    n_targets = int(duration / 1.8) + 3
    targets = []
    for _ in range(n_targets):
        pool = sunlit_points if (sunlit_points is not None and len(sunlit_points) and rng.random() < 0.4) \
            else surface_points
        if pool is None or not len(pool):
            targets.append(np.array([rng.uniform(0, W), rng.uniform(0, D), rng.uniform(0.3, 2.2)]))
        else:
            targets.append(pool[rng.integers(len(pool))])
    tt = np.sort(np.concatenate([[0.0, duration], rng.uniform(0.0, duration, n_targets - 2)]))
    target = PchipInterpolator(tt, np.array(targets), axis=0)(t)
    fwd = target - pos
    horiz = np.linalg.norm(fwd[:, :2], axis=1)
    too_close = horiz < 0.3  # look somewhere else than straight down
    fwd[too_close, :2] += 0.3
    pitch = np.arctan2(fwd[:, 2], np.linalg.norm(fwd[:, :2], axis=1))
    pitch = np.clip(pitch, math.radians(-55), math.radians(25))
    yaw = np.unwrap(np.arctan2(fwd[:, 1], fwd[:, 0]))
    # smooth the viewing angles (~0.25 s) like a hand following the gaze
    k = max(1, int(0.25 * rate_hz))
    kern = np.hanning(2 * k + 1)
    kern /= kern.sum()

    def smooth(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.convolve(np.pad(x, k, mode="edge"), kern, mode="valid")

    yaw = _rate_limited(yaw, math.radians(MAX_YAW_RATE_DEG_S) / rate_hz)
    pitch = _rate_limited(pitch, math.radians(MAX_PITCH_RATE_DEG_S) / rate_hz)
    yaw, pitch = smooth(yaw), smooth(pitch)
    roll = math.radians(4.0) * np.sin(2 * math.pi * t / 7.0 + ph[2]) * np.sin(2 * math.pi * t / 3.1 + ph[3])
    # hand jitter: sums of sinusoids at 2–9 Hz
    freqs = rng.uniform(2.0, 9.0, (6, 6))
    phases = rng.uniform(0, 2 * math.pi, (6, 6))
    jit = np.stack([np.sum(np.sin(2 * math.pi * freqs[j][:, None] * t + phases[j][:, None]), axis=0)
                    for j in range(6)], axis=1) / math.sqrt(3.0)  # unit rms per axis
    yaw = yaw + math.radians(0.17) * jit[:, 0]
    pitch = pitch + math.radians(0.17) * jit[:, 1]
    roll = roll + math.radians(0.17) * jit[:, 2]
    pos = pos + 0.0015 * jit[:, 3:6]
    f = np.stack([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)], axis=1)
    return np.stack([_look_at(pos[i], f[i], roll[i]) for i in range(n_frames)])


# ----------------------------------------------------------------------------------------------------------------
# files


def depth_camera_poses(poses: NDArray[np.float64], rate_hz: float, sensor: DepthSensor) -> NDArray[np.float64]:
    """``T_map_depth`` per frame: the camera pose ``sensor.time_offset_s`` before each colour image (geodesic
    interpolation between frames, extrapolated before the first) times the registration error."""
    w = sensor.time_offset_s * rate_hz
    if len(poses) < 2 or w == 0.0:
        return poses @ sensor.registration()
    prev = np.concatenate([poses[1:2], poses[:-1]])  # frame 0 extrapolates away from frame 1
    out = np.empty_like(poses)
    for i in range(len(poses)):
        out[i] = poses[i] @ se3_exp((-w if i == 0 else w) * se3_log(inverse(poses[i]) @ prev[i]))
    return out @ sensor.registration()


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
    lit = inside & (cache.sun_direct > 0.3)
    sunlit = pos[lit][rng_sel.choice(int(lit.sum()), size=min(2000, int(lit.sum())), replace=False)] \
        if lit.any() else None
    poses = hand_held_trajectory(scene, frames, rate_hz, np.random.default_rng([spec.seed, 3]),
                                 sunlit_points=sunlit, surface_points=surface)
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
    sequences: Sequence[str] | None = None,
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
    """Render the daylight sequences (default all 12 of :data:`SEQUENCES`) into ``out_dir``; returns the sequence
    directories. Complete sequences with the same parameters are skipped (``force`` re-renders them).

    ``resolution_m`` is the scene mesh resolution (default 2 cm); ``cache_settings`` overrides the per-scene
    :data:`DEFAULT_CACHE`; ``site`` overrides Freiburg. Small values (e.g. ``frames=3, width=64, height=48,
    resolution_m=0.15``) give tiny test recordings.
    """
    names = list(sequences) if sequences else [s.name for s in SEQUENCES]
    unknown = [n for n in names if n not in _BY_NAME]
    if unknown:
        raise ValueError(f"unknown sequence(s) {unknown}; choose from {[s.name for s in SEQUENCES]}")
    if frames < 1 or width < 8 or height < 8:
        raise ValueError(f"need frames >= 1 and an image of at least 8x8, got {frames} frames {width}x{height}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    camera = camera_for_size(width, height)
    results: list[Path] = []
    scenes: dict[str, tuple[DaylightScene, dict[str, Path]]] = {}
    renderers: dict[str, GroundTruthRenderer] = {}
    skipped_scenes: dict[str, float] = {}  # scenes of complete recordings: their files are still brought up to date
    for name in names:
        spec = _BY_NAME[name]
        res = resolution_m if resolution_m is not None else 0.02
        cfg = cache_settings or DEFAULT_CACHE[spec.scene]
        cfg = replace(cfg, seed=spec.seed)
        params = {
            "format_version": FORMAT_VERSION, "spec": asdict(spec), "frames": frames, "width": width,
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
