"""Tracking when a busy node drops frames: the constant-velocity prediction scaled to each frame's interval against
the last motion as it is (the prediction of DVO and ORB-SLAM), in the same run.

A node that cannot keep up with its camera (``benchmarks/results/daylight_pipeline.md``: 640×480 at 15 fps on a
2-core machine) tracks only some frames, so the intervals between the frames it aligns vary. Here the §IV-C protocol
(``lightfast.eval.daylight.run_sequence``: f2f, relight, f2m, a reset to the truth after a loss, mode ``proposed``)
runs on a daylight recording with each frame after the first left out with probability ``--drop`` (seeds
``--seeds``; :class:`lightfast.eval.daylight_inputs.InputChange`), once per ``motion_prior`` of
:class:`lightfast.tracking.pipeline.TrackerConfig`. Without drops both priors give the same poses (a check).

Development data: the demo's recording DS1.T6 (``scripts/demo.sh``'s ``LIGHTFAST_OUT``, at each ``--sizes``); no
setting was chosen on it. Prints a markdown table, writes ``benchmarks/results/tracking_drops.{md,json}``.

Usage: ``.venv/bin/python benchmarks/tracking_drops.py --out DIR [--sizes 320x240 640x480] [--drop 0.2 0.4 0.6]``
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lightfast.daylight.lighting_map import LightingMap
from lightfast.eval.daylight import pooled, run_sequence, sequence_sun_radiosity
from lightfast.eval.daylight_inputs import InputChange
from lightfast.eval.machine import describe_machine
from lightfast.io import write_text_atomic
from lightfast.tracking.pipeline import TrackerConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from daylight_pipeline import RESULTS, demo_lighting_map, demo_sim

PRIORS = ("constant-velocity", "last-motion")


def one_run(sim: Path, lmap: LightingMap, sun_B: NDArray[np.float32], prior: str, drop: float, seed: int) -> dict:
    run = run_sequence(sim / "DS1.T6", lmap, "proposed", progress=False, sun_B=sun_B,
                       tracker_config=TrackerConfig(motion_prior=prior), inputs=InputChange(drop_rate=drop,
                                                                                             drop_seed=seed))
    return {"prior": prior, "drop": drop, "seed": seed, "frames": len(run.frames), "losses": run.losses,
            "f2m": sum(f.source == "f2m" for f in run.frames), "rmse_cm": pooled([run])["rmse_cm"],
            "T_est": [T.tolist() for T in run.T_est]}


def markdown(rows: list[dict], args: argparse.Namespace, same_without_drops: dict[str, bool]) -> str:
    lines = [
        "# Tracking when a busy node drops frames",
        "",
        f"`benchmarks/tracking_drops.py`: DS1.T6 (the demo's recording, development data), the §IV-C protocol "
        f"(f2f, relight, f2m, mode `proposed`, reset to the truth after a loss), each frame after the first left "
        f"out with the given probability (seeds {', '.join(map(str, args.seeds))}); `motion_prior` "
        f"`constant-velocity` scales the last motion to the frame's interval, `last-motion` starts at the last motion "
        f"as it is. Losses = frames > 10 cm or 10° off (then reset), summed over the seeds; RMSE over the other "
        f"frames, mean over the seeds.",
        "",
        "| size | frames dropped | motion_prior | frames tracked | losses | f2m | RMSE |",
        "|---|---:|---|---:|---:|---:|---:|",
    ]
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["size"], r["drop"], r["prior"]), []).append(r)
    for (size, drop, prior), rs in groups.items():
        frames = sum(r["frames"] for r in rs)
        lines.append(f"| {size} | {100 * drop:.0f} % | {prior} | {frames} | {sum(r['losses'] for r in rs)} | "
                     f"{100 * sum(r['f2m'] for r in rs) / frames:.0f} % | "
                     f"{np.nanmean([r['rmse_cm'] for r in rs]):.2f} cm |")
    lines += [
        "",
        "Without drops the two priors give the same poses: "
        + ", ".join(f"{size} {'yes' if same else '**no**'}" for size, same in same_without_drops.items()) + ".",
        "",
        f"Generated {dt.datetime.now(dt.UTC).isoformat(timespec='seconds')} on {describe_machine()}.",
    ]
    return "\n".join(lines) + "\n"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=Path.home() / ".cache" / "lightfast" / "bench-pipeline",
                   help="where scripts/demo.sh (LIGHTFAST_OUT) made the recordings and maps")
    p.add_argument("--sizes", nargs="+", default=["320x240", "640x480"])
    p.add_argument("--drop", type=float, nargs="+", default=[0.2, 0.4, 0.6])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    args = p.parse_args()
    rows, same = [], {}
    for size in args.sizes:
        sim = demo_sim(args.out, size)
        lmap = demo_lighting_map(sim)
        sun_B = sequence_sun_radiosity(sim / "DS1.T6", lmap)
        plain = [one_run(sim, lmap, sun_B, prior, 0.0, 0) for prior in PRIORS]
        same[size] = plain[0]["T_est"] == plain[1]["T_est"]
        for drop in [0.0, *args.drop]:
            for seed in [0] if drop == 0.0 else args.seeds:
                for prior in PRIORS:
                    r = plain[PRIORS.index(prior)] if drop == 0.0 else one_run(sim, lmap, sun_B, prior, drop, seed)
                    rows.append({**{k: v for k, v in r.items() if k != "T_est"}, "size": size})
                    print(f"{size} drop {drop:.1f} seed {seed} {prior}: {r['frames']} frames, {r['losses']} losses, "
                          f"RMSE {r['rmse_cm']:.2f} cm", flush=True)
    text = markdown(rows, args, same)
    print(text)
    write_text_atomic(RESULTS / "tracking_drops.md", text)
    write_text_atomic(RESULTS / "tracking_drops.json",
                      json.dumps({"runs": rows, "same_without_drops": same, "machine": describe_machine()}, indent=1)
                      + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
