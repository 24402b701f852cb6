"""Readiness of lightfast's nodes, for launch-free scripts: a node announces itself on ``/lightfast/ready`` once it
can take data (its map loaded, its kernels compiled or loaded from numba's cache), and ``lightfast wait-ready``
waits for the names it is given.

The topic is latched (transient local, reliable, depth 1): each node's publisher keeps its one announcement, so a
waiter that starts later still receives the announcements of every node already up. A script starts its nodes,
then ``lightfast wait-ready sun_update_node daylight_relight_node --pid 123 --pid 124`` before it plays data; the
``--pid`` processes are watched so that a node that dies during its start-up fails the wait at once.
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable

from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from lightfast.ros.errors import NotReadyError
from lightfast.ros.qos import LATCHED_QOS
from lightfast.ros.spin import spin_until
from lightfast.topics import READY_TOPIC

__all__ = ["READY_TOPIC", "announce_ready", "process_alive", "wait_ready"]


def announce_ready(node: Node) -> Publisher:
    """Publish the node's name on :data:`READY_TOPIC` (latched); keep the returned publisher alive as long as the
    node, or late waiters miss the announcement."""
    pub = node.create_publisher(String, READY_TOPIC, LATCHED_QOS)
    pub.publish(String(data=node.get_name()))
    return pub


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` still exists (signal 0; a process of another user counts as alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def wait_ready(node: Node, executor: Executor, names: Iterable[str], *, timeout_s: float,
               alive: Callable[[], bool] | None = None) -> set[str]:
    """Spin until every node in ``names`` has announced itself; returns the names seen (also others). Raises
    :class:`NotReadyError` after ``timeout_s`` or as soon as ``alive()`` turns false."""
    wanted = set(names)
    seen: set[str] = set()
    # a deep reader history: the announcements of all nodes arrive at once, and a depth of 1 kept only the last
    qos = QoSProfile(depth=256, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)

    def on_ready(msg: String) -> None:
        seen.add(msg.data)

    sub = node.create_subscription(String, READY_TOPIC, on_ready, qos)
    deadline = time.monotonic() + timeout_s
    try:
        while not wanted <= seen:
            if alive is not None and not alive():
                raise NotReadyError(f"a watched process ended before {sorted(wanted - seen)} announced readiness")
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                raise NotReadyError(f"not ready after {timeout_s:g} s: {', '.join(sorted(wanted - seen))} "
                                    f"(ready: {', '.join(sorted(seen)) or 'none'})")
            spin_until(executor, lambda: wanted <= seen, min(0.2, remaining))
    finally:
        node.destroy_subscription(sub)
    return seen
