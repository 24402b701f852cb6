"""What the VT&R evaluation (paper §VI) reads from a directory written by ``lightfast sim vtr``.

- :func:`sim_runs`: the complete runs (a ``run.json`` each: kind ``teach`` or ``repeat``, date, start, weather —
  truth-side metadata), ordered by date and start time;
- :func:`stereo_frames`: the stereo pairs of a run's bag, paired by exact stamp — the rgb8 left and right images and
  the ``camera_info`` projection matrices P (3×4, px), what ``vtr_localizer_node`` receives (no ground truth);
- :func:`check_camera`: whether a run's first stereo pair has the teach map's image size and projections;
- :func:`load_truth`: the run's ``truth.csv`` (read only for scoring) — per stamp (ns) the left camera's pose
  ``T_map_cam`` (m), its position along the route ``s_m`` (m) and the sun's elevation (deg).

Unreadable inputs raise :class:`~lightfast.eval.errors.VtrEvalError`.
"""
from __future__ import annotations

import csv
import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lightfast.bag.reader import open_bag
from lightfast.eval.errors import VtrEvalError
from lightfast.geometry import quat_to_matrix
from lightfast.vtr.map_store import TeachMap

_STEREO_TOPICS = ("/stereo/left/image_raw", "/stereo/right/image_raw", "/stereo/left/camera_info",
                  "/stereo/right/camera_info")


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


def check_camera(run_name: str, tmap: TeachMap, left: NDArray[np.generic], P_left: NDArray[np.float64],
                 P_right: NDArray[np.float64]) -> None:
    """Raise :class:`VtrEvalError` unless a run's stereo pair (its left image and projections) has the image size and
    projection matrices of the teach map ``tmap``: the map's landmarks are in that camera's pixels."""
    if ((left.shape[1], left.shape[0]) != tmap.image_size
            or not (np.allclose(P_left, tmap.P_left) and np.allclose(P_right, tmap.P_right))):
        raise VtrEvalError(f"{run_name}: the camera differs from the teach map's")


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
