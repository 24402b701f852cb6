"""``lightfast vtr …``: helpers around ``vtr_localizer_node`` for scripts (``scripts/vtr_demo.sh``), and ``calibrate``,
which fits the colour-constant weights of a camera from a fixed-camera time-lapse (:mod:`lightfast.vtr.calibration`)."""
from __future__ import annotations

import argparse
from pathlib import Path

NAME = "vtr"
HELP = "helpers around vtr_localizer_node for scripts; fit colour-constant weights (calibrate)"


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


def _cmd_vtr_calibrate(args: argparse.Namespace) -> int:
    from lightfast.vtr.calibration import CalibrationConfig, calibrate, load_timelapse
    from lightfast.vtr.color_constant import ColorConstantConfig
    from lightfast.vtr.stereo_config import StereoConfig

    _, images = load_timelapse(args.folder)
    lo, hi = args.alpha_range
    config = CalibrationConfig(rule=args.rule, alpha_min=lo, alpha_max=hi, max_pairs=args.pairs,
                               tolerance_px=args.tolerance)
    stereo = StereoConfig(feature=args.feature, max_features=args.max_features)
    r = calibrate(images, config, stereo=stereo, color=ColorConstantConfig(normalization=args.normalization),
                  source=str(args.folder))
    f, pv, pr = r.fitted, r.printed["fv"], r.printed["fr"]
    print(f"fitted on {args.folder}: {r.images} images, {r.pairs} pairs, {r.feature.upper()}, rule {r.rule}: "
          f"alpha {r.alpha:.3f}, beta {r.beta:.3f}: {f.correct_per_pair:.2f} correct matches per pair "
          f"(precision {100 * f.precision:.0f} %)")
    print(f"printed weights on the same pairs: F_v ({pv.alpha:g}, {pv.beta:g}) {pv.correct_per_pair:.2f} "
          f"({100 * pv.precision:.0f} %), F_r ({pr.alpha:g}, {pr.beta:g}) {pr.correct_per_pair:.2f} "
          f"({100 * pr.precision:.0f} %)")
    if r.on_range_end:
        print(f"note: the optimum is an end of the alpha range [{lo:g}, {hi:g}]; widen --alpha-range")
    if args.output:
        r.to_yaml(args.output)
        print(f"written {args.output}")
    return 0


def _alpha_range(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected MIN,MAX, e.g. -2,2, got {text!r}") from None
    return lo, hi


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
    p = vtr_sub.add_parser("calibrate", help="fit colour-constant weights (alpha, beta) from a fixed-camera time-lapse",
                           description="Fit the colour-constant weight alpha (beta by --rule) of a camera from a "
                           "folder of images of a fixed camera across lighting changes: the alpha whose image gives "
                           "the most correct feature matches per image pair (paper §IV-A, Eq. 10).")
    p.add_argument("folder", type=Path, metavar="DIR", help="images of one fixed camera (png, jpg, ...), one size")
    p.add_argument("-o", "--output", type=Path, metavar="OUT.yaml", help="write the result as YAML (atomically)")
    p.add_argument("--rule", default="eq10", choices=("eq10", "sum1"),
                   help="beta from alpha: eq10, the paper's Eq. 10 (default), or sum1, beta = 1 - alpha")
    p.add_argument("--alpha-range", type=_alpha_range, default=(-2.0, 2.0), metavar="MIN,MAX",
                   help="alpha search range (-2,2; write --alpha-range=-1,1 for a negative minimum)")
    p.add_argument("--pairs", type=int, default=200, help="image pairs scored per alpha (200; a seeded sample)")
    p.add_argument("--feature", default="orb", choices=("orb", "sift"), help="feature type (orb)")
    p.add_argument("--max-features", type=int, default=1000, help="features per image (1000)")
    p.add_argument("--normalization", default="fixed", choices=("fixed", "percentile"),
                   help="8-bit mapping of the colour-constant image (fixed)")
    p.add_argument("--tolerance", type=float, default=4.0, help="correct-match radius, px (4)")
    p.set_defaults(func=_cmd_vtr_calibrate)
