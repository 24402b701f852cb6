"""``lightfast``: the command line. Each subcommand is a thin wrapper over a library function.

Exit codes: 0 success; 1 a lightfast error (one line on stderr, no traceback; ``LIGHTFAST_DEBUG=1`` shows it);
2 bad usage; 3 an unexpected internal error; 4 ``bag compare`` found differences; 5 ``bag play`` skipped corrupt
chunks of the bag (one warning line; ``--skip-corrupt`` accepts that and exits 0) or ``bag info --check`` found
some; 130 interrupted.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from lightfast.errors import LightfastError

EXIT_ERROR, EXIT_USAGE, EXIT_INTERNAL, EXIT_DIFFERENT, EXIT_INTERRUPTED = 1, 2, 3, 4, 130
EXIT_CORRUPT = 5  # bag play skipped corrupt chunks (without --skip-corrupt), bag info --check found some
log = logging.getLogger("lightfast")


@contextmanager
def _stop_on_signals() -> Iterator[threading.Event]:
    """An event set by SIGINT or SIGTERM while the block runs (previous handlers restored after)."""
    stop = threading.Event()
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}

    def handler(signum: int, _frame: object) -> None:
        if stop.is_set() and signum == signal.SIGINT:
            raise KeyboardInterrupt  # a second Ctrl-C aborts
        stop.set()

    for s in previous:
        signal.signal(s, handler)
    try:
        yield stop
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


# --- bag ------------------------------------------------------------------------------------------------------

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
    from lightfast.bag import open_bag

    with open_bag(args.bag) as bag, _stop_on_signals() as stop:
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
    with _stop_on_signals() as stop, ros_session(
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


# --- data, config, dds ----------------------------------------------------------------------------------------

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


def _cmd_data_7scenes(args: argparse.Namespace) -> int:
    from lightfast.data.sevenscenes import convert_7scenes

    path = convert_7scenes(args.src, args.out, first=args.first, count=args.count, rate_hz=args.rate,
                           overwrite=args.overwrite, progress=sys.stderr.isatty())
    print(f"wrote {path}")
    return 0


def _cmd_config_write(args: argparse.Namespace) -> int:
    from lightfast.nodes import write_node_configs

    stale = write_node_configs(Path(args.dir), check=args.check)
    if args.check and stale:
        print("out of date (run `lightfast config write`): " + ", ".join(map(str, stale)), file=sys.stderr)
        return EXIT_ERROR
    return 0


def _cmd_daylight_prepare(args: argparse.Namespace) -> int:
    from lightfast.config import config_from_mapping
    from lightfast.daylight.lighting_map import LightingMapConfig, prepare_lighting_map
    from lightfast.daylight.mesh import load_ply
    from lightfast.daylight.openings import load_openings
    from lightfast.daylight.sun import Site

    overrides = {k: v for k, v in (("patch_size_m", args.patch_size), ("normal_merge_deg", args.normal_merge),
                                   ("sky_directions", args.sky_directions),
                                   ("sun_samples", args.sun_samples), ("iterations", args.iterations))
                 if v is not None}
    config = config_from_mapping(LightingMapConfig, overrides)
    mesh = load_ply(args.mesh)
    site = Site.from_yaml(args.site)
    openings = load_openings(args.openings) if args.openings else None
    start = time.monotonic()
    lmap = prepare_lighting_map(mesh, site, config, openings=openings, progress=sys.stderr.isatty())
    path = lmap.save(args.out, overwrite=args.overwrite)
    size_mb = sum(p.stat().st_size for p in Path(path).iterdir()) / 1e6
    print(f"wrote {path}: {mesh.num_vertices} vertices, {lmap.patches.count} patches, {size_mb:.1f} MB, "
          f"{time.monotonic() - start:.1f} s")
    return 0


def _cmd_daylight_sun(args: argparse.Namespace) -> int:
    import datetime as dt

    from lightfast.daylight.sun import Site, sun_position

    site = Site.from_yaml(args.site)
    try:
        when = dt.datetime.fromisoformat(args.time) if args.time else dt.datetime.now(dt.UTC)
    except ValueError as exc:
        raise LightfastError(f"bad --time {args.time!r}: {exc} (use ISO 8601 with an offset)") from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=site.zone)
    sun = sun_position(site, when)
    d = sun.direction_map
    print(f"{when.isoformat()}: azimuth {float(sun.azimuth_deg):.4f}°, elevation {float(sun.elevation_deg):.4f}°, "
          f"direction in map ({d[0]:.5f}, {d[1]:.5f}, {d[2]:.5f})" + ("" if sun.above_horizon else ", below horizon"))
    return 0


def _add_passthrough(subparsers: argparse._SubParsersAction, name: str, target: str, help_text: str) -> None:
    """A subcommand whose arguments go to ``target`` ("module:function(argv) -> exit code"), which parses them."""
    p = subparsers.add_parser(name, add_help=False, prefix_chars="\0", help=help_text)
    p.add_argument("rest", nargs=argparse.REMAINDER)

    def run_target(args: argparse.Namespace) -> int:
        module, _, function = target.partition(":")
        return getattr(importlib.import_module(module), function)(args.rest)

    p.set_defaults(func=run_target)


def _cmd_wait_ready(args: argparse.Namespace) -> int:
    from lightfast.ros.ready import process_alive, wait_ready
    from lightfast.ros.runtime import ros_session

    pids = tuple(args.pid or ())
    with ros_session("lightfast_wait_ready", domain_id=args.domain_id, install_signal_handlers=False) as (node, ex):
        wait_ready(node, ex, args.nodes, timeout_s=args.timeout, alive=lambda: all(map(process_alive, pids)))
    return 0


def _cmd_dds_env(args: argparse.Namespace) -> int:
    from lightfast.ros import transport

    if not args.network:
        given = [flag for flag, value in (("--hosts", args.hosts), ("--interface", args.interface),
                                          ("--udp-only", args.udp_only)) if value]
        if given:
            raise LightfastError(f"{' and '.join(given)} only go with --network")
        print("\n".join(transport.shell_lines(transport.local_transport_env(), transport.LOCAL_UNSET)))
        return 0
    env = transport.network_transport_env(args.hosts or (), args.interface or (), udp_only=args.udp_only)
    if missing := transport.unresolved_hosts(args.hosts or ()):
        raise LightfastError(f"cannot resolve {', '.join(missing)} to an IPv4 address (the nodes would not start: "
                             "rmw_fastrtps resolves ROS_STATIC_PEERS when it creates a node)")
    for name in transport.unknown_interfaces(args.interface or ()):
        print(f"lightfast: warning: {name} is no interface or IPv4 address of this machine; Fast DDS uses only "
              "the whitelisted ones that exist (loopback if none)", file=sys.stderr)
    unset = transport.NETWORK_UNSET if args.hosts else (*transport.NETWORK_UNSET, transport.PEERS_ENV)
    print(f"# {transport.describe_transport(transport.apply_env(os.environ, env, unset))}")
    print("\n".join(transport.shell_lines(env, unset)))
    return 0


# --- parser ---------------------------------------------------------------------------------------------------

def _optional_float(default: float) -> dict[str, object]:
    return dict(nargs="?", type=float, const=default, default=None, metavar="VALUE")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lightfast", description="lightfast: bag tools, datasets and node configuration."
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    bag = sub.add_parser("bag", help="inspect, play, record and compare rosbag2 bags (MCAP, sqlite3)")
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

    data = sub.add_parser("data", help="convert public datasets into bags")
    data_sub = data.add_subparsers(dest="data_command", required=True, metavar="DATASET")
    p = data_sub.add_parser("7scenes", help="7-Scenes RGB-D frames with ground-truth poses to an MCAP bag")
    p.add_argument("src", help="folder with frame-NNNNNN.{color.jpg,depth.png,pose.txt} and camera-intrinsics.txt")
    p.add_argument("out", help="bag directory to create")
    p.add_argument("--first", type=int, default=0, help="position of the first frame to convert (default 0)")
    p.add_argument("--count", type=int, default=None, help="number of frames (default all)")
    p.add_argument("--rate", type=float, default=30.0, help="frame rate of the stamps in Hz (default 30)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing bag")
    p.set_defaults(func=_cmd_data_7scenes)

    config = sub.add_parser("config", help="node parameter files")
    config_sub = config.add_subparsers(dest="config_command", required=True, metavar="CONFIG_COMMAND")
    p = config_sub.add_parser("write", help="regenerate config/<node>.yaml from the config dataclasses")
    p.add_argument("--dir", default=str(Path(__file__).resolve().parent.parent / "config"), help="output folder")
    p.add_argument("--check", action="store_true", help="only check that the files are up to date")
    p.set_defaults(func=_cmd_config_write)

    daylight = sub.add_parser("daylight", help="daylight illumination: sun position, lighting maps")
    daylight_sub = daylight.add_subparsers(dest="daylight_command", required=True, metavar="DAYLIGHT_COMMAND")
    p = daylight_sub.add_parser("prepare", help="build a lighting map (patches, transport, sky and ground radiosity)")
    p.add_argument("mesh", help="PLY mesh with per-vertex reflectance (red green blue in [0,1])")
    p.add_argument("site", help="site YAML (latitude_deg, longitude_deg, altitude_m, heading_deg, timezone)")
    p.add_argument("out", help="lighting map directory to create")
    p.add_argument("--patch-size", type=float, help="patch edge length in metres (default 0.1)")
    p.add_argument("--normal-merge", type=float, help="face-normal bins within this many degrees form one patch "
                   "inside a cell (default 30; 0 keeps every 10° bin apart)")
    p.add_argument("--sky-directions", type=int, help="directional lights over the sphere (default 2048)")
    p.add_argument("--sun-samples", type=int, help="directions inside the solar disk (default 8)")
    p.add_argument("--iterations", type=int, help="Jacobi iterations of Eq. 2 (default: until converged)")
    p.add_argument("--openings", help="YAML of the room's window openings: outdoor light then enters only through "
                   "them, not through holes of a reconstructed mesh (format: lightfast.daylight.openings)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing map")
    p.set_defaults(func=_cmd_daylight_prepare)
    p = daylight_sub.add_parser("sun", help="sun position at a site and time")
    p.add_argument("site", help="site YAML")
    p.add_argument("--time", help="ISO 8601 time (default now); without an offset the site's time zone is used")
    p.set_defaults(func=_cmd_daylight_sun)

    sim = sub.add_parser("sim", help="simulators that write recordings with ground truth")
    sim_sub = sim.add_subparsers(dest="sim_command", required=True, metavar="SIMULATOR")
    _add_passthrough(sim_sub, "daylight", "lightfast.sim.daylight_recordings:main_sim_daylight",
                     "indoor daylight RGB-D sequences DS1.T1-T6, DS2.T1-T6 (see `sim daylight --help`)")
    _add_passthrough(sim_sub, "racr", "lightfast.sim.racr_scenes:main_sim_racr",
                     "20 textured relocalization scenes with reference observations (see `sim racr --help`)")
    _add_passthrough(sim_sub, "vtr", "lightfast.sim.vtr_recordings:main_sim_vtr",
                     "spectral outdoor stereo route: teach and day-long repeats (see `sim vtr --help`)")
    crf = sub.add_parser("crf", help="camera response function")
    crf_sub = crf.add_subparsers(dest="crf_command", required=True, metavar="CRF_COMMAND")
    _add_passthrough(crf_sub, "calibrate", "lightfast.daylight.crf:main_crf_calibrate",
                     "fit the camera response from an exposure bracket (see `crf calibrate --help`)")

    ev = sub.add_parser("eval", help="evaluations that reproduce the papers' tables")
    ev_sub = ev.add_subparsers(dest="eval_command", required=True, metavar="EVALUATION")
    _add_passthrough(ev_sub, "daylight", "lightfast.eval.daylight:main_eval_daylight",
                     "Table I: the tracker and its ablations on the daylight recordings (see `eval daylight --help`)")
    _add_passthrough(ev_sub, "racr", "lightfast.eval.racr:main_eval_racr",
                     "rACR vs ACR and its ablations on the simulated scenes, Tables 2/4/5 (see `eval racr --help`)")
    _add_passthrough(ev_sub, "vtr", "lightfast.eval.vtr:main_eval_vtr",
                     "VT&R Table I / Fig. 7: autonomy by distance over the simulated day (see `eval vtr --help`)")
    _add_passthrough(ev_sub, "recording", "lightfast.eval.recording:main_eval_recording",
                     "score a recorded live run of the tracking nodes against the played bag's ground truth")

    p = sub.add_parser("wait-ready", help="wait until lightfast nodes announce that they can take data (for "
                       "launch-free scripts; exit 1 on timeout or when a --pid process ends first)")
    p.add_argument("nodes", nargs="+", metavar="NODE", help="node names, e.g. rgbd_tracker_node")
    p.add_argument("--timeout", type=float, default=300.0, help="seconds to wait (default 300)")
    p.add_argument("--pid", type=int, action="append", help="fail as soon as this process ends (repeatable)")
    p.add_argument("--domain-id", type=int, default=None, help="DDS domain (default: ROS_DOMAIN_ID)")
    p.set_defaults(func=_cmd_wait_ready)

    dds = sub.add_parser("dds", help="DDS transport settings")
    dds_sub = dds.add_subparsers(dest="dds_command", required=True, metavar="DDS_COMMAND")
    p = dds_sub.add_parser(
        "env", help="print the export lines that run nodes by hand with lightfast's profile",
        description="Print shell lines for `eval \"$(lightfast dds env ...)\"`. Default: the local profile (shared "
        "memory + UDP on loopback, discovery LOCALHOST: this machine only). --network: the network profile "
        "(shared memory within a machine, UDP between machines, discovery SUBNET).")
    p.add_argument("--network", action="store_true",
                   help="run across machines: lightfast/ros/fastdds_network.xml, ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET")
    p.add_argument("--hosts", nargs="+", metavar="HOST",
                   help="with --network: also discover these machines by unicast (ROS_STATIC_PEERS; IPv4 or name)")
    p.add_argument("--interface", nargs="+", metavar="ADDR",
                   help="with --network: UDP only on these interfaces (IPv4 address or name; loopback is added); "
                   "writes a generated profile to ~/.cache/lightfast/dds/")
    p.add_argument("--udp-only", action="store_true",
                   help="with --network: no shared memory (containers that do not share /dev/shm); generated profile")
    p.set_defaults(func=_cmd_dds_env)
    return parser


def run(func: Callable[[argparse.Namespace], int], args: argparse.Namespace, *, prog: str = "lightfast") -> int:
    """Run a subcommand, mapping errors to one line on stderr and an exit code (also for the nodes' tools)."""
    debug = bool(os.environ.get("LIGHTFAST_DEBUG"))
    try:
        return int(func(args))
    except (LightfastError, OSError) as exc:  # bad input, missing or unreadable files
        if debug:
            raise
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:
        if debug:
            raise
        print(f"{prog}: internal error: {type(exc).__name__}: {exc} (set LIGHTFAST_DEBUG=1 for the traceback)",
              file=sys.stderr)
        return EXIT_INTERNAL


def main(argv: Sequence[str] | None = None) -> int:
    # Ctrl-C / SIGINT interrupts a command even when a script started it in the background (`cmd &` in a
    # non-interactive shell starts it with SIGINT ignored; the demos stop their processes with SIGINT)
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="lightfast: %(levelname)s: %(message)s")
    return run(args.func, args)


if __name__ == "__main__":
    sys.exit(main())
