"""sun_update_node as its own process, driven by /clock from `lightfast bag play --clock`."""
from __future__ import annotations

import datetime as dt
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2

from lightfast.bag import BagWriter
from lightfast.daylight.lighting_map import LightingMap
from lightfast.daylight.sun_update import SunUpdate
from lightfast.ros.convert import ns_to_stamp, pointcloud2_to_numpy, stamp_to_ns
from lightfast.ros.spin import spin_until
from test.helpers import LIGHTFAST, bounded_process, child_env, run_bounded

START_NS = int(dt.datetime(2026, 6, 21, 11, 0, tzinfo=dt.UTC).timestamp() * 1e9)


def tick_bag(path: Path, seconds: float = 4.0, hz: float = 20.0) -> Path:
    with BagWriter(path) as bag:
        bag.add_topic("/tick", "std_msgs/msg/Header")
        Header, BagTime = bag.typestore.types["std_msgs/msg/Header"], bag.typestore.types["builtin_interfaces/msg/Time"]
        for i in range(int(seconds * hz)):
            t = START_NS + int(i * 1e9 / hz)
            bag.write_message("/tick", t, Header(stamp=BagTime(sec=t // 10**9, nanosec=t % 10**9), frame_id="x"))
    return path


def test_node_follows_bag_clock(tmp_path: Path, tiny_lighting_map: Path, domain_id: int, make_node,
                                executor) -> None:
    chunks: dict[int, list[np.ndarray]] = defaultdict(list)
    node = make_node("listener")
    node.create_subscription(PointCloud2, "/radiosity/sun_chunk",
                             lambda m: chunks[stamp_to_ns(m.header.stamp)].append(pointcloud2_to_numpy(m)),
                             QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    lmap = LightingMap.load(tiny_lighting_map)
    V = lmap.num_vertices
    # an epoch is the time its update will finish: up to this much after the clock when the update starts
    lead_ns = SunUpdate.estimate_steps(V, 400, lmap.config.iterations, num_patches=lmap.patches.count) * 10**7
    env = child_env(domain_id)
    cmd = [sys.executable, "-m", "sun_update_node.node", "--ros-args", "-p", f"lighting_map:={tiny_lighting_map}",
           "-p", "use_sim_time:=true", "-p", "chunk_vertices:=400", "-p", "step_period_s:=0.01",
           "-p", "update_period_s:=1.0"]
    with bounded_process(cmd, timeout_s=120, env=env) as proc:
        assert spin_until(executor, lambda: node.count_publishers("/radiosity/sun_chunk") == 1, timeout_s=60)
        assert not chunks  # no /clock yet: the node waits
        bag = tick_bag(tmp_path / "ticks", seconds=10.0)
        play = run_bounded([*LIGHTFAST, "bag", "play", str(bag), "--clock", "100"], timeout_s=60, env=env)
        assert play.returncode == 0, play.stderr
        # 10 s of bag time: under a loaded CI machine the first epoch took more than 4 s to compute (one chunk came)
        spin_until(executor, lambda: False, timeout_s=0.5)  # let the last chunks arrive
        proc.terminate()
        proc.communicate(timeout=30)
    complete = [e for e, parts in chunks.items() if sum(len(p) for p in parts) == V]
    assert complete, {e: sum(len(p) for p in parts) for e, parts in chunks.items()}
    # stamped in bag time (the bag's 10 s, plus an update's lead), not in wall time (months later)
    assert all(START_NS <= e <= START_NS + 10 * 10**9 + lead_ns for e in chunks), \
        sorted((e - START_NS) * 1e-9 for e in chunks)


def test_a_negative_clock_does_not_end_the_node(tiny_lighting_map: Path, domain_id: int, make_node,
                                                executor) -> None:
    """rclpy's time source raises on a /clock message with a negative time, through the executor: the node ended
    with a traceback. run_node logs it (throttled) and the node carries on with the next good /clock."""
    chunks: list[int] = []
    node = make_node("clock_fuzzer")
    node.create_subscription(PointCloud2, "/radiosity/sun_chunk", lambda m: chunks.append(stamp_to_ns(m.header.stamp)),
                             QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    clock = node.create_publisher(Clock, "/clock", 10)
    cmd = [sys.executable, "-m", "sun_update_node.node", "--ros-args", "-p", f"lighting_map:={tiny_lighting_map}",
           "-p", "use_sim_time:=true", "-p", "chunk_vertices:=400", "-p", "step_period_s:=0.01"]
    with bounded_process(cmd, timeout_s=120, env=child_env(domain_id)) as proc:
        assert proc.stderr is not None
        err_lines: list[str] = []
        reader = threading.Thread(target=lambda: err_lines.extend(iter(proc.stderr.readline, "")), daemon=True)
        reader.start()
        assert spin_until(executor, lambda: node.count_publishers("/radiosity/sun_chunk") == 1
                          and clock.get_subscription_count() == 1, timeout_s=60)
        # rclpy's time source keeps one /clock message: send the bad one until the node has taken it
        deadline = time.monotonic() + 30
        while not any("a callback failed, carrying on" in line for line in err_lines) and time.monotonic() < deadline:
            clock.publish(Clock(clock=Time(sec=-5, nanosec=0)))
            spin_until(executor, lambda: False, timeout_s=0.05)
        t = START_NS
        while not chunks and t < START_NS + 20 * 10**9:  # good /clock messages at 100 Hz
            t += 10**7
            clock.publish(Clock(clock=ns_to_stamp(t)))
            spin_until(executor, lambda: False, timeout_s=0.01)
        alive = proc.poll() is None
        proc.terminate()
        proc.wait(timeout=30)
        reader.join(timeout=10)
    err = "".join(err_lines)
    assert alive, err
    assert chunks and all(c >= START_NS for c in chunks)
    assert "a callback failed, carrying on" in err and "Traceback" not in err
    # at start-up the node said which DDS profile and discovery range it uses (this host only, here)
    assert "DDS: profile local (lightfast/ros/fastdds_local.xml" in err and "discovery LOCALHOST" in err
