"""Lighting of the simulated rACR scenes (paper §5.1: indoor a movable LED on the arm, reference under front light,
relocalization under side light, Fig. 7's clock positions; outdoor the sun days later or at another time of day,
S14–S15 day–night): :class:`LightingSpec` (what scene.yaml holds) → :class:`Lighting` (physical light).

Each scene has three variants: ``reference`` (the reference observation), ``similar`` (a small change) and
``varied`` (a large one). Indoor: a point light at "clock" position ``clock_h`` around the reference camera's
axis (12 = above, 3 = right as seen by the camera), tilted ``tilt_deg`` off that axis at ``distance_m`` from the
subject (:func:`clock_position`, world frame, metres): reference 12 o'clock at 30–40° (front light), similar 11 or
1 o'clock, varied a side light at 2, 3, 9 or 10 o'clock at 65–78° (grazing, long shadows). Irradiance
``I cos θ / r²`` (``I`` in W/sr per unit luminance colour) with a shadow ray, plus a uniform room radiance of
``ambient_frac`` of the front irradiance. Outdoor: the sun from the NREL SPA
(:func:`lightfast.daylight.sun.sun_position`) at the scene's site and local time (``time_local``, ISO), clear-sky
DNI/DHI (W/m²) from pvlib with the sun's colour (:mod:`lightfast.sim.sky_model`), ``sun_transmittance`` < 1 for
haze/cloud (dims the sun, adds an overcast component); similar = the same time of day a few days later with a
slightly different transmittance, varied = another time of day (the sun on the other side) or night with a
floodlight. :class:`Lighting` holds linear RGB: the point light's intensity, the sun's direction (world, towards
the sun) and irradiance, the sky state, the room radiance and a crude one-bounce radiance.
"""
from __future__ import annotations

import dataclasses
import datetime as dt
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lightfast.daylight.sun import Site, sun_position
from lightfast.sim.errors import RacrSimError
from lightfast.sim.racr.builder import unit
from lightfast.sim.sky_model import CLEAR_SKY_RGB, LUMA, OVERCAST_SKY_RGB, SkyState, clear_sky_irradiance, sun_rgb

__all__ = ["Lighting", "LightingSpec", "clock_position", "resolve_lighting"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class LightingSpec:
    """One lighting condition (see the module docstring). ``kind`` is ``"point"`` (a point light, optionally
    placed by ``clock_h``/``tilt_deg``/``distance_m`` around the reference view) or ``"daylight"`` (sun + sky at
    ``time_local``, ISO local time at the scene's site). ``exposure`` is the camera's normalized exposure per unit
    radiance for a session under this light (None: set by auto-exposure at scene generation)."""

    name: str
    kind: str
    description: str = ""
    clock_h: float | None = None
    tilt_deg: float | None = None
    distance_m: float | None = None
    position_m: tuple[float, float, float] | None = None
    intensity_w_sr: float = 1.0
    color_rgb: tuple[float, float, float] = (1.0, 0.95, 0.88)
    ambient_frac: float = 0.06
    time_local: str | None = None
    sun_transmittance: float = 1.0
    sun_azimuth_deg: float | None = None
    sun_elevation_deg: float | None = None
    exposure: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> LightingSpec:
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise RacrSimError(f"unknown lighting key(s): {sorted(unknown)}")
        kw: dict[str, Any] = {k: (tuple(float(x) for x in v) if isinstance(v, list) else v) for k, v in d.items()}
        return cls(**kw)


@dataclass(frozen=True, eq=False)
class Lighting:
    """A resolved lighting condition: everything the renderer needs, in physical units (linear RGB)."""

    spec: LightingSpec
    point_position_m: F64 | None
    point_intensity_rgb: F64
    sun_direction: F64 | None
    sun_irradiance_rgb: F64
    sky: SkyState | None
    ambient_rgb: F64
    bounce_rgb: F64

    def environment(self, directions: F64) -> F64:
        """Radiance ``(N, 3)`` seen along unit directions that leave the scene."""
        out = np.broadcast_to(self.ambient_rgb, (len(directions), 3)).copy()
        if self.sky is not None:
            out += self.sky.radiance(directions)
        return out


def resolve_lighting(spec: LightingSpec, site: Site | None) -> Lighting:
    """Physical light of ``spec`` (the sun position from the NREL SPA for daylight)."""
    if spec.kind == "point":
        if spec.position_m is None:
            raise RacrSimError(f"lighting {spec.name!r}: a point light needs a position")
        col = np.asarray(spec.color_rgb, float)
        col = col / float(LUMA @ col)
        intensity = spec.intensity_w_sr * col
        d = spec.distance_m or 1.0
        amb = spec.ambient_frac * intensity / (d * d) / math.pi
        return Lighting(spec, np.asarray(spec.position_m, float), intensity, None, np.zeros(3), None, amb, 0.5 * amb)
    if spec.kind == "daylight":
        if site is None or spec.time_local is None:
            raise RacrSimError(f"lighting {spec.name!r}: daylight needs a site and a local time")
        when = dt.datetime.fromisoformat(spec.time_local).replace(tzinfo=site.zone)
        pos = sun_position(site, when)
        el = float(pos.elevation_deg)
        sdir = np.asarray(pos.direction_map, float)
        cs = clear_sky_irradiance(el, altitude_m=site.altitude_m)
        a = float(spec.sun_transmittance)
        dni = cs.dni_wm2 * a * sun_rgb(el) if el > 0 else np.zeros(3)
        clear = cs.dhi_wm2 * (1.0 - 0.2 * (1.0 - a)) * np.asarray(CLEAR_SKY_RGB)
        over = 0.3 * (1.0 - a) * cs.dni_wm2 * max(math.sin(math.radians(el)), 0.0) * np.asarray(OVERCAST_SKY_RGB)
        sky = SkyState(tuple(sdir), tuple(dni), tuple(clear), tuple(over))
        night = np.full(3, 1e-3)
        bounce = 0.5 * 0.3 * sky.ghi_rgb / math.pi + night
        return Lighting(spec, None, np.zeros(3), sdir, dni, sky, night, bounce)
    raise RacrSimError(f"lighting {spec.name!r}: unknown kind {spec.kind!r} (point or daylight)")


def clock_position(target: F64, T_world_cam: F64, clock_h: float, tilt_deg: float, distance_m: float) -> F64:
    """Point-light position at ``clock_h`` (12 = above, 3 = right, as the camera sees it), ``tilt_deg`` off the
    axis from the target to the camera."""
    a = unit(T_world_cam[:3, 3] - target)
    up = -T_world_cam[:3, 1]
    up = unit(up - np.dot(up, a) * a)
    right = np.cross(up, a)
    right = -right if np.dot(right, T_world_cam[:3, 0]) < 0 else right
    phi = math.radians(30.0 * clock_h)
    t = math.radians(tilt_deg)
    d = math.cos(t) * a + math.sin(t) * (math.cos(phi) * up + math.sin(phi) * right)
    return target + distance_m * d
