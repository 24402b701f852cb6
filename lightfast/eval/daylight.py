"""The tracking evaluation of paper §IV-C (Table I): the two-step tracker and its ablations on daylight recordings.

For each recording made by ``lightfast sim daylight`` (DS1.T1–T6, DS2.T1–T6) and each method, the tracker runs
in-process over every frame — f2f (:class:`~lightfast.tracking.pipeline.RGBDTracker`), the relit reference at T≈
(:class:`~lightfast.daylight.relight.DaylightRelighter`), f2m — exactly the work the three nodes split between them.
The method sees the bag's colour and depth images, ``camera_info``, the lighting map, the camera response file and
the site; ground truth is read only here, by the protocol:

* the tracker starts at the ground-truth pose of the first frame;
* a frame whose estimate deviates from ground truth by more than 10 cm or 10° is a *tracking loss*: it is excluded
  from the RMSE and the tracker is reset to the ground-truth pose of that frame;
* RMSE is the root mean square translation error of the remaining frames (the map frame is the ground-truth frame,
  so no trajectory alignment is applied).

Methods: ``proposed`` (E_crf), ``proposed-lin`` (the same with E_lin, Eq. 6 — the paper's E_crf vs E_lin remark),
``refl-f2m``, ``depth-only``, ``no-color-f2m``. B̂_sun is computed once per recording for its middle time (the
recordings last 20 s; the sun moves 0.08° in that time).

Resumable: every finished (recording, method) run is kept in ``OUT/runs/<recording>.<method>.json`` with a key of
everything that decides it (the recording's parameters, the lighting map's metadata, the tracker and relighting
configuration, the frame limit, :data:`PROTOCOL_VERSION`); a later call with the same key reuses it instead of
running again, so an interrupted evaluation continues where it stopped.
"""
from __future__ import annotations

import csv
import dataclasses
import datetime as dt
import json
import logging
import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lightfast.bag.reader import open_bag
from lightfast.camera import PinholeCamera
from lightfast.config import config_from_mapping
from lightfast.daylight.crf import load_crf
from lightfast.daylight.lighting_map import FORMAT_VERSION as MAP_FORMAT_VERSION
from lightfast.daylight.lighting_map import LightingMap, LightingMapConfig
from lightfast.daylight.relight import DaylightRelighter, RelightConfig
from lightfast.daylight.sun import sun_position
from lightfast.daylight.sun_update import sun_radiosity
from lightfast.eval.cache import code_version, content_digest, run_key
from lightfast.eval.daylight_inputs import InputChange
from lightfast.eval.errors import DaylightEvalError
from lightfast.geometry import rotation_angle_deg
from lightfast.io import write_text_atomic
from lightfast.progress import track
from lightfast.topics import COLOR_INFO_TOPIC, COLOR_TOPIC, DEPTH_TOPIC, GT_POSE_TOPIC
from lightfast.tracking.pipeline import RGBDTracker, TrackerConfig

__all__ = ["METHODS", "FrameRecord", "InputChange", "SequenceRun", "evaluate_daylight", "method_configs",
           "pooled", "recording_frames", "run_sequence", "scene_lighting_map", "scene_of", "sequence_files"]

log = logging.getLogger(__name__)

#: method name → (tracker mode, reference kind, brightness error)
METHODS: dict[str, tuple[str, str, str]] = {
    "proposed": ("proposed", "relit", "crf"),
    "proposed-lin": ("proposed", "relit", "lin"),
    "refl-f2m": ("refl-f2m", "reflectance", "crf"),
    "depth-only": ("depth-only", "relit", "crf"),
    "no-color-f2m": ("no-color-f2m", "relit", "crf"),
}
#: Bump when the protocol or the method changes in a way the run key does not see (stored runs are then redone).
PROTOCOL_VERSION = 3
LOSS_TRANSLATION_M = 0.10
LOSS_ROTATION_DEG = 10.0


@dataclass(frozen=True)
class FrameRecord:
    stamp_ns: int
    t_err_m: float
    r_err_deg: float
    lost: bool
    source: str
    scale_sun: tuple[float, float, float]
    scale_sky: tuple[float, float, float]
    scale_ground: tuple[float, float, float]
    ms_f2f: float
    ms_render: float
    ms_estimate: float
    ms_f2m: float


@dataclass
class SequenceRun:
    sequence: str
    method: str
    frames: list[FrameRecord] = field(default_factory=list)
    T_est: list[NDArray[np.float64]] = field(default_factory=list)
    T_gt: list[NDArray[np.float64]] = field(default_factory=list)

    @property
    def losses(self) -> int:
        return sum(f.lost for f in self.frames)

    @property
    def loss_ratio(self) -> float:
        return self.losses / max(len(self.frames), 1)

    @property
    def rmse_m(self) -> float:
        e = np.array([f.t_err_m for f in self.frames if not f.lost])
        return float(np.sqrt(np.mean(e**2))) if len(e) else math.nan


def pooled(runs: Sequence[SequenceRun]) -> dict[str, float]:
    """Frames, lost frames, loss in % and the RMSE (cm) over the tracked frames of all ``runs`` taken together (one
    pool, not a mean of per-sequence figures)."""
    frames = sum(len(r.frames) for r in runs)
    lost = sum(r.losses for r in runs)
    err = np.array([f.t_err_m for r in runs for f in r.frames if not f.lost])
    return {"frames": frames, "lost": lost, "loss_pct": 100.0 * lost / max(frames, 1),
            "rmse_cm": 100.0 * float(np.sqrt(np.mean(err**2))) if len(err) else float("nan")}


def recording_frames(bag_dir: Path, *, step: int = 1, limit: int | None = None,
                     kept: Callable[[int], bool] | None = None) -> Iterator[
        tuple[int, NDArray[np.uint8], NDArray[np.float32], PinholeCamera, NDArray[np.float64]]]:
    """(stamp_ns, rgb, depth_m, camera, T_map_cam of the truth) of every ``step``-th complete frame (paired by exact
    stamp) of the first ``limit`` of a recording, of those only the ones ``kept(i)`` (asked in order, i counting
    every ``step``-th frame) keeps; skipped frames are not converted, nor the bag read on. A lens in the colour
    ``camera_info`` is undistorted as ``rgbd_tracker_node`` does by default (``camera`` is then the pinhole of K)."""
    from lightfast.ros.convert import CameraInfoReader, image_to_numpy, pose_stamped_to_matrix

    if step < 1:
        raise DaylightEvalError(f"step must be at least 1, got {step}")
    parts: dict[int, dict[str, Any]] = {}
    need = (COLOR_TOPIC, DEPTH_TOPIC, COLOR_INFO_TOPIC, GT_POSE_TOPIC)
    complete = 0
    read_camera = CameraInfoReader(undistort=True)
    with open_bag(bag_dir) as bag:
        for m in bag.messages(topics=need):
            if limit is not None and complete >= limit:
                return
            msg = bag.deserialize(m)
            stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
            p = parts.setdefault(stamp, {})
            p[m.topic] = msg
            if len(p) < 4:
                continue
            del parts[stamp]
            complete += 1
            if (complete - 1) % step or (kept is not None and not kept((complete - 1) // step)):
                continue
            camera = read_camera(p[COLOR_INFO_TOPIC])
            rgb, d = image_to_numpy(p[COLOR_TOPIC]), image_to_numpy(p[DEPTH_TOPIC])
            depth = d.astype(np.float32) / 1000.0 if d.dtype == np.uint16 else d.astype(np.float32)
            if (undistorter := read_camera.undistorter) is not None:
                rgb, depth = undistorter.colour(rgb), undistorter.depth(depth)
            yield stamp, rgb, depth, camera, pose_stamped_to_matrix(p[GT_POSE_TOPIC])[0]


def sequence_files(seq_dir: Path) -> dict[str, Path]:
    """The recording's bag, camera response and sequence info (:class:`DaylightEvalError` if one is missing)."""
    files = {"bag": seq_dir / "bag", "crf": seq_dir / "camera.yaml", "info": seq_dir / "sequence.json"}
    missing = [str(p) for p in files.values() if not p.exists()]
    if missing:
        raise DaylightEvalError(f"{seq_dir} is not a complete daylight recording (missing {', '.join(missing)}); "
                                f"make it with `lightfast sim daylight`")
    return files


def sequence_sun_radiosity(seq_dir: Path, lmap: LightingMap) -> NDArray[np.float32]:
    """B̂_sun for the middle of a recording (from its ``sequence.json`` start time, frame count and rate)."""
    info = json.loads(sequence_files(seq_dir)["info"].read_text())
    start = dt.datetime.fromisoformat(info["start_utc"])
    mid_ns = int(start.timestamp() * 1e9) + int(0.5 * info["frames"] / float(info["rate_hz"]) * 1e9)
    return sun_radiosity(lmap, sun_position(lmap.site, mid_ns).direction_map)


def method_configs(method: str, tracker_config: TrackerConfig | None = None) -> tuple[TrackerConfig, RelightConfig]:
    """The tracker's and the relighter's configuration of ``method`` (:data:`METHODS`) on top of ``tracker_config``
    (default: the node's defaults)."""
    if method not in METHODS:
        raise DaylightEvalError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    mode, reference, brightness = METHODS[method]
    return (dataclasses.replace(tracker_config or TrackerConfig(), mode=mode),
            RelightConfig(reference=reference, method=brightness))


def run_sequence(seq_dir: Path, lmap: LightingMap, method: str, *, max_frames: int | None = None,
                 progress: bool = True, sun_B: NDArray[np.float32] | None = None,
                 tracker_config: TrackerConfig | None = None, inputs: InputChange = InputChange(),
                 T_truth_start: NDArray[np.float64] | None = None, reset_on_loss: bool = True) -> SequenceRun:
    """Run one method over one recording with the §IV-C protocol (see the module docstring); ``inputs``: what-if
    changes to the recording (:class:`InputChange`). Outside the protocol: the tracker starts at the first frame's
    truth times ``T_truth_start`` (a wrong start pose), and with ``reset_on_loss`` False a lost frame is only
    recorded (recovery is the tracker's own)."""
    tracker_cfg, relight_cfg = method_configs(method, tracker_config)
    files = sequence_files(seq_dir)
    info = json.loads(files["info"].read_text())
    frames_total = int(info["frames"])
    crf = load_crf(files["crf"])
    relighter = DaylightRelighter(lmap, crf, config=relight_cfg)
    run = SequenceRun(seq_dir.name, method)
    tracker: RGBDTracker | None = None
    n = frames_total if max_frames is None else min(frames_total, max_frames)
    it = recording_frames(files["bag"], step=inputs.frame_step, limit=n, kept=inputs.kept())
    for stamp, rgb, depth_m, camera, T_gt in track(it, desc=f"{seq_dir.name} {method}",
                                                   total=-(-n // inputs.frame_step), enabled=progress, unit="frame"):
        depth_m = inputs.depth(depth_m)
        if tracker is None:
            tracker = RGBDTracker(camera, config=tracker_cfg)
            tracker.reset(T_gt if T_truth_start is None else T_gt @ T_truth_start)
            if sun_B is None:
                sun_B = sequence_sun_radiosity(seq_dir, lmap)
            relighter.set_sun_radiosity(sun_B, stamp)
        coarse = tracker.track_coarse(stamp, rgb, depth_m)
        ref = relighter.step(stamp, rgb, coarse.T_map_cam, camera)
        res = tracker.refine(stamp, ref.color, ref.depth_m)
        E = np.linalg.solve(T_gt, res.T_map_cam)
        t_err = float(np.linalg.norm(E[:3, 3]))
        r_err = float(rotation_angle_deg(E[:3, :3]))
        lost = t_err > LOSS_TRANSLATION_M or r_err > LOSS_ROTATION_DEG
        if lost and reset_on_loss:
            tracker.reset(T_gt, stamp_ns=stamp)
        s = {n_: tuple(float(v) for v in ref.scale(n_)) for n_ in ref.names}
        run.frames.append(FrameRecord(
            stamp, t_err, r_err, lost, res.source, s["sun"], s["sky"], s["ground"],  # type: ignore[arg-type]
            1e3 * res.seconds.get("f2f", 0.0), 1e3 * ref.seconds["render"], 1e3 * ref.seconds["estimate"],
            1e3 * res.seconds.get("f2m", 0.0)))
        run.T_est.append(res.T_map_cam)
        run.T_gt.append(T_gt)
    if not run.frames:
        raise DaylightEvalError(f"{seq_dir}: no complete frames (colour + depth + camera_info + ground truth) in "
                                "the bag")
    return run


# ----------------------------------------------------------------------------------------------------------------
# the whole evaluation


def scene_lighting_map(scene: str, sim_dir: Path, maps_dir: Path, progress: bool,
                       config: LightingMapConfig | None = None) -> LightingMap:
    """The scene's lighting map, prepared once into ``maps_dir/<scene>`` (reused while the mesh is unchanged)."""
    from lightfast.daylight.errors import LightingMapVersionError
    from lightfast.daylight.lighting_map import prepare_lighting_map
    from lightfast.daylight.mesh import load_ply
    from lightfast.daylight.openings import load_openings, openings_array
    from lightfast.daylight.sun import Site

    out = maps_dir / scene
    mesh_path, site_path = sim_dir / "scenes" / f"{scene}.map.ply", sim_dir / "scenes" / f"{scene}.site.yaml"
    openings_path = sim_dir / "scenes" / f"{scene}.openings.yaml"
    openings = load_openings(openings_path) if openings_path.exists() else ()
    stale = False
    if out.exists():
        try:
            lmap = LightingMap.load(out)
        except LightingMapVersionError as exc:  # made by an older lightfast: prepare it again below
            log.warning("%s; preparing it again", exc)
            stale = True
    if out.exists() and not stale:
        if lmap.mesh.content_hash != load_ply(mesh_path).content_hash:
            raise DaylightEvalError(f"{out} was prepared for another {scene} mesh; remove it to prepare it again")
        if not np.array_equal(lmap.openings, openings_array(openings)):
            raise DaylightEvalError(f"{out} was prepared with other window openings than {openings_path}; remove it "
                                    "to prepare it again")
        return lmap
    log.info("preparing the lighting map of %s into %s", scene, out)
    lmap = prepare_lighting_map(load_ply(mesh_path), Site.from_yaml(site_path), config or LightingMapConfig(),
                                openings=openings, progress=progress)
    lmap.save(out, overwrite=stale)
    return lmap


def _write_csv(path: Path, runs: Sequence[SequenceRun]) -> None:
    import io

    buf = io.StringIO()
    names = [f.name for f in FrameRecord.__dataclass_fields__.values()]
    w = csv.writer(buf)
    w.writerow(["sequence", "method", "frame", *names])
    for run in runs:
        for i, f in enumerate(run.frames):
            row = asdict(f)
            w.writerow([run.sequence, run.method, i, *[_csv_value(row[k]) for k in names]])
    write_text_atomic(path, buf.getvalue())


def _csv_value(v: object) -> object:
    """Six significant digits for floats (µm and µs are below what the evaluation resolves), tuples space-joined."""
    if isinstance(v, tuple):
        return " ".join(f"{x:.6g}" for x in v)
    return f"{v:.6g}" if isinstance(v, float) else v


def table_markdown(runs: Sequence[SequenceRun], methods: Sequence[str]) -> str:
    seqs = sorted({r.sequence for r in runs})
    by = {(r.sequence, r.method): r for r in runs}
    lines = ["| sequence | " + " | ".join(methods) + " |", "|---|" + "---|" * len(methods)]
    for s in seqs:
        cells = []
        for m in methods:
            r = by.get((s, m))
            cells.append("—" if r is None else f"{r.rmse_m:.4f} m / {100 * r.loss_ratio:.2f} %")
        lines.append(f"| {s} | " + " | ".join(cells) + " |")
    avg = []
    for m in methods:
        rs = [by[(s, m)] for s in seqs if (s, m) in by]
        avg.append("—" if not rs else f"**{np.nanmean([r.rmse_m for r in rs]):.4f} m / "
                   f"{100 * np.mean([r.loss_ratio for r in rs]):.2f} %**")
    lines.append("| **average** | " + " | ".join(avg) + " |")
    return "\n".join(lines) + "\n"


def _plots(out: Path, runs: Sequence[SequenceRun], sim_dir: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure

    written: list[Path] = []

    def save(fig: Figure, name: str) -> None:
        fig.tight_layout()
        p = out / name
        fig.savefig(p, dpi=80)
        plt.close(fig)
        written.append(p)

    seqs = sorted({r.sequence for r in runs})
    methods = list(dict.fromkeys(r.method for r in runs))
    by = {(r.sequence, r.method): r for r in runs}
    # per-frame translation error and trajectories
    fig, axes = plt.subplots(len(seqs), 2, figsize=(12, 2.6 * len(seqs)), squeeze=False)
    for row, s in enumerate(seqs):
        for m in methods:
            r = by.get((s, m))
            if r is None:
                continue
            e = np.array([f.t_err_m for f in r.frames])
            axes[row, 0].plot(100 * e, lw=0.8, label=m)
            T = np.array(r.T_est)
            axes[row, 1].plot(T[:, 0, 3], T[:, 1, 3], lw=0.8, label=m)
        gt = np.array(next(by[(s, m)] for m in methods if (s, m) in by).T_gt)
        axes[row, 1].plot(gt[:, 0, 3], gt[:, 1, 3], "k--", lw=1.0, label="ground truth")
        axes[row, 0].set_ylabel(f"{s}\nerror [cm]")
        axes[row, 0].axhline(100 * LOSS_TRANSLATION_M, color="r", lw=0.5)
        axes[row, 1].set_aspect("equal", adjustable="datalim")
    axes[0, 0].legend(fontsize=7, ncol=3)
    axes[0, 1].legend(fontsize=7)
    axes[-1, 0].set_xlabel("frame")
    axes[-1, 1].set_xlabel("x [m] (top view)")
    save(fig, "daylight_tracking.png")
    # estimated vs true brightness (proposed) for the cloudy sequences and one clear one
    shown = [s for s in seqs if s.endswith("T6")] + [s for s in seqs if s.endswith("T1")]
    if shown and any((s, "proposed") in by for s in shown):
        fig, axes = plt.subplots(len(shown), 1, figsize=(9, 2.8 * len(shown)), squeeze=False)
        for ax, s in zip(axes[:, 0], shown, strict=True):
            r = by.get((s, "proposed"))
            if r is None:
                continue
            true = _true_sun(sim_dir / s)
            est = np.array([f.scale_sun[1] for f in r.frames])
            n = min(len(est), len(true))
            k = float(np.dot(est[:n], true[:n]) / max(np.dot(true[:n], true[:n]), 1e-30))
            ax.plot(est[:n], label="estimated s_sun (G, 30-frame average)")
            ax.plot(k * true[:n], "--", label=f"true sun irradiance (G) x {k:.3g}")
            ax.set_ylabel(s)
            ax.legend(fontsize=7)
        axes[-1, 0].set_xlabel("frame")
        save(fig, "daylight_brightness.png")
    return written


def _true_sun(seq_dir: Path) -> NDArray[np.float64]:
    with open(seq_dir / "truth.csv") as fh:
        return np.array([float(row["sun_g"]) for row in csv.DictReader(fh)])


def brightness_correlation(run: SequenceRun, seq_dir: Path) -> float:
    """Pearson correlation of the estimated sun scale (G) with the simulator's sun irradiance over the run."""
    true = _true_sun(seq_dir)
    est = np.array([f.scale_sun[1] for f in run.frames])
    n = min(len(est), len(true))
    if n < 3 or np.std(true[:n]) == 0 or np.std(est[:n]) == 0:
        return math.nan
    return float(np.corrcoef(est[:n], true[:n])[0, 1])


def evaluate_daylight(sim_dir: Path, out_dir: Path, *, methods: Sequence[str] = tuple(METHODS),
                      sequences: Sequence[str] | None = None, maps_dir: Path | None = None,
                      max_frames: int | None = None, progress: bool = True, jobs: int = 1,
                      map_config: LightingMapConfig | None = None, tracker_config: TrackerConfig | None = None,
                      inputs: InputChange = InputChange(),
                      on_run: Callable[[SequenceRun], None] | None = None) -> list[SequenceRun]:
    """Run ``methods`` over the recordings in ``sim_dir`` and write ``daylight_table.md``, ``daylight_frames.csv``,
    ``daylight_summary.json`` and PNG plots into ``out_dir``. ``tracker_config``: the tracker's parameters (the
    node's defaults if None); each method sets only its ``mode``. ``inputs``: what-if changes to the recordings
    (:class:`InputChange`; none by default)."""
    for m in methods:
        if m not in METHODS:
            raise DaylightEvalError(f"unknown method {m!r}; choose from {', '.join(METHODS)}")
    seq_dirs = sorted(p for p in sim_dir.iterdir() if (p / "sequence.json").exists()) if sim_dir.is_dir() else []
    if sequences:
        wanted = set(sequences)
        seq_dirs = [p for p in seq_dirs if p.name in wanted]
        missing = wanted - {p.name for p in seq_dirs}
        if missing:
            raise DaylightEvalError(f"recordings not found in {sim_dir}: {', '.join(sorted(missing))}")
    if not seq_dirs:
        raise DaylightEvalError(f"no recordings in {sim_dir} (make them with `lightfast sim daylight {sim_dir}`)")
    maps_dir = maps_dir or sim_dir / "maps"
    out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cfg_dict = None if map_config is None else dataclasses.asdict(map_config)
    tracker_dict = None if tracker_config is None else tracker_config.to_dict()
    map_meta = {}
    for scene in dict.fromkeys(scene_of(s) for s in seq_dirs):
        meta_path = maps_dir / scene / "metadata.json"
        current = meta_path.exists() and json.loads(meta_path.read_text()).get("version") == MAP_FORMAT_VERSION
        if not current:  # prepare once (or again, if an older lightfast made it) before the workers load it
            scene_lighting_map(scene, sim_dir, maps_dir, progress, map_config)
        map_meta[scene] = json.loads((maps_dir / scene / "metadata.json").read_text())
    runs: list[SequenceRun] = []
    todo = []
    for seq in seq_dirs:
        for m in methods:
            key = _run_key(seq, m, map_meta[scene_of(seq)], max_frames, tracker_config, inputs)
            stored = _load_run(out_dir, seq.name, m, key)
            if stored is not None:
                runs.append(stored)
            else:
                todo.append(((str(seq), m, str(maps_dir), max_frames, str(sim_dir), cfg_dict, tracker_dict,
                              asdict(inputs)), key))
    if runs:
        log.info("%d of %d runs reused from %s", len(runs), len(runs) + len(todo), out_dir / "runs")

    def finished(run: SequenceRun, key: str) -> None:
        _save_run(out_dir, run, key)
        runs.append(run)
        _write_outputs(out_dir, runs, list(methods), [p.name for p in seq_dirs], sim_dir,
                       time.perf_counter() - t0)  # partial results survive an interruption
        log.info("%s %s: RMSE %.4f m, loss %.2f %%", run.sequence, run.method, run.rmse_m, 100 * run.loss_ratio)
        if on_run is not None:
            on_run(run)

    if jobs <= 1:
        for job, key in track(todo, desc="daylight evaluation", enabled=progress, unit="run"):
            finished(_run_job(job), key)
    elif todo:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn")) as pool:
            done = pool.map(_run_job, [job for job, _ in todo])
            for run, (_, key) in track(zip(done, todo, strict=True), desc="daylight evaluation", total=len(todo),
                                       enabled=progress, unit="run"):
                finished(run, key)
    order = {(p.name, m): i for i, (p, m) in enumerate((p, m) for p in seq_dirs for m in methods)}
    runs.sort(key=lambda r: order[(r.sequence, r.method)])
    _write_outputs(out_dir, runs, list(methods), [p.name for p in seq_dirs], sim_dir, time.perf_counter() - t0)
    return runs


def scene_of(seq_dir: Path) -> str:
    """The scene name a simulated recording was made in."""
    return str(json.loads((seq_dir / "sequence.json").read_text())["sequence"]["scene"])


#: The code a run executes (its version is part of the run's key).
CODE = ("daylight", "tracking", "eval/daylight.py", "eval/daylight_inputs.py", "bag", "geometry", "camera.py",
        "raycast.py", "config.py")


def _run_key(seq_dir: Path, method: str, map_meta: dict, max_frames: int | None,
             tracker_config: TrackerConfig | None = None, inputs: InputChange = InputChange()) -> str:
    """A hash of everything that decides one run's outcome (:mod:`lightfast.eval.cache`)."""
    tracker_cfg, relight_cfg = method_configs(method, tracker_config)
    parts = {
        "protocol": PROTOCOL_VERSION,
        "recording": content_digest(seq_dir),  # every file: another seed or simulator version is another input
        "code": code_version(*CODE),
        "map": {k: map_meta.get(k) for k in ("mesh_sha256", "config", "site", "version")},
        "method": method,
        "tracker": dataclasses.asdict(tracker_cfg),
        "relight": dataclasses.asdict(relight_cfg),
        "max_frames": max_frames,
    }
    if inputs != InputChange():  # the recording as it is keeps the keys of runs stored before this option existed
        parts["inputs"] = asdict(inputs)
    return run_key(parts)


def _run_path(out_dir: Path, sequence: str, method: str) -> Path:
    return out_dir / "runs" / f"{sequence}.{method}.json"


def _save_run(out_dir: Path, run: SequenceRun, key: str) -> None:
    doc = {"key": key, "sequence": run.sequence, "method": run.method,
           "frames": [asdict(f) for f in run.frames],
           "T_est": [np.round(T, 9).reshape(-1).tolist() for T in run.T_est],
           "T_gt": [np.round(T, 9).reshape(-1).tolist() for T in run.T_gt]}
    path = _run_path(out_dir, run.sequence, run.method)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, json.dumps(doc) + "\n")


def _frame_record(doc: dict[str, Any]) -> FrameRecord:
    """A :class:`FrameRecord` from its JSON form (lists back to tuples)."""
    fields: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in doc.items()}
    return FrameRecord(**fields)


def _load_run(out_dir: Path, sequence: str, method: str, key: str) -> SequenceRun | None:
    """The stored run if it exists and has ``key``; None otherwise (also for a damaged file: it is redone)."""
    path = _run_path(out_dir, sequence, method)
    try:
        doc = json.loads(path.read_text())
        if doc.get("key") != key:
            return None
        frames = [_frame_record(f) for f in doc["frames"]]
        return SequenceRun(sequence, method, frames, [np.array(T).reshape(4, 4) for T in doc["T_est"]],
                           [np.array(T).reshape(4, 4) for T in doc["T_gt"]])
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        log.warning("%s is damaged (%s); running it again", path, exc)
        return None


def _write_outputs(out_dir: Path, runs: Sequence[SequenceRun], methods: list[str], sequences: list[str],
                   sim_dir: Path, seconds: float) -> None:
    summary = {
        "methods": methods,
        "sequences": sequences,
        "seconds": seconds,
        "runs": [{"sequence": r.sequence, "method": r.method, "frames": len(r.frames), "rmse_m": r.rmse_m,
                  "loss_ratio": r.loss_ratio,
                  "brightness_correlation": brightness_correlation(r, sim_dir / r.sequence),
                  "median_ms": {k: float(np.median([getattr(f, f"ms_{k}") for f in r.frames]))
                                for k in ("f2f", "render", "estimate", "f2m")}} for r in runs],
    }
    write_text_atomic(out_dir / "daylight_table.md", table_markdown(runs, methods))
    _write_csv(out_dir / "daylight_frames.csv", runs)
    write_text_atomic(out_dir / "daylight_summary.json", json.dumps(summary, indent=1) + "\n")
    _plots(out_dir, runs, sim_dir)


def _run_job(job: tuple[str, str, str, int | None, str, dict | None, dict | None, dict]) -> SequenceRun:
    """Worker of ``--jobs``: one (recording, method) run in its own process."""
    seq_dir, method, maps_dir, max_frames, sim_dir, map_config, tracker, inputs = job
    seq = Path(seq_dir)
    scene = json.loads((seq / "sequence.json").read_text())["sequence"]["scene"]
    lmap = _cached_map(scene, Path(sim_dir), Path(maps_dir), map_config)
    return run_sequence(seq, lmap, method, max_frames=max_frames, progress=False, sun_B=_cached_sun(seq, lmap),
                        tracker_config=None if tracker is None else config_from_mapping(TrackerConfig, tracker),
                        inputs=InputChange(**inputs))


_MAPS: dict[str, LightingMap] = {}
_SUNS: dict[str, NDArray[np.float32]] = {}


def _cached_map(scene: str, sim_dir: Path, maps_dir: Path, map_config: dict | None) -> LightingMap:
    if scene not in _MAPS:
        _MAPS.clear()
        _SUNS.clear()
        cfg = None if map_config is None else LightingMapConfig(**map_config)
        _MAPS[scene] = scene_lighting_map(scene, sim_dir, maps_dir, False, cfg)
    return _MAPS[scene]


def _cached_sun(seq: Path, lmap: LightingMap) -> NDArray[np.float32]:
    if seq.name not in _SUNS:
        _SUNS[seq.name] = sequence_sun_radiosity(seq, lmap)
    return _SUNS[seq.name]
