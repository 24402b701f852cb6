"""Table I on the held-out daylight recordings (issue 21, point 5): the regime check at the truth, then the five
methods, as written down in benchmarks/results/HELDOUT.md before the recordings were rendered.

Recordings: a round of :data:`lightfast.sim.daylight.sequences.HELDOUT_ROUNDS` (default the last; never used in
development; do not tune on them). For each one, :func:`lightfast.eval.daylight_regime.regime_check` says from the
truth (no method involved) whether it is in the paper's regime. Then ``lightfast eval daylight``
(:func:`~lightfast.eval.daylight.evaluate_daylight`: the paper's protocol, the node's code path) runs the five methods
with two tracker configurations:

* ``node defaults``: the rgbd_tracker_node's defaults (the headline: what a user runs);
* ``paper-like``: no f2f prior and every converged f2m correction used whatever its size (the paper names neither
  safeguard; benchmarks/daylight_ablation_causes.py showed both hide the methods' differences).

    lightfast sim daylight SIM --sequences DS3.H4 DS3.H5 DS2.H2 DS2.H3
    .venv/bin/python benchmarks/daylight_heldout.py SIM --maps MAPS --jobs 2 [--round 2]

Writes ``OUT/heldout_summary.json`` (``methods``: per method ``rmse_cm`` and ``loss_pct`` pooled over the recordings
with the node defaults; the same per configuration, per recording and over the in-regime recordings; the regime
check per recording; the paper's Table I averages) and ``OUT/heldout_table.md`` (default OUT
``benchmarks/results/eval_daylight/heldout``; an earlier round: ``heldout_roundN_*``); keeps the evaluations in
``WORK/<configuration>/`` (resumable; default ``SIM/heldout``).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from daylight_ablation_causes import VARIANTS, _slug  # noqa: E402  (the script's folder is on sys.path)

from lightfast.eval.daylight import METHODS, SequenceRun, evaluate_daylight, pooled  # noqa: E402
from lightfast.tracking.pipeline import TrackerConfig  # noqa: E402

#: The headline and the causes benchmark's variant closest to the paper (no f2f prior, f2m's size check off).
CONFIGURATIONS: dict[str, TrackerConfig] = {
    "node defaults": VARIANTS["as recorded"][0],
    "paper-like": VARIANTS["no f2f prior + f2m unchecked"][0],
}
#: The paper's Table I, average row (RMSE cm over tracked frames, loss %); E_lin: §IV-D's text (loss only).
PAPER_AVERAGE = {"proposed": {"rmse_cm": 3.61, "loss_pct": 2.16}, "proposed-lin": {"loss_pct": 10.0},
                 "refl-f2m": {"rmse_cm": 4.99, "loss_pct": 31.98}, "depth-only": {"rmse_cm": 4.53, "loss_pct": 11.89},
                 "no-color-f2m": {"rmse_cm": 4.53, "loss_pct": 11.90}}


def _results(runs: list[SequenceRun], in_regime: set[str]) -> dict[str, Any]:
    per_method = {m: pooled([r for r in runs if r.method == m]) for m in METHODS}
    regime_runs = [r for r in runs if r.sequence in in_regime]
    return {
        "methods": per_method,
        "in_regime_recordings": {m: pooled([r for r in regime_runs if r.method == m]) for m in METHODS}
        if regime_runs else {},
        "per_recording": {s: {m: pooled([r for r in runs if r.sequence == s and r.method == m]) for m in METHODS}
                          for s in dict.fromkeys(r.sequence for r in runs)},
    }


def _cell(s: dict[str, float]) -> str:
    return f"{s['rmse_cm']:.2f} / {s['loss_pct']:.2f} % ({s['lost']})"


def _markdown(doc: dict[str, Any]) -> str:
    lines = [f"# Table I on the held-out daylight recordings, round {doc['round']} (issue 21, point 5)", "",
             "Recordings, regime and configurations were written in benchmarks/results/HELDOUT.md before the "
             "recordings were rendered; nothing was tuned on them. Cells: RMSE cm over tracked frames / tracking loss "
             "% (lost frames); the paper's protocol (more than 10 cm or 10° off: lost, reset to the truth).",
             f"`{doc['command']}` ({doc['seconds'] / 60:.0f} min)", "", "## Regime at the truth (no method involved)",
             "", "| recording | regime frames % | frames with large sunlit depth loss % | in the regime |",
             "|---|---|---|---|"]
    for s, r in doc["regime"].items():
        lines.append(f"| {s} | {100 * r['regime_frames']:.1f} | {100 * r['large_sunlit_depth_loss']:.1f} | "
                     f"{'yes' if r['in_regime'] else 'no'} |")
    for conf, res in doc["configurations"].items():
        lines += ["", f"## {conf}", "", "| recording | " + " | ".join(METHODS) + " |", "|---|" + "---|" * len(METHODS)]
        for s, per in res["per_recording"].items():
            lines.append(f"| {s} | " + " | ".join(_cell(per[m]) for m in METHODS) + " |")
        lines.append("| **all** | " + " | ".join(_cell(res["methods"][m]) for m in METHODS) + " |")
        if res["in_regime_recordings"]:
            lines.append("| in-regime recordings | " + " | ".join(_cell(res["in_regime_recordings"][m])
                                                                 for m in METHODS) + " |")
    paper = doc["paper_average"]
    lines += ["", "Paper, Table I average (real DS1/DS2): " + "; ".join(
        f"{m} " + " / ".join(f"{v:g}{' cm' if k == 'rmse_cm' else ' %'}" for k, v in paper[m].items())
        for m in METHODS)]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from lightfast.data.shared import shown_command
    from lightfast.eval.daylight_regime import analyze_recording, regime_check
    from lightfast.eval.errors import DaylightEvalError
    from lightfast.io import json_finite, write_text_atomic
    from lightfast.sim.daylight.sequences import HELDOUT_ROUNDS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sim_dir", type=Path, help="directory holding the held-out recordings (`lightfast sim daylight`)")
    ap.add_argument("--maps", type=Path, default=None, help="lighting map cache (default SIM_DIR/maps)")
    ap.add_argument("--work", type=Path, default=None, help="per-configuration evaluations (default SIM_DIR/heldout)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "eval_daylight" / "heldout")
    ap.add_argument("--jobs", type=int, default=1, help="parallel worker processes")
    last = max(HELDOUT_ROUNDS)
    ap.add_argument("--round", type=int, default=last, choices=sorted(HELDOUT_ROUNDS),
                    help=f"held-out round (default {last}, the current one)")
    args = ap.parse_args(argv)
    names = [s.name for s in HELDOUT_ROUNDS[args.round]]
    missing = [n for n in names if not (args.sim_dir / n / "sequence.json").is_file()]
    if missing:
        print(f"error: held-out recordings missing in {args.sim_dir}: {', '.join(missing)} (make them with "
              f"`lightfast sim daylight {args.sim_dir} --sequences {' '.join(names)}`)", file=sys.stderr)
        return 2
    work = args.work or args.sim_dir / "heldout"
    progress = sys.stderr.isatty()
    t0 = time.perf_counter()
    try:
        regime = {n: regime_check(analyze_recording(args.sim_dir / n, progress=progress)) for n in names}
        in_regime = {n for n, r in regime.items() if r["in_regime"]}
        print("regime: " + ", ".join(f"{n} {'yes' if r['in_regime'] else 'no'}" for n, r in regime.items()),
              flush=True)
        configurations = {}
        for conf, tracker in CONFIGURATIONS.items():
            runs = evaluate_daylight(args.sim_dir, work / _slug(conf), methods=tuple(METHODS), sequences=names,
                                     maps_dir=args.maps, jobs=args.jobs, progress=progress, tracker_config=tracker)
            configurations[conf] = {"tracker": tracker.to_dict(), **_results(runs, in_regime)}
            print(f"{conf}: " + ", ".join(f"{m} {s['rmse_cm']:.2f} cm {s['loss_pct']:.2f} %"
                                          for m, s in configurations[conf]["methods"].items()), flush=True)
    except DaylightEvalError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    command = shown_command("benchmarks/daylight_heldout.py", sys.argv[1:] if argv is None else argv)
    doc = {"command": command, "round": args.round, "seconds": time.perf_counter() - t0, "recordings": names,
           "specs": {s.name: asdict(s) for s in HELDOUT_ROUNDS[args.round]},
           "methods": configurations["node defaults"]["methods"],
           "regime": regime, "configurations": configurations, "paper_average": PAPER_AVERAGE}
    args.out.mkdir(parents=True, exist_ok=True)
    text = _markdown(doc)
    stem = "heldout" if args.round == last else f"heldout_round{args.round}"
    write_text_atomic(args.out / f"{stem}_table.md", text)
    write_text_atomic(args.out / f"{stem}_summary.json", json.dumps(json_finite(doc), indent=1) + "\n")
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
