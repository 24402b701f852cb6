"""Hand-held camera trajectories through the daylight test room, and the depth camera's poses along them.

:func:`hand_held_trajectory` returns ``T_map_camera`` per frame ((N, 4, 4), colour camera optical frame: x right,
y down, z forward; map frame, metres): a smooth walk at 0.2–0.5 m/s through the free middle of the room (PCHIP
through random waypoints clear of the scene's furniture boxes, ≥ 0.8 m from the walls) at 1.15–1.75 m above the
floor, looking at a sequence of targets (random surface points, by default 40 % of them sunlit), with the gaze's
yaw and pitch rates limited (:data:`MAX_YAW_RATE_DEG_S`, :data:`MAX_PITCH_RATE_DEG_S`), smooth roll (±4°) and
2–9 Hz hand jitter. Like the recordings of Krawez et al. (RA-L 2021) §IV-A, Fig. 6, made with a hand-held Asus Xtion.

:func:`depth_camera_poses` gives ``T_map_depth`` per frame: the pose ``time_offset_s`` before each colour image
times the depth sensor's registration error (:class:`~lightfast.sim.daylight.sensors.DepthSensor`).
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import PchipInterpolator

from lightfast.geometry import inverse, look_at, se3_exp, se3_log
from lightfast.sim.daylight.scene import DaylightScene
from lightfast.sim.daylight.sensors import DepthSensor

__all__ = [
    "MAX_PITCH_RATE_DEG_S",
    "MAX_YAW_RATE_DEG_S",
    "depth_camera_poses",
    "hand_held_trajectory",
]

#: Limits of the gaze's angular rates (before the hand jitter), like a person panning a hand-held camera.
MAX_YAW_RATE_DEG_S = 75.0
MAX_PITCH_RATE_DEG_S = 45.0


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
                         wall_margin_m: float = 0.8, sunlit_share: float = 0.4) -> NDArray[np.float64]:
    """Camera poses ``(n_frames, 4, 4)`` (T_map_camera, optical frame): a smooth walk at 0.2–0.5 m/s through the
    free middle of the room (PCHIP through random waypoints, so it never overshoots them) at 1.15–1.75 m, looking at
    a sequence of targets (random surface points, a share ``sunlit_share`` of them sunlit), with smooth roll (±4°)
    and 2–9 Hz hand jitter (≈ 0.3° and ≈ 1.5 mm rms). The gaze follows the targets with its yaw and pitch rates
    limited to :data:`MAX_YAW_RATE_DEG_S` and :data:`MAX_PITCH_RATE_DEG_S` (a target passing close by would
    otherwise whip the camera round at hundreds of degrees per second)."""
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
        pool = sunlit_points if (sunlit_points is not None and len(sunlit_points) and rng.random() < sunlit_share) \
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
    return np.stack([look_at(pos[i], pos[i] + f[i], roll_rad=roll[i]) for i in range(n_frames)])


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
