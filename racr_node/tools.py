"""Command-line helper around a live rACR run for launch-free scripts (there is no ``ros2`` CLI here; used by
``scripts/racr_demo.sh``)::

    python -m racr_node.tools wait --scene SCENE_DIR [--timeout S] [--pid PID ...]

``wait`` follows ``/racr/status`` until ``racr_node`` reports ``converged`` (exit 0) or a stage it cannot leave by
itself (``initialization_failed``, ``failed``; exit 1), or the timeout passes (exit 1), and gives up as soon as one
of the ``--pid`` processes has exited. It then scores where the camera really is — the evaluation reads the
simulator's truth: the last ``/sim/ground_truth/camera_pose`` and the scene's ``truth.yaml`` — and prints the
final AFD against the reference image (paper §5.2, success < 3 px), the camera pose error against the reference
pose, the number of motions, the wall time and the simulated platform time (``/platform/status``), and the errors
of the estimated real scale s and hand–eye X. Exit codes: 0 converged, 1 not (message on stderr), 2 bad usage,
130 interrupted (Ctrl-C).
"""
from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lightfast.cli import run
from lightfast.errors import LightfastError
from lightfast.geometry import make_transform, quat_to_matrix
from lightfast.ros.convert import pose_stamped_to_matrix
from lightfast.ros.diagnostics import diagnostic_values
from lightfast.topics import PLATFORM_STATUS_TOPIC, RACR_STATUS_TOPIC, SIM_CAMERA_POSE_TOPIC

NODE_NAME = "racr_node"
_PROG = "python -m racr_node.tools"
#: Stages racr_node does not leave by itself.
TERMINAL_FAILURES = ("initialization_failed", "failed")


class ToolError(LightfastError):
    """The run did not converge (timeout, failure, a process exited) or cannot be scored."""


def _pose7(text: str) -> np.ndarray | None:
    try:
        v = [float(x) for x in text.split()]
    except ValueError:
        return None
    return make_transform(quat_to_matrix(v[3:]), v[:3]) if len(v) == 7 else None


def _wait(node: Any, executor: Any, *, timeout_s: float, pids: Sequence[int]) -> dict[str, Any]:
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
        seen["truth"] = pose_stamped_to_matrix(msg)

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
        if stage == "converged" and end is None:
            end = time.monotonic()
        # after convergence, let the platform's at-rest state and the truth of its last stop arrive
        if end is not None and time.monotonic() - end > 0.5 and seen["platform"].get("moving") == "false":
            break
    else:
        state = seen["racr"] or f"no status on {RACR_STATUS_TOPIC} (is {NODE_NAME} running?)"
        raise ToolError(f"{NODE_NAME} did not converge within {timeout_s:g} s; last status: {state}")
    if seen["truth"] is None:
        raise ToolError(f"no {SIM_CAMERA_POSE_TOPIC} received: is the platform simulator running?")
    assert end is not None
    return {**seen, "wall_s": end - start}


def cmd_wait(args: argparse.Namespace) -> int:
    from lightfast.ros.runtime import ros_session
    from lightfast.sim.racr_live import evaluate_final_pose
    from lightfast.sim.racr_scenes import load_scene

    scene = load_scene(args.scene)
    with ros_session("racr_wait") as (node, executor):
        seen = _wait(node, executor, timeout_s=args.timeout, pids=args.pid or ())
    st, plat = seen["racr"], seen["platform"]
    T_world_cam = seen["truth"][0]
    s_est = float(st["scale_m_per_vse"]) if st.get("scale_m_per_vse") else None
    r = evaluate_final_pose(scene, T_world_cam, scale_m_per_vse=s_est, T_cam_hand=_pose7(st.get("T_cam_hand", "")),
                            vse_scale_m_per_vse=args.vse_scale)
    motions, init = st.get("motions_issued", "?"), st.get("init_motions_total", "?")
    print(f"racr: converged after {st.get('adjustments', '?')} adjustments ({motions} motions, {init} for the "
          f"initialization) in {seen['wall_s']:.1f} s wall, {float(plat.get('simulated_time_s', 'nan')):.1f} s "
          f"simulated platform time, g={st.get('g', '?')} (eta {st.get('eta', '?')})")
    print(f"racr: final AFD {r.afd_px:.2f} px over {r.afd_points} grid points ({'success' if r.success else 'FAILURE'}"
          f": < 3 px)")
    print(f"racr: final camera pose vs the reference: {1e3 * r.translation_error_m:.2f} mm, "
          f"{r.rotation_error_deg:.3f} deg")
    if r.scale_error_rel is not None and r.hand_eye_rotation_error_deg is not None:
        print(f"racr: real scale s {s_est:.5g} ({100 * r.scale_error_rel:+.2f} % off the truth), hand-eye X error "
              f"{r.hand_eye_rotation_error_deg:.3f} deg, {1e3 * (r.hand_eye_translation_error_m or 0.0):.2f} mm")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=_PROG, description="Helper around a live rACR run for scripts.")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("wait", help="wait until racr_node converged, then score the final camera pose")
    p.add_argument("--scene", type=Path, required=True, help="the scene directory (its truth scores the run)")
    p.add_argument("--timeout", type=float, default=300.0, help="give up after this many seconds (300)")
    p.add_argument("--pid", type=int, nargs="*", help="give up as soon as one of these processes has exited")
    p.add_argument("--vse-scale", type=float, default=None,
                   help="the VSE stand-in's monocular scale if it was not the scene's (for the scale error)")
    p.set_defaults(func=cmd_wait)
    args = parser.parse_args(argv)
    return run(args.func, args, prog=f"{_PROG} {args.command}")


if __name__ == "__main__":
    sys.exit(main())
