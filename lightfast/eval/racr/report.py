"""The outputs of the rACR evaluation (paper §5) from the records of one evaluation: :func:`write_outputs`.

All written atomically into ``OUT``:

- ``racr_table.md``: Tables 2/4 — mean AFD (px) per scene, method and lighting, failures (AFD ≥ 3 px) marked, and the
  per-method statistics of :func:`~lightfast.eval.racr.aggregate.summarize`;
- ``racr_parallel_serial.md``: Table 5 — serial vs parallel rACR on paired runs, simulated seconds;
- ``racr_runs.csv``: one row per run; ``racr_summary.json``: the protocol, the statistics and
  :func:`~lightfast.eval.racr.aggregate.done_means`;
- ``racr_convergence.png``: Fig. 8 — AFD (px) and the camera's true position error (mm) after each adjustment, rACR
  vs ACR; ``racr_ablation.png``: Fig. 12(b) — mean ± std AFD of rACR and its ablations on paired runs.
"""
from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lightfast.eval.racr.aggregate import common_runs, done_means, paired, summarize
from lightfast.eval.racr.protocol import (
    ABLATION,
    AFD_SUCCESS_PX,
    LABELS,
    LIGHTINGS,
    METHODS,
    RacrEvalConfig,
)
from lightfast.eval.racr.records import RunRecord
from lightfast.io import json_finite, write_text_atomic
from lightfast.racr.node_config import RacrNodeConfig


def fmt(x: float, nd: int = 2) -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else (
        "inf" if math.isinf(x) else f"{x:.{nd}f}")


def _pct(x: float) -> str:
    return "–" if math.isnan(x) else f"{100 * x:.0f} %"


def table_markdown(runs: Sequence[RunRecord]) -> str:
    """Table 2/4 style: mean AFD per scene (over repeats) per method and lighting, failures marked."""
    lines = ["# rACR evaluation (paper §5, Tables 2 and 4)", "",
             "Mean AFD (px) over the repeats; **bold ✗** marks a failure (AFD ≥ 3 px, the paper's criterion). "
             "Simulated time; see `docs/racr_evaluation.md` for the protocol.", ""]
    for lt in LIGHTINGS:
        rs = [r for r in runs if r.lighting == lt]
        if not rs:
            continue
        scenes = sorted({r.scene for r in rs})
        methods = [m for m in METHODS if any(r.method == m for r in rs)]
        lines += [f"## {lt} lighting", "", "| method | " + " | ".join(scenes) + " | success | median AFD |",
                  "|---|" + "---:|" * (len(scenes) + 2)]
        for m in methods:
            cells = []
            for s in scenes:
                v = [r.afd_px for r in rs if r.method == m and r.scene == s]
                if not v:
                    cells.append("")
                    continue
                mean = float(np.mean(v))
                cells.append(fmt(mean) if mean < AFD_SUCCESS_PX else f"**{fmt(mean)} ✗**")
            mr = [r for r in rs if r.method == m]
            rate = np.mean([r.success for r in mr])
            med = float(np.median([r.afd_px for r in mr]))
            lines.append(f"| {LABELS[m]} | " + " | ".join(cells) + f" | {100 * rate:.0f} % ({len(mr)}) | {fmt(med)} |")
        lines.append("")
    summ = summarize(runs)
    lines += ["## Per method", "", "| method | lighting | runs | success | median AFD | mean ± std AFD | adjustments "
              "| reported converged | failures it reported | successes it did not claim | loop time [s] | "
              "total time [s] |",
              "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for v in summ.values():
        lines.append(f"| {LABELS[v['method']]} | {v['lighting']} | {v['runs']} | {100 * v['success_rate']:.0f} % | "
                     f"{fmt(v['afd_median_px'])} | {fmt(v['afd_mean_px'])} ± {fmt(v['afd_std_px'])} | "
                     f"{v['adjustments_mean']:.1f} | {100 * v['converged_rate']:.0f} % | "
                     f"{_pct(v['self_reported_failure_rate'])} | {_pct(v['unclaimed_success_rate'])} | "
                     f"{v['time_loop_mean_s']:.1f} ± {v['time_loop_std_s']:.1f} | "
                     f"{v['time_total_mean_s']:.1f} ± {v['time_total_std_s']:.1f} |")
    return "\n".join(lines) + "\n"


def speed_markdown(runs: Sequence[RunRecord]) -> str:
    """Table 5 style: serial vs parallel rACR on the same (scene, lighting, repeat)."""
    pairs = paired(runs, "racr", "racr-serial")
    lines = ["# Parallel vs serial rACR (paper Table 5)", ""]
    if not pairs:
        return "\n".join(lines + ["No paired runs yet.", ""])

    def col(idx: int, attr: str) -> NDArray[np.float64]:
        return np.array([getattr(pr[idx], attr) for pr in pairs], dtype=np.float64)

    lines += [f"{len(pairs)} paired runs (same scene, lighting, initial pose and noise seeds). Simulated seconds "
              "(alignment jobs at the paper's durations unless the protocol says `job_cost: measured`). *Stop*: "
              "from the first VSE observation after initialization to the stop (g ≤ η, or the adjustment limit); "
              "*total* adds the initialization motions (identical for both); *to AFD < 3 px*: until the truth's AFD "
              "first fell below 3 px (pairs where both got there).", "",
              "| scheme | stop mean [s] | stop std [s] | total mean [s] | total std [s] | to AFD < 3 px mean [s] | "
              "adjustments | stopped by g ≤ η | success |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    both = [i for i, (p, q) in enumerate(pairs) if math.isfinite(p.time_to_success_s)
            and math.isfinite(q.time_to_success_s)]
    for name, idx in (("serial rACR", 1), ("parallel rACR", 0)):
        loop, tot = col(idx, "time_loop_s"), col(idx, "time_total_s")
        tts = col(idx, "time_to_success_s")[both]
        lines.append(f"| {name} | {loop.mean():.1f} | {loop.std():.1f} | {tot.mean():.1f} | {tot.std():.1f} | "
                     f"{fmt(float(tts.mean()) if len(tts) else math.nan, 1)} | {col(idx, 'adjustments').mean():.1f} | "
                     f"{100 * col(idx, 'converged').mean():.0f} % | {100 * col(idx, 'success').mean():.0f} % |")
    ratio = col(1, "time_loop_s").mean() / col(0, "time_loop_s").mean()
    ratio_t = col(1, "time_total_s").mean() / col(0, "time_total_s").mean()
    text = f"Speed-up (serial / parallel mean): to the stop {ratio:.2f}×, total {ratio_t:.2f}×"
    if both:
        r_s = col(1, "time_to_success_s")[both].mean() / col(0, "time_to_success_s")[both].mean()
        text += f", to AFD < 3 px {r_s:.2f}× ({len(both)} pairs)"
    lines += ["", text + " (paper: 84.6 s / 59.5 s = 1.42×).", ""]
    return "\n".join(lines)


def _write_csv(path: Path, runs: Sequence[RunRecord]) -> None:
    buf = io.StringIO()
    w = csv.writer(buf)
    cols = ["scene", "kind", "lighting", "method", "repeat", "afd_px", "success", "afd_initial_px", "adjustments",
            "converged", "stop_reason", "time_loop_s", "time_init_s", "time_total_s", "time_to_success_s", "wall_s"]
    extra = ["scale_error_rel", "handeye_rotation_error_deg", "handeye_translation_error_mm", "fast_alignments",
             "fine_alignments", "alignment_failures", "sigma_p"]
    w.writerow(cols + extra)
    for r in runs:
        d = r.to_dict()
        w.writerow([d[c] for c in cols] + [r.details.get(c, "") for c in extra])
    write_text_atomic(path, buf.getvalue())


def _plots(out_dir: Path, runs: Sequence[RunRecord]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # Fig. 8: AFD and camera error per adjustment, rACR vs ACR
    conv = [r for r in runs if r.method in ("racr", "acr") and r.repeat == 0]
    if conv:
        fig, axes = plt.subplots(1, 2, figsize=(11, 4))
        colors = {"racr": "tab:blue", "acr": "tab:red"}
        for r in conv:
            idx = [p.index for p in r.trace]
            ls = "-" if r.lighting == "varied" else ":"
            axes[0].plot(idx, [max(p.afd_px, 1e-2) for p in r.trace], ls, color=colors[r.method], alpha=0.5, lw=1)
            axes[1].plot(idx, [max(p.position_error_mm, 1e-2) for p in r.trace], ls, color=colors[r.method],
                         alpha=0.5, lw=1)
        for m, c in colors.items():
            axes[0].plot([], [], color=c, label=LABELS[m])
        axes[0].plot([], [], "k-", label="varied lighting")
        axes[0].plot([], [], "k:", label="similar lighting")
        axes[0].axhline(AFD_SUCCESS_PX, color="k", lw=0.8, ls="--")
        axes[0].set(yscale="log", xlabel="adjustment", ylabel="AFD [px]", title="AFD after each adjustment")
        axes[1].set(yscale="log", xlabel="adjustment", ylabel="camera position error [mm]",
                    title="‖t̃_A − t_A^ref‖ (truth)")
        axes[0].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out_dir / "racr_convergence.png", dpi=110)
        plt.close(fig)
    # Fig. 12(b): ablation mean ± std AFD
    common = common_runs(runs, ABLATION)
    lights = [lt for lt in LIGHTINGS if any(r.lighting == lt for r in common)]
    if common:
        fig, ax = plt.subplots(figsize=(6, 3.8))
        x = np.arange(len(ABLATION))
        width = 0.8 / max(len(lights), 1)
        for j, lt in enumerate(lights):
            vals = [[r.afd_px for r in common if r.method == m and r.lighting == lt] for m in ABLATION]
            ax.bar(x + (j - (len(lights) - 1) / 2) * width, [np.mean(v) for v in vals],
                   yerr=[np.std(v) for v in vals], width=width, capsize=3,
                   label=f"{lt} lighting (n={len(vals[0])} each)")
        ax.set_xticks(x, [LABELS[m] for m in ABLATION])
        ax.axhline(AFD_SUCCESS_PX, color="k", lw=0.8, ls="--")
        ax.set(ylabel="AFD [px] (mean ± std)", title="rACR ablation (Fig. 12(b)), paired runs")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out_dir / "racr_ablation.png", dpi=110)
        plt.close(fig)


def write_outputs(out_dir: Path, records: Sequence[RunRecord], config: RacrEvalConfig, node: RacrNodeConfig) -> None:
    """(Re)write the table, CSV, JSON and plots of ``records`` into ``out_dir``."""
    runs = sorted(records, key=lambda r: (r.scene, r.lighting, list(METHODS).index(r.method), r.repeat))
    if not runs:
        return
    write_text_atomic(out_dir / "racr_table.md", table_markdown(runs))
    write_text_atomic(out_dir / "racr_parallel_serial.md", speed_markdown(runs))
    _write_csv(out_dir / "racr_runs.csv", runs)
    summary = {"config": config.to_dict(), "node": node.to_dict(), "runs": len(runs), "per_method": summarize(runs),
               "done_means": done_means(runs)}
    write_text_atomic(out_dir / "racr_summary.json",
                      json.dumps(json_finite(summary), indent=1, default=float, allow_nan=False) + "\n")
    _plots(out_dir, runs)

