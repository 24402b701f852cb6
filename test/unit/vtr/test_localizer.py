"""The VT&R node's policy without ROS (lightfast.vtr.localizer): input checks, teach → finish → repeat on the
corridor of test_teach_repeat, the localization covariance, time going back, and an unusable map."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from lightfast.config import ConfigError
from lightfast.geometry import so3_exp
from lightfast.status import Level, Log, Problem, Status
from lightfast.vtr.localizer import (
    ImagesOut,
    LocalizationOut,
    OdometryOut,
    StereoCamera,
    StereoPair,
    VtrLocalizer,
    drift_covariance,
    pose_covariance,
)
from lightfast.vtr.localizer_config import VtrLocalizerConfig
from test.unit.vtr.test_teach_repeat import P_LEFT, P_RIGHT, TEACH_Z, H, Scene, W, pose

S = 1_000_000_000
LEFT, RIGHT = StereoCamera(P_LEFT, (W, H)), StereoCamera(P_RIGHT, (W, H))


@pytest.fixture(scope="module")
def corridor() -> Scene:
    return Scene()


def make(config: VtrLocalizerConfig) -> tuple[VtrLocalizer, list]:
    events: list = []
    return VtrLocalizer(config, events.append, clock=lambda: 0.0), events


def pair(corridor: Scene, z: float, stamp_s: float, rng: np.random.Generator, x: float = 0.0) -> StereoPair:
    left, right = corridor.stereo("teach", pose(x, z), rng)
    return StereoPair(int(stamp_s * S), left, right, "stereo_left_optical_frame", 0.0)


def problems(events: list) -> list[str]:
    return [e.key for e in events if isinstance(e, Problem)]


def test_pose_covariance_moves_the_camera_frame_perturbation_into_the_parent_frame() -> None:
    R = so3_exp([0.3, -0.2, 0.5])
    T = np.eye(4)
    T[:3, :3] = R
    cov_xi = np.diag([1e-4, 4e-4, 9e-4, 1e-6, 2e-6, 3e-6])
    C = pose_covariance(T, cov_xi)
    np.testing.assert_allclose(C[:3, :3], R @ cov_xi[:3, :3] @ R.T, atol=1e-15)
    np.testing.assert_allclose(C[3:, 3:], R @ cov_xi[3:, 3:] @ R.T, atol=1e-15)
    np.testing.assert_allclose(C, C.T)
    # sampled: p' = p + R ρ has the covariance of the position block
    rho = np.random.default_rng(0).multivariate_normal(np.zeros(3), cov_xi[:3, :3], 20000)
    np.testing.assert_allclose(np.cov((rho @ R.T).T), C[:3, :3], rtol=0.05, atol=2e-6)


def test_drift_covariance_grows_with_the_distance_on_vo() -> None:
    near, far = drift_covariance(1.0, 0.05, 0.5), drift_covariance(4.0, 0.05, 0.5)
    assert math.isclose(near[0, 0], 0.05**2 + 1e-6) and math.isclose(far[0, 0], 0.2**2 + 1e-6)
    assert math.isclose(far[5, 5], math.radians(2.0) ** 2 + 1e-8)


def test_bad_pairs_are_reported_not_processed(corridor, tmp_path) -> None:
    loc, events = make(VtrLocalizerConfig(mode="teach", map_path=str(tmp_path / "map")))
    rng = np.random.default_rng(1)
    good = pair(corridor, 0.0, 1.0, rng)
    loc.process(good, None, RIGHT, 2 * S)
    loc.process(StereoPair(good.stamp_ns, good.left, good.right[:, :-8], "cam", 0.0), LEFT, RIGHT, 2 * S)
    loc.process(good, StereoCamera(P_LEFT, (W // 2, H)), RIGHT, 2 * S)
    black = np.zeros_like(good.left)
    loc.process(StereoPair(good.stamp_ns, good.left, black, "cam", 0.0), LEFT, RIGHT, 2 * S)
    loc.process(StereoPair(100 * S, good.left, good.right, "cam", 0.0), LEFT, RIGHT, 2 * S)  # far ahead
    assert problems(events) == ["no_camera_info", "size", "info_size", "black", "stamp"]
    assert "right image" in [e for e in events if isinstance(e, Problem)][1].text
    assert loc.stats["frames_done"] == 0 and loc.teach is not None and loc.teach.num_keyframes == 0
    ok, text = loc.finish_teach()
    assert not ok and "nothing taught" in text


def test_teach_finish_then_repeat_localizes_and_restarts_when_time_goes_back(corridor, tmp_path) -> None:
    path = tmp_path / "map"
    teach, events = make(VtrLocalizerConfig(mode="teach", map_path=str(path)))
    rng = np.random.default_rng(2)
    for i, z in enumerate(TEACH_Z[:8]):
        teach.process(pair(corridor, float(z), 1.0 + i, rng), LEFT, RIGHT, 20 * S)
    assert problems(events) == [] and teach.stats["frames_done"] == 8
    assert [type(e) for e in events[:3]] == [OdometryOut, ImagesOut, Status]
    teach.process(pair(corridor, 0.0, 0.5, rng), LEFT, RIGHT, 20 * S)  # stamps went back during a teach: refused
    assert problems(events) == ["stamp"] and "finish the teach" in events[-1].text
    ok, text = teach.finish_teach()
    assert ok and "map written" in text and path.is_dir()
    assert teach.finish_teach()[0] is False  # only once
    teach.process(pair(corridor, 5.0, 30.0, rng), LEFT, RIGHT, 40 * S)
    assert any(isinstance(e, Status) and e.message.startswith("teach finished") for e in events)
    teach.close()

    repeat, events = make(VtrLocalizerConfig(mode="repeat", map_path=str(path)))
    assert repeat.load_map() and "map loaded" in events[0].text
    for i, z in enumerate((0.3, 0.9, 1.5)):
        repeat.process(pair(corridor, z, 1.0 + i, rng, x=0.1), LEFT, RIGHT, 10 * S)
    locs = [e for e in events if isinstance(e, LocalizationOut)]
    assert locs and locs[-1].keyframe_frame.startswith("vtr_keyframe_") and locs[-1].covariance.shape == (6, 6)
    assert np.all(np.linalg.eigvalsh(locs[-1].covariance) > 0)
    repeat.process(pair(corridor, 0.3, 0.2, rng, x=0.1), LEFT, RIGHT, 10 * S)  # a bag played again
    assert repeat.stats["time_jumps"] == 1
    assert any(isinstance(e, Log) and "starts over" in e.text and e.level == Level.WARN for e in events)
    odom = [e for e in events if isinstance(e, OdometryOut)]
    np.testing.assert_allclose(odom[-1].T_odom_cam, np.eye(4))  # the VO chain at its origin again
    other = StereoCamera(P_RIGHT * np.array([[1.1], [1.0], [1.0]]), (W, H))
    repeat.process(pair(corridor, 0.9, 3.0, rng, x=0.1), LEFT, other, 10 * S)
    assert problems(events)[-1] in ("camera", "stereo_info")
    repeat.close()


def test_a_missing_map_is_retried_and_not_counted_as_bad_input(tmp_path) -> None:
    now = [0.0]
    events: list = []
    cfg = VtrLocalizerConfig(mode="repeat", map_path=str(tmp_path / "none"), map_retry_s=2.0)
    loc = VtrLocalizer(cfg, events.append, clock=lambda: now[0])
    assert not loc.load_map() and not loc.load_map()  # the second within map_retry_s: not tried again
    assert len([e for e in events if isinstance(e, Problem)]) == 1
    problem = next(e for e in events if isinstance(e, Problem))
    assert problem.level == Level.ERROR and not problem.counted and "no usable teach map" in loc.map_error
    now[0] = 2.5
    assert not loc.load_map() and len([e for e in events if isinstance(e, Problem)]) == 2
    assert loc.status_values()["map_loaded"] is False


def test_config_is_required(tmp_path) -> None:
    with pytest.raises(ConfigError, match="map_path"):
        VtrLocalizer(replace(VtrLocalizerConfig(), map_path=""), lambda e: None)
