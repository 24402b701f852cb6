"""racr_node's policies without ROS: a VSE observation assembled from its topics (lightfast.racr.vse_inputs), the
reference loaded and retried (ReferenceLoader), and what /racr/status says (lightfast.racr.status_report)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from lightfast.camera import PinholeCamera
from lightfast.racr.node_config import RacrNodeConfig, ReferenceLoader
from lightfast.racr.status_report import STAGE_NO_REFERENCE, pose7, racr_status, thin_cloud
from lightfast.racr.vse_inputs import VseInputs
from lightfast.status import Level, Log, Problem

CAMERA = PinholeCamera(64, 48, 50.0, 50.0, 31.5, 23.5)
POINTS = np.random.default_rng(0).normal(size=(100, 3))


def inputs(keyframes: int = 2) -> VseInputs:
    return VseInputs(keyframes, input_wait_s=1.0, pose_source="/vse/pose", camera_source="/vse/camera_info")


def test_a_cloud_is_used_once_its_pose_keyframes_and_camera_are_there() -> None:
    vse = inputs()
    assert vse.add_cloud(0.0, 5, POINTS, None)
    assert not vse.add_cloud(0.0, 5, POINTS, None)  # a repeat of the waiting one
    vse.add_pose(5, np.eye(4))
    vse.add_keyframe_image(5, "kf0", np.zeros((48, 64)))
    vse.add_keyframe_pose(5, "kf0", np.eye(4))
    assert vse.take(0.1) == (None, [])  # one keyframe of two, no camera yet
    vse.camera = CAMERA
    vse.add_keyframe_image(5, "kf1", np.zeros((48, 64)))
    vse.add_keyframe_pose(5, "kf1", np.eye(4))
    obs, reports = vse.take(0.2)
    assert obs is not None and obs.stamp_ns == 5 and len(obs.keyframes) == 2 and reports == []
    assert vse.take(0.3) == (None, [])


def test_a_cloud_waits_two_ticks_then_goes_with_what_came_or_without_its_pose_is_dropped() -> None:
    vse = inputs()
    vse.camera = CAMERA
    vse.add_cloud(0.0, 7, POINTS, None)
    vse.add_pose(7, np.eye(4))
    vse.add_keyframe_image(7, "kf0", np.zeros((24, 32)))  # not the camera's size
    vse.add_keyframe_pose(7, "kf0", np.eye(4))
    assert vse.take(2.0) == (None, [])  # no tick: waits on
    assert vse.take(2.0, at_tick=True) == (None, [])  # the first tick after the wait marks it
    obs, reports = vse.take(2.1, at_tick=True)
    assert obs is not None and obs.keyframes == []
    assert [type(r) for r in reports] == [Problem, Log] and "32x24 but camera_info 64x48" in reports[0].text
    vse.add_cloud(3.0, 9, POINTS, None)
    vse.add_cloud(3.0, 11, POINTS, None)  # replaces the waiting one
    assert vse.stats["clouds_superseded"] == 1
    vse.take(5.0, at_tick=True)
    obs, reports = vse.take(5.1, at_tick=True)
    assert obs is None and reports[0].key == "cloud_pose" and "no /vse/pose" in reports[0].text
    assert vse.stats["clouds_dropped"] == 1


def test_the_reference_loader_retries_and_says_why(tmp_path) -> None:
    loader = ReferenceLoader(RacrNodeConfig(reference_path=str(tmp_path / "missing"), reference_retry_s=2.0))
    assert loader.attempt(0.0, clock=lambda: 0.0) is None and "reference" in (loader.error or "")
    first = loader.error
    loader.error = None
    assert loader.attempt(1.0, clock=lambda: 0.0) is None and loader.error is None  # not tried: within 2 s
    assert loader.attempt(2.5, clock=lambda: 0.0) is None and loader.error == first
    loader.forget_attempts()
    assert loader.attempt(2.6, clock=lambda: 0.0) is None


def test_status_levels_and_the_problem_that_overrides() -> None:
    common = {"reference_path": "/r"}
    st = racr_status(None, reference=None, reference_error="reference /r: missing", platform_subscribed=False,
                     motion_topic="/racr/hand_motion", values=common)
    assert st.level == Level.ERROR and st.values["stage"] == STAGE_NO_REFERENCE and "missing" in st.message
    st = racr_status(None, reference=None, reference_error=None, platform_subscribed=True,
                     motion_topic="/racr/hand_motion", values=common, problem=(Level.WARN, "bad cloud", "cloud"))
    assert st.level == Level.ERROR and st.values["problem"] == "cloud"  # the missing reference is worse
    assert pose7(None) == "" and pose7(np.eye(4)) == "0 0 0 0 0 0 1"
    pts, inten = thin_cloud(POINTS, POINTS[:, 0], 10)
    assert inten is not None and np.array_equal(inten, pts[:, 0]) and len(pts) == 10
    assert np.array_equal(pts[0], POINTS[0]) and np.array_equal(pts[-1], POINTS[-1])
    assert thin_cloud(POINTS, None, 0)[0] is POINTS
    assert replace(RacrNodeConfig(), reference_path="x").reference_path == "x"
