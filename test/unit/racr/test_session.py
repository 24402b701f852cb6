"""The rACR session (paper §3.2 then §3.6) without ROS: the initialization motions, the pairing of camera and hand
motions by stamps (a motion ends with a stop stamped at or after it and a VSE pose stamped after the stop), X and s
exactly from a noise-free rig, and the stop conditions (failed initialization, platform timeout)."""
from __future__ import annotations

import numpy as np
import pytest

from lightfast.config import ConfigError
from lightfast.geometry import inverse, make_transform, rotation_angle_deg, so3_exp
from lightfast.racr import AlignmentError, SchemeConfig
from lightfast.racr.session import RacrSession, SessionConfig, initialization_motions

X_TRUE = make_transform(so3_exp(np.radians(30.0) * np.array([0.0, 0.6, 0.8])), [0.05, -0.02, -0.07])
S_VSE = 2.5
REFERENCE = np.random.default_rng(0).uniform(-0.5, 0.5, (500, 3)) * [1.0, 1.0, 0.1] + [0.0, 0.0, 1.0]


class Rig:
    """Exact platform and VSE (poses only) on a settable clock."""

    def __init__(self, *, rotations: bool = True) -> None:
        self.now = 0.0
        self.T_base_hand = make_transform(so3_exp([0.2, -0.1, 0.3]), [0.3, 0.2, 0.4])
        self.T_cam0 = self.T_base_hand @ inverse(X_TRUE)
        self.rotations = rotations

    def clock(self) -> float:
        return self.now

    def T_vse_cam(self) -> np.ndarray:
        T = inverse(self.T_cam0) @ self.T_base_hand @ inverse(X_TRUE)
        T[:3, 3] /= S_VSE
        return T

    def execute(self, M: np.ndarray) -> None:
        self.T_base_hand = self.T_base_hand @ (M if self.rotations else make_transform(np.eye(3), M[:3, 3]))


def session(rig: Rig, **config: object) -> RacrSession:
    return RacrSession(REFERENCE, np.eye(4), config=SessionConfig(**config),
                       scheme_config=SchemeConfig(platform_timeout_s=5.0), clock=rig.clock)


def run_initialization(s: RacrSession, rig: Rig) -> list:
    commands = []
    s.add_platform_pose(rig.T_base_hand, stamp=rig.now)
    s.add_vse_pose(rig.T_vse_cam(), stamp=rig.now)
    for _ in range(20):
        rig.now += 0.1
        cmd = s.next_hand_motion()
        if cmd is None:
            continue
        commands.append(cmd)
        assert s.next_hand_motion() is None  # one at a time: nothing before the stop
        rig.now += 1.0
        rig.execute(cmd.M_hand)
        s.add_vse_pose(rig.T_vse_cam(), stamp=rig.now - 0.5)  # taken during the motion: not used
        s.platform_stopped(rig.T_base_hand, stamp=rig.now)
        assert s.next_hand_motion() is None  # no VSE pose after the stop yet
        rig.now += 0.1
        s.add_vse_pose(rig.T_vse_cam(), stamp=rig.now)
    return commands


def test_initialization_recovers_hand_eye_and_scale_exactly() -> None:
    rig = Rig()
    s = session(rig)
    try:
        commands = run_initialization(s, rig)
        plan = initialization_motions(s.config)
        assert len(commands) == len(plan) == 4 and all(c.kind == "initialization" for c in commands)
        assert all(np.allclose(c.M_hand, M) for c, M in zip(commands, plan, strict=True))
        assert [c.index for c in commands] == [1, 2, 3, 4]
        st = s.status
        assert st.init_motions_done == 4 and st.scale_m_per_vse == pytest.approx(S_VSE, rel=1e-9)
        assert np.allclose(st.T_cam_hand, X_TRUE, atol=1e-9)
        assert s.scheme is not None and s.scheme.running  # the scheme took over
        assert st.stage == "aligning" and st.level == "warn"  # it waits for a cloud
        # the screw motions: 20 deg about hand x / y with 2 cm along the axis, each followed by its inverse
        assert rotation_angle_deg(plan[0][:3, :3]) == pytest.approx(20.0)
        assert np.allclose(plan[0][:3, 3], [0.02, 0.0, 0.0]) and np.allclose(plan[1], inverse(plan[0]))
        # clouds are checked like the scheme checks them
        with pytest.raises(AlignmentError, match="finite points"):
            s.add_vse_observation(np.full((100, 3), np.nan), None, rig.T_vse_cam(), [], stamp=rig.now)
    finally:
        s.stop()
    assert not s.scheme.running


def test_pure_translations_end_in_initialization_failed() -> None:
    rig = Rig(rotations=False)
    s = session(rig)
    commands = run_initialization(s, rig)
    st = s.status
    assert len(commands) == 4 and st.stage == "initialization_failed" and st.level == "error"
    assert "DegenerateMotionError" in st.init_error and s.scheme is None
    rig.now += 10.0
    assert s.next_hand_motion() is None


def test_a_missing_stop_is_a_platform_timeout() -> None:
    rig = Rig()
    s = session(rig)
    s.add_platform_pose(rig.T_base_hand, stamp=0.0)
    assert s.status.stage == "waiting_for_vse"
    s.add_vse_pose(rig.T_vse_cam(), stamp=0.0)
    cmd = s.next_hand_motion()
    assert cmd is not None and s.status.stage == "initializing"
    s.platform_stopped(rig.T_base_hand, stamp=cmd.stamp - 0.1)  # an old stop does not end the command
    rig.now += 6.0
    st = s.status
    assert st.stage == "platform_timeout" and st.level == "error" and "motion 1 of 4" in st.message
    assert s.next_hand_motion() is None


def test_session_config_needs_an_axis() -> None:
    with pytest.raises(ConfigError, match="at least one hand axis"):
        SessionConfig(init_axes=())
