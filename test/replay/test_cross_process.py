"""Across processes: `lightfast bag play` and `lightfast bag record` as subprocesses on the local transport."""
from __future__ import annotations

import re
import signal
import subprocess
import threading
import time
from pathlib import Path

import cv2
import numpy as np
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import Image
from std_msgs.msg import String

from lightfast.bag import compare_bags, open_bag
from lightfast.data.sevenscenes import COLOR_TOPIC, DEPTH_TOPIC
from lightfast.ros.convert import image_to_numpy
from lightfast.ros.spin import spin_until
from test.helpers import LIGHTFAST, bounded_process, child_env

RELIABLE_ALL = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)


def test_play_subprocess_delivers_every_message(sevenscenes_bag: Path, sevenscenes_dir: Path, domain_id: int,
                                                make_node, executor) -> None:
    node = make_node("listener")
    received: dict[str, list] = {COLOR_TOPIC: [], DEPTH_TOPIC: []}
    for topic in received:
        node.create_subscription(Image, topic, received[topic].append, RELIABLE_ALL)
    cmd = [*LIGHTFAST, "bag", "play", str(sevenscenes_bag), "--rate", "0", "--wait-for-subscribers", "30",
           "--topics", COLOR_TOPIC, DEPTH_TOPIC]
    with bounded_process(cmd, timeout_s=120, env=child_env(domain_id)) as proc:
        assert spin_until(executor, lambda: all(len(v) == 300 for v in received.values()), timeout_s=120)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert re.search(r"played 600 messages on 2 topics", out)
    first = cv2.cvtColor(cv2.imread(str(sevenscenes_dir / "frame-000000.color.jpg")), cv2.COLOR_BGR2RGB)
    np.testing.assert_array_equal(image_to_numpy(received[COLOR_TOPIC][0]), first)
    depth = cv2.imread(str(sevenscenes_dir / "frame-000299.depth.png"), cv2.IMREAD_UNCHANGED)
    depth[depth == 65535] = 0
    np.testing.assert_array_equal(image_to_numpy(received[DEPTH_TOPIC][-1]), depth)


def record_while_playing(src: Path, out: Path, domain_id: int) -> str:
    """Record every topic of ``src`` into ``out`` while ``lightfast bag play`` replays it as fast as possible."""
    with open_bag(src) as bag:
        topics = [t.name for t in bag.info.topics]
    env = child_env(domain_id)
    with bounded_process([*LIGHTFAST, "bag", "record", "-o", str(out), *topics], timeout_s=180, env=env) as rec:
        play = subprocess.run(["timeout", "-k", "5", "120", *LIGHTFAST, "bag", "play", str(src), "--rate", "0",
                               "--wait-for-subscribers", "60"], env=env, capture_output=True, text=True)
        assert play.returncode == 0, play.stderr
        rec.send_signal(signal.SIGINT)
        rec_out, rec_err = rec.communicate(timeout=60)
    assert rec.returncode == 0, rec_err
    return rec_out


def test_record_play_record_round_trip_is_byte_identical(sevenscenes_bag: Path, tmp_path: Path,
                                                         domain_id: int) -> None:
    first, second = tmp_path / "first", tmp_path / "second"
    summary = record_while_playing(sevenscenes_bag, first, domain_id)
    assert "recorded 1500 messages on 5 topics" in summary
    record_while_playing(first, second, domain_id)
    for a, b in ((sevenscenes_bag, first), (first, second)):
        result = compare_bags(a, b)
        assert result.identical, result.summary()
        assert [t.count_b for t in result.topics] == [300] * 5


def test_sigint_mid_stream_leaves_a_complete_bag(tmp_path: Path, domain_id: int, make_node, executor) -> None:
    """Messages stream continuously; SIGINT/SIGTERM reach the recorder mid-stream; the bag opens in rosbags and
    holds exactly the messages the recorder reports it received, as an unbroken sequence."""
    node = make_node("talker")
    pub = node.create_publisher(String, "/stream", RELIABLE_ALL)
    for sig in (signal.SIGINT, signal.SIGTERM):
        out = tmp_path / f"rec_{sig.name}"
        sent = {"n": 0}
        stop = threading.Event()

        with bounded_process([*LIGHTFAST, "bag", "record", "-o", str(out), "/stream"], timeout_s=120,
                             env=child_env(domain_id)) as rec:
            assert spin_until(executor, lambda: pub.get_subscription_count() == 1, timeout_s=60)
            talker = threading.Thread(target=_talk, args=(pub, sent, stop), daemon=True)
            talker.start()
            assert spin_until(executor, lambda: sent["n"] >= 500, timeout_s=60)  # noqa: B023 - used within this iteration
            rec.send_signal(sig)
            rec_out, rec_err = rec.communicate(timeout=60)
            stop.set()
            talker.join(timeout=10)
        assert rec.returncode == 0, rec_err
        reported = int(re.search(r"recorded (\d+) messages", rec_out).group(1))
        with Reader(out) as reader:  # rosbags opens it
            values = [int(reader_msg) for reader_msg in _strings(reader)]
        assert len(values) == reported > 0
        assert values == list(range(values[0], values[0] + len(values)))  # nothing lost in between
        assert reported < sent["n"]  # the signal really came mid-stream


def _talk(pub, sent: dict[str, int], stop: threading.Event) -> None:
    """Publish consecutive numbers at about 1 kHz until ``stop``."""
    while not stop.is_set():
        pub.publish(String(data=str(sent["n"])))
        sent["n"] += 1
        time.sleep(0.001)


def _strings(reader: Reader) -> list[str]:
    from lightfast.bag import default_typestore

    store = default_typestore()
    return [store.deserialize_cdr(raw, conn.msgtype).data for conn, _, raw in reader.messages()]
