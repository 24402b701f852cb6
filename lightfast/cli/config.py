"""``lightfast config …``: the node parameter files."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from lightfast.cli.common import EXIT_ERROR

NAME = "config"
HELP = "node parameter files"
#: ``config/`` and ``docs/parameters.md`` of the repository (the package's parent directory).
CONFIG_DIR = Path(__file__).resolve().parents[2] / "config"
DOCS_PATH = Path(__file__).resolve().parents[2] / "docs" / "parameters.md"


def _cmd_config_write(args: argparse.Namespace) -> int:
    from lightfast.nodes import write_node_configs

    stale = write_node_configs(Path(args.dir), docs_path=Path(args.docs) if args.docs else None, check=args.check)
    if args.check and stale:
        print("out of date (run `lightfast config write`): " + ", ".join(map(str, stale)), file=sys.stderr)
        return EXIT_ERROR
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """``lightfast config`` and its subcommands."""
    config = subparsers.add_parser(NAME, help=HELP)
    config_sub = config.add_subparsers(dest="config_command", required=True, metavar="CONFIG_COMMAND")
    p = config_sub.add_parser("write", help="regenerate config/<node>.yaml and docs/parameters.md from the config "
                              "dataclasses")
    p.add_argument("--dir", default=str(CONFIG_DIR), help="output folder of the YAML files")
    p.add_argument("--docs", default=str(DOCS_PATH), help="the parameter reference to write ('' for none)")
    p.add_argument("--check", action="store_true", help="only check that the files are up to date")
    p.set_defaults(func=_cmd_config_write)
