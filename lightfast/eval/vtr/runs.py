"""``lightfast eval vtr SIM_DIR OUT`` (paper §VI): teach once, repeat every run in every mode, score, keep the results.

1. **Teach once** from the teach run with the parameters of ``vtr_localizer_node``
   (:class:`~lightfast.vtr.localizer_config.VtrLocalizerConfig` defaults: its teach and stereo sections): every
   stereo pair through :class:`~lightfast.vtr.teach.TeachPipeline`, the map written into ``MAPS/teach-<key>``
   (default ``SIM_DIR/vtr_maps``) and reused while the teach run and the parameters are unchanged
   (:func:`teach_map`).
2. **Repeat** every repeat run in every mode (``fused``, ``grey``, ``mcmanus``) in-process through
   :meth:`lightfast.vtr.repeat.RepeatPipeline.step` — the call ``vtr_localizer_node`` makes per stereo pair — with
   the node's repeat parameters (its ``repeat`` section). The method sees the bag's rgb8 images and the
   ``camera_info`` projection matrices only; the first frame starts with the whole-map search, as a node does.
3. **Score** each frame against the ground truth (:mod:`lightfast.eval.vtr.scoring`; :func:`run_repeat`).

A finished (run, mode) is kept in ``OUT/runs/`` (or ``keep_dir``) under a key of its inputs and parameters and
skipped when the evaluation is started again with the same ones; the report
(:func:`~lightfast.eval.vtr.report.write_outputs`) is rewritten after every finished run (:func:`evaluate_vtr`).
Runs go in-process or in ``jobs`` spawned processes, each loading the map once.
"""
from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lightfast.config import config_from_mapping, replace_config
from lightfast.data.shared import shown_path
from lightfast.eval.cache import code_version, content_digest, run_key
from lightfast.eval.errors import VtrEvalError
from lightfast.eval.vtr.inputs import SimRun, Truth, check_camera, load_truth, sim_runs, stereo_frames
from lightfast.eval.vtr.report import write_outputs
from lightfast.eval.vtr.scoring import REPORTED_SOURCES, FrameRecord, RepeatRun
from lightfast.geometry import rotation_angle_deg
from lightfast.io import json_finite, write_text_atomic
from lightfast.progress import track
from lightfast.vtr.localizer_config import VtrLocalizerConfig
from lightfast.vtr.map_store import MapStore, TeachMap
from lightfast.vtr.repeat import RepeatPipeline
from lightfast.vtr.repeat_config import MODES
from lightfast.vtr.teach import TeachPipeline

log = logging.getLogger(__name__)

#: Bump when the per-run results change meaning (invalidates the results kept in ``OUT/runs``).
EVAL_FORMAT = 1


#: The code a run executes (its version is part of the run's key).
CODE = ("vtr", "eval/vtr", "bag", "geometry", "config.py")


def _key(*parts: object) -> str:
    """What decides a result (:mod:`lightfast.eval.cache`): the recording's content (another route seed or
    simulator version is another recording), the configuration, the code version."""
    return run_key({"parts": parts, "format": EVAL_FORMAT, "code": code_version(*CODE)})


def _teach_key(teach: SimRun, config: VtrLocalizerConfig) -> str:
    return _key("teach", content_digest(teach.path), config.teach.to_dict(), config.stereo.to_dict(),
                config.vo.to_dict())


def teach_map(teach: SimRun, maps_dir: Path, config: VtrLocalizerConfig | None = None, *,
              progress: bool = False) -> tuple[TeachMap, str]:
    """The map of the teach run (taught now, or loaded from ``maps_dir/teach-<key>``) and its key."""
    config = config or VtrLocalizerConfig(mode="teach")
    key = _teach_key(teach, config)
    path = maps_dir / f"teach-{key}"
    if MapStore.exists(path):
        log.info("reusing the teach map %s", path)
        return MapStore.load(path), key
    maps_dir.mkdir(parents=True, exist_ok=True)
    tp = TeachPipeline(path, config.teach, stereo=config.stereo, vo=config.vo, overwrite=True)
    n = int(teach.info.get("frames", 0)) or None
    t0 = time.perf_counter()
    try:
        for stamp, left, right, Pl, Pr in track(stereo_frames(teach.path / "bag"), desc=f"teach {teach.name}",
                                                total=n, enabled=progress, unit="frame"):
            tp.step(stamp, left, right, Pl, Pr)
        m = tp.finish()
    except BaseException:
        tp.abort()
        raise
    log.info("taught %s: %d keyframes, %.1f m in %.0f s (%d VO failures)", teach.name, len(m), m.length_m,
             time.perf_counter() - t0, tp.vo_failures)
    return m, key


def run_repeat(run: SimRun, tmap: TeachMap, teach_truth: Truth, mode: str, *,
               config: VtrLocalizerConfig | None = None, max_frames: int | None = None,
               progress: bool = False) -> RepeatRun:
    """One repeat run in one mode (module docstring, steps 2–3)."""
    if mode not in MODES:
        raise VtrEvalError(f"unknown mode {mode!r}; choose from {', '.join(MODES)}")
    cfg = replace_config(config or VtrLocalizerConfig(), {"repeat.mode": mode})
    truth = load_truth(run.path)
    kf_T = np.stack([teach_truth.T_map_cam[teach_truth.index(kf.stamp_ns)] for kf in tmap.keyframes])
    rp = RepeatPipeline(tmap, cfg.repeat, vo=cfg.vo)
    spec = run.info["run"]
    out = RepeatRun(run.name, mode, {k: spec.get(k) for k in ("date", "start", "weather", "summary", "kind",
                                                              "paper_repeat")})
    total = int(run.info.get("frames", 0)) or None
    if max_frames is not None and total is not None:
        total = min(total, max_frames)
    prev_pos: NDArray[np.float64] | None = None
    vo_truth = 0.0
    t_start = time.perf_counter()
    try:
        for i, (stamp, left, right, Pl, Pr) in enumerate(track(
                stereo_frames(run.path / "bag"), desc=f"{run.name} {mode}", total=total, enabled=progress,
                unit="frame")):
            if max_frames is not None and i >= max_frames:
                break
            if i == 0:
                check_camera(run.name, tmap, left, Pl, Pr)
            t0 = time.perf_counter()
            res = rp.step(stamp, left, right, Pl, Pr)
            ms_total = 1e3 * (time.perf_counter() - t0)
            k = truth.index(stamp)
            T_map_cam = truth.T_map_cam[k]
            pos = T_map_cam[:3, 3]
            step = 0.0 if prev_pos is None else float(np.linalg.norm(pos - prev_pos))
            prev_pos = pos
            vo_truth = 0.0 if res.localized else vo_truth + step
            err_m = err_deg = math.nan
            if res.T_kf_cam is not None:
                T_true = np.linalg.solve(kf_T[res.keyframe_index], T_map_cam)
                err_m = float(np.linalg.norm(res.T_kf_cam[:3, 3] - T_true[:3, 3]))
                err_deg = float(rotation_angle_deg(res.T_kf_cam[:3, :3], T_true[:3, :3]))
            ins, mat, tm = res.inliers_per_source, res.matches_per_source, res.timing_s
            out.frames.append(FrameRecord(
                frame=i, stamp_ns=stamp, s_m=float(truth.s_m[k]), step_m=step,
                sun_elevation_deg=float(truth.sun_elevation_deg[k]), localized=bool(res.localized),
                failure=bool(res.failure), relocalized=bool(res.relocalized), searched_map=bool(res.searched_map),
                keyframe=int(res.keyframe_index),
                **{f"inliers_{s}": int(ins.get(s, 0)) for s in REPORTED_SOURCES},
                **{f"matches_{s}": int(mat.get(s, 0)) for s in REPORTED_SOURCES},
                vo_success=bool(res.vo_success), distance_on_vo_m=float(res.distance_on_vo_m), vo_truth_m=vo_truth,
                error_m=err_m, error_deg=err_deg, ms_total=ms_total,
                ms_front_end=1e3 * tm.get("front_end", 0.0), ms_vo=1e3 * tm.get("vo", 0.0),
                ms_localization=1e3 * tm.get("localization", 0.0), ms_search=1e3 * tm.get("search", 0.0)))
    finally:
        rp.close()
    if not out.frames:
        raise VtrEvalError(f"{run.name}: no complete stereo pairs in {run.path / 'bag'}")
    out.failures = rp.failures
    out.seconds = time.perf_counter() - t_start
    return out


def _job_key(run: SimRun, mode: str, map_key: str, config: VtrLocalizerConfig, max_frames: int | None) -> str:
    return _key("repeat", content_digest(run.path), mode, map_key,
                replace_config(config, {"repeat.mode": mode}).repeat.to_dict(), config.vo.to_dict(), max_frames)


_JOB_MAP: dict[str, tuple[TeachMap, Truth]] = {}


def _run_job(job: tuple[str, str, str, str, str, dict[str, Any], int | None]) -> RepeatRun:
    """Worker of ``--jobs``: one (run, mode) in its own process (the map is loaded once per process)."""
    run_dir, run_json, teach_dir, map_dir, mode, cfg, max_frames = job
    if map_dir not in _JOB_MAP:
        _JOB_MAP.clear()
        _JOB_MAP[map_dir] = (MapStore.load(map_dir), load_truth(Path(teach_dir)))
    tmap, teach_truth = _JOB_MAP[map_dir]
    run = SimRun(Path(run_dir).name, Path(run_dir), json.loads(run_json))
    return run_repeat(run, tmap, teach_truth, mode, config=config_from_mapping(VtrLocalizerConfig, cfg),
                      max_frames=max_frames)


def evaluate_vtr(sim_dir: Path, out_dir: Path, *, modes: Sequence[str] = MODES, runs: Sequence[str] | None = None,
                 maps_dir: Path | None = None, keep_dir: Path | None = None, config: VtrLocalizerConfig | None = None,
                 max_frames: int | None = None, jobs: int = 1, progress: bool = False, force: bool = False,
                 report_only: bool = False, on_run: Callable[[RepeatRun], None] | None = None) -> list[RepeatRun]:
    """The evaluation of the module docstring; returns every (run, mode) result (kept ones included). Finished
    (run, mode) results are kept in ``keep_dir`` (default ``out_dir/runs``). With ``report_only`` nothing is
    evaluated: the outputs are written from the kept results (missing (run, mode) pairs show as "—")."""
    for m in modes:
        if m not in MODES:
            raise VtrEvalError(f"unknown mode {m!r}; choose from {', '.join(MODES)}")
    if not modes:
        raise VtrEvalError("no modes to evaluate")
    config = config or VtrLocalizerConfig()
    all_runs = sim_runs(sim_dir)
    teaches = [r for r in all_runs if r.kind == "teach"]
    if len(teaches) != 1:
        raise VtrEvalError(f"{sim_dir} must hold exactly one complete teach run, found {len(teaches)} "
                           f"(make it with `lightfast sim vtr {sim_dir} --runs teach ...`)")
    teach = teaches[0]
    repeats = [r for r in all_runs if r.kind == "repeat"]
    if runs:
        missing = sorted(set(runs) - {r.name for r in repeats})
        if missing:
            raise VtrEvalError(f"repeat runs not found (complete) in {sim_dir}: {', '.join(missing)}")
        repeats = [r for r in repeats if r.name in set(runs)]
    if not repeats:
        raise VtrEvalError(f"no complete repeat runs in {sim_dir}")
    t0 = time.perf_counter()
    maps_dir = maps_dir or sim_dir / "vtr_maps"
    teach_cfg = replace(config, mode="teach")
    tmap, map_key = teach_map(teach, maps_dir, teach_cfg, progress=progress)
    teach_truth = load_truth(teach.path)
    runs_dir = keep_dir or out_dir / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    order = [r.name for r in repeats]
    meta: dict[str, Any] = {
        "sim_dir": shown_path(sim_dir), "teach": teach.name, "map": shown_path(maps_dir / f"teach-{map_key}"),
        "keyframes": len(tmap), "map_length_m": tmap.length_m, "modes": list(modes), "runs": order,
        "config": config.to_dict(), "max_frames": max_frames, "jobs_total": len(repeats) * len(modes),
        "image_size": list(tmap.image_size), "eval_format": EVAL_FORMAT,
    }
    results: list[RepeatRun] = []
    todo: list[tuple[SimRun, str, str]] = []
    for r in repeats:
        for m in modes:
            key = _job_key(r, m, map_key, config, max_frames)
            kept = runs_dir / f"{r.name}.{m}.json"
            if not force and kept.is_file():
                try:
                    d = json.loads(kept.read_text())
                    if d.get("key") == key:
                        results.append(RepeatRun.from_json(d["result"]))
                        log.info("%s %s: kept from %s", r.name, m, kept)
                        continue
                except (OSError, ValueError, KeyError, TypeError) as exc:
                    log.warning("ignoring unreadable %s: %s", kept, exc)
            todo.append((r, m, key))
    if report_only:
        if todo:
            log.info("report only: %d (run, mode) pairs not evaluated: %s", len(todo),
                     ", ".join(f"{r.name}/{m}" for r, m, _ in todo))
        todo = []
    limit = config.repeat.max_distance_on_vo_m
    min_inliers = config.repeat.min_inliers

    def finished(res: RepeatRun, key: str) -> None:
        write_text_atomic(runs_dir / f"{res.run}.{res.mode}.json",
                          json.dumps(json_finite({"key": key, "result": res.to_json()})) + "\n")
        results.append(res)
        results.sort(key=lambda x: (order.index(x.run), list(modes).index(x.mode)))
        meta.update(generated=time.strftime("%Y-%m-%dT%H:%M:%S%z"), seconds=time.perf_counter() - t0)
        write_outputs(out_dir, results, modes, order, meta=meta, limit_m=limit, min_inliers=min_inliers)
        log.info("%s %s: autonomy %.2f %%, %d failures, max %.1f m on VO, %d frames in %.0f s", res.run, res.mode,
                 100 * res.autonomy, res.failures, res.max_vo_m, len(res.frames), res.seconds)
        if on_run is not None:
            on_run(res)

    if jobs <= 1 or len(todo) <= 1:
        for r, m, key in track(todo, desc="vtr evaluation", enabled=progress and len(todo) > 1, unit="run"):
            finished(run_repeat(r, tmap, teach_truth, m, config=config, max_frames=max_frames, progress=progress),
                     key)
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        map_dir = str(maps_dir / f"teach-{map_key}")
        cfg = config.to_dict()
        with ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn")) as pool:
            futures = {pool.submit(_run_job, (str(r.path), json.dumps(r.info), str(teach.path), map_dir, m, cfg,
                                              max_frames)): key for r, m, key in todo}
            for fut in track(as_completed(futures), desc="vtr evaluation", total=len(futures), enabled=progress,
                             unit="run"):
                finished(fut.result(), futures[fut])
    results.sort(key=lambda x: (order.index(x.run), list(modes).index(x.mode)))
    meta.update(generated=time.strftime("%Y-%m-%dT%H:%M:%S%z"), seconds=time.perf_counter() - t0)
    write_outputs(out_dir, results, modes, order, meta=meta, limit_m=limit, min_inliers=min_inliers)
    return results
