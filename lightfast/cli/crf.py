"""``lightfast crf …``: the camera response function."""
from __future__ import annotations

import argparse
from pathlib import Path

NAME = "crf"
HELP = "camera response function"


def _cmd_crf_calibrate(args: argparse.Namespace) -> int:
    from lightfast.daylight.crf import calibrate_from_files

    if len(args.images) != len(args.exposures):
        args.parser.error(f"{len(args.images)} images but {len(args.exposures)} --exposures")
    calibrate_from_files(args.images, args.exposures, args.output, method=args.method, samples=args.samples,
                         smoothness=args.smoothness, exposure_s=args.exposure, gain=args.gain)
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """``lightfast crf`` and its subcommands."""
    crf = subparsers.add_parser(NAME, help=HELP)
    crf_sub = crf.add_subparsers(dest="crf_command", required=True, metavar="CRF_COMMAND")
    p = crf_sub.add_parser("calibrate", help="fit the camera response from an exposure bracket (see `crf calibrate "
                           "--help`)", description="Calibrate the camera response function from an exposure bracket "
                           "of a static scene (Debevec or Robertson, OpenCV).")
    p.add_argument("images", nargs="+", type=Path, help="images of the same static scene (8-bit colour)")
    p.add_argument("--exposures", nargs="+", type=float, required=True, metavar="T",
                   help="exposure time of each image in seconds, in the same order")
    p.add_argument("-o", "--output", type=Path, required=True, help="output YAML file")
    p.add_argument("--method", choices=("debevec", "robertson"), default="debevec")
    p.add_argument("--samples", type=int, default=70, help="Debevec sample points (default 70)")
    p.add_argument("--smoothness", type=float, default=10.0, help="Debevec smoothness λ (default 10)")
    p.add_argument("--exposure", type=float, default=None,
                   help="exposure time to store for later use (default: the median of --exposures)")
    p.add_argument("--gain", type=float, default=1.0, help="gain to store (default 1)")
    p.set_defaults(func=_cmd_crf_calibrate, parser=p)
