"""The outputs of the VT&R evaluation (paper §VI, Table I, Fig. 7) from the (run, mode) results so far.

:func:`write_outputs` writes, atomically, into ``OUT``:

- ``vtr_table.md``: Table I style — per repeat and mode the strict autonomy by distance (the published score beside
  it) and the longest distance on VO (m),
  the verdict on the goals (:func:`verdict`) and per run and mode the localized share, median inliers per source,
  localization error (cm) and time per frame (ms);
- ``vtr_runs.csv`` (one row per run and mode), ``vtr_frames.csv`` (per frame: inliers and matches per source,
  distance on VO, failure state, error) and ``vtr_summary.json``;
- ``vtr_cdf.png``: the CDF of the distance driven on VO (Fig. 7 style) for every repeat; ``vtr_cdf_fig7.png``: the
  same for repeats 4 and 7 as in the paper's figure, when evaluated;
- ``vtr_inliers.png``: inliers per source along the route (m, truth) — the diagnostic trace.
"""
from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Sequence
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

import numpy as np

from lightfast.eval.vtr.scoring import REPORTED_SOURCES, FrameRecord, RepeatRun, cdf, overall
from lightfast.io import json_finite, write_text_atomic

#: The runs of the paper's Fig. 7.
FIG7_RUNS = ("repeat04", "repeat07")


def _pct(x: float) -> str:
    if not math.isfinite(x):
        return "—"
    if x >= 1.0:
        return "100 %"
    return f"{100 * math.floor(x * 1000) / 1000:.1f} %" if x >= 0.99 else f"{100 * x:.1f} %"


def table_markdown(runs: Sequence[RepeatRun], modes: Sequence[str], run_order: Sequence[str]) -> str:
    """Table I style: one row per repeat, per mode the strict autonomy by distance, the published score (any
    localization counts) and the longest distance on VO."""
    by = {(r.run, r.mode): r for r in runs}
    lines = ["| Action | Day | Start | Summary | sun elevation | distance | "
             + " | ".join(f"{m}: strict autonomy [published] (max on VO)" for m in modes) + " |",
             "|---|---|---|---|---|---:|" + "---:|" * len(modes)]
    for name in run_order:
        present = [by[(name, m)] for m in modes if (name, m) in by]
        if not present:
            continue
        r0 = present[0]
        el = r0.summary()["sun_elevation_deg"]
        summ = r0.info.get("summary") or r0.info.get("weather") or ""
        cells = []
        for m in modes:
            r = by.get((name, m))
            cells.append("—" if r is None else
                         f"{_pct(r.strict_autonomy)} [{_pct(r.autonomy)}] ({r.max_vo_m:.1f} m)")
        lines.append(f"| {name} | {r0.info.get('date', '')} | {r0.info.get('start', '')} | {summ} | "
                     f"{el[0]:.0f}° → {el[1]:.0f}° | {r0.distance_m:.0f} m | " + " | ".join(cells) + " |")
    cells = []
    n_rows = len({r.run for r in runs})
    for m in modes:
        o = overall(runs, m)
        part = "" if o["runs"] == n_rows else f" [{o['runs']} of {n_rows} repeats]"
        cells.append("—" if not o["runs"] else
                     f"**{_pct(o['strict_autonomy'])}** [{_pct(o['autonomy'])}] ({o['max_vo_m']:.1f} m){part}")
    total = max((overall(runs, m)["distance_m"] for m in modes), default=0.0)
    lines.append(f"| **all repeats** | | | | | {total:.0f} m | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def details_markdown(runs: Sequence[RepeatRun], modes: Sequence[str], run_order: Sequence[str]) -> str:
    lines = ["| run | mode | frames | localized | failures | median inliers grey / F_v / F_r | error median / p95 "
             "(localized) | gross (> 1 m) | error p95 (all poses) | ms per frame |",
             "|---|---|---:|---:|---:|---|---:|---:|---:|---:|"]
    for name in run_order:
        for m in modes:
            r = next((x for x in runs if x.run == name and x.mode == m), None)
            if r is None:
                continue
            s = r.summary()
            ins = " / ".join("–" if s[f"inliers_{k}_median"] is None else f"{s[f'inliers_{k}_median']:.0f}"
                             for k in REPORTED_SOURCES)
            err = "—" if s["error_m_median"] is None else \
                f"{100 * s['error_m_median']:.1f} / {100 * s['error_m_p95']:.1f} cm"
            err_all = "—" if s["error_all_m_p95"] is None else f"{100 * s['error_all_m_p95']:.1f} cm"
            ms = "—" if s["ms_median"] is None else f"{s['ms_median']:.0f}"
            lines.append(f"| {name} | {m} | {s['frames']} | {100 * s['localized_share']:.1f} % | {s['failures']} | "
                         f"{ins} | {err} | {s['gross_localizations']} | {err_all} | {ms} |")
    return "\n".join(lines) + "\n"


def verdict(runs: Sequence[RepeatRun], modes: Sequence[str]) -> list[str]:
    """What the numbers say about the issue's goals (computed, never asserted)."""
    out = []
    if "fused" in modes and any(r.mode == "fused" for r in runs):
        o = overall(runs, "fused")
        out.append(f"Fused (paper's method): strict autonomy by distance {100 * o['strict_autonomy']:.2f} % "
                   f"(published score {100 * o['autonomy']:.2f} %) over {o['distance_m']:.0f} m of repeats "
                   f"({o['failures']} localization failures, {o['false_accepts_over_5m']} whole-map search places "
                   f"accepted > 5 m off, longest distance on VO {o['max_vo_m']:.1f} m, {o['gross_localizations']} "
                   f"gross localizations) — goal ≥ 99.9 % strict "
                   f"{'met' if o['strict_autonomy'] >= 0.999 else 'NOT met'}.")
    for m in modes:
        if m == "fused" or not any(r.mode == m for r in runs):
            continue
        o = overall(runs, m)
        failed = [r.run for r in runs if r.mode == m and r.failures > 0]
        n_rows = len({r.run for r in runs})
        part = "" if o["runs"] == n_rows else f" (evaluated on {o['runs']} of the {n_rows} repeats only)"
        out.append(f"{m}: strict autonomy by distance {100 * o['strict_autonomy']:.2f} % (published score "
                   f"{100 * o['autonomy']:.2f} %), {o['failures']} localization failures, "
                   f"{o['false_accepts_over_5m']} search places accepted > 5 m off{part}; repeats with a failure: "
                   f"{', '.join(failed) if failed else 'none'}.")
    return out


def _write_frames_csv(path: Path, runs: Sequence[RepeatRun]) -> None:
    buf = io.StringIO()
    names = [f.name for f in fields(FrameRecord)]
    w = csv.writer(buf)
    w.writerow(["run", "mode", *names])
    for r in runs:
        for f in r.frames:
            row = asdict(f)
            w.writerow([r.run, r.mode, *[f"{row[k]:.6g}" if isinstance(row[k], float) else row[k] for k in names]])
    write_text_atomic(path, buf.getvalue())


def _write_runs_csv(path: Path, runs: Sequence[RepeatRun]) -> None:
    buf = io.StringIO()
    rows = [r.summary() for r in runs]
    if rows:
        keys = [k for k in rows[0] if k != "sun_elevation_deg"]
        w = csv.writer(buf)
        w.writerow(keys)
        for s in rows:
            w.writerow(["" if s[k] is None else (f"{s[k]:.6g}" if isinstance(s[k], float) else s[k]) for k in keys])
    write_text_atomic(path, buf.getvalue())


_MODE_STYLE = {"fused": ("tab:green", "fused (ours, paper)"), "grey": ("0.4", "grey (Furgale 2010 [6])"),
               "mcmanus": ("tab:red", "mcmanus (McManus 2014 [10])")}


def _plot_cdfs(path: Path, runs: Sequence[RepeatRun], names: Sequence[str], limit_m: float, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by = {(r.run, r.mode): r for r in runs}
    ncol = min(3, len(names))
    nrow = math.ceil(len(names) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(max(4.6 * ncol, 8.0), 3.4 * nrow), squeeze=False)
    for ax, name in zip(axes.flat, names, strict=False):
        xmax = limit_m * 1.5
        for mode, (color, label) in _MODE_STYLE.items():
            r = by.get((name, mode))
            if r is None:
                continue
            x, y = cdf(r)
            ax.step(np.r_[0.0, x], 100 * np.r_[0.0, y], where="post", color=color, lw=1.6, label=label)
            xmax = max(xmax, float(x.max()) * 1.05)
        ax.axvline(limit_m, color="k", ls="--", lw=0.8, label="localization failure (map search)")
        r0 = next(by[(name, m)] for m in _MODE_STYLE if (name, m) in by)
        ax.set_title(f"{name}: {r0.info.get('date', '')} {r0.info.get('start', '')} {r0.info.get('weather', '')}",
                     fontsize=9)
        ax.set_xlim(0, min(xmax, max(limit_m * 1.5, 1.02 * r0.distance_m)))
        ax.set_ylim(0, 101)
        ax.set_xlabel("distance driven on VO since the last localization [m]", fontsize=8)
        ax.set_ylabel("% of the traverse", fontsize=8)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7, loc="lower right")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plot_inliers(path: Path, runs: Sequence[RepeatRun], names: Sequence[str], min_inliers: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by = {(r.run, r.mode): r for r in runs}
    fig, axes = plt.subplots(len(names), 1, figsize=(11, 2.0 * len(names)), squeeze=False, sharex=True)
    colors = {"grey": "0.3", "fv": "tab:green", "fr": "tab:orange"}
    for ax, name in zip(axes[:, 0], names, strict=True):
        fused, grey = by.get((name, "fused")), by.get((name, "grey"))
        if fused is not None:
            s = np.array([f.s_m for f in fused.frames])
            for src, color in colors.items():
                ax.plot(s, [getattr(f, f"inliers_{src}") for f in fused.frames], color=color, lw=0.8,
                        label=f"fused: {src} inliers")
            fail = np.array([f.failure for f in fused.frames])
            if fail.any():
                ax.fill_between(s, 0, 1, where=fail, transform=ax.get_xaxis_transform(), color="tab:green",
                                alpha=0.15, lw=0)
        if grey is not None:
            s = np.array([f.s_m for f in grey.frames])
            ax.plot(s, [f.inliers_grey for f in grey.frames], color="k", ls=":", lw=0.8, label="grey mode inliers")
            fail = np.array([f.failure for f in grey.frames])
            if fail.any():
                ax.fill_between(s, 0, 1, where=fail, transform=ax.get_xaxis_transform(), color="0.5", alpha=0.2,
                                lw=0, label="grey mode: failure")
        ax.axhline(min_inliers, color="r", lw=0.6)
        ax.set_yscale("symlog", linthresh=10)
        r0 = fused or grey
        if r0 is not None:
            ax.set_ylabel(f"{name}\n{r0.info.get('start', '')} {r0.info.get('weather', '')}", fontsize=8)
    axes[0, 0].legend(fontsize=7, ncol=5, loc="upper right")
    axes[-1, 0].set_xlabel("position along the route [m] (truth)")
    fig.tight_layout()
    fig.savefig(path, dpi=64)
    plt.close(fig)


def write_outputs(out_dir: Path, runs: Sequence[RepeatRun], modes: Sequence[str], run_order: Sequence[str], *,
                  meta: dict[str, Any], limit_m: float, min_inliers: int) -> list[Path]:
    """Table, CSVs, JSON and plots of the runs finished so far (atomically; called after every run)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    names = [n for n in run_order if any(r.run == n for r in runs)]
    done = f"{len(runs)} of {meta.get('jobs_total', len(runs))} (run, mode) evaluations"
    text = [
        "# Colour-constant VT&R on the simulated day schedule (paper §VI, Table I, Fig. 7)",
        "",
        f"Simulation `{meta.get('sim_dir', '')}`; teach run `{meta.get('teach', '')}` "
        f"(map: {meta.get('keyframes', '?')} keyframes, {meta.get('map_length_m', float('nan')):.0f} m). "
        f"Autonomy by distance = share of the route driven without a localization failure (20 m on VO alone, "
        f"then whole-map search; the distance until relocalization counts as manual); max on VO = the longest "
        f"distance driven without a localization (truth). {done}.",
        "",
        table_markdown(runs, modes, names),
        *[f"- {v}" for v in verdict(runs, modes)],
        "",
        "Per run and mode (localized = share of frames with a successful localization; inliers = median over "
        "localized frames; error = position error of the localized pose against the truth):",
        "",
        details_markdown(runs, modes, names),
        f"Generated by `lightfast eval vtr` ({meta.get('generated', '')}; the (run, mode) evaluations took "
        f"{sum(r.seconds for r in runs):.0f} s of wall time in total).",
        "",
    ]
    written = [out_dir / "vtr_table.md"]
    write_text_atomic(written[0], "\n".join(text))
    _write_runs_csv(out_dir / "vtr_runs.csv", runs)
    _write_frames_csv(out_dir / "vtr_frames.csv", runs)
    summary = {"meta": meta, "modes": list(modes), "runs": [r.summary() for r in runs],
               "overall": {m: overall(runs, m) for m in modes}, "verdict": verdict(runs, modes)}
    write_text_atomic(out_dir / "vtr_summary.json", json.dumps(json_finite(summary), indent=1) + "\n")
    written += [out_dir / "vtr_runs.csv", out_dir / "vtr_frames.csv", out_dir / "vtr_summary.json"]
    if names:
        _plot_cdfs(out_dir / "vtr_cdf.png", runs, names, limit_m,
                   "CDF of the distance driven on VO (Fig. 7 style), every repeat")
        _plot_inliers(out_dir / "vtr_inliers.png", runs, names, min_inliers)
        written += [out_dir / "vtr_cdf.png", out_dir / "vtr_inliers.png"]
        fig7 = [n for n in FIG7_RUNS if n in names]
        if fig7:
            _plot_cdfs(out_dir / "vtr_cdf_fig7.png", runs, fig7, limit_m,
                       "Fig. 7 style: repeat 4 (3 h after the teach), repeat 7 (shadows opposite to the map's)")
            written.append(out_dir / "vtr_cdf_fig7.png")
    return written
