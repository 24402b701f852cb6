"""Helpers around ``vtr_localizer_node`` for launch-free scripts (there is no ``ros2`` CLI here): ``lightfast vtr
wait-idle``, ``finish-teach`` and ``summary``, used by ``scripts/vtr_demo.sh``.

:func:`wait_idle` waits until the node reports on ``/vtr/status``, every listed topic has a subscriber, and the
node has had nothing queued and received no new stereo pair for ``settle_s`` seconds — e.g. after ``lightfast bag
play`` returned, until the node has processed everything; with ``pid`` it gives up as soon as that process (the
node) has exited. :func:`finish_teach` does the same, then calls the ``/vtr/finish_teach`` service.
:func:`summarize` reads a bag recorded from a repeat (``/vtr/status``, ``/vtr/localization``): how many pairs
localized, the failures, inliers per source and timings; with the map and the teach and repeat bags (which hold
``/ground_truth/pose``, stamped like the images) also the localization error against the truth: the true pose of
the matched keyframe (its stamp is that of a teach pair) to the true camera pose of the repeat pair.
Failures raise :class:`~lightfast.ros.errors.ToolError`.

Importing this module does not import rclpy.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lightfast.bag.reader import open_bag
from lightfast.ros.convert import pose_to_matrix, stamp_to_ns
from lightfast.ros.diagnostics import diagnostic_level, diagnostic_values
from lightfast.ros.errors import ToolError
from lightfast.topics import GT_POSE_TOPIC, VTR_FINISH_TEACH_SERVICE, VTR_LOCALIZATION_TOPIC, VTR_STATUS_TOPIC
from lightfast.vtr.map_store import MapStore

__all__ = ["NODE_NAME", "finish_teach", "summarize", "wait_idle"]

NODE_NAME = "vtr_localizer_node"


def wait_idle(node: Any, executor: Any, *, settle_s: float, timeout_s: float, subscribers: Sequence[str] = (),
              pid: int | None = None) -> dict[str, str]:
    """Spin until the node is idle (see the module docstring); returns its last status values."""
    from diagnostic_msgs.msg import DiagnosticArray

    from lightfast.ros.qos import OUTPUT_QOS

    latest: dict[str, str] = {}

    def on_status(msg: DiagnosticArray) -> None:
        for s in msg.status:
            if s.name == NODE_NAME:
                latest.clear()
                latest.update(diagnostic_values(s))

    node.create_subscription(DiagnosticArray, VTR_STATUS_TOPIC, on_status, OUTPUT_QOS)
    deadline = time.monotonic() + timeout_s
    key: tuple[str, ...] | None = None
    since = time.monotonic()
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
        now = time.monotonic()
        if pid is not None and not Path(f"/proc/{pid}").exists():
            raise ToolError(f"{NODE_NAME} (process {pid}) has exited")
        if not latest or any(node.count_subscribers(t) < 1 for t in subscribers):
            since = now
            continue
        new_key = tuple(latest.get(k, "") for k in ("frames_in", "frames_done", "dropped_behind", "bad_inputs",
                                                     "ignored"))
        if new_key != key or latest.get("queued", "0") != "0":
            key, since = new_key, now
        elif now - since >= settle_s:
            return dict(latest)
    state = f"last status {latest}" if latest else f"no status on {VTR_STATUS_TOPIC} (is {NODE_NAME} running?)"
    raise ToolError(f"{NODE_NAME} did not become idle within {timeout_s:g} s: {state}")


def finish_teach(node: Any, executor: Any, *, settle_s: float, timeout_s: float, pid: int | None = None) -> str:
    """Wait until the node is idle, then finish the teach through ``/vtr/finish_teach``; returns the node's reply
    (raises :class:`ToolError` if the teach could not be finished)."""
    from std_srvs.srv import Trigger

    wait_idle(node, executor, settle_s=settle_s, timeout_s=timeout_s, pid=pid)
    client = node.create_client(Trigger, VTR_FINISH_TEACH_SERVICE)
    if not client.wait_for_service(timeout_sec=timeout_s):
        raise ToolError(f"no service {VTR_FINISH_TEACH_SERVICE} within {timeout_s:g} s")
    future = client.call_async(Trigger.Request())
    executor.spin_until_future_complete(future, timeout_sec=timeout_s)
    if not future.done():
        raise ToolError(f"{VTR_FINISH_TEACH_SERVICE} did not answer within {timeout_s:g} s")
    response = future.result()
    if not response.success:
        raise ToolError(f"the teach was not finished: {response.message}")
    return str(response.message)


def _gt_poses(bag_path: Path) -> dict[int, np.ndarray]:
    with open_bag(bag_path) as bag:
        if GT_POSE_TOPIC not in [t.name for t in bag.info.topics]:
            return {}
        out = {}
        for m in bag.messages(topics=[GT_POSE_TOPIC]):
            msg = bag.deserialize(m)
            out[stamp_to_ns(msg.header.stamp)] = pose_to_matrix(msg.pose)
        return out


def summarize(recorded: Path, map_path: Path | None = None, teach_bag: Path | None = None,
              repeat_bag: Path | None = None) -> dict[str, Any]:
    """The numbers of a recorded repeat (see the module docstring): ``pairs``, ``localized``, ``failure_pairs``,
    ``max_distance_on_vo_m``, ``median_inliers`` per source, ``median_total_ms``, ``localization_messages``; with
    the map and both bags also ``scored``, ``error_median_cm``, ``error_max_cm`` and ``rotation_max_deg``."""
    frames: dict[int, dict[str, str]] = {}
    poses: dict[int, tuple[int, np.ndarray]] = {}
    with open_bag(recorded) as bag:
        topics = [t.name for t in bag.info.topics]
        for m in bag.messages(topics=[t for t in (VTR_STATUS_TOPIC, VTR_LOCALIZATION_TOPIC) if t in topics]):
            msg = bag.deserialize(m)
            if m.topic == VTR_STATUS_TOPIC:
                for s in msg.status:
                    v = diagnostic_values(s)
                    if s.name == NODE_NAME and "localized" in v and v.get("stamp_ns"):
                        frames[int(v["stamp_ns"])] = v | {"level": str(int(diagnostic_level(s)))}
            else:
                kf = int(msg.header.frame_id.rsplit("_", 1)[-1])
                poses[stamp_to_ns(msg.header.stamp)] = (kf, pose_to_matrix(msg.pose.pose))
    if not frames:
        raise ToolError(f"{recorded}: no per-pair {VTR_STATUS_TOPIC} of a repeat")
    vals = [frames[s] for s in sorted(frames)]
    localized = [v["localized"] == "true" for v in vals]
    sources = sorted({k.removeprefix("inliers_") for v in vals for k in v if k.startswith("inliers_")})
    out: dict[str, Any] = {
        "pairs": len(vals),
        "localized": int(sum(localized)),
        "failure_pairs": sum(v["failure"] == "true" for v in vals),
        "max_distance_on_vo_m": max(float(v["distance_on_vo_m"]) for v in vals),
        "median_inliers": {s: float(np.median([int(v[f"inliers_{s}"]) for v, ok in zip(vals, localized, strict=True)
                                                if ok] or [0])) for s in sources},
        "median_total_ms": float(np.median([float(v["total_ms"]) for v in vals])),
        "localization_messages": len(poses),
    }
    if map_path is not None and teach_bag is not None and repeat_bag is not None:
        teach_map = MapStore.load(map_path)
        gt_teach, gt_repeat = _gt_poses(teach_bag), _gt_poses(repeat_bag)
        errs = []
        for stamp, v in zip(sorted(frames), vals, strict=True):
            if v["localized"] != "true" or stamp not in poses or stamp not in gt_repeat:
                continue
            kf, T = poses[stamp]
            kf_stamp = teach_map.keyframes[kf].stamp_ns
            if kf_stamp not in gt_teach:
                continue
            truth = np.linalg.inv(gt_teach[kf_stamp]) @ gt_repeat[stamp]
            dR = truth[:3, :3].T @ T[:3, :3]
            errs.append((float(np.linalg.norm(T[:3, 3] - truth[:3, 3])),
                         float(np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))))))
        if errs:
            t, r = np.array(errs).T
            out |= {"scored": len(errs), "error_median_cm": 100 * float(np.median(t)),
                    "error_max_cm": 100 * float(t.max()), "rotation_max_deg": float(r.max())}
    return out
