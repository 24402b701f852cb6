"""Sun position (paper §III-A): NREL SPA reference values, map-frame geometry, time inputs, site files."""
from __future__ import annotations

import datetime as dt
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pvlib
import pytest

from lightfast.config import ConfigError
from lightfast.daylight.errors import SiteError, SunPositionError
from lightfast.daylight.sun import FREIBURG, Site, enu_to_map, sun_position
from lightfast.errors import LightfastError

# Reda & Andreas (2004), NREL SPA, Table A4.1 example.
SPA_SITE = Site(latitude_deg=39.742476, longitude_deg=-105.1786, altitude_m=1830.14, pressure_hpa=820.0,
                temperature_c=11.0)
SPA_TIME = dt.datetime(2003, 10, 17, 12, 30, 30, tzinfo=dt.timezone(dt.timedelta(hours=-7)))
SPA_ZENITH_DEG = 50.11162  # topocentric zenith angle (refraction-corrected)
SPA_AZIMUTH_DEG = 194.34024  # topocentric azimuth, clockwise from north
SPA_DELTA_T_S = 67.0
SPA_NS = 1066419030 * 10**9  # 2003-10-17 19:30:30 UTC

EQUINOX_NOON_UTC = dt.datetime(2021, 3, 20, 11, 36, tzinfo=dt.UTC)  # solar noon at Freiburg; equinox 09:37 UTC


def test_spa_paper_example() -> None:
    sun = sun_position(SPA_SITE, SPA_TIME, delta_t_s=SPA_DELTA_T_S)
    assert abs(sun.zenith_deg - SPA_ZENITH_DEG) < 1e-4
    assert abs(sun.azimuth_deg - SPA_AZIMUTH_DEG) < 1e-4
    assert sun.elevation_deg == pytest.approx(90.0 - SPA_ZENITH_DEG, abs=1e-4)
    assert sun.above_horizon is True
    assert isinstance(sun.zenith_deg, float)
    el, az = math.radians(90.0 - SPA_ZENITH_DEG), math.radians(SPA_AZIMUTH_DEG)
    expected = [math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)]
    np.testing.assert_allclose(sun.direction_map, expected, atol=1e-6)


def test_spa_example_uses_site_pressure_and_temperature() -> None:
    # SPA's topocentric elevation without refraction is 39.872046° for this example; pressure 0 removes refraction.
    no_air = Site(**{**SPA_SITE.to_dict(), "pressure_hpa": 0.0})
    geometric = sun_position(no_air, SPA_TIME, delta_t_s=SPA_DELTA_T_S).elevation_deg
    assert geometric == pytest.approx(39.872046, abs=1e-5)
    sea_level = Site(**{**SPA_SITE.to_dict(), "pressure_hpa": 1013.25})
    dense = sun_position(sea_level, SPA_TIME, delta_t_s=SPA_DELTA_T_S).elevation_deg
    thin = sun_position(SPA_SITE, SPA_TIME, delta_t_s=SPA_DELTA_T_S).elevation_deg
    assert geometric < thin < dense
    assert (dense - geometric) / (thin - geometric) == pytest.approx(1013.25 / 820.0, rel=1e-6)


def test_default_delta_t_is_close() -> None:
    exact = sun_position(SPA_SITE, SPA_TIME, delta_t_s=SPA_DELTA_T_S)
    estimated = sun_position(SPA_SITE, SPA_TIME)
    assert abs(exact.azimuth_deg - estimated.azimuth_deg) < 1e-3
    assert abs(exact.elevation_deg - estimated.elevation_deg) < 1e-3


@pytest.mark.parametrize(
    "when",
    [
        SPA_TIME,
        SPA_TIME.astimezone(dt.UTC),
        pd.Timestamp("2003-10-17 12:30:30", tz="America/Denver"),  # MDT, UTC-6: 18:30:30 UTC
        np.datetime64("2003-10-17T19:30:30"),
        np.datetime64("2003-10-17T19:30:30.000000000"),
        SPA_NS,
        np.int64(SPA_NS),
    ],
    ids=["aware", "utc", "timestamp-denver", "datetime64-s", "datetime64-ns", "int-ns", "np-int64"],
)
def test_time_inputs_agree(when: object) -> None:
    sun = sun_position(SPA_SITE, when, delta_t_s=SPA_DELTA_T_S)
    shift_h = 1.0 if isinstance(when, pd.Timestamp) else 0.0  # the Denver timestamp is one hour earlier
    reference = sun_position(SPA_SITE, SPA_NS - int(shift_h * 3600e9), delta_t_s=SPA_DELTA_T_S)
    assert sun.azimuth_deg == reference.azimuth_deg
    assert sun.elevation_deg == reference.elevation_deg
    if shift_h == 0.0:
        assert abs(sun.zenith_deg - SPA_ZENITH_DEG) < 1e-4


def test_vectorized_matches_pvlib_get_solarposition() -> None:
    times = pd.date_range("2021-06-21 00:00", periods=48, freq="30min", tz="Europe/Berlin")
    sun = sun_position(FREIBURG, times, delta_t_s=69.0)
    ref = pvlib.solarposition.get_solarposition(
        times, FREIBURG.latitude_deg, FREIBURG.longitude_deg, altitude=FREIBURG.altitude_m,
        pressure=FREIBURG.pressure_hpa * 100.0, method="nrel_numpy", temperature=FREIBURG.temperature_c,
        delta_t=69.0,
    )
    assert sun.elevation_deg.shape == (48,) and sun.direction_map.shape == (48, 3)
    np.testing.assert_allclose(sun.elevation_deg, ref["apparent_elevation"].to_numpy(), atol=1e-9)
    np.testing.assert_allclose(sun.azimuth_deg, ref["azimuth"].to_numpy(), atol=1e-9)
    np.testing.assert_allclose(sun.zenith_deg, ref["apparent_zenith"].to_numpy(), atol=1e-9)
    np.testing.assert_array_equal(sun.above_horizon, ref["apparent_elevation"].to_numpy() > 0)
    assert 0 < sun.above_horizon.sum() < 48  # a day and a night
    np.testing.assert_allclose(np.linalg.norm(sun.direction_map, axis=-1), 1.0, atol=1e-12)


def test_array_shapes_and_read_only() -> None:
    base = np.datetime64("2021-03-20T11:36:00", "s")
    times = base + np.arange(6).reshape(2, 3) * np.timedelta64(4, "h")
    sun = sun_position(FREIBURG, times)
    assert sun.azimuth_deg.shape == sun.elevation_deg.shape == sun.above_horizon.shape == (2, 3)
    assert sun.direction_map.shape == (2, 3, 3)
    flat = sun_position(FREIBURG, times.ravel())
    np.testing.assert_array_equal(flat.elevation_deg.reshape(2, 3), sun.elevation_deg)
    with pytest.raises(ValueError, match="read-only"):
        sun.direction_map[0, 0, 0] = 1.0
    listed = sun_position(FREIBURG, [EQUINOX_NOON_UTC, pd.Timestamp(EQUINOX_NOON_UTC)])
    assert listed.elevation_deg.shape == (2,) and listed.elevation_deg[0] == listed.elevation_deg[1]
    empty = sun_position(FREIBURG, np.array([], dtype="datetime64[ns]"))
    assert empty.elevation_deg.shape == (0,) and empty.direction_map.shape == (0, 3)


def test_equinox_solar_noon_freiburg_hand_checked() -> None:
    # Equinox: declination ~0 so the noon sun stands 90 - 48 = 42° high, due south (plus ~0.02° refraction).
    sun = sun_position(FREIBURG, EQUINOX_NOON_UTC)
    assert sun.azimuth_deg == pytest.approx(180.0, abs=0.3)
    assert sun.elevation_deg == pytest.approx(42.0, abs=0.1)
    el = math.radians(sun.elevation_deg)
    np.testing.assert_allclose(sun.direction_map, [0.0, -math.cos(el), math.sin(el)], atol=6e-3)
    # Map +y points east (heading 90), so map +x points south: the sun lies along map +x.
    east_up = Site(**{**FREIBURG.to_dict(), "heading_deg": 90.0})
    turned = sun_position(east_up, EQUINOX_NOON_UTC)
    assert turned.elevation_deg == sun.elevation_deg and turned.azimuth_deg == sun.azimuth_deg
    np.testing.assert_allclose(turned.direction_map, [math.cos(el), 0.0, math.sin(el)], atol=6e-3)


def test_equator_equinox_noon_sun_near_zenith() -> None:
    times = pd.date_range("2021-03-20 11:50", "2021-03-20 12:20", freq="1min", tz="UTC")
    sun = sun_position(Site(latitude_deg=0.0, longitude_deg=0.0), times)
    assert 89.7 < sun.elevation_deg.max() < 90.0


def test_local_midnight_below_horizon() -> None:
    midnight = dt.datetime(2021, 3, 21, 0, 36, tzinfo=FREIBURG.zone)  # 23:36 UTC, opposite solar noon
    sun = sun_position(FREIBURG, midnight)
    assert sun.above_horizon is False
    assert sun.elevation_deg == pytest.approx(-42.0, abs=0.3)
    assert min(sun.azimuth_deg, 360.0 - sun.azimuth_deg) < 0.5  # due north
    assert sun.direction_map[2] < -0.6 and sun.direction_map[1] > 0.7


def test_enu_to_map() -> None:
    R = enu_to_map(Site(latitude_deg=0.0, longitude_deg=0.0, heading_deg=90.0))
    np.testing.assert_allclose(R @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)  # east is map +y
    np.testing.assert_allclose(R @ [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], atol=1e-15)  # north is map -x
    np.testing.assert_array_equal(enu_to_map(FREIBURG), np.eye(3))
    site = Site(**{**FREIBURG.to_dict(), "heading_deg": 37.0})
    R = enu_to_map(site)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0)
    times = pd.date_range("2021-07-01 04:00", periods=10, freq="90min", tz="UTC")
    enu = sun_position(FREIBURG, times).direction_map
    np.testing.assert_allclose(sun_position(site, times).direction_map, enu @ R.T, atol=1e-12)


@pytest.mark.parametrize(
    "when",
    [
        dt.datetime(2021, 3, 20, 12, 0),
        pd.Timestamp("2021-03-20 12:00"),
        pd.date_range("2021-03-20", periods=3, freq="h"),
        [dt.datetime(2021, 3, 20, 12, 0)],
    ],
    ids=["datetime", "timestamp", "index", "list"],
)
def test_naive_times_refused(when: object) -> None:
    with pytest.raises(SunPositionError, match="naive"):
        sun_position(FREIBURG, when)


def test_bad_times() -> None:
    with pytest.raises(TypeError, match="unsupported time type"):
        sun_position(FREIBURG, 1.5e18)
    with pytest.raises(TypeError):
        sun_position(FREIBURG, True)
    with pytest.raises(SunPositionError, match="NaT"):
        sun_position(FREIBURG, np.array(["2021-01-01", "NaT"], dtype="datetime64[ns]"))
    with pytest.raises(SunPositionError, match="NaT"):
        sun_position(FREIBURG, pd.NaT)


def test_site_validation() -> None:
    assert FREIBURG.latitude_deg == 48.0 and FREIBURG.longitude_deg == 7.85 and FREIBURG.altitude_m == 278.0
    assert FREIBURG.timezone == "Europe/Berlin" and FREIBURG.heading_deg == 0.0
    assert FREIBURG.pressure_hpa == 1013.25 and FREIBURG.temperature_c == 12.0
    with pytest.raises(SiteError, match=r"latitude_deg=91.0 is above its maximum"):
        Site(latitude_deg=91.0, longitude_deg=0.0)
    with pytest.raises(SiteError, match="Mars/Olympus"):
        Site(latitude_deg=0.0, longitude_deg=0.0, timezone="Mars/Olympus")
    with pytest.raises(SiteError, match="Europe"):
        Site(latitude_deg=0.0, longitude_deg=0.0, timezone="Europe")  # a tzdata directory, not a zone
    with pytest.raises(TypeError):
        Site(latitude_deg=0.0)  # type: ignore[call-arg]
    err = SiteError("x")
    assert isinstance(err, LightfastError) and isinstance(err, ValueError) and isinstance(err, ConfigError)


def test_site_yaml_round_trip(tmp_path: Path) -> None:
    site = Site(latitude_deg=-33.9, longitude_deg=151.2, altitude_m=3.5, heading_deg=-12.25,
                timezone="Australia/Sydney", pressure_hpa=1000.0, temperature_c=21.5)
    path = tmp_path / "sub" / "site.yaml"
    text = site.to_yaml(path)
    assert path.read_text() == text
    assert not [p for p in path.parent.iterdir() if p.name != "site.yaml"]  # no temporary left behind
    assert Site.from_yaml(path) == site
    assert Site.from_yaml(_write(tmp_path, "latitude_deg: 48\nlongitude_deg: 7.85\n")).latitude_deg == 48.0


def _write(tmp_path: Path, text: str, name: str = "site.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("latitude_deg: 48\nlongitude_deg: 7\nlatitude: 3\n", "unknown site key.*latitude"),
        ("latitude_deg: 148\nlongitude_deg: 7\n", "latitude_deg=148.0 is above"),
        ("latitude_deg: 48\nlongitude_deg: east\n", "longitude_deg must be float"),
        ("latitude_deg: 48\n", "missing site key.*longitude_deg"),
        ("latitude_deg: 48\nlongitude_deg: 7\ntimezone: Nowhere\n", "timezone='Nowhere'"),
        ("- 1\n- 2\n", "expected a mapping"),
        ("latitude_deg: [\n", "cannot read"),
    ],
)
def test_site_yaml_errors_name_file_and_key(tmp_path: Path, text: str, match: str) -> None:
    path = _write(tmp_path, text, "bad_site.yaml")
    with pytest.raises(SiteError, match=match) as info:
        Site.from_yaml(path)
    assert "bad_site.yaml" in str(info.value)


def test_site_yaml_missing_file(tmp_path: Path) -> None:
    with pytest.raises(SiteError, match="no site file"):
        Site.from_yaml(tmp_path / "absent.yaml")
