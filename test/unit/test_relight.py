"""The relit reference (§III-C/D) and the two-step tracker (§III-D) on a synthetic window room, and the sun-epoch
assembler of the chunk stream (§III-E)."""
from __future__ import annotations

import numpy as np
import pytest

from lightfast.camera import PinholeCamera
from lightfast.daylight.brightness import relit_image
from lightfast.daylight.crf import CameraResponse
from lightfast.daylight.errors import BrightnessError
from lightfast.daylight.lighting_map import LightingMapConfig, prepare_lighting_map
from lightfast.daylight.relight import DaylightRelighter, RelightConfig, _apply_response, _response_table
from lightfast.daylight.sun import FREIBURG
from lightfast.daylight.sun_update import SunEpochAssembler, sun_radiosity
from lightfast.geometry import compose, inverse, look_at, rotation_angle_deg, se3_exp, se3_log
from lightfast.sim.validation_rooms import box_room_with_window
from lightfast.tracking import AlignResult, align
from lightfast.tracking.errors import TrackingError
from lightfast.tracking.pipeline import RGBDTracker, TrackerConfig
from test.unit.test_brightness import S_TRUE

CAMERA = PinholeCamera(320, 240, 250.0, 250.0, 159.5, 119.5)


@pytest.fixture(scope="module")
def room():
    mesh = box_room_with_window(tessellation_m=0.1)
    # texture: a checker of reflectance so that the photometric term has gradients
    v = mesh.vertices_m
    checker = ((np.floor(v[:, 0] / 0.3) + np.floor(v[:, 1] / 0.3) + np.floor(v[:, 2] / 0.3)) % 2)[:, None]
    mesh = type(mesh)(mesh.vertices_m, mesh.faces, np.clip(mesh.reflectance * (0.55 + 0.6 * checker), 0.03, 0.95))
    lmap = prepare_lighting_map(mesh, FREIBURG, LightingMapConfig(patch_size_m=0.5, sky_directions=256,
                                                                  hemisphere_rays=32))
    el = np.radians(35.0)
    sun = sun_radiosity(lmap, np.array([0.0, -np.cos(el), np.sin(el)]))
    return lmap, sun


def ready_relighter(lmap, sun, crf) -> DaylightRelighter:
    """A relighter with the room's B̂_sun swapped in."""
    rl = DaylightRelighter(lmap, crf)
    rl.set_sun_radiosity(sun, epoch_ns=1)
    return rl


def live_frame(lmap, sun, crf, T):
    comps = {"sun": sun, "sky": lmap.sky_radiosity, "ground": lmap.ground_radiosity}
    r = relit_image(lmap, comps, S_TRUE, T, CAMERA, crf)
    return r.rgb8(), r.depth_m


T0 = look_at([2.25, 4.3, 1.6], np.add([2.25, 4.3, 1.6], [0.0, -2.8, -1.4]))
#: The second frame of the two-frame tracker tests: 2.2 cm and 0.6° from T0.
T1 = compose(T0, se3_exp([0.01, 0.0, 0.02, 0.0, 0.01, 0.0]))


def test_relighter_estimates_scales_and_renders_the_live_image(room, true_crf):
    lmap, sun = room
    rgb, depth = live_frame(lmap, sun, true_crf, T0)
    rl = DaylightRelighter(lmap, true_crf, config=RelightConfig(window=1, reference_scale=1.0))
    with pytest.raises(BrightnessError, match="B̂_sun"):
        rl.step(0, rgb, T0, CAMERA)
    rl.set_sun_radiosity(sun, epoch_ns=1)
    ref = rl.step(0, rgb, T0, CAMERA)
    np.testing.assert_allclose(ref.scales, S_TRUE, rtol=0.03)
    assert np.mean(np.abs(ref.color.astype(float) - rgb)) < 1.0
    np.testing.assert_allclose(ref.depth_m, depth, atol=1e-5)
    assert set(ref.seconds) >= {"render", "estimate"}
    # the default half-resolution reference: the same estimate, the scene as the half-size camera sees it
    half = CAMERA.scaled(0.5)
    rh = DaylightRelighter(lmap, true_crf, config=RelightConfig(window=1))
    rh.set_sun_radiosity(sun, epoch_ns=1)
    ref_h = rh.step(0, rgb, T0, CAMERA)
    np.testing.assert_allclose(ref_h.scales, ref.scales, rtol=1e-6)
    comps = {"sun": sun, "sky": lmap.sky_radiosity, "ground": lmap.ground_radiosity}
    truth_h = relit_image(lmap, comps, S_TRUE, T0, half, true_crf)
    assert ref_h.color.shape == (half.height, half.width, 3)
    assert np.mean(np.abs(ref_h.color.astype(float) - truth_h.rgb8())) < 1.0
    np.testing.assert_allclose(ref_h.depth_m, truth_h.depth_m, atol=1e-5)
    # reflectance reference: mean grey brightness matches the live image
    rr = DaylightRelighter(lmap, true_crf, config=RelightConfig(reference="reflectance", reference_scale=1.0))
    rr.set_sun_radiosity(sun, epoch_ns=1)
    refl = rr.step(0, rgb, T0, CAMERA)
    grey = np.array([0.299, 0.587, 0.114])
    hit = depth > 0
    assert abs((refl.color[hit] @ grey).mean() - (rgb[hit] @ grey).mean()) < 2.0


@pytest.mark.parametrize("gamma", [0.45, 1.0, 2.2, 5.0])
def test_reference_colour_is_the_rounded_camera_response(gamma):
    """The table lookup of the reference shading gives round(f(x)) of CameraResponse.apply for every exposure,
    including the thresholds themselves, values beyond both ends of the curve, inf and NaN (0)."""
    levels = np.arange(256.0)
    inverse = np.stack([s * (levels / 255) ** gamma + o + 1e-9 * levels for s, o in ((1, 0), (2, 0.01), (0.5, 1e-3))],
                       axis=1)
    crf = CameraResponse(inverse)
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(-0.1, 2.2, (50_000, 3)), rng.uniform(0, 1e-3, (5_000, 3)), inverse,
                        0.5 * (inverse[1:] + inverse[:-1]), [[np.inf, -np.inf, 1e30]]]).astype(np.float32)
    expected = np.minimum(255, np.floor(crf.apply(x.astype(np.float64)) + 0.5)).astype(np.uint8)
    np.testing.assert_array_equal(_apply_response(x, *_response_table(crf.inverse)), expected)
    assert _apply_response(np.full((1, 3), np.nan, np.float32), *_response_table(crf.inverse)).tolist() == [[0, 0, 0]]


def test_relighter_rejects_bad_input(room, true_crf):
    lmap, sun = room
    rl = DaylightRelighter(lmap, true_crf)
    with pytest.raises(BrightnessError):
        rl.set_sun_radiosity(sun[:-1], epoch_ns=1)
    rl.set_sun_radiosity(sun, epoch_ns=1)
    with pytest.raises(BrightnessError, match="shape"):
        rl.step(0, np.zeros((10, 10, 3), np.uint8), T0, CAMERA)
    with pytest.raises(BrightnessError, match="4x4"):
        rl.step(0, np.zeros((240, 320, 3), np.uint8), np.full((4, 4), np.nan), CAMERA)


def test_two_step_tracker_recovers_a_perturbed_pose(room, true_crf):
    """The f2m step against the relit reference pulls a wrong coarse pose back to the truth."""
    lmap, sun = room
    rgb0, d0 = live_frame(lmap, sun, true_crf, T0)
    rgb1, d1 = live_frame(lmap, sun, true_crf, T1)
    rl = ready_relighter(lmap, sun, true_crf)
    for mode in ("proposed", "no-color-f2m", "depth-only"):
        tracker = RGBDTracker(CAMERA, config=TrackerConfig(mode=mode))
        # start 3 cm / 1.7° off: f2f keeps the error, f2m against the map removes it
        T_start = compose(T0, se3_exp([0.02, -0.02, 0.01, 0.0, 0.03, 0.0]))
        tracker.reset(T_start)
        c0 = tracker.track_coarse(0, rgb0, d0)
        assert np.allclose(c0.T_map_cam, T_start)
        ref = rl.step(0, rgb0, c0.T_map_cam, CAMERA)
        r0 = tracker.refine(0, ref.color, ref.depth_m)
        assert r0.source == "f2m", r0.reason
        E = compose(inverse(T0), r0.T_map_cam)
        assert np.linalg.norm(E[:3, 3]) < 0.005 and rotation_angle_deg(E[:3, :3]) < 0.3, mode
        c1 = tracker.track_coarse(1, rgb1, d1)
        ref = rl.step(1, rgb1, c1.T_map_cam, CAMERA)
        r1 = tracker.refine(1, ref.color, ref.depth_m)
        E = compose(inverse(T1), r1.T_map_cam)
        assert np.linalg.norm(E[:3, 3]) < 0.005 and rotation_angle_deg(E[:3, :3]) < 0.3, mode


def test_tracker_pipelining_skip_and_errors(room, true_crf):
    lmap, sun = room
    rgb0, d0 = live_frame(lmap, sun, true_crf, T0)
    T1 = compose(T0, se3_exp([0.01, 0.0, 0.0, 0.0, 0.0, 0.0]))
    rgb1, d1 = live_frame(lmap, sun, true_crf, T1)
    tracker = RGBDTracker(CAMERA, config=TrackerConfig(max_pending=1))
    with pytest.raises(TrackingError, match="reset"):
        tracker.track_coarse(0, rgb0, d0)
    T_off = compose(T0, se3_exp([0.02, 0.0, 0.0, 0.0, 0.0, 0.0]))
    tracker.reset(T_off)
    tracker.track_coarse(0, rgb0, d0)
    c1 = tracker.track_coarse(1, rgb1, d1)  # frame 0 still waits for its reference
    assert tracker.pending_stamps == [0, 1] and tracker.expired() == [0]
    rl = ready_relighter(lmap, sun, true_crf)
    ref0 = rl.step(0, rgb0, T_off, CAMERA)
    r0 = tracker.refine(0, ref0.color, ref0.depth_m)  # late reference of frame 0 re-chains frame 1
    assert r0.source == "f2m"
    r1 = tracker.skip_reference(1, "timeout")
    assert r1.source == "f2f" and r1.reason == "timeout"
    E = compose(inverse(T1), r1.T_map_cam)  # f2f from the refined frame 0: near the truth, not 2 cm off
    assert np.linalg.norm(E[:3, 3]) < 0.005
    assert not np.allclose(r1.T_map_cam, c1.T_map_cam)
    with pytest.raises(TrackingError, match="pending"):
        tracker.refine(1, ref0.color, ref0.depth_m)
    with pytest.raises(TrackingError, match="not after"):
        tracker.track_coarse(1, rgb1, d1)
    # a reference without depth finishes the frame with the f2f pose
    tracker.track_coarse(2, rgb1, d1)
    r2 = tracker.refine(2, ref0.color, np.zeros_like(ref0.depth_m))
    assert r2.source == "f2f" and "depth" in r2.reason


def test_f2m_job_runs_apart_from_the_tracker_state(room, true_crf):
    """start_refine → run (another thread in the node) → finish_refine is refine; a frame finished meanwhile
    (reset, timeout) refuses the job's result."""
    lmap, sun = room
    rgb0, d0 = live_frame(lmap, sun, true_crf, T0)
    rl = ready_relighter(lmap, sun, true_crf)
    T_off = compose(T0, se3_exp([0.02, 0.0, 0.0, 0.0, 0.0, 0.0]))
    ref = rl.step(0, rgb0, T_off, CAMERA)  # the first frame's T≈ is the start pose
    results = []
    for split in (False, True):
        tracker = RGBDTracker(CAMERA)
        tracker.reset(T_off)
        tracker.track_coarse(0, rgb0, d0)
        if split:
            job = tracker.start_refine(0, ref.color, ref.depth_m)
            assert tracker.pending_stamps == [0]  # nothing changes until the job is finished
            results.append(tracker.finish_refine(job.run()))
        else:
            results.append(tracker.refine(0, ref.color, ref.depth_m))
    assert results[0].source == results[1].source == "f2m"
    np.testing.assert_allclose(results[0].T_map_cam, results[1].T_map_cam, atol=1e-12)
    tracker = RGBDTracker(CAMERA)
    tracker.reset(T_off)
    tracker.track_coarse(0, rgb0, d0)
    job = tracker.start_refine(0, ref.color, ref.depth_m).run()
    tracker.skip_reference(0, "timeout")
    with pytest.raises(TrackingError, match="finished while"):
        tracker.finish_refine(job)
    with pytest.raises(TrackingError, match="neither the camera"):
        tracker.track_coarse(1, rgb0, d0)
        tracker.start_refine(1, ref.color[:10], ref.depth_m[:10])


def test_f2f_job_chains_to_the_pose_of_the_previous_frame_at_its_finish(room, true_crf):
    """start_coarse → run → finish_coarse is track_coarse; a previous frame refined by f2m while the f2f job ran
    carries the new frame along; a reset meanwhile makes the job's frame refuse to join."""
    lmap, sun = room
    rgb0, d0 = live_frame(lmap, sun, true_crf, T0)
    rgb1, d1 = live_frame(lmap, sun, true_crf, T1)
    rl = ready_relighter(lmap, sun, true_crf)
    T_off = compose(T0, se3_exp([0.02, 0.0, 0.0, 0.0, 0.0, 0.0]))
    ref0 = rl.step(0, rgb0, T_off, CAMERA)
    tracker = RGBDTracker(CAMERA)
    tracker.reset(T_off)
    tracker.track_coarse(0, rgb0, d0)
    job = tracker.start_coarse(1, rgb1, d1).run()
    assert tracker.pending_stamps == [0]  # nothing changes until the job is finished
    r0 = tracker.refine(0, ref0.color, ref0.depth_m)  # meanwhile f2m moves frame 0 from T_off to the truth
    assert r0.source == "f2m"
    c1 = tracker.finish_coarse(job)
    np.testing.assert_allclose(c1.T_map_cam, r0.T_map_cam @ job.result.T_target_source, atol=1e-12)
    E = compose(inverse(T1), c1.T_map_cam)
    assert np.linalg.norm(E[:3, 3]) < 0.01  # the f2f error alone, not the 2 cm of T_off on top
    job = tracker.start_coarse(2, rgb1, d1).run()
    tracker.reset(T0)
    with pytest.raises(TrackingError, match="reset or moved on"):
        tracker.finish_coarse(job)
    bad = tracker.start_coarse(3, rgb1, np.zeros_like(d1)).run()
    with pytest.raises(TrackingError, match="no valid depth"):
        tracker.finish_coarse(bad)
    assert tracker.pending_stamps == []


def test_tracker_does_not_align_a_repeated_depth_image(room, true_crf):
    """A live frame whose depth image repeats the previous frame's (a dropped depth frame, an unsynchronised stream)
    keeps the previous pose and stays out of f2f: the next frame is aligned to the previous one. A frame whose colour
    image alone repeats is aligned by E_G only."""
    lmap, sun = room
    rgb0, d0 = live_frame(lmap, sun, true_crf, T0)
    rgb1, d1 = live_frame(lmap, sun, true_crf, T1)
    tracker = RGBDTracker(CAMERA)
    tracker.reset(T0)
    c0 = tracker.track_coarse(0, rgb0, d0)
    c1 = tracker.track_coarse(1, rgb1, d0)  # new colour, the old depth
    assert c1.repeated == "depth" and c1.f2f is None
    np.testing.assert_array_equal(c1.T_map_cam, c0.T_map_cam)
    with pytest.raises(TrackingError, match="not after"):
        tracker.track_coarse(1, rgb1, d1)
    job = tracker.start_coarse(2, rgb1, d1)
    assert job.previous is not None and job.previous[0] == 0  # aligned to frame 0, not to frame 1
    c2 = tracker.finish_coarse(job.run())
    assert c2.repeated == "" and c2.f2f is not None and c2.f2f.converged
    E = compose(inverse(T1), c2.T_map_cam)
    assert np.linalg.norm(E[:3, 3]) < 0.005 and rotation_angle_deg(E[:3, :3]) < 0.3
    T2 = compose(T1, se3_exp([0.01, 0.0, 0.02, 0.0, 0.01, 0.0]))
    d2 = live_frame(lmap, sun, true_crf, T2)[1]
    c3 = tracker.track_coarse(3, rgb1, d2)  # the colour alone repeats
    assert c3.repeated == "colour" and c3.f2f is not None
    error_m = np.linalg.norm(compose(inverse(T2), c3.T_map_cam)[:3, 3])
    both = align(rgb1, d2, rgb1, d1, CAMERA, init_T_target_source=c2.f2f.T_target_source,
                 config=tracker.config.f2f_config)  # E_C too: the unchanged colour holds the pose back
    both_m = np.linalg.norm(compose(inverse(T2), c2.T_map_cam @ both.T_target_source)[:3, 3])
    assert error_m < 0.01 < both_m  # 6.5 mm against 2.6 cm
    assert [r.source for r in (tracker.skip_reference(s) for s in (0, 1, 2, 3))] == ["f2f"] * 4


def test_f2f_prediction_spans_the_frames_a_busy_node_dropped(room, true_crf):
    """A camera moving at constant velocity; the tracker gets frames 0, 1 and 2, then (a node that fell behind
    dropped frames 3 and 4) frame 5: its f2f starts at the motion measured over one frame scaled to three frames,
    not at one frame's motion, and tracks it. After a gap longer than ``motion_prior_max_gap_s`` it starts at
    identity."""
    lmap, sun = room
    V = se3_exp([0.012, 0.0, 0.015, 0.0, 0.012, 0.0])  # per 1/30 s
    poses = [T0]
    for _ in range(5):
        poses.append(compose(poses[-1], V))
    frames = {i: live_frame(lmap, sun, true_crf, poses[i]) for i in (0, 1, 2, 5)}
    period_ns = 1_000_000_000 // 30
    tracker = RGBDTracker(CAMERA)
    tracker.reset(T0)
    for i in (0, 1, 2):
        tracker.track_coarse(i * period_ns, *frames[i])
    job = tracker.start_coarse(5 * period_ns, *frames[5])
    np.testing.assert_allclose(se3_log(job.T_prev_cur_init), 3 * se3_log(V), atol=3e-3)  # T_prev_cur = V³
    c5 = tracker.finish_coarse(job.run())
    assert c5.f2f is not None and c5.f2f.converged
    E = compose(inverse(poses[5]), c5.T_map_cam)
    assert np.linalg.norm(E[:3, 3]) < 0.01 and rotation_angle_deg(E[:3, :3]) < 0.5
    late = tracker.start_coarse(5 * period_ns + int(tracker.config.motion_prior_max_gap_s * 1e9) + 1, *frames[5])
    np.testing.assert_array_equal(late.T_prev_cur_init, np.eye(4))


def test_sun_epoch_assembler_swaps_only_complete_epochs():
    a = SunEpochAssembler(10)
    B = np.arange(30, dtype=np.float32).reshape(10, 3)
    assert a.add(5, np.arange(0, 6), B[:6]) is None
    assert a.progress == pytest.approx(0.6)
    assert a.add(7, np.arange(0, 4), B[:4] + 1) is None  # newer epoch replaces the unfinished one
    assert a.add(5, np.arange(6, 10), B[6:]) is None  # late chunk of the superseded epoch: dropped
    out = a.add(7, np.arange(4, 10), B[4:] + 1)
    np.testing.assert_array_equal(out, B + 1)
    assert a.completed_epoch_ns == 7 and a.add(7, np.arange(10), B) is None  # duplicate epoch ignored
    with pytest.raises(ValueError, match="another lighting map"):
        a.add(9, np.array([10]), B[:1])
    with pytest.raises(ValueError, match="finite"):
        a.add(9, np.array([0]), np.full((1, 3), np.nan))


def _track_from_wrong_start(lmap, sun, crf, config, ref_offsets=None, frames=4):
    """Track a camera moving from T0 with the tracker started 12 cm off; references rendered at T≈ (or at T≈ moved
    by ``ref_offsets[i]``, a planted inconsistent reference). Returns the final results."""
    V = se3_exp([0.004, 0.0, 0.005, 0.0, 0.004, 0.0])
    relighter = ready_relighter(lmap, sun, crf)
    tracker = RGBDTracker(CAMERA, config=config)
    tracker.reset(compose(T0, se3_exp([0.12, 0.0, 0.0, 0.0, 0.0, 0.0])))
    T, out = T0, []
    for i in range(frames):
        rgb, depth = live_frame(lmap, sun, crf, T)
        stamp = i * 33_333_333
        T_ref = tracker.track_coarse(stamp, rgb, depth).T_map_cam
        if ref_offsets is not None:
            T_ref = compose(T_ref, se3_exp(ref_offsets[i]))
        ref = relighter.step(stamp, rgb, T_ref, CAMERA)
        r = tracker.refine(stamp, ref.color, ref.depth_m)
        out.append((r, np.linalg.norm(compose(inverse(T), r.T_map_cam)[:3, 3])))
        T = compose(T, V)
    return out


def test_large_f2m_corrections_that_agree_bring_the_pose_back(room, true_crf):
    """Started 12 cm off (a wrong start pose, or f2f gone off once): each frame's f2m against the reference rendered
    at T≈ finds the true pose, a correction beyond max_f2m_correction_m. One alone is rejected; three in a row that
    agree are accepted (f2m_confirm_frames) and the pose is back within 5 mm; with 0 the tracker stays 12 cm off for
    good. Large corrections that disagree (references planted 4 cm up and down in turn) are never accepted."""
    lmap, sun = room
    out = _track_from_wrong_start(lmap, sun, true_crf, TrackerConfig())
    assert [r.source for r, _ in out] == ["f2f", "f2f", "f2m", "f2m"]
    assert out[0][0].reason.startswith("f2m correction too large") and out[2][0].reason == "large correction confirmed"
    assert out[1][1] > 0.1 and out[2][1] < 0.005 and out[3][1] < 0.005
    never = _track_from_wrong_start(lmap, sun, true_crf, TrackerConfig(f2m_confirm_frames=0))
    assert all(r.source == "f2f" and err > 0.1 for r, err in never)
    sides = [[0.0, 0.04 * (-1) ** i, 0.0, 0.0, 0.0, 0.0] for i in range(5)]
    planted = _track_from_wrong_start(lmap, sun, true_crf, TrackerConfig(), ref_offsets=sides, frames=5)
    assert all(r.source == "f2f" and err > 0.1 for r, err in planted)


def test_agreed_large_corrections_are_a_probe_that_a_reference_rendered_there_must_confirm(room, true_crf):
    """The rule's states with planted f2m results (a still camera: repeated frames, so T_best stays T0): two large
    corrections that agree make the next frame's T≈ the pose they give (a probe); a large correction against that
    reference drops the probe (the frame keeps its f2f pose, T≈ goes back); a small one confirms it."""
    lmap, sun = room
    rgb, depth = live_frame(lmap, sun, true_crf, T0)
    tracker = RGBDTracker(CAMERA)
    tracker.reset(T0)
    C = se3_exp([0.12, 0.0, 0.0, 0.0, 0.0, 0.0])  # T_ref_cur of f2m: 12 cm, beyond max_f2m_correction_m
    results = []
    for i, T_ref_cur in enumerate([C, C, C, C, C, np.eye(4)]):
        coarse = tracker.track_coarse(i, rgb, depth)
        job = tracker.start_refine(i, rgb, depth)
        job.result = AlignResult(T_ref_cur, True, 5, 0.8, 1e-3)
        results.append((coarse.T_map_cam, tracker.finish_refine(job)))
    probe = T0 @ C
    for i in (0, 1, 3, 4):  # rejected; after 1 (and 4) the two agree
        np.testing.assert_array_equal(results[i][0], T0)
        assert results[i][1].source == "f2f" and "too large" in results[i][1].reason
    np.testing.assert_allclose(results[2][0], probe, atol=1e-12)  # the probe, not confirmed
    assert results[2][1].source == "f2f" and results[2][1].reason.endswith("a large correction not confirmed")
    np.testing.assert_array_equal(results[2][1].T_map_cam, T0)
    np.testing.assert_allclose(results[5][0], probe, atol=1e-12)  # the probe again, confirmed
    assert results[5][1].source == "f2m" and results[5][1].reason == "large correction confirmed"
    np.testing.assert_allclose(results[5][1].T_map_cam, probe, atol=1e-12)
    assert np.linalg.norm(tracker.track_coarse(6, rgb, depth).T_map_cam - probe) < 1e-12  # the track goes on there


def test_a_probe_confirmed_once_moves_the_frames_pending_behind_it(room, true_crf):
    """Pipelined: frames 2 and 3 are coarse-tracked at the probe before either reference is aligned. Frame 2's f2m
    confirms it and the whole track moves (frame 3's best pose too); frame 3's f2m against its reference, rendered at
    the probe as well, is then an ordinary small correction."""
    lmap, sun = room
    rgb, depth = live_frame(lmap, sun, true_crf, T0)
    tracker = RGBDTracker(CAMERA)
    tracker.reset(T0)
    C = se3_exp([0.12, 0.0, 0.0, 0.0, 0.0, 0.0])

    def refine(stamp: int, T_ref_cur: np.ndarray):
        job = tracker.start_refine(stamp, rgb, depth)
        job.result = AlignResult(T_ref_cur, True, 5, 0.8, 1e-3)
        return tracker.finish_refine(job)

    for i in (0, 1):
        tracker.track_coarse(i, rgb, depth)
        assert refine(i, C).source == "f2f"
    probe = T0 @ C
    for i in (2, 3):
        np.testing.assert_allclose(tracker.track_coarse(i, rgb, depth).T_map_cam, probe, atol=1e-12)
    r2 = refine(2, np.eye(4))
    assert r2.source == "f2m" and r2.reason == "large correction confirmed"
    r3 = refine(3, se3_exp([0.002, 0.0, 0.0, 0.0, 0.0, 0.0]))
    assert r3.source == "f2m" and r3.reason == ""
    np.testing.assert_allclose(r3.T_map_cam, probe @ se3_exp([0.002, 0.0, 0.0, 0.0, 0.0, 0.0]), atol=1e-12)
