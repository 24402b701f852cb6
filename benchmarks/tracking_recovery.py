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

By default on the demo's recording DS1.T6 (``scripts/demo.sh``'s ``LIGHTFAST_OUT``; development data, no setting
was chosen on it), or on ``--sequences`` of a ``lightfast sim daylight`` directory ``--sim`` (a room of the user's
choice). Prints a markdown table, writes ``--output`` (default ``benchmarks/results/tracking_recovery.md``) and the
JSON beside it.

Usage: ``.venv/bin/python benchmarks/tracking_recovery.py --out DIR [--size 320x240] [--offsets 0.12 0.2 0.3]
[--seeds 1 2 3 4 5 6]``, or ``... --sim SIM --sequences DS3.H4 DS2.H2 --output FILE.md``
"""
from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import functools
import json
import sys
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lightfast.daylight.lighting_map import LightingMap
from lightfast.eval.daylight import SequenceRun, run_sequence, scene_lighting_map, scene_of, sequence_sun_radiosity
from lightfast.eval.machine import describe_machine
from lightfast.geometry import make_transform, se3_exp
from lightfast.io import write_text_atomic
from lightfast.tracking.pipeline import TrackerConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from daylight_pipeline import RESULTS, demo_lighting_map, demo_sim


def start_offset(seed: int, offset_m: float, rotation_deg: float) -> NDArray[np.float64]:
    """A rigid offset (camera frame): ``offset_m`` along a random direction, ``rotation_deg`` about a random axis."""
    rng = np.random.default_rng(seed)
    t, axis = rng.normal(size=3), rng.normal(size=3)
    R = se3_exp(np.r_[0.0, 0.0, 0.0, np.radians(rotation_deg) * axis / np.linalg.norm(axis)])[:3, :3]
    return make_transform(R, offset_m * t / np.linalg.norm(t))


def summary(run: SequenceRun) -> dict:
    lost = [i for i, f in enumerate(run.frames) if f.lost]
    back = None if lost and lost[-1] == len(run.frames) - 1 else (lost[-1] + 1 if lost else 0)  # lost no more
    return {"frames": len(run.frames), "lost": run.losses, "back_at": back,
            "last_error_cm": 100 * run.frames[-1].t_err_m}


def track(seq: Path, lmap: LightingMap, sun_B: NDArray[np.float32], frames: int, cfg: TrackerConfig,
          T_truth_start: NDArray[np.float64] | None) -> SequenceRun:
    """The first ``frames`` of ``seq`` tracked from the first frame's truth times ``T_truth_start``, no resets."""
    return run_sequence(seq, lmap, "proposed", max_frames=frames, progress=False, sun_B=sun_B, tracker_config=cfg,
                        T_truth_start=T_truth_start, reset_on_loss=False)


def recordings(args: argparse.Namespace) -> list[tuple[Path, LightingMap]]:
    """(recording directory, lighting map) of the demo's DS1.T6, or of ``--sequences`` in ``--sim``."""
    if args.sim is None:
        sim = demo_sim(args.out, args.size)
        return [(sim / "DS1.T6", demo_lighting_map(sim))]
    return [(args.sim / name, scene_lighting_map(scene_of(args.sim / name), args.sim, args.sim / "maps", True))
            for name in args.sequences]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=Path.home() / ".cache" / "lightfast" / "bench-pipeline",
                   help="where scripts/demo.sh (LIGHTFAST_OUT) made the recording and map")
    p.add_argument("--size", default="320x240", help="the demo recording's size")
    p.add_argument("--sim", type=Path, default=None,
                   help="instead of the demo's recording: a `lightfast sim daylight` directory ...")
    p.add_argument("--sequences", nargs="+", default=[], help="... and its recordings to run")
    p.add_argument("--frames", type=int, default=90)
    p.add_argument("--offsets", type=float, nargs="+", default=[0.12, 0.2, 0.3])
    p.add_argument("--rotation-deg", type=float, default=3.0)
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6])
    p.add_argument("--output", type=Path, default=RESULTS / "tracking_recovery.md",
                   help="markdown results (the JSON beside it)")
    args = p.parse_args()
    if args.sim is not None and not args.sequences:
        p.error("--sim needs --sequences")
    base = TrackerConfig()
    rules = {f"confirm {base.f2m_confirm_frames}": base, "reject (0)": dataclasses.replace(base, f2m_confirm_frames=0)}
    rows, same = [], {}
    for seq, lmap in recordings(args):
        sun_B = sequence_sun_radiosity(seq, lmap)
        one = functools.partial(track, seq, lmap, sun_B, args.frames)
        plain = [one(cfg, None).T_est for cfg in rules.values()]
        same[seq.name] = all(np.array_equal(a, b) for a, b in zip(*plain, strict=True))
        for offset_m in args.offsets:
            for seed in args.seeds:
                T_off = start_offset(seed, offset_m, args.rotation_deg)
                for name, cfg in rules.items():
                    r = {"recording": seq.name, "rule": name, "offset_m": offset_m, "seed": seed,
                         **summary(one(cfg, T_off))}
                    rows.append(r)
                    print(r, flush=True)
    names = ", ".join(same)
    data = "the demo's recording, development data" if args.sim is None else f"`{args.sim.name}`"
    lines = [
        "# Tracking from a wrong start pose",
        "",
        f"`benchmarks/tracking_recovery.py`: {names} ({data}), first "
        f"{args.frames} frames, f2f + relight + f2m (`proposed`) without the reset after a loss; the tracker starts "
        f"at the first frame's truth moved by the offset in a random direction and {args.rotation_deg:g}° about a "
        f"random axis (seeds {', '.join(map(str, args.seeds))}). `confirm {base.f2m_confirm_frames}`: once "
        f"{base.f2m_confirm_frames} f2m corrections in a row beyond {100 * base.max_f2m_correction_m:g} cm / "
        f"{base.max_f2m_correction_deg:g}° agree, the next reference is rendered at the pose they give and f2m "
        f"against it confirms the pose or not (the default); `reject (0)`: a large correction is always rejected. "
        f"Lost = frames > 10 cm or 10° off (the §IV-C loss); back on track = the frame after the last lost one. "
        f"Runs of all recordings together.",
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
    lines += ["", "Without an offset the two rules give the same poses: "
              + ", ".join(f"{n} {'yes' if ok else '**no**'}" for n, ok in same.items()) + ".", "",
              f"Generated {dt.datetime.now(dt.UTC).isoformat(timespec='seconds')} on {describe_machine()}."]
    text = "\n".join(lines) + "\n"
    print(text)
    write_text_atomic(args.output, text)
    write_text_atomic(args.output.with_suffix(".json"), json.dumps(
        {"runs": rows, "same_without_offset": same, "machine": describe_machine(), "args": vars(args) | {
            "out": args.out.name, "sim": None if args.sim is None else args.sim.name, "output": args.output.name}},
        indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
