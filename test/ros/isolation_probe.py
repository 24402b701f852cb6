"""Run by test_isolation.py as a separate pytest process (the file name keeps it out of normal collection).

It talks on a fixed topic with discovery on this host and asserts it hears only itself: a concurrent test run on
another reserved domain id must stay invisible. ``PROBE_TAG`` names this run.
"""
import os
import time

from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from lightfast.ros.spin import spin_until

TOPIC = "/lightfast_isolation_probe"


def test_hears_only_itself(make_node, executor) -> None:
    tag = os.environ["PROBE_TAG"]
    heard: set[str] = set()
    node = make_node(f"probe_{tag}")
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(String, TOPIC, lambda m: heard.add(m.data), qos)
    pub = node.create_publisher(String, TOPIC, qos)
    node.create_timer(0.05, lambda: pub.publish(String(data=tag)))
    end = time.monotonic() + float(os.environ.get("PROBE_SECONDS", "4"))
    spin_until(executor, lambda: time.monotonic() > end, timeout_s=60)
    print(f"PROBE {tag} heard {sorted(heard)}")
    assert heard == {tag}
