"""sun_update_node in-process: sim time from /clock, chunks cover every vertex once per epoch, epochs advance."""
from __future__ import annotations

import datetime as dt
from collections import defaultdict
from pathlib import Path

import numpy as np
from geometry_msgs.msg import Vector3Stamped
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2

from lightfast.daylight.sun import FREIBURG, sun_position
from lightfast.ros.convert import ns_to_stamp, pointcloud2_to_numpy, stamp_to_ns
from lightfast.ros.qos import LATCHED_QOS
from lightfast.ros.spin import spin_until
from sun_update_node.node import SunUpdateNode

NOON_NS = int(dt.datetime(2026, 6, 21, 11, 0, tzinfo=dt.UTC).timestamp() * 1e9)
NIGHT_NS = int(dt.datetime(2026, 6, 21, 23, 0, tzinfo=dt.UTC).timestamp() * 1e9)


def run_node(make_node, executor, tiny_lighting_map: Path, start_ns: int, seconds: float, **params):
    overrides = [Parameter("lighting_map", value=str(tiny_lighting_map)), Parameter("use_sim_time", value=True),
                 Parameter("chunk_vertices", value=400), Parameter("step_period_s", value=0.01),
                 Parameter("update_period_s", value=1.0)]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    node = SunUpdateNode(context=executor.context, parameter_overrides=overrides)
    executor.add_node(node)
    probe = make_node("probe")
    clock = probe.create_publisher(Clock, "/clock", 10)
    chunks: dict[int, list[np.ndarray]] = defaultdict(list)
    directions: list[Vector3Stamped] = []
    probe.create_subscription(
        PointCloud2, "/radiosity/sun_chunk",
        lambda m: chunks[stamp_to_ns(m.header.stamp)].append(pointcloud2_to_numpy(m)),
        QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    probe.create_subscription(Vector3Stamped, "/sun/direction", directions.append, LATCHED_QOS)
    sim = {"t": start_ns}

    def tick() -> None:  # like `bag play --clock 100 --rate 5`: sim time runs 50 ms per 10 ms of wall time
        sim["t"] += 50_000_000
        clock.publish(Clock(clock=ns_to_stamp(sim["t"])))

    probe.create_timer(0.01, tick)
    end = start_ns + int(seconds * 1e9)
    spin_until(executor, lambda: sim["t"] >= end, timeout_s=60)
    executor.remove_node(node)
    node.destroy_node()
    return node, chunks, directions, sim["t"]


def test_epochs_cover_every_vertex_once_and_follow_the_clock(make_node, executor, tiny_lighting_map) -> None:
    node, chunks, directions, end_ns = run_node(make_node, executor, tiny_lighting_map, NOON_NS, seconds=15.0)
    V = node.pipeline.lmap.num_vertices
    complete = {}
    for epoch, parts in chunks.items():
        ids = np.concatenate([p["vertex"] for p in parts])
        if len(ids) == V:
            assert np.array_equal(np.sort(ids), np.arange(V)), "each vertex exactly once"
            complete[epoch] = np.concatenate([np.stack([p["r"], p["g"], p["b"]], 1) for p in parts])[np.argsort(ids)]
    assert len(complete) >= 3, sorted(chunks)
    epochs = sorted(complete)
    assert all(NOON_NS < e <= end_ns + 5_000_000_000 for e in epochs)  # aimed ahead, at sim time
    assert np.all(np.diff(epochs) >= 1e9 * 0.99)  # a new update per update_period_s of sim time
    assert max(b.max() for b in complete.values()) > 0  # noon: sunlight enters the room
    # the direction message is the sun at its stamp
    d = directions[-1]
    expected = sun_position(FREIBURG, stamp_to_ns(d.header.stamp)).direction_map
    np.testing.assert_allclose([d.vector.x, d.vector.y, d.vector.z], expected, atol=1e-9)
    assert d.header.frame_id == "map"


def test_night_gives_zero_radiosity(make_node, executor, tiny_lighting_map) -> None:
    _, chunks, _, _ = run_node(make_node, executor, tiny_lighting_map, NIGHT_NS, seconds=3.0)
    assert chunks and all(not np.any(p["r"]) for parts in chunks.values() for p in parts)


def test_invalid_parameter_changes_are_refused(make_node, executor, tiny_lighting_map) -> None:
    node = SunUpdateNode(context=executor.context,
                         parameter_overrides=[Parameter("lighting_map", value=str(tiny_lighting_map))])
    executor.add_node(node)
    try:
        assert not node.set_parameters([Parameter("chunk_vertices", value=0)])[0].successful
        assert node.set_parameters([Parameter("chunk_vertices", value=123)])[0].successful
        assert node.pipeline.config.chunk_vertices == 123
    finally:
        executor.remove_node(node)
        node.destroy_node()


def test_the_sun_node_starts_a_new_update_when_sim_time_jumps_back(make_node, executor, tiny_lighting_map) -> None:
    """/clock an hour back (a restarted simulation) while an update runs: the running update, aimed at the old
    future, is dropped and the next epochs follow the new time."""
    node = SunUpdateNode(context=executor.context, parameter_overrides=[
        Parameter("lighting_map", value=str(tiny_lighting_map)), Parameter("use_sim_time", value=True),
        Parameter("chunk_vertices", value=50), Parameter("step_period_s", value=0.01)])
    executor.add_node(node)
    player = make_node("player")
    clock = player.create_publisher(Clock, "/clock", 10)
    sim = {"t": NOON_NS}

    def tick() -> None:  # sim time at wall speed: the node's timers run on it
        sim["t"] += 10_000_000
        clock.publish(Clock(clock=ns_to_stamp(sim["t"])))

    player.create_timer(0.01, tick)
    epochs: list[int] = []  # the epoch of each chunk, in arrival order
    make_node("listener").create_subscription(PointCloud2, "/radiosity/sun_chunk",
                                              lambda m: epochs.append(stamp_to_ns(m.header.stamp)), 1000)
    try:
        assert spin_until(executor, lambda: len(epochs) >= 2, 10.0)  # an update is streaming
        old = epochs[0]
        assert node.pipeline.current is not None and node.pipeline.current.epoch_ns == old
        chunks_per_update = -(-node.pipeline.lmap.num_vertices // 50)
        assert len(epochs) < chunks_per_update - 5
        sim["t"] = NOON_NS - 3600 * 10**9
        seen = len(epochs)
        assert spin_until(executor, lambda: any(e < NOON_NS for e in epochs), 10.0)
        # the old update, aimed at the old future, was dropped rather than finished first (a chunk or two in flight)
        assert epochs[seen:].count(old) <= 2, (epochs[seen:].count(old), chunks_per_update)
    finally:
        executor.remove_node(node)
        node.destroy_node()
