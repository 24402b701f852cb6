"""No DDS packet leaves the machine: sniff every interface while processes discover each other and exchange data.

RTPS packets start with the magic ``RTPS``. A raw AF_PACKET socket (root only) sees every packet an interface
sends; the loopback interface must carry RTPS (that proves the sniffer works) and no other interface may.
"""
from __future__ import annotations

import os
import socket
import threading
from pathlib import Path

import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from lightfast.bag import BagWriter
from lightfast.ros.spin import spin_until
from test.helpers import LIGHTFAST, bounded_process, child_env

ETH_P_ALL = 0x0003


class Sniffer:
    """Counts RTPS packets on one interface until stopped."""

    def __init__(self, interface: str) -> None:
        self.interface = interface
        self.rtps_packets = 0
        self.sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
        self.sock.bind((interface, 0))
        self.sock.settimeout(0.05)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                packet = self.sock.recv(65535)
            except TimeoutError:
                continue
            except OSError:
                return
            if b"RTPS" in packet:
                self.rtps_packets += 1

    def stop(self) -> int:
        self._stop.set()
        self._thread.join(timeout=5)
        self.sock.close()
        return self.rtps_packets


@pytest.mark.skipif(os.geteuid() != 0, reason="raw packet capture needs root")
def test_dds_traffic_stays_on_loopback(tmp_path: Path, domain_id: int, make_node, executor) -> None:
    interfaces = [name for _, name in socket.if_nameindex()]
    sniffers = {name: Sniffer(name) for name in interfaces}
    with BagWriter(tmp_path / "bag") as bag:
        bag.add_topic("/chatter", "std_msgs/msg/String")
        for i in range(50):
            bag.write_message("/chatter", i * 1_000_000, bag.typestore.types["std_msgs/msg/String"](data=str(i)))
    got: list[str] = []
    make_node("listener").create_subscription(String, "/chatter", lambda m: got.append(m.data),
                                              QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    cmd = [*LIGHTFAST, "bag", "play", str(tmp_path / "bag"), "--wait-for-subscribers", "30"]
    with bounded_process(cmd, timeout_s=60, env=child_env(domain_id)) as proc:
        assert spin_until(executor, lambda: len(got) == 50, timeout_s=60)
        proc.communicate(timeout=30)
    counts = {name: s.stop() for name, s in sniffers.items()}
    assert counts.get("lo", 0) > 0, counts  # the sniffer sees discovery on loopback
    assert {name: n for name, n in counts.items() if name != "lo" and n} == {}, counts
