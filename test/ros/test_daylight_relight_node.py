"""daylight_relight_node in-process: image/pose stamp matching in either order, B̂_sun swapped in only for complete
epochs, bad input (missing camera_info, wrong encoding, NaN pose, chunks of another map) reported without a crash.

The scene helpers here are shared with test_rgbd_tracker_node.py: the tiny window room, the sun through its window,
live frames rendered with known brightness scales at known poses, and a gamma camera response saved as a file.
"""
from __future__ import annotations

import dataclasses
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Vector3Stamped
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from daylight_relight_node.node import CHUNK_QOS, DaylightRelightNode
from lightfast.camera import PinholeCamera
from lightfast.daylight.brightness import relit_image
from lightfast.daylight.crf import CameraResponse, save_crf
from lightfast.daylight.lighting_map import LightingMap
from lightfast.daylight.sun_update import sun_radiosity
from lightfast.geometry import look_at, se3_exp
from lightfast.ros.convert import (
    camera_info_from_camera,
    image_to_numpy,
    matrix_to_pose_stamped,
    numpy_to_image,
    numpy_to_pointcloud2,
    stamp_to_ns,
)
from lightfast.ros.diagnostics import Level
from lightfast.ros.qos import OUTPUT_QOS
from lightfast.ros.spin import spin_until
from lightfast.topics import (
    COARSE_POSE_TOPIC,
    COLOR_INFO_TOPIC,
    COLOR_TOPIC,
    OPTICAL_FRAME,
    REFERENCE_COLOR_TOPIC,
    REFERENCE_DEPTH_TOPIC,
    RELIGHT_STATUS_TOPIC,
    SCALE_SUN_TOPIC,
    SUN_CHUNK_TOPIC,
)
from sun_update_node.node import CHUNK_DTYPE
from test.helpers import distorted
from test.ros.probe import StatusProbe

S_TRUE = np.array([[800.0, 760.0, 680.0], [60.0, 70.0, 90.0], [30.0, 28.0, 24.0]])  # sun, sky, ground
T0_S = 1_700_000_000
TIMEOUT_S = 15.0


@dataclass
class Scene:
    lighting_map: Path
    lmap: LightingMap
    sun: np.ndarray  # (V, 3) B̂_sun of the scene's sun position
    crf: CameraResponse
    crf_file: Path
    camera: PinholeCamera
    poses: list[np.ndarray]  # true T_map_cam of the frames
    frames: list[tuple[np.ndarray, np.ndarray]]  # live (rgb8, depth_m) rendered at the poses

    def render(self, T: np.ndarray, sun: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        comps = {"sun": self.sun if sun is None else sun, "sky": self.lmap.sky_radiosity,
                 "ground": self.lmap.ground_radiosity}
        r = relit_image(self.lmap, comps, S_TRUE, T, self.camera, self.crf)
        return r.rgb8(), r.depth_m


def make_scene(lighting_map: Path, directory: Path, num_frames: int = 4) -> Scene:
    lmap = LightingMap.load(lighting_map)
    el = np.radians(35.0)
    sun = sun_radiosity(lmap, np.array([0.0, -np.cos(el), np.sin(el)])).astype(np.float32)  # through the window
    crf = CameraResponse.from_function(lambda v: (v / 255.0) ** 2.2, exposure_s=0.004, sensitivity=2.5)
    crf_file = save_crf(crf, directory / "crf.yaml")
    camera = PinholeCamera(160, 120, 125.0, 125.0, 79.5, 59.5)
    eye = [3.5, 4.0, 1.6]
    T0 = look_at(eye, np.add(eye, [-1.0, -2.0, -0.8]))  # towards the south-west corner and the sunlit floor
    poses = [T0 @ se3_exp([0.01 * i, 0.005 * i, 0.0, 0.0, 0.01 * i, 0.0]) for i in range(num_frames)]
    scene = Scene(lighting_map, lmap, sun, crf, crf_file, camera, poses, [])
    scene.frames = [scene.render(T) for T in poses]
    return scene


LENS = [-0.2, 0.06, 0.001, -0.001, 0.0]  # plumb_bob, as strong as a RealSense D455's colour lens at its corners


def lens_info(scene: Scene, d: list[float]) -> CameraInfo:
    info = camera_info_from_camera(scene.camera, frame_id=OPTICAL_FRAME)
    info.distortion_model, info.d = "plumb_bob", d
    return info


def lens_frame(scene: Scene, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Frame ``i`` as a camera with lens ``LENS`` records it (rgb8, depth m): sampled where its rays go from a
    rendering at 4x the resolution with a margin of 20 % (the barrel lens sees beyond the pinhole image's edges)."""
    fine = scene.camera.scaled(4)
    pad_u, pad_v = fine.width // 5, fine.height // 5
    wide = PinholeCamera(fine.width + 2 * pad_u, fine.height + 2 * pad_v, fine.fx, fine.fy, fine.cx + pad_u,
                         fine.cy + pad_v)
    rgb, depth = dataclasses.replace(scene, camera=wide).render(scene.poses[i])
    return (distorted(rgb, scene.camera, "plumb_bob", LENS, source=wide),
            distorted(depth, scene.camera, "plumb_bob", LENS, nearest=True, source=wide))


def stamp(i: int) -> int:
    return T0_S * 1_000_000_000 + i * 33_000_000


def chunk_messages(radiosity: np.ndarray, epoch_ns: int, chunk_vertices: int = 400) -> list[PointCloud2]:
    msgs = []
    for first in range(0, len(radiosity), chunk_vertices):
        part = radiosity[first:first + chunk_vertices]
        arr = np.empty(len(part), dtype=CHUNK_DTYPE)
        arr["vertex"] = np.arange(first, first + len(part))
        arr["r"], arr["g"], arr["b"] = part.T
        msgs.append(numpy_to_pointcloud2(arr, stamp_ns=epoch_ns, frame_id="map"))
    return msgs


class Probe(StatusProbe):
    """A test node: publishers for the node's inputs, recorders of its outputs (keyed by stamp)."""

    timeout_s = TIMEOUT_S

    def __init__(self, make_node: Callable[..., Node], executor: Executor, outputs: dict[str, tuple[type, str]],
                 inputs: dict[str, tuple[type, str]]) -> None:
        self.executor = executor
        self.node = make_node("probe")
        self.pubs = {k: self.node.create_publisher(t, topic, CHUNK_QOS if topic == SUN_CHUNK_TOPIC else OUTPUT_QOS)
                     for k, (t, topic) in inputs.items()}
        self.got: dict[str, dict[int, object]] = defaultdict(dict)
        self.status: list[DiagnosticArray] = []
        self.subs = []
        for key, (t, topic) in outputs.items():
            cb = self.status.append if t is DiagnosticArray else self._recorder(key)
            self.subs.append(self.node.create_subscription(t, topic, cb, OUTPUT_QOS))

    def _recorder(self, key: str) -> Callable[[object], None]:
        def record(msg: object) -> None:
            self.got[key][stamp_to_ns(msg.header.stamp)] = msg  # type: ignore[attr-defined]
        return record

    def wait_matched(self) -> None:
        assert spin_until(self.executor, lambda: all(p.get_subscription_count() > 0 for p in self.pubs.values())
                          and all(s.get_publisher_count() > 0 for s in self.subs), TIMEOUT_S)

    def publish(self, key: str, msg: object) -> None:
        self.pubs[key].publish(msg)


@pytest.fixture(scope="module")
def scene(tiny_lighting_map: Path, tmp_path_factory: pytest.TempPathFactory) -> Scene:
    return make_scene(tiny_lighting_map, tmp_path_factory.mktemp("relight_scene"))


RELIGHT_INPUTS = {"image": (Image, COLOR_TOPIC), "info": (CameraInfo, COLOR_INFO_TOPIC),
                  "pose": (PoseStamped, COARSE_POSE_TOPIC), "chunk": (PointCloud2, SUN_CHUNK_TOPIC)}
RELIGHT_OUTPUTS = {"color": (Image, REFERENCE_COLOR_TOPIC), "depth": (Image, REFERENCE_DEPTH_TOPIC),
                   "sun_scale": (Vector3Stamped, SCALE_SUN_TOPIC), "status": (DiagnosticArray, RELIGHT_STATUS_TOPIC)}


@pytest.fixture
def relight(scene: Scene, executor: Executor, make_node: Callable[..., Node]):
    """``relight(**params) -> (node, probe)``: the node on the test executor and a matched probe."""
    nodes = []

    def start(**params: object) -> tuple[DaylightRelightNode, Probe]:
        params = {"lighting_map": str(scene.lighting_map), "crf_file": str(scene.crf_file),
                  "sensor_reliability": "reliable", **params}  # lossless: the tests count every frame
        overrides = [Parameter(k, value=v) for k, v in params.items()]
        node = DaylightRelightNode(context=executor.context, parameter_overrides=overrides)
        executor.add_node(node)
        nodes.append(node)
        probe = Probe(make_node, executor, RELIGHT_OUTPUTS, RELIGHT_INPUTS)
        probe.wait_matched()
        return node, probe

    yield start
    for node in nodes:
        executor.remove_node(node)
        node.destroy_node()


def image_msg(scene: Scene, i: int, rgb: np.ndarray | None = None) -> Image:
    return numpy_to_image(scene.frames[i][0] if rgb is None else rgb, "rgb8", stamp_ns=stamp(i),
                          frame_id=OPTICAL_FRAME)


def pose_msg(scene: Scene, i: int) -> PoseStamped:
    return matrix_to_pose_stamped(scene.poses[i], stamp_ns=stamp(i), frame_id="map")


def send_epoch(probe: Probe, radiosity: np.ndarray, epoch_ns: int, parts: slice = slice(None)) -> int:
    msgs = chunk_messages(radiosity, epoch_ns)[parts]
    for m in msgs:
        probe.publish("chunk", m)
    return len(msgs)


def test_reference_for_image_and_pose_in_either_order(relight, scene: Scene) -> None:
    node, probe = relight(window=1, reference_scale=1.0)  # full resolution: comparable with the live frames
    probe.publish("info", camera_info_from_camera(scene.camera, stamp_ns=stamp(0), frame_id=OPTICAL_FRAME))
    send_epoch(probe, scene.sun, stamp(0))
    probe.wait_status(lambda lvl, msg, v: v.get("sun_epoch_ns") == str(stamp(0)))

    # image first, then its pose
    probe.publish("image", image_msg(scene, 1))
    assert probe.spin_until(lambda: node.stats["frames_in"] == 1)
    assert not probe.got["color"]
    probe.publish("pose", pose_msg(scene, 1))
    assert probe.spin_until(lambda: stamp(1) in probe.got["color"] and stamp(1) in probe.got["depth"]
                            and stamp(1) in probe.got["sun_scale"])
    # pose first, then its image
    probe.publish("pose", pose_msg(scene, 2))
    assert probe.spin_until(lambda: node.stats["poses_in"] == 2)
    assert stamp(2) not in probe.got["color"]
    probe.publish("image", image_msg(scene, 2))
    assert probe.spin_until(lambda: stamp(2) in probe.got["color"] and stamp(2) in probe.got["depth"]
                            and stamp(2) in probe.got["sun_scale"])

    for i in (1, 2):
        color_msg, depth_msg = probe.got["color"][stamp(i)], probe.got["depth"][stamp(i)]
        assert (color_msg.encoding, depth_msg.encoding) == ("rgb8", "32FC1")
        assert color_msg.header.frame_id == depth_msg.header.frame_id == OPTICAL_FRAME
        color, depth = image_to_numpy(color_msg), image_to_numpy(depth_msg)
        live_rgb, live_depth = scene.frames[i]
        # rendered at the true pose with the scales estimated from the live image: the live image again
        assert np.mean(np.abs(color.astype(int) - live_rgb)) < 2.0
        hit = live_depth > 0
        np.testing.assert_allclose(depth[hit], live_depth[hit], atol=1e-4)
        s = probe.got["sun_scale"][stamp(i)].vector
        np.testing.assert_allclose([s.x, s.y, s.z], S_TRUE[0], rtol=0.05)
    level, _, values = probe.wait_status(lambda lvl, msg, v: v.get("stamp_ns") == str(stamp(2))
                                         and msg == "reference published")
    assert level == Level.OK and int(values["pixels_used"]) > 20
    assert float(values["render_ms"]) > 0 and float(values["estimate_ms"]) > 0


def test_the_image_of_a_lens_distorted_camera_is_undistorted_before_its_brightness_is_fitted(relight,
                                                                                            scene: Scene) -> None:
    node, probe = relight(window=1, reference_scale=1.0)
    probe.publish("info", lens_info(scene, LENS))
    assert probe.spin_until(lambda: node._read_camera_info.undistorter is not None)  # the lens first
    send_epoch(probe, scene.sun, stamp(0))
    probe.wait_status(lambda lvl, msg, v: v.get("sun_epoch_ns") == str(stamp(0)))
    probe.publish("image", image_msg(scene, 1, lens_frame(scene, 1)[0]))
    probe.publish("pose", pose_msg(scene, 1))
    assert probe.spin_until(lambda: stamp(1) in probe.got["color"] and stamp(1) in probe.got["sun_scale"])
    color = image_to_numpy(probe.got["color"][stamp(1)])
    assert np.mean(np.abs(color.astype(int) - scene.frames[1][0])) < 2.0  # the pinhole image at the true pose
    s = probe.got["sun_scale"][stamp(1)].vector
    np.testing.assert_allclose([s.x, s.y, s.z], S_TRUE[0], rtol=0.05)


def test_sun_epoch_swapped_in_only_when_complete(relight, scene: Scene) -> None:
    node, probe = relight(window=1)
    probe.publish("info", camera_info_from_camera(scene.camera, stamp_ns=stamp(0), frame_id=OPTICAL_FRAME))

    def frame(i: int) -> None:  # the same live image and pose under new stamps
        probe.publish("image", numpy_to_image(scene.frames[0][0], "rgb8", stamp_ns=stamp(i), frame_id=OPTICAL_FRAME))
        probe.publish("pose", matrix_to_pose_stamped(scene.poses[0], stamp_ns=stamp(i), frame_id="map"))

    def waiting(i: int) -> dict[str, str]:
        level, message, values = probe.wait_status(lambda lvl, msg, v: v.get("stamp_ns") == str(stamp(i)))
        assert level == Level.WARN and "waiting" in message
        return values

    def reference(i: int) -> np.ndarray:
        assert probe.spin_until(lambda: stamp(i) in probe.got["color"] and stamp(i) in probe.got["sun_scale"])
        return image_to_numpy(probe.got["color"][stamp(i)])

    epoch1, epoch2 = stamp(100), stamp(200)
    frame(1)  # no chunks at all
    waiting(1)
    n = send_epoch(probe, scene.sun, epoch1, slice(0, 2))  # a partial first epoch
    assert probe.spin_until(lambda: node.stats["chunks"] == n)
    frame(2)
    values = waiting(2)
    assert values["pending_epoch_ns"] == str(epoch1) and 0 < float(values["chunk_progress"]) < 1
    send_epoch(probe, scene.sun, epoch1, slice(2, None))
    probe.wait_status(lambda lvl, msg, v: v.get("sun_epoch_ns") == str(epoch1))
    frame(3)
    ref1 = reference(3)
    assert not probe.got["color"].keys() & {stamp(1), stamp(2)}  # nothing before the first complete epoch

    # a newer epoch with the sunlight elsewhere: while partial, the output is unchanged
    sun2 = (0.5 * scene.sun + 0.2 * np.roll(scene.sun, 200, axis=0)).astype(np.float32)
    m = send_epoch(probe, sun2, epoch2, slice(0, 2))
    total = len(chunk_messages(scene.sun, epoch1))
    assert probe.spin_until(lambda: node.stats["chunks"] == total + m)
    frame(4)
    ref_partial = reference(4)
    assert np.max(np.abs(ref_partial.astype(int) - ref1)) <= 1
    _, _, values = probe.wait_status(lambda lvl, msg, v: v.get("stamp_ns") == str(stamp(4)))
    assert values["sun_epoch_ns"] == str(epoch1) and values["pending_epoch_ns"] == str(epoch2)
    # once complete it is swapped in
    send_epoch(probe, sun2, epoch2, slice(2, None))
    probe.wait_status(lambda lvl, msg, v: v.get("sun_epoch_ns") == str(epoch2))
    frame(5)
    ref2 = reference(5)
    assert np.mean(np.abs(ref2.astype(int) - ref1)) > 2.0
    s1, s2 = probe.got["sun_scale"][stamp(3)].vector, probe.got["sun_scale"][stamp(5)].vector
    assert abs(s2.x - s1.x) > 0.1 * s1.x


def test_bad_inputs_are_reported_and_the_node_keeps_running(relight, scene: Scene) -> None:
    node, probe = relight(window=1)
    send_epoch(probe, scene.sun, stamp(0))
    probe.wait_status(lambda lvl, msg, v: v.get("sun_epoch_ns") == str(stamp(0)))

    # an image before any camera_info
    probe.publish("image", image_msg(scene, 1))
    probe.publish("pose", pose_msg(scene, 1))
    level, message, _ = probe.wait_status(lambda lvl, msg, v: "camera_info" in msg)
    assert level == Level.WARN and "no camera_info" in message
    # wrong encoding, NaN pose, chunks of another (bigger) map
    grey = numpy_to_image(scene.frames[1][0][:, :, 1].copy(), "mono8", stamp_ns=stamp(2), frame_id=OPTICAL_FRAME)
    probe.publish("image", grey)  # the brightness fit needs colour
    probe.wait_status(lambda lvl, msg, v: "encoding 'mono8'" in msg)
    nan_pose = pose_msg(scene, 2)
    nan_pose.pose.position.x = float("nan")
    probe.publish("pose", nan_pose)
    probe.wait_status(lambda lvl, msg, v: "coarse pose" in msg and "not finite" in msg)
    big = np.ones((scene.lmap.num_vertices + 500, 3), dtype=np.float32)
    probe.publish("chunk", chunk_messages(big, stamp(50), chunk_vertices=len(big))[0])
    level, message, _ = probe.wait_status(lambda lvl, msg, v: "sun chunk" in msg)
    assert level == Level.ERROR and "another lighting map" in message
    # camera_info of another size than the images
    probe.publish("info", camera_info_from_camera(scene.camera.scaled(0.5), frame_id=OPTICAL_FRAME))
    assert probe.spin_until(lambda: node._camera is not None)
    probe.publish("image", image_msg(scene, 3))
    probe.publish("pose", pose_msg(scene, 3))
    probe.wait_status(lambda lvl, msg, v: "camera_info says 80x60" in msg)
    assert not probe.got["color"]

    # good data again: a reference, from the epoch that was complete all along
    probe.publish("info", camera_info_from_camera(scene.camera, frame_id=OPTICAL_FRAME))
    assert probe.spin_until(lambda: node._camera == scene.camera)
    probe.publish("pose", pose_msg(scene, 1))
    probe.publish("image", image_msg(scene, 1))
    assert probe.spin_until(lambda: stamp(1) in probe.got["color"])
    assert node.relighter.sun_epoch_ns == stamp(0)


# --- time that misbehaves ------------------------------------------------------------------------------------

def epoch_in_use(node) -> int | None:
    return node.relighter.sun_epoch_ns


def test_a_bogus_future_epoch_is_refused_and_logged_and_later_epochs_still_come_in(relight, scene: Scene) -> None:
    """Before: one epoch stamped far ahead was swapped in, and every real epoch after it was silently dropped as
    older -- the sunlight froze for good."""
    node, probe = relight(window=1)
    send_epoch(probe, scene.sun, stamp(0))
    assert probe.spin_until(lambda: epoch_in_use(node) == stamp(0))
    bogus = time.time_ns() + 365 * 86_400 * 10**9  # a year ahead of the node's wall clock
    send_epoch(probe, scene.sun * 2, bogus)
    assert probe.spin_until(lambda: node.stats["dropped_epochs"] == 1)
    send_epoch(probe, scene.sun * 3, stamp(10))
    assert probe.spin_until(lambda: epoch_in_use(node) == stamp(10))
    assert node.stats["dropped_epochs"] == 1  # one line for the bogus epoch (all its chunks)


def test_an_older_epoch_is_dropped_with_a_log_line_until_time_jumps_back(relight, scene: Scene) -> None:
    node, probe = relight(window=1, time_jump_back_s=0.01)
    probe.publish("info", camera_info_from_camera(scene.camera, frame_id="camera_color_optical_frame"))
    send_epoch(probe, scene.sun, stamp(5))
    assert probe.spin_until(lambda: epoch_in_use(node) == stamp(5))
    for i in (2, 3):  # frames: the newest stamp seen is stamp(3)
        probe.publish("image", image_msg(scene, i))
        probe.publish("pose", pose_msg(scene, i))
    assert probe.spin_until(lambda: node.stats["references"] == 2)
    send_epoch(probe, scene.sun, stamp(1))  # a sun node restarted after time went back: older than the one in use
    assert probe.spin_until(lambda: node.stats["dropped_epochs"] == 1)
    assert epoch_in_use(node) == stamp(5)
    probe.publish("image", image_msg(scene, 0))  # the frames go back too: a bag played again
    probe.publish("pose", pose_msg(scene, 0))
    assert probe.spin_until(lambda: node.stats["time_jumps"] == 1 and node.stats["references"] == 3)
    send_epoch(probe, scene.sun * 0.5, stamp(1))  # now taken: time went back
    assert probe.spin_until(lambda: epoch_in_use(node) == stamp(1))
