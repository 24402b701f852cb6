"""The rACR simulator (paper §5.1): scenes, Embree renderer, platform, VSE stand-in, AFD and scene files.

Scenes are built small (coarse meshes, tiny images) so the module runs in seconds.
"""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from lightfast import cli
from lightfast.geometry import inverse, make_transform, rotation_angle_deg, so3_exp, so3_log
from lightfast.racr.errors import ReferenceFileError
from lightfast.racr.reference import REFERENCE_FORMAT, load_reference, write_reference
from lightfast.sim.errors import PlatformError, RacrSimError
from lightfast.sim.racr import (
    build_scene,
    camera_for_size,
    generate_racr_set,
    load_scene,
    scene_complete,
    scene_specs,
    write_scene,
)
from lightfast.sim.racr_platform import PlatformConfig, PlatformSimulator, VseConfig, motion_duration_s

TINY = {"width": 96, "height": 72, "resolution_m": 0.012}


@pytest.fixture(scope="module")
def indoor():
    """S01 (indoor, point light), coarse."""
    return build_scene(scene_specs()[0], width=160, height=120, resolution_m=0.01)


def _umeyama_scale(src: np.ndarray, dst: np.ndarray) -> float:
    """Scale of the best similarity dst ≈ s R src + t (Umeyama)."""
    ms, md = src.mean(0), dst.mean(0)
    A, B = src - ms, dst - md
    U, S, Vt = np.linalg.svd(B.T @ A / len(src))
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt))
    return float(np.trace(np.diag(S) @ D) / (A**2).sum(1).mean())


# ------------------------------------------------------------------------------------------------------------
# scenes and renderer


def test_twenty_scenes_with_three_lightings() -> None:
    specs = scene_specs()
    assert [s.name for s in specs] == [f"S{i:02d}" for i in range(1, 21)]
    assert [s.kind for s in specs] == ["indoor"] * 10 + ["outdoor"] * 10
    for s in specs:
        assert [lt.name for lt in s.lighting] == ["reference", "similar", "varied"]
        assert 0.3 <= s.vse_scale_m_per_vse <= 3.0
        assert s.lighting[0].kind == ("point" if s.kind == "indoor" else "daylight")
    assert {s.recipe for s in specs} == {"panel", "tablet", "cabinet", "motor", "stupa", "facade", "bogie"}
    assert specs == scene_specs() and specs != scene_specs(seed=1)


def test_render_is_deterministic_with_a_seed(indoor) -> None:
    T = indoor.truth.T_world_camref
    a = indoor.render(T, "reference", seed=5)
    b = indoor.render(T, "reference", seed=5)
    c = indoor.render(T, "reference", seed=6)
    assert a.image.shape == (120, 160, 3) and a.image.dtype == np.uint8
    assert np.array_equal(a.image, b.image) and np.array_equal(a.radiance, b.radiance)
    assert np.array_equal(a.depth_m, b.depth_m)
    assert not np.array_equal(a.image, c.image)  # sensor noise follows the seed
    assert np.array_equal(a.radiance, c.radiance)
    assert a.hit.mean() > 0.95 and np.all(a.depth_m[a.hit] > 0.2)
    # the image has texture and shading structure (features exist)
    g = a.image.mean(axis=2)
    assert np.percentile(np.abs(np.diff(g, axis=1)), 90) > 3.0


def test_point_light_casts_shadows(indoor) -> None:
    T = indoor.truth.T_world_camref
    lit = indoor.lighting("varied")
    assert lit.point_position_m is not None
    r = indoor.renderer
    with_sh = r.render(T, indoor.camera, lit)
    without = r.render(T, indoor.camera, lit, shadows=False)
    sh = with_sh.shadow
    assert sh.mean() > 0.01  # grazing side light: long shadows
    L1, L0 = with_sh.radiance.sum(axis=2), without.radiance.sum(axis=2)
    assert np.all(L1[sh] < L0[sh])  # shadowed pixels are darker than their unshadowed shading
    assert np.median(L1[sh] / L0[sh]) < 0.5
    assert np.allclose(L1[~sh], L0[~sh])
    # the lighting variants really differ in appearance; the front light casts fewer shadows
    ref = r.render(T, indoor.camera, indoor.lighting("reference"))
    assert ref.shadow.mean() < sh.mean()
    # Fig. 7: extra point-light variants at any clock position, auto-exposed
    name = indoor.add_clock_lighting(3.0)
    assert name == "clock3" and indoor.lightings[name].exposure > 0
    right = np.asarray(indoor.lightings[name].position_m) - indoor.truth.target_m
    assert right @ T[:3, 0] > 0.5 * np.linalg.norm(right)  # 3 o'clock: on the camera's right
    assert indoor.render(T, name).image.mean() > 10


def test_look_and_intrinsics() -> None:
    cam = camera_for_size(640, 480)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (525.0, 525.0, 319.5, 239.5)


# ------------------------------------------------------------------------------------------------------------
# platform


def test_platform_error_statistics() -> None:
    cfg = PlatformConfig(rotation_noise_frac=0.02, rotation_noise_floor_deg=0.0, translation_noise_frac=0.03,
                         translation_noise_floor_m=0.0, rotation_bias_frac=0.01, translation_bias_frac=-0.02)
    p = PlatformSimulator(np.eye(4), np.eye(4), config=cfg, seed=3)
    rng = np.random.default_rng(0)
    rot_ratio, rot_res, tr_ratio, tr_res = [], [], [], []
    for _ in range(1200):
        phi = rng.normal(size=3)
        phi *= math.radians(rng.uniform(2, 10)) / np.linalg.norm(phi)
        t = rng.normal(size=3)
        t *= rng.uniform(0.01, 0.1) / np.linalg.norm(t)
        M_true = p.perturb(make_transform(so3_exp(phi), t))
        th, L = np.linalg.norm(phi), np.linalg.norm(t)
        phi_t = so3_log(M_true[:3, :3])
        rot_ratio.append(phi_t @ phi / th**2)
        rot_res.append((phi_t - 1.01 * phi) / th)
        tr_ratio.append(M_true[:3, 3] @ t / L**2)
        tr_res.append((M_true[:3, 3] - 0.98 * t) / L)
    assert np.mean(rot_ratio) == pytest.approx(1.01, abs=2e-3)
    assert np.mean(tr_ratio) == pytest.approx(0.98, abs=3e-3)
    assert np.std(np.concatenate(rot_res)) == pytest.approx(0.02, rel=0.05)
    assert np.std(np.concatenate(tr_res)) == pytest.approx(0.03, rel=0.05)


def test_platform_time_model_reports_and_truth() -> None:
    X = make_transform(so3_exp([0.2, -0.3, 0.1]), [0.05, -0.02, 0.08])
    T0 = make_transform(so3_exp([0.0, 0.0, 1.0]), [0.3, -0.8, 0.4])
    base = make_transform(so3_exp([0.0, 0.0, 0.5]), [1.0, 2.0, 0.0])
    p = PlatformSimulator(T0, X, T_world_base=base, seed=1)
    assert np.allclose(p.true_camera_pose, T0 @ inverse(X))
    assert np.allclose(p.reported_hand_pose, inverse(base) @ T0)
    assert p.execute(make_transform(np.eye(3), [0.1, 0.0, 0.0])) == pytest.approx(15.0)  # 1.5 s per cm
    assert p.execute(make_transform(so3_exp([0.0, math.radians(10.0), 0.0]), [0, 0, 0])) == pytest.approx(5.0)
    assert p.execute(np.eye(4)) == 0.0
    assert p.clock_s == pytest.approx(20.0) and len(p.motions) == 3
    M = make_transform(so3_exp([0.05, 0.02, -0.03]), [0.01, -0.02, 0.015])
    cfg = PlatformConfig(seconds_per_cm=2.0, seconds_per_deg=0.25, settle_s=1.0)
    expected = 1.0 + 2.0 * 100 * np.linalg.norm(M[:3, 3]) + 0.25 * math.degrees(np.linalg.norm([0.05, 0.02, -0.03]))
    assert motion_duration_s(M, cfg) == pytest.approx(expected)
    # encoders report the commanded motions; the truth carries the mechanical error
    cmd = np.eye(4)
    for Mi in [r.M_commanded for r in p.motions]:
        cmd = cmd @ Mi
    assert np.allclose(p.reported_hand_pose, inverse(base) @ T0 @ cmd)
    true = T0.copy()
    for r in p.motions:
        true = true @ r.M_true
    assert np.allclose(p.true_hand_pose, true)
    assert not np.allclose(p.true_hand_pose, base @ p.reported_hand_pose, atol=1e-6)
    assert np.allclose(p.true_camera_pose, p.true_hand_pose @ inverse(X))
    # camera motion = X M X^-1 for the true hand motion
    before = p.true_camera_pose
    p.execute(M)
    assert np.allclose(inverse(before) @ p.true_camera_pose, X @ p.motions[-1].M_true @ inverse(X))


def test_platform_refuses_garbage_without_moving() -> None:
    p = PlatformSimulator(np.eye(4), np.eye(4), seed=0)
    bad = [np.full((4, 4), np.nan), np.ones((3, 3)), np.diag([2.0, 1.0, 1.0, 1.0]),
           make_transform(np.eye(3), [1.0, 0.0, 0.0]), make_transform(so3_exp([0.0, 0.0, 2.5]), [0.0, 0.0, 0.0])]
    for M in bad:
        with pytest.raises(PlatformError):
            p.execute(M)
    assert np.array_equal(p.true_hand_pose, np.eye(4)) and p.clock_s == 0.0 and not p.motions


# ------------------------------------------------------------------------------------------------------------
# VSE stand-in


def test_vse_cloud_has_the_configured_scale(indoor) -> None:
    s = 2.5
    vse = indoor.make_vse("varied", scale_m_per_vse=s, seed=2)
    T0 = indoor.truth.T_world_cam0
    obs = vse.observe(T0)
    assert obs.points_vse.dtype == np.float32 and obs.points_vse.shape[1] == 3 and len(obs.points_vse) > 200
    assert obs.intensity.shape == (len(obs.points_vse),) and 0.0 <= obs.intensity.min() <= obs.intensity.max() <= 1
    assert len(obs.keyframes) == 4 and obs.keyframes[0].image.ndim == 2
    truth = vse.truth
    assert truth.scale_m_per_vse == s
    # Umeyama similarity from the VSE cloud to the true metric points recovers s (noise, outliers: 1 %)
    assert _umeyama_scale(obs.points_vse.astype(float), truth.points_world) == pytest.approx(s, rel=0.01)
    # the first observation defines the VSE frame: the current pose is (nearly) the identity
    assert np.linalg.norm(obs.T_vse_cam[:3, 3]) < 1e-3 and rotation_angle_deg(obs.T_vse_cam) < 0.1
    # a platform motion: the VSE translation times s is the metric camera translation (slight drift only)
    plat = indoor.make_platform(seed=0)
    assert np.allclose(plat.true_camera_pose, T0)
    plat.execute(make_transform(so3_exp([0.0, 0.05, 0.0]), [0.04, 0.0, 0.01]))
    T1 = plat.true_camera_pose
    M_A_vse = inverse(vse.pose(T0)) @ vse.pose(T1)
    M_A_true = inverse(T0) @ T1
    assert np.linalg.norm(s * M_A_vse[:3, 3] - M_A_true[:3, 3]) < 0.05 * np.linalg.norm(M_A_true[:3, 3])
    assert rotation_angle_deg(M_A_vse, M_A_true) < 0.2


def test_vse_drift_grows_with_path(indoor) -> None:
    cfg = VseConfig(drift_rotation_deg_per_m=2.0, drift_translation_per_m=0.05, drift_scale_per_m=0.05,
                    pose_noise_deg=0.0, pose_noise_m=0.0)
    vse = indoor.make_vse("reference", config=cfg, scale_m_per_vse=1.0, seed=4)
    T = indoor.truth.T_world_camref
    vse.pose(T)
    assert np.allclose(vse.truth.drift, np.eye(4))
    for k in range(10):
        vse.pose(T @ make_transform(np.eye(3), [0.02 * (k % 2), 0.0, 0.0]))
    assert not np.allclose(vse.truth.drift, np.eye(4), atol=1e-5)
    assert np.abs(vse.truth.drift - np.eye(4)).max() < 0.1  # slight


# ------------------------------------------------------------------------------------------------------------
# AFD


def test_afd_zero_at_reference_and_growing_with_offset(indoor) -> None:
    T = indoor.truth.T_world_camref
    r0 = indoor.afd(T)
    assert r0.afd_px == pytest.approx(0.0, abs=1e-6) and r0.success and r0.n_visible == r0.n_points > 100
    values = []
    for d in (0.002, 0.005, 0.01, 0.02, 0.04):
        values.append(indoor.afd(T @ make_transform(np.eye(3), [d, 0.0, 0.0])).afd_px)
    assert np.all(np.diff(values) > 0)
    assert values[0] < 3.0 < values[-1]
    rot = indoor.afd(T @ make_transform(so3_exp([0.0, math.radians(2.0), 0.0]), [0, 0, 0]))
    # a 2 deg pan moves every point by at least fx * tan(2 deg) pixels (more towards the image border)
    f_theta = indoor.camera.fx * math.tan(math.radians(2.0))
    assert f_theta <= rot.afd_px < 1.3 * f_theta
    assert not rot.success


def test_truth_driven_adjustments_converge(indoor) -> None:
    """Eq. 3 with the true X and true poses (in place of rACR's estimates) drives the simulated platform to the
    reference despite its mechanical error: the simulator's conventions match the paper's M_A X = X M_B."""
    plat = indoor.make_platform(seed=7)
    X = plat.truth_T_cam_hand
    T_ref = indoor.truth.T_world_camref
    afds = [indoor.afd(plat.true_camera_pose).afd_px]
    for _ in range(6):
        M_B = inverse(X) @ inverse(plat.true_camera_pose) @ T_ref @ X
        plat.execute(M_B)
        afds.append(indoor.afd(plat.true_camera_pose).afd_px)
    assert afds[0] > 10.0 and afds[-1] < 0.5 and afds[1] < 0.2 * afds[0]
    assert plat.clock_s > 0.0


# ------------------------------------------------------------------------------------------------------------
# files


def _same_scene(a, b) -> None:
    assert a.spec == b.spec and a.lightings == b.lightings and a.camera == b.camera
    assert np.array_equal(a.mesh.vertices_m, b.mesh.vertices_m) and np.array_equal(a.mesh.faces, b.mesh.faces)
    assert np.array_equal(a.mesh.reflectance, b.mesh.reflectance)
    for name in ("T_world_camref", "T_camref_cam0", "T_cam_hand", "T_world_base", "T_world_ref",
                 "afd_points_world", "afd_pixels_ref"):
        assert np.array_equal(getattr(a.truth, name), getattr(b.truth, name)), name
    assert a.truth.vse_scale_m_per_vse == b.truth.vse_scale_m_per_vse
    ra, rb = a.reference, b.reference
    assert np.array_equal(ra.points_m, rb.points_m) and np.array_equal(ra.intensity, rb.intensity)
    assert np.array_equal(ra.image, rb.image) and np.array_equal(ra.T_ref_camref, rb.T_ref_camref)
    assert ra.camera == rb.camera and ra.scene == rb.scene
    assert a.platform_config == b.platform_config and a.vse_config == b.vse_config


def test_scene_directory_round_trip(indoor, tmp_path: Path) -> None:
    d = write_scene(indoor, tmp_path / "S01", params_hash="abc")
    assert scene_complete(d, "abc") and not scene_complete(d, "other")
    loaded = load_scene(d)
    _same_scene(indoor, loaded)
    # rendering the loaded scene gives the same image
    T = indoor.truth.T_world_cam0
    assert np.array_equal(indoor.render(T, "similar", seed=1).image, loaded.render(T, "similar", seed=1).image)
    # the reference directory holds no truth
    ref_dir = d / "reference"
    assert sorted(p.name for p in ref_dir.iterdir()) == ["image.png", "points.npz", "reference.yaml"]
    doc = yaml.safe_load((ref_dir / "reference.yaml").read_text())
    assert doc["format"] == REFERENCE_FORMAT and doc["format_version"] == 1
    assert not {k for k in doc if "world" in k or "hand" in k or "truth" in k}
    with np.load(ref_dir / "points.npz", allow_pickle=False) as z:
        assert sorted(z.files) == ["intensity", "points_m"]
    scene_doc = yaml.safe_load((d / "scene.yaml").read_text())
    assert "T_cam_hand" in scene_doc["truth"] and "T_cam_hand" not in scene_doc
    assert {"reference", "similar", "varied"} <= set(scene_doc["lighting"])
    assert (d / "truth.yaml").is_file() and (d / "mesh.ply").is_file()


def test_reference_loader_refuses_bad_input(indoor, tmp_path: Path) -> None:
    with pytest.raises(ReferenceFileError, match=r"reference\.yaml missing"):
        load_reference(tmp_path / "nothing")
    d = write_reference(indoor.reference, tmp_path / "ref")
    assert load_reference(d, scene="S01").points_m.shape == indoor.reference.points_m.shape
    with pytest.raises(ReferenceFileError, match="scene 'S01', not 'S02'"):
        load_reference(d, scene="S02")
    doc = yaml.safe_load((d / "reference.yaml").read_text())
    doc["format_version"] = 99
    (d / "reference.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(ReferenceFileError, match="format_version"):
        load_reference(d)
    d2 = write_reference(indoor.reference, tmp_path / "ref2")
    (d2 / "points.npz").write_bytes(b"garbage")
    with pytest.raises(ReferenceFileError, match="reference cloud"):
        load_reference(d2)
    d3 = write_reference(indoor.reference, tmp_path / "ref3")  # truncated: zipfile raised through racr_node
    data = (d3 / "points.npz").read_bytes()
    (d3 / "points.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ReferenceFileError, match="reference cloud is damaged or truncated"):
        load_reference(d3)
    d4 = write_reference(indoor.reference, tmp_path / "ref4")
    (d4 / "reference.yaml").write_text("format: [unclosed\n")
    with pytest.raises(ReferenceFileError, match="cannot read a reference observation"):
        load_reference(d4)


def test_generate_caches_and_rebuilds_half_written(tmp_path: Path) -> None:
    out = tmp_path / "racr"
    assert cli.main(["sim", "racr", str(out), "--only", "S02", "S15", "--size", "96x72", "--resolution", "0.012",
                          "--no-progress"]) == 0
    dirs = [out / "S02", out / "S15"]
    assert all(scene_complete(d) for d in dirs)
    s15 = load_scene(out / "S15")
    assert s15.spec.kind == "outdoor" and s15.lightings["reference"].kind == "daylight"
    assert s15.lightings["varied"].kind == "point"  # S15: relocalized at night under a floodlight
    assert s15.lightings["reference"].sun_elevation_deg > 0
    assert len(list((out / "S15" / "preview").glob("*.png"))) == 3
    stamp = {d: (d / "scene.json").stat().st_mtime_ns for d in dirs}
    manifest = json.loads((out / "S02" / "scene.json").read_text())
    assert "mesh.ply" in manifest["files"] and manifest["stats"]["triangles"] > 1000
    # a rerun with the same parameters reuses both
    generate_racr_set(out, scenes=["S02", "S15"], **TINY)
    assert {d: (d / "scene.json").stat().st_mtime_ns for d in dirs} == stamp
    # half-written: a truncated file makes the scene incomplete; it is rebuilt, the other one is reused
    ply = out / "S02" / "mesh.ply"
    ply.write_bytes(ply.read_bytes()[:1000])
    assert not scene_complete(out / "S02")
    with pytest.raises(RacrSimError, match="not a complete"):
        load_scene(out / "S02")
    generate_racr_set(out, scenes=["S02", "S15"], **TINY)
    assert scene_complete(out / "S02")
    assert (out / "S02" / "scene.json").stat().st_mtime_ns != stamp[out / "S02"]
    assert (out / "S15" / "scene.json").stat().st_mtime_ns == stamp[out / "S15"]
    # a missing manifest (interrupted before the end) is never reused either
    (out / "S15" / "scene.json").unlink()
    assert not scene_complete(out / "S15")
    shutil.rmtree(out / "S15")
    # other parameters: rebuilt
    generate_racr_set(out, scenes=["S02"], width=80, height=60, resolution_m=0.012)
    assert (out / "S02" / "scene.json").stat().st_mtime_ns != stamp[out / "S02"]
    assert load_scene(out / "S02").camera.width == 80
