"""``lightfast eval racr SCENES_DIR OUT`` (paper §5): every missing (scene, lighting, method, repeat) run, resumable.

Input: a directory of scenes written by ``lightfast sim racr`` (one ``<scene>/scene.json`` each). The runs go
scene-major through :func:`~lightfast.eval.racr.run.run_one`, in-process or in ``jobs`` spawned processes, each
process holding one loaded scene at a time (:func:`cached_scene`). Every finished run is cached as a record
(:mod:`lightfast.eval.racr.records`) and the outputs (:func:`~lightfast.eval.racr.report.write_outputs`) are
rewritten after it: an interrupted evaluation leaves valid partial results, and one started again skips the runs
recorded with the same key (scene content, method configuration, protocol, code version).

Outputs in ``OUT``: ``runs/*.json`` and the report's tables, CSV, JSON and plots, from the records of this call's
runs only.
"""
from __future__ import annotations

import json
import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from lightfast.config import config_from_mapping
from lightfast.eval.cache import content_digest, run_key
from lightfast.eval.errors import RacrEvalError
from lightfast.eval.racr.protocol import LIGHTINGS, METHODS, RacrEvalConfig, protocol_parts
from lightfast.eval.racr.records import RunRecord, load_records, record_path
from lightfast.eval.racr.report import write_outputs
from lightfast.eval.racr.run import run_one
from lightfast.io import json_finite, write_text_atomic
from lightfast.progress import track
from lightfast.racr.node_config import RacrNodeConfig

log = logging.getLogger(__name__)


_SCENES: dict[str, Any] = {}


def cached_scene(path: Path) -> Any:
    """The scene at ``path``, loaded once: one scene at a time per process."""
    from lightfast.sim.racr import load_scene

    key = str(path)
    if key not in _SCENES:
        _SCENES.clear()  # one scene at a time per process (meshes are large)
        _SCENES[key] = load_scene(path)
    return _SCENES[key]


def _job(job: tuple[str, str, str, int, dict[str, Any], dict[str, Any], str]) -> RunRecord:
    path, lighting, method, repeat, cfg, node, key = job
    return run_one(cached_scene(Path(path)), lighting, method, repeat, config_from_mapping(RacrEvalConfig, cfg),
                   config_from_mapping(RacrNodeConfig, node), key)


def evaluate_racr(scenes_dir: Path, out_dir: Path, *, methods: Sequence[str] = tuple(METHODS),
                  scenes: Sequence[str] | None = None, lightings: Sequence[str] = ("varied",), repeats: int = 1,
                  config: RacrEvalConfig | None = None, node: RacrNodeConfig | None = None, jobs: int = 1,
                  progress: bool = True, max_runs: int | None = None,
                  on_run: Callable[[RunRecord], None] | None = None) -> list[RunRecord]:
    """Run every missing (scene, lighting, method, repeat) — at most ``max_runs`` of them — and (re)write the
    outputs from the records in ``out_dir`` of these scenes' content and this protocol (any method and lighting).
    ``node``: the rACR node's configuration the methods start from (default: its defaults). Returns those
    records."""
    config = config or RacrEvalConfig()
    node = node or RacrNodeConfig()
    for m in methods:
        if m not in METHODS:
            raise RacrEvalError(f"unknown method {m!r}; choose from {', '.join(METHODS)}")
    for lt in lightings:
        if lt not in LIGHTINGS:
            raise RacrEvalError(f"unknown lighting {lt!r}; choose from {', '.join(LIGHTINGS)}")
    if repeats < 1:
        raise RacrEvalError("repeats must be at least 1")
    dirs = sorted(p for p in scenes_dir.iterdir() if (p / "scene.json").is_file()) if scenes_dir.is_dir() else []
    if scenes:
        wanted = set(scenes)
        dirs = [p for p in dirs if p.name in wanted]
        missing = wanted - {p.name for p in dirs}
        if missing:
            raise RacrEvalError(f"scenes not found in {scenes_dir}: {', '.join(sorted(missing))}")
    if not dirs:
        raise RacrEvalError(f"no scenes in {scenes_dir} (make them with `lightfast sim racr {scenes_dir}`)")
    out_dir.mkdir(parents=True, exist_ok=True)
    shared = protocol_parts(config, node)
    keys = {}  # (scene dir, lighting, method, repeat) -> key, for every method and lighting: the report shows all
    for d in dirs:
        scene = content_digest(d, skip=("preview",))
        for r in range(repeats):
            for lt in LIGHTINGS:
                for m in METHODS:
                    keys[(str(d), lt, m, r)] = run_key({**shared, "scene": scene, "lighting": lt, "method": m,
                                                        "repeat": r})
    done = {rec.key for rec in load_records(out_dir, set(keys.values()))}
    # scene-major order: one scene's mesh stays loaded for all its runs
    todo = [(d, lt, m, r, config.to_dict(), node.to_dict(), k) for (d, lt, m, r), k in keys.items()
            if lt in lightings and m in methods and k not in done]
    if max_runs is not None:
        todo = todo[:max_runs]
    log.info("%d runs to do (%d already done)", len(todo), len(done))

    def finish(rec: RunRecord) -> None:
        write_text_atomic(record_path(out_dir, rec),
                          json.dumps(json_finite(rec.to_dict()), indent=1, allow_nan=False) + "\n")
        write_outputs(out_dir, load_records(out_dir, set(keys.values())), config, node)  # survives an interruption
        log.info("%s: AFD %.2f px (%s), %d adjustments, %.1f s simulated, %.0f s wall, %s", rec.key, rec.afd_px,
                 "ok" if rec.success else "FAIL", rec.adjustments, rec.time_loop_s, rec.wall_s, rec.stop_reason)
        if on_run is not None:
            on_run(rec)

    if jobs <= 1:
        for job in track(todo, desc="rACR evaluation", enabled=progress, unit="run"):
            finish(_job(job))
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn")) as pool:
            for rec in track(pool.map(_job, todo), desc="rACR evaluation", total=len(todo), enabled=progress,
                             unit="run"):
                finish(rec)
    runs = load_records(out_dir, set(keys.values()))
    write_outputs(out_dir, runs, config, node)
    return runs
