"""Tests of the Eq. 7 RGB-D alignment (paper §III-D) in :mod:`lightfast.tracking.rgbd_odometry` and of ATE."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lightfast.camera import PinholeCamera
from lightfast.config import ConfigError
from lightfast.errors import LightfastError
from lightfast.geometry import compose, inverse, rotation_angle_deg, se3_exp
from lightfast.tracking import TrackingConfig, TrackingError, align, ate_rmse, track_sequence
from lightfast.tracking.metrics import MetricsError

DATA = Path("/work/shared/data/7scenes_redkitchen_300")
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason="7-Scenes sample data not available")
FAST = TrackingConfig(resolution_scale=0.5)


@pytest.fixture(scope="module")
def scenes():
    from lightfast.data.sevenscenes import SevenScenes

    return SevenScenes(DATA)


def _errors(T_est: np.ndarray, T_gt: np.ndarray) -> tuple[float, float]:
    E = compose(inverse(T_gt), T_est)
    return float(np.linalg.norm(E[:3, 3])), float(rotation_angle_deg(E[:3, :3]))


def _render(rgb: np.ndarray, depth_m: np.ndarray, cam: PinholeCamera, T_src_tgt: np.ndarray):
    """Forward-splat the target frame's coloured point cloud into a camera at ``T_src_tgt`` (z-buffered)."""
    P = cam.backproject_depth(depth_m).reshape(-1, 3)
    col = rgb.reshape(-1, 3)
    ok = np.isfinite(P[:, 2])
    P, col = P[ok] @ T_src_tgt[:3, :3].T + T_src_tgt[:3, 3], col[ok]
    uv, front = cam.project(P)
    inside = front & cam.in_image(uv)
    uv, P, col = uv[inside], P[inside], col[inside]
    pix = np.rint(uv[:, 1]).astype(int) * cam.width + np.rint(uv[:, 0]).astype(int)
    order = np.argsort(-P[:, 2])  # far first, near ones overwrite
    depth = np.zeros(cam.width * cam.height)
    out = np.zeros((cam.width * cam.height, 3), dtype=np.uint8)
    depth[pix[order]] = P[order, 2]
    out[pix[order]] = col[order]
    return out.reshape(cam.height, cam.width, 3), depth.reshape(cam.height, cam.width)


@needs_data
@pytest.mark.parametrize("frames", [(0, 5), (0, 10)])
def test_recovers_ground_truth_motion_on_7scenes(scenes, frames):
    a, b = scenes.frame(frames[0]), scenes.frame(frames[1])
    T_gt = compose(inverse(a.T_world_cam), b.T_world_cam)  # target a <- source b
    res = align(b.rgb, b.depth_mm / 1000.0, a.rgb, a.depth_mm / 1000.0, scenes.camera, config=FAST)
    dt, dr = _errors(res.T_target_source, T_gt)
    assert res.converged
    assert 0.5 < res.inlier_ratio <= 1.0
    assert np.isfinite(res.residual) and res.iterations > 0
    assert dt < 0.01 and dr < 0.5, (dt, dr)


@needs_data
def test_synthetic_known_motion_is_recovered(scenes):
    f = scenes.frame(0)
    depth = f.depth_mm / 1000.0
    T_tgt_src = se3_exp([0.02, -0.01, 0.015, 0.01, -0.015, 0.005])  # 2.7 cm, ~1.1°
    rgb_s, depth_s = _render(f.rgb, depth, scenes.camera, inverse(T_tgt_src))
    for use_color in (True, False):
        res = align(rgb_s, depth_s, f.rgb, depth, scenes.camera, config=FAST, use_color=use_color)
        dt, dr = _errors(res.T_target_source, T_tgt_src)
        assert res.converged
        assert dt < 0.002 and dr < 0.1, (use_color, dt, dr)


@needs_data
def test_color_only_and_depth_only_terms(scenes):
    a, b = scenes.frame(0), scenes.frame(5)
    T_gt = compose(inverse(a.T_world_cam), b.T_world_cam)
    args = (b.rgb, b.depth_mm / 1000.0, a.rgb, a.depth_mm / 1000.0, scenes.camera)
    depth_only = align(*args, config=TrackingConfig(resolution_scale=0.5, mode="depth-only"))
    color_only = align(*args, config=FAST, use_depth=False)
    for res in (depth_only, color_only):
        dt, dr = _errors(res.T_target_source, T_gt)
        assert dt < 0.01 and dr < 0.5
    # the two terms give different (independent) estimates: the switches really change the cost
    assert not np.allclose(depth_only.T_target_source, color_only.T_target_source, atol=1e-6)
    with pytest.raises(TrackingError):
        align(*args, config=FAST, use_color=False, use_depth=False)


def test_track_sequence_on_static_synthetic_scene():
    cam = PinholeCamera(width=160, height=120, fx=150.0, fy=150.0, cx=79.5, cy=59.5)
    rng = np.random.default_rng(0)
    v, u = np.mgrid[0:120, 0:160]
    rgb = (127 + 60 * np.sin(u / 5.0) * np.cos(v / 7.0) + rng.normal(0, 2, u.shape)).clip(0, 255)
    rgb = np.repeat(rgb[..., None], 3, axis=2).astype(np.uint8)
    depth = 1.5 + 0.3 * (u / 160.0) + 0.2 * np.sin(v / 15.0)  # a slanted, curved surface
    cfg = TrackingConfig(pyramid_levels=2, iterations=(10, 5))
    track = track_sequence([(rgb, depth)] * 3, cam, config=cfg)
    assert track.poses.shape == (3, 4, 4) and len(track.results) == 2 and track.seconds.shape == (2,)
    assert np.allclose(track.poses, np.eye(4), atol=1e-4)
    assert ate_rmse(track.poses, track.poses) < 1e-12


def test_invalid_inputs_raise_tracking_error():
    cam = PinholeCamera(width=64, height=48, fx=60.0, fy=60.0, cx=31.5, cy=23.5)
    rgb = np.full((48, 64, 3), 100, dtype=np.uint8)
    depth = np.full((48, 64), 1.0)
    with pytest.raises(TrackingError, match="no valid depth"):
        align(rgb, np.zeros((48, 64)), rgb, depth, cam)
    with pytest.raises(TrackingError, match="camera size"):
        align(rgb, depth, rgb[:40], depth[:40], cam)
    with pytest.raises(TrackingError, match="float metres"):
        align(rgb, depth.astype(np.uint16), rgb, depth, cam)
    with pytest.raises(TrackingError, match="4x4"):
        align(rgb, depth, rgb, depth, cam, init_T_target_source=np.eye(3))
    assert issubclass(TrackingError, LightfastError)
    with pytest.raises(ConfigError):
        TrackingConfig(pyramid_levels=2)  # iterations must have one entry per level
    with pytest.raises(ConfigError):
        TrackingConfig(mode="nonsense")


def test_ate_rmse_is_invariant_to_rigid_alignment():
    rng = np.random.default_rng(1)
    gt = np.repeat(np.eye(4)[None], 20, axis=0)
    gt[:, :3, 3] = rng.normal(size=(20, 3))
    G = se3_exp([1.0, -2.0, 0.5, 0.3, 0.2, -0.1])
    est = G @ gt
    assert ate_rmse(est, gt) < 1e-9
    noisy = est.copy()
    noisy[:, :3, 3] += rng.normal(0, 0.01, size=(20, 3))
    assert 0.003 < ate_rmse(noisy, gt) < 0.02
    with pytest.raises(MetricsError):
        ate_rmse(est[:5], gt)
