"""Does colour carry pose information in the f2m step, and does the relit reference give it more than the
reflectance reference? (issue 21, point 5: why proposed, refl-f2m and no-color-f2m do not separate here.)

On development recordings only. For every ``--step``-th frame the f2m step is started from the true pose moved by
a seeded perturbation (translation ``--shift-cm`` in a random direction and rotation ``--turn-deg`` about a random
axis: the error of T≈ that f2m must remove), the reference is rendered there by the daylight relighter (the nodes'
code: relit as proposed, reflectance scaled to the live brightness as refl-f2m), and the live frame is aligned to it
with the tracker's f2m configuration (node defaults) three ways: both terms of Eq. 7 (proposed / refl-f2m), the
geometric term alone (no-color-f2m, depth-only) and the photometric term alone. Reported per reference and term:
the remaining translation and rotation error against the truth (median, 90th percentile) and the share of frames
left beyond the evaluation's loss thresholds.

Reading: if colour alone brings the pose back from the relit reference but not from the reflectance one, and the
two terms together do as well as geometry alone, then geometry dominates f2m wherever it is well conditioned and the
ablation cannot separate without views where it is not.

    .venv/bin/python benchmarks/daylight_f2m_terms.py SIM_DIR --maps MAPS [--sequences A,B] [--step 10]

Writes ``OUT/f2m_terms_<shift>cm_<turn>deg.md`` and ``.json`` (default OUT:
``benchmarks/results/eval_daylight/heldout``).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lightfast.daylight.crf import load_crf  # noqa: E402
from lightfast.daylight.lighting_map import LightingMap  # noqa: E402
from lightfast.daylight.relight import DaylightRelighter, RelightConfig  # noqa: E402
from lightfast.eval.daylight import (  # noqa: E402
    LOSS_ROTATION_DEG,
    LOSS_TRANSLATION_M,
    recording_frames,
    sequence_files,
    sequence_sun_radiosity,
)
from lightfast.geometry import make_transform, rotation_angle_deg, so3_exp  # noqa: E402
from lightfast.tracking.errors import TrackingError  # noqa: E402
from lightfast.tracking.pipeline import TrackerConfig, f2m_rejection  # noqa: E402
from lightfast.tracking.rgbd_odometry import align_frames, prepare_frame  # noqa: E402

REFERENCES = ("relit", "reflectance")
#: term → (use_color, use_depth)
TERMS = {"both": (True, True), "geometry": (False, True), "colour": (True, False)}


def _perturbation(rng: np.random.Generator, shift_m: float, turn_deg: float) -> np.ndarray:
    axis_t, axis_r = rng.normal(size=3), rng.normal(size=3)
    return make_transform(so3_exp(np.radians(turn_deg) * axis_r / np.linalg.norm(axis_r)),
                          shift_m * axis_t / np.linalg.norm(axis_t))


def _errors(T_est: np.ndarray, T_gt: np.ndarray) -> tuple[float, float]:
    E = np.linalg.solve(T_gt, T_est)
    return float(np.linalg.norm(E[:3, 3])), float(rotation_angle_deg(E[:3, :3]))


def study(seq_dir: Path, lmap: LightingMap, *, step: int, shift_m: float, turn_deg: float, seed: int,
          max_frames: int | None = None) -> list[dict[str, Any]]:
    """One row per (frame, reference, term): start and final errors (module docstring)."""
    files = sequence_files(seq_dir)
    crf = load_crf(files["crf"])
    cfg = TrackerConfig()
    f2m = cfg.f2m_config
    relighters = {r: DaylightRelighter(lmap, crf, config=RelightConfig(reference=r)) for r in REFERENCES}
    sun_B = sequence_sun_radiosity(seq_dir, lmap)
    rng = np.random.default_rng(seed)
    rows: list[dict[str, Any]] = []
    for k, (stamp, rgb, depth_m, camera, T_gt) in enumerate(recording_frames(files["bag"], step=step,
                                                                             limit=max_frames)):
        i = k * step  # the frame's index in the recording
        T_start = T_gt @ _perturbation(rng, shift_m, turn_deg)
        live = prepare_frame(rgb, depth_m, camera, config=cfg, name=f"live {stamp}")
        start_t, start_r = _errors(T_start, T_gt)
        for ref_kind, relighter in relighters.items():
            if not relighter.ready:
                relighter.set_sun_radiosity(sun_B, stamp)
            ref = relighter.step(stamp, rgb, T_start, camera)
            ref_cam = camera if ref.depth_m.shape == camera.shape else camera.scaled(0.5)
            try:
                target = prepare_frame(ref.color, ref.depth_m, ref_cam, config=cfg, name=f"reference {stamp}")
            except TrackingError:
                continue
            for term, (use_color, use_depth) in TERMS.items():
                try:
                    res = align_frames(live, target, config=f2m, use_color=use_color, use_depth=use_depth)
                    t_err, r_err = _errors(T_start @ res.T_target_source, T_gt)
                    rejection = f2m_rejection(res, cfg)
                except TrackingError as exc:
                    t_err, r_err, rejection = start_t, start_r, str(exc)
                rows.append({"sequence": seq_dir.name, "frame": i, "reference": ref_kind, "term": term,
                             "start_t_m": start_t, "start_r_deg": start_r, "t_m": t_err, "r_deg": r_err,
                             "accepted": not rejection, "not_converged": rejection == "f2m did not converge"})
    return rows


def summarize(rows: list[dict[str, Any]]) -> dict[str, dict[str, dict[str, float]]]:
    out: dict[str, dict[str, dict[str, float]]] = {}
    for ref in REFERENCES:
        for term in TERMS:
            rs = [r for r in rows if r["reference"] == ref and r["term"] == term]
            if not rs:
                continue
            t = np.array([r["t_m"] for r in rs])
            a = np.array([r["r_deg"] for r in rs])
            ok = np.array([r["accepted"] for r in rs], dtype=bool)
            t_kept = np.where(ok, t, [r["start_t_m"] for r in rs])  # the tracker keeps T≈ when it rejects f2m
            a_kept = np.where(ok, a, [r["start_r_deg"] for r in rs])
            lost = (t_kept > LOSS_TRANSLATION_M) | (a_kept > LOSS_ROTATION_DEG)
            out.setdefault(ref, {})[term] = {
                "frames": len(rs), "accepted_pct": 100 * float(np.mean(ok)),
                "not_converged_pct": 100 * float(np.mean([r.get("not_converged", False) for r in rs])),
                "t_median_cm": 100 * float(np.median(t)), "t_p90_cm": 100 * float(np.percentile(t, 90)),
                "r_median_deg": float(np.median(a)), "r_p90_deg": float(np.percentile(a, 90)),
                "kept_t_median_cm": 100 * float(np.median(t_kept)),
                "kept_t_p90_cm": 100 * float(np.percentile(t_kept, 90)),
                "worse_than_start_pct": 100 * float(np.mean(t_kept > [r["start_t_m"] for r in rs])),
                "beyond_loss_pct": 100 * float(np.mean(lost))}
    return out


def _markdown(summary: dict[str, dict[str, dict[str, float]]], args: argparse.Namespace, sequences: list[str],
              command: str, seconds: float) -> str:
    lines = [
        "# f2m with each term of Eq. 7, from perturbed starts (issue 21, point 5; development recordings)",
        "",
        f"Recordings {', '.join(sequences)}, every {args.step}th frame; start: the true pose moved by "
        f"{args.shift_cm:g} cm and {args.turn_deg:g}° (random directions, seed {args.seed}); the tracker's f2m "
        f"configuration (node defaults); loss thresholds of the evaluation ({100 * LOSS_TRANSLATION_M:g} cm, "
        f"{LOSS_ROTATION_DEG:g}°). Made by `{command}` in {seconds:.0f} s.",
        "",
        "f2m's own result (raw) and what the tracker keeps: f2m's pose when it converged within "
        "max_f2m_correction (accepted), else T≈ (pipeline.f2m_rejection).",
        "",
        "| reference | term | frames | raw translation median / p90 [cm] | raw rotation median / p90 [°] | accepted "
        "(rejected: not converged) | "
        "kept translation median / p90 [cm] | kept worse than the start | kept beyond loss |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for ref, per in summary.items():
        for term, s in per.items():
            lines.append(f"| {ref} | {term} | {s['frames']} | {s['t_median_cm']:.2f} / {s['t_p90_cm']:.2f} | "
                         f"{s['r_median_deg']:.2f} / {s['r_p90_deg']:.2f} | {s['accepted_pct']:.0f} % "
                         f"({s['not_converged_pct']:.0f} %) | "
                         f"{s['kept_t_median_cm']:.2f} / {s['kept_t_p90_cm']:.2f} | "
                         f"{s['worse_than_start_pct']:.1f} % | {s['beyond_loss_pct']:.1f} % |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from lightfast.data.shared import shown_command
    from lightfast.io import json_finite, write_text_atomic

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sim_dir", type=Path, help="development recordings of `lightfast sim daylight`")
    ap.add_argument("--maps", type=Path, required=True, help="lighting maps prepared by `lightfast eval daylight`")
    ap.add_argument("--sequences", default="", help="comma-separated recordings (default: all in SIM_DIR)")
    ap.add_argument("--step", type=int, default=10, help="every STEP-th frame (default 10)")
    ap.add_argument("--shift-cm", type=float, default=3.0, help="start translation error, cm (default 3)")
    ap.add_argument("--turn-deg", type=float, default=1.5, help="start rotation error, degrees (default 1.5)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "eval_daylight" / "heldout")
    args = ap.parse_args(argv)
    if args.step < 1 or args.shift_cm < 0 or args.turn_deg < 0:
        ap.error("--step must be >= 1, --shift-cm and --turn-deg >= 0")
    wanted = [s for s in args.sequences.split(",") if s]
    seqs = [p for p in sorted(args.sim_dir.iterdir()) if (p / "sequence.json").exists()
            and (not wanted or p.name in wanted)]
    if not seqs:
        print(f"daylight_f2m_terms: no recordings in {args.sim_dir}", file=sys.stderr)
        return 1
    t0 = time.perf_counter()
    rows: list[dict[str, Any]] = []
    for seq in seqs:
        scene = json.loads((seq / "sequence.json").read_text())["sequence"]["scene"]
        lmap = LightingMap.load(args.maps / scene)
        rows += study(seq, lmap, step=args.step, shift_m=args.shift_cm / 100, turn_deg=args.turn_deg, seed=args.seed,
                      max_frames=args.max_frames)
        print(f"{seq.name}: {len(rows)} alignments so far", flush=True)
    summary = summarize(rows)
    command = shown_command("benchmarks/daylight_f2m_terms.py", sys.argv[1:] if argv is None else argv)
    text = _markdown(summary, args, [s.name for s in seqs], command, time.perf_counter() - t0)
    args.out.mkdir(parents=True, exist_ok=True)
    stem = f"f2m_terms_{args.shift_cm:g}cm_{args.turn_deg:g}deg"
    write_text_atomic(args.out / f"{stem}.md", text)
    write_text_atomic(args.out / f"{stem}.json", json.dumps(json_finite(
        {"command": command, "summary": summary, "rows": rows}), indent=1) + "\n")
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
