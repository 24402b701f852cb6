"""Sun position for the sun light set L_sun of the outdoor illumination model (Krawez et al., §III-A).

The paper computes L_sun "analytically from the current date and time of the day and the geographic location of
the scene". This module does that with the NREL Solar Position Algorithm (Reda & Andreas 2004, as implemented by
``pvlib.spa``), which is accurate to about 0.0003° for the years -2000..6000.

Frames and angles
-----------------
* **Azimuth** is a compass bearing: degrees clockwise from geographic north, in [0, 360).
* **Elevation** is the *apparent* (topocentric, refraction-corrected) elevation of the centre of the solar disk,
  using the site's pressure and temperature; **zenith** is ``90 - elevation``. Refraction is applied only while
  the geometric elevation is above ``-(0.26667 + 0.5667)``° (SPA convention), so night-time values are geometric.
* **ENU** is x east, y north, z up; the unit vector from the scene *to* the sun is
  ``(sin az cos el, cos az cos el, sin el)``.
* The **map frame** shares z (up) with ENU; its +y axis points at the compass bearing ``Site.heading_deg``
  (0: the map frame is ENU). Directions rotate with :func:`enu_to_map`:
  ``d_map = (sin(az - h) cos el, cos(az - h) cos el, sin el)``.

Times
-----
:func:`sun_position` accepts timezone-aware ``datetime`` objects, pandas ``Timestamp``/``DatetimeIndex`` (aware),
NumPy ``datetime64`` scalars or arrays (taken as UTC, NumPy has no time zones), integer nanoseconds since the UNIX
epoch (UTC, scalars or integer arrays) and sequences of any of these. Naive datetimes are refused: a wrong time
zone silently moves the sun by 15° per hour.
"""
from __future__ import annotations

import dataclasses
import datetime as dt
import math
import os
import zoneinfo
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeAlias

import numpy as np
import pandas as pd
import yaml
from numpy.typing import ArrayLike, NDArray

from lightfast.config import Config, ConfigError, field_specs, param
from lightfast.daylight.errors import SiteError, SunPositionError
from lightfast.io import write_text_atomic

__all__ = [
    "FREIBURG",
    "Site",
    "SunPosition",
    "TimeLike",
    "enu_to_map",
    "sun_position",
]

#: What :func:`sun_position` accepts as time (see the module docstring).
TimeLike: TypeAlias = dt.datetime | pd.Timestamp | pd.DatetimeIndex | np.datetime64 | NDArray[Any] | int | Sequence[Any]

#: SPA's approximate atmospheric refraction at sunrise/sunset (degrees); only decides when refraction applies.
ATMOS_REFRACT_DEG = 0.5667

_EPOCH = dt.datetime(1970, 1, 1, tzinfo=dt.UTC)


@dataclass(frozen=True)
class Site(Config):
    """Where the scene is on Earth and how its map frame is oriented.

    ``latitude_deg`` and ``longitude_deg`` have no default: a forgotten location would silently give a wrong sun.
    Invalid values raise :class:`SiteError`.
    """

    latitude_deg: float = param(
        dataclasses.MISSING, description="Geodetic latitude, degrees north.", min=-90.0, max=90.0
    )
    longitude_deg: float = param(
        dataclasses.MISSING, description="Longitude, degrees east of Greenwich.", min=-180.0, max=180.0
    )
    altitude_m: float = param(0.0, description="Height above mean sea level, metres.", min=-1000.0, max=10000.0)
    heading_deg: float = param(
        0.0,
        description="Compass bearing (degrees clockwise from north) of the map frame's +y axis; 0: map frame is ENU.",
        min=-360.0,
        max=360.0,
    )
    timezone: str = param("UTC", description="IANA time zone of the site, e.g. Europe/Berlin (for local times).")
    pressure_hpa: float = param(
        1013.25, description="Mean air pressure at the site, hPa (refraction correction).", min=0.0, max=1200.0
    )
    temperature_c: float = param(
        12.0, description="Mean air temperature at the site, degrees Celsius (refraction correction).", min=-100.0,
        max=100.0,
    )

    def __post_init__(self) -> None:
        try:
            super().__post_init__()
        except SiteError:
            raise
        except ConfigError as exc:
            raise SiteError(str(exc)) from None

    def check(self) -> None:
        try:
            zoneinfo.ZoneInfo(self.timezone)
        except (zoneinfo.ZoneInfoNotFoundError, ValueError, OSError):
            raise SiteError(f"Site.timezone={self.timezone!r} is not a known IANA time zone") from None

    @property
    def zone(self) -> zoneinfo.ZoneInfo:
        """The site's time zone, e.g. for ``datetime(2021, 6, 1, 12, tzinfo=site.zone)``."""
        return zoneinfo.ZoneInfo(self.timezone)

    @classmethod
    def from_yaml(cls, path: str | os.PathLike[str]) -> Site:
        """Load a plain YAML site file whose keys are the field names (``yaml.safe_load``).

        Raises :class:`SiteError` naming the file and the offending key for a missing file, invalid YAML, unknown
        or missing keys and bad values.
        """
        path = Path(path)
        try:
            data = yaml.safe_load(path.read_text())
        except FileNotFoundError:
            raise SiteError(f"no site file at {path}") from None
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            raise SiteError(f"{path}: cannot read site file: {exc}") from None
        if not isinstance(data, dict):
            raise SiteError(f"{path}: expected a mapping of Site fields, got {type(data).__name__}")
        specs = field_specs(cls)
        known = [s.name for s in specs]
        unknown = sorted(str(k) for k in data if k not in known)
        if unknown:
            raise SiteError(f"{path}: unknown site key(s): {', '.join(unknown)} (known: {', '.join(known)})")
        missing = [s.name for s in specs if s.default is dataclasses.MISSING and s.name not in data]
        if missing:
            raise SiteError(f"{path}: missing site key(s): {', '.join(missing)}")
        try:
            return cls(**data)
        except ConfigError as exc:
            raise SiteError(f"{path}: {exc}") from None

    def to_yaml(self, path: str | os.PathLike[str] | None = None) -> str:
        """The site as a commented plain YAML mapping (readable by :meth:`from_yaml`); written atomically to
        ``path`` when given. Returns the text."""
        lines = ["# lightfast site: location and map-frame heading for the sun position (paper §III-A)."]
        for spec in field_specs(self):
            value = yaml.safe_dump({spec.name: getattr(self, spec.name)}, default_flow_style=False, width=10_000)
            lines.append(f"# {spec.describe()}")
            lines.append(value.rstrip("\n"))
        text = "\n".join(lines) + "\n"
        if path is not None:
            write_text_atomic(path, text)
        return text


#: The site of the paper's experiments (Freiburg im Breisgau, Germany).
FREIBURG = Site(latitude_deg=48.0, longitude_deg=7.85, altitude_m=278.0, timezone="Europe/Berlin")


@dataclass(frozen=True, eq=False)
class SunPosition:
    """Where the sun is, seen from a :class:`Site`.

    For a scalar time every angle is a ``float``, ``above_horizon`` a ``bool`` and ``direction_map`` has shape
    (3,). For an array of times of shape ``S`` the angles and ``above_horizon`` are read-only arrays of shape ``S``
    and ``direction_map`` has shape ``S + (3,)``.
    """

    azimuth_deg: float | NDArray[np.float64]  # clockwise from north, [0, 360)
    elevation_deg: float | NDArray[np.float64]  # apparent (refraction-corrected), [-90, 90]
    zenith_deg: float | NDArray[np.float64]  # 90 - elevation_deg
    direction_map: NDArray[np.float64]  # (..., 3) unit vector from the scene to the sun, map frame
    above_horizon: bool | NDArray[np.bool_]  # elevation_deg > 0


def enu_to_map(site: Site) -> NDArray[np.float64]:
    """``R_map_enu`` (3, 3): rotates vectors from ENU (x east, y north, z up) into the site's map frame,
    ``d_map = R_map_enu @ d_enu``. It is a rotation about z by ``+heading_deg`` (counter-clockwise)."""
    h = math.radians(site.heading_deg)
    c, s = math.cos(h), math.sin(h)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _datetime_ns(value: dt.datetime) -> int:
    if value is pd.NaT:
        raise SunPositionError("sun_position: time is NaT")
    if isinstance(value, pd.Timestamp):
        if value.tz is None:
            raise SunPositionError(
                f"sun_position: naive pandas Timestamp {value}; localize it (e.g. ts.tz_localize(site.zone)) first"
            )
        return int(value.as_unit("ns").value)
    if value.tzinfo is None or value.utcoffset() is None:
        raise SunPositionError(
            f"sun_position: naive datetime {value.isoformat()}; pass tzinfo (e.g. tzinfo=site.zone or datetime.UTC)"
        )
    delta = value - _EPOCH
    return (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1_000


def _datetime64_ns(value: np.datetime64 | NDArray[Any]) -> NDArray[np.int64]:
    arr = np.asarray(value)
    if np.any(np.isnat(arr)):
        raise SunPositionError("sun_position: times contain NaT")
    return arr.astype("datetime64[ns]").astype(np.int64)


def _to_unix_ns(when: Any) -> tuple[NDArray[np.int64], bool]:
    """Times as int64 nanoseconds since the UNIX epoch (UTC), and whether the input was a scalar."""
    if isinstance(when, pd.Series):
        when = pd.DatetimeIndex(when)
    if isinstance(when, pd.DatetimeIndex):
        if when.tz is None:
            raise SunPositionError(
                "sun_position: naive DatetimeIndex; localize it (index.tz_localize(site.zone)) first"
            )
        if when.hasnans:
            raise SunPositionError("sun_position: times contain NaT")
        return np.asarray(when.as_unit("ns").asi8, dtype=np.int64), False
    if isinstance(when, dt.datetime):  # includes pd.Timestamp
        return np.array(_datetime_ns(when), dtype=np.int64), True
    if isinstance(when, np.datetime64):
        return _datetime64_ns(when), True
    if isinstance(when, (bool, np.bool_)):
        raise TypeError("sun_position: a bool is not a time")
    if isinstance(when, (int, np.integer)):
        return np.array(int(when), dtype=np.int64), True
    if isinstance(when, np.ndarray):
        if np.issubdtype(when.dtype, np.datetime64):
            return _datetime64_ns(when), False
        if np.issubdtype(when.dtype, np.integer):
            return when.astype(np.int64), False
        if when.dtype == object:
            return _to_unix_ns(list(when.ravel()))[0].reshape(when.shape), False
        raise TypeError(f"sun_position: cannot read times from an array of dtype {when.dtype}")
    if isinstance(when, Sequence) and not isinstance(when, (str, bytes)):
        out = np.empty(len(when), dtype=np.int64)
        for i, item in enumerate(when):
            ns, scalar = _to_unix_ns(item)
            if not scalar:
                raise TypeError("sun_position: a sequence of times must hold scalar times")
            out[i] = ns
        return out, False
    raise TypeError(
        f"sun_position: unsupported time type {type(when).__name__}; use an aware datetime, pandas Timestamp or "
        "DatetimeIndex, numpy datetime64 (UTC) or int nanoseconds since the UNIX epoch"
    )


def _default_delta_t(ns: NDArray[np.int64]) -> NDArray[np.float64]:
    """pvlib's polynomial estimate of TT - UT1 (seconds) for the UTC year and month of each time."""
    from pvlib import spa  # imports all of pvlib (~1 s): only when a sun position is asked for
    t = ns.astype("datetime64[ns]")
    months = t.astype("datetime64[M]").astype(np.int64)
    year = months // 12 + 1970
    month = months % 12 + 1
    return np.asarray(spa.calculate_deltat(year, month), dtype=np.float64)


def sun_position(site: Site, when: TimeLike, *, delta_t_s: float | ArrayLike | None = None) -> SunPosition:
    """The apparent sun position at ``site`` for the time(s) ``when`` (NREL SPA via ``pvlib.spa``).

    ``when`` is any time described in the module docstring; naive datetimes raise :class:`SunPositionError` (a
    ``ValueError``), unsupported types ``TypeError``. ``delta_t_s`` is TT - UT1 in seconds (scalar or
    broadcastable to the times); ``None`` uses pvlib's polynomial estimate for the year (off by a few seconds,
    which moves the sun by < 0.0001°).
    The site's pressure and temperature drive the refraction correction. The sun below the horizon is not an
    error: ``above_horizon`` is then False.
    """
    ns, scalar = _to_unix_ns(when)
    shape = ns.shape
    flat = ns.ravel()
    if delta_t_s is None:
        delta_t = _default_delta_t(flat)
    else:
        delta_t = np.broadcast_to(np.asarray(delta_t_s, dtype=np.float64), shape).ravel()
        if not np.all(np.isfinite(delta_t)):
            raise SunPositionError("sun_position: delta_t_s must be finite")
    if flat.size:
        # Split before converting so that float seconds keep sub-microsecond precision.
        from pvlib import spa

        unixtime = (flat // 1_000_000_000).astype(np.float64) + (flat % 1_000_000_000).astype(np.float64) * 1e-9
        result = spa.solar_position(
            unixtime,
            site.latitude_deg,
            site.longitude_deg,
            site.altitude_m,
            site.pressure_hpa,  # hPa == mbar, the unit of pvlib.spa
            site.temperature_c,
            delta_t,
            ATMOS_REFRACT_DEG,
        )
        elevation = np.asarray(result[2], dtype=np.float64)  # apparent topocentric elevation
        azimuth = np.asarray(result[4], dtype=np.float64) % 360.0
    else:
        elevation = azimuth = np.empty(0, dtype=np.float64)
    elevation = elevation.reshape(shape)
    azimuth = azimuth.reshape(shape)
    zenith = 90.0 - elevation
    el = np.radians(elevation)
    rel_az = np.radians(azimuth - site.heading_deg)
    direction = np.stack([np.sin(rel_az) * np.cos(el), np.cos(rel_az) * np.cos(el), np.sin(el)], axis=-1)
    above = elevation > 0.0
    if scalar:
        direction.setflags(write=False)
        return SunPosition(float(azimuth), float(elevation), float(zenith), direction, bool(above))
    for arr in (azimuth, elevation, zenith, direction, above):
        arr.setflags(write=False)
    return SunPosition(azimuth, elevation, zenith, direction, above)
