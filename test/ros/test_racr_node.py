"""racr_node in-process: the three nodes of a live rACR run (racr_node, the platform simulator, the VSE stand-in)
converge on a tiny scene; the initialization flow against a synthetic rig (no rendering); and bad input — empty and
NaN clouds, bad poses, a missing reference or one of another scene, pure-translation initialization motions, a
platform that stops answering, garbage hand motions for the platform — reported on the status, no motion from
garbage, no crash.

The synthetic rig (:class:`Rig`) is a test node standing in for a platform and a VSE: it executes every hand motion
exactly (``T_base_hand ← T_base_hand · M``), reports the stop, then publishes the VSE pose of the camera carried at
the hand–eye ``X`` in a VSE frame with the monocular scale ``S_VSE`` (``t_VSE = t / s``).
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TransformStamped
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from scipy.spatial import cKDTree
from sensor_msgs.msg import Image, PointCloud2

from lightfast.config import ConfigError
from lightfast.geometry import inverse, make_transform, rotation_angle_deg, so3_exp
from lightfast.racr.reference import load_reference, write_reference
from lightfast.racr.session import initialization_motions
from lightfast.ros.convert import (
    matrix_to_pose_stamped,
    ns_to_stamp,
    numpy_to_image,
    numpy_to_pointcloud2,
    pointcloud2_to_numpy,
    xyz_to_pointcloud2,
)
from lightfast.ros.diagnostics import Level, diagnostic_level, diagnostic_values
from lightfast.ros.qos import OUTPUT_QOS
from lightfast.ros.racr_msgs import matrix_to_transform_stamped, transform_stamped_to_matrix
from lightfast.ros.racr_tools import pose7_to_matrix
from lightfast.ros.spin import spin_until
from lightfast.sim.racr import generate_racr_set, load_scene
from lightfast.sim.racr_live import evaluate_final_pose
from lightfast.topics import (
    PLATFORM_BASE_FRAME,
    PLATFORM_HAND_FRAME,
    PLATFORM_HAND_GOAL_FRAME,
    PLATFORM_POSE_TOPIC,
    PLATFORM_STATUS_TOPIC,
    PLATFORM_STOPPED_TOPIC,
    RACR_ALIGNED_CLOUD_TOPIC,
    RACR_CAMERA_POSE_TOPIC,
    RACR_HAND_MOTION_TOPIC,
    RACR_STATUS_TOPIC,
    SIM_CAMERA_POSE_TOPIC,
    VSE_FRAME,
    VSE_KEYFRAME_IMAGE_TOPIC,
    VSE_POINTS_TOPIC,
    VSE_POSE_TOPIC,
)
from racr_node.node import NODE_NAME, RacrNode
from racr_platform_sim_node.node import RacrPlatformSimNode
from racr_vse_node.node import RacrVseNode

X_TRUE = make_transform(so3_exp(np.radians(25.0) * np.array([0.6, -0.3, 0.74])), [0.03, -0.05, -0.06])
S_VSE = 0.4  # metres per VSE unit


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """S01 (indoor relief panel) at 160×120 px with a 1 cm mesh: about 1 s to build."""
    out = tmp_path_factory.mktemp("racr_scene")
    return generate_racr_set(out, scenes=["S01"], width=160, height=120, resolution_m=0.01, previews=False)[0]


def params(**values: object) -> list[Parameter]:
    return [Parameter(k, value=v) for k, v in values.items()]


class Probe:
    """Records racr_node's outputs (hand motions, status) and publishes inputs."""

    def __init__(self, make_node: Callable[..., Node], executor: Executor, name: str = "probe") -> None:
        self.executor = executor
        self.node = make_node(name)
        self.motions: list[TransformStamped] = []
        self.status: list[tuple[Level, str, dict[str, str]]] = []
        self.node.create_subscription(TransformStamped, RACR_HAND_MOTION_TOPIC, self.motions.append, OUTPUT_QOS)
        self.node.create_subscription(DiagnosticArray, RACR_STATUS_TOPIC, self._on_status, OUTPUT_QOS)
        self.pubs: dict[str, object] = {}

    def _on_status(self, msg: DiagnosticArray) -> None:
        for s in msg.status:
            if s.name == NODE_NAME:
                self.status.append((diagnostic_level(s), s.message, diagnostic_values(s)))

    def publisher(self, msg_type: type, topic: str):
        if topic not in self.pubs:
            self.pubs[topic] = self.node.create_publisher(msg_type, topic, OUTPUT_QOS)
        return self.pubs[topic]

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float = 30.0) -> bool:
        return spin_until(self.executor, predicate, timeout_s)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        spin_until(self.executor, lambda: time.monotonic() >= end, seconds + 1.0)

    def wait_status(self, predicate: Callable[[Level, str, dict[str, str]], bool], timeout_s: float = 30.0):
        def found():
            return next((s for s in reversed(self.status) if predicate(*s)), None)
        assert self.spin_until(lambda: found() is not None, timeout_s), self.status[-3:]
        return found()

    @property
    def last(self) -> tuple[Level, str, dict[str, str]]:
        assert self.status
        return self.status[-1]


@pytest.fixture
def start(executor: Executor) -> Iterator[Callable[..., Node]]:
    """``start(NodeClass, **parameters)``: a node on the test's executor, destroyed afterwards."""
    nodes: list[Node] = []

    def factory(cls: type, **values: object) -> Node:
        node = cls(context=executor.context, parameter_overrides=params(**values))
        executor.add_node(node)
        nodes.append(node)
        return node

    yield factory
    for node in reversed(nodes):
        executor.remove_node(node)
        node.destroy_node()


# ------------------------------------------------------------------------------------------------------------
# the three nodes converge


@pytest.mark.slow
def test_racr_platform_and_vse_nodes_relocalize_the_camera(scene_dir: Path, start, make_node, executor) -> None:
    """racr_node issues the four initialization motions, recovers X and s, then aligns and adjusts until g ≤ η; the
    camera really is at the reference: AFD < 3 px (the paper's success) by the simulator's truth. η = 3e-3: at
    160×120 px the estimate's own noise (~1e-3 in g) keeps the paper's 1e-4 out of reach. Measured: 3 adjustments,
    ~0.8 px, ~6 mm.

    The self-check (lightfast/racr/verification.py) may answer ``ambiguous`` here: under the varied lighting at
    160×120 px the reference image gives 4-11 SIFT matches, around its ``min_agreeing`` of 6, and the restarts of
    the geometric check then decide (seen once in CI: a restart 2.3 cm away as good). ``ambiguous`` makes no claim
    the truth can contradict; ``failed`` does (the pose is wrong): seen once in CI (session 32, after 18 adjustments
    instead of ~3, the clouds' timing differing run to run), it passes only if the truth agrees (AFD ≥ 3 px) and the
    motions were as planned. How often rACR succeeds and the check is right is measured by the evaluation (`lightfast
    eval racr`), not here."""
    probe = Probe(make_node, executor)
    aligned: list[PointCloud2] = []
    camera_poses: list[PoseStamped] = []
    probe.node.create_subscription(PointCloud2, RACR_ALIGNED_CLOUD_TOPIC, aligned.append, OUTPUT_QOS)
    probe.node.create_subscription(PoseStamped, RACR_CAMERA_POSE_TOPIC, camera_poses.append, OUTPUT_QOS)
    platform = start(RacrPlatformSimNode, scene_path=str(scene_dir), time_scale=20.0, seed=3)
    start(RacrVseNode, scene_path=str(scene_dir), seed=4)
    racr = start(RacrNode, reference_path=str(scene_dir / "reference"), reference_scene="S01", status_period_s=0.5,
                 **{"adjustment.eta": 3e-3})
    # racr_node never reads the simulator's truth
    assert SIM_CAMERA_POSE_TOPIC not in {s.topic_name for s in racr.subscriptions}
    level, message, values = probe.wait_status(lambda lv, m, v: v.get("stage") in ("converged", "ambiguous", "failed",
                                                                                   "initialization_failed"), 90.0)
    assert (values["stage"], level) in (("converged", Level.OK), ("ambiguous", Level.WARN),
                                        ("failed", Level.ERROR)), (message, values)
    assert racr.session is not None and racr.session.scheme is not None and racr.session.scheme.running
    # the initialization motions first, exactly as planned, then adjustments; nothing after convergence
    init = initialization_motions(racr.config.session)
    got = [transform_stamped_to_matrix(m) for m in probe.motions]
    assert all(f == PLATFORM_HAND_FRAME and c == PLATFORM_HAND_GOAL_FRAME for _, _, f, c in got)
    assert len(got) == int(values["motions_issued"]) >= len(init) + 1
    for (M, _, _, _), M_plan in zip(got, init, strict=False):
        assert np.allclose(M, M_plan, atol=1e-6)
    stamps = [s for _, s, _, _ in got]
    assert stamps == sorted(stamps)
    n_motions = len(probe.motions)
    probe.spin_for(1.0)
    assert len(probe.motions) == n_motions
    # where the camera is, by the truth (evaluation only)
    scene = load_scene(scene_dir)
    r = evaluate_final_pose(scene, platform.platform.true_camera_pose, scale_m_per_vse=float(values["scale_m_per_vse"]),
                            T_cam_hand=pose7_to_matrix(values["T_cam_hand"]))
    if values["stage"] == "failed":  # the self-check's verdict must be the truth's
        assert not (r.success and r.afd_px < 3.0), (message, r)
        return
    assert r.success and r.afd_px < 3.0, r
    assert r.translation_error_m < 0.02 and r.rotation_error_deg < 0.5, r
    assert abs(r.scale_error_rel) < 0.05 and r.hand_eye_rotation_error_deg < 2.0, r
    assert float(values["g"]) <= 3e-3 and values["converged"] == "true"
    assert int(values["init_motions_done"]) == 4 and int(values["bad_inputs"]) == 0
    # inspection outputs: the aligned cloud lies on the reference cloud; the camera pose is in the reference frame
    ref = load_reference(scene_dir / "reference")
    assert aligned and camera_poses and camera_poses[-1].header.frame_id == ref.frame_id
    cloud = pointcloud2_to_numpy(aligned[-1])
    pts = np.stack([cloud["x"], cloud["y"], cloud["z"]], axis=1).astype(float)
    d, _ = cKDTree(ref.points_m).query(pts)
    # the VSE cloud's own depth noise puts its median distance to the reference near 1 cm even when the pose is right
    # (1.24 cm in a run whose pose passed the checks above): 2 cm, the translation bound above, tells an aligned
    # cloud from one left in VSE coordinates or another frame (metres off); the accuracy is checked by the truth above
    assert aligned[-1].header.frame_id == ref.frame_id and np.median(d) < 0.02


# ------------------------------------------------------------------------------------------------------------
# a synthetic rig: exact platform, VSE poses without clouds


class Rig:
    """Executes hand motions exactly and answers with a stop and a VSE pose (see the module docstring)."""

    def __init__(self, probe: Probe, *, answer: int | None = None, only_translation: bool = False) -> None:
        self.probe = probe
        self.T_base_hand = make_transform(so3_exp([0.1, 0.2, -0.3]), [0.4, 0.1, 0.5])
        self.T_cam0 = self.T_base_hand @ inverse(X_TRUE)
        self.answer = answer  # answer this many commands, then go silent (None: all)
        self.only_translation = only_translation  # a broken platform that drops every rotation
        self.answered = 0
        node = probe.node
        self.pose_pub = probe.publisher(PoseStamped, PLATFORM_POSE_TOPIC)
        self.stopped_pub = probe.publisher(PoseStamped, PLATFORM_STOPPED_TOPIC)
        self.vse_pub = probe.publisher(PoseStamped, VSE_POSE_TOPIC)
        node.create_subscription(TransformStamped, RACR_HAND_MOTION_TOPIC, self._on_command, OUTPUT_QOS)
        self.now_ns = lambda: node.get_clock().now().nanoseconds

    def T_vse_cam(self) -> np.ndarray:
        T = inverse(self.T_cam0) @ self.T_base_hand @ inverse(X_TRUE)
        T[:3, 3] /= S_VSE
        return T

    def publish_state(self) -> None:
        t = self.now_ns()
        self.pose_pub.publish(matrix_to_pose_stamped(self.T_base_hand, stamp_ns=t, frame_id=PLATFORM_BASE_FRAME))
        self.vse_pub.publish(matrix_to_pose_stamped(self.T_vse_cam(), stamp_ns=t, frame_id=VSE_FRAME))

    def _on_command(self, msg: TransformStamped) -> None:
        if self.answer is not None and self.answered >= self.answer:
            return
        self.answered += 1
        M, _, _, _ = transform_stamped_to_matrix(msg)
        if self.only_translation:
            M = make_transform(np.eye(3), M[:3, 3])
        self.T_base_hand = self.T_base_hand @ M
        t = self.now_ns()
        self.stopped_pub.publish(matrix_to_pose_stamped(self.T_base_hand, stamp_ns=t, frame_id=PLATFORM_BASE_FRAME))
        self.vse_pub.publish(matrix_to_pose_stamped(self.T_vse_cam(), stamp_ns=t + 1000, frame_id=VSE_FRAME))


def start_rig_run(scene_dir: Path, start, make_node, executor, *, answer: int | None = None,
                  only_translation: bool = False, **racr_params: object) -> tuple[RacrNode, Probe, Rig]:
    probe = Probe(make_node, executor)
    rig = Rig(probe, answer=answer, only_translation=only_translation)
    racr = start(RacrNode, reference_path=str(scene_dir / "reference"), status_period_s=0.2, **racr_params)
    assert probe.spin_until(lambda: all(p.get_subscription_count() > 0 for p in probe.pubs.values()))
    rig.publish_state()
    return racr, probe, rig


def test_initialization_flow_recovers_hand_eye_and_scale_and_garbage_clouds_issue_nothing(
        scene_dir: Path, start, make_node, executor) -> None:
    """Four initialization motions (two screw motions and their inverses), X and s exactly (noise-free rig); then,
    with only garbage clouds (empty, all NaN, no x field), no adjustment is ever issued and every bad cloud is
    reported (throttled)."""
    racr, probe, rig = start_rig_run(scene_dir, start, make_node, executor, keyframes_per_cloud=0)
    level, message, values = probe.wait_status(lambda lv, m, v: v.get("stage") == "aligning")
    assert len(probe.motions) == 4 and values["init_motions_done"] == "4"
    assert float(values["scale_m_per_vse"]) == pytest.approx(S_VSE, rel=1e-6)
    X = pose7_to_matrix(values["T_cam_hand"])
    assert X is not None and np.allclose(X, X_TRUE, atol=1e-5)
    assert rotation_angle_deg(rig.T_base_hand[:3, :3], (rig.T_cam0 @ X_TRUE)[:3, :3]) < 1e-6  # back at the start
    assert level == Level.WARN and "waiting for a usable VSE cloud" in message
    cloud_pub = probe.publisher(PointCloud2, VSE_POINTS_TOPIC)
    assert probe.spin_until(lambda: cloud_pub.get_subscription_count() > 0)
    garbage = [np.zeros((0, 3), np.float32), np.full((500, 3), np.nan, np.float32)]
    for i in range(12):
        t = rig.now_ns()
        probe.publisher(PoseStamped, VSE_POSE_TOPIC).publish(
            matrix_to_pose_stamped(rig.T_vse_cam(), stamp_ns=t, frame_id=VSE_FRAME))
        pts = garbage[i % 2]
        cloud_pub.publish(xyz_to_pointcloud2(pts, stamp_ns=t, frame_id=VSE_FRAME,
                                             extra_fields={"intensity": np.zeros(len(pts), np.float32)}))
        assert probe.spin_until(lambda i=i: racr.stats["bad_inputs"] > i)
    no_x = np.zeros(50, dtype=[("y", "<f4"), ("z", "<f4")])
    cloud_pub.publish(numpy_to_pointcloud2(no_x, stamp_ns=rig.now_ns(), frame_id=VSE_FRAME))
    assert probe.spin_until(lambda: int(probe.last[2].get("bad_inputs", 0)) >= 13, 20.0), probe.status[-2:]
    problems = [m for lv, m, v in probe.status if lv == Level.WARN and "skipped" in m]
    assert any("finite points" in m for m in problems) and any("no field(s) ['x']" in m for m in problems)
    assert racr.problems._suppressed.get("cloud", 0) >= 8  # one log line per period, not one per cloud
    probe.spin_for(0.5)
    assert len(probe.motions) == 4  # no adjustment from garbage
    assert probe.last[2]["stage"] == "aligning" and probe.last[2]["fast_alignments"] == "0"


def test_pure_translation_initialization_fails_clearly(scene_dir: Path, start, make_node, executor) -> None:
    """A platform that only translates (its rotations are lost): the hand-eye cannot be determined (§3.2); the
    status says so (ERROR) and no motion follows the initialization motions."""
    racr, probe, _ = start_rig_run(scene_dir, start, make_node, executor, only_translation=True)
    level, message, values = probe.wait_status(lambda lv, m, v: v.get("stage") == "initialization_failed")
    assert level == Level.ERROR and "DegenerateMotionError" in message and "pure translations" in message
    assert values["init_error"] and len(probe.motions) == 4
    probe.spin_for(0.5)
    assert len(probe.motions) == 4 and probe.last[2]["stage"] == "initialization_failed"
    assert racr.session is not None and racr.session.scheme is None


def test_zero_rotation_configuration_is_a_degenerate_initialization(scene_dir: Path, start, make_node,
                                                                    executor) -> None:
    _, probe, _ = start_rig_run(scene_dir, start, make_node, executor, **{"session.init_rotation_deg": 0.0})
    level, message, _ = probe.wait_status(lambda lv, m, v: v.get("stage") == "initialization_failed")
    assert level == Level.ERROR and "rotate" in message


def test_a_platform_that_stops_answering(scene_dir: Path, start, make_node, executor) -> None:
    """The platform executes two motions, then never reports a stop again: stage platform_timeout (ERROR) after
    platform_timeout_s, no further motion, the node keeps reporting."""
    _, probe, rig = start_rig_run(scene_dir, start, make_node, executor, answer=2, **{"scheme.platform_timeout_s": 0.5})
    level, message, _ = probe.wait_status(lambda lv, m, v: v.get("stage") == "platform_timeout", 10.0)
    assert level == Level.ERROR and "has not reported a stop" in message and "motion 3 of 4" in message
    assert len(probe.motions) == 3 and rig.answered == 2
    n = len(probe.status)
    probe.spin_for(0.6)
    assert len(probe.motions) == 3 and len(probe.status) > n  # still alive and reporting


def test_no_platform_and_garbage_poses_issue_nothing(scene_dir: Path, start, make_node, executor) -> None:
    """Without a platform pose the node waits (WARN); NaN and non-unit-quaternion poses are reported and skipped;
    no motion is issued without a platform subscribed to /racr/hand_motion either."""
    probe = Probe(make_node, executor)
    start(RacrNode, reference_path=str(scene_dir / "reference"), status_period_s=0.2)
    level, message, _ = probe.wait_status(lambda lv, m, v: v.get("stage") == "waiting_for_platform")
    assert level == Level.WARN and "hand pose" in message
    vse = probe.publisher(PoseStamped, VSE_POSE_TOPIC)
    plat = probe.publisher(PoseStamped, PLATFORM_POSE_TOPIC)
    assert probe.spin_until(lambda: vse.get_subscription_count() > 0 and plat.get_subscription_count() > 0)
    bad = matrix_to_pose_stamped(np.eye(4), stamp_ns=1, frame_id=VSE_FRAME)
    bad.pose.position.x = math.nan
    vse.publish(bad)
    bad2 = matrix_to_pose_stamped(np.eye(4), stamp_ns=2, frame_id=PLATFORM_BASE_FRAME)
    bad2.pose.orientation.w = 3.0
    plat.publish(bad2)
    assert probe.spin_until(lambda: int(probe.last[2].get("bad_inputs", 0)) >= 2)
    msgs = [m for _, m, _ in probe.status]
    assert any("VSE pose skipped" in m and "not finite" in m for m in msgs)
    assert any("platform pose skipped" in m and "unit quaternion" in m for m in msgs)
    kf = probe.publisher(Image, VSE_KEYFRAME_IMAGE_TOPIC)
    assert probe.spin_until(lambda: kf.get_subscription_count() > 0)
    kf.publish(numpy_to_image(np.zeros((4, 4, 3), np.uint8), "rgb8", stamp_ns=3, frame_id="vse_keyframe_1"))
    assert probe.spin_until(lambda: any("keyframe image skipped" in m for _, m, _ in probe.status))
    assert probe.motions == []


def test_missing_reference_is_reported_and_retried(scene_dir: Path, tmp_path: Path, start, make_node,
                                                   executor) -> None:
    """No reference at reference_path: stage no_reference (ERROR), nothing issued although platform and VSE are
    there; once the reference appears it is loaded and the initialization starts."""
    probe = Probe(make_node, executor)
    rig = Rig(probe)
    path = tmp_path / "later"
    start(RacrNode, reference_path=str(path), reference_retry_s=0.1, status_period_s=0.2)
    level, message, _ = probe.wait_status(lambda lv, m, v: v.get("stage") == "no_reference")
    assert level == Level.ERROR and "reference.yaml missing" in message and str(path) in message
    assert probe.spin_until(lambda: all(p.get_subscription_count() > 0 for p in probe.pubs.values()))
    rig.publish_state()
    probe.spin_for(0.5)
    assert probe.motions == [] and probe.last[2]["stage"] == "no_reference"
    write_reference(load_reference(scene_dir / "reference"), path)
    assert probe.spin_until(lambda: probe.last[2].get("stage") not in (None, "no_reference"))
    rig.publish_state()
    assert probe.spin_until(lambda: len(probe.motions) >= 1)


def test_sim_time_jumping_back_starts_the_relocalization_over(scene_dir: Path, start, make_node, executor) -> None:
    """On use_sim_time, /clock going back (a restarted simulation): the session timed on the old clock is dropped
    (stopped) and a new one starts from the reference."""
    racr = start(RacrNode, reference_path=str(scene_dir / "reference"), use_sim_time=True, status_period_s=0.2)
    player = make_node("sim_clock")
    clock = player.create_publisher(Clock, "/clock", 10)
    sim = {"t": 1_700_000_000 * 10**9}

    def tick() -> None:  # sim time at wall speed: the node's timers run on it
        sim["t"] += 10_000_000
        clock.publish(Clock(clock=ns_to_stamp(sim["t"])))

    player.create_timer(0.01, tick)
    assert spin_until(executor, lambda: racr.session is not None and racr.get_clock().now().nanoseconds > 0, 30.0)
    first = racr.session
    sim["t"] -= 100 * 10**9
    assert spin_until(executor, lambda: racr.session is not None and racr.session is not first, 30.0)


def test_reference_of_another_scene_is_refused(scene_dir: Path, tmp_path: Path, start, make_node,
                                               executor) -> None:
    ref = load_reference(scene_dir / "reference")
    other = write_reference(dataclasses.replace(ref, scene="S02"), tmp_path / "S02_reference")
    probe = Probe(make_node, executor)
    start(RacrNode, reference_path=str(other), reference_scene="S01", status_period_s=0.2)
    level, message, _ = probe.wait_status(lambda lv, m, v: v.get("stage") == "no_reference")
    assert level == Level.ERROR and "scene 'S02', not 'S01'" in message


def test_racr_node_needs_a_reference_path(executor) -> None:
    with pytest.raises(ConfigError, match="reference_path is required"):
        node = RacrNode(context=executor.context)
        node.destroy_node()


# ------------------------------------------------------------------------------------------------------------
# the platform simulator refuses garbage


def test_platform_simulator_refuses_garbage_and_reports_stops(scene_dir: Path, start, make_node, executor) -> None:
    """Non-rigid, NaN, wrong-frame and too large hand motions are refused without moving (the platform reports a
    stop at once, so a client is not left waiting); a good one takes its simulated time and moves the truth."""
    probe = make_node("platform_probe")
    stops: list[PoseStamped] = []
    truth: list[PoseStamped] = []
    status: list[dict[str, str]] = []
    probe.create_subscription(PoseStamped, PLATFORM_STOPPED_TOPIC, stops.append, OUTPUT_QOS)
    probe.create_subscription(PoseStamped, SIM_CAMERA_POSE_TOPIC, truth.append, OUTPUT_QOS)
    probe.create_subscription(DiagnosticArray, PLATFORM_STATUS_TOPIC,
                              lambda m: status.append(diagnostic_values(m.status[0])), OUTPUT_QOS)
    pub = probe.create_publisher(TransformStamped, RACR_HAND_MOTION_TOPIC, OUTPUT_QOS)
    platform = start(RacrPlatformSimNode, scene_path=str(scene_dir), time_scale=100.0)
    assert spin_until(executor, lambda: pub.get_subscription_count() > 0 and truth, 20.0)
    T0 = platform.platform.true_camera_pose

    def command(M: np.ndarray, frame: str = PLATFORM_HAND_FRAME) -> TransformStamped:
        return matrix_to_transform_stamped(M, stamp_ns=probe.get_clock().now().nanoseconds, frame_id=frame,
                                           child_frame_id=PLATFORM_HAND_GOAL_FRAME)

    nan = command(np.eye(4))
    nan.transform.translation.x = math.nan
    pub.publish(nan)
    pub.publish(command(make_transform(np.eye(3), [0.01, 0, 0]), frame="world"))
    pub.publish(command(make_transform(np.eye(3), [2.0, 0, 0])))  # beyond max_translation_m
    assert spin_until(executor, lambda: len(stops) >= 3, 10.0)
    assert spin_until(executor, lambda: status and status[-1]["refused"] == "1" and
                      status[-1]["bad_commands"] == "2", 10.0), status[-1:]
    assert "max_translation_m" in status[-1]["last_error"]
    assert np.allclose(platform.platform.true_camera_pose, T0) and status[-1]["executed"] == "0"
    n_stops = len(stops)
    pub.publish(command(make_transform(so3_exp([0.0, 0.0, math.radians(2.0)]), [0.02, 0.0, 0.0])))
    assert spin_until(executor, lambda: len(stops) > n_stops and status[-1]["executed"] == "1", 10.0)
    assert float(status[-1]["simulated_time_s"]) == pytest.approx(4.0, rel=0.01)
    assert not np.allclose(platform.platform.true_camera_pose, T0, atol=1e-3)
