"""vtr_localizer_node in-process: teach a short rendered route, finish it with the service, repeat it under another
illuminant with a second node instance (fused localizes near the truth, grey does not); bad input (no camera_info,
mono8, mismatched sizes, black frames, a camera other than the map's, a missing or corrupt map) reported without a
crash; a teach shut down before it finished leaves the previous map as it was.

The route is rendered by the synthetic corridor of ``test/unit/vtr/test_teach_repeat.py`` (320×240 rectified
stereo, 24 cm baseline): a 6 m teach on the centreline under the teach lighting and a repeat 0.3 m to the side,
2° turned, under the "changed" illuminant pattern (greyscale cannot match it, F_v / F_r can).
"""
from __future__ import annotations

import functools
import re
import shutil
from collections import defaultdict
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger

from lightfast.camera import PinholeCamera
from lightfast.config import ConfigError
from lightfast.ros.convert import (
    camera_info_from_camera,
    image_to_numpy,
    numpy_to_image,
    odometry_to_matrix,
    pose_to_matrix,
    stamp_to_ns,
)
from lightfast.ros.diagnostics import Level
from lightfast.ros.msgtypes import RCLPY, MessageTypes
from lightfast.ros.qos import OUTPUT_QOS
from lightfast.ros.tf import TF_QOS, TF_TOPIC
from lightfast.topics import (
    STEREO_LEFT_FRAME,
    STEREO_LEFT_IMAGE_TOPIC,
    STEREO_LEFT_INFO_TOPIC,
    STEREO_RIGHT_FRAME,
    STEREO_RIGHT_IMAGE_TOPIC,
    STEREO_RIGHT_INFO_TOPIC,
    VTR_FINISH_TEACH_SERVICE,
    VTR_FR_TOPIC,
    VTR_FV_TOPIC,
    VTR_LOCALIZATION_TOPIC,
    VTR_ODOM_FRAME,
    VTR_ODOMETRY_TOPIC,
    VTR_STATUS_TOPIC,
)
from lightfast.vtr import MapExistsError, MapStore, TeachConfig, TeachMap, TeachPipeline
from test.ros.probe import StatusProbe
from test.unit.vtr import test_teach_repeat as corridor
from vtr_localizer_node.node import VtrLocalizerNode

TIMEOUT_S = 30.0
STEP_NS = 500_000_000  # 2 Hz, like the simulated recordings
TEACH_T0_NS = 1_700_000_000 * 10**9
REPEAT_T0_NS = TEACH_T0_NS + 86_400 * 10**9  # the next day
TEACH_Z = tuple(np.round(np.arange(0.0, 6.01, 0.6), 3))  # 11 pairs, 6 m: 6 keyframes at 1 m spacing
REPEAT_Z = tuple(np.round(np.arange(0.25, 5.8, 0.5), 3))  # 12 pairs
REPEAT_X, REPEAT_YAW_DEG = corridor.REPEAT_X, corridor.REPEAT_YAW_DEG
#: Localization tolerances relative to the taught path (measured: all pairs within 2 cm under the changed light)
TOL_M, TOL_DEG = 0.05, 0.5


# --------------------------------------------------------------------------------------------------------------
# The route (shared with test/replay/test_vtr_cross_process.py)


@dataclass(frozen=True)
class Route:
    """Rendered stereo pairs with their true left-camera poses (corridor world frame) and stamps."""

    teach: tuple[tuple[np.ndarray, np.ndarray], ...]
    teach_poses: tuple[np.ndarray, ...]
    teach_stamps: tuple[int, ...]
    repeat: tuple[tuple[np.ndarray, np.ndarray], ...]
    repeat_poses: tuple[np.ndarray, ...]
    repeat_stamps: tuple[int, ...]

    def keyframe_pose(self, teach_map: TeachMap, k: int) -> np.ndarray:
        """True pose of keyframe ``k`` (its stamp is that of a teach pair)."""
        return self.teach_poses[self.teach_stamps.index(teach_map.keyframes[k].stamp_ns)]


@functools.cache
def route() -> Route:
    scene = corridor.Scene()
    teach_poses = tuple(corridor.pose(0.0, z) for z in TEACH_Z)
    repeat_poses = tuple(corridor.pose(REPEAT_X, z, REPEAT_YAW_DEG) for z in REPEAT_Z)
    rng = np.random.default_rng(61)
    teach = tuple(scene.stereo("teach", T, rng) for T in teach_poses)
    repeat = tuple(scene.stereo("changed", T, rng) for T in repeat_poses)
    return Route(teach, teach_poses, tuple(TEACH_T0_NS + i * STEP_NS for i in range(len(teach))),
                 repeat, repeat_poses, tuple(REPEAT_T0_NS + i * STEP_NS for i in range(len(repeat))))


def stereo_camera_infos(stamp_ns: int = 0, *, types: MessageTypes = RCLPY, scale: float = 1.0,
                        P_right: np.ndarray | None = None) -> tuple[object, object]:
    """``camera_info`` of the corridor's rectified pair (P_left = [K|0], P_right with Tx = −f·B); ``scale`` resizes
    the camera, ``P_right`` replaces the right projection matrix."""
    camera = PinholeCamera.from_matrix(corridor.K, corridor.W, corridor.H).scaled(scale)
    left = camera_info_from_camera(camera, stamp_ns=stamp_ns, frame_id=STEREO_LEFT_FRAME, types=types)
    right = camera_info_from_camera(camera, stamp_ns=stamp_ns, frame_id=STEREO_RIGHT_FRAME, types=types)
    Pr = np.c_[camera.K, [-camera.fx * corridor.B, 0.0, 0.0]] if P_right is None else P_right
    right.p = types.float64_array(Pr)
    return left, right


def translation_rotation_error(T: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    return float(np.linalg.norm(T[:3, 3] - T_true[:3, 3])), corridor.rotation_deg(np.linalg.inv(T_true) @ T)


# --------------------------------------------------------------------------------------------------------------
# Probe and node helpers

INPUTS = {"left": (Image, STEREO_LEFT_IMAGE_TOPIC), "right": (Image, STEREO_RIGHT_IMAGE_TOPIC),
          "left_info": (CameraInfo, STEREO_LEFT_INFO_TOPIC), "right_info": (CameraInfo, STEREO_RIGHT_INFO_TOPIC)}
OUTPUTS = {"localization": (PoseWithCovarianceStamped, VTR_LOCALIZATION_TOPIC), "odom": (Odometry, VTR_ODOMETRY_TOPIC),
           "fv": (Image, VTR_FV_TOPIC), "fr": (Image, VTR_FR_TOPIC)}


class Probe(StatusProbe):
    """A test node: publishers of the node's inputs, recorders of its outputs (by stamp), the finish client."""

    timeout_s = TIMEOUT_S

    def __init__(self, make_node: Callable[..., Node], executor: Executor) -> None:
        self.executor = executor
        self.node = make_node("vtr_probe")
        self.pubs = {k: self.node.create_publisher(t, topic, OUTPUT_QOS) for k, (t, topic) in INPUTS.items()}
        self.got: dict[str, dict[int, object]] = defaultdict(dict)
        self.status: list[DiagnosticArray] = []
        self.subs = [self.node.create_subscription(DiagnosticArray, VTR_STATUS_TOPIC, self.status.append, OUTPUT_QOS)]
        for key, (t, topic) in OUTPUTS.items():
            self.subs.append(self.node.create_subscription(t, topic, self._recorder(key), OUTPUT_QOS))
        self.client = self.node.create_client(Trigger, VTR_FINISH_TEACH_SERVICE)

    def _recorder(self, key: str) -> Callable[[object], None]:
        def record(msg: object) -> None:
            self.got[key][stamp_to_ns(msg.header.stamp)] = msg  # type: ignore[attr-defined]
        return record

    def reset(self) -> None:
        self.got.clear()
        self.status.clear()

    def wait_matched(self) -> None:
        """Exactly one node on the other side of every topic and the service."""
        assert self.spin_until(lambda: all(p.get_subscription_count() == 1 for p in self.pubs.values())
                               and all(s.get_publisher_count() == 1 for s in self.subs)
                               and self.client.service_is_ready())

    def publish(self, key: str, msg: object) -> None:
        self.pubs[key].publish(msg)

    def send_infos(self, infos: tuple[object, object] | None = None) -> None:
        left, right = stereo_camera_infos() if infos is None else infos
        self.publish("left_info", left)
        self.publish("right_info", right)

    def send_pair(self, stamp_ns: int, left: np.ndarray, right: np.ndarray, *, right_first: bool = False,
                  left_encoding: str = "rgb8") -> None:
        msgs = [("left", numpy_to_image(left, left_encoding, stamp_ns=stamp_ns, frame_id=STEREO_LEFT_FRAME)),
                ("right", numpy_to_image(right, "rgb8", stamp_ns=stamp_ns, frame_id=STEREO_RIGHT_FRAME))]
        for key, msg in reversed(msgs) if right_first else msgs:
            self.publish(key, msg)

    def frame_status(self, stamp_ns: int) -> tuple[Level, str, dict[str, str]]:
        return self.wait_status(lambda lvl, msg, v: v.get("stamp_ns") == str(stamp_ns))

    def problem(self, text: str) -> tuple[Level, str, dict[str, str]]:
        return self.wait_status(lambda lvl, msg, v: text in msg and lvl != Level.OK)

    def finish(self) -> Trigger.Response:
        future = self.client.call_async(Trigger.Request())
        assert self.spin_until(future.done)
        return future.result()


@pytest.fixture
def vtr(executor: Executor, make_node: Callable[..., Node]) -> Iterator[Callable[..., tuple[VtrLocalizerNode, Probe]]]:
    """``vtr(**params) -> (node, probe)``: a node on the test executor (the previous one is destroyed first: the
    shutdown of a process) and a probe matched with it."""
    state: dict[str, object] = {}

    def start(**params: object) -> tuple[VtrLocalizerNode, Probe]:
        stop()
        params = {"sensor_reliability": "reliable", **params}  # lossless: the tests count every pair
        node = VtrLocalizerNode(context=executor.context,
                                parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
        executor.add_node(node)
        state["node"] = node
        probe = state.get("probe")
        if probe is None:
            probe = state["probe"] = Probe(make_node, executor)
        assert isinstance(probe, Probe)
        probe.reset()
        probe.wait_matched()
        return node, probe

    def stop() -> None:
        node = state.pop("node", None)
        if isinstance(node, VtrLocalizerNode):
            executor.remove_node(node)
            node.destroy_node()

    start.stop = stop  # type: ignore[attr-defined]
    yield start
    stop()


@pytest.fixture(scope="module")
def small_map(tmp_path_factory: pytest.TempPathFactory) -> TeachMap:
    """A map of the first 2.4 m of the route taught with the core pipeline (3 keyframes)."""
    r = route()
    teach = TeachPipeline(tmp_path_factory.mktemp("vtr_small") / "map", TeachConfig())
    for stamp, (left, right) in zip(r.teach_stamps[:5], r.teach[:5], strict=True):
        teach.step(stamp, left, right, corridor.P_LEFT, corridor.P_RIGHT)
    return teach.finish()


def partial_dirs(map_path: Path) -> list[Path]:
    return sorted(map_path.parent.glob(f".{map_path.name}.*"))


# --------------------------------------------------------------------------------------------------------------
# Tests


def test_teach_finish_then_repeat_localizes_near_the_truth(vtr, tmp_path: Path) -> None:
    """Teach, finish, repeat; the bag played again restarts the repeat; the poses on /tf."""
    r = route()
    map_path = tmp_path / "route_map"
    node, probe = vtr(mode="teach", map_path=str(map_path))
    probe.send_infos()
    for i, (stamp, (left, right)) in enumerate(zip(r.teach_stamps, r.teach, strict=True)):
        probe.send_pair(stamp, left, right, right_first=bool(i % 2))  # either image may come first
        level, message, values = probe.frame_status(stamp)
        assert level == Level.OK, message
        assert values["mode"] == "teach" and int(values["landmarks_fv"]) > 100 and float(values["front_end_ms"]) > 0
    assert not map_path.exists()  # nothing at the path before the teach finishes
    # VO odometry and the colour-constant images of the left camera
    assert probe.spin_until(lambda: r.teach_stamps[-1] in probe.got["odom"] and r.teach_stamps[-1] in probe.got["fr"])
    T, _, frame_id, child = odometry_to_matrix(probe.got["odom"][r.teach_stamps[-1]])
    assert (frame_id, child) == (VTR_ODOM_FRAME, STEREO_LEFT_FRAME)
    assert abs(T[2, 3] - TEACH_Z[-1]) < 0.1 and abs(T[0, 3]) < 0.05, T[:3, 3]
    for key in ("fv", "fr"):
        img = probe.got[key][r.teach_stamps[-1]]
        assert (img.encoding, img.width, img.height) == ("mono8", corridor.W, corridor.H)
        assert np.ptp(image_to_numpy(img)) > 50  # texture, not a flat image

    response = probe.finish()
    assert response.success, response.message
    m = re.search(r"(\d+) keyframes, ([\d.]+) m path", response.message)
    assert m, response.message
    taught = MapStore.load(map_path)
    assert int(m.group(1)) == len(taught) >= 6 and abs(float(m.group(2)) - TEACH_Z[-1]) < 0.1
    assert taught.sources == ("grey", "fv", "fr") and not partial_dirs(map_path)
    again = probe.finish()
    assert not again.success and "already finished" in again.message
    assert node.stats["bad_inputs"] == 0

    # a second node instance repeats the route under the changed illuminant
    node, probe = vtr(mode="repeat", map_path=str(map_path), **{"repeat.mode": "fused"})
    probe.wait_status(lambda lvl, msg, v: msg.startswith(f"map loaded: {len(taught)} keyframes"))
    probe.send_infos()
    errors = []
    for i, (stamp, (left, right)) in enumerate(zip(r.repeat_stamps, r.repeat, strict=True)):
        probe.send_pair(stamp, left, right, right_first=bool(i % 2))
        level, message, values = probe.frame_status(stamp)
        assert values["localized"] == "true" and level == Level.OK, (i, message)
        assert probe.spin_until(lambda s=stamp: s in probe.got["localization"] and s in probe.got["odom"])
        loc = probe.got["localization"][stamp]
        k = int(values["keyframe_id"])
        assert loc.header.frame_id == f"vtr_keyframe_{k}"
        truth = np.linalg.inv(r.keyframe_pose(taught, k)) @ r.repeat_poses[i]
        errors.append(translation_rotation_error(pose_to_matrix(loc.pose.pose), truth))
        cov = np.asarray(loc.pose.covariance).reshape(6, 6)
        assert np.all(np.isfinite(cov)) and np.all(np.diag(cov) > 0) and np.allclose(cov, cov.T)
        assert float(values["distance_on_vo_m"]) == 0.0 and values["failure"] == ("true" if i == 0 else "false")
        assert int(values["inliers_fv"]) + int(values["inliers_fr"]) >= 20, values
        for stage in ("front_end", "vo", "localization", "total"):
            assert float(values[f"{stage}_ms"]) > 0, stage
    t_err, r_err = np.array(errors).T
    assert t_err.max() < TOL_M and r_err.max() < TOL_DEG, (t_err, r_err)
    assert values["relocalized"] == "false" and node.stats["frames_done"] == len(r.repeat)
    # a featureless pair (fog): VO alone carries the pose on, with a covariance growing with the distance on VO
    fog_stamp = r.repeat_stamps[-1] + STEP_NS
    fog = np.full_like(r.repeat[0][0], 128)
    probe.send_pair(fog_stamp, fog, fog)
    level, message, values = probe.frame_status(fog_stamp)
    assert (level, values["localized"], values["failure"]) == (Level.WARN, "false", "false"), message
    d = float(values["distance_on_vo_m"])
    assert "on VO for" in message and 0.3 < d < 0.7, d  # the constant-velocity step
    assert probe.spin_until(lambda: fog_stamp in probe.got["localization"])
    cov = np.asarray(probe.got["localization"][fog_stamp].pose.covariance).reshape(6, 6)
    np.testing.assert_allclose(np.diag(cov)[:3], (0.05 * d) ** 2 + 1e-6, rtol=1e-4)  # vo_drift_m_per_m (d: 6 digits)

    # the bag played again: the stamps go back, the repeat starts over (VO at its origin, a whole-map search); on /tf
    # the left camera hangs off vtr_odom and the localized keyframe off the camera (the camera keeps one parent)
    tf2_msgs = pytest.importorskip("tf2_msgs.msg", reason="tf2_msgs is built by scripts/setup.sh")
    transforms: list = []
    probe.node.create_subscription(tf2_msgs.TFMessage, TF_TOPIC, lambda m: transforms.extend(m.transforms), TF_QOS)
    probe.reset()
    stamp0 = r.repeat_stamps[0]
    probe.send_pair(stamp0, *r.repeat[0])
    level, message, values = probe.frame_status(stamp0)
    assert values["localized"] == "true" and values["searched_map"] == "true", message
    assert node.stats["time_jumps"] == 1
    assert probe.spin_until(lambda: stamp0 in probe.got["localization"] and stamp0 in probe.got["odom"]
                            and len([t for t in transforms if stamp_to_ns(t.header.stamp) == stamp0]) == 2)
    tf = {(t.header.frame_id, t.child_frame_id): t.transform for t in transforms
          if stamp_to_ns(t.header.stamp) == stamp0}
    keyframe = probe.got["localization"][stamp0].header.frame_id
    assert set(tf) == {(VTR_ODOM_FRAME, STEREO_LEFT_FRAME), (STEREO_LEFT_FRAME, keyframe)}
    np.testing.assert_allclose(pose_to_matrix(probe.got["odom"][stamp0].pose.pose), np.eye(4), atol=1e-9)  # origin
    t = tf[(STEREO_LEFT_FRAME, keyframe)].translation
    T_kf_cam = pose_to_matrix(probe.got["localization"][stamp0].pose.pose)
    np.testing.assert_allclose([t.x, t.y, t.z], np.linalg.inv(T_kf_cam)[:3, 3], atol=1e-9)

    # legacy greyscale cannot match the changed illuminant: it never localizes near the truth. (Its whole-map search
    # may accept a wrong consensus of a few inliers in this repetitive corridor: 9 of 96 matches, 2.7 m off, found
    # by the PROSAC-ordered hypotheses.) A frame without a localization is reported as such.
    node, probe = vtr(mode="repeat", map_path=str(map_path), **{"repeat.mode": "grey"})
    probe.send_infos()
    probe.send_pair(r.repeat_stamps[0] - STEP_NS, fog, fog)
    level, message, values = probe.frame_status(r.repeat_stamps[0] - STEP_NS)
    assert (level, values["localized"], values["failure"]) == (Level.WARN, "false", "true"), message
    assert "not localized yet" in message and values["repeat_mode"] == "grey"
    for i, (stamp, (left, right)) in enumerate(zip(r.repeat_stamps[:2], r.repeat[:2], strict=True)):
        probe.send_pair(stamp, left, right)
        level, message, values = probe.frame_status(stamp)
        if values["localized"] == "true":
            assert probe.spin_until(lambda s=stamp: s in probe.got["localization"])
            truth = np.linalg.inv(r.keyframe_pose(taught, int(values["keyframe_id"]))) @ r.repeat_poses[i]
            assert translation_rotation_error(pose_to_matrix(probe.got["localization"][stamp].pose.pose),
                                              truth)[0] > 10 * TOL_M, message
        else:
            assert level == Level.WARN and "not localized" in message, message


def test_teach_bad_input_is_reported_and_a_shutdown_leaves_the_previous_map(vtr, small_map: TeachMap,
                                                                            tmp_path: Path) -> None:
    r = route()
    map_path = MapStore.save(small_map, tmp_path / "map")  # the previous complete map
    node, probe = vtr(mode="teach", map_path=str(map_path), overwrite_map=True)
    left, right = r.teach[0]
    stamps = iter(TEACH_T0_NS + i * STEP_NS for i in range(100))

    probe.send_pair(next(stamps), left, right)  # before any camera_info
    assert "/stereo/left/camera_info and /stereo/right/camera_info" in probe.problem("no usable camera_info")[1]
    nothing = probe.finish()
    assert not nothing.success and "nothing taught yet" in nothing.message
    uncalibrated, _ = stereo_camera_infos()
    uncalibrated.p = np.zeros(12)
    probe.publish("left_info", uncalibrated)
    probe.problem("ignored /stereo/left/camera_info: P is zero")
    probe.send_infos()
    probe.send_pair(next(stamps), left[..., 1].copy(), right, left_encoding="mono8")
    probe.problem("encoding 'mono8' is not supported (accepted: rgb8")
    probe.send_pair(next(stamps), left, right[::2, ::2].copy())
    probe.problem("left image 320x240 and right image 160x120 differ in size")
    probe.send_pair(next(stamps), left[:4, :4].copy(), right[:4, :4].copy())
    probe.problem("images of 4x4 are too small")
    probe.send_pair(next(stamps), np.zeros_like(left), np.zeros_like(right))
    probe.problem("black left and right image")
    probe.send_infos(stereo_camera_infos(scale=0.5))
    assert probe.spin_until(lambda: node._info["right"].size == (160, 120))
    probe.send_pair(next(stamps), left, right)
    probe.problem("images are 320x240 but the left camera_info says 160x120")
    probe.send_infos(stereo_camera_infos(P_right=corridor.P_LEFT))  # no baseline
    assert probe.spin_until(lambda: node._info["right"].size == (320, 240))
    probe.send_pair(next(stamps), left, right)
    probe.problem("no stereo baseline")
    assert node.stats["bad_inputs"] >= 8 and node.stats["frames_done"] == 0

    # good pairs are taught (keyframes go to the hidden staging directory) ...
    probe.send_infos()
    for (lft, rgt) in r.teach[:4]:
        stamp = next(stamps)
        probe.send_pair(stamp, lft, rgt)
        assert probe.frame_status(stamp)[0] == Level.OK
    assert node.teach is not None and node.teach.num_keyframes >= 2
    assert partial_dirs(map_path)
    # ... and the node shuts down before the teach finished: the previous map is unchanged, no partial map is left
    vtr.stop()
    kept = MapStore.load(map_path)
    assert [k.stamp_ns for k in kept.keyframes] == [k.stamp_ns for k in small_map.keyframes]
    assert not partial_dirs(map_path)


def test_repeat_reports_a_missing_or_corrupt_map_and_starts_once_it_is_there(vtr, small_map: TeachMap,
                                                                              tmp_path: Path) -> None:
    r = route()
    map_path = tmp_path / "map"
    node, probe = vtr(mode="repeat", map_path=str(map_path), map_retry_s=0.1)
    level, message, values = probe.wait_status(lambda lvl, msg, v: "no teach map at" in msg)
    assert level == Level.ERROR and values["map_loaded"] == "false" and "retrying every 0.1 s" in message
    probe.send_infos()
    left, right = r.teach[1]  # the teach lighting at 0.6 m: within the small map
    probe.send_pair(r.teach_stamps[1], left, right)
    level, message, _ = probe.frame_status(r.teach_stamps[1])
    assert level == Level.ERROR and "skipped: no usable teach map" in message
    refused = probe.finish()
    assert not refused.success and "repeat mode" in refused.message

    # a corrupt map (truncated keyframe) is refused with the reason
    tmp = MapStore.save(small_map, tmp_path / "corrupt")
    kf = tmp / "keyframes" / "kf_000001.npz"
    kf.write_bytes(kf.read_bytes()[:100])
    shutil.move(tmp, map_path)
    level, message, _ = probe.wait_status(lambda lvl, msg, v: "checksum" in msg)
    assert level == Level.ERROR and "keyframe 1" in message
    # the complete map replaces it: loaded at the next retry
    MapStore.save(small_map, map_path, overwrite=True)
    probe.wait_status(lambda lvl, msg, v: msg.startswith(f"map loaded: {len(small_map)} keyframes"))

    # a camera other than the taught one is refused
    P_wide = np.c_[corridor.K, [-corridor.F * 0.5, 0.0, 0.0]]  # 50 cm baseline
    probe.send_infos(stereo_camera_infos(P_right=P_wide))
    assert probe.spin_until(lambda: node._info["right"].P[0, 3] == P_wide[0, 3])
    probe.send_pair(r.teach_stamps[2], left, right)
    probe.problem("differs from the map's")
    # the taught camera again: localized by the whole-map search
    probe.send_infos()
    assert probe.spin_until(lambda: node._info["right"].P[0, 3] == corridor.P_RIGHT[0, 3])
    probe.send_pair(r.teach_stamps[3], left, right)
    level, message, values = probe.frame_status(r.teach_stamps[3])
    assert values["localized"] == "true" and values["searched_map"] == "true", message
    assert probe.spin_until(lambda: r.teach_stamps[3] in probe.got["localization"])
    T = pose_to_matrix(probe.got["localization"][r.teach_stamps[3]].pose.pose)
    truth = np.linalg.inv(r.keyframe_pose(small_map, int(values["keyframe_id"]))) @ r.teach_poses[1]
    assert translation_rotation_error(T, truth)[0] < TOL_M


def test_bad_configuration_is_refused_at_start(ros_context, small_map: TeachMap, tmp_path: Path) -> None:
    def make(**params: object) -> VtrLocalizerNode:
        return VtrLocalizerNode(context=ros_context, parameter_overrides=[Parameter(k, value=v)
                                                                          for k, v in params.items()])

    with pytest.raises(ConfigError, match="map_path is required"):
        make(mode="teach")
    existing = MapStore.save(small_map, tmp_path / "map")
    with pytest.raises(MapExistsError):
        make(mode="teach", map_path=str(existing))
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "todo.txt").write_text("mine")
    with pytest.raises(ConfigError, match="not a teach map"):
        make(mode="teach", map_path=str(tmp_path / "notes"), overwrite_map=True)
    (tmp_path / "empty").mkdir()
    with pytest.raises(ConfigError, match="empty directory"):
        make(mode="teach", map_path=str(tmp_path / "empty"))
    with pytest.raises(ConfigError, match="grey"):
        make(mode="teach", map_path=str(tmp_path / "new"), **{"teach.sources": ["fv", "fr"]})
    assert (tmp_path / "notes" / "todo.txt").read_text() == "mine"
