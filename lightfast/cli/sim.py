"""``lightfast sim …``: simulators that write recordings with ground truth."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from lightfast.cli.common import image_size

NAME = "sim"
HELP = "simulators that write recordings with ground truth"
log = logging.getLogger(__name__)


def _cmd_sim_daylight(args: argparse.Namespace) -> int:
    from lightfast.sim.daylight.recordings import generate_daylight_set

    if args.frames < 1:
        args.parser.error("--frames must be >= 1")
    w, h = args.size
    dirs = generate_daylight_set(args.out, sequences=args.sequences, frames=args.frames, width=w, height=h,
                                 progress=not args.no_progress, resolution_m=args.resolution,
                                 supersample=args.supersample, force=args.force)
    for d in dirs:
        log.info("wrote %s", d)
    return 0


def _cmd_sim_racr(args: argparse.Namespace) -> int:
    from lightfast.sim.racr import generate_racr_set

    if args.scenes is not None and not 1 <= args.scenes <= 20:
        args.parser.error("--scenes must be in 1..20")
    if args.resolution <= 0:
        args.parser.error("--resolution must be > 0")
    w, h = args.size
    dirs = generate_racr_set(args.out, scenes=args.only, count=args.scenes, width=w, height=h,
                             resolution_m=args.resolution, seed=args.seed, force=args.force,
                             progress=not args.no_progress, previews=not args.no_previews)
    for d in dirs:
        log.info("wrote %s", d)
    return 0


def _cmd_sim_vtr(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from lightfast.sim.vtr.camera import StereoRig
    from lightfast.sim.vtr.recordings import DriveConfig, generate_vtr_set, load_schedule
    from lightfast.sim.vtr.scene import RouteConfig

    if args.schedule and args.runs:
        args.parser.error("give --runs or --schedule, not both")
    if args.frames is not None and args.frames < 1:
        args.parser.error("--frames must be >= 1")
    if not args.length > 5.0:
        args.parser.error("--length must be > 5 m")
    w, h = args.size
    if w < 16 or h < 16:
        args.parser.error("--size must be at least 16x16")
    runs = load_schedule(args.schedule) if args.schedule else args.runs
    dirs = generate_vtr_set(
        args.out, runs=runs, route=replace(RouteConfig(), length_m=args.length, seed=args.scene_seed),
        rig=replace(StereoRig(), width=w, height=h),
        drive=replace(DriveConfig(), rate_hz=args.rate, speed_mps=args.speed, max_frames=args.frames),
        seed=args.seed, progress=not args.no_progress, force=args.force)
    for d in dirs:
        log.info("wrote %s", d)
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """``lightfast sim`` and its simulators (imports their modules for the choices and defaults)."""
    from lightfast.sim.daylight.sequences import HELDOUT_SEQUENCES, SEQUENCES
    from lightfast.sim.racr import DEFAULT_RESOLUTION_M
    from lightfast.sim.vtr.recordings import DEFAULT_RUNS, TABLE_I
    from lightfast.sim.vtr.scene import RouteConfig

    sim = subparsers.add_parser(NAME, help=HELP)
    sim_sub = sim.add_subparsers(dest="sim_command", required=True, metavar="SIMULATOR")

    p = sim_sub.add_parser(
        "daylight", help="indoor daylight RGB-D sequences DS1.T1-T6, DS2.T1-T6 (see `sim daylight --help`)",
        description="Render the simulated indoor daylight RGB-D sequences DS1.T1-T6 and DS2.T1-T6 (MCAP bags + "
                    "truth).")
    p.add_argument("out", type=Path, help="output directory")
    p.add_argument("--sequences", nargs="+", metavar="NAME", choices=[s.name for s in SEQUENCES + HELDOUT_SEQUENCES],
                   help="sequences to render (default: the 12 of Table I; the held-out DS3.H1-H5, DS2.H1-H3 of "
                        "issue 21 by name only)")
    p.add_argument("--frames", type=int, default=600, help="frames per sequence (30 Hz; default 600)")
    p.add_argument("--size", type=image_size("320x240"), default=(320, 240), help="image size WxH (default 320x240)")
    p.add_argument("--resolution", type=float, default=None, help="scene mesh resolution in m (default 0.02)")
    p.add_argument("--supersample", type=int, default=2, help="subpixels per axis (default 2)")
    p.add_argument("--force", action="store_true", help="re-render complete sequences")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_sim_daylight, parser=p)

    p = sim_sub.add_parser(
        "racr", help="20 textured relocalization scenes with reference observations (see `sim racr --help`)",
        description="Write the 20 simulated rACR scenes (paper §5.1): mesh, lighting variants, reference "
                    "observation and truth per scene.")
    p.add_argument("out", type=Path, help="output directory")
    p.add_argument("--scenes", type=int, default=None, metavar="N", help="only the first N scenes (S01..)")
    p.add_argument("--only", nargs="+", metavar="NAME", default=None, help="only these scenes, e.g. S03 S14")
    p.add_argument("--size", type=image_size("640x480"), default=(640, 480), help="image size WxH (default 640x480)")
    p.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION_M,
                   help=f"vertex step of detailed surfaces in m (default {DEFAULT_RESOLUTION_M})")
    p.add_argument("--seed", type=int, default=0, help="scene set seed (default 0)")
    p.add_argument("--force", action="store_true", help="rebuild complete scenes")
    p.add_argument("--no-previews", action="store_true", help="skip the preview images")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_sim_racr, parser=p)

    p = sim_sub.add_parser(
        "vtr", help="spectral outdoor stereo route: teach and day-long repeats (see `sim vtr --help`)",
        description="Render spectral outdoor stereo recordings for colour-constant visual teach & repeat: a "
                    "teach run at 10:50 in sun and repeats from sunrise to sunset on a sunny and a cloudy day "
                    "(MCAP bags + truth).")
    p.add_argument("out", type=Path, help="output directory")
    p.add_argument("--runs", nargs="+", metavar="NAME", choices=[r.name for r in TABLE_I],
                   help=f"runs of the paper's Table I (default: {' '.join(DEFAULT_RUNS)})")
    p.add_argument("--schedule", type=Path, metavar="FILE",
                   help="YAML list of runs {name, date, start, weather[, kind]} instead of --runs")
    p.add_argument("--length", type=float, default=300.0, help="route length in m (default 300)")
    p.add_argument("--size", type=image_size("640x480"), default=(640, 480), help="image size WxH (default 640x480)")
    p.add_argument("--rate", type=float, default=2.0, help="stereo frames per second (default 2)")
    p.add_argument("--speed", type=float, default=0.8, help="driving speed in m/s (default 0.8)")
    p.add_argument("--frames", type=int, default=None, help="at most this many frames per run")
    p.add_argument("--seed", type=int, default=0, help="seed of driving and noise (default 0)")
    p.add_argument("--scene-seed", type=int, default=RouteConfig.seed, help="seed of the scene")
    p.add_argument("--force", action="store_true", help="re-render complete runs")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_sim_vtr, parser=p)
