"""``lightfast dds …``: DDS transport settings."""
from __future__ import annotations

import argparse
import os
import sys

from lightfast.errors import LightfastError

NAME = "dds"
HELP = "DDS transport settings"


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


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """``lightfast dds`` and its subcommands."""
    dds = subparsers.add_parser(NAME, help=HELP)
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
