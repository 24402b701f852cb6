"""Tests of the Eq. 7 RGB-D alignment (paper §III-D) in :mod:`lightfast.tracking.rgbd_odometry` and of ATE."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lightfast.camera import PinholeCamera
from lightfast.config import ConfigError
from lightfast.errors import LightfastError
from lightfast.geometry import compose, inverse, rotation_angle_deg, se3_exp, se3_log
from lightfast.tracking import TrackingConfig, align, ate_rmse, motion_rmse, own_errors, track_sequence
from lightfast.tracking.errors import MetricsError, TrackingError, TrackingInputError
from lightfast.tracking.pipeline import TrackerConfig
from lightfast.tracking.rgbd_odometry import GEOMETRIC_TERMS, MOTION_PRIORS, MotionPrior, predict_motion

FAST = TrackingConfig(resolution_scale=0.5)


@pytest.fixture(scope="module")
def scenes(sevenscenes_dir: Path):
    """The real 7-Scenes frames, read in place from the shared data (conftest: ``$LIGHTFAST_SHARED`` or
    ``../shared``)."""
    from lightfast.data.sevenscenes import SevenScenes

    return SevenScenes(sevenscenes_dir)


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


def test_synthetic_known_motion_is_recovered(scenes):
    f = scenes.frame(0)
    depth = f.depth_mm / 1000.0
    T_tgt_src = se3_exp([0.02, -0.01, 0.015, 0.01, -0.015, 0.005])  # 2.7 cm, ~1.1°
    rgb_s, depth_s = _render(f.rgb, depth, scenes.camera, inverse(T_tgt_src))
    for use_color in (True, False):
        for term in GEOMETRIC_TERMS:
            cfg = dataclasses.replace(FAST, geometric_term=term)
            res = align(rgb_s, depth_s, f.rgb, depth, scenes.camera, config=cfg, use_color=use_color)
            dt, dr = _errors(res.T_target_source, T_tgt_src)
            assert res.converged
            assert dt < 0.002 and dr < 0.1, (use_color, term, dt, dr)


def test_tracker_prior_costs_little_near_its_start(scenes):
    """The tracker's f2f prior sits at the constant-velocity prediction, a few mm from the truth: there it holds
    back less than half of that offset, with or without the colour term."""
    f = scenes.frame(0)
    depth = f.depth_mm / 1000.0
    T_tgt_src = se3_exp([0.02, -0.01, 0.015, 0.01, -0.015, 0.005])
    rgb_s, depth_s = _render(f.rgb, depth, scenes.camera, inverse(T_tgt_src))
    start = T_tgt_src @ se3_exp([0.002, -0.001, 0.001, 0.001, 0.0, -0.001])  # 2.4 mm, 0.08° off
    offset = float(np.linalg.norm(start[:3, 3] - T_tgt_src[:3, 3]))
    cfg = dataclasses.replace(FAST, pose_prior_weight=TrackerConfig().pose_prior_weight)
    for use_color in (True, False):
        res = align(rgb_s, depth_s, f.rgb, depth, scenes.camera, config=cfg, init_T_target_source=start,
                    use_color=use_color)
        dt, _ = _errors(res.T_target_source, T_tgt_src)
        assert dt < 0.5 * offset, (use_color, dt, offset)


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


def test_repeated_images_of_unsynchronised_kinect_streams(scenes):
    """7-Scenes' colour and depth streams repeat images (frame 222 repeats 221's depth with a new colour image,
    258 repeats 257's colour with a new depth image; the ground truth follows the depth). A repeated depth image is
    not aligned: the frame keeps its predecessor's pose, and the next frame is aligned to the predecessor. A colour
    image alone repeated is aligned by E_G only. Both terms on either pair fit a motion one image did not make."""
    from lightfast.tracking import prepare_frame, repeated_input

    def frames(ids):
        return [scenes.frame(i) for i in ids]

    def step_error_mm(track, gt, k):
        E = compose(inverse(compose(inverse(gt[k - 1]), gt[k])), compose(inverse(track.poses[k - 1]),
                                                                           track.poses[k]))
        return 1000.0 * float(np.linalg.norm(E[:3, 3]))

    for ids, k, kind, bound_mm in (((220, 221, 222, 223), 2, "depth", 1.0), ((256, 257, 258, 259), 2, "colour", 6.0)):
        fr = frames(ids)
        prepared = [prepare_frame(f.rgb, f.depth_mm / 1000.0, scenes.camera, config=FAST) for f in fr]
        assert repeated_input(prepared[k], prepared[k - 1]) == kind
        assert repeated_input(prepared[k - 1], prepared[k - 2]) == ""
        track = track_sequence([(f.rgb, f.depth_mm / 1000.0) for f in fr], scenes.camera, config=FAST)
        gt = [f.T_world_cam for f in fr]
        assert (track.results[k - 1] is None) == (kind == "depth")
        if kind == "depth":
            np.testing.assert_array_equal(track.poses[k], track.poses[k - 1])
        error_mm = step_error_mm(track, gt, k)
        assert error_mm < bound_mm
        a, b = fr[k - 1], fr[k]  # the same pair with both terms: millimetres more
        both = align(b.rgb, b.depth_mm / 1000.0, a.rgb, a.depth_mm / 1000.0, scenes.camera, config=FAST)
        T_gt = compose(inverse(a.T_world_cam), b.T_world_cam)
        assert 1000.0 * _errors(both.T_target_source, T_gt)[0] > error_mm + 3.0
        assert step_error_mm(track, gt, k + 1) < 10.0  # the next frame is tracked on


def test_t_distribution_scale_fits_t_distributed_residuals():
    """The fixed point of Kerl et al. (ICRA 2013, Eq. 10-11) recovers the scale of t-distributed residuals."""
    from lightfast.tracking.rgbd_odometry.kernels import _t_scale

    rng = np.random.default_rng(3)
    for scale in (0.01, 0.3):
        buf = np.zeros((20000, 14))
        buf[:, 7] = scale * rng.standard_t(5.0, size=len(buf))
        assert _t_scale(buf, len(buf), 7, 5.0) == pytest.approx(scale, rel=0.03)


@pytest.mark.parametrize("frames", [(0, 5), (0, 10)])
def test_t_distribution_norm_recovers_ground_truth_motion_on_7scenes(scenes, frames):
    a, b = scenes.frame(frames[0]), scenes.frame(frames[1])
    T_gt = compose(inverse(a.T_world_cam), b.T_world_cam)
    cfg = dataclasses.replace(FAST, robust_norm="t-distribution", geometric_weight=1.0)
    res = align(b.rgb, b.depth_mm / 1000.0, a.rgb, a.depth_mm / 1000.0, scenes.camera, config=cfg)
    dt, dr = _errors(res.T_target_source, T_gt)
    assert res.converged and dt < 0.01 and dr < 0.5


def test_pose_prior_holds_directions_a_plain_wall_leaves_free():
    """A flat wall constrains depth and two rotations; a shading ramp that differs between the frames (as a relit
    reference's small reflectance error does) then drags plain Gauss-Newton along the wall. The prior at the start
    pose resists where the data is weak (textured scenes keep their accuracy: see the 7-Scenes tests)."""
    cam = PinholeCamera(width=160, height=120, fx=150.0, fy=150.0, cx=79.5, cy=59.5)
    rng = np.random.default_rng(1)
    u = np.mgrid[0:120, 0:160][1]

    def wall(shift_px: float) -> tuple[np.ndarray, np.ndarray]:
        grey = 100 + 40 * (u + shift_px) / 160.0 + rng.normal(0, 1.0, u.shape)
        return np.repeat(grey[..., None], 3, axis=2).clip(0, 255).astype(np.uint8), 1.5 + rng.normal(0, 1e-3, u.shape)

    live, reference = wall(0.0), wall(5.0)  # the ramp 5 px (5 cm at 1.5 m) apart, the geometry identical
    free = align(*live, *reference, cam, config=TrackingConfig())  # Eq. 7 alone
    held = align(*live, *reference, cam, config=TrackingConfig(pose_prior_weight=TrackerConfig().pose_prior_weight))
    assert np.linalg.norm(free.T_target_source[:3, 3]) > 0.04  # slides the whole 5 cm along the wall
    assert np.linalg.norm(held.T_target_source[:3, 3]) < 0.005


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


def test_own_errors_recover_each_estimates_error_without_the_truth():
    rng = np.random.default_rng(3)
    n = 400
    s = np.linspace(0.0, 2.0 * np.pi, n)
    truth = np.stack([np.cos(s), np.sin(2 * s), 0.3 * s], axis=1)  # m
    # independent drifts (random walks) of different sizes, each estimate also rigidly moved
    est = {}
    for name, step_m in (("a", 0.0004), ("b", 0.0008), ("c", 0.0012), ("d", 0.002)):
        G = se3_exp(rng.normal(0.0, 0.3, size=6))
        p = truth + np.cumsum(rng.normal(0.0, step_m, size=(n, 3)), axis=0)
        est[name] = p @ G[:3, :3].T + G[:3, 3]
    out = own_errors(est)
    for name, p in est.items():
        assert out.own_m[name] == pytest.approx(ate_rmse(p, truth), rel=0.2), name
    assert out.pairwise_m[("a", "b")] == pytest.approx(ate_rmse(est["a"], est["b"]))
    # an error the others share is counted as the odd one's own: "b", "c", "d" drift alike, "a" does not
    common = np.cumsum(rng.normal(0.0, 0.002, size=(n, 3)), axis=0)
    shared = {"a": est["a"], **{k: v + common for k, v in est.items() if k != "a"}}
    moved = own_errors(shared)
    assert moved.own_m["a"] > 2.0 * out.own_m["a"]
    with pytest.raises(MetricsError):
        own_errors({"a": truth, "b": truth})


def test_own_errors_of_the_frame_to_frame_motions():
    rng = np.random.default_rng(4)
    n = 300
    motions = [se3_exp(np.r_[rng.normal(0.0, 0.005, 3), rng.normal(0.0, 0.003, 3)]) for _ in range(n - 1)]

    def chain(noise_m: float) -> np.ndarray:
        poses = [np.eye(4)]
        for M in motions:
            poses.append(poses[-1] @ M @ se3_exp(np.r_[rng.normal(0.0, noise_m, 3), 0.0, 0.0, 0.0]))
        return np.stack(poses)

    truth = chain(0.0)
    est = {name: chain(noise) for name, noise in (("a", 0.0005), ("b", 0.001), ("c", 0.002))}
    out = own_errors(est, distance=motion_rmse)
    for name, poses in est.items():
        assert out.own_m[name] == pytest.approx(motion_rmse(poses, truth), rel=0.15), name
    assert motion_rmse(truth, truth) < 1e-12
    with pytest.raises(MetricsError):
        motion_rmse(truth[:5], truth)


def _reference_terms(src, tgt, T, cfg, use_color, use_depth):
    """Eq. 7 normal equations written out with NumPy (independent of the fused kernel): nearest-pixel
    association with the occlusion test, bilinear intensity/gradient, point-to-plane or depth difference (target
    depth and its Sobel gradient bilinear at the projection, all four pixels around it with a gradient), Huber IRLS
    weights."""
    cam = tgt.camera
    q = src.points.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
    z = q[:, 2]
    u = cam.fx * q[:, 0] / z + cam.cx
    v = cam.fy * q[:, 1] / z + cam.cy
    keep = (z > 1e-6) & (u >= 0) & (u <= cam.width - 1.001) & (v >= 0) & (v <= cam.height - 1.001)
    iu, iv = np.floor(u[keep] + 0.5).astype(int), np.floor(v[keep] + 0.5).astype(int)
    geo = tgt.geometry[iv, iu].astype(np.float64)
    ok = (geo[:, 0] > 0) & (np.abs(geo[:, 0] - z[keep]) <= cfg.depth_outlier_trunc_m)
    depth_difference = cfg.geometric_term == "depth-difference"
    u0, v0 = np.floor(u[keep]).astype(int), np.floor(v[keep]).astype(int)
    if use_depth and depth_difference:
        dg = tgt.depth_grad.astype(np.float64)
        for dv, du in ((0, 0), (0, 1), (1, 0), (1, 1)):
            ok &= np.isfinite(dg[v0 + dv, u0 + du, 0])
    elif use_depth:
        ok &= np.isfinite(geo[:, 4])
    idx = np.flatnonzero(keep)[ok]
    q, u, v, geo = q[idx], u[idx], v[idx], geo[ok]
    H, b = np.zeros((6, 6)), np.zeros(6)

    def bilinear(image):
        """``image`` (H, W, C) bilinearly interpolated at the projections (u, v) of the kept points."""
        x0, y0 = np.floor(u).astype(int), np.floor(v).astype(int)
        a, c = (u - x0)[:, None], (v - y0)[:, None]
        return ((1 - a) * (1 - c) * image[y0, x0] + a * (1 - c) * image[y0, x0 + 1] + (1 - a) * c * image[y0 + 1, x0]
                + a * c * image[y0 + 1, x0 + 1])

    def add(J, r, delta, weight):
        w = weight * np.minimum(1.0, delta / np.maximum(np.abs(r), 1e-30))
        H[...] += (J * w[:, None]).T @ J
        b[...] += (J * w[:, None]).T @ r

    if use_color:
        s = bilinear(tgt.grey_grad.astype(np.float64))
        r = s[:, 0] - src.point_grey[idx]
        grad = np.stack([s[:, 1] * cam.fx / q[:, 2], s[:, 2] * cam.fy / q[:, 2], np.zeros(len(q))], axis=1)
        grad[:, 2] = -(grad[:, 0] * q[:, 0] + grad[:, 1] * q[:, 1]) / q[:, 2]
        add(np.concatenate([grad, np.cross(q, grad)], axis=1), r, cfg.intensity_huber_delta, 1.0)
    if use_depth and depth_difference:
        grad = bilinear(tgt.depth_grad.astype(np.float64))
        J = np.stack([grad[:, 0] * cam.fx / q[:, 2], grad[:, 1] * cam.fy / q[:, 2], np.zeros(len(q))], axis=1)
        J[:, 2] = -(J[:, 0] * q[:, 0] + J[:, 1] * q[:, 1]) / q[:, 2] - 1.0
        r = bilinear(tgt.geometry[..., :1].astype(np.float64))[:, 0] - q[:, 2]
        add(np.concatenate([J, np.cross(q, J)], axis=1), r, cfg.geometric_huber_delta_m, cfg.geometric_weight)
    elif use_depth:
        n = geo[:, 4:7]
        r = np.einsum("ij,ij->i", n, q - geo[:, 1:4])
        add(np.concatenate([n, np.cross(q, n)], axis=1), r, cfg.geometric_huber_delta_m, cfg.geometric_weight)
    return H, b, len(idx)


@pytest.mark.parametrize("term", GEOMETRIC_TERMS)
@pytest.mark.parametrize("use_color,use_depth", [(True, True), (True, False), (False, True)])
def test_fused_kernel_matches_numpy_normal_equations(scenes, use_color, use_depth, term):
    from lightfast.tracking import prepare_frame
    from lightfast.tracking.rgbd_odometry.kernels import linearize

    a, b = scenes.frame(0), scenes.frame(5)
    src = prepare_frame(b.rgb, b.depth_mm / 1000.0, scenes.camera, config=FAST)
    tgt = prepare_frame(a.rgb, a.depth_mm / 1000.0, scenes.camera, config=FAST)
    T = se3_exp([0.01, -0.005, 0.008, 0.004, -0.006, 0.003])
    cfg = dataclasses.replace(FAST, geometric_term=term)
    for level in range(FAST.pyramid_levels):
        terms = linearize(src.levels[level], tgt.levels[level], T, cfg, use_color, use_depth)
        H, g, count = _reference_terms(src.levels[level], tgt.levels[level], T, cfg, use_color, use_depth)
        assert abs(terms.count - count) <= max(2, count // 2000)  # float32 vs float64 at the borders
        np.testing.assert_allclose(terms.H, H, rtol=2e-3, atol=1e-6 * np.abs(H).max())
        np.testing.assert_allclose(terms.b, g, rtol=5e-3, atol=2e-3 * np.abs(g).max())


def test_depth_gradient_of_a_slanted_plane_and_its_invalid_pixels():
    """The depth-difference term's target gradient: exact on a plane (Sobel of a linear ramp), NaN next to missing
    depth and across a step larger than the discontinuity threshold."""
    from lightfast.tracking import prepare_frame

    cam = PinholeCamera(64, 48, 60.0, 60.0, 31.5, 23.5)
    v, u = np.mgrid[0:48, 0:64].astype(np.float64)
    depth = 1.5 + 0.004 * u - 0.002 * v
    depth[10, 20] = 0.0  # a hole
    depth[:, 40:] += 0.3  # a step
    rgb = np.zeros((48, 64, 3), np.uint8)
    grad = prepare_frame(rgb, depth, cam, config=TrackingConfig(pyramid_levels=1, iterations=(5,))).levels[0].depth_grad
    ok = np.isfinite(grad[..., 0])
    np.testing.assert_allclose(grad[ok], np.broadcast_to([0.004, -0.002], grad[ok].shape), atol=1e-5)
    assert not ok[9:12, 19:22].any() and ok[13, 23]  # the hole's 3x3 neighbourhood
    assert not ok[:, 39:41].any() and ok[5:-5, 36:39].all() and ok[5:-5, 42:60].all()  # the step, not beside it
    assert not ok[0].any() and not ok[:, -1].any()  # image border: no full neighbourhood


def test_prepared_frames_must_match_the_alignment_config(scenes):
    from lightfast.tracking import align_frames, prepare_frame

    f = scenes.frame(0)
    frame = prepare_frame(f.rgb, f.depth_mm / 1000.0, scenes.camera, config=FAST)
    res = align_frames(frame, frame, config=FAST)
    assert res.converged and np.allclose(res.T_target_source, np.eye(4), atol=1e-6)
    with pytest.raises(TrackingError, match="pyramid_levels"):
        align_frames(frame, frame, config=TrackingConfig())


def _surface_depth(cam: PinholeCamera, T_surface_cam: np.ndarray) -> np.ndarray:
    """Depth (m) seen by ``cam`` at ``T_surface_cam`` of the smooth surface ``z = f(x, y)`` (a slanted, wavy floor
    in front of the camera: every direction constrained), by Newton steps along each pixel's ray."""
    def f(x, y):
        return 1.6 + 0.25 * y + 0.06 * np.sin(6.0 * x) + 0.05 * np.cos(5.0 * y + x)

    def grad(x, y):
        return 0.36 * np.cos(6.0 * x) - 0.05 * np.sin(5.0 * y + x), 0.25 - 0.25 * np.sin(5.0 * y + x)

    v, u = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
    d = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u)], -1) @ T_surface_cam[:3, :3].T
    o = T_surface_cam[:3, 3]
    t = np.full(u.shape, 1.5)  # ray parameter = camera depth (the ray's camera-frame z is 1)
    for _ in range(50):
        x, y, z = (o[k] + t * d[..., k] for k in range(3))
        gx, gy = grad(x, y)
        t = t - (z - f(x, y)) / (d[..., 2] - gx * d[..., 0] - gy * d[..., 1])
    return t


def test_depth_difference_converges_where_a_nearest_pixel_depth_would_cycle():
    """Issue 21: the depth-difference E_G read the target depth at the nearest pixel, a staircase in the projection
    whose steps (|∇D| per pixel) its Jacobian (the smooth Sobel gradient) does not see, so Gauss-Newton cycled
    between neighbouring pixels and used up its iterations (not converged, millimetres off on this 80×60 view of a steep
    wavy surface). Read bilinearly, the residual is continuous and agrees with its Jacobian: the step criterion
    ends every level early and the exact motion is found."""
    cam = PinholeCamera(80, 60, 75.0, 75.0, 39.5, 29.5)
    T_true = se3_exp([0.012, -0.008, 0.01, 0.01, -0.015, 0.012])  # target <- source
    depth_t, depth_s = _surface_depth(cam, np.eye(4)), _surface_depth(cam, T_true)
    grey = np.full(depth_t.shape, 0.5)
    cfg = TrackingConfig(geometric_term="depth-difference", geometric_weight=30.0, iterations=(10, 10, 10))
    res = align(grey, depth_s, grey, depth_t, cam, config=cfg, use_color=False)
    dt, dr = _errors(res.T_target_source, T_true)
    assert res.converged and res.iterations < sum(cfg.iterations) // 2
    assert dt < 3e-4 and dr < 0.02


def test_constant_velocity_prediction_scales_with_the_interval() -> None:
    """The same motion per second: the last motion itself over an equal interval (bit for bit, also when the stamps'
    rounding to ns makes them differ by 1 ns), twice its twist over
    twice the interval; identity without a measured interval or across a gap longer than the limit."""
    T = se3_exp([0.01, -0.02, 0.005, 0.01, 0.0, -0.02])
    ms = 1_000_000
    np.testing.assert_array_equal(predict_motion(T, 33 * ms, 33 * ms), T)
    np.testing.assert_array_equal(predict_motion(T, 33_333_333, 33_333_334), T)  # 30 Hz stamps rounded to ns
    np.testing.assert_allclose(se3_log(predict_motion(T, 33 * ms, 66 * ms)), 2 * se3_log(T), atol=1e-12)
    np.testing.assert_allclose(predict_motion(T, 66 * ms, 33 * ms) @ predict_motion(T, 66 * ms, 33 * ms), T,
                               atol=1e-12)
    for dt_last, dt in ((0, 33 * ms), (33 * ms, 0), (33 * ms, 600 * ms)):
        np.testing.assert_array_equal(predict_motion(T, dt_last, dt, max_gap_s=0.5), np.eye(4))


def test_motion_prior_rules_forget_a_motion_that_did_not_converge() -> None:
    """The three starts over a doubled interval; an alignment that did not converge, or a reset, leaves identity;
    an unknown rule is refused."""
    T = se3_exp([0.01, -0.02, 0.005, 0.01, 0.0, -0.02])
    ms = 1_000_000
    priors = {rule: MotionPrior(rule) for rule in MOTION_PRIORS}
    for prior in priors.values():
        np.testing.assert_array_equal(prior.predict(33 * ms), np.eye(4))  # nothing measured yet
        prior.measured(T, 33 * ms, converged=True)
    np.testing.assert_allclose(se3_log(priors["constant-velocity"].predict(66 * ms)), 2 * se3_log(T), atol=1e-12)
    np.testing.assert_array_equal(priors["last-motion"].predict(66 * ms), T)
    np.testing.assert_array_equal(priors["none"].predict(66 * ms), np.eye(4))
    priors["constant-velocity"].measured(T, 33 * ms, converged=False)
    priors["last-motion"].reset()
    for prior in priors.values():
        np.testing.assert_array_equal(prior.predict(33 * ms), np.eye(4))
    with pytest.raises(TrackingInputError, match="motion prior"):
        MotionPrior("constant-acceleration")
