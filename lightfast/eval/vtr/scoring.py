"""The scores of the VT&R evaluation (paper §VI, Table I, Fig. 7): per-frame records of a repeat and their metrics.

A :class:`FrameRecord` holds the method's output for one stereo pair (localized, failure state, keyframe, inliers
and matches per image source, VO, timings in ms) next to the truth; a :class:`RepeatRun` is one repeat run in one
mode. From the ground truth:

* *distance*: the true path length of the left camera between consecutive frames (m);
* *autonomy by distance* (Table I, §VI-A): the share of the route driven without a localization failure. A failure
  is declared by the method after 20 m on VO alone (§IV-C); the robot "stops" and searches the whole map, and the
  distance it then covers until it relocalizes would be driven manually (offline the recording goes on). The frames
  flagged ``failure`` by :class:`~lightfast.vtr.repeat.RepeatResult` — from the declaration through the
  relocalizing frame, and the frames before the first localization — count as manual distance:
  autonomy = 1 − manual distance / distance (:meth:`RepeatRun.autonomy`; over several runs :func:`overall`) — the
  published score, which counts any localization as autonomy. *Strict autonomy* also counts as manual every frame
  whose estimate is more than ``GROSS_ERROR_M`` (1 m) from the truth or missing (:meth:`RepeatRun.strict_autonomy`):
  a robot driving on a wrong pose is not driving autonomously. *False accepts*: frames on which the whole-map search
  accepted a place more than ``FALSE_ACCEPT_M`` (5 m) from the truth;
* *distance on VO* (§VI-B, Fig. 7): the true distance driven since the last successful localization, per frame; its
  distribution over the traverse, weighted by distance, is the CDF "for Y % of the traverse, the robot drove less
  than X m on VO" (:func:`cdf`);
* *localization error*: the estimated ``T_kf_cam`` against the truth ``inv(T_map_kf) · T_map_cam`` (the keyframe's
  truth = the teach run's truth at the keyframe's stamp), translation (m) and rotation (deg), on localized frames
  and on all frames with a pose; localizations off by more than ``GROSS_ERROR_M`` (1 m) are counted as gross.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: A localization farther than this from the truth is counted as gross, and the distance driven on it as manual in
#: the strict score (m).
GROSS_ERROR_M = 1.0
#: A place accepted by the whole-map search farther than this from the truth is a false accept (m).
FALSE_ACCEPT_M = 5.0
#: The image sources whose inliers are reported (every mode uses a subset).
REPORTED_SOURCES = ("grey", "fv", "fr")


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
    def manual_strict_m(self) -> float:
        """Distance in the failure state or on an estimate more than ``GROSS_ERROR_M`` off (or none)."""
        if not self.frames:
            return 0.0
        err = self._col("error_m").astype(float)
        off = ~(err <= GROSS_ERROR_M)  # NaN (no estimate) counts as off
        return float(self._col("step_m")[self._col("failure").astype(bool) | off].sum())

    @property
    def strict_autonomy(self) -> float:
        d = self.distance_m
        return 1.0 - self.manual_strict_m / d if d > 0 else math.nan

    @property
    def false_accepts(self) -> int:
        """Frames whose whole-map search accepted a place more than ``FALSE_ACCEPT_M`` from the truth."""
        return sum(1 for f in self.frames if f.searched_map and f.localized and f.error_m > FALSE_ACCEPT_M)

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
            "autonomy": self.autonomy, "strict_autonomy": self.strict_autonomy, "manual_strict_m": self.manual_strict_m,
            "false_accepts_over_5m": self.false_accepts, "failures": self.failures, "max_vo_m": self.max_vo_m,
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


def overall(runs: Sequence[RepeatRun], mode: str) -> dict[str, Any]:
    """Autonomy by distance over all repeats of a mode (distance-weighted; published and strict), false accepts,
    failures, worst distance on VO."""
    rs = [r for r in runs if r.mode == mode]
    dist = sum(r.distance_m for r in rs)
    manual = sum(r.manual_m for r in rs)
    strict = sum(r.manual_strict_m for r in rs)
    return {"mode": mode, "runs": len(rs), "distance_m": dist, "manual_m": manual,
            "autonomy": 1.0 - manual / dist if dist > 0 else math.nan,
            "strict_autonomy": 1.0 - strict / dist if dist > 0 else math.nan, "manual_strict_m": strict,
            "false_accepts_over_5m": sum(r.false_accepts for r in rs), "failures": sum(r.failures for r in rs),
            "max_vo_m": max((r.max_vo_m for r in rs), default=math.nan),
            "gross_localizations": sum(int(np.count_nonzero(r.errors() > GROSS_ERROR_M)) for r in rs)}


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
