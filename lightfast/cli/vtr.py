"""``lightfast vtr …``: helpers around ``vtr_localizer_node`` for scripts (``scripts/vtr_demo.sh``)."""
from __future__ import annotations

import argparse
from pathlib import Path

NAME = "vtr"
HELP = "helpers around vtr_localizer_node for scripts (scripts/vtr_demo.sh)"


def _cmd_vtr_wait_idle(args: argparse.Namespace) -> int:
    from lightfast.ros.runtime import ros_session
    from lightfast.ros.vtr_tools import NODE_NAME, wait_idle

    with ros_session("vtr_wait_idle") as (node, executor):
        values = wait_idle(node, executor, settle_s=args.settle, timeout_s=args.timeout, subscribers=args.subscribers,
                           pid=args.pid)
    print(f"{NODE_NAME} idle: {values.get('frames_in', '?')} stereo pairs in, {values.get('frames_done', '?')} "
          f"processed, {values.get('dropped_behind', '?')} dropped behind, {values.get('bad_inputs', '?')} bad inputs")
    return 0


def _cmd_vtr_finish_teach(args: argparse.Namespace) -> int:
    from lightfast.ros.runtime import ros_session
    from lightfast.ros.vtr_tools import finish_teach

    with ros_session("vtr_finish_teach") as (node, executor):
        message = finish_teach(node, executor, settle_s=args.settle, timeout_s=args.timeout, pid=args.pid)
    print(f"teach finished: {message}")
    return 0


def _cmd_vtr_summary(args: argparse.Namespace) -> int:
    from lightfast.ros.vtr_tools import summarize

    s = summarize(args.recorded, args.map, args.teach_bag, args.repeat_bag)
    inl = ", ".join(f"{k} {v:g}" for k, v in s["median_inliers"].items())
    print(f"repeat: {s['pairs']} stereo pairs, localized {s['localized']} ({100 * s['localized'] / s['pairs']:.1f} %), "
          f"pairs in the failure state {s['failure_pairs']}, longest stretch on VO {s['max_distance_on_vo_m']:.2f} m")
    print(f"repeat: median inliers of localized pairs: {inl}; median time per pair {s['median_total_ms']:.0f} ms")
    if "scored" in s:
        print(f"repeat: error against ground truth ({s['scored']} localized pairs): median {s['error_median_cm']:.1f} "
              f"cm, max {s['error_max_cm']:.1f} cm, rotation max {s['rotation_max_deg']:.2f} deg")
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """``lightfast vtr`` and its subcommands."""
    vtr = subparsers.add_parser(NAME, help=HELP, description="Helpers around vtr_localizer_node for scripts.")
    vtr_sub = vtr.add_subparsers(dest="vtr_command", required=True, metavar="VTR_COMMAND")
    for name, func, text in (("wait-idle", _cmd_vtr_wait_idle, "wait until the node has processed everything"),
                             ("finish-teach", _cmd_vtr_finish_teach, "wait until idle, then finish the teach")):
        p = vtr_sub.add_parser(name, help=text)
        p.add_argument("--settle", type=float, default=2.0, help="seconds without news that count as idle (2)")
        p.add_argument("--timeout", type=float, default=300.0, help="give up after this many seconds (300)")
        p.add_argument("--pid", type=int, help="give up as soon as this process (the node) has exited")
        if name == "wait-idle":
            p.add_argument("--subscribers", nargs="*", default=[], metavar="TOPIC",
                           help="also wait until each of these topics has a subscriber")
        p.set_defaults(func=func)
    p = vtr_sub.add_parser("summary", help="summarize a bag recorded from a repeat")
    p.add_argument("recorded", type=Path)
    p.add_argument("--map", type=Path, help="the teach map (for the error against ground truth)")
    p.add_argument("--teach-bag", type=Path, help="the taught bag with /ground_truth/pose")
    p.add_argument("--repeat-bag", type=Path, help="the repeated bag with /ground_truth/pose")
    p.set_defaults(func=_cmd_vtr_summary)
