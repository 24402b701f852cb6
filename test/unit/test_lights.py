"""Light sets of the outdoor illumination model (paper §III-A): sky/ground sphere split and the area sun."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lightfast.daylight.errors import LightsError
from lightfast.daylight.lights import SUN_ANGULAR_DIAMETER_DEG, LightSet, fibonacci_sphere, sky_and_ground, sun_disk

SUN_RADIUS_DEG = SUN_ANGULAR_DIAMETER_DEG / 2.0


def _unit(v: object) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    return a / np.linalg.norm(a)


def _angles_deg(directions: np.ndarray, centre: np.ndarray) -> np.ndarray:
    # atan2 of |cross| and dot stays accurate for the tiny angles of the solar disk.
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(directions, centre), axis=-1), directions @ centre))


def test_fibonacci_sphere_uniform_and_deterministic() -> None:
    d = fibonacci_sphere(1000)
    assert d.shape == (1000, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(d.mean(axis=0), 0.0, atol=2e-3)
    # Uniform on the sphere: E[x^2] = E[y^2] = E[z^2] = 1/3.
    np.testing.assert_allclose((d**2).mean(axis=0), 1.0 / 3.0, atol=2e-3)
    np.testing.assert_array_equal(fibonacci_sphere(1000), d)
    np.testing.assert_allclose(fibonacci_sphere(1), [[1.0, 0.0, 0.0]], atol=1e-15)
    for bad in (0, -3, 2.5, True):
        with pytest.raises(LightsError):
            fibonacci_sphere(bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("n_total", [2, 101, 2000, 2001, 5000])
def test_sky_and_ground_weights_sum_to_four_pi(n_total: int) -> None:
    sky, ground = sky_and_ground(n_total)
    assert len(sky) + len(ground) == n_total
    assert sky.total_weight + ground.total_weight == pytest.approx(4.0 * math.pi, rel=1e-12)
    np.testing.assert_allclose(sky.weights, 4.0 * math.pi / n_total)
    assert np.all(sky.directions[:, 2] > 0.0) and np.all(ground.directions[:, 2] <= 0.0)
    assert (sky.name, ground.name) == ("sky", "ground")
    assert len(sky) == n_total // 2


@pytest.mark.parametrize("n_total", [2000, 2001, 5000])
@pytest.mark.parametrize("up", [(0.0, 0.0, 1.0), (1.0, 1.0, 1.0), (0.0, -1.0, 0.2)])
def test_open_floor_sky_irradiance_is_pi(n_total: int, up: tuple[float, float, float]) -> None:
    u = _unit(up)
    sky, ground = sky_and_ground(n_total, up=up)
    assert np.all(sky.directions @ u > 0.0)
    assert np.all(ground.directions @ u <= 1e-12)
    assert abs(sky.irradiance(u) / math.pi - 1.0) < 0.01
    assert ground.irradiance(u) < 1e-12  # only the horizon point of odd counts may graze it
    assert ground.irradiance(-u) == pytest.approx(math.pi, rel=0.01)
    # A wall (normal in the horizon plane) sees half the sky: ∫ over the quarter sphere of cos = π/2.
    wall = _unit(np.cross(u, [0.3, 0.5, 0.7]))
    assert sky.irradiance(wall) == pytest.approx(math.pi / 2.0, rel=0.02)
    assert ground.irradiance(wall) == pytest.approx(math.pi / 2.0, rel=0.02)


def test_sky_and_ground_deterministic_and_vectorized_irradiance() -> None:
    a_sky, a_grd = sky_and_ground(600, up=(0.2, 0.1, 1.0))
    b_sky, b_grd = sky_and_ground(600, up=(0.2, 0.1, 1.0))
    np.testing.assert_array_equal(a_sky.directions, b_sky.directions)
    np.testing.assert_array_equal(a_grd.directions, b_grd.directions)
    normals = fibonacci_sphere(50).reshape(5, 10, 3)
    e = a_sky.irradiance(normals)
    assert e.shape == (5, 10)
    assert e[2, 3] == pytest.approx(float(np.maximum(a_sky.directions @ normals[2, 3], 0.0) @ a_sky.weights))
    # sky + ground is the full sphere: every normal receives π.
    np.testing.assert_allclose(e + a_grd.irradiance(normals), math.pi, rtol=0.01)


@pytest.mark.parametrize("n_samples", [1, 2, 3, 7, 16, 64, 1001])
@pytest.mark.parametrize("centre", [(0.0, 0.6, 0.8), (0.0, 0.0, 1.0), (-0.9, 0.1, 0.05), (0.0, 0.0, -1.0)])
def test_sun_disk_within_radius_and_centred(n_samples: int, centre: tuple[float, float, float]) -> None:
    c = _unit(centre)
    sun = sun_disk(centre, n_samples)
    assert len(sun) == n_samples and sun.name == "sun"
    np.testing.assert_allclose(sun.weights, 1.0 / n_samples)
    assert sun.total_weight == pytest.approx(1.0)
    angles = _angles_deg(sun.directions, c)
    assert angles.max() <= SUN_RADIUS_DEG + 1e-9
    mean = sun.directions.mean(axis=0)
    assert _angles_deg(mean / np.linalg.norm(mean), c) < 1e-3
    if n_samples == 1:
        np.testing.assert_allclose(sun.directions[0], c, atol=1e-15)
    else:
        assert angles.max() > 0.5 * SUN_RADIUS_DEG


def test_sun_disk_is_uniform_over_the_disk() -> None:
    c = _unit((0.3, -0.4, 0.6))
    sun = sun_disk(c, 2000, angular_diameter_deg=2.0)
    angles = _angles_deg(sun.directions, c)
    # Uniform in area: half of the samples within R/sqrt(2), a quarter within R/2; E[r^2] = R^2/2.
    assert np.mean(angles < 1.0 / math.sqrt(2.0)) == pytest.approx(0.5, abs=0.01)
    assert np.mean(angles < 0.5) == pytest.approx(0.25, abs=0.01)
    assert np.mean(angles**2) == pytest.approx(0.5, rel=0.01)
    assert angles.max() > 0.99
    # Azimuthally uniform: the tangential offsets from the centre average out in every direction.
    offsets = sun.directions - np.outer(sun.directions @ c, c)
    assert np.linalg.norm(offsets.mean(axis=0)) < 1e-9


def test_sun_disk_irradiance_is_cosine_of_incidence() -> None:
    c = _unit((0.0, 0.5, 0.5))
    sun = sun_disk(c, 32)
    assert sun.irradiance(c) == pytest.approx(1.0, abs=1e-5)
    tilted = np.array([0.0, math.sin(math.radians(105.0)), math.cos(math.radians(105.0))])  # 60° from c
    assert sun.irradiance(tilted) == pytest.approx(0.5, abs=1e-5)
    assert sun.irradiance(-c) == 0.0


def test_sun_disk_below_horizon_and_determinism() -> None:
    below = sun_disk((0.0, 1.0, -0.1), 16, horizon_up=(0.0, 0.0, 1.0))
    assert len(below) == 0 and below.directions.shape == (0, 3) and below.weights.shape == (0,)
    assert below.total_weight == 0.0
    np.testing.assert_array_equal(below.irradiance(np.eye(3)), np.zeros(3))
    on_horizon = sun_disk((1.0, 0.0, 0.0), 4, horizon_up=(0.0, 0.0, 1.0))
    assert len(on_horizon) == 0
    assert len(sun_disk((0.0, 1.0, -0.1), 16)) == 16  # no horizon test unless asked
    a = sun_disk((0.1, 0.7, 0.7), 64, horizon_up=(0.0, 0.0, 1.0))
    b = sun_disk((0.1, 0.7, 0.7), 64, horizon_up=(0.0, 0.0, 1.0))
    np.testing.assert_array_equal(a.directions, b.directions)
    np.testing.assert_array_equal(a.directions, sun_disk((0.1, 0.7, 0.7), 64).directions)


def test_sun_disk_bad_input() -> None:
    with pytest.raises(LightsError):
        sun_disk((0.0, 0.0, 1.0), 0)
    with pytest.raises(LightsError):
        sun_disk((0.0, 0.0, 0.0), 4)
    with pytest.raises(LightsError):
        sun_disk((0.0, 0.0, 1.0), 4, angular_diameter_deg=-1.0)
    with pytest.raises(LightsError):
        sky_and_ground(1)


def test_light_set_validation() -> None:
    ok = LightSet(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), np.array([0.5, 0.5]), "test")
    with pytest.raises(ValueError, match="read-only"):
        ok.directions[0, 0] = 2.0
    with pytest.raises(ValueError, match="read-only"):
        ok.weights[0] = 2.0
    with pytest.raises(LightsError, match="unit vectors"):
        LightSet(np.array([[0.0, 0.0, 2.0]]), np.array([1.0]), "bad")
    with pytest.raises(LightsError, match="weights must have shape"):
        LightSet(np.array([[0.0, 0.0, 1.0]]), np.array([1.0, 1.0]), "bad")
    with pytest.raises(LightsError, match="non-negative"):
        LightSet(np.array([[0.0, 0.0, 1.0]]), np.array([-1.0]), "bad")
    with pytest.raises(LightsError, match=r"\(M, 3\)"):
        LightSet(np.zeros((2, 2)), np.zeros(2), "bad")
    empty = LightSet(np.empty((0, 3)), np.empty(0), "none")
    assert len(empty) == 0
