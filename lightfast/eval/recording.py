"""Scoring a recorded live run of the tracking pipeline (the demo and the cross-process benchmark).

Reads the outputs the nodes published — ``/tracker/pose``, ``/tracker/status``, ``/relight/status`` — from a bag
recorded during ``lightfast bag play``, and the ground truth from the played bag. Reports:

* accuracy as in paper §IV-C: RMSE of the translation error over the frames within 10 cm / 10° of ground truth; the
  other frames count as tracking loss (a live run cannot be reset to ground truth, so a loss may last);
* throughput: poses per second of wall time (the recorder's receive times), and frames that got no pose;
* latency: the tracker's ``latency_ms`` (how far the node clock was past the image stamp when the frame arrived,
  plus the wall time from there to the pose's publication; with ``use_sim_time`` the node clock is the player's
  /clock, which runs with wall time at rate 1), median and 95th percentile;
* per-stage timings like paper Table II: f2f and f2m from the tracker's status, rendering and estimation from the
  relight node's status (median and mean, ms).

A recording of the bag played several times (played again, or ``--loop``) is scored per play: a play starts where
the stamps of the recorded poses go back by more than :data:`PLAY_RESTART_S` (:func:`play_windows`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lightfast.bag.reader import open_bag
from lightfast.eval.daylight import LOSS_ROTATION_DEG, LOSS_TRANSLATION_M
from lightfast.eval.errors import RecordingError
from lightfast.geometry import rotation_angle_deg
from lightfast.topics import (
    COLOR_TOPIC,
    GT_POSE_TOPIC,
    RELIGHT_STATUS_TOPIC,
    SUN_CHUNK_TOPIC,
    TRACKER_POSE_TOPIC,
    TRACKER_STATUS_TOPIC,
)

__all__ = ["PLAY_RESTART_S", "RecordingScore", "play_windows", "score_recording"]

#: Pose stamps going back by more than this start a new play of the bag, s.
PLAY_RESTART_S = 1.0
#: Below this share of poses refined by f2m, :meth:`RecordingScore.summary` says why frames kept their f2f pose.
F2M_SHARE_HINT = 0.9
STAGES = {"f2f": ("tracker", "f2f_ms"), "rendering": ("relight", "render_ms"),
          "estimation": ("relight", "estimate_ms"), "f2m": ("tracker", "f2m_ms")}


@dataclass
class RecordingScore:
    frames: int
    poses: int
    f2m: int
    rmse_m: float
    loss_ratio: float
    fps: float
    latency_ms: NDArray[np.float64]
    stages_ms: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    sun_chunks: int = 0  # B̂_sun chunks received while poses were being published
    sun_epochs: int = 0

    def summary(self) -> str:
        lat = self.latency_ms
        lines = [
            f"frames {self.frames}, poses {self.poses} ({self.frames - self.poses} without a pose), "
            f"f2m {self.f2m} ({100 * self.f2m / max(self.poses, 1):.1f} %)",
            f"RMSE {100 * self.rmse_m:.2f} cm, tracking loss {100 * self.loss_ratio:.2f} % "
            f"(> {100 * LOSS_TRANSLATION_M:.0f} cm or {LOSS_ROTATION_DEG:.0f} deg)",
            f"throughput {self.fps:.1f} poses/s; latency image stamp -> /tracker/pose: median "
            f"{np.median(lat) if len(lat) else math.nan:.1f} ms, p95 "
            f"{np.percentile(lat, 95) if len(lat) else math.nan:.1f} ms",
            f"sun update streaming meanwhile: {self.sun_chunks} chunks of {self.sun_epochs} epochs" if self.sun_chunks
            else "sun update: no B̂_sun chunk published while the poses were (expected when its update period is "
                 "longer than the recording, or when the niced sun update gets no CPU while the nodes track)",
        ]
        if self.poses and self.f2m < F2M_SHARE_HINT * self.poses:
            lines.append(f"only {100 * self.f2m / self.poses:.0f} % refined by f2m: the other frames kept their f2f "
                         "pose because their relit reference came too late (the nodes did not keep up with the input "
                         "rate on this machine: a slower playback or smaller images help)")
        return "\n".join(lines) + "\n" + self.stage_table()

    def stage_table(self) -> str:
        rows = ["| stage | median ms | mean ms | frames |", "|---|---|---|---|"]
        for name, v in self.stages_ms.items():
            if len(v):
                rows.append(f"| {name} | {np.median(v):.1f} | {np.mean(v):.1f} | {len(v)} |")
            else:
                rows.append(f"| {name} | — | — | 0 |")
        return "\n".join(rows) + "\n"


def _values(msg: object) -> dict[str, str]:
    from lightfast.ros.diagnostics import diagnostic_values

    status = getattr(msg, "status", [])
    return diagnostic_values(status[0]) if status else {}


def play_windows(recorded: Path) -> list[tuple[int, int]]:
    """The log-time windows ``[start_ns, end_ns)`` of each play of the bag in ``recorded``: a new play starts at
    the first pose whose stamp is more than :data:`PLAY_RESTART_S` before the previous pose's."""
    from lightfast.ros.convert import stamp_to_ns

    starts: list[int] = []
    previous: int | None = None
    with open_bag(recorded) as bag:
        if TRACKER_POSE_TOPIC not in set(bag.select_topics(None)):
            raise RecordingError(f"{recorded}: no {TRACKER_POSE_TOPIC} recorded")
        for m in bag.messages(topics=[TRACKER_POSE_TOPIC]):
            stamp = stamp_to_ns(bag.deserialize(m).header.stamp)
            if previous is None or previous - stamp > PLAY_RESTART_S * 1e9:
                starts.append(m.log_time_ns if previous is not None else 0)
            previous = stamp
    if not starts:
        raise RecordingError(f"{recorded}: no {TRACKER_POSE_TOPIC} message")
    return list(zip(starts, [*starts[1:], 2**63 - 1], strict=True))


def score_recording(recorded: Path, truth: Path, window: tuple[int, int] | None = None) -> RecordingScore:
    """Score the pipeline outputs in ``recorded`` against the ground truth poses in ``truth`` (see module doc);
    ``window`` (from :func:`play_windows`) scores only the messages recorded in that log-time window."""
    from lightfast.ros.convert import pose_stamped_to_matrix

    lo, hi = window if window is not None else (0, 2**63 - 1)

    gt: dict[int, NDArray[np.float64]] = {}
    frames = 0
    with open_bag(truth) as bag:
        for m in bag.messages(topics=[GT_POSE_TOPIC, COLOR_TOPIC]):
            msg = bag.deserialize(m)
            if m.topic == GT_POSE_TOPIC:
                T, stamp, _ = pose_stamped_to_matrix(msg)
                gt[stamp] = T
            else:
                frames += 1
    if not gt:
        raise RecordingError(f"{truth}: no ground truth on {GT_POSE_TOPIC}")
    errors: list[tuple[float, float]] = []
    receive_s: list[float] = []
    latency: list[float] = []
    stages: dict[str, list[float]] = {k: [] for k in STAGES}
    f2m = 0
    with open_bag(recorded) as bag:
        topics = set(bag.select_topics(None))
        if TRACKER_POSE_TOPIC not in topics:
            raise RecordingError(f"{recorded}: no {TRACKER_POSE_TOPIC} recorded")
        wanted = [t for t in (TRACKER_POSE_TOPIC, TRACKER_STATUS_TOPIC, RELIGHT_STATUS_TOPIC, SUN_CHUNK_TOPIC)
                  if t in topics]
        chunk_times: list[tuple[float, int]] = []
        for m in bag.messages(topics=wanted):
            if not lo <= m.log_time_ns < hi:
                continue
            if m.topic == SUN_CHUNK_TOPIC:  # only the arrival time and epoch (header stamp) are needed
                header = bag.deserialize(m).header
                chunk_times.append((m.log_time_ns * 1e-9, header.stamp.sec * 1_000_000_000 + header.stamp.nanosec))
                continue
            msg = bag.deserialize(m)
            if m.topic == TRACKER_POSE_TOPIC:
                T, stamp, _ = pose_stamped_to_matrix(msg)
                if stamp in gt:
                    E = np.linalg.solve(gt[stamp], T)
                    errors.append((float(np.linalg.norm(E[:3, 3])), float(rotation_angle_deg(E[:3, :3]))))
                receive_s.append(m.log_time_ns * 1e-9)
                continue
            v = _values(msg)
            if m.topic == TRACKER_STATUS_TOPIC:
                if v.get("source") not in ("f2m", "f2f"):
                    continue
                f2m += v.get("source") == "f2m"
                if v.get("latency_ms"):
                    latency.append(float(v["latency_ms"]))
            elif not v.get("stamp_ns") or not v.get("render_ms"):
                continue  # a heartbeat or a frame without a reference
            node = "tracker" if m.topic == TRACKER_STATUS_TOPIC else "relight"
            for stage, (who, key) in STAGES.items():
                if who == node and v.get(key):
                    stages[stage].append(float(v[key]))
    if not errors:
        raise RecordingError(f"{recorded}: no {TRACKER_POSE_TOPIC} message matches a ground-truth stamp")
    e = np.array(errors)
    ok = (e[:, 0] <= LOSS_TRANSLATION_M) & (e[:, 1] <= LOSS_ROTATION_DEG)
    rmse = float(np.sqrt(np.mean(e[ok, 0] ** 2))) if ok.any() else math.nan
    span = receive_s[-1] - receive_s[0] if len(receive_s) > 1 else 0.0
    during = [epoch for t, epoch in chunk_times if receive_s[0] <= t <= receive_s[-1]]
    return RecordingScore(
        frames=frames, poses=len(errors), f2m=int(f2m), rmse_m=rmse, loss_ratio=float(1.0 - ok.mean()),
        fps=(len(receive_s) - 1) / span if span > 0 else math.nan, latency_ms=np.array(latency),
        stages_ms={k: np.array(v) for k, v in stages.items()}, sun_chunks=len(during), sun_epochs=len(set(during)))
