"""``lightfast wait-ready``: wait until lightfast nodes announce that they can take data."""
from __future__ import annotations

import argparse

NAME = "wait-ready"
HELP = ("wait until lightfast nodes announce that they can take data (for launch-free scripts; exit 1 on timeout or "
        "when a --pid process ends first)")


def _cmd_wait_ready(args: argparse.Namespace) -> int:
    from lightfast.ros.ready import process_alive, wait_ready
    from lightfast.ros.runtime import ros_session

    pids = tuple(args.pid or ())
    with ros_session("lightfast_wait_ready", domain_id=args.domain_id, install_signal_handlers=False) as (node, ex):
        wait_ready(node, ex, args.nodes, timeout_s=args.timeout, alive=lambda: all(map(process_alive, pids)))
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """``lightfast wait-ready``."""
    p = subparsers.add_parser(NAME, help=HELP)
    p.add_argument("nodes", nargs="+", metavar="NODE", help="node names, e.g. rgbd_tracker_node")
    p.add_argument("--timeout", type=float, default=300.0, help="seconds to wait (default 300)")
    p.add_argument("--pid", type=int, action="append", help="fail as soon as this process ends (repeatable)")
    p.add_argument("--domain-id", type=int, default=None, help="DDS domain (default: ROS_DOMAIN_ID)")
    p.set_defaults(func=_cmd_wait_ready)
