"""False accepts of the VT&R relocalization on places that cannot be right (issue 19, point 3): the repeat runs of
one simulated route are driven through :class:`lightfast.vtr.RepeatPipeline` against the teach map of **another**
route (another ``--scene-seed``: another scene). The repeat never localizes at first, so it searches the whole map
every frame; every place it accepts is a false accept, and the right answer is "not localized" on every frame.

Per mode the table gives the frames, the frames whose search found a place at all (success before the look-alike
rules), the places refused by them (``search_min_inliers``, ``search_margin``), the weak places held, and the frames
localized (all false: after a false accept the windowed localization goes on against the wrong place). The peer, in
the same run, is the paper's rule (§IV-C: the search's best place with six inliers; no margin, no verification, no
second frame): ``search_min_inliers`` 6, ``search_margin`` 1, ``search_accept_inliers`` 6,
``search_verify_places`` 0. The node's defaults are the method.

Data: two routes made by ``lightfast sim vtr`` with the same camera (e.g. ``--size 320x240 --rate 1``); nothing here
reads their truth. Usage::

    nice -n 10 .venv/bin/python benchmarks/vtr_foreign_map.py MAP_ROUTE FRAMES_ROUTE [--runs repeat01 repeat07]
        [--modes fused grey] [--max-frames N] [--output benchmarks/results/vtr_foreign_map.md]

writes the markdown table and a ``.json`` beside it (atomically).
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import sys
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from lightfast.config import replace_config  # noqa: E402
from lightfast.eval.errors import VtrEvalError  # noqa: E402
from lightfast.eval.vtr.inputs import SimRun, check_camera, sim_runs, stereo_frames  # noqa: E402
from lightfast.eval.vtr.runs import teach_map  # noqa: E402
from lightfast.io import json_finite, write_text_atomic  # noqa: E402
from lightfast.progress import track  # noqa: E402
from lightfast.vtr import RepeatPipeline  # noqa: E402
from lightfast.vtr.localizer_config import VtrLocalizerConfig  # noqa: E402
from lightfast.vtr.map_store import TeachMap  # noqa: E402

#: The paper's acceptance (§IV-C): the best place of the search with six inliers, nothing else.
PAPER_RULE = {"repeat.search_min_inliers": 6, "repeat.search_margin": 1.0, "repeat.search_accept_inliers": 6,
              "repeat.search_verify_places": 0}


@dataclass
class Count:
    rule: str
    mode: str
    run: str
    frames: int = 0
    found: int = 0  # frames whose search found a successful place (before the look-alike rules)
    refused: int = 0
    held: int = 0
    localized: int = 0  # every one a false accept
    most_inliers_accepted: int = 0
    seconds: float = 0.0


def run_foreign(tmap: TeachMap, run: SimRun, mode: str, rule: str, max_frames: int | None,
                progress: bool) -> Count:
    """``run`` (of another route) against the teach map ``tmap`` with ``mode`` and the acceptance ``rule``."""
    overrides: dict[str, Any] = {"repeat.mode": mode} | (PAPER_RULE if rule == "paper" else {})
    cfg = replace_config(VtrLocalizerConfig(), overrides)
    rp = RepeatPipeline(tmap, cfg.repeat, vo=cfg.vo)
    out = Count(rule, mode, run.name)
    t0 = time.perf_counter()
    total = int(run.info.get("frames", 0)) or None
    try:
        for i, (stamp, left, right, Pl, Pr) in enumerate(track(stereo_frames(run.path / "bag"),
                                                               desc=f"{run} {mode} {rule}", total=total,
                                                               enabled=progress, unit="frame")):
            if max_frames is not None and i >= max_frames:
                break
            if i == 0:
                check_camera(run.name, tmap, left, Pl, Pr)
            held, refused = rp.held_places, rp.refused_places
            res = rp.step(stamp, left, right, Pl, Pr)
            out.frames += 1
            out.held += rp.held_places - held
            out.refused += rp.refused_places - refused
            out.found += int(res.searched_map and (res.localized or rp.held_places > held or rp.refused_places
                                                   > refused))
            if res.localized:
                out.localized += 1
                out.most_inliers_accepted = max(out.most_inliers_accepted, sum(res.inliers_per_source.values()))
    finally:
        rp.close()
    out.seconds = time.perf_counter() - t0
    return out


def markdown(counts: list[Count], meta: dict[str, Any]) -> str:
    lines = [
        "# VT&R relocalization against another route's map: every accepted place is false",
        "",
        f"Map: `{meta['map_route']}`; frames: `{meta['frames_route']}` ({', '.join(meta['runs'])}, at most "
        f"{meta['max_frames'] or 'all'} frames each); {meta['date']}, {meta['cpus']} CPUs. "
        "Produced by `benchmarks/vtr_foreign_map.py` (module docstring: the rules compared).",
        "",
        "| rule | mode | run | frames | search found a place | refused (look-alike rules) | held | localized (false) | "
        "most inliers accepted |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for c in counts:
        lines.append(f"| {c.rule} | {c.mode} | {c.run} | {c.frames} | {c.found} | {c.refused} | {c.held} | "
                     f"**{c.localized}** | {c.most_inliers_accepted or '—'} |")
    lines.append("")
    for rule in ("node", "paper"):
        cs = [c for c in counts if c.rule == rule]
        if cs:
            n, bad = sum(c.frames for c in cs), sum(c.localized for c in cs)
            lines.append(f"- {rule} rule: {bad} of {n} frames localized on a map of another scene "
                         f"({100 * bad / n:.1f} %).")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map_route", type=Path, help="route whose teach map is searched (lightfast sim vtr output)")
    ap.add_argument("frames_route", type=Path, help="route whose repeat runs are driven (another scene)")
    ap.add_argument("--runs", nargs="+", default=["repeat01", "repeat07"])
    ap.add_argument("--modes", nargs="+", default=["fused", "grey"])
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--output", type=Path, default=ROOT / "benchmarks" / "results" / "vtr_foreign_map.md")
    ap.add_argument("--no-progress", action="store_true")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    maps = {r.name: r for r in sim_runs(a.map_route)}
    runs = {r.name: r for r in sim_runs(a.frames_route)}
    if "teach" not in maps or not set(a.runs) <= set(runs):
        raise SystemExit(f"vtr_foreign_map: {a.map_route} needs a teach run and {a.frames_route} the runs {a.runs}")
    tmap, _ = teach_map(maps["teach"], a.map_route / "vtr_maps")  # the teach key does not depend on the mode
    counts = []
    for mode in a.modes:
        for run in a.runs:
            for rule in ("node", "paper"):
                try:
                    c = run_foreign(tmap, runs[run], mode, rule, a.max_frames, not a.no_progress)
                except VtrEvalError as e:
                    raise SystemExit(f"vtr_foreign_map: {e}") from None
                print(f"{rule:5s} {mode:5s} {run}: {c.frames} frames, found {c.found}, refused {c.refused}, held "
                      f"{c.held}, localized (false) {c.localized}", flush=True)
                counts.append(c)
    meta = {"map_route": a.map_route.name, "frames_route": a.frames_route.name, "runs": a.runs,
            "max_frames": a.max_frames, "date": datetime.now(UTC).isoformat(timespec="seconds"),
            "cpus": os.cpu_count(), "python": platform.python_version(), "paper_rule": PAPER_RULE}
    write_text_atomic(a.output, markdown(counts, meta))
    payload = {"meta": meta, "counts": [c.__dict__ for c in counts]}
    write_text_atomic(a.output.with_suffix(".json"),
                      json.dumps(json_finite(payload), indent=1, allow_nan=False) + "\n")
    print(f"wrote {a.output} and {a.output.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
