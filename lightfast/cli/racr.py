"""``lightfast racr …``: helpers around a live rACR run for scripts (``scripts/racr_demo.sh``)."""
from __future__ import annotations

import argparse
from pathlib import Path

NAME = "racr"
HELP = "helpers around a live rACR run for scripts (scripts/racr_demo.sh)"


def _cmd_racr_wait(args: argparse.Namespace) -> int:
    """Exit 0 when racr_node converged (verified, or ``ambiguous``: its self-check could not confirm it); 1 when its
    self-check found the convergence wrong (``failed``; still scored) or it never finished (timeout, failed
    initialization, a --pid process exited); 130 on Ctrl-C."""
    from lightfast.ros.racr_tools import score_run, wait_converged
    from lightfast.ros.runtime import ros_session
    from lightfast.sim.racr import load_scene

    scene = load_scene(args.scene)
    with ros_session("racr_wait") as (node, executor):
        run = wait_converged(node, executor, timeout_s=args.timeout, pids=args.pid or ())
    r = score_run(scene, run, vse_scale_m_per_vse=args.vse_scale)
    st, plat = run.status, run.platform
    motions, init = st.get("motions_issued", "?"), st.get("init_motions_total", "?")
    print(f"racr: {run.stage} after {st.get('adjustments', '?')} adjustments ({motions} motions, {init} for the "
          f"initialization) in {run.wall_s:.1f} s wall, {float(plat.get('simulated_time_s', 'nan')):.1f} s "
          f"simulated platform time, g={st.get('g', '?')} (eta {st.get('eta', '?')})")
    print(f"racr: self-check: {st.get('message', '')}")
    print(f"racr: final AFD {r.afd_px:.2f} px over {r.afd_points} grid points ({'success' if r.success else 'FAILURE'}"
          f": < 3 px)")
    print(f"racr: final camera pose vs the reference: {1e3 * r.translation_error_m:.2f} mm, "
          f"{r.rotation_error_deg:.3f} deg")
    if r.scale_error_rel is not None and r.hand_eye_rotation_error_deg is not None:
        print(f"racr: real scale s {run.scale_m_per_vse:.5g} ({100 * r.scale_error_rel:+.2f} % off the truth), "
              f"hand-eye X error {r.hand_eye_rotation_error_deg:.3f} deg, "
              f"{1e3 * (r.hand_eye_translation_error_m or 0.0):.2f} mm")
    return 1 if run.stage == "failed" else 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """``lightfast racr`` and its subcommands."""
    racr = subparsers.add_parser(NAME, help=HELP, description="Helper around a live rACR run for scripts.")
    racr_sub = racr.add_subparsers(dest="racr_command", required=True, metavar="RACR_COMMAND")
    p = racr_sub.add_parser("wait", help="wait until racr_node converged, then score the final camera pose")
    p.add_argument("--scene", type=Path, required=True, help="the scene directory (its truth scores the run)")
    p.add_argument("--timeout", type=float, default=300.0, help="give up after this many seconds (300)")
    p.add_argument("--pid", type=int, nargs="*", help="give up as soon as one of these processes has exited")
    p.add_argument("--vse-scale", type=float, default=None,
                   help="the VSE stand-in's monocular scale if it was not the scene's (for the scale error)")
    p.set_defaults(func=_cmd_racr_wait)
