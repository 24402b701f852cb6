"""The two-step tracking policy without ROS (lightfast.tracking.session): which step finishes a frame, restarts on
camera, configuration and time changes, resets, and the problems it reports."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lightfast.camera import PinholeCamera
from lightfast.geometry import compose, matrix_to_quat, se3_exp
from lightfast.status import Level, Log, Problem, Status
from lightfast.tracking.pipeline import TrackerConfig
from lightfast.tracking.session import CoarsePose, Finished, Frame, TrackingSession
from test.unit.test_relight import CAMERA, T0, T1, live_frame, ready_relighter, room  # noqa: F401 (fixture)

S = 1_000_000_000  # ns per second
OTHER_CAMERA = PinholeCamera(320, 240, 260.0, 260.0, 159.5, 119.5)


class Clock:
    def __init__(self) -> None:
        self.s = 100.0

    def __call__(self) -> float:
        return self.s


@pytest.fixture(scope="module")
def frames(room, true_crf):  # noqa: F811 (fixture)
    lmap, sun = room
    rl = ready_relighter(lmap, sun, true_crf)
    out = []
    for T in (T0, T1, compose(T1, se3_exp([0.01, 0.0, 0.0, 0.0, 0.0, 0.0]))):
        rgb, depth = live_frame(lmap, sun, true_crf, T)
        out.append((rgb, depth, rl))
    return out


def make_session(**options) -> tuple[TrackingSession, list, Clock]:
    events: list = []
    clock = Clock()
    cfg = TrackerConfig(initial_pose=(*T0[:3, 3], *matrix_to_quat(T0[:3, :3])), **options)
    return TrackingSession(cfg, events.append, clock=clock), events, clock


def feed(session: TrackingSession, frames, i: int, stamp_s: float, camera=CAMERA, **kw):
    rgb, depth, _ = frames[i]
    frame = Frame(int(stamp_s * S), rgb, depth.astype(np.float32), "cam", 0.0, 0)
    job = session.start_frame(frame, camera=camera, now_ns=int(stamp_s * S), **kw)
    if job is not None:
        session.finish_frame(job.run(), frame)
    return frame


def refine(session: TrackingSession, events, frames, i: int, stamp_s: float) -> None:
    rgb, _, rl = frames[i]
    coarse = [e for e in events if isinstance(e, CoarsePose) and e.stamp_ns == int(stamp_s * S)]
    ref = rl.step(int(stamp_s * S), rgb, coarse[-1].T_map_cam, CAMERA)
    refinement = session.start_refine(int(stamp_s * S), ref.color, ref.depth_m)
    if refinement is not None:
        refinement.job.run()
        session.finish_refine(refinement)


def finished(events) -> dict[int, Finished]:
    return {e.result.stamp_ns: e for e in events if isinstance(e, Finished)}


def test_reference_refines_and_missing_references_finish_with_f2f(frames) -> None:
    session, events, clock = make_session(reference_timeout_s=0.5)
    feed(session, frames, 0, 1.0)
    assert isinstance(events[-1], CoarsePose) and session.waiting == 1
    refine(session, events, frames, 0, 1.0)
    assert finished(events)[S].result.source == "f2m" and session.waiting == 0
    feed(session, frames, 1, 2.0)
    clock.s += 0.4
    session.start_frame(None, camera=CAMERA, now_ns=2 * S)  # not yet overdue
    assert 2 * S not in finished(events)
    clock.s += 0.2
    session.start_frame(None, camera=CAMERA, now_ns=2 * S)
    done = finished(events)[2 * S]
    assert done.result.source == "f2f" and "no reference within 0.5 s" in done.result.reason
    assert done.frame_id == "cam"
    assert session.stats["f2m"] == 1 and session.stats["f2f"] == 1 and session.stats["frames_tracked"] == 2
    status = done.status(clock.s + 0.1)
    assert status.level == Level.WARN and status.values["source"] == "f2f" and status.values["pipeline_ms"] > 0


def test_a_later_reference_finishes_the_earlier_frames_and_a_late_one_is_ignored(frames) -> None:
    session, events, _ = make_session()
    feed(session, frames, 0, 1.0)
    feed(session, frames, 1, 2.0)
    refine(session, events, frames, 1, 2.0)
    done = finished(events)
    assert done[S].result.source == "f2f" and "later frame's reference" in done[S].result.reason
    assert done[2 * S].result.source == "f2m"
    refine(session, events, frames, 0, 1.0)  # frame 1 is finished already
    assert session.stats["late_references"] == 1
    assert any(isinstance(e, Log) and e.key == "late" for e in events)


def test_camera_and_preparation_changes_restart_at_the_last_pose(frames) -> None:
    session, events, _ = make_session()
    feed(session, frames, 0, 1.0)
    last = [e for e in events if isinstance(e, CoarsePose)][-1].T_map_cam
    feed(session, frames, 1, 2.0, camera=OTHER_CAMERA)
    assert "camera_info changed" in finished(events)[S].result.reason
    assert any(isinstance(e, Log) and "restarts at the last pose" in e.text for e in events)
    np.testing.assert_allclose([e for e in events if isinstance(e, CoarsePose)][-1].T_map_cam, last, atol=1e-9)
    # a frame-preparation option restarts too; another option is handed to the tracker as it is
    feed(session, frames, 2, 3.0, camera=OTHER_CAMERA, config=replace(session.config, reference_timeout_s=2.0))
    assert session.tracker.config.reference_timeout_s == 2.0
    slower = replace(session.config, min_depth_m=session.config.min_depth_m + 0.1)
    feed(session, frames, 2, 4.0, camera=OTHER_CAMERA, config=slower)
    assert "frame preparation options changed" in finished(events)[3 * S].result.reason


def test_time_going_back_starts_over_at_the_initial_pose(frames) -> None:
    session, events, _ = make_session()
    start = session.config.T_map_cam_initial
    feed(session, frames, 0, 10.0)
    reset_to = compose(T0, se3_exp([0.0, 0.0, 0.05, 0.0, 0.0, 0.0]))
    feed(session, frames, 1, 11.0, reset=(reset_to, None, "/initialpose"))
    assert any(isinstance(e, Status) and e.message == "tracking reset" for e in events)
    np.testing.assert_allclose([e for e in events if isinstance(e, CoarsePose)][-1].T_map_cam, reset_to, atol=1e-9)
    feed(session, frames, 0, 2.0)  # stamps went back 9 s: a bag played again
    assert session.stats["time_jumps"] == 1
    np.testing.assert_allclose([e for e in events if isinstance(e, CoarsePose)][-1].T_map_cam, start, atol=1e-9)
    feed(session, frames, 1, 6.0)
    assert session.stats["time_jumps"] == 1
    feed(session, frames, 0, 7.0, clock_jump_ns=1 * S)  # the clock went back 5 s behind the stamps: starts over
    assert session.stats["time_jumps"] == 2
    np.testing.assert_allclose([e for e in events if isinstance(e, CoarsePose)][-1].T_map_cam, start, atol=1e-9)


def test_bad_frames_are_reported_not_tracked(frames) -> None:
    session, events, _ = make_session()
    rgb, depth, _ = frames[0]
    session.start_frame(Frame(S, rgb, depth, "cam", 0.0, 0), camera=None, now_ns=S)
    session.start_frame(Frame(2 * S, rgb, depth[::2, ::2].copy(), "cam", 0.0, 0), camera=CAMERA, now_ns=2 * S)
    session.start_frame(Frame(300 * S, rgb, depth, "cam", 0.0, 0), camera=CAMERA, now_ns=3 * S)  # far ahead
    problems = [e for e in events if isinstance(e, Problem)]
    assert [p.key for p in problems] == ["no_camera_info", "size", "stamp"]
    assert problems[1].values["reason"] == problems[1].text and "depth 160x120" in problems[1].text
    assert not [e for e in events if isinstance(e, CoarsePose)] and session.tracker is None


def test_depth_in_another_frame_than_the_colour_is_said_and_tracked_anyway(frames) -> None:
    """A driver's raw depth topic (its own optical frame) instead of the one registered to the colour camera."""
    session, events, _ = make_session()
    rgb, depth, _ = frames[0]
    for stamp_s, depth_frame in ((1.0, "cam"), (2.0, ""), (3.0, "camera_depth_optical_frame")):
        frame = Frame(int(stamp_s * S), rgb, depth.astype(np.float32), "cam", 0.0, 0, depth_frame)
        job = session.start_frame(frame, camera=CAMERA, now_ns=int(stamp_s * S))
        assert job is not None
        session.finish_frame(job.run(), frame)
    said = [e for e in events if isinstance(e, Log) and e.key == "depth_frame"]
    assert len(said) == 1 and "'camera_depth_optical_frame', colour in 'cam'" in said[0].text
    assert said[0].level == Level.WARN and "aligned_depth_to_color" in said[0].text
