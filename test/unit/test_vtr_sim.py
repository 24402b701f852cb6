"""The spectral outdoor VT&R recordings (lightfast.sim.vtr): determinism,
rectified stereo geometry, bluish shadows, departure from the narrow-band Planckian model, bags and truth files,
rendering speed. Kept fast: a 30 m test route, small images, few frames."""
from __future__ import annotations

import csv
import json
import math
import time

import numpy as np
import pytest

from lightfast import cli
from lightfast.bag import open_bag
from lightfast.ros.convert import camera_from_camera_info, image_to_numpy, pose_stamped_to_matrix
from lightfast.sim.vtr.build import build_route_scene, flat_test_scene
from lightfast.sim.vtr.camera import AutoExposure, SensorModel, StereoRig
from lightfast.sim.vtr.light import daylight_illumination, solar_spectra
from lightfast.sim.vtr.recordings import (
    DEFAULT_RUNS,
    LEFT_IMAGE_TOPIC,
    LEFT_INFO_TOPIC,
    MET_SITE,
    RIGHT_IMAGE_TOPIC,
    RIGHT_INFO_TOPIC,
    TABLE_I,
    DriveConfig,
    RunSpec,
    drive_route,
    generate_vtr_set,
    load_schedule,
)
from lightfast.sim.vtr.renderer import SpectralRenderer
from lightfast.sim.vtr.scene import RouteConfig, base_pose
from lightfast.sim.vtr.spectra import (
    BASIS,
    WAVELENGTHS_NM,
    camera_response,
    camera_sensitivities,
    material_spectra,
    planck,
    spectrum_cct,
)
from lightfast.topics import GT_POSE_TOPIC


def _sun_dir(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)])


def _sunny(azimuth_deg: float = 150.0, elevation_deg: float = 50.0, weather: str = "sunny"):
    return daylight_illumination(_sun_dir(azimuth_deg, elevation_deg), elevation_deg, weather)


@pytest.fixture(scope="module")
def scene():
    return build_route_scene(RouteConfig.for_tests(length_m=30.0))


@pytest.fixture(scope="module")
def renderer(scene):
    return SpectralRenderer(scene)


# ---------------------------------------------------------------------------------------------------- scene


def test_scene_is_deterministic_and_has_all_stretches(scene):
    small = RouteConfig.for_tests(length_m=12.0, outer_margin_m=10.0, sky_samples=4)
    a, b = build_route_scene(small), build_route_scene(small)
    assert a.content_hash == b.content_hash
    np.testing.assert_array_equal(a.vertex_vis, b.vertex_vis)
    other = build_route_scene(RouteConfig.for_tests(length_m=12.0, outer_margin_m=10.0, sky_samples=4, seed=8))
    assert other.content_hash != a.content_hash
    s = np.linspace(0.5, 29.5, 59)
    assert set(scene.stretch_at(s).tolist()) == {0, 1, 2}  # sand_rock, grass, wood in that order
    assert scene.stats["rocks"] > 5 and scene.stats["trees"] > 5
    # nothing but terrain in the driving lane: rays down from 2 m above the centreline hit ground
    xy, _ = scene.centreline(s)
    kinds = scene.face_kind[SpectralRenderer(scene, texture=False).caster.intersect(
        np.column_stack([xy, scene.height(xy) + 2.0]), [0.0, 0.0, -1.0]).triangle_id]
    assert np.all(kinds == 0)


def test_scene_save_load_roundtrip(scene, tmp_path):
    scene.save(tmp_path / "scene.npz")
    loaded = type(scene).load(tmp_path / "scene.npz")
    assert loaded.content_hash == scene.content_hash
    assert loaded.config == scene.config
    np.testing.assert_array_equal(loaded.height(scene.stations[:5, 1:3]), scene.height(scene.stations[:5, 1:3]))


def test_spectra_are_physical():
    rho = material_spectra()
    assert rho.shape == (len(BASIS), len(WAVELENGTHS_NM))
    assert rho.min() >= 0.01 and rho.max() <= 0.95
    red_edge = rho[BASIS.index("grass_green")]
    assert red_edge[WAVELENGTHS_NM == 750][0] > 2.5 * red_edge[WAVELENGTHS_NM == 670][0]  # vegetation red edge
    S = camera_sensitivities()
    assert S.shape == (len(WAVELENGTHS_NM), 3) and S.max() == pytest.approx(1.0)
    assert np.argmax(S[:, 0]) > np.argmax(S[:, 1]) > np.argmax(S[:, 2])  # R, G, B peaks by wavelength
    # sunlight reddens towards the horizon, skylight is much bluer than sunlight
    cct = {el: (spectrum_cct(solar_spectra(el)[0]), spectrum_cct(solar_spectra(el)[1])) for el in (5, 20, 60)}
    assert cct[5][0] < cct[20][0] < cct[60][0]
    assert 4500 < cct[60][0] < 6000
    assert all(sky > 1.5 * sun for sun, sky in cct.values())
    cloudy = _sunny(weather="cloudy")
    assert 6000 < spectrum_cct(cloudy.sky_horizontal) < 8000
    assert cloudy.direct_normal.sum() < 0.05 * _sunny().direct_normal.sum()


# ---------------------------------------------------------------------------------------------------- render


def test_render_and_capture_are_deterministic(renderer, scene):
    rig = StereoRig(width=64, height=48)
    T = rig.camera_poses(base_pose(scene, 12.0, 0.1))
    light = _sunny()
    a = renderer.render(T, rig.camera, light, np.random.default_rng(3))
    b = renderer.render(T, rig.camera, light, np.random.default_rng(3))
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.raw, y.raw)
    sensor = SensorModel()
    img = [sensor.capture(a[0].raw, 0.002, 1.0, np.random.default_rng(5)) for _ in range(2)]
    np.testing.assert_array_equal(img[0], img[1])
    assert img[0].dtype == np.uint8 and img[0].shape == (48, 64, 3)
    assert not np.array_equal(img[0], sensor.capture(a[0].raw, 0.002, 1.0, np.random.default_rng(6)))  # noise


def test_stereo_pair_is_rectified(renderer, scene):
    """A scene point appears in the same row of both images, at disparity f·b/z: checked on the rendered geometry
    (the right view sees the left view's point where the rectified model says) and on the 8-bit images (block
    matching recovers f·b/z)."""
    import cv2

    rig = StereoRig(width=320, height=240)
    T_l, T_r = rig.camera_poses(base_pose(scene, 6.0, 0.0))
    np.testing.assert_allclose(np.linalg.inv(T_l) @ T_r, rig.T_left_right, atol=1e-12)
    assert rig.P_right[0, 3] == pytest.approx(-rig.fx * 0.24)
    left, right = renderer.render([T_l, T_r], rig.camera, _sunny(), np.random.default_rng(0))
    fb = rig.fx * rig.baseline_m
    v, u = np.nonzero(np.isfinite(left.depth_m) & (left.depth_m < 15.0))
    z = left.depth_m[v, u].astype(np.float64)
    ur = u - fb / z
    # the left hit point, seen from the right camera, projects to the same row and the predicted column
    p = left.points[v, u].astype(np.float64)
    Tinv = np.linalg.inv(T_r)
    pr = p @ Tinv[:3, :3].T + Tinv[:3, 3]
    uv = pr[:, :2] / pr[:, 2:3] * rig.fx + [rig.camera.cx, rig.camera.cy]
    assert np.max(np.abs(uv[:, 1] - v)) < 0.01 and np.max(np.abs(uv[:, 0] - ur)) < 0.01
    # and the right render sees that point there (where the predicted column is close to a pixel centre)
    near = (np.abs(ur - np.round(ur)) < 0.1) & (ur > 0.5)
    q = right.points[v[near], np.round(ur[near]).astype(int)].astype(np.float64)
    err = np.linalg.norm(q - p[near], axis=1) / (z[near] / rig.fx)  # in pixel footprints
    assert np.median(err) < 0.3
    # block matching on the 8-bit pair recovers the disparity f·b/z
    sensor = SensorModel()
    e, g = AutoExposure(sensor).update(left.raw)
    rng = np.random.default_rng(1)
    grey = [cv2.cvtColor(sensor.capture(o.raw, e, g, rng), cv2.COLOR_RGB2GRAY) for o in (left, right)]
    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=64, blockSize=7, uniquenessRatio=15,
                                 P1=8 * 49, P2=32 * 49, mode=cv2.STEREO_SGBM_MODE_HH)
    d = sgbm.compute(grey[0], grey[1]).astype(np.float64) / 16.0
    truth = fb / left.depth_m.astype(np.float64)
    ok = (d > 1.0) & np.isfinite(truth) & (truth > 4.0) & (truth < 60.0)
    ok[:, :70] = False  # no right-image counterpart near the left border
    assert ok.sum() > 0.3 * ok.size
    err = np.abs(d[ok] - truth[ok])
    assert np.median(err) < 0.5, np.median(err)


def _lit_and_shade(material: str, light) -> tuple[np.ndarray, np.ndarray]:
    """Raw responses of sunlit and shadowed ground (one material, no texture) beside a wall, seen from the north."""
    r = SpectralRenderer(flat_test_scene(material=material, wall=True), texture=False)
    rig = StereoRig(width=160, height=120, pitch_down_deg=30.0)
    T = np.eye(4)  # robot north of the wall, looking south at its shadow
    T[:3, :3] = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = (0.0, 14.0, 0.0)
    out = r.render([rig.camera_poses(T)[0]], rig.camera, light, np.random.default_rng(0))[0]
    ground = out.kind == 0
    lit, shade = ground & (out.sun > 0.1), ground & (out.sun == 0) & (out.sky_vis > 0.6)
    assert lit.sum() > 100 and shade.sum() > 100
    return out.raw[lit], out.raw[shade]


def test_shadow_is_bluer_than_sunlit_ground():
    """Shadows are lit by skylight, which is bluer than sunlight: same material, higher B/R in the raw response."""
    for light in (_sunny(180.0, 35.0), _sunny(240.0, 20.0)):
        for material in ("sand_rock", "grass"):
            lit, shade = _lit_and_shade(material, light)
            br = [np.median(x[:, 2] / x[:, 0]) for x in (lit, shade)]
            assert br[1] > 1.3 * br[0], (material, br)


def _log_chroma(rgb: np.ndarray) -> np.ndarray:
    rgb = np.asarray(rgb, dtype=np.float64)
    return np.stack([np.log(rgb[..., 0] / rgb[..., 1]), np.log(rgb[..., 2] / rgb[..., 1])], axis=-1)


def _line_residual(points: np.ndarray) -> float:
    """RMS distance of 2-D points from their total-least-squares line."""
    c = points - points.mean(axis=0)
    return float(np.linalg.svd(c, compute_uv=False)[-1] / math.sqrt(len(points)))


def test_renderer_is_not_the_narrow_band_planckian_model(renderer, scene):
    """§III's model (infinitely narrow sensors, Wien/Planck illuminants) puts the log-chromaticity of a surface under
    changing colour temperature on a straight line, shifted by the same vector for every surface. The simulated
    camera (broad measured sensitivities) and daylight (not black bodies) violate both."""
    lam = WAVELENGTHS_NM
    temps = np.array([2500.0, 3500.0, 4500.0, 5500.0, 6500.0, 8000.0, 10000.0])
    wien = np.array([lam**-5.0 * np.exp(-1.4388e7 / (lam * T)) for T in temps])
    narrow = np.zeros((len(lam), 3))
    narrow[[lam.tolist().index(x) for x in (610.0, 530.0, 460.0)], [0, 1, 2]] = 1.0
    rho = material_spectra()
    control = max(_line_residual(_log_chroma(camera_response(r, wien, narrow))) for r in rho)
    assert control < 1e-9  # the model is exact for narrow sensors and Wien illuminants
    # broad sensitivities: every basis surface leaves the line (rms distance in log-chromaticity, 1e-3 to 1e-2),
    # under Wien, Planck and the simulator's daylight across sun elevations
    planckian = np.array([planck(lam, T) for T in temps])
    days = np.array([_sunny(180.0, el).global_horizontal for el in (3.0, 6.0, 10.0, 20.0, 40.0, 60.0)])
    for illum, bound in ((wien, 5e-4), (planckian, 5e-4), (days, 5e-3)):
        res = [_line_residual(_log_chroma(camera_response(r, illum))) for r in rho]
        assert min(res) > bound, dict(zip(BASIS, res, strict=True))
    # rendered: the log-chromaticity shift from sunlit to shadowed ground (sun + sky → sky) depends on the surface;
    # in the narrow-band model it is the same vector for every surface (about 0.03 apart here, of 0.36)
    shift = {}
    for material in ("sand_rock", "grass"):
        lit, shade = _lit_and_shade(material, _sunny(180.0, 35.0))
        shift[material] = _log_chroma(np.median(shade, axis=0)) - _log_chroma(np.median(lit, axis=0))
    assert np.linalg.norm(shift["sand_rock"] - shift["grass"]) > 0.015, shift


def test_auto_exposure_follows_the_light(renderer, scene):
    rig = StereoRig(width=64, height=48)
    T = rig.camera_poses(base_pose(scene, 5.0))[0]
    exp = {}
    for name, light in (("noon", _sunny(180.0, 60.0)), ("cloudy", _sunny(180.0, 60.0, "cloudy")),
                        ("dusk", _sunny(290.0, 1.0))):
        raw = renderer.render([T], rig.camera, light, np.random.default_rng(0))[0].raw
        e, g = AutoExposure(SensorModel()).update(raw)
        exp[name] = e * g
    assert exp["noon"] < exp["cloudy"] < exp["dusk"]


# ---------------------------------------------------------------------------------------------------- recordings


def test_schedule():
    assert len(TABLE_I) == 28 and TABLE_I[0].name == "teach" and TABLE_I[0].start == "10:50"
    by = {r.name: r for r in TABLE_I}
    assert by["repeat07"].start == "18:14" and by["repeat07"].weather == "sunny"
    assert by["repeat13"].weather == "cloudy" and by["repeat27"].date == "2014-05-15"
    assert 8 <= len(DEFAULT_RUNS) - 1 <= 10 and DEFAULT_RUNS[0] == "teach"
    assert {by[n].weather for n in DEFAULT_RUNS} == {"sunny", "cloudy"}
    with pytest.raises(ValueError):
        RunSpec("x", "2014-05-12", "25:00", "sunny")


def test_drive(scene):
    cfg = DriveConfig()
    teach = drive_route(scene, cfg, teach=True, seed=1)
    rep = drive_route(scene, cfg, teach=False, seed=2)
    speed = np.diff(teach.s_m) / np.diff(teach.time_s)
    assert 0.5 < speed.min() and speed.max() < 1.0
    assert np.max(np.abs(teach.lateral_m)) < 0.05 and np.max(np.abs(rep.lateral_m)) < 0.45
    assert teach.s_m[-1] <= scene.length_m - 1.0 + 1e-9
    z_ground = scene.height(teach.T_map_base[:, :2, 3])
    np.testing.assert_allclose(teach.T_map_base[:, 2, 3], z_ground)


def test_recordings_bags_truth_and_cache(tmp_path):
    route = RouteConfig.for_tests(length_m=20.0)
    rig = StereoRig(width=96, height=72)
    drive = DriveConfig(max_frames=4)
    kw = dict(runs=["teach", "repeat07", "repeat13"], route=route, rig=rig, drive=drive)
    t0 = time.perf_counter()
    dirs = generate_vtr_set(tmp_path, **kw)
    first = time.perf_counter() - t0
    assert [d.name for d in dirs] == ["teach", "repeat07", "repeat13"]
    for d in dirs:
        with open_bag(d / "bag") as bag:
            info = bag.info
            assert {t.name: t.message_count for t in info.topics} == {
                LEFT_IMAGE_TOPIC: 4, RIGHT_IMAGE_TOPIC: 4, LEFT_INFO_TOPIC: 4, RIGHT_INFO_TOPIC: 4, GT_POSE_TOPIC: 4}
            assert info.topic(LEFT_IMAGE_TOPIC).msgtype == "sensor_msgs/msg/Image"
            assert info.topic(GT_POSE_TOPIC).msgtype == "geometry_msgs/msg/PoseStamped"
            seen = {}
            for m in bag.messages():
                seen.setdefault(m.topic, bag.deserialize(m))
        left, right = seen[LEFT_IMAGE_TOPIC], seen[RIGHT_IMAGE_TOPIC]
        assert left.encoding == right.encoding == "rgb8"
        assert image_to_numpy(left).shape == (72, 96, 3)
        P_l = np.asarray(seen[LEFT_INFO_TOPIC].p).reshape(3, 4)
        P_r = np.asarray(seen[RIGHT_INFO_TOPIC].p).reshape(3, 4)
        assert P_l[0, 3] == 0.0 and P_r[0, 3] == pytest.approx(-rig.fx * rig.baseline_m)
        assert camera_from_camera_info(seen[RIGHT_INFO_TOPIC]) == rig.camera
        T, _, frame = pose_stamped_to_matrix(seen[GT_POSE_TOPIC])
        assert frame == "map"
        with open(d / "truth.csv") as fh:
            rows = list(csv.DictReader(fh))
        assert len(rows) == 4
        np.testing.assert_allclose([float(rows[0][k]) for k in ("x_m", "y_m", "z_m")], T[:3, 3], atol=1e-6)
        meta = json.loads((d / "run.json").read_text())
        assert meta["frames"] == 4 and meta["ms_per_frame"] > 0
        assert {r["weather"] for r in rows} == {meta["run"]["weather"]}
        assert all(float(r["exposure_s"]) > 0 for r in rows)
    teach = json.loads((dirs[0] / "run.json").read_text())
    assert teach["start_local"].startswith("2014-05-12T10:50") and teach["run"]["weather"] == "sunny"
    assert 50.0 < teach["sun_elevation_deg"][0] < 56.0  # Saint-Hubert, mid-May, 10:50 EDT
    assert json.loads((tmp_path / "runs.json").read_text())["runs"][2]["weather"] == "cloudy"
    assert (tmp_path / "scene" / "scene.npz").is_file() and (tmp_path / "scene" / "camera.yaml").is_file()
    # complete runs are reused; a changed parameter re-renders
    mtime = (dirs[1] / "run.json").stat().st_mtime_ns
    t0 = time.perf_counter()
    generate_vtr_set(tmp_path, **kw)
    assert time.perf_counter() - t0 < 0.5 * first
    assert (dirs[1] / "run.json").stat().st_mtime_ns == mtime
    generate_vtr_set(tmp_path, runs=["repeat07"], route=route, rig=rig, drive=drive, seed=1)
    assert (dirs[1] / "run.json").stat().st_mtime_ns != mtime


def test_cli_and_schedule_file(tmp_path):
    sched = tmp_path / "s.yaml"
    sched.write_text("- {name: teach, date: '2014-06-01', start: '12:00', weather: sunny}\n"
                     "- {name: evening, date: '2014-06-01', start: '19:30', weather: cloudy}\n")
    runs = load_schedule(sched)
    assert [r.kind for r in runs] == ["teach", "repeat"] and runs[1].weather == "cloudy"
    with pytest.raises(SystemExit):
        cli.main(["sim", "vtr", str(tmp_path / "o"), "--runs", "teach", "--schedule", str(sched)])
    with pytest.raises(SystemExit):
        cli.main(["sim", "vtr", str(tmp_path / "o"), "--size", "10x"])


def test_render_speed(renderer, scene, capsys):
    """Rendering speed of a short run (stereo pair, render + exposure + noise); the number is printed."""
    rig = StereoRig(width=320, height=240)
    sensor = SensorModel()
    ae = AutoExposure(sensor)
    light = _sunny()
    renderer.render(rig.camera_poses(base_pose(scene, 3.0)), rig.camera, light, np.random.default_rng(0))
    t0 = time.perf_counter()
    n = 3
    for i in range(n):
        out = renderer.render(rig.camera_poses(base_pose(scene, 3.0 + 0.4 * i)), rig.camera, light,
                              np.random.default_rng(i))
        e, g = ae.update(out[0].raw)
        rng = np.random.default_rng(i)
        for o in out:
            sensor.capture(o.raw, e, g, rng)
    ms = 1000.0 * (time.perf_counter() - t0) / n
    with capsys.disabled():
        print(f"\nvtr sim: {ms:.0f} ms per 320x240 stereo frame (test scene)")
    assert ms < 5000.0


def test_site_is_the_mars_emulation_terrain():
    assert MET_SITE.timezone == "America/Toronto" and 45.0 < MET_SITE.latitude_deg < 46.0
