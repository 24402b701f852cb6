"""The simulated daylight recordings: scenes, sky model, ground-truth renderer (against closed forms), camera,
and tiny recordings written and read back. Kept fast (coarse meshes, small images, few samples)."""
from __future__ import annotations

import datetime as dt
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lightfast.bag import open_bag
from lightfast.camera import PinholeCamera
from lightfast.daylight.mesh import ReflectanceMesh, as_mesh, merge_meshes
from lightfast.daylight.sun import FREIBURG, sun_position
from lightfast.ros.convert import image_to_numpy, pose_stamped_to_matrix, stamp_to_ns
from lightfast.sim.daylight.irradiance_cache import CacheSettings, IrradianceCache
from lightfast.sim.daylight.recordings import COLOR_TOPIC, DEPTH_TOPIC, GT_POSE_TOPIC, generate_daylight_set
from lightfast.sim.daylight.renderer import GroundTruthRenderer
from lightfast.sim.daylight.rooms import make_ds1, make_ds2, make_ds3
from lightfast.sim.daylight.scene import RHO_MAX, RHO_MIN
from lightfast.sim.daylight.sensors import CameraResponse, DepthSensor
from lightfast.sim.daylight.sequences import SEQUENCES, camera_for_size, cloud_transmittance
from lightfast.sim.daylight.trajectory import hand_held_trajectory
from lightfast.sim.sky_model import (
    CIE_CLEAR_SKY,
    SUN_ANGULAR_RADIUS_RAD,
    UNIFORM_SKY,
    SkyState,
    sun_rgb,
)

TINY_CACHE = CacheSettings(hemisphere_samples=8, window_samples=4, sunlit_samples=4, sun_disk_samples=4, bounces=3,
                           filter_radius_m=0.3)
TINY = dict(frames=4, width=64, height=48, resolution_m=0.15, supersample=1, cache_settings=TINY_CACHE)


def _quad(z: float = 0.0, half: float = 1.0, n: int = 21, tilt_deg: float = 0.0, rho: float = 0.5) -> ReflectanceMesh:
    """A square grid in the plane z (front face +z), optionally tilted about the x axis."""
    xs = np.linspace(-half, half, n)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(n * n)], 1)
    t = math.radians(tilt_deg)
    R = np.array([[1, 0, 0], [0, math.cos(t), -math.sin(t)], [0, math.sin(t), math.cos(t)]])
    V = V @ R.T + [0, 0, z]
    i, j = (a.ravel() for a in np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij"))
    a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return as_mesh(V, F, [rho, rho, rho])


def _look_down(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.stack([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]], axis=1)  # optical x, y, z in the map
    T[:3, 3] = (x, y, z)
    return T


def _sun(el_deg: float, az_deg: float = 180.0) -> tuple[float, float, float]:
    el, az = math.radians(el_deg), math.radians(az_deg)
    return (math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el))


# --- scenes --------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("make", [make_ds1, make_ds2, make_ds3])
def test_scene_is_valid_and_faces_point_into_the_room(make) -> None:
    scene = make(resolution_m=0.1)
    mesh = scene.mesh
    mesh.validate_topology()
    assert RHO_MIN - 1e-12 <= mesh.reflectance.min() and mesh.reflectance.max() <= RHO_MAX + 1e-12
    # every surface seen from inside the room shows its front side
    renderer = GroundTruthRenderer(mesh, scene.window)
    rng = np.random.default_rng(0)
    d = rng.normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    hits = renderer.caster.intersect(np.array([2.2, 2.9, 1.4]), d)
    n = mesh.face_normals[hits.triangle_id[hits.hit]]
    assert np.mean(np.einsum("ij,ij->i", n, d[hits.hit]) < 0) > 0.995
    assert hits.hit.mean() > 0.97  # closed room but for the window
    w = scene.window
    assert w.area_m2 == pytest.approx(1.7 * 1.5)


def test_ds3_is_drawn_from_its_seed() -> None:
    a, b, c = make_ds3(resolution_m=0.1), make_ds3(resolution_m=0.1), make_ds3(resolution_m=0.1, seed=4)
    assert np.array_equal(a.mesh.vertices_m, b.mesh.vertices_m) and a.obstacles == b.obstacles
    assert a.obstacles != c.obstacles
    assert a.name == "DS3" and len(a.obstacles) == 3


def test_default_ds1_vertex_budget_and_texture() -> None:
    ds1 = make_ds1()
    assert 150_000 < ds1.mesh.num_vertices < 400_000
    rho = ds1.mesh.reflectance
    assert rho.std() > 0.1  # richly textured
    ds2 = make_ds2(resolution_m=0.1)
    walls = np.abs(ds2.mesh.vertex_normals[:, 2]) < 0.1
    assert np.ptp(ds2.mesh.reflectance[walls & (ds2.mesh.vertices_m[:, 1] > 4.7)], axis=0).max() < 1e-9


# --- sky ------------------------------------------------------------------------------------------------------------


def test_sky_normalization_and_colours() -> None:
    state = SkyState(_sun(25.0), (0, 0, 0), (100.0, 100.0, 100.0), overcast_dhi_rgb=(10.0, 10.0, 10.0))
    # horizontal irradiance of the normalized sky on an independent grid (Fibonacci sphere) = DHI
    n = 400_000
    k = np.arange(n) + 0.5
    z = 1 - k / n  # upper hemisphere, equal areas
    phi = math.pi * (1 + 5**0.5) * k
    r = np.sqrt(1 - z**2)
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
    E = (state.radiance(dirs) * z[:, None]).mean(axis=0) * 2 * math.pi
    assert E == pytest.approx([110.0] * 3, rel=3e-3)
    rel = CIE_CLEAR_SKY.relative(np.array([[0, 0, 1.0]]), _sun(25.0))
    assert rel[0] == pytest.approx(1.0)
    brighter_near_sun = CIE_CLEAR_SKY.relative(np.array([_sun(30.0), _sun(30.0, 0.0)]), _sun(25.0))
    assert brighter_near_sun[0] > 3 * brighter_near_sun[1]
    low, high = sun_rgb(5.0), sun_rgb(60.0)
    assert low[0] > low[2] * 3 and high[2] > 0.9 * high[0]


# --- renderer against closed forms ---------------------------------------------------------------------------------


def test_open_quad_under_the_sun_only() -> None:
    mesh = _quad()
    renderer = GroundTruthRenderer(mesh, None)
    el = 35.0
    state = SkyState(_sun(el), (800.0, 800.0, 800.0), (0.0, 0.0, 0.0), ground_albedo_rgb=(0, 0, 0))
    cache = renderer.compute_cache(state, CacheSettings(hemisphere_samples=8, sun_disk_samples=16))
    cos_z = math.sin(math.radians(el))
    assert cache.sun_direct.mean() == pytest.approx(cos_z, rel=0.02)
    assert np.abs(cache.irradiance["sun"]).max() < 1e-6  # nothing to inter-reflect
    cam = PinholeCamera(40, 30, 30.0, 30.0, 19.5, 14.5)
    out = renderer.render(_look_down(0.0, 0.0, 1.0), cam, cache, state, rng=np.random.default_rng(0))
    assert out.hit.all()
    assert np.median(out.sun_irradiance_wm2) == pytest.approx(800.0 * cos_z, rel=0.02)
    assert np.median(out.radiance[..., 1]) == pytest.approx(0.5 / math.pi * 800.0 * cos_z, rel=0.02)
    assert np.median(out.depth_m) == pytest.approx(1.0, abs=1e-4)


def test_uniform_sky_and_ground_irradiance() -> None:
    tilt = 60.0
    mesh = _quad(tilt_deg=tilt, n=11)
    renderer = GroundTruthRenderer(mesh, None)
    state = SkyState(_sun(30.0), (0, 0, 0), (1.0, 1.0, 1.0), clear_sky=UNIFORM_SKY)
    cache = renderer.compute_cache(state, CacheSettings(hemisphere_samples=256, filter_radius_m=0))
    c = math.cos(math.radians(tilt))
    # per unit DHI the uniform sky has L = 1/π: E = π L (1 + cos t) / 2; per unit ground radiance E = π (1 - cos t)/2
    assert cache.irradiance["clear"][:, 0].mean() == pytest.approx((1 + c) / 2, rel=0.03)
    assert cache.irradiance["ground"][:, 0].mean() == pytest.approx(math.pi * (1 - c) / 2, rel=0.03)
    flat = GroundTruthRenderer(_quad(n=5), None).compute_cache(state, CacheSettings(hemisphere_samples=64))
    assert flat.irradiance["clear"][:, 0] == pytest.approx(1.0, rel=1e-6)  # π L exactly


def test_soft_shadow_width_matches_the_sun_disk() -> None:
    h = 1.5  # occluder edge height above the floor
    floor = _quad(half=0.5, n=3)
    plate = _quad(z=h, half=1.0, n=3)
    plate = ReflectanceMesh(plate.vertices_m - [1.0, 0, 0], plate.faces, plate.reflectance)  # covers x < 0
    renderer = GroundTruthRenderer(merge_meshes([floor, plate]), None)
    state = SkyState((0.0, 0.0, 1.0), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), ground_albedo_rgb=(0, 0, 0))
    cache = IrradianceCache((0.0, 0.0, 1.0), {k: np.zeros((floor.num_vertices + plate.num_vertices, 3), np.float32)
                                              for k in ("sun", "clear", "overcast", "ground")},
                            np.zeros(1, np.float32), CacheSettings())
    cam = PinholeCamera(200, 20, 1000.0, 1000.0, 99.5, 9.5)  # 0.5 mm per pixel at 0.5 m
    out = renderer.render(_look_down(0.0, 0.0, 0.5), cam, cache, state, supersample=1, sun_samples=64,
                          rng=np.random.default_rng(1))
    x = (np.arange(200) - 99.5) / 1000.0 * 0.5
    profile = out.sun_irradiance_wm2.mean(axis=0)
    assert profile[0] < 0.01 and profile[-1] > 0.99
    # analytic edge profile of the limb-darkened disk seen from the floor: the visible fraction of the disk
    rng = np.random.default_rng(2)
    r = np.sqrt(rng.random(200_000))
    px = r * np.cos(2 * math.pi * rng.random(200_000))
    w = 1 - 0.6 * (1 - np.sqrt(1 - r**2))
    radius = h * math.tan(SUN_ANGULAR_RADIUS_RAD)
    frac = np.array([np.sum(w[px * radius < xx]) for xx in x]) / w.sum()

    def width(p: np.ndarray) -> float:
        return float(np.interp(0.9, p, x) - np.interp(0.1, p, x))

    assert width(profile) == pytest.approx(width(frac), rel=0.2)
    full = 2 * radius  # ≈ h × 0.0093 rad
    assert full == pytest.approx(h * 0.0093, rel=0.01)
    lit = x > full
    dark = x < -full
    assert profile[lit].min() > 0.97 and profile[dark].max() < 0.03


@pytest.fixture(scope="module")
def ds2_tiny():
    scene = make_ds2(resolution_m=0.1)
    renderer = GroundTruthRenderer(scene.mesh, scene.window)
    when = dt.datetime(2021, 1, 19, 12, 30, tzinfo=FREIBURG.zone)
    sun = sun_position(FREIBURG, when)
    state = SkyState(tuple(sun.direction_map), (700.0, 700.0, 700.0), (80.0, 80.0, 80.0))
    cache = renderer.compute_cache(state, TINY_CACHE)
    return scene, renderer, state, cache


def test_sunlit_pixels_are_brighter_and_lose_depth(ds2_tiny) -> None:
    scene, renderer, state, cache = ds2_tiny
    lit = (cache.sun_direct > 0.3) & (scene.mesh.vertices_m[:, 2] < 0.01)  # the sun patch on the floor
    assert lit.any()
    target = scene.mesh.vertices_m[lit].mean(axis=0)
    p = np.array([2.25, 3.6, 1.6])
    z = (target - p) / np.linalg.norm(target - p)
    x = np.cross(z, [0, 0, 1.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, np.cross(z, x), z], 1)
    T[:3, 3] = p
    cam = camera_for_size(80, 60)
    out = renderer.render(T, cam, cache, state, supersample=1, rng=np.random.default_rng(0))
    sunny = out.sun_irradiance_wm2 > 200
    shade = out.hit & (out.sun_irradiance_wm2 == 0)
    assert sunny.mean() > 0.02 and shade.mean() > 0.05
    resp = CameraResponse(exposure_s=0.18 / (8.0 * float(np.median(out.radiance[shade][:, 1]))))
    rng = np.random.default_rng(1)
    rgb = resp.capture(out.radiance, rng)
    assert rgb[sunny].mean() > rgb[shade].mean() + 50
    assert (rgb[sunny] == 255).mean() > 0.5  # over-exposed like the paper's sun patches
    depth = DepthSensor().measure(out.depth_m, out.sun_irradiance_wm2, rng)
    assert (depth[sunny] == 0).all()
    assert (depth[shade] > 0).mean() > 0.95
    # depth noise grows with z² (Kinect-like)
    ok = shade & (depth > 0)
    err = depth[ok] - out.depth_m[ok]
    assert np.abs(err).mean() < 0.02 and np.abs(err).max() < 0.2


def test_camera_response_saturates_and_inverts() -> None:
    resp = CameraResponse(exposure_s=0.01, gain=2.0)
    x = np.linspace(0, 1, 1001)
    f = resp.crf(x)
    assert f[0] == 0 and f[-1] == pytest.approx(255.0)
    assert np.all(np.diff(f) > 0)
    assert resp.crf(np.array([1.5, 10.0])) == pytest.approx([255.0, 255.0])
    assert resp.inverse_crf(f) == pytest.approx(x, abs=1e-9)
    rng = np.random.default_rng(0)
    L_sat = 2.0 / (resp.sensitivity * resp.exposure_s * resp.gain)
    assert (resp.capture(np.full((10, 10, 3), L_sat), rng) == 255).all()
    L_mid = 0.2 / (resp.sensitivity * resp.exposure_s * resp.gain)
    img = resp.capture(np.full((100, 100, 3), L_mid), rng).astype(float)
    assert img.mean() == pytest.approx(resp.crf(0.2), abs=1.0)
    assert 0.5 < img.std() < 5.0  # shot + read noise, a few values
    assert resp.capture(np.zeros((10, 10, 3)), rng).mean() < 3.0  # read noise only


def test_render_is_deterministic_with_a_seed(ds2_tiny) -> None:
    _, renderer, state, cache = ds2_tiny
    cam = camera_for_size(32, 24)
    T = np.eye(4)
    T[:3, :3] = np.stack([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]], 1)
    T[:3, 3] = (2.2, 3.0, 1.3)
    a = renderer.render(T, cam, cache, state, rng=np.random.default_rng(5))
    b = renderer.render(T, cam, cache, state, rng=np.random.default_rng(5))
    assert np.array_equal(a.radiance, b.radiance) and np.array_equal(a.depth_m, b.depth_m)
    c2 = renderer.compute_cache(state, TINY_CACHE)
    assert np.array_equal(c2.irradiance["clear"], cache.irradiance["clear"])


def test_trajectory_is_hand_held_like() -> None:
    scene = make_ds2(resolution_m=0.2)
    poses = hand_held_trajectory(scene, 300, 30.0, np.random.default_rng(3))
    p = poses[:, :3, 3]
    assert p[:, 0].min() > 0.75 and p[:, 0].max() < 4.5 - 0.75
    assert p[:, 1].min() > 0.75 and p[:, 1].max() < 4.8 - 0.75
    speed = np.linalg.norm(np.diff(p[::3], axis=0), axis=1) * 10.0  # over 0.1 s
    assert 0.18 < np.median(speed) < 0.52 and speed.max() < 0.6
    R = poses[:, :3, :3]
    assert np.allclose(np.einsum("nji,njk->nik", R, R), np.eye(3), atol=1e-9)
    rel = np.einsum("nji,njk->nik", R[:-1], R[1:])
    rate_deg_s = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1))) * 30.0
    assert rate_deg_s.max() < 110.0 and np.median(rate_deg_s) < 75.0  # hand-held panning: gaze limit + jitter
    a = cloud_transmittance(np.arange(600) / 30.0, np.random.default_rng(0))
    assert a.min() < 0.2 and a.max() > 0.9 and np.abs(np.diff(a)).max() < 0.2


# --- recordings -----------------------------------------------------------------------------------------------------


def test_tiny_recording_roundtrip_caching_and_determinism(tmp_path: Path) -> None:
    out = tmp_path / "set"
    [seq] = generate_daylight_set(out, sequences=["DS1.T6"], **TINY)
    for name in ("mesh.ply", "site.yaml", "camera.yaml", "truth.csv", "sequence.json"):
        assert (seq / name).is_file()
    from lightfast.daylight.mesh import load_ply

    recon, truth = load_ply(out / "scenes" / "DS1.map.ply"), load_ply(out / "scenes" / "DS1.ply")
    assert recon.content_hash != truth.content_hash  # the method's map is a reconstruction, not the truth
    recon.validate_topology()  # ready for `lightfast daylight prepare`
    meta = json.loads((seq / "sequence.json").read_text())
    start_ns = int(dt.datetime(2021, 2, 3, 12, 15, tzinfo=dt.UTC).timestamp()) * 10**9
    with open_bag(seq / "bag") as bag:
        counts = {t.name: t.message_count for t in bag.info.topics}
        assert counts == {"/camera/color/image_raw": 4, "/camera/color/camera_info": 4, "/camera/depth/image_raw": 4,
                          "/camera/depth/camera_info": 4, "/ground_truth/pose": 4}
        msgs = list(bag.messages(topics=[COLOR_TOPIC]))
        stamps = [stamp_to_ns(bag.deserialize(m).header.stamp) for m in msgs]
        assert stamps == [m.log_time_ns for m in msgs]
        assert stamps == [start_ns + round(i * 1e9 / 30) for i in range(4)]
        img = image_to_numpy(bag.deserialize(msgs[0]))
        assert img.shape == (48, 64, 3) and img.dtype == np.uint8
        depth_msg = bag.deserialize(next(iter(bag.messages(topics=[DEPTH_TOPIC]))))
        assert depth_msg.encoding == "16UC1" and image_to_numpy(depth_msg).shape == (48, 64)
        pose_msg = bag.deserialize(next(iter(bag.messages(topics=[GT_POSE_TOPIC]))))
        T, _, frame = pose_stamped_to_matrix(pose_msg)
        assert frame == "map" and 0.5 < T[2, 3] < 2.0
        first_img = bytes(msgs[0].data)
    assert meta["frames"] == 4 and meta["sequence"]["clouds"] is True
    # fields added later are left out at their defaults: recordings made before them keep their hash
    assert "sunlit_gaze_share" not in meta["params"]["spec"] and "floor_in_gaze" not in meta["params"]["spec"]
    # a complete sequence is skipped
    mtime = (seq / "sequence.json").stat().st_mtime_ns
    generate_daylight_set(out, sequences=["DS1.T6"], **TINY)
    assert (seq / "sequence.json").stat().st_mtime_ns == mtime
    # the same parameters elsewhere give the same bytes
    [seq2] = generate_daylight_set(tmp_path / "again", sequences=["DS1.T6"], **TINY)
    with open_bag(seq2 / "bag") as bag:
        assert bytes(next(iter(bag.messages(topics=[COLOR_TOPIC]))).data) == first_img
    assert (seq2 / "truth.csv").read_text() == (seq / "truth.csv").read_text()
    # other parameters re-render
    generate_daylight_set(out, sequences=["DS1.T6"], **{**TINY, "frames": 3})
    assert json.loads((seq / "sequence.json").read_text())["frames"] == 3


def test_cli_entry_point(tmp_path: Path) -> None:
    from lightfast import cli

    code = cli.main(["sim", "daylight", str(tmp_path / "out"), "--sequences", "DS2.T1", "--frames", "2", "--size",
                     "32x24", "--resolution", "0.25", "--supersample", "1", "--no-progress"])
    assert code == 0
    meta = json.loads((tmp_path / "out" / "DS2.T1" / "sequence.json").read_text())
    assert meta["params"]["width"] == 32 and meta["frames"] == 2
    with pytest.raises(SystemExit):
        cli.main(["sim", "daylight", str(tmp_path / "out"), "--size", "32by24"])


def test_held_out_recordings_by_name_only(tmp_path: Path) -> None:
    from lightfast import cli

    args = ["--frames", "2", "--size", "32x24", "--resolution", "0.25", "--supersample", "1", "--no-progress"]
    assert cli.main(["sim", "daylight", str(tmp_path / "out"), "--sequences", "DS3.H1", *args]) == 0
    meta = json.loads((tmp_path / "out" / "DS3.H1" / "sequence.json").read_text())
    assert meta["sequence"]["scene"] == "DS3" and meta["params"]["spec"]["sunlit_gaze_share"] == 0.8
    assert (tmp_path / "out" / "scenes" / "DS3.map.ply").is_file()
    assert not any(s.name.endswith(".H1") for s in SEQUENCES)  # the default set is Table I's twelve
    with pytest.raises(ValueError, match="sunlit_gaze_share"):
        replace(SEQUENCES[0], sunlit_gaze_share=1.5)
    custom = replace(SEQUENCES[6], name="DS2.X1", floor_in_gaze=True)  # any spec, not only the named ones
    [seq] = generate_daylight_set(tmp_path / "out", sequences=[custom], **TINY)
    assert json.loads((seq / "sequence.json").read_text())["params"]["spec"]["floor_in_gaze"] is True
    with pytest.raises(ValueError, match="unknown sequence"):
        generate_daylight_set(tmp_path / "out", sequences=["DS9.T1"], **TINY)


def _wall_with_box() -> ReflectanceMesh:
    """A wall at z = 3 m (facing -z) and a 0.4 m box face at z = 2 m in front of it, seen from the origin."""
    def quad(x0: float, x1: float, y0: float, y1: float, z: float) -> tuple[np.ndarray, np.ndarray]:
        v = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
        return v, np.array([[0, 2, 1], [0, 3, 2]])
    (vw, fw), (vb, fb) = quad(-5, 5, -5, 5, 3.0), quad(-0.2, 0.2, -0.2, 0.2, 2.0)
    v = np.concatenate([vw, vb])
    return ReflectanceMesh(v, np.concatenate([fw, fb + 4]), np.full(v.shape, 0.5))


def test_depth_sensor_projector_shadow_beside_an_occluding_edge() -> None:
    from lightfast.raycast import RayCaster

    mesh = _wall_with_box()
    caster = RayCaster(mesh.vertices_m, mesh.faces)
    cam = PinholeCamera(160, 120, 131.25, 131.25, 79.5, 59.5)
    z = DepthSensor().true_depth(caster, np.eye(4), cam)
    no_proj = DepthSensor(projector_baseline_m=0.0).true_depth(caster, np.eye(4), cam)
    assert (no_proj > 0).all()
    row = z[60]
    # the box spans u ≈ 66..93; the projector sits at +x, so the wall just left of the box is in its shadow (as
    # on a Kinect), width ≈ f b (1/z_box − 1/z_wall) = 131.25 · 0.075 · (1/2 − 1/3) ≈ 1.6 px
    shadow = np.flatnonzero(row == 0)
    assert 1 <= len(shadow) <= 3 and 62 <= shadow.min() and shadow.max() <= 66
    assert np.isclose(row[80], 2.0) and np.isclose(row[20], 3.0)


def test_depth_sensor_noise_is_spatially_correlated_and_distortion_systematic() -> None:
    sensor = DepthSensor(disparity_step_px=1e-6, distortion_px=0.0)
    z = np.full((240, 320), 2.0)
    errs = [sensor.measure(z, np.zeros_like(z), np.random.default_rng(s)) - z for s in range(4)]
    e = np.stack(errs)
    lag1 = np.corrcoef(e[:, :, :-1].ravel(), e[:, :, 1:].ravel())[0, 1]
    assert lag1 > 0.6  # block-correlation disparity: neighbours share their error
    white = DepthSensor(disparity_step_px=1e-6, distortion_px=0.0, correlation_px=0.0)
    w = white.measure(z, np.zeros_like(z), np.random.default_rng(0)) - z
    assert abs(np.corrcoef(w[:, :-1].ravel(), w[:, 1:].ravel())[0, 1]) < 0.05
    # random error ≈ z² / (f b) · σ_d, the same rms with or without correlation
    expect = 4.0 / sensor.focal_baseline_px_m * sensor.disparity_noise_px
    assert np.isclose(e.std(), expect, rtol=0.1) and np.isclose(w.std(), expect, rtol=0.1)
    # the systematic part repeats frame after frame and differs between centre and corners
    biased = DepthSensor(disparity_step_px=1e-6, disparity_noise_px=0.0)
    b1 = biased.measure(z, np.zeros_like(z), np.random.default_rng(1)) - z
    b2 = biased.measure(z, np.zeros_like(z), np.random.default_rng(2)) - z
    assert np.allclose(b1, b2)
    assert abs(b1[0, 0] - b1[120, 160]) > 0.005


def test_depth_camera_poses_lag_the_colour_camera() -> None:
    from lightfast.sim.daylight.trajectory import depth_camera_poses

    poses = np.repeat(np.eye(4)[None], 5, axis=0)
    poses[:, 0, 3] = 0.3 * np.arange(5) / 30.0  # 0.3 m/s along x at 30 Hz
    sensor = DepthSensor(registration_rotation_deg=0.0, registration_translation_m=0.0)
    T = depth_camera_poses(poses, 30.0, sensor)
    assert np.allclose(T[:, 0, 3], poses[:, 0, 3] - 0.3 * sensor.time_offset_s)
    reg = DepthSensor().registration()
    assert np.allclose(reg[:3, :3] @ reg[:3, :3].T, np.eye(3))
    assert np.isclose(np.linalg.norm(reg[:3, 3]), DepthSensor().registration_translation_m)
