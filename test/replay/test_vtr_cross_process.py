"""Colour-constant VT&R across processes: ``scripts/vtr_demo.sh`` on bags written here from the rendered route of
``test/ros/test_vtr_localizer_node.py`` (teach node process, ``lightfast bag play``, the finish service, a repeat
node process under the changed illuminant, ``lightfast bag record``, the summary against ground truth); and a teach
node process stopped by SIGINT before it finished leaves the previous map as it was."""
from __future__ import annotations

import re
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import CameraInfo, Image

from lightfast.bag.writer import BagWriter, make_qos
from lightfast.ros.convert import matrix_to_pose_stamped, numpy_to_image
from lightfast.ros.diagnostics import diagnostic_values
from lightfast.ros.msgtypes import rosbags_types
from lightfast.ros.qos import OUTPUT_QOS
from lightfast.ros.spin import spin_until
from lightfast.topics import (
    GT_POSE_TOPIC,
    MAP_FRAME,
    STEREO_LEFT_FRAME,
    STEREO_LEFT_IMAGE_TOPIC,
    STEREO_LEFT_INFO_TOPIC,
    STEREO_RIGHT_FRAME,
    STEREO_RIGHT_IMAGE_TOPIC,
    STEREO_RIGHT_INFO_TOPIC,
    VTR_STATUS_TOPIC,
)
from lightfast.vtr import MapStore, TeachConfig, TeachPipeline
from test.helpers import bounded_process, child_env
from test.ros.test_vtr_localizer_node import TOL_DEG, TOL_M, partial_dirs, route, stereo_camera_infos
from test.unit.vtr import test_teach_repeat as corridor

ROOT = Path(__file__).resolve().parents[2]


def write_route_bag(path: Path, pairs: Sequence[tuple[np.ndarray, np.ndarray]], poses: Sequence[np.ndarray],
                    stamps: Sequence[int]) -> Path:
    """A bag like those of ``lightfast sim vtr``: stereo images, camera_info and the true left-camera pose."""
    types = rosbags_types()
    qos = [make_qos(reliable=True, depth=10)]
    with BagWriter(path) as bag:
        for topic, msgtype in ((STEREO_LEFT_IMAGE_TOPIC, "sensor_msgs/msg/Image"),
                               (STEREO_RIGHT_IMAGE_TOPIC, "sensor_msgs/msg/Image"),
                               (STEREO_LEFT_INFO_TOPIC, "sensor_msgs/msg/CameraInfo"),
                               (STEREO_RIGHT_INFO_TOPIC, "sensor_msgs/msg/CameraInfo"),
                               (GT_POSE_TOPIC, "geometry_msgs/msg/PoseStamped")):
            bag.add_topic(topic, msgtype, offered_qos=qos)
        for (left, right), T, t in zip(pairs, poses, stamps, strict=True):
            left_info, right_info = stereo_camera_infos(t, types=types)
            bag.write_message(STEREO_LEFT_IMAGE_TOPIC, t, numpy_to_image(left, "rgb8", stamp_ns=t,
                                                                         frame_id=STEREO_LEFT_FRAME, types=types))
            bag.write_message(STEREO_RIGHT_IMAGE_TOPIC, t, numpy_to_image(right, "rgb8", stamp_ns=t,
                                                                          frame_id=STEREO_RIGHT_FRAME, types=types))
            bag.write_message(STEREO_LEFT_INFO_TOPIC, t, left_info)
            bag.write_message(STEREO_RIGHT_INFO_TOPIC, t, right_info)
            bag.write_message(GT_POSE_TOPIC, t, matrix_to_pose_stamped(T, stamp_ns=t, frame_id=MAP_FRAME, types=types))
    return path


def _leftovers(marker: str) -> list[str]:
    out = subprocess.run(["pgrep", "-af", marker], capture_output=True, text=True).stdout
    return [line for line in out.splitlines() if "pgrep" not in line]


@pytest.mark.timeout(400)
def test_vtr_demo_teaches_and_repeats_across_processes(tmp_path: Path, domain_id: int) -> None:
    r = route()
    teach_bag = write_route_bag(tmp_path / "teach_bag", r.teach, r.teach_poses, r.teach_stamps)
    repeat_bag = write_route_bag(tmp_path / "repeat_bag", r.repeat, r.repeat_poses, r.repeat_stamps)
    out = tmp_path / "out"
    env = child_env(domain_id, LIGHTFAST_OUT=str(out))
    with bounded_process(["bash", str(ROOT / "scripts/vtr_demo.sh"), str(teach_bag), str(repeat_bag)],
                         timeout_s=330, env=env) as proc:
        stdout, stderr = proc.communicate(timeout=350)
    log = stdout[-3000:] + stderr[-3000:]
    assert proc.returncode == 0, log
    m = re.search(r"teach finished: map written to .*: (\d+) keyframes, ([\d.]+) m path, (\d+) stereo pairs", stdout)
    assert m, log
    keyframes, length_m, pairs = int(m.group(1)), float(m.group(2)), int(m.group(3))
    assert pairs == len(r.teach) and keyframes >= 6 and abs(length_m - (r.teach_poses[-1][2, 3])) < 0.1, log
    taught = MapStore.load(out / "vtr-map")
    assert len(taught) == keyframes and not partial_dirs(out / "vtr-map")
    m = re.search(r"repeat: (\d+) stereo pairs, localized (\d+)", stdout)
    assert m, log
    assert int(m.group(1)) >= len(r.repeat) - 1 and int(m.group(2)) >= int(m.group(1)) - 1, log
    m = re.search(r"error against ground truth \((\d+) localized pairs\): median ([\d.]+) cm, max ([\d.]+) cm, "
                  r"rotation max ([\d.]+) deg", stdout)
    assert m, log
    scored, max_cm, max_deg = int(m.group(1)), float(m.group(3)), float(m.group(4))
    assert scored >= len(r.repeat) - 2 and max_cm < 100 * TOL_M and max_deg < TOL_DEG, log
    assert (out / "vtr-repeat-output" / "metadata.yaml").is_file()
    assert not _leftovers(str(tmp_path))


@pytest.mark.timeout(300)
def test_sigint_during_a_teach_leaves_the_previous_map(tmp_path: Path, domain_id: int, make_node, executor) -> None:
    r = route()
    previous = TeachPipeline(tmp_path / "map", TeachConfig())
    for stamp, (left, right) in zip(r.teach_stamps[:3], r.teach[:3], strict=True):
        previous.step(stamp, left, right, corridor.P_LEFT, corridor.P_RIGHT)
    before = previous.finish()
    map_path = tmp_path / "map"

    probe = make_node("teacher")
    topics = {"left": (Image, STEREO_LEFT_IMAGE_TOPIC), "right": (Image, STEREO_RIGHT_IMAGE_TOPIC),
              "left_info": (CameraInfo, STEREO_LEFT_INFO_TOPIC), "right_info": (CameraInfo, STEREO_RIGHT_INFO_TOPIC)}
    pubs = {k: probe.create_publisher(t, topic, OUTPUT_QOS) for k, (t, topic) in topics.items()}
    status: dict[str, str] = {}
    probe.create_subscription(DiagnosticArray, VTR_STATUS_TOPIC,
                              lambda msg: status.update(diagnostic_values(msg.status[0])), OUTPUT_QOS)
    cmd = [sys.executable, "-m", "vtr_localizer_node.node", "--ros-args", "-p", "mode:=teach", "-p",
           f"map_path:={map_path}", "-p", "overwrite_map:=true", "-p", "max_queued_frames:=100",
           "-p", "sensor_reliability:=reliable"]
    with bounded_process(cmd, timeout_s=240, env=child_env(domain_id)) as proc:
        assert spin_until(executor, lambda: all(p.get_subscription_count() == 1 for p in pubs.values()), 120)
        left_info, right_info = stereo_camera_infos()
        pubs["left_info"].publish(left_info)
        pubs["right_info"].publish(right_info)
        for stamp, (left, right) in zip(r.teach_stamps[:5], r.teach[:5], strict=True):
            pubs["left"].publish(numpy_to_image(left, "rgb8", stamp_ns=stamp, frame_id=STEREO_LEFT_FRAME))
            pubs["right"].publish(numpy_to_image(right, "rgb8", stamp_ns=stamp, frame_id=STEREO_RIGHT_FRAME))
        assert spin_until(executor, lambda: status.get("frames_done") == "5", 120), status
        assert int(status["keyframes"]) >= 3 and status["teach_finished"] == "false"
        assert partial_dirs(map_path)  # keyframes are on disk, beside the map
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err[-2000:]
    after = MapStore.load(map_path)
    assert [k.stamp_ns for k in after.keyframes] == [k.stamp_ns for k in before.keyframes]
    assert not partial_dirs(map_path)
