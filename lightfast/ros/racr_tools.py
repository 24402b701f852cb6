"""Helpers around a live rACR run for launch-free scripts (there is no ``ros2`` CLI here): ``lightfast racr wait``,
used by ``scripts/racr_demo.sh``.

:func:`wait_converged` follows ``/racr/status`` until ``racr_node`` has ended its run (``converged``, or the same
convergence its self-check did not confirm: ``ambiguous`` or ``failed``, :data:`FINISHED`), and raises
:class:`~lightfast.ros.errors.ToolError` when the initialization failed, the timeout passes or one of the watched
processes has exited. :func:`score_run` then scores where
the camera really is — the evaluation reads the simulator's truth: the last ``/sim/ground_truth/camera_pose`` and
the scene's ``truth.yaml`` —: the final AFD against the reference image (paper §5.2, success < 3 px), the camera
pose error against the reference pose, and the errors of the estimated real scale s and hand–eye X.

Importing this module does not import rclpy.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lightfast.geometry import make_transform, quat_to_matrix
from lightfast.ros.convert import pose_stamped_to_matrix
from lightfast.ros.diagnostics import diagnostic_values
from lightfast.ros.errors import ToolError
from lightfast.sim.racr import RacrScene
from lightfast.sim.racr_live import FinalPoseResult, evaluate_final_pose
from lightfast.topics import PLATFORM_STATUS_TOPIC, RACR_STATUS_TOPIC, SIM_CAMERA_POSE_TOPIC

__all__ = ["FINISHED", "NODE_NAME", "TERMINAL_FAILURES", "RacrRun", "pose7_to_matrix", "score_run", "wait_converged"]

NODE_NAME = "racr_node"
#: Stages in which racr_node's run has ended: g <= eta, and the self-check's verdict on it (verified: converged).
FINISHED = ("converged", "ambiguous", "failed")
#: Stages racr_node does not leave by itself, without a pose to score.
TERMINAL_FAILURES = ("initialization_failed",)


@dataclass(frozen=True)
class RacrRun:
    """What :func:`wait_converged` saw of a finished run (``stage``: one of :data:`FINISHED`)."""

    status: dict[str, str]  # racr_node's last status values (and "message")
    platform: dict[str, str]  # the platform simulator's last status values
    T_world_cam: np.ndarray  # the true camera pose after the last motion
    wall_s: float  # wall time from the start of the wait to convergence

    @property
    def stage(self) -> str:
        return self.status.get("stage", "")

    @property
    def scale_m_per_vse(self) -> float | None:
        """The real scale s racr_node estimated (None if it reported none)."""
        s = self.status.get("scale_m_per_vse")
        return float(s) if s else None


def pose7_to_matrix(text: str) -> np.ndarray | None:
    """``"x y z qx qy qz qw"`` (as racr_node reports ``T_cam_hand``) as a 4×4 transform; None if malformed."""
    try:
        v = [float(x) for x in text.split()]
    except ValueError:
        return None
    return make_transform(quat_to_matrix(v[3:]), v[:3]) if len(v) == 7 else None


def wait_converged(node: Any, executor: Any, *, timeout_s: float, pids: Sequence[int] = ()) -> RacrRun:
    """Spin until racr_node's run has ended (a stage of :data:`FINISHED`) and the platform has come to rest; raises
    :class:`ToolError` when the initialization failed, a process of ``pids`` exits, ``timeout_s`` passes or no true
    camera pose arrived. Ctrl-C (rclpy's signal handler) raises KeyboardInterrupt."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import ExternalShutdownException

    from lightfast.ros.qos import OUTPUT_QOS

    seen: dict[str, Any] = {"racr": {}, "platform": {}, "truth": None}

    def on_status(msg: DiagnosticArray) -> None:
        for s in msg.status:
            if s.name == NODE_NAME:
                seen["racr"] = diagnostic_values(s) | {"message": s.message}

    def on_platform(msg: DiagnosticArray) -> None:
        for s in msg.status:
            seen["platform"] = diagnostic_values(s)

    def on_truth(msg: PoseStamped) -> None:
        seen["truth"] = pose_stamped_to_matrix(msg)[0]

    node.create_subscription(DiagnosticArray, RACR_STATUS_TOPIC, on_status, OUTPUT_QOS)
    node.create_subscription(DiagnosticArray, PLATFORM_STATUS_TOPIC, on_platform, OUTPUT_QOS)
    node.create_subscription(PoseStamped, SIM_CAMERA_POSE_TOPIC, on_truth, OUTPUT_QOS)
    start = time.monotonic()
    deadline = start + timeout_s
    end: float | None = None
    while time.monotonic() < deadline:
        try:
            executor.spin_once(timeout_sec=0.1)
        except ExternalShutdownException:  # Ctrl-C, through rclpy's signal handler
            raise KeyboardInterrupt from None
        for pid in pids:
            if not Path(f"/proc/{pid}").exists():
                raise ToolError(f"process {pid} has exited; last {NODE_NAME} status: {seen['racr'] or 'none'}")
        stage = seen["racr"].get("stage")
        if stage in TERMINAL_FAILURES:
            raise ToolError(f"{NODE_NAME} stopped in stage {stage}: {seen['racr'].get('message')}")
        if stage in FINISHED and end is None:
            end = time.monotonic()
        # after convergence, let the platform's at-rest state and the truth of its last stop arrive
        if end is not None and time.monotonic() - end > 0.5 and seen["platform"].get("moving") == "false":
            break
    else:
        state = seen["racr"] or f"no status on {RACR_STATUS_TOPIC} (is {NODE_NAME} running?)"
        raise ToolError(f"{NODE_NAME} did not finish within {timeout_s:g} s; last status: {state}")
    if seen["truth"] is None:
        raise ToolError(f"no {SIM_CAMERA_POSE_TOPIC} received: is the platform simulator running?")
    assert end is not None
    return RacrRun(seen["racr"], seen["platform"], seen["truth"], end - start)


def score_run(scene: RacrScene, run: RacrRun, *, vse_scale_m_per_vse: float | None = None) -> FinalPoseResult:
    """Score the final camera pose of ``run`` on ``scene`` with the scene's truth; ``vse_scale_m_per_vse`` is the
    VSE stand-in's monocular scale if it was not the scene's (for the scale error)."""
    return evaluate_final_pose(scene, run.T_world_cam, scale_m_per_vse=run.scale_m_per_vse,
                               T_cam_hand=pose7_to_matrix(run.status.get("T_cam_hand", "")),
                               vse_scale_m_per_vse=vse_scale_m_per_vse)
