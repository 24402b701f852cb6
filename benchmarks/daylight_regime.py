"""The regime of the simulated daylight recordings at the true pose: does colour (and the relit reference) matter?

Runs :mod:`lightfast.eval.daylight_regime` (what each measure is: its docstring) over recordings made by
``lightfast sim daylight`` and prints a markdown table (median [10 %, 90 %] per recording, then the shares of frames
with weak geometry, where colour matters, and with large sunlit depth loss); writes ``STEM.md`` and ``STEM.json``
(summaries and per-frame records).

Usage: ``.venv/bin/python benchmarks/daylight_regime.py SIM_DIR [--sequences A,B] [--max-frames N] [--out STEM]``
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_STEM = ROOT / "benchmarks" / "results" / "eval_daylight" / "regime"


def main(argv: list[str] | None = None) -> int:
    from lightfast.data.shared import shown_path
    from lightfast.eval.daylight_regime import (
        PHOTO_STRONG_RATIO,
        SUNLIT_LOSS_IMAGE_SHARE,
        WEAK_EIGEN_RATIO,
        analyze_recording,
        summarize,
        table_markdown,
    )
    from lightfast.eval.errors import DaylightEvalError
    from lightfast.io import json_finite, write_text_atomic

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sim_dir", type=Path, help="directory of `lightfast sim daylight` recordings")
    ap.add_argument("--sequences", default="", help="comma-separated recordings (default: all in SIM_DIR)")
    ap.add_argument("--max-frames", type=int, default=None, help="first N frames of each recording")
    ap.add_argument("--out", type=Path, default=DEFAULT_STEM, help="output stem: STEM.md and STEM.json")
    ap.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = ap.parse_args(argv)
    sim_dir: Path = args.sim_dir
    found = sorted(p.name for p in sim_dir.iterdir() if (p / "sequence.json").is_file()) if sim_dir.is_dir() else []
    wanted = [s for s in args.sequences.split(",") if s] or found
    missing = [s for s in wanted if s not in found]
    if missing or not wanted:
        print(f"error: recordings not found in {sim_dir}: {', '.join(missing) or 'none at all'}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    summaries, frames = {}, {}
    try:
        for name in wanted:
            regime = analyze_recording(sim_dir / name, max_frames=args.max_frames, progress=not args.no_progress)
            summaries[name], frames[name] = summarize(regime), regime
    except DaylightEvalError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    table = table_markdown(summaries)
    header = (f"# Daylight recordings at the true pose ({shown_path(sim_dir)}: {', '.join(wanted)}; "
              f"{'all' if args.max_frames is None else f'first {args.max_frames}'} frames)\n\n"
              f"Made by `benchmarks/daylight_regime.py` in {time.perf_counter() - t0:.0f} s. Measures: the docstring "
              f"of `lightfast/eval/daylight_regime.py`. Thresholds: weak direction below {WEAK_EIGEN_RATIO:g} λmax; "
              f"colour matters: weak geometry and E_C λmin/λmax ≥ {PHOTO_STRONG_RATIO:g}; colour fills the weak "
              f"directions: weak geometry and (E_C in E_G's weak directions, sensor noise's expected information "
              f"removed) / E_C λmax ≥ {PHOTO_STRONG_RATIO:g}; "
              f"large sunlit depth loss: > {100 * SUNLIT_LOSS_IMAGE_SHARE:g} % of the image sunlit without depth.\n\n")
    out: Path = args.out
    out.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out.with_name(out.name + ".md"), header + table)
    doc = {"sim_dir": shown_path(sim_dir), "sequences": wanted, "max_frames": args.max_frames,
           "summaries": summaries, "frames": {k: [asdict(f) for f in v] for k, v in frames.items()}}
    write_text_atomic(out.with_name(out.name + ".json"), json.dumps(json_finite(doc), indent=1) + "\n")
    print(table, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
