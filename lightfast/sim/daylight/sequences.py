"""The simulated daylight recording set DS1.T1–T6, DS2.T1–T6 (Krawez et al., RA-L 2021, §IV-A, Fig. 6) and its light.

Site Freiburg (48.0° N 7.85° E), map frame ENU, window facing south; local start times, sun approximate:

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

The held-out recordings DS3.H1–H5, DS2.H1–H3 (:data:`HELDOUT_SEQUENCES`, issue 21) are never used in development.

Light per frame (:func:`sky_states` → :class:`~lightfast.sim.sky_model.SkyState`, W m⁻², linear RGB): clear-sky
DNI/DHI (pvlib simplified Solis) for the true sun position; in T6 a smooth random cloud transmittance
``a(t) ∈ [0.02, 1]`` (:func:`cloud_transmittance`, clouds passing over seconds) scales the sun's DNI, dims the clear
sky by ``1 - 0.2 (1 - a)`` and adds a CIE overcast component with DHI ``0.3 (1 - a) DNI_clear sin(elevation)``, so
the sky gets brighter while the sun is covered. :func:`camera_for_size` gives the Xtion-like colour camera.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import PchipInterpolator

from lightfast.camera import PinholeCamera
from lightfast.daylight.sun import Site, sun_position
from lightfast.sim.daylight.irradiance_cache import CacheSettings, frame_scales
from lightfast.sim.sky_model import (
    CLEAR_SKY_RGB,
    OVERCAST_SKY_RGB,
    SkyState,
    clear_sky_irradiance,
    float3,
    luminance,
    sun_rgb,
)

__all__ = [
    "DEFAULT_CACHE",
    "HELDOUT_ROUNDS",
    "HELDOUT_SEQUENCES",
    "SEQUENCES",
    "SequenceSpec",
    "camera_for_size",
    "cloud_transmittance",
    "sky_states",
]

@dataclass(frozen=True)
class SequenceSpec:
    """One recording: scene, local start time (ISO, in the site's time zone), clouds or clear, seed, the share of
    the hand-held camera's gaze targets that lie in the sun (the rest: any visible surface) and whether sun patches
    on the floor may be gaze targets (by default only surfaces 5 cm – 2.3 m above the floor are)."""

    name: str
    scene: str
    start_local: str
    clouds: bool
    seed: int
    description: str
    sunlit_gaze_share: float = 0.4
    floor_in_gaze: bool = False

    def __post_init__(self) -> None:
        if not 0.0 <= self.sunlit_gaze_share <= 1.0:
            raise ValueError(f"{self.name}: sunlit_gaze_share must lie in [0, 1], got {self.sunlit_gaze_share}")


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

#: The held-out recordings of issue 21 (point 5), each round written down in benchmarks/results/HELDOUT.md before it
#: was rendered: seeds drawn for them, the room DS3 never used in development, times of year not used in development,
#: and a gaze that dwells on sun patches (80 % of its targets sunlit, against 40 % in DS*.T*; round 2: also on the
#: floor). Round 1 is retired (its results were read). Never tune on them.
HELDOUT_ROUNDS: dict[int, tuple[SequenceSpec, ...]] = {
    1: (
        SequenceSpec("DS3.H1", "DS3", "2021-12-08T09:45:00", False, 93354, "winter morning, low sun, clear", 0.8),
        SequenceSpec("DS3.H2", "DS3", "2021-03-17T12:30:00", True, 13051, "equinox noon, moving clouds", 0.8),
        SequenceSpec("DS3.H3", "DS3", "2021-10-05T15:40:00", False, 15860, "autumn afternoon, clear", 0.8),
        SequenceSpec("DS2.H1", "DS2", "2021-11-10T11:30:00", False, 84634, "late autumn late morning, clear", 0.8),
    ),
    2: (
        SequenceSpec("DS3.H4", "DS3", "2021-01-28T10:30:00", False, 708, "winter morning, clear", 0.8, True),
        SequenceSpec("DS3.H5", "DS3", "2021-11-24T13:30:00", False, 2647, "late autumn early afternoon, clear", 0.8,
                     True),
        SequenceSpec("DS2.H2", "DS2", "2021-02-16T11:15:00", False, 14969, "winter late morning, clear", 0.8, True),
        SequenceSpec("DS2.H3", "DS2", "2021-12-15T14:00:00", False, 16503, "winter afternoon, low sun, clear", 0.8,
                     True),
    ),
}
#: Every held-out recording, the rounds in order (the last round is the current held-out set).
HELDOUT_SEQUENCES: tuple[SequenceSpec, ...] = tuple(s for specs in HELDOUT_ROUNDS.values() for s in specs)

#: Default irradiance-cache sample counts per scene (DS2 has fewer vertices and no texture to hide noise).
DEFAULT_CACHE = {
    "DS1": CacheSettings(hemisphere_samples=32, window_samples=16, sunlit_samples=16),
    "DS2": CacheSettings(hemisphere_samples=64, window_samples=32, sunlit_samples=32, filter_radius_m=0.12),
    "DS3": CacheSettings(hemisphere_samples=64, window_samples=32, sunlit_samples=32, filter_radius_m=0.12),
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

