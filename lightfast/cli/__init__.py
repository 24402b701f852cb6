"""``lightfast``: the command line. Each subcommand is a thin wrapper over a library function; each command group
is a module of this package (``bag``, ``data``, ``config``, ``daylight``, ``sim``, ``crf``, ``eval``, ``ready``
for ``wait-ready``, ``dds``, ``racr``, ``vtr``) with ``NAME``, ``HELP``, ``add_parser(subparsers)`` and its
``_cmd_*`` functions, which import what they need when they run (``lightfast --help`` and the commands without ROS
load no rclpy).

Exit codes: 0 success; 1 a lightfast error (one line on stderr, no traceback; ``LIGHTFAST_DEBUG=1`` shows it);
2 bad usage; 3 an unexpected internal error; 4 ``bag compare`` found differences; 5 ``bag play`` skipped corrupt
chunks of the bag (one warning line; ``--skip-corrupt`` accepts that and exits 0) or ``bag info --check`` found
some; 130 interrupted.
"""
from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from collections.abc import Collection, Sequence
from types import ModuleType

from lightfast.cli import bag, config, crf, data, daylight, dds, racr, ready, sim, vtr
from lightfast.cli import eval as evaluation
from lightfast.cli.common import run

__all__ = ["GROUPS", "build_parser", "main"]

#: The command groups, in the order ``lightfast --help`` lists them.
GROUPS: tuple[ModuleType, ...] = (bag, data, config, daylight, sim, crf, evaluation, ready, dds, racr, vtr)


def build_parser(groups: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The parser of ``lightfast``. Only the command groups named in ``groups`` (default: all) get their subcommands
    and options, the others just their name and help line: building ``sim`` or ``eval`` imports their library
    modules (numpy, scipy, OpenCV: about a second), which the other commands should not wait for."""
    parser = argparse.ArgumentParser(
        prog="lightfast", description="lightfast: bag tools, datasets and node configuration."
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for group in GROUPS:
        if groups is None or group.NAME in groups:
            group.add_parser(sub)
        else:
            sub.add_parser(group.NAME, help=group.HELP)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``lightfast`` with ``argv`` (default: the process's arguments); returns the exit code."""
    # Ctrl-C / SIGINT interrupts a command even when a script started it in the background (`cmd &` in a
    # non-interactive shell starts it with SIGINT ignored; the demos stop their processes with SIGINT)
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
    argv = sys.argv[1:] if argv is None else list(argv)
    group = [a for a in argv if not a.startswith("-")][:1]  # the first word: no global option takes a value
    args = build_parser(group).parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="lightfast: %(levelname)s: %(message)s")
    return run(args.func, args)
