"""Readiness announcements for launch-free scripts (lightfast.ros.ready): latched, received by late waiters, a
timeout and a dead watched process fail the wait; the daylight nodes announce themselves."""
from __future__ import annotations

import re
import subprocess
import sys
import time

import pytest
from rclpy.parameter import Parameter

from lightfast.ros.errors import NotReadyError
from lightfast.ros.ready import announce_ready, process_alive, wait_ready
from sun_update_node.node import SunUpdateNode


def test_late_waiter_receives_every_announcement(make_node, executor) -> None:
    announce_ready(make_node("node_a"))
    announce_ready(make_node("node_b"))
    waiter = make_node("waiter")  # subscribes after both announcements: the topic is latched
    assert {"node_a", "node_b"} <= wait_ready(waiter, executor, ["node_a", "node_b"], timeout_s=10.0)


def test_missing_node_times_out_and_names_it(make_node, executor) -> None:
    announce_ready(make_node("node_a"))
    waiter = make_node("waiter")
    t0 = time.monotonic()
    with pytest.raises(NotReadyError, match=re.escape("not ready after 0.5 s: node_b (ready: node_a")):
        wait_ready(waiter, executor, ["node_a", "node_b"], timeout_s=0.5)
    assert time.monotonic() - t0 < 5.0


def test_dead_watched_process_fails_at_once(make_node, executor) -> None:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    assert not process_alive(proc.pid)
    waiter = make_node("waiter")
    t0 = time.monotonic()
    with pytest.raises(NotReadyError, match="watched process ended"):
        wait_ready(waiter, executor, ["never"], timeout_s=30.0, alive=lambda: process_alive(proc.pid))
    assert time.monotonic() - t0 < 5.0


def test_sun_update_node_announces_itself_once_loaded(make_node, executor, tiny_lighting_map) -> None:
    node = SunUpdateNode(context=executor.context,
                         parameter_overrides=[Parameter("lighting_map", value=str(tiny_lighting_map))])
    executor.add_node(node)
    try:
        assert "sun_update_node" in wait_ready(make_node("waiter"), executor, ["sun_update_node"], timeout_s=10.0)
    finally:
        executor.remove_node(node)
        node.destroy_node()
