"""Benchmark: cross-process bag replay throughput of ``lightfast bag play`` on the real 7-Scenes bag.

``lightfast bag play`` runs as a subprocess; this process is the reliable subscriber (raw subscriptions on every
topic, KEEP_ALL). For ``--rate 0`` (as fast as possible) and ``--rate 1`` (the recording's 30 Hz) it reports, as
the median of ``--repeats`` runs: the player's real-time factor (bag seconds per wall second while publishing),
the subscriber's received message rate and MB/s, and drops (messages played but not received).
Target (foundation issue): >= 3x real time at rate 0 with zero drops.

    .venv/bin/python benchmarks/bag_play.py [--bag DIR] [--repeats 3]

Writes ``benchmarks/results/bag_play.md`` and ``.json`` (atomically).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from lightfast.ros.transport import local_transport_env, use_local_transport  # noqa: E402

use_local_transport(force=True)

import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

from lightfast.bag import open_bag  # noqa: E402
from lightfast.data.sevenscenes import convert_7scenes  # noqa: E402
from lightfast.data.shared import shared_root  # noqa: E402
from lightfast.io import write_text_atomic  # noqa: E402
from lightfast.ros.domain import reserve_domain_id  # noqa: E402
from lightfast.ros.runtime import message_class  # noqa: E402
from lightfast.ros.spin import spin_until  # noqa: E402


def run_once(bag: Path, rate: float, domain_id: int, topics: dict[str, str], total: int) -> dict[str, float]:
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    executor = SingleThreadedExecutor(context=context)
    node = Node("bench_subscriber", context=context)
    executor.add_node(node)
    counts = {t: 0 for t in topics}
    stats = {"bytes": 0, "first": 0.0, "last": 0.0}

    def make_cb(topic: str):
        def cb(data: bytes) -> None:
            now = time.monotonic()
            if not stats["first"]:
                stats["first"] = now
            stats["last"] = now
            stats["bytes"] += len(data)
            counts[topic] += 1
        return cb

    qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
    for topic, msgtype in topics.items():
        node.create_subscription(message_class(msgtype), topic, make_cb(topic), qos, raw=True)
    env = dict(os.environ, **local_transport_env(discovery_range="LOCALHOST", domain_id=domain_id))
    cmd = ["timeout", "-k", "5", "300", sys.executable, "-m", "lightfast", "bag", "play", str(bag), "--rate",
           str(rate), "--wait-for-subscribers", "60"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        spin_until(executor, lambda: sum(counts.values()) >= total or proc.poll() is not None, timeout_s=300)
        spin_until(executor, lambda: sum(counts.values()) >= total, timeout_s=5)  # late arrivals after exit
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    if proc.returncode != 0:
        raise SystemExit(f"player failed: {err.strip()}")
    m = re.search(r"played (\d+) messages .* in ([\d.]+) s \(([\d.]+)x real time", out)
    if not m:
        raise SystemExit(f"unexpected player output: {out!r}")
    received = sum(counts.values())
    span = max(stats["last"] - stats["first"], 1e-9)
    return {
        "played": int(m.group(1)),
        "player_wall_s": float(m.group(2)),
        "realtime_factor": float(m.group(3)),
        "received": received,
        "drops": int(m.group(1)) - received,
        "received_msgs_per_s": received / span,
        "received_mb_per_s": stats["bytes"] / span / 1e6,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bag", type=Path, help="7-Scenes bag (default: converted into a temp dir)")
    parser.add_argument("--shared", type=Path, default=shared_root(),
                        help="the shared folder holding data/ (default: $LIGHTFAST_SHARED, else ../shared)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "bag_play")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        bag = args.bag or convert_7scenes(args.shared / "data" / "7scenes_redkitchen_300", Path(tmp) / "7scenes")
        with open_bag(bag) as b:
            topics = {t.name: t.msgtype for t in b.info.topics}
            total = b.info.message_count
            duration_s = b.info.duration_ns * 1e-9
            size_mb = b.info.size_bytes / 1e6
        rows = []
        with reserve_domain_id() as lease:
            for rate in (0.0, 1.0):
                runs = [run_once(bag, rate, lease.domain_id, topics, total) for _ in range(args.repeats)]
                med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
                med["max_drops"] = max(r["drops"] for r in runs)
                med["rate"] = rate
                rows.append(med)
                print(f"rate {rate:g}: {med}", flush=True)

    lines = [
        "# Bag replay throughput (cross-process, reliable subscriber)",
        "",
        f"Bag: real 7-Scenes redkitchen, {total} messages on {len(topics)} topics, {duration_s:.2f} s at 30 Hz, "
        f"{size_mb:.0f} MB (640x480 rgb8 + 16UC1 depth, camera_info, ground-truth pose).",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; median of "
        f"{args.repeats} runs; `python benchmarks/bag_play.py`.",
        "",
        "| --rate | real-time factor | player wall s | received msg/s | received MB/s | drops (median / max) |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        rate = "0 (max)" if r["rate"] == 0 else f"{r['rate']:g} (30 Hz)"
        lines.append(
            f"| {rate} | {r['realtime_factor']:.2f}x | {r['player_wall_s']:.2f} | {r['received_msgs_per_s']:.0f} | "
            f"{r['received_mb_per_s']:.0f} | {r['drops']:.0f} / {r['max_drops']:.0f} |"
        )
    target_ok = rows[0]["realtime_factor"] >= 3.0 and all(r["max_drops"] == 0 for r in rows)
    lines += ["", f"Target >= 3x real time at rate 0 with zero drops: {'met' if target_ok else 'NOT met'}.", ""]
    text = "\n".join(lines)
    print(text)
    write_text_atomic(args.out.with_suffix(".md"), text)
    write_text_atomic(args.out.with_suffix(".json"), json.dumps({"rows": rows, "target_met": target_ok}, indent=2))
    return 0 if target_ok else 1


if __name__ == "__main__":
    sys.exit(main())
