"""Tracking from a wrong start pose: large f2m corrections confirmed by agreeing frames (``f2m_confirm_frames``)
against always rejecting them, in the same run.

``rgbd_tracker_node`` rejects an f2m correction of T≈ beyond ``max_f2m_correction_m`` / ``_deg``. Once f2f has gone
off by more than that (a wrong ``initial_pose``, a blurred frame, a jump), every later T≈ is off by the same
map-frame transform and f2m's corrections, however right, would be rejected for good. Here the tracker starts at
the first frame's truth moved by a random offset (translation ``--offsets`` metres in a random direction, rotation
``--rotation-deg`` about a random axis; seeds ``--seeds``) and tracks the first ``--frames`` frames of a daylight
recording (f2f, relight, f2m, mode ``proposed``) without the §IV-C protocol's reset after a loss
(:func:`lightfast.eval.daylight.run_sequence` with ``reset_on_loss=False``), once with the default
``f2m_confirm_frames`` and once with 0. Without an offset both give the same poses (a check that the rule does not
act on a tracker that is on track).

Development data: the demo's recording DS1.T6 (``scripts/demo.sh``'s ``LIGHTFAST_OUT``); no setting was chosen on
it. Prints a markdown table, writes ``benchmarks/results/tracking_recovery.{md,json}``.

Usage: ``.venv/bin/python benchmarks/tracking_recovery.py --out DIR [--size 320x240] [--offsets 0.12 0.2 0.3]
[--seeds 1 2 3 4 5 6]``
"""
from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import json
import sys
from pathlib import Path

import numpy as np

from lightfast.eval.daylight import SequenceRun, run_sequence, sequence_sun_radiosity
from lightfast.eval.machine import describe_machine
from lightfast.geometry import make_transform, se3_exp
from lightfast.io import write_text_atomic
from lightfast.tracking.pipeline import TrackerConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from daylight_pipeline import RESULTS, demo_lighting_map, demo_sim


def start_offset(seed: int, offset_m: float, rotation_deg: float) -> np.ndarray:
    """A rigid offset (camera frame): ``offset_m`` along a random direction, ``rotation_deg`` about a random axis."""
    rng = np.random.default_rng(seed)
    t, axis = rng.normal(size=3), rng.normal(size=3)
    R = se3_exp(np.r_[0.0, 0.0, 0.0, np.radians(rotation_deg) * axis / np.linalg.norm(axis)])[:3, :3]
    return make_transform(R, offset_m * t / np.linalg.norm(t))


def summary(run: SequenceRun) -> dict:
    lost = [i for i, f in enumerate(run.frames) if f.lost]
    back = None if lost and lost[-1] == len(run.frames) - 1 else (lost[-1] + 1 if lost else 0)  # lost no more
    return {"frames": len(run.frames), "lost": sum(f.lost for f in run.frames), "back_at": back,
            "last_error_cm": 100 * run.frames[-1].t_err_m}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=Path.home() / ".cache" / "lightfast" / "bench-pipeline",
                   help="where scripts/demo.sh (LIGHTFAST_OUT) made the recording and map")
    p.add_argument("--size", default="320x240")
    p.add_argument("--frames", type=int, default=90)
    p.add_argument("--offsets", type=float, nargs="+", default=[0.12, 0.2, 0.3])
    p.add_argument("--rotation-deg", type=float, default=3.0)
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6])
    args = p.parse_args()
    sim = demo_sim(args.out, args.size)
    lmap = demo_lighting_map(sim)
    seq = sim / "DS1.T6"
    sun_B = sequence_sun_radiosity(seq, lmap)
    base = TrackerConfig()
    rules = {f"confirm {base.f2m_confirm_frames}": base, "reject (0)": dataclasses.replace(base, f2m_confirm_frames=0)}

    def one(cfg: TrackerConfig, offset: np.ndarray | None) -> SequenceRun:
        return run_sequence(seq, lmap, "proposed", max_frames=args.frames, progress=False, sun_B=sun_B,
                            tracker_config=cfg, T_truth_start=offset, reset_on_loss=False)

    plain = {name: one(cfg, None) for name, cfg in rules.items()}
    same = all(np.array_equal(a, b) for a, b in zip(*(r.T_est for r in plain.values()), strict=True))
    rows = []
    for offset_m in args.offsets:
        for seed in args.seeds:
            T_off = start_offset(seed, offset_m, args.rotation_deg)
            for name, cfg in rules.items():
                r = {"rule": name, "offset_m": offset_m, "seed": seed, **summary(one(cfg, T_off))}
                rows.append(r)
                print(r, flush=True)
    lines = [
        "# Tracking from a wrong start pose",
        "",
        f"`benchmarks/tracking_recovery.py`: DS1.T6 at {args.size} (the demo's recording, development data), first "
        f"{args.frames} frames, f2f + relight + f2m (`proposed`) without the reset after a loss; the tracker starts "
        f"at the first frame's truth moved by the offset in a random direction and {args.rotation_deg:g}° about a "
        f"random axis (seeds {', '.join(map(str, args.seeds))}). `confirm {base.f2m_confirm_frames}`: once "
        f"{base.f2m_confirm_frames} f2m corrections in a row beyond {100 * base.max_f2m_correction_m:g} cm / "
        f"{base.max_f2m_correction_deg:g}° agree, the next reference is rendered at the pose they give and f2m "
        f"against it confirms the pose or not (the default); `reject (0)`: a large correction is always rejected. "
        f"Lost = frames > 10 cm or 10° off (the §IV-C loss); back on track = the frame after the last lost one.",
        "",
        "| offset | rule | runs back on track | back at frame (median) | lost frames | last frame's error (median) |",
        "|---:|---|---:|---:|---:|---:|",
    ]
    for offset_m in args.offsets:
        for name in rules:
            rs = [r for r in rows if r["rule"] == name and r["offset_m"] == offset_m]
            backs = [r["back_at"] for r in rs if r["back_at"] is not None]
            at = f"{np.median(backs):.0f}" if backs else "–"
            lines.append(f"| {100 * offset_m:g} cm | {name} | {len(backs)} / {len(rs)} | {at} | "
                         f"{sum(r['lost'] for r in rs)} / {sum(r['frames'] for r in rs)} | "
                         f"{np.median([r['last_error_cm'] for r in rs]):.1f} cm |")
    lines += ["", f"Without an offset the two rules give the same poses: {'yes' if same else '**no**'}.", "",
              f"Generated {dt.datetime.now(dt.UTC).isoformat(timespec='seconds')} on {describe_machine()}."]
    text = "\n".join(lines) + "\n"
    print(text)
    write_text_atomic(RESULTS / "tracking_recovery.md", text)
    write_text_atomic(RESULTS / "tracking_recovery.json", json.dumps(
        {"runs": rows, "same_without_offset": same, "machine": describe_machine(), "args": vars(args) | {
            "out": str(args.out.name)}}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
