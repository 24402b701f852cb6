"""The VT&R field-trial evaluation of paper §VI (Table I, Fig. 7) on the simulated day schedule: ``lightfast eval vtr``.

Input: a directory written by ``lightfast sim vtr`` (one teach run and any number of repeats; see
:mod:`lightfast.sim.vtr_recordings`). Protocol:

1. **Teach once** from the teach run with the parameters of ``vtr_localizer_node``
   (:class:`~lightfast.vtr.localizer_config.VtrLocalizerConfig` defaults: :meth:`teach_config`,
   :meth:`stereo_config`): every stereo pair through :class:`~lightfast.vtr.teach.TeachPipeline`, the map written
   into ``MAPS/teach-<key>`` (default ``SIM_DIR/vtr_maps``) and reused while the teach run and the parameters are
   unchanged.
2. **Repeat** every repeat run in every mode (``fused``, ``grey``, ``mcmanus``) in-process through
   :meth:`lightfast.vtr.repeat.RepeatPipeline.step` — the call ``vtr_localizer_node`` makes per stereo pair — with
   the node's repeat parameters (its ``repeat`` section). The method sees the bag's rgb8 images and the
   ``camera_info`` projection matrices only; the first frame starts with the whole-map search, as a node does.
3. **Score** with the ground truth (``truth.csv``; read here only):

   * *distance*: the true path length of the left camera between consecutive frames;
   * *autonomy by distance* (the paper's Table I metric, §VI-A): the share of the route driven without a
     localization failure. A failure is declared by the method after 20 m on VO alone (§IV-C); the robot "stops"
     and searches the whole map, and the distance it then covers until it relocalizes would be driven manually
     (offline the recording goes on). The frames flagged ``failure`` by
     :class:`~lightfast.vtr.repeat.RepeatResult` — from the declaration through the relocalizing frame, and the
     frames before the first localization — therefore count as manual distance:
     autonomy = 1 − manual distance / distance;
   * *distance on VO* (§VI-B, Fig. 7): the true distance driven since the last successful localization, per
     frame; its distribution over the traverse is the CDF "for Y % of the traverse, the robot drove less than X m
     on VO" (weighted by distance);
   * *localization error*: the estimated ``T_kf_cam`` against the truth ``inv(T_map_kf) · T_map_cam`` (the
     keyframe's truth = the teach run's truth at the keyframe's stamp), translation (m) and rotation (deg), on
     localized frames and on all frames with a pose; localizations off by more than 1 m are counted as gross.

Outputs in ``OUT`` (rewritten after every finished run, so an interrupted evaluation leaves valid partial
results; a finished (run, mode) is kept in ``OUT/runs/`` (or ``--keep DIR``) and skipped when the evaluation is
started again with the same inputs and parameters): ``vtr_table.md`` (Table I style), ``vtr_runs.csv`` (one row per
run and mode),
``vtr_frames.csv`` (per frame: inliers and matches per source, distance on VO, failure state, error),
``vtr_summary.json``, ``vtr_cdf.png`` (Fig. 7 style, every repeat), ``vtr_cdf_fig7.png`` (repeats 4 and 7 as in
the paper's figure, when evaluated) and ``vtr_inliers.png`` (inliers per source along the route: the diagnostic
trace).
"""
from __future__ import annotations

import csv
import hashlib
import io
import json
import logging
import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lightfast.bag.reader import open_bag
from lightfast.config import config_from_mapping, replace_config
from lightfast.eval.errors import VtrEvalError
from lightfast.geometry import quat_to_matrix, rotation_angle_deg
from lightfast.io import write_text_atomic
from lightfast.progress import track
from lightfast.vtr.localizer_config import VtrLocalizerConfig
from lightfast.vtr.map_store import MapStore, TeachMap
from lightfast.vtr.repeat import MODES, RepeatPipeline
from lightfast.vtr.teach import TeachPipeline

__all__ = [
    "EVAL_FORMAT",
    "GROSS_ERROR_M",
    "FrameRecord",
    "RepeatRun",
    "evaluate_vtr",
    "run_repeat",
    "teach_map",
]

log = logging.getLogger(__name__)

#: Bump when the per-run results change meaning (invalidates the results kept in ``OUT/runs``).
EVAL_FORMAT = 1
#: A localization farther than this from the truth is counted as gross (m).
GROSS_ERROR_M = 1.0
#: The image sources whose inliers are reported (every mode uses a subset).
REPORTED_SOURCES = ("grey", "fv", "fr")
#: The runs of the paper's Fig. 7.
FIG7_RUNS = ("repeat04", "repeat07")
_STEREO_TOPICS = ("/stereo/left/image_raw", "/stereo/right/image_raw", "/stereo/left/camera_info",
                  "/stereo/right/camera_info")


# ----------------------------------------------------------------------------------------------------------------
# inputs


@dataclass(frozen=True)
class SimRun:
    """One run directory of ``lightfast sim vtr`` (its ``run.json`` is truth-side metadata)."""

    name: str
    path: Path
    info: dict[str, Any]

    @property
    def kind(self) -> str:
        return str(self.info["run"]["kind"])


def sim_runs(sim_dir: Path) -> list[SimRun]:
    """The complete runs in ``sim_dir`` (those with a ``run.json``), ordered by date and start time."""
    if not sim_dir.is_dir():
        raise VtrEvalError(f"no simulation directory at {sim_dir} (make one with `lightfast sim vtr {sim_dir}`)")
    runs = []
    for p in sorted(sim_dir.iterdir()):
        info_path = p / "run.json"
        if p.is_dir() and info_path.is_file():
            try:
                info = json.loads(info_path.read_text())
                if not all(isinstance(info["run"][k], str) for k in ("kind", "date", "start")):
                    raise TypeError("run kind, date and start must be strings")
            except (OSError, ValueError, KeyError, TypeError) as exc:
                raise VtrEvalError(f"{info_path} is unreadable: {exc}") from exc
            runs.append(SimRun(p.name, p, info))
    runs.sort(key=lambda r: (r.info["run"]["date"], r.info["run"]["start"], r.name))
    return runs


def stereo_frames(bag_dir: Path) -> Iterator[tuple[int, NDArray[np.uint8], NDArray[np.uint8], NDArray[np.float64],
                                                   NDArray[np.float64]]]:
    """(stamp_ns, left rgb, right rgb, P_left, P_right) per stereo pair of a bag, paired by exact stamp — what the
    node receives (no ground truth)."""
    from lightfast.ros.convert import image_to_numpy

    parts: dict[int, dict[str, Any]] = {}
    left_img, right_img, left_info, right_info = _STEREO_TOPICS
    with open_bag(bag_dir) as bag:
        for m in bag.messages(topics=_STEREO_TOPICS):
            msg = bag.deserialize(m)
            stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
            p = parts.setdefault(stamp, {})
            if m.topic in (left_img, right_img):
                if msg.encoding != "rgb8":
                    raise VtrEvalError(f"{bag_dir}: {m.topic} has encoding {msg.encoding}, expected rgb8")
                p[m.topic] = np.array(image_to_numpy(msg))
            else:
                p[m.topic] = np.asarray(msg.p, dtype=np.float64).reshape(3, 4)
            if len(p) == 4:
                del parts[stamp]
                yield stamp, p[left_img], p[right_img], p[left_info], p[right_info]


@dataclass(frozen=True)
class Truth:
    """A run's ground truth per stamp (from ``truth.csv``): left camera poses ``T_map_cam`` and route position."""

    stamp_ns: NDArray[np.int64]
    T_map_cam: NDArray[np.float64]
    s_m: NDArray[np.float64]
    sun_elevation_deg: NDArray[np.float64]

    def index(self, stamp_ns: int) -> int:
        i = int(np.searchsorted(self.stamp_ns, stamp_ns))
        if i >= self.stamp_ns.size or self.stamp_ns[i] != stamp_ns:
            raise VtrEvalError(f"no ground truth for stamp {stamp_ns}")
        return i


def load_truth(run_dir: Path) -> Truth:
    path = run_dir / "truth.csv"
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
        stamps = np.array([int(r["stamp_ns"]) for r in rows], np.int64)
        T = np.tile(np.eye(4), (len(rows), 1, 1))
        for i, r in enumerate(rows):
            T[i, :3, :3] = quat_to_matrix([float(r[k]) for k in ("qx", "qy", "qz", "qw")])
            T[i, :3, 3] = [float(r["x_m"]), float(r["y_m"]), float(r["z_m"])]
        s = np.array([float(r["s_m"]) for r in rows])
        el = np.array([float(r["sun_elevation_deg"]) for r in rows])
    except (OSError, KeyError, ValueError) as exc:
        raise VtrEvalError(f"{path} is unreadable: {exc}") from exc
    order = np.argsort(stamps, kind="stable")
    return Truth(stamps[order], T[order], s[order], el[order])


# ----------------------------------------------------------------------------------------------------------------
# teach


def _key(*parts: object) -> str:
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _teach_key(teach: SimRun, config: VtrLocalizerConfig) -> str:
    return _key("teach", EVAL_FORMAT, teach.info.get("params_hash"), teach.info.get("frames"),
                config.teach.to_dict(), config.stereo.to_dict())


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
    tp = TeachPipeline(path, config.teach, stereo=config.stereo, overwrite=True)
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


# ----------------------------------------------------------------------------------------------------------------
# repeat


@dataclass(frozen=True)
class FrameRecord:
    """One repeat frame: the method's output and its score against the truth (see the module docstring)."""

    frame: int
    stamp_ns: int
    s_m: float  # truth: position along the route
    step_m: float  # truth: distance driven since the previous frame
    sun_elevation_deg: float
    localized: bool
    failure: bool
    relocalized: bool
    searched_map: bool
    keyframe: int
    inliers_grey: int
    inliers_fv: int
    inliers_fr: int
    matches_grey: int
    matches_fv: int
    matches_fr: int
    vo_success: bool
    distance_on_vo_m: float  # the method's own (VO) distance since the last localization
    vo_truth_m: float  # truth: distance driven since the last localization
    error_m: float  # translation error of T_kf_cam (NaN without a pose)
    error_deg: float
    ms_total: float
    ms_front_end: float
    ms_vo: float
    ms_localization: float
    ms_search: float


@dataclass
class RepeatRun:
    """A repeat run in one mode: its frames and the run's schedule entry (``info``: date, start, weather)."""

    run: str
    mode: str
    info: dict[str, Any] = field(default_factory=dict)
    frames: list[FrameRecord] = field(default_factory=list)
    failures: int = 0  # localization failures declared (entries into the failure state)
    seconds: float = 0.0

    def _col(self, name: str) -> NDArray[Any]:
        return np.array([getattr(f, name) for f in self.frames])

    @property
    def distance_m(self) -> float:
        return float(self._col("step_m").sum()) if self.frames else 0.0

    @property
    def manual_m(self) -> float:
        if not self.frames:
            return 0.0
        return float(self._col("step_m")[self._col("failure").astype(bool)].sum())

    @property
    def autonomy(self) -> float:
        d = self.distance_m
        return 1.0 - self.manual_m / d if d > 0 else math.nan

    @property
    def max_vo_m(self) -> float:
        return float(self._col("vo_truth_m").max()) if self.frames else math.nan

    @property
    def localized_share(self) -> float:
        return float(self._col("localized").mean()) if self.frames else math.nan

    def errors(self, localized_only: bool = True) -> NDArray[np.float64]:
        e = self._col("error_m").astype(float)
        if localized_only:
            e = e[self._col("localized").astype(bool)]
        return e[np.isfinite(e)]

    def summary(self) -> dict[str, Any]:
        e = self.errors()
        e_all = self.errors(localized_only=False)
        loc = self._col("localized").astype(bool) if self.frames else np.zeros(0, bool)
        out: dict[str, Any] = {
            "run": self.run, "mode": self.mode, "date": self.info.get("date"), "start": self.info.get("start"),
            "weather": self.info.get("weather"), "summary": self.info.get("summary"),
            "frames": len(self.frames), "distance_m": self.distance_m, "manual_m": self.manual_m,
            "autonomy": self.autonomy, "failures": self.failures, "max_vo_m": self.max_vo_m,
            "localized_share": self.localized_share,
            "error_m_median": float(np.median(e)) if e.size else None,
            "error_m_p95": float(np.percentile(e, 95)) if e.size else None,
            "error_m_max": float(e.max()) if e.size else None,
            "error_all_m_median": float(np.median(e_all)) if e_all.size else None,
            "error_all_m_p95": float(np.percentile(e_all, 95)) if e_all.size else None,
            "gross_localizations": int(np.count_nonzero(e > GROSS_ERROR_M)),
            "sun_elevation_deg": [float(self._col("sun_elevation_deg")[0]), float(self._col("sun_elevation_deg")[-1])]
            if self.frames else None,
            "seconds": self.seconds,
        }
        for s in REPORTED_SOURCES:
            ins = self._col(f"inliers_{s}")[loc] if self.frames else np.zeros(0)
            out[f"inliers_{s}_median"] = float(np.median(ins)) if ins.size else None
        ms = self._col("ms_total") if self.frames else np.zeros(0)
        out["ms_median"] = float(np.median(ms[1:])) if ms.size > 1 else None
        return out

    def to_json(self) -> dict[str, Any]:
        cols = {f.name: [getattr(fr, f.name) for fr in self.frames] for f in fields(FrameRecord)}
        return {"run": self.run, "mode": self.mode, "info": self.info, "failures": self.failures,
                "seconds": self.seconds, "frames": cols}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> RepeatRun:
        cols = d["frames"]
        names = [f.name for f in fields(FrameRecord)]
        n = len(cols["frame"])
        frames = [FrameRecord(**{k: _from_json(cols[k][i]) for k in names}) for i in range(n)]
        return cls(d["run"], d["mode"], dict(d["info"]), frames, int(d["failures"]), float(d["seconds"]))


def _from_json(v: Any) -> Any:
    return math.nan if v is None else v


def _json_safe(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    if isinstance(v, np.generic):
        return _json_safe(v.item())
    return v


def run_repeat(run: SimRun, tmap: TeachMap, teach_truth: Truth, mode: str, *,
               config: VtrLocalizerConfig | None = None, max_frames: int | None = None,
               progress: bool = False) -> RepeatRun:
    """One repeat run in one mode (module docstring, steps 2–3)."""
    if mode not in MODES:
        raise VtrEvalError(f"unknown mode {mode!r}; choose from {', '.join(MODES)}")
    cfg = replace_config(config or VtrLocalizerConfig(), {"repeat.mode": mode})
    truth = load_truth(run.path)
    kf_T = np.stack([teach_truth.T_map_cam[teach_truth.index(kf.stamp_ns)] for kf in tmap.keyframes])
    rp = RepeatPipeline(tmap, cfg.repeat)
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
            if i == 0 and ((left.shape[1], left.shape[0]) != tmap.image_size
                           or not (np.allclose(Pl, tmap.P_left) and np.allclose(Pr, tmap.P_right))):
                raise VtrEvalError(f"{run.name}: the camera differs from the teach map's")
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


# ----------------------------------------------------------------------------------------------------------------
# outputs


def _pct(x: float) -> str:
    if not math.isfinite(x):
        return "—"
    if x >= 1.0:
        return "100 %"
    return f"{100 * math.floor(x * 1000) / 1000:.1f} %" if x >= 0.99 else f"{100 * x:.1f} %"


def overall(runs: Sequence[RepeatRun], mode: str) -> dict[str, Any]:
    """Autonomy by distance over all repeats of a mode (distance-weighted), failures, worst distance on VO."""
    rs = [r for r in runs if r.mode == mode]
    dist = sum(r.distance_m for r in rs)
    manual = sum(r.manual_m for r in rs)
    return {"mode": mode, "runs": len(rs), "distance_m": dist, "manual_m": manual,
            "autonomy": 1.0 - manual / dist if dist > 0 else math.nan, "failures": sum(r.failures for r in rs),
            "max_vo_m": max((r.max_vo_m for r in rs), default=math.nan),
            "gross_localizations": sum(int(np.count_nonzero(r.errors() > GROSS_ERROR_M)) for r in rs)}


def table_markdown(runs: Sequence[RepeatRun], modes: Sequence[str], run_order: Sequence[str]) -> str:
    """Table I style: one row per repeat, per mode autonomy by distance (and the longest distance on VO)."""
    by = {(r.run, r.mode): r for r in runs}
    lines = ["| Action | Day | Start | Summary | sun elevation | distance | "
             + " | ".join(f"{m}: autonomy (max on VO)" for m in modes) + " |",
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
            cells.append("—" if r is None else f"{_pct(r.autonomy)} ({r.max_vo_m:.1f} m)")
        lines.append(f"| {name} | {r0.info.get('date', '')} | {r0.info.get('start', '')} | {summ} | "
                     f"{el[0]:.0f}° → {el[1]:.0f}° | {r0.distance_m:.0f} m | " + " | ".join(cells) + " |")
    cells = []
    n_rows = len({r.run for r in runs})
    for m in modes:
        o = overall(runs, m)
        part = "" if o["runs"] == n_rows else f" [{o['runs']} of {n_rows} repeats]"
        cells.append("—" if not o["runs"] else f"**{_pct(o['autonomy'])}** ({o['max_vo_m']:.1f} m){part}")
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
        out.append(f"Fused (paper's method): autonomy by distance {100 * o['autonomy']:.2f} % over "
                   f"{o['distance_m']:.0f} m of repeats ({o['failures']} localization failures, longest distance on "
                   f"VO {o['max_vo_m']:.1f} m, {o['gross_localizations']} gross localizations) — goal ≥ 99.9 % "
                   f"{'met' if o['autonomy'] >= 0.999 else 'NOT met'}.")
    for m in modes:
        if m == "fused" or not any(r.mode == m for r in runs):
            continue
        o = overall(runs, m)
        failed = [r.run for r in runs if r.mode == m and r.failures > 0]
        n_rows = len({r.run for r in runs})
        part = "" if o["runs"] == n_rows else f" (evaluated on {o['runs']} of the {n_rows} repeats only)"
        out.append(f"{m}: autonomy by distance {100 * o['autonomy']:.2f} %, {o['failures']} localization failures"
                   f"{part}; repeats with a failure: {', '.join(failed) if failed else 'none'}.")
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


def cdf(run: RepeatRun) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Distance on VO (truth) sorted, and the share of the traverse (by distance) driven with at most that much on
    VO: "for Y % of the traverse, the robot drove less than X m on VO" (Fig. 7)."""
    x = np.array([f.vo_truth_m for f in run.frames])
    w = np.array([f.step_m for f in run.frames])
    order = np.argsort(x, kind="stable")
    x, w = x[order], w[order]
    total = w.sum()
    y = np.cumsum(w) / total if total > 0 else np.linspace(0, 1, x.size)
    return x, y


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
    write_text_atomic(out_dir / "vtr_summary.json", json.dumps(_json_safe(summary), indent=1) + "\n")
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


# ----------------------------------------------------------------------------------------------------------------
# the whole evaluation


def _job_key(run: SimRun, mode: str, map_key: str, config: VtrLocalizerConfig, max_frames: int | None) -> str:
    return _key("repeat", EVAL_FORMAT, run.info.get("params_hash"), run.info.get("frames"), mode, map_key,
                replace_config(config, {"repeat.mode": mode}).repeat.to_dict(), max_frames)


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
        "sim_dir": str(sim_dir), "teach": teach.name, "map": str(maps_dir / f"teach-{map_key}"),
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
                          json.dumps(_json_safe({"key": key, "result": res.to_json()})) + "\n")
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
