"""``lightfast eval …``: the evaluations that reproduce the papers' tables, and the score of a recorded live run."""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from lightfast.cli.common import EXIT_USAGE
from lightfast.errors import LightfastError

NAME = "eval"
HELP = "evaluations that reproduce the papers' tables"


def _csv_list(text: str) -> list[str]:
    return [x for x in text.replace(" ", ",").split(",") if x]


def _cmd_eval_daylight(args: argparse.Namespace) -> int:
    from lightfast.eval.daylight import InputChange, evaluate_daylight

    methods = [m for m in args.methods.split(",") if m]
    sequences = [s for s in args.sequences.split(",") if s] or None
    tracker = None
    if args.params_file:
        from lightfast.config import load_config_yaml
        from lightfast.tracking.pipeline import TrackerConfig

        tracker = load_config_yaml(TrackerConfig, args.params_file, node_name="rgbd_tracker_node")
    runs = evaluate_daylight(args.sim_dir, args.out, methods=methods, sequences=sequences, maps_dir=args.maps,
                             max_frames=args.max_frames, progress=sys.stderr.isatty(), jobs=args.jobs,
                             tracker_config=tracker,
                             inputs=InputChange(frame_step=args.frame_step, depth_hole_grow_px=args.depth_hole_grow))
    print((args.out / "daylight_table.md").read_text(), end="")
    print(f"{len(runs)} runs; wrote {args.out}")
    return 0


def _cmd_eval_racr(args: argparse.Namespace) -> int:
    """Bad arguments the evaluation finds (an unknown method, lighting or scene) exit 2, as argparse errors do."""
    from lightfast.config import load_config_yaml
    from lightfast.eval.racr import RacrEvalConfig, evaluate_racr, run_convergence_study
    from lightfast.racr.node_config import RacrNodeConfig

    if args.convergence_condition:
        try:
            path = run_convergence_study(args.scenes_dir, args.out, args.convergence_condition,
                                         full_errors=[float(x) for x in _csv_list(args.full_errors)],
                                         lighting=(_csv_list(args.lighting) or ["varied"])[0])
        except (LightfastError, ValueError) as exc:
            print(f"lightfast eval racr: error: {exc}", file=sys.stderr)
            return EXIT_USAGE
        print(path.read_text(), end="")
        return 0
    try:
        scenes = [s for x in (args.scenes or []) for s in _csv_list(x)] or None
        config = RacrEvalConfig(job_cost=args.job_cost, eta=args.eta, handeye_error_deg=args.handeye_error_deg)
        node = load_config_yaml(RacrNodeConfig, args.params_file, node_name="racr_node") if args.params_file else None
        runs = evaluate_racr(args.scenes_dir, args.out, methods=_csv_list(args.methods), scenes=scenes,
                             lightings=_csv_list(args.lighting), repeats=args.repeats, config=config, node=node,
                             jobs=args.jobs, progress=not args.no_progress and sys.stderr.isatty(),
                             max_runs=args.max_runs)
    except (LightfastError, ValueError) as exc:
        print(f"lightfast eval racr: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    table = args.out / "racr_table.md"
    if table.exists():
        print(table.read_text(), end="")
    print(f"{len(runs)} runs recorded; wrote {args.out}")
    return 0


def _cmd_eval_vtr(args: argparse.Namespace) -> int:
    from lightfast.config import load_config_yaml, replace_config
    from lightfast.eval.vtr import evaluate_vtr
    from lightfast.vtr.localizer_config import VtrLocalizerConfig

    modes = [m for m in args.modes.split(",") if m]
    if args.max_frames is not None and args.max_frames < 1:
        args.parser.error("--max-frames must be >= 1")
    if args.jobs < 1:
        args.parser.error("--jobs must be >= 1")
    try:
        base = (load_config_yaml(VtrLocalizerConfig, args.params_file, node_name="vtr_localizer_node")
                if args.params_file else VtrLocalizerConfig())
        config = replace_config(base, {"teach.workers": args.workers, "repeat.workers": args.workers,
                                       "repeat.initial_keyframe": args.initial_keyframe})
    except LightfastError as exc:
        args.parser.error(str(exc))
    logging.getLogger(evaluate_vtr.__module__).setLevel(logging.INFO)  # one line per finished run
    results = evaluate_vtr(args.sim_dir, args.out, modes=modes, runs=args.runs, maps_dir=args.maps,
                           keep_dir=args.keep, config=config, max_frames=args.max_frames, jobs=args.jobs,
                           progress=sys.stderr.isatty() and not args.no_progress, force=args.force,
                           report_only=args.report_only)
    print((args.out / "vtr_table.md").read_text(), end="")
    print(f"{len(results)} (run, mode) results; wrote {args.out}")
    return 0


def _cmd_eval_recording(args: argparse.Namespace) -> int:
    from lightfast.eval.recording import play_windows, score_recording

    windows = play_windows(args.recorded)
    if len(windows) == 1:
        print(score_recording(args.recorded, args.truth).summary(), end="")
        return 0
    for i, window in enumerate(windows, 1):  # the bag was played several times: each play on its own
        print(f"== play {i} of {len(windows)}")
        print(score_recording(args.recorded, args.truth, window).summary(), end="")
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """``lightfast eval`` and its evaluations (imports their modules for the choices, defaults and descriptions)."""
    from lightfast.eval import daylight, recording
    from lightfast.eval.racr import METHODS as RACR_METHODS
    from lightfast.eval.racr import RacrEvalConfig
    from lightfast.vtr.repeat_config import MODES

    ev = subparsers.add_parser(NAME, help=HELP)
    ev_sub = ev.add_subparsers(dest="eval_command", required=True, metavar="EVALUATION")

    p = ev_sub.add_parser(
        "daylight", help="Table I: the tracker and its ablations on the daylight recordings (see `eval daylight "
        "--help`)", description=(daylight.__doc__ or "").split("\n\n")[0])
    p.add_argument("sim_dir", type=Path, help="directory of recordings made by `lightfast sim daylight`")
    p.add_argument("out", type=Path, help="output directory for the table, CSV, JSON and plots")
    p.add_argument("--methods", default=",".join(daylight.METHODS),
                   help=f"comma-separated subset of {', '.join(daylight.METHODS)}")
    p.add_argument("--sequences", default="", help="comma-separated recordings (default: all in SIM_DIR)")
    p.add_argument("--maps", type=Path, default=None, help="lighting map cache directory (default SIM_DIR/maps)")
    p.add_argument("--max-frames", type=int, default=None, help="evaluate only the first N frames of each recording")
    p.add_argument("--jobs", type=int, default=1, help="parallel worker processes (one recording x method each)")
    p.add_argument("--params-file", type=Path, default=None,
                   help="rgbd_tracker_node parameter file for the tracker (default: the node's defaults, "
                        "config/rgbd_tracker_node.yaml); each method then sets only its mode")
    p.add_argument("--frame-step", type=int, default=1,
                   help="what-if: track every k-th frame only (30/k Hz); default 1, the recording as it is")
    p.add_argument("--depth-hole-grow", type=int, default=0, metavar="PX",
                   help="what-if: grow every region without depth by PX pixels; default 0")
    p.set_defaults(func=_cmd_eval_daylight)

    p = ev_sub.add_parser(
        "racr", help="rACR vs ACR and its ablations on the simulated scenes, Tables 2/4/5 (see `eval racr --help`)",
        description="rACR vs ACR and the ablations on the simulated scenes (paper §5: Tables 2, 4, 5, Fig. 8, "
                    "Fig. 12(b)), in simulated time. Resumable: runs already recorded in OUT/runs are skipped.")
    p.add_argument("scenes_dir", type=Path, help="directory of scenes made by `lightfast sim racr`")
    p.add_argument("out", type=Path, help="output directory (runs/, racr_table.md, racr_runs.csv, racr_summary.json, "
                   "racr_parallel_serial.md, racr_convergence.png, racr_ablation.png)")
    p.add_argument("--methods", default=",".join(RACR_METHODS),
                   help=f"comma-separated subset of {', '.join(RACR_METHODS)}")
    p.add_argument("--scenes", nargs="*", default=None, metavar="NAME", help="scenes, e.g. S01 S14 (default all)")
    p.add_argument("--lighting", default="varied", help="comma-separated: similar, varied (default varied)")
    p.add_argument("--repeats", type=int, default=1, help="repeats per scene; repeat r>0 draws a new initial pose")
    p.add_argument("--jobs", type=int, default=1, help="parallel worker processes (one run each)")
    p.add_argument("--max-runs", type=int, default=None, help="do at most this many missing runs, then stop")
    p.add_argument("--job-cost", choices=("paper", "measured"), default="paper",
                   help="simulated alignment durations: the paper's (fast 0.2 s, fine 5 s) or measured CPU time")
    p.add_argument("--params-file", type=Path, default=None, metavar="YAML",
                   help="racr_node parameter file the rACR methods start from (default: the node's defaults, as in "
                   "config/racr_node.yaml); each method then changes only what it ablates")
    p.add_argument("--eta", type=float, default=RacrEvalConfig().eta,
                   help="stop threshold of g, replaces adjustment.eta (the simulated sensors cannot resolve 1e-4)")
    p.add_argument("--handeye-error-deg", type=float, default=0.0,
                   help="inject this rotation error into the estimated hand-eye X (section 3.7 study)")
    p.add_argument("--convergence-condition", metavar="SCENE", default=None,
                   help="instead of the evaluation: the section 3.7 study (hand-eye rotation errors 10..80 deg) on "
                   "SCENE, written to OUT/racr_convergence_condition.{md,json,png}")
    p.add_argument("--full-errors", default="",
                   help="with --convergence-condition: also run full rACR with these injected errors, e.g. 20,40,60")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_eval_racr)

    p = ev_sub.add_parser(
        "vtr", help="VT&R Table I / Fig. 7: autonomy by distance over the simulated day (see `eval vtr --help`)",
        description="Colour-constant VT&R on the simulated day schedule (paper §VI): teach once from the teach run, "
                    "repeat every repeat run in every mode through the node's pipeline, and report autonomy by "
                    "distance (Table I), the distance driven on VO (Fig. 7 CDFs) and the localization error against "
                    "the ground truth. Finished (run, mode) results are kept in OUT/runs and reused when started "
                    "again; the outputs are rewritten after every run.")
    p.add_argument("sim_dir", type=Path, help="directory written by `lightfast sim vtr` (a teach run + repeats)")
    p.add_argument("out", type=Path, help="output directory: vtr_table.md, vtr_runs.csv, vtr_frames.csv, "
                   "vtr_summary.json, vtr_cdf.png, vtr_cdf_fig7.png, vtr_inliers.png")
    p.add_argument("--modes", default=",".join(MODES), help=f"comma-separated subset of {', '.join(MODES)} "
                   "(default: all)")
    p.add_argument("--runs", nargs="+", metavar="NAME", help="repeat runs to evaluate (default: all in SIM_DIR)")
    p.add_argument("--maps", type=Path, default=None, help="teach map cache (default SIM_DIR/vtr_maps)")
    p.add_argument("--keep", type=Path, default=None, help="where finished (run, mode) results are kept for a "
                   "restart (default OUT/runs)")
    p.add_argument("--max-frames", type=int, default=None, help="evaluate only the first N frames of each repeat")
    p.add_argument("--jobs", type=int, default=1, help="parallel worker processes, one (run, mode) each (default 1)")
    p.add_argument("--workers", type=int, default=1, help="threads of each pipeline's stereo front end (default 1)")
    p.add_argument("--params-file", type=Path, default=None, metavar="YAML",
                   help="vtr_localizer_node parameter file to teach and repeat with (default: the node's defaults, as "
                   "in config/vtr_localizer_node.yaml); --workers, --initial-keyframe and each mode replace theirs")
    p.add_argument("--initial-keyframe", type=int, default=-1, help="keyframe where every repeat starts (default -1, "
                   "the node's default: search the whole map for the first localization; 0: the repeat starts at "
                   "the start of the taught path, as in a field trial)")
    p.add_argument("--force", action="store_true", help="re-evaluate (run, mode) pairs kept from an earlier call")
    p.add_argument("--report-only", action="store_true", help="evaluate nothing: write the outputs from the kept "
                   "results (missing (run, mode) pairs show as —)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_eval_vtr, parser=p)

    p = ev_sub.add_parser(
        "recording", help="score a recorded live run of the tracking nodes against the played bag's ground truth",
        description=(recording.__doc__ or "").split("\n\n")[0])
    p.add_argument("recorded", type=Path, help="bag recorded from the running nodes")
    p.add_argument("--truth", type=Path, required=True, help="the bag that was played (with ground truth poses)")
    p.set_defaults(func=_cmd_eval_recording)
