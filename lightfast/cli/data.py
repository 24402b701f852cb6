"""``lightfast data …``: convert public datasets into bags."""
from __future__ import annotations

import argparse
import sys

NAME = "data"
HELP = "convert public datasets into bags"


def _cmd_data_7scenes(args: argparse.Namespace) -> int:
    from lightfast.data.sevenscenes import convert_7scenes

    path = convert_7scenes(args.src, args.out, first=args.first, count=args.count, rate_hz=args.rate,
                           overwrite=args.overwrite, progress=sys.stderr.isatty())
    print(f"wrote {path}")
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """``lightfast data`` and its datasets."""
    data = subparsers.add_parser(NAME, help=HELP)
    data_sub = data.add_subparsers(dest="data_command", required=True, metavar="DATASET")
    p = data_sub.add_parser("7scenes", help="7-Scenes RGB-D frames with ground-truth poses to an MCAP bag")
    p.add_argument("src", help="folder with frame-NNNNNN.{color.jpg,depth.png,pose.txt} and camera-intrinsics.txt")
    p.add_argument("out", help="bag directory to create")
    p.add_argument("--first", type=int, default=0, help="position of the first frame to convert (default 0)")
    p.add_argument("--count", type=int, default=None, help="number of frames (default all)")
    p.add_argument("--rate", type=float, default=30.0, help="frame rate of the stamps in Hz (default 30)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing bag")
    p.set_defaults(func=_cmd_data_7scenes)
