"""Brightness scale estimation (§III-C, Eq. 3–6): radiosity images, E_crf vs E_lin, moving average, relit image."""
from __future__ import annotations

import numpy as np
import pytest

from lightfast.camera import PinholeCamera
from lightfast.daylight.brightness import (
    COMPONENTS,
    BrightnessEstimator,
    RadiosityImages,
    ScaleFit,
    fit_scales,
    radiosity_images,
    relit_image,
)
from lightfast.daylight.crf import CameraResponse
from lightfast.daylight.errors import BrightnessError
from lightfast.daylight.lighting_map import LightingMapConfig, prepare_lighting_map
from lightfast.daylight.sun import FREIBURG
from lightfast.daylight.sun_update import sun_radiosity
from lightfast.geometry import look_at
from lightfast.sim.validation_rooms import box_room_with_window

S_TRUE = np.array([[800.0, 760.0, 680.0],  # sun (per unit of B̂_sun)
                   [60.0, 70.0, 90.0],  # sky
                   [30.0, 28.0, 24.0]])  # ground


@pytest.fixture(scope="module")
def scene():
    mesh = box_room_with_window(tessellation_m=0.2)
    lmap = prepare_lighting_map(mesh, FREIBURG, LightingMapConfig(patch_size_m=0.5, sky_directions=256,
                                                                  hemisphere_rays=32))
    el = np.radians(35.0)
    sun = sun_radiosity(lmap, np.array([0.0, -np.cos(el), np.sin(el)]))  # through the south window
    comps = {"sun": sun, "sky": lmap.sky_radiosity, "ground": lmap.ground_radiosity}
    eye = [2.25, 4.3, 1.6]
    T = look_at(eye, np.add(eye, [0.0, -2.8, -1.4]))  # from the north wall towards the window and the sun patch
    camera = PinholeCamera(320, 240, 250.0, 250.0, 159.5, 119.5)
    return lmap, comps, T, camera


def synth(ri: RadiosityImages, crf: CameraResponse, s: np.ndarray) -> np.ndarray:
    B = sum(s[i] * ri.images[n] for i, n in enumerate(COMPONENTS))
    return crf.apply_radiosity(B)


def test_radiosity_images_grid_and_interpolation(scene):
    lmap, comps, T, camera = scene
    ri = radiosity_images(lmap, comps, T, camera, stride_px=15)
    assert ri.names == COMPONENTS
    us = np.unique(ri.uv_px[:, 0])
    vs = np.unique(ri.uv_px[:, 1])
    assert us[0] == 7 and vs[0] == 7 and np.all(np.diff(us) == 15) and np.all(np.diff(vs) == 15)
    assert len(ri) == len(us) * len(vs) == 21 * 16
    assert ri.valid.sum() > 0.8 * len(ri)
    # every pixel of the closed room hits something except the window; reflectance is the mesh's, interpolated
    rho = np.asarray(lmap.mesh.reflectance)
    assert np.all(ri.reflectance[ri.valid] <= rho.max(0) + 1e-6)
    # interpolation check against a direct ray cast and nearest-vertex lookup
    hits = lmap.caster.intersect(T[:3, 3], camera.backproject(ri.uv_px.astype(float), np.ones(len(ri))) @ T[:3, :3].T)
    np.testing.assert_array_equal(hits.hit, ri.depth_m > 0)
    p = hits.points()[hits.hit]
    p_cam = (p - T[:3, 3]) @ T[:3, :3]
    np.testing.assert_allclose(ri.depth_m[hits.hit], p_cam[:, 2], rtol=1e-5, atol=1e-5)
    # a per-vertex linear function of position is reproduced exactly by barycentric interpolation
    lin = {"x": np.asarray(lmap.mesh.vertices_m, np.float32)}
    ri2 = radiosity_images(lmap, lin, T, camera, stride_px=15)
    np.testing.assert_allclose(ri2.images["x"][hits.hit], p, atol=1e-4)


def test_invalid_pixels_are_excluded(scene):
    lmap, comps, T, camera = scene
    ri = radiosity_images(lmap, comps, T, camera)
    crf = CameraResponse.from_function(lambda v: (v / 255.0) ** 2.2, exposure_s=0.004, sensitivity=2.5)
    I_C = synth(ri, crf, S_TRUE)
    garbage = I_C.copy()
    bad = np.zeros(len(ri), bool)
    bad[::3] = True
    garbage[bad] = 255.0 - garbage[bad]  # wrong data...
    valid = ri.valid & ~bad  # ... that is masked out
    fit = fit_scales(garbage, ri.images, crf, valid=valid)
    np.testing.assert_allclose(fit.scales, S_TRUE, rtol=1e-3)
    assert fit.num_pixels == valid.sum()
    # the low-reflectance / miss filter: a dark patch of the mesh makes pixels invalid
    rho = np.asarray(lmap.mesh.reflectance).copy()
    rho[np.asarray(lmap.mesh.vertices_m)[:, 2] < 0.01] = 0.02  # floor below the 0.03 threshold
    dark = type(lmap.mesh)(lmap.mesh.vertices_m, lmap.mesh.faces, rho)

    class _Map:  # only mesh and caster are used
        mesh = dark
        caster = lmap.caster

    ri_dark = radiosity_images(_Map(), comps, T, camera)
    on_floor = np.abs(ri.reflectance - np.asarray((0.32, 0.26, 0.20), np.float32)).max(1) < 1e-4
    assert on_floor.sum() > 20
    assert not ri_dark.valid[on_floor].any()
    assert ri_dark.valid.sum() == ri.valid.sum() - on_floor.sum()


def test_crf_fit_recovers_scales_despite_saturation(scene, true_crf):
    lmap, comps, T, camera = scene
    ri = radiosity_images(lmap, comps, T, camera)
    exact = synth(ri, true_crf, S_TRUE)
    sat = (exact[ri.valid] >= 255).any(1).mean()
    assert 0.1 < sat < 0.6, sat
    fit = fit_scales(exact, ri, true_crf, method="crf")
    assert isinstance(fit, ScaleFit) and fit.observed.all()
    np.testing.assert_allclose(fit.scales, S_TRUE, rtol=1e-3)
    I_C = np.round(exact)  # quantized like a real image
    fit = fit_scales(I_C, ri, true_crf, method="crf")
    # sun and sky within 1 %; the ground image is nearly collinear with the sky one here, so quantization moves it more
    np.testing.assert_allclose(fit.scales[:2], S_TRUE[:2], rtol=0.01)
    np.testing.assert_allclose(fit.scales[2], S_TRUE[2], rtol=0.05)
    assert np.all(fit.rms_px < 0.5)
    lm = fit_scales(I_C, ri, true_crf, method="crf", solver="lm")
    np.testing.assert_allclose(lm.scales, fit.scales, rtol=1e-3)
    # E_lin (Eq. 6) clips the saturated pixels and under-estimates the brightness (paper Fig. 5)
    lin = fit_scales(I_C, ri, true_crf, method="lin")
    saturating = (I_C[ri.valid] >= 255).mean(0) > 0.1
    assert saturating.tolist() == [True, True, False]  # blue stays below 255 with this reflectance and sun
    assert np.all(lin.scales[0, saturating] < 0.9 * S_TRUE[0, saturating])
    assert np.all(lin.rms_px[saturating] > 5 * fit.rms_px[saturating])
    # no saturation, no bias: exact on the unquantized image; on the quantized one within the crf fit's tolerances
    # (the ground image is nearly collinear with the sky one here)
    np.testing.assert_allclose(fit_scales(exact, ri, true_crf, method="lin").scales[:, 2], S_TRUE[:, 2], rtol=1e-3)
    np.testing.assert_allclose(lin.scales[:2, 2], S_TRUE[:2, 2], rtol=0.02)
    np.testing.assert_allclose(lin.scales[2, 2], S_TRUE[2, 2], rtol=0.05)
    # the predicted sun-lit brightness: E_lin is darker
    B_true = sum(S_TRUE[i] * ri.images[n] for i, n in enumerate(COMPONENTS))
    B_lin = sum(lin.scales[i] * ri.images[n] for i, n in enumerate(COMPONENTS))
    brightest = np.argsort(B_true[:, 1])[-10:]
    assert np.all(B_lin[brightest, 1] < 0.9 * B_true[brightest, 1])


def test_lin_fit_is_exact_without_saturation(scene, true_crf):
    lmap, comps, T, camera = scene
    ri = radiosity_images(lmap, comps, T, camera)
    dim = true_crf.with_exposure(exposure_s=0.0008)
    I_C = synth(ri, dim, S_TRUE)
    assert I_C[ri.valid].max() < 250
    for method in ("lin", "crf"):
        fit = fit_scales(I_C, ri, dim, method=method)
        np.testing.assert_allclose(fit.scales, S_TRUE, rtol=1e-3)


def test_noisy_fit_and_moving_average(scene, true_crf):
    lmap, comps, T, camera = scene
    ri = radiosity_images(lmap, comps, T, camera)
    clean = synth(ri, true_crf, S_TRUE)
    rng = np.random.default_rng(1)
    est = BrightnessEstimator(true_crf, window=5)
    frames = []
    for _ in range(8):
        I_C = np.clip(np.round(clean + rng.normal(0.0, 2.0, clean.shape)), 0, 255)
        avg = est.update(I_C, ri)
        frames.append(est.last_fit.scales)
    assert len(est) == 5
    np.testing.assert_allclose(avg, np.mean(frames[-5:], axis=0), rtol=1e-12)
    np.testing.assert_allclose(avg, S_TRUE, rtol=0.05)
    # unobserved entries keep their average; reset clears
    fit = ScaleFit(COMPONENTS, np.full((3, 3), 1e6), np.zeros((3, 3), bool), np.zeros(3), 100, "crf")
    np.testing.assert_allclose(est.push(fit), np.mean(frames[-4:], axis=0), rtol=1e-12)
    est.reset()
    assert len(est) == 0 and not est.scales.any()


def test_moving_average_tracks_changes():
    crf = CameraResponse.from_function(lambda v: v / 255.0)
    est = BrightnessEstimator(crf, window=3)
    obs = np.ones((3, 3), bool)
    for k in range(1, 6):
        out = est.push(ScaleFit(COMPONENTS, np.full((3, 3), float(k)), obs, np.zeros(3), 50, "crf"))
    np.testing.assert_allclose(out, 4.0)  # mean of 3, 4, 5
    with pytest.raises(BrightnessError):
        BrightnessEstimator(crf, window=0)


def test_relit_image_reproduces_synthetic_image(scene, true_crf):
    lmap, comps, T, camera = scene
    relit = relit_image(lmap, comps, S_TRUE, T, camera, true_crf)
    assert relit.color.shape == (240, 320, 3) and relit.depth_m.shape == (240, 320)
    ri = radiosity_images(lmap, comps, T, camera, stride_px=15)
    u, v = ri.uv_px[:, 0], ri.uv_px[:, 1]
    np.testing.assert_allclose(relit.color[v, u], synth(ri, true_crf, S_TRUE), atol=0.05)
    np.testing.assert_allclose(relit.depth_m[v, u], ri.depth_m, atol=1e-6)
    # fitting on the relit image itself gives the scales back (Ω on a stride-7 grid of the full render)
    ri7 = radiosity_images(lmap, comps, T, camera, stride_px=7)
    fit = fit_scales(relit.rgb8(), ri7, true_crf)
    np.testing.assert_allclose(fit.scales, S_TRUE, rtol=0.02)
    # a dict of scales and a ScaleFit work the same
    again = relit_image(lmap, comps, fit, T, camera, true_crf)
    np.testing.assert_allclose(again.color, relit_image(lmap, comps, fit.as_dict(), T, camera, true_crf).color)


def test_unobserved_component_keeps_initial(scene, true_crf):
    lmap, comps, T, camera = scene
    ri = radiosity_images(lmap, comps, T, camera)
    images = dict(ri.images)
    images["sun"] = np.zeros_like(images["sun"])  # the sun does not reach this view
    s = S_TRUE.copy()
    s[0] = 0.0
    I_C = synth(RadiosityImages(ri.uv_px, images, ri.reflectance, ri.valid, ri.depth_m), true_crf, s)
    init = np.array([[5.0, 5.0, 5.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0]])
    fit = fit_scales(I_C, images, true_crf, valid=ri.valid, initial=init)
    assert not fit.observed[0].any() and fit.observed[1:].all()
    np.testing.assert_allclose(fit.scales[0], 5.0)
    np.testing.assert_allclose(fit.scales[1:], S_TRUE[1:], rtol=0.01)


def test_errors(scene, true_crf):
    lmap, comps, T, camera = scene
    with pytest.raises(BrightnessError, match="shape"):
        radiosity_images(lmap, {"sun": np.zeros((3, 3))}, T, camera)
    with pytest.raises(BrightnessError, match="4x4"):
        radiosity_images(lmap, comps, np.eye(3), camera)
    with pytest.raises(BrightnessError, match="stride"):
        radiosity_images(lmap, comps, T, camera, stride_px=0)
    ri = radiosity_images(lmap, comps, T, camera)
    with pytest.raises(BrightnessError, match="method"):
        fit_scales(np.zeros((len(ri), 3)), ri, true_crf, method="foo")
    with pytest.raises(BrightnessError, match="I_C"):
        fit_scales(np.zeros((len(ri), 2)), ri.images, true_crf)
    with pytest.raises(BrightnessError, match="scale"):
        relit_image(lmap, comps, {"sun": 1.0}, T, camera, true_crf)
    with pytest.raises(BrightnessError, match="components"):
        BrightnessEstimator(true_crf).update(np.zeros((len(ri), 3)), {"sun": ri.images["sun"]})
