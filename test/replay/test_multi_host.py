"""Two machines on one: the tracking pipeline split over two network namespaces on the network DDS profile.

Host A (192.0.2.1, "the camera computer") runs `lightfast bag play` (the camera driver, with /clock) and
sun_update_node; host B (192.0.2.2, "the tracking computer") runs daylight_relight_node, rgbd_tracker_node and
`lightfast bag record`. Each side takes its environment from `eval "$(lightfast dds env --network --hosts
192.0.2.1 192.0.2.2 --interface <own address> --udp-only)"` run inside its namespace, as a user would on each
machine. UDP-only because namespaces share /dev/shm: the images must cross the veth pair, which its byte counters
prove. Only the veth pair joins the namespaces and neither has a route beyond 192.0.2.0/24, so no packet can leave.
A second, quicker test checks the packaged profile as shipped (shared memory + UDP, multicast discovery, SUBNET).
"""
from __future__ import annotations

import itertools
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from lightfast.bag import BagWriter, open_bag
from lightfast.eval.recording import score_recording
from lightfast.ros.transport import NETWORK_PROFILE_PATH, NETWORK_UNSET, apply_env, network_transport_env
from lightfast.topics import COLOR_INFO_TOPIC, COLOR_TOPIC, DEPTH_TOPIC, SUN_CHUNK_TOPIC
from test.helpers import LIGHTFAST, bounded_process, child_env, run_bounded
from test.replay.test_demo import TINY

pytestmark = [pytest.mark.skipif(os.geteuid() != 0, reason="network namespaces need root"),
              pytest.mark.skipif(shutil.which("ip") is None, reason="no `ip` command (iproute2)")]

SEQUENCE = "DS1.T6"
PLAYED = [COLOR_TOPIC, COLOR_INFO_TOPIC, DEPTH_TOPIC]
RECORDED = ["/tracker/pose", "/tracker/status", "/relight/status", SUN_CHUNK_TOPIC]
_serial = itertools.count()


@dataclass(frozen=True)
class Host:
    netns: str
    veth: str
    address: str

    def cmd(self, *argv: str) -> list[str]:
        return ["ip", "netns", "exec", self.netns, *argv]

    def counter(self, name: str) -> int:
        """A byte counter of the host's veth, read inside its namespace (/sys shows that namespace there)."""
        out = subprocess.run(self.cmd("cat", f"/sys/class/net/{self.veth}/statistics/{name}"), capture_output=True,
                             text=True, check=True, timeout=10).stdout
        return int(out)


def _ip(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["ip", *argv], capture_output=True, text=True, timeout=20)


@pytest.fixture
def two_hosts() -> Iterator[tuple[Host, Host]]:
    """Two namespaces (names unique per test run) joined by a veth pair, 192.0.2.1/24 and 192.0.2.2/24, loopback
    up, nothing else; deleted again whatever happens (deleting a namespace deletes its end of the pair)."""
    tag = f"{os.getpid()}x{next(_serial)}"
    a, b = Host(f"lightfast-a-{tag}", f"lfa{tag}"[:15], "192.0.2.1"), Host(f"lightfast-b-{tag}", f"lfb{tag}"[:15],
                                                                           "192.0.2.2")
    made: list[str] = []
    try:
        for host in (a, b):
            result = _ip("netns", "add", host.netns)
            if result.returncode != 0:
                pytest.skip(f"cannot create network namespaces (`ip netns add`: {result.stderr.strip()})")
            made.append(host.netns)
            # IPv4 only (the UDPv4 transport): no IPv6 link-local addresses or routes appear on the veth
            script = "for c in all default; do f=/proc/sys/net/ipv6/conf/$c/disable_ipv6; [ ! -e $f ] || echo 1 >$f; " \
                "done"
            result = subprocess.run(host.cmd("sh", "-c", script), capture_output=True, text=True, timeout=20)
            assert result.returncode == 0, result.stderr
        steps = [("link", "add", a.veth, "type", "veth", "peer", "name", b.veth)]
        for host in (a, b):
            steps += [("link", "set", host.veth, "netns", host.netns),
                      ("-n", host.netns, "addr", "add", f"{host.address}/24", "dev", host.veth),
                      ("-n", host.netns, "link", "set", host.veth, "up"),
                      ("-n", host.netns, "link", "set", "lo", "up")]
        for step in steps:
            result = _ip(*step)
            assert result.returncode == 0, f"ip {' '.join(step)}: {result.stderr}"
        for host in (a, b):  # the whole world of each host: loopback, its veth end, one on-link route
            links = _ip("-n", host.netns, "-o", "link", "show").stdout
            assert sorted(line.split(":")[1].strip().split("@")[0] for line in links.splitlines()) == \
                sorted(["lo", host.veth]), links
            routes = [line.strip() for line in _ip("-n", host.netns, "-4", "route", "show").stdout.splitlines()]
            assert routes == [f"192.0.2.0/24 dev {host.veth} proto kernel scope link src {host.address}"], routes
            assert "default" not in _ip("-n", host.netns, "route", "show", "table", "all").stdout
            assert _ip("-n", host.netns, "-6", "route", "show").stdout.strip() == ""
        yield a, b
    finally:
        for name in made:
            _ip("netns", "del", name)
        if made:
            leftover = _ip("netns", "list").stdout
            assert not any(name in leftover for name in made), leftover


def network_env(host: Host, peers: list[Host], domain_id: int, cache: Path, *, udp_only: bool = True) -> dict:
    """The environment after `eval "$(lightfast dds env --network ...)"` inside ``host``'s namespace."""
    base = child_env(domain_id, XDG_CACHE_HOME=str(cache), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    for key in ("FASTRTPS_DEFAULT_PROFILES_FILE", "ROS_AUTOMATIC_DISCOVERY_RANGE", "RMW_IMPLEMENTATION"):
        base.pop(key)  # what a user's shell would not have: the eval must provide them
    args = ["--hosts", *(p.address for p in peers), "--interface", host.address] + (["--udp-only"] * udp_only)
    script = f'eval "$({sys.executable} -m lightfast dds env --network {" ".join(args)})" && env -0'
    result = run_bounded(host.cmd("bash", "-c", script), timeout_s=60, env=base)
    assert result.returncode == 0 and result.stderr == "", result.stderr  # no warning: the address is the host's
    env = dict(item.split("=", 1) for item in result.stdout.split("\0") if "=" in item)
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    assert env["ROS_STATIC_PEERS"] == ";".join(p.address for p in peers)
    assert env == apply_env(env, network_transport_env([p.address for p in peers], [host.address],
                                                       udp_only=udp_only, cache_dir=cache / "lightfast" / "dds"),
                            NETWORK_UNSET)  # the CLI printed what the library returns
    return env


@pytest.fixture(scope="module")
def tiny_daylight(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The demo test's tiny recording (20 frames, 160x120, 10 cm mesh) and its lighting map (0.5 m patches), made
    the way scripts/demo.sh makes them: (sequence dir, map dir)."""
    sim = tmp_path_factory.mktemp("multi_host_sim")
    env = child_env(0, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    size = TINY["SIZE"]
    made = run_bounded([*LIGHTFAST, "sim", "daylight", str(sim), "--sequences", SEQUENCE, "--frames", TINY["FRAMES"],
                        "--size", size, "--resolution", TINY["RESOLUTION"]], timeout_s=300, env=env)
    assert made.returncode == 0, made.stderr[-2000:]
    scene = SEQUENCE.split(".")[0]
    scenes = sim / "scenes"
    lmap = sim / "map"
    made = run_bounded([*LIGHTFAST, "daylight", "prepare", str(scenes / f"{scene}.map.ply"),
                        str(scenes / f"{scene}.site.yaml"), str(lmap), "--patch-size", TINY["PATCH_SIZE"],
                        "--openings", str(scenes / f"{scene}.openings.yaml")], timeout_s=300, env=env)
    assert made.returncode == 0, made.stderr[-2000:]
    return sim / SEQUENCE, lmap


def payload_bytes(bag: Path, topics: list[str]) -> int:
    with open_bag(bag) as reader:
        return sum(len(m.data) for m in reader.messages(topics=topics))


@pytest.mark.timeout(300)
def test_pipeline_across_two_hosts(two_hosts: tuple[Host, Host], tiny_daylight: tuple[Path, Path],
                                   domain_id: int, tmp_path: Path) -> None:
    a, b = two_hosts
    seq_dir, lmap = tiny_daylight
    bag = seq_dir / "bag"
    env_a = network_env(a, [a, b], domain_id, tmp_path / "cache")
    env_b = network_env(b, [a, b], domain_id, tmp_path / "cache")
    envs = {a: env_a, b: env_b}
    initial_pose = run_bounded([*LIGHTFAST, "bag", "pose", str(bag)], timeout_s=60, env=env_b).stdout.strip()
    assert initial_pose.startswith("["), initial_pose
    recorded = tmp_path / "recorded"
    logs = tmp_path / "logs"
    logs.mkdir()
    before = {(h.netns, n): h.counter(n) for h in (a, b) for n in ("rx_bytes", "tx_bytes")}
    node = [sys.executable, "-m"]
    reliable = ["-p", "sensor_reliability:=reliable"]  # the test counts every frame's pose
    nodes = {  # name: (host, argv); the sun update is a background job there, as in the demo
        "sun_update_node": (a, ["nice", "-n", "19", *node, "sun_update_node.node", "--ros-args",
                                "-p", "use_sim_time:=true", "-p", f"lighting_map:={lmap}",
                                "-p", "update_period_s:=60.0", "-p", "patches_per_step:=2000"]),
        "daylight_relight_node": (b, [*node, "daylight_relight_node.node", "--ros-args", "-p", "use_sim_time:=true",
                                      "-p", f"lighting_map:={lmap}", "-p", f"crf_file:={seq_dir / 'camera.yaml'}",
                                      "-p", "reference:=relit", *reliable]),
        "rgbd_tracker_node": (b, [*node, "rgbd_tracker_node.node", "--ros-args", "-p", "use_sim_time:=true",
                                  "-p", "mode:=proposed", "-p", f"initial_pose:={initial_pose}", *reliable]),
    }
    with ExitStack() as stack:
        log = stack.enter_context(open(logs / "nodes.log", "w"))
        pids = []
        for host, argv in nodes.values():
            proc = stack.enter_context(bounded_process(host.cmd(*argv), timeout_s=240, env=envs[host], stdout=log,
                                                       stderr=subprocess.STDOUT))
            pids += ["--pid", str(proc.pid)]
        recorder = stack.enter_context(bounded_process(
            b.cmd(*LIGHTFAST, "bag", "record", "-o", str(recorded), *RECORDED), timeout_s=240, env=env_b))
        # host B sees all three nodes, host A's over the veth; a node that dies while starting fails the wait
        ready = run_bounded(b.cmd(*LIGHTFAST, "wait-ready", *nodes, "--timeout", "150", *pids), timeout_s=170,
                            env=env_b)
        assert ready.returncode == 0, ready.stderr + _tail(logs / "nodes.log")
        play = run_bounded(a.cmd(*LIGHTFAST, "bag", "play", str(bag), "--clock", "20", "--preroll",
                                 TINY["PREROLL"], "--wait-for-subscribers", "60", "--topics", *PLAYED),
                           timeout_s=120, env=env_a)
        assert play.returncode == 0, play.stderr + _tail(logs / "nodes.log")
        # the last frames' poses (as the demo waits), then the recorder stops
        time.sleep(2)
        recorder.send_signal(signal.SIGINT)
        rec_out, rec_err = recorder.communicate(timeout=60)
        assert recorder.returncode == 0, rec_err
    after = {(h.netns, n): h.counter(n) for h in (a, b) for n in ("rx_bytes", "tx_bytes")}
    delta = {k: after[k] - before[k] for k in after}
    score = score_recording(recorded, bag)
    images = payload_bytes(bag, PLAYED)
    with open_bag(recorded) as reader:
        chunks = sum(1 for _ in reader.messages(topics=[SUN_CHUNK_TOPIC]))
    print(f"\nveth bytes {delta}; played image + info payload {images} B; frames {score.frames}, poses "
          f"{score.poses}, f2m {score.f2m}, sun chunks recorded on B {chunks}; recorder: {rec_out.strip()}")
    assert score.frames == int(TINY["FRAMES"]) and score.poses >= score.frames - 2, (score, _tail(logs / "nodes.log"))
    assert score.f2m >= 1, "poses must be refined against the relit reference (f2m)"
    assert chunks >= 1  # host A's sun_update_node reached host B's relight node and recorder
    # the frames crossed the veth by UDP: A sent and B received at least the played payload (both ends of the
    # pair count the same packets, up to a late ARP or discovery packet between the two reads)
    assert delta[(a.netns, "tx_bytes")] >= images and delta[(b.netns, "rx_bytes")] >= images, delta
    assert abs(delta[(a.netns, "tx_bytes")] - delta[(b.netns, "rx_bytes")]) < 0.01 * images, delta


def _tail(path: Path, n: int = 3000) -> str:
    return "\n" + path.read_text(errors="replace")[-n:] if path.exists() else ""


@pytest.mark.timeout(120)
def test_packaged_network_profile_discovers_by_multicast(two_hosts: tuple[Host, Host], domain_id: int,
                                                         tmp_path: Path) -> None:
    """`lightfast dds env --network` with no options, as shipped: shared memory + UDP on all interfaces, SUBNET
    (multicast) discovery. Fast DDS derives its host id from the IPv4 addresses, so the two namespaces count as two
    machines and talk UDP, not shared memory, over the veth: 30 640x480 images arrive and cross it."""
    a, b = two_hosts
    net = {**network_transport_env(domain_id=domain_id), "OPENBLAS_NUM_THREADS": "1"}
    env = apply_env(child_env(domain_id), net, [*NETWORK_UNSET, "ROS_STATIC_PEERS"])
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(NETWORK_PROFILE_PATH)
    with BagWriter(tmp_path / "images") as writer:
        writer.add_topic("/images", "sensor_msgs/msg/Image")
        Image = writer.typestore.types["sensor_msgs/msg/Image"]
        Header, Time = writer.typestore.types["std_msgs/msg/Header"], writer.typestore.types[
            "builtin_interfaces/msg/Time"]
        for i in range(30):
            data = np.full(640 * 480 * 3, i, dtype=np.uint8)
            writer.write_message("/images", i * 33_000_000, Image(
                header=Header(stamp=Time(sec=0, nanosec=i * 33_000_000), frame_id="camera"), height=480, width=640,
                encoding="rgb8", is_bigendian=0, step=1920, data=data))
    before = b.counter("rx_bytes")
    out = tmp_path / "got"
    with bounded_process(b.cmd(*LIGHTFAST, "bag", "record", "-o", str(out), "--max-messages", "30", "/images"),
                         timeout_s=90, env=env) as rec:
        play = run_bounded(a.cmd(*LIGHTFAST, "bag", "play", str(tmp_path / "images"), "--rate", "0",
                                 "--wait-for-subscribers", "60"), timeout_s=90, env=env)
        assert play.returncode == 0, play.stderr
        rec_out, rec_err = rec.communicate(timeout=60)
    assert rec.returncode == 0, rec_err
    assert "recorded 30 messages" in rec_out, rec_out
    crossed = b.counter("rx_bytes") - before
    print(f"\nveth rx on B: {crossed} B for 30 images of {640 * 480 * 3} B")
    assert crossed >= 30 * 640 * 480 * 3
