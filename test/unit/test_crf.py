"""Camera response function: table model, YAML files, simulator camera.yaml, bracket calibration (§III-C's f)."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from lightfast import cli
from lightfast.camera import PinholeCamera
from lightfast.daylight.crf import CameraResponse, calibrate_from_bracket, calibrate_from_files, load_crf, save_crf
from lightfast.daylight.errors import CrfError
from lightfast.errors import LightfastError
from lightfast.sim.daylight.recordings import _camera_yaml
from lightfast.sim.daylight.sensors import CameraResponse as SimCameraResponse
from lightfast.sim.daylight.sensors import DepthSensor

SHOULDER = 0.5


def f_true(x):
    """Known curve: gamma 1/2.2 with a soft shoulder, saturating at x = 1."""
    t = np.power(np.clip(x, 0.0, 1.0), 1.0 / 2.2)
    return 255.0 * (1.0 + SHOULDER) * t / (t + SHOULDER)


def finv_true(v):
    g = np.clip(np.asarray(v, float) / 255.0, 0.0, 1.0)
    return (SHOULDER * g / (1.0 + SHOULDER - g)) ** 2.2


def bracket(noise: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    radiance = np.exp(rng.uniform(np.log(1e-3), np.log(1.0), (60, 80, 3)))
    times = [0.5**k for k in range(-3, 8)]
    images = [np.clip(np.round(f_true(radiance * t) + rng.normal(0.0, noise, radiance.shape)), 0, 255)
              .astype(np.uint8) for t in times]
    return images, times


def recovered_error(crf: CameraResponse, lo: int = 20, hi: int = 235) -> np.ndarray:
    v = np.arange(lo, hi + 1)
    ref = finv_true(v) / finv_true(128)
    return np.abs(crf.inverse[lo:hi + 1] / ref[:, None] - 1.0)


def test_table_apply_linearize_derivative():
    crf = CameraResponse.from_function(finv_true, exposure_s=0.01, gain=2.0, sensitivity=3.0)
    assert crf.exposure_factor == pytest.approx(0.06)
    x = np.random.default_rng(0).uniform(0.0, 1.2, (50, 40, 3))
    y = crf.apply(x)
    assert y.shape == x.shape and y.min() >= 0 and y.max() == 255.0
    np.testing.assert_allclose(y, f_true(x), atol=0.6)  # piecewise linear between exact table nodes
    np.testing.assert_array_equal(y[x >= 1.0], 255.0)  # saturation
    ok = y < 255
    np.testing.assert_allclose(crf.linearize(y)[ok], x[ok], rtol=1e-9, atol=1e-12)  # exact inverse
    np.testing.assert_allclose(crf.apply(crf.linearize(np.arange(256.0)[:, None].repeat(3, 1))),
                               np.arange(256.0)[:, None].repeat(3, 1), atol=1e-9)
    v, d = crf.apply_and_derivative(x)
    np.testing.assert_allclose(v, y, atol=1e-9)
    h = 1e-7
    inside = (x > 1e-3) & (x < 0.99)
    numeric = (crf.apply(x + h) - crf.apply(x - h)) / (2 * h)
    rel = np.abs(numeric[inside] - d[inside]) / d[inside]
    assert np.median(rel) < 1e-4  # equal except where x ± h crosses a table node
    assert np.all(d[x >= 1.0] == 0.0)
    np.testing.assert_allclose(crf.apply_radiosity(np.full((2, 3), 5.0)), crf.apply(np.full((2, 3), 0.3)))
    np.testing.assert_allclose(crf.radiosity(crf.apply_radiosity(np.full((1, 3), 5.0))), 5.0, rtol=1e-9)
    assert crf.with_exposure(exposure_s=0.02).exposure_factor == pytest.approx(0.12)
    with pytest.raises(CrfError, match="shape"):
        crf.apply(np.zeros((4, 2)))


def test_bad_tables():
    with pytest.raises(CrfError, match="shape"):
        CameraResponse(np.zeros((10, 3)))
    with pytest.raises(CrfError, match="strictly increasing"):
        CameraResponse(np.ones((256, 3)))
    with pytest.raises(CrfError, match="finite"):
        CameraResponse(np.r_[np.nan, np.linspace(0, 1, 255)])
    with pytest.raises(CrfError, match="exposure_s"):
        CameraResponse(np.linspace(0, 1, 256), exposure_s=0.0)
    assert issubclass(CrfError, LightfastError)


def test_yaml_round_trip(tmp_path):
    crf = CameraResponse(np.stack([finv_true(np.arange(256.0)) * k for k in (1.0, 1.1, 0.9)], 1),
                         exposure_s=0.004, gain=1.5, sensitivity=2.0)
    path = save_crf(crf, tmp_path / "crf.yaml", description="test")
    back = load_crf(path)
    np.testing.assert_array_equal(back.inverse, crf.inverse)
    assert (back.exposure_s, back.gain, back.sensitivity) == (0.004, 1.5, 2.0)
    doc = yaml.safe_load(path.read_text())
    assert doc["format"] == "lightfast-crf" and doc["version"] == 1
    doc["version"] = 2
    (tmp_path / "v2.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(CrfError, match="version 2"):
        load_crf(tmp_path / "v2.yaml")
    doc["version"] = 1
    doc["inverse"]["g"] = doc["inverse"]["g"][::-1]
    (tmp_path / "dec.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(CrfError, match="channel g"):
        load_crf(tmp_path / "dec.yaml")
    (tmp_path / "bad.yaml").write_text("a: [1, 2\n")
    with pytest.raises(CrfError, match="invalid YAML"):
        load_crf(tmp_path / "bad.yaml")
    (tmp_path / "other.yaml").write_text("foo: 1\n")
    with pytest.raises(CrfError, match="not a camera response"):
        load_crf(tmp_path / "other.yaml")
    with pytest.raises(CrfError, match="cannot read"):
        load_crf(tmp_path / "missing.yaml")


def test_loads_simulator_camera_yaml(tmp_path):
    sim = SimCameraResponse(exposure_s=0.006, gain=1.3)
    path = tmp_path / "camera.yaml"
    path.write_text(_camera_yaml(sim, DepthSensor(), PinholeCamera(320, 240, 250.0, 250.0, 159.5, 119.5)))
    crf = load_crf(path)
    assert crf.exposure_s == 0.006 and crf.gain == 1.3
    radiance = np.random.default_rng(2).uniform(0.0, 40.0, (1000, 3))
    # our f on radiosity B = π L equals the simulator's f on its normalized exposure, up to the 256-entry table
    np.testing.assert_allclose(crf.apply_radiosity(np.pi * radiance), sim.crf(sim.exposure(radiance)), atol=0.3)
    x = sim.exposure(radiance)
    np.testing.assert_allclose(crf.linearize(sim.crf(x))[x < 0.99], x[x < 0.99], rtol=2e-3, atol=1e-6)


@pytest.mark.parametrize(("method", "noise", "tol"), [("debevec", 0.0, 0.02), ("debevec", 1.0, 0.05),
                                                      ("robertson", 0.0, 0.06)])
def test_calibrate_from_bracket_recovers_known_curve(method, noise, tol):
    images, times = bracket(noise)
    crf = calibrate_from_bracket(images, times, method=method)
    assert crf.inverse[128] == pytest.approx([1.0, 1.0, 1.0])
    assert np.all(np.diff(crf.inverse, axis=0) > 0)
    err = recovered_error(crf)
    assert err.max() < tol, err.max(0)
    assert err.mean() < tol / 3


def test_calibration_errors():
    images, times = bracket(0.0)
    with pytest.raises(CrfError, match="at least 2"):
        calibrate_from_bracket(images[:1], times[:1])
    with pytest.raises(CrfError, match="exposure times"):
        calibrate_from_bracket(images, times[:-1])
    with pytest.raises(CrfError, match="different"):
        calibrate_from_bracket(images[:2], [0.1, 0.1])
    with pytest.raises(CrfError, match="uint8"):
        calibrate_from_bracket([i.astype(float) for i in images], times)
    with pytest.raises(CrfError, match="shape"):
        calibrate_from_bracket([images[0], images[1][:10]], times[:2])
    with pytest.raises(CrfError, match="method"):
        calibrate_from_bracket(images, times, method="magic")


def test_cli_calibrate(tmp_path):
    import cv2

    images, times = bracket(0.0)
    paths = []
    for i, img in enumerate(images):
        p = tmp_path / f"img{i}.png"
        cv2.imwrite(str(p), img[..., ::-1])
        paths.append(str(p))
    out = tmp_path / "crf.yaml"
    assert cli.main(["crf", "calibrate", *paths, "--exposures", *map(str, times), "-o", str(out)]) == 0
    crf = load_crf(out)
    assert recovered_error(crf).max() < 0.02
    assert crf.exposure_s == pytest.approx(float(np.median(times)))
    with pytest.raises(CrfError, match="cannot read"):
        calibrate_from_files([tmp_path / "nope.png", paths[0]], [1.0, 2.0], out)
    with pytest.raises(SystemExit):
        cli.main(["crf", "calibrate", *paths, "--exposures", "1", "-o", str(out)])
