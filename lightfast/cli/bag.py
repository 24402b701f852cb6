"""``lightfast bag …``: inspect, play, record and compare bags; print one pose of a bag."""
from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from lightfast.cli.common import EXIT_CORRUPT, EXIT_DIFFERENT, EXIT_INTERRUPTED, stop_on_signals
from lightfast.errors import LightfastError

NAME = "bag"
HELP = "inspect, play, record and compare rosbag2 bags (MCAP, sqlite3)"


def _cmd_bag_info(args: argparse.Namespace) -> int:
    from lightfast.bag import SkippedChunks, open_bag

    with open_bag(args.bag) as bag:
        print(bag.info.format(), flush=True)
        if not args.check:
            return 0
        skipped = SkippedChunks()
        count = sum(1 for _ in bag.messages(skipped=skipped))
    print(f"Check:             {count} messages read" + (f", {skipped.summary()}" if skipped else ", no corrupt chunk"))
    if skipped:
        _warn_corrupt(args.bag, skipped.summary(), [c.describe() for c in skipped.chunks.values()],
                      "the bag is damaged")
        return EXIT_CORRUPT
    return 0


def _cmd_bag_play(args: argparse.Namespace) -> int:
    from lightfast.bag import open_bag
    from lightfast.ros.player import PlayOptions, play_bag
    from lightfast.ros.runtime import ros_session

    options = PlayOptions(
        rate=args.rate,
        loop=args.loop or args.loops > 0,
        max_loops=args.loops,
        clock_hz=args.clock or 0.0,
        topics=tuple(args.topics or ()),
        start_offset_s=args.start_offset,
        preroll_s=args.preroll,
        wait_for_subscribers_s=args.wait_for_subscribers or 0.0,
        ack_timeout_s=args.ack_timeout,
        qos_depth=args.qos_depth,
        reliability=args.reliability,
    )
    with open_bag(args.bag) as bag, stop_on_signals() as stop:
        with ros_session("lightfast_bag_play", domain_id=args.domain_id, install_signal_handlers=False) as (node, _):
            report = play_bag(bag, node, options, stop=stop)
    print(report.summary(), flush=True)
    if report.interrupted:
        return EXIT_INTERRUPTED
    if report.corrupt_chunks:
        verdict = "accepted (--skip-corrupt)" if args.skip_corrupt else "the replay is incomplete"
        _warn_corrupt(args.bag, report.skipped_summary(), [c.describe() for c in report.corrupt_chunks], verdict)
        return 0 if args.skip_corrupt else EXIT_CORRUPT
    return 0


def _warn_corrupt(bag: str, summary: str, chunks: Sequence[str], verdict: str) -> None:
    """One warning line on stderr: what was skipped, the first corrupt chunk (descriptions), the verdict."""
    more = f" (and {len(chunks) - 1} more)" if len(chunks) > 1 else ""
    print(f"lightfast: warning: {bag}: {summary}; first: {chunks[0]}{more}; {verdict}", file=sys.stderr)


def _cmd_bag_record(args: argparse.Namespace) -> int:
    from lightfast.bag import BagWriter
    from lightfast.ros.recorder import BagRecorder, drain
    from lightfast.ros.runtime import ros_session

    topics = None if args.all or not args.topics else args.topics
    with stop_on_signals() as stop, ros_session(
        "lightfast_bag_record", domain_id=args.domain_id, install_signal_handlers=False,
        use_sim_time=args.use_sim_time,
    ) as (node, executor):
        writer = BagWriter(args.output, storage=args.storage, overwrite=args.overwrite, compression=args.compression)
        recorder = BagRecorder(node, writer, topics=topics)
        try:
            print(f"recording {'all topics' if topics is None else ' '.join(topics)} to {args.output} "
                  "(Ctrl-C to stop)", file=sys.stderr, flush=True)
            deadline = time.monotonic() + args.max_duration if args.max_duration else float("inf")
            while not stop.is_set() and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
                if args.max_messages and recorder.report.message_count >= args.max_messages:
                    break
            drain(lambda t: executor.spin_once(timeout_sec=t), lambda: recorder.report.message_count)
        finally:
            report = recorder.close()
    print(report.summary())
    return 0


def _cmd_bag_compare(args: argparse.Namespace) -> int:
    from lightfast.bag import compare_bags

    result = compare_bags(args.reference, args.other, topics=args.topics)
    print(result.summary())
    return 0 if result.identical else EXIT_DIFFERENT


def _cmd_bag_pose(args: argparse.Namespace) -> int:
    from lightfast.bag import open_bag
    from lightfast.geometry import matrix_to_quat
    from lightfast.ros.convert import pose_stamped_to_matrix

    with open_bag(args.bag) as bag:
        if args.topic not in bag.select_topics(None):
            raise LightfastError(f"{args.bag}: no topic {args.topic}")
        for i, m in enumerate(bag.messages(topics=[args.topic])):
            if i == args.index:
                T = pose_stamped_to_matrix(bag.deserialize(m))[0]
                values = [*T[:3, 3], *matrix_to_quat(T[:3, :3])]
                print("[" + ", ".join(f"{v:.9g}" for v in values) + "]")
                return 0
    raise LightfastError(f"{args.bag}: {args.topic} has no message {args.index}")


def _optional_float(default: float) -> dict[str, object]:
    return dict(nargs="?", type=float, const=default, default=None, metavar="VALUE")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """``lightfast bag`` and its subcommands."""
    bag = subparsers.add_parser(NAME, help=HELP)
    bag_sub = bag.add_subparsers(dest="bag_command", required=True, metavar="BAG_COMMAND")

    p = bag_sub.add_parser("info", help="print a bag's topics, types, counts, rates and QoS")
    p.add_argument("bag", help="bag directory, or its .mcap/.db3 file")
    p.add_argument("--check", action="store_true",
                   help="also read every message and check every MCAP chunk (exit 5 if some are corrupt)")
    p.set_defaults(func=_cmd_bag_info)

    p = bag_sub.add_parser("play", help="publish a bag's messages on live topics")
    p.add_argument("bag", help="bag directory, or its .mcap/.db3 file")
    p.add_argument("-r", "--rate", type=float, default=1.0, help="speed factor; 0 = as fast as possible (default 1)")
    p.add_argument("-l", "--loop", action="store_true", help="play again from the start when the bag ends")
    p.add_argument("--loops", type=int, default=0, metavar="N",
                   help="with --loop, stop after N plays of the bag (default: until interrupted)")
    p.add_argument("--clock", **_optional_float(40.0),
                   help="publish /clock for use_sim_time, at VALUE Hz (default 40) and before every message")
    p.add_argument("--topics", nargs="+", metavar="TOPIC", help="play only these topics")
    p.add_argument("--start-offset", type=float, default=0.0, metavar="SECONDS", help="skip the first SECONDS")
    p.add_argument("--preroll", type=float, default=0.0, metavar="SECONDS",
                   help="with --clock: run /clock from SECONDS before the first message first (nodes get ready)")
    p.add_argument("--wait-for-subscribers", **_optional_float(10.0),
                   help="wait up to VALUE s (default 10) until every topic has a subscriber")
    p.add_argument("--ack-timeout", type=float, default=30.0, metavar="SECONDS",
                   help="at the end wait this long for reliable subscribers to acknowledge (default 30)")
    p.add_argument("--qos-depth", type=int, default=0, metavar="N", help="KEEP_LAST N instead of KEEP_ALL")
    p.add_argument("--reliability", choices=("reliable", "best_effort"), default="",
                   help="publish with this QoS reliability instead of the recorded publishers' (best_effort: as a "
                   "camera driver with sensor-data QoS does)")
    p.add_argument("--skip-corrupt", action="store_true",
                   help="exit 0 even if corrupt chunks of the bag were skipped (they are skipped and reported "
                   "either way; without this option the exit code is 5)")
    p.add_argument("--domain-id", type=int, default=None, help="ROS domain id (default: ROS_DOMAIN_ID or 0)")
    p.set_defaults(func=_cmd_bag_play)

    p = bag_sub.add_parser("record", help="record live topics into an MCAP bag (Ctrl-C or SIGTERM to stop)")
    p.add_argument("topics", nargs="*", metavar="TOPIC", help="topics to record (default: all)")
    p.add_argument("-a", "--all", action="store_true", help="record every topic (except /rosout, /parameter_events)")
    p.add_argument("-o", "--output", required=True, help="bag directory to create")
    p.add_argument("-s", "--storage", choices=("mcap", "sqlite3"), default="mcap", help="storage (default mcap)")
    p.add_argument("--compression", choices=("none", "zstd", "lz4"), default="none",
                   help="MCAP chunk compression (default none); the file stays readable by any MCAP reader")
    p.add_argument("--overwrite", action="store_true", help="replace an existing bag at --output")
    p.add_argument("--max-duration", type=float, default=0.0, metavar="SECONDS", help="stop after SECONDS")
    p.add_argument("--max-messages", type=int, default=0, metavar="N", help="stop after N messages")
    p.add_argument("--use-sim-time", action="store_true", help="log times from /clock instead of the system clock")
    p.add_argument("--domain-id", type=int, default=None, help="ROS domain id (default: ROS_DOMAIN_ID or 0)")
    p.set_defaults(func=_cmd_bag_record)

    p = bag_sub.add_parser("compare", help="compare two bags topic by topic (exit 4 if they differ)")
    p.add_argument("reference", help="the reference bag (e.g. what was played)")
    p.add_argument("other", help="the bag to check (e.g. what was recorded)")
    p.add_argument("--topics", nargs="+", metavar="TOPIC", help="compare only these topics")
    p.set_defaults(func=_cmd_bag_compare)

    p = bag_sub.add_parser("pose", help="print one PoseStamped of a bag as [x, y, z, qx, qy, qz, qw] (e.g. for "
                           "the tracker's initial_pose parameter)")
    p.add_argument("bag", help="bag directory, or its .mcap/.db3 file")
    p.add_argument("--topic", default="/ground_truth/pose", help="PoseStamped topic (default /ground_truth/pose)")
    p.add_argument("--index", type=int, default=0, help="message index on that topic (default 0, the first)")
    p.set_defaults(func=_cmd_bag_pose)
