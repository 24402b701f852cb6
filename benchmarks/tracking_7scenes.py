"""Benchmark frame-to-frame RGB-D tracking (paper §III-D, Eq. 7) on 7-Scenes, against Open3D's hybrid odometry.

For frames ``--first``..``--last`` (frame numbers, as in ``frame-NNNNNN``; default all) of a 7-Scenes sequence
folder (``--data``, default ``7scenes_redkitchen_300`` in the shared data: ``$LIGHTFAST_SHARED/data`` or
``../shared/data``; any folder of ``frame-NNNNNN.color.{png,jpg}`` / ``.depth.png`` / ``.pose.txt`` whose numbers
start anywhere, with the 7-Scenes intrinsics when it has no ``camera-intrinsics.txt``), at 640×480 and 320×240, in
the same run:

* **lightfast Eq. 7** — :func:`lightfast.tracking.track_sequence` (photometric + w_G·point-to-plane, w_G = 10,
  Huber, 3-level pyramid) and its depth-only variant (E_C off) at 320×240;
* **Open3D hybrid (default)** — ``open3d.t.pipelines.odometry.rgbd_odometry_multi_scale`` with ``Method.Hybrid``
  and default parameters (intensity + depth-difference, 0.5/0.5 weights, depth_max 3 m), frame to frame;
* **Open3D legacy hybrid** — ``open3d.pipelines.odometry.compute_rgbd_odometry`` with
  ``RGBDOdometryJacobianFromHybridTerm`` and the default ``OdometryOption`` (the long-standing API of Open3D's RGB-D
  odometry tutorial; the issue's "about 2.5 cm" reference), frame to frame;
* **Open3D hybrid, w_G = 10** — the same tensor-API call with the depth scaled by ``s = sqrt(10)`` (and
  ``depth_huber_delta``, ``depth_outlier_trunc``, ``depth_max`` scaled by ``s``, translation divided by ``s``), which
  turns its cost into ``E_I + 10 E_D`` (see docs/daylight.md, "Direct RGB-D tracking").

The same four main runs again on colour images registered to depth by the similarity (scale about the centre and
shift) :func:`lightfast.data.sevenscenes.colour_registration` estimates from the images alone (no ground truth): the
Kinect v1's colour and depth cameras are not registered in 7-Scenes (PROVENANCE.md), and the colour camera's focal
length is about 0.9 times the depth camera's, whose K the data set ships.

Each chained trajectory is compared with the ground truth by ATE RMSE after a rigid Umeyama alignment
(:func:`lightfast.tracking.ate_rmse`), by the mean ATE of 100-frame windows, by the drift over 1 s (RMSE of the
translation error of 30-frame motions) and by the median frame-to-frame error (RPE);
time per frame includes the image pyramid / tensor preparation; lightfast's alignments that did not converge
(``AlignResult.converged``) and Open3D legacy's failed steps are counted.

Sub-sequences: the frames cut into consecutive stretches of ``--subsequence`` frames (default 150; a shorter rest
is dropped), each tracked on its own by Open3D's two APIs and lightfast's f2f at both resolutions; the table gives
each stretch's ATE and their mean, the verdict whether lightfast's f2f is ahead of both Open3D APIs on that mean,
and each tracker's own error (the N-cornered hat, :func:`lightfast.tracking.own_errors`, over the pairwise ATEs and
frame-to-frame motions of the four trackers and the ground truth: the part that is not shared with the others);
on the raw frames and again on the registered colour (every method gets the same frames). lightfast does not align a
frame whose depth image repeats its predecessor's and aligns one whose colour alone repeats by E_G only
(:func:`lightfast.tracking.repeated_input`; 7-Scenes' unsynchronised Kinect streams repeat images); Open3D's rows
run as users call them, and again with this benchmark applying the same rule (``repeated images as lightfast``),
with a second verdict against those.

Prints markdown and writes it atomically to ``--output`` (default ``benchmarks/results/tracking_7scenes.md``), the
sub-sequence numbers beside it as JSON (same name, ``.json``).

Usage: ``.venv/bin/python benchmarks/tracking_7scenes.py [--data DIR] [--first N] [--last M] [--subsequence 150]
[--no-main] [--no-orderings]``
"""
from __future__ import annotations

import argparse
import dataclasses
import functools
import itertools
import json
import math
import platform
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np
import open3d as o3d
from numpy.typing import NDArray

from lightfast.camera import PinholeCamera
from lightfast.data.errors import DatasetError
from lightfast.data.sevenscenes import SevenScenes, colour_registration, register_colour
from lightfast.data.shared import shared_data_dir, shown_path
from lightfast.io import write_text_atomic
from lightfast.tracking import TrackingConfig, ate_rmse, motion_rmse, own_errors, repeated_images, track_sequence

DATA_NAME = "7scenes_redkitchen_300"
Frames = list[tuple[NDArray[np.uint8], NDArray[np.float64]]]
#: lightfast with the depth-difference geometric term (Kerl et al.; Open3D's form) at the weight ratio of Open3D's
#: legacy defaults, lambda_dep / lambda_img = 0.968 / 0.032 ~ 30 (not tuned here).
DEPTH_DIFF = "lightfast E_C + 30 E_G, depth-difference E_G"
DEPTH_DIFF_CFG = functools.partial(TrackingConfig, geometric_term="depth-difference", geometric_weight=30.0)
EQ7 = "lightfast Eq. 7 (E_C + 10 E_G)"
O3D_TENSOR = "Open3D hybrid (defaults)"
O3D_LEGACY = "Open3D legacy hybrid (defaults)"
#: the same with lightfast's rule for repeated images applied by this benchmark (the peer given what lightfast does)
O3D_TENSOR_SKIP = f"{O3D_TENSOR}, repeated images as lightfast"
O3D_LEGACY_SKIP = f"{O3D_LEGACY}, repeated images as lightfast"


@dataclass(frozen=True)
class Track:
    """A chained trajectory (``T_world_cam`` per frame), ms per aligned frame and the failed alignments: lightfast's
    not converged, Open3D legacy's unsuccessful steps; None where the API does not say (Open3D tensor)."""

    poses: NDArray[np.float64]
    ms: float
    failed: int | None


@dataclass(frozen=True)
class Sequence7:
    """Frames of one 7-Scenes folder: ``numbers`` (file numbers), full-size and 320×240 frames (rgb, depth m),
    ground truth ``T_world_cam``, both cameras, and every 20th frame's raw (rgb, depth mm) for the colour
    registration."""

    data: Path
    numbers: list[int]
    frames: Frames
    small: Frames
    gt: NDArray[np.float64]
    cam: PinholeCamera
    small_cam: PinholeCamera
    raw_sparse: list[tuple[NDArray[np.uint8], NDArray[np.uint16]]]
    intrinsics_file: bool


def load_sequence(data: Path, first: int | None = None, last: int | None = None) -> Sequence7:
    """Frames numbered ``first``..``last`` (inclusive; None: from the first / to the last present) of ``data``."""
    try:
        ds = SevenScenes(data)
    except DatasetError as exc:
        raise SystemExit(f"tracking_7scenes: {exc} (set --data, or LIGHTFAST_SHARED for the shared data)") from None
    numbers = [i for i in ds.indices if (first is None or i >= first) and (last is None or i <= last)]
    if len(numbers) < 2:
        raise SystemExit(f"tracking_7scenes: frames {first}..{last} of {data}: {len(numbers)} frame(s); the folder "
                         f"holds {len(ds.indices)} numbered {ds.indices[0]}..{ds.indices[-1]}")
    raw = [ds.frame(i) for i in numbers]
    frames: Frames = [(f.rgb, f.depth_mm.astype(np.float64) / 1000.0) for f in raw]
    small, small_cam = _resize(frames, ds.camera)
    return Sequence7(data, numbers, frames, small, np.stack([f.T_world_cam for f in raw]), ds.camera, small_cam,
                     [(f.rgb, f.depth_mm) for f in raw[::20]], ds.intrinsics_file)


def registered(seq: Sequence7) -> tuple[Sequence7, str]:
    """``seq`` with its colour registered to depth by the similarity estimated from every 20th frame's images (no
    poses; :func:`lightfast.data.sevenscenes.colour_registration`), and a label saying which."""
    reg = colour_registration(seq.raw_sparse, seq.cam)
    frames: Frames = [(register_colour(rgb, reg, seq.cam), depth) for rgb, depth in seq.frames]
    small, _ = _resize(frames, seq.cam)
    return (dataclasses.replace(seq, frames=frames, small=small),
            f"colour registered (scale {reg.scale:.3f}, {reg.dx_px:+.0f}, {reg.dy_px:+.0f} px)")


def _repeated(rgb: NDArray[np.uint8], depth: NDArray[np.float64],
              target: tuple[NDArray[np.uint8], NDArray[np.float64]] | None) -> str:
    """:func:`lightfast.tracking.repeated_images` against the target frame's input images (none: ""), for the Open3D
    rows that get lightfast's rule."""
    return "" if target is None else repeated_images(rgb, depth, *target)


def _o3d_track(frames: Frames, cam: PinholeCamera, *, w_G: float | None, constant_velocity: bool = True,
               skip_repeats: bool = False) -> Track:
    """Chain Open3D hybrid f2f odometry; ``w_G`` None = all defaults, else the depth-scaling emulation.
    ``skip_repeats``: lightfast's rule for repeated images, applied here (a frame whose depth repeats is not aligned
    and keeps its predecessor's pose; one whose colour alone repeats is aligned by ``Method.PointToPlane``)."""
    odo = o3d.t.pipelines.odometry
    s = 1.0 if w_G is None else math.sqrt(w_G / 1.0)  # Open3D weighs both terms 0.5: ratio 1 -> s² = w_G
    params = odo.OdometryLossParams() if w_G is None else odo.OdometryLossParams(0.07 * s, 0.05 * s, 0.1)
    K = o3d.core.Tensor(cam.K, o3d.core.Dtype.Float64)
    velocity = np.eye(4)  # the previous relative motion: both trackers start at the constant-velocity prediction
    poses = [np.eye(4)]
    prev = target = None
    seconds = 0.0
    for rgb, depth in frames:
        t0 = time.perf_counter()
        repeated = _repeated(rgb, depth, target) if skip_repeats else ""
        if repeated == "depth":
            poses.append(poses[-1])
            seconds += time.perf_counter() - t0
            continue
        target = (rgb, depth)
        img = o3d.t.geometry.RGBDImage(
            o3d.t.geometry.Image(np.ascontiguousarray(rgb)),
            o3d.t.geometry.Image(np.ascontiguousarray((depth * 1000.0).astype(np.uint16))),
        )
        if prev is not None:
            init = velocity.copy()
            init[:3, 3] *= s
            res = odo.rgbd_odometry_multi_scale(
                img, prev, K, o3d.core.Tensor(init, o3d.core.Dtype.Float64), 1000.0 / s, 3.0 * s,
                method=odo.Method.PointToPlane if repeated == "colour" else odo.Method.Hybrid, params=params
            )
            T = res.transformation.numpy().copy()
            T[:3, 3] /= s
            velocity = T if constant_velocity else np.eye(4)
            poses.append(poses[-1] @ T)
            seconds += time.perf_counter() - t0
        prev = img
    return Track(np.stack(poses), 1000.0 * seconds / max(len(frames) - 1, 1), None)


def _o3d_legacy_track(frames: Frames, cam: PinholeCamera, skip_repeats: bool = False) -> Track:
    """Chain Open3D's legacy hybrid odometry (default options), each step started at the constant-velocity
    prediction; a failed step keeps the prediction. ``skip_repeats``: a frame whose depth repeats the target's is not
    aligned and keeps its predecessor's pose (the legacy API has no depth-only term for a repeated colour image)."""
    odo = o3d.pipelines.odometry
    intrinsic = o3d.camera.PinholeCameraIntrinsic(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy)
    option, jacobian = odo.OdometryOption(), odo.RGBDOdometryJacobianFromHybridTerm()
    velocity, poses, prev, seconds, failed = np.eye(4), [np.eye(4)], None, 0.0, 0
    target: tuple[NDArray[np.uint8], NDArray[np.float64]] | None = None
    for rgb, depth in frames:
        t0 = time.perf_counter()
        if skip_repeats and _repeated(rgb, depth, target) == "depth":
            poses.append(poses[-1])
            seconds += time.perf_counter() - t0
            continue
        target = (rgb, depth)
        img = o3d.geometry.RGBDImage.create_from_color_and_depth(
            o3d.geometry.Image(np.ascontiguousarray(rgb)),
            o3d.geometry.Image(np.ascontiguousarray((depth * 1000.0).astype(np.uint16))),
            depth_scale=1000.0, depth_trunc=3.0, convert_rgb_to_intensity=True,
        )
        if prev is not None:
            ok, T, _ = odo.compute_rgbd_odometry(img, prev, intrinsic, velocity, jacobian, option)
            velocity = T if ok else velocity
            failed += not ok
            poses.append(poses[-1] @ velocity)
            seconds += time.perf_counter() - t0
        prev = img
    return Track(np.stack(poses), 1000.0 * seconds / max(len(frames) - 1, 1), failed)


def _lf_track(frames: Frames, cam: PinholeCamera, cfg: TrackingConfig, constant_velocity: bool = True) -> Track:
    track = track_sequence(frames, cam, config=cfg, motion_prior="constant-velocity" if constant_velocity else "none")
    return Track(track.poses, 1000.0 * float(np.mean(track.seconds)),
                 sum(r is not None and not r.converged for r in track.results))


def _rpe(poses: NDArray[np.float64], gt: NDArray[np.float64]) -> tuple[float, float]:
    """Median translation (mm) and rotation (deg) error of the frame-to-frame motions."""
    est = np.linalg.inv(poses[:-1]) @ poses[1:]
    true = np.linalg.inv(gt[:-1]) @ gt[1:]
    err = np.linalg.inv(true) @ est
    cos = np.clip((np.trace(err[:, :3, :3], axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    t_mm = 1000.0 * float(np.median(np.linalg.norm(err[:, :3, 3], axis=1)))
    return t_mm, float(np.degrees(np.median(np.arccos(cos))))


def _drift_mm(poses: NDArray[np.float64], gt: NDArray[np.float64], delta: int = 30) -> float:
    """:func:`lightfast.tracking.motion_rmse` over ``delta`` frames (30 = 1 s at 30 Hz), mm: the drift rate, the TUM
    RPE over 1 s; NaN for a sequence not longer than ``delta``."""
    return math.nan if len(poses) <= delta else 1000.0 * motion_rmse(poses, gt, delta)


def _windowed_ate_cm(poses: NDArray[np.float64], gt: NDArray[np.float64], window: int = 100, step: int = 25
                     ) -> float:
    """Mean ATE RMSE (cm) over the ``window``-frame stretches starting every ``step`` frames, each aligned on its
    own: the same accumulation as the whole-sequence ATE, less dominated by how one run's drift directions add up
    (NaN for a sequence shorter than ``window``)."""
    starts = range(0, len(poses) - window + 1, step)
    if not starts:
        return math.nan
    return 100.0 * float(np.mean([ate_rmse(poses[s:s + window], gt[s:s + window]) for s in starts]))


def _orderings(n: int) -> dict[str, list[int]]:
    """Twelve sequences made of the same frames: forward and reversed, every frame and every 2nd / 3rd frame from
    each possible start (15 / 10 Hz). Chained odometry's whole-sequence ATE depends on how one run's small errors
    add up; over these orderings a tracker's typical value shows, not one draw."""
    out = {}
    for stride in (1, 2, 3):
        for start in range(stride):
            idx = list(range(start, n, stride))
            out[f"{stride}/{start}"] = idx
            out[f"{stride}/{start} rev"] = idx[::-1]
    return out


def _resize(frames: Frames, cam: PinholeCamera) -> tuple[Frames, PinholeCamera]:
    """Half-size input for Open3D (lightfast downsamples internally with ``resolution_scale``)."""
    small = cam.scaled(0.5)
    out: Frames = [
        (
            cast(NDArray[np.uint8], cv2.resize(rgb, (small.width, small.height), interpolation=cv2.INTER_AREA)),
            cast(NDArray[np.float64], cv2.resize(d, (small.width, small.height), interpolation=cv2.INTER_NEAREST)),
        )
        for rgb, d in frames
    ]
    return out, small


def _size(cam: PinholeCamera) -> str:
    return f"{cam.width}×{cam.height}"


#: (method, full / half size, tracker of the frames at the positions given) for the sub-sequence table
SubTracker = tuple[str, bool, Callable[[Sequence7, Sequence[int]], Track]]


def sub_trackers() -> list[SubTracker]:
    """Open3D's two APIs and lightfast's two f2f variants, each at full and half size (all defaults)."""
    def pick(frames: Frames, ix: Sequence[int]) -> Frames:
        return [frames[i] for i in ix]

    return [
        (O3D_TENSOR, True, lambda s, ix: _o3d_track(pick(s.frames, ix), s.cam, w_G=None)),
        (O3D_TENSOR, False, lambda s, ix: _o3d_track(pick(s.small, ix), s.small_cam, w_G=None)),
        (O3D_LEGACY, True, lambda s, ix: _o3d_legacy_track(pick(s.frames, ix), s.cam)),
        (O3D_LEGACY, False, lambda s, ix: _o3d_legacy_track(pick(s.small, ix), s.small_cam)),
        (O3D_TENSOR_SKIP, True, lambda s, ix: _o3d_track(pick(s.frames, ix), s.cam, w_G=None, skip_repeats=True)),
        (O3D_TENSOR_SKIP, False,
         lambda s, ix: _o3d_track(pick(s.small, ix), s.small_cam, w_G=None, skip_repeats=True)),
        (O3D_LEGACY_SKIP, True, lambda s, ix: _o3d_legacy_track(pick(s.frames, ix), s.cam, skip_repeats=True)),
        (O3D_LEGACY_SKIP, False, lambda s, ix: _o3d_legacy_track(pick(s.small, ix), s.small_cam, skip_repeats=True)),
        (EQ7, True, lambda s, ix: _lf_track(pick(s.frames, ix), s.cam, TrackingConfig())),
        (EQ7, False, lambda s, ix: _lf_track(pick(s.frames, ix), s.cam, TrackingConfig(resolution_scale=0.5))),
        (DEPTH_DIFF, True, lambda s, ix: _lf_track(pick(s.frames, ix), s.cam, DEPTH_DIFF_CFG())),
        (DEPTH_DIFF, False, lambda s, ix: _lf_track(pick(s.frames, ix), s.cam, DEPTH_DIFF_CFG(resolution_scale=0.5))),
    ]


def subsequences(n: int, length: int) -> list[range]:
    """Positions of the consecutive stretches of ``length`` frames in ``n`` (a shorter rest is dropped; all frames
    as one stretch when ``length >= n``)."""
    if length < 2:
        raise ValueError(f"a sub-sequence needs at least 2 frames, got {length}")
    if length >= n:
        return [range(n)]
    return [range(a, a + length) for a in range(0, n - length + 1, length)]


def evaluate_subsequences(seq: Sequence7, length: int, trackers: list[SubTracker] | None = None
                          ) -> dict[str, Any]:
    """Every tracker on every stretch (:func:`subsequences`): per row the ATE (cm), median RPE (mm) and failed
    alignments of each stretch, their means, and per lightfast row whether its mean ATE is below both Open3D APIs'
    at the same size (``ahead_of_both``; None without both Open3D rows)."""
    stretches = subsequences(len(seq.numbers), length)
    rows: list[dict[str, Any]] = []
    poses: dict[tuple[str, str], list[NDArray[np.float64]]] = {}
    for name, full, fn in sub_trackers() if trackers is None else trackers:
        ate, rpe, failed, ms = [], [], [], []
        size = _size(seq.cam if full else seq.small_cam)
        for ix in stretches:
            track = fn(seq, ix)
            gt = seq.gt[ix.start:ix.stop]
            ate.append(100.0 * ate_rmse(track.poses, gt))
            rpe.append(_rpe(track.poses, gt)[0])
            failed.append(track.failed)
            ms.append(track.ms)
            poses.setdefault((name, size), []).append(track.poses)
        rows.append({"method": name, "resolution": size, "ate_cm": ate, "rpe_mm": rpe, "failed": failed,
                     "mean_ate_cm": float(np.mean(ate)), "mean_rpe_mm": float(np.mean(rpe)),
                     "ms_per_frame": float(np.mean(ms))})
        print(f"{name:45s} {size:8s} sub-sequence ATE " + ", ".join(f"{a:.2f}" for a in ate)
              + f" cm, mean {rows[-1]['mean_ate_cm']:.2f}; failed {failed}", flush=True)
    for row in rows:
        if row["method"].startswith("lightfast"):
            for key, peers in (("ahead_of_both", (O3D_TENSOR, O3D_LEGACY)),
                               ("ahead_of_both_same_rule", (O3D_TENSOR_SKIP, O3D_LEGACY_SKIP))):
                o3d_means: list[float] = [r["mean_ate_cm"] for r in rows
                                          if r["resolution"] == row["resolution"] and r["method"] in peers]
                row[key] = bool(row["mean_ate_cm"] < min(o3d_means)) if len(o3d_means) == 2 else None
    hats = _own_errors(seq, stretches, rows, poses)
    return {"length": length, "frames": [seq.numbers[0], seq.numbers[-1]],
            "stretches": [[seq.numbers[ix.start], seq.numbers[ix.stop - 1]] for ix in stretches], "rows": rows,
            "own_errors": hats}


#: the trackers compared with each other and with the ground truth by the N-cornered hat (one row per method:
#: the rows with lightfast's rule for repeated images share most of their errors with the rows without it)
HAT_METHODS = (O3D_TENSOR, O3D_LEGACY, EQ7, DEPTH_DIFF)
GROUND_TRUTH = "ground truth"


def _own_errors(seq: Sequence7, stretches: list[range], rows: list[dict[str, Any]],
                poses: dict[tuple[str, str], list[NDArray[np.float64]]]) -> list[dict[str, Any]]:
    """Per resolution, :func:`lightfast.tracking.own_errors` of every stretch over the :data:`HAT_METHODS` rows and
    the ground truth, on the ATE and on the frame-to-frame motions (:func:`lightfast.tracking.motion_rmse`); adds
    ``own_cm`` / ``own_rpe_mm`` (per stretch) and their means to those rows and returns, per resolution, the ground
    truth's share of both (its own error plus what all four trackers get wrong alike) and the fits' misfit."""
    out = []
    for size in dict.fromkeys(r["resolution"] for r in rows):
        methods = [m for m in HAT_METHODS if (m, size) in poses]
        if len(methods) < 2:
            continue
        sets = [{**{m: poses[(m, size)][k] for m in methods}, GROUND_TRUTH: seq.gt[ix.start:ix.stop]}
                for k, ix in enumerate(stretches)]
        ate_fits = [own_errors(t) for t in sets]
        rpe_fits = [own_errors(t, distance=motion_rmse) for t in sets]
        for r in rows:
            if r["resolution"] == size and r["method"] in methods:
                r["own_cm"] = [100.0 * f.own_m[r["method"]] for f in ate_fits]
                r["mean_own_cm"] = float(np.mean(r["own_cm"]))
                r["own_rpe_mm"] = [1000.0 * f.own_m[r["method"]] for f in rpe_fits]
                r["rpe_rmse_mm"] = [1000.0 * f.pairwise_m[(r["method"], GROUND_TRUTH)] for f in rpe_fits]
        out.append({"resolution": size, "ground_truth_cm": [100.0 * f.own_m[GROUND_TRUTH] for f in ate_fits],
                    "misfit_cm2": [1e4 * f.misfit_m2 for f in ate_fits],
                    "ground_truth_rpe_mm": [1000.0 * f.own_m[GROUND_TRUTH] for f in rpe_fits]})
    return out


def _subsequence_lines(sub: dict[str, Any], colour: str) -> list[str]:
    heads = [f"{a}–{b}" for a, b in sub["stretches"]]
    def verdict(r: dict[str, Any]) -> str:
        out = f"{r['method']} at {r['resolution']}: mean {r['mean_ate_cm']:.2f} cm, " + (
            "ahead of both Open3D APIs" if r["ahead_of_both"] else "**not** ahead of both Open3D APIs")
        if r.get("ahead_of_both_same_rule") is not None:
            out += "; " + ("ahead of both" if r["ahead_of_both_same_rule"] else "**not** ahead of both") + (
                " when they get lightfast's rule for repeated images")
        peers = [p for p in sub["rows"] if p["resolution"] == r["resolution"] and "mean_own_cm" in p
                 and p["method"] in (O3D_TENSOR, O3D_LEGACY)]
        if "mean_own_cm" in r and len(peers) == 2:
            ahead = r["mean_own_cm"] < min(p["mean_own_cm"] for p in peers)
            out += f"; own error {r['mean_own_cm']:.2f} cm, " + ("below" if ahead else "**not** below") + (
                " both Open3D APIs' (" + ", ".join(f"{p['mean_own_cm']:.2f}" for p in peers) + ")")
        return out

    def own(r: dict[str, Any]) -> str:
        return f"{r['mean_own_cm']:.2f}" if "mean_own_cm" in r else "–"

    hats = [f"{h['resolution']}: ATE " + ", ".join(f"{g:.2f}" for g in h["ground_truth_cm"]) + " cm (misfit "
            + ", ".join(f"{m:.2f}" for m in h["misfit_cm2"]) + " cm²), frame-to-frame motion "
            + ", ".join(f"{g:.2f}" for g in h["ground_truth_rpe_mm"]) + " mm" for h in sub.get("own_errors", [])]
    per_frame = [f"{r['method']} at {r['resolution']} " + ", ".join(f"{a:.2f}" for a in r["rpe_rmse_mm"]) + " → "
                 + ", ".join(f"{a:.2f}" for a in r["own_rpe_mm"]) for r in sub["rows"] if "own_rpe_mm" in r]

    verdicts = [verdict(r) for r in sub["rows"] if r.get("ahead_of_both") is not None]

    def failed(r: dict[str, Any]) -> str:
        return "–" if None in r["failed"] else str(sum(r["failed"]))

    return [
        "",
        f"## Sub-sequences of {sub['length']} frames, {colour}",
        "",
        f"Frames {sub['frames'][0]}–{sub['frames'][1]} cut into {len(heads)} consecutive "
        f"stretch{'es' if len(heads) > 1 else ''} of {sub['length']} frames (a shorter rest left out), each tracked "
        "on its own from its first frame (constant-velocity start); ATE RMSE [cm] of each stretch after its own rigid "
        "alignment, mean over the stretches, mean of the stretches' median RPE [mm], failed alignments over all "
        "stretches (lightfast: `AlignResult.converged` false; Open3D legacy: `compute_rgbd_odometry` unsuccessful; "
        "Open3D tensor does not report it: –).",
        "Own error [cm]: each tracker's share of its ATE, without the ground truth's: the N-cornered hat "
        "(`lightfast.tracking.own_errors`) over the pairwise ATEs of the four trackers at one resolution (Open3D's "
        "two APIs, lightfast's two forms) and the ground truth, per stretch, mean over the stretches. It assumes "
        "independent errors; what all four trackers get wrong alike counts as the ground truth's; a stretch's 0 is the "
        "fit's bound, where the pairwise ATEs are not those of independent errors (see the misfit below).",
        "",
        "| method | resolution | " + " | ".join(heads) + " | mean ATE [cm] | own error [cm] | RPE [mm] | failed "
        "| ms/frame |",
        "|---|---|" + "---:|" * (len(heads) + 5),
        *[f"| {r['method']} | {r['resolution']} | " + " | ".join(f"{a:.2f}" for a in r["ate_cm"])
          + f" | **{r['mean_ate_cm']:.2f}** | {own(r)} | {r['mean_rpe_mm']:.2f} | {failed(r)} "
          f"| {r['ms_per_frame']:.1f} |" for r in sub["rows"]],
        "",
        *[f"- {v}" for v in verdicts],
        *([f"- The ground truth's share by the same fit (its own error and whatever all four trackers share), per "
           f"stretch: {'; '.join(hats)}.",
           "- Frame-to-frame motions, translation RMSE against the ground truth → each tracker's own by the same fit "
           f"[mm], per stretch: {'; '.join(per_frame)}."] if hats else []),
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--data", type=Path, default=shared_data_dir(DATA_NAME),
                    help="a 7-Scenes sequence folder (default: 7scenes_redkitchen_300 in $LIGHTFAST_SHARED/data "
                    "or ../shared/data)")
    ap.add_argument("--first", type=int, default=None, help="first frame number (default: the folder's first)")
    ap.add_argument("--last", type=int, default=None, help="last frame number, inclusive (default: the folder's last)")
    ap.add_argument("--subsequence", type=int, default=150,
                    help="frames per sub-sequence of the sub-sequence table (0: no such table)")
    ap.add_argument("--main", action=argparse.BooleanOptionalAction, default=True,
                    help="the main table on all frames (every method, colour registration, identity start)")
    ap.add_argument("--repeats", type=int, default=3,
                    help="runs of the headline rows (Open3D tensor and lightfast Eq. 7, raw frames) for the "
                    "repeatability table")
    ap.add_argument("--orderings", action=argparse.BooleanOptionalAction, default=True,
                    help="also track twelve orderings of the same frames (forward / reversed, strides 1-3; ~15 min)")
    ap.add_argument("--output", type=Path, default=Path(__file__).parent / "results" / "tracking_7scenes.md")
    args = ap.parse_args(argv)
    seq = load_sequence(args.data, args.first, args.last)
    frames, small_frames, cam, small_cam, gt = seq.frames, seq.small, seq.cam, seq.small_cam, seq.gt
    full, half = _size(cam), _size(small_cam)
    # the registration (8 s) only for the tables that use it
    reg_seq, reg_tag = registered(seq) if args.main or args.subsequence else (seq, "raw frames")
    for scale in (1.0, 0.5):  # numba compiles on first use (and after a move of the source): not a frame's time
        track_sequence(frames[:2], cam, config=TrackingConfig(resolution_scale=scale))

    runs: list[tuple[str, str, Callable[[], Track]]] = [
        (O3D_TENSOR, full, lambda: _o3d_track(frames, cam, w_G=None)),
        ("Open3D hybrid, w_G=10 via depth scaling", full, lambda: _o3d_track(frames, cam, w_G=10.0)),
        (O3D_TENSOR, half, lambda: _o3d_track(small_frames, small_cam, w_G=None)),
        (O3D_LEGACY, full, lambda: _o3d_legacy_track(frames, cam)),
        (O3D_LEGACY, half, lambda: _o3d_legacy_track(small_frames, small_cam)),
        (EQ7, half, lambda: _lf_track(frames, cam, TrackingConfig(resolution_scale=0.5))),
        ("lightfast depth-only (E_G)", half,
         lambda: _lf_track(frames, cam, TrackingConfig(resolution_scale=0.5, mode="depth-only"))),
        (EQ7, full, lambda: _lf_track(frames, cam, TrackingConfig())),
        (DEPTH_DIFF, half, lambda: _lf_track(frames, cam, DEPTH_DIFF_CFG(resolution_scale=0.5))),
        (DEPTH_DIFF, full, lambda: _lf_track(frames, cam, DEPTH_DIFF_CFG())),
        # the protocol of the earlier runs: every alignment started at identity
        ("Open3D hybrid (defaults), identity start", full,
         lambda: _o3d_track(frames, cam, w_G=None, constant_velocity=False)),
        ("Open3D hybrid (defaults), identity start", half,
         lambda: _o3d_track(small_frames, small_cam, w_G=None, constant_velocity=False)),
        ("lightfast Eq. 7, identity start", half,
         lambda: _lf_track(frames, cam, TrackingConfig(resolution_scale=0.5), constant_velocity=False)),
        ("lightfast Eq. 7, identity start", full,
         lambda: _lf_track(frames, cam, TrackingConfig(), constant_velocity=False)),
    ] if args.main else []
    if args.main:
        # the Kinect v1's colour and depth cameras are not registered: the same runs on registered colour
        reg, small_reg, tag = reg_seq.frames, reg_seq.small, reg_tag
        runs += [
            (f"Open3D hybrid (defaults), {tag}", full, lambda: _o3d_track(reg, cam, w_G=None)),
            (f"Open3D hybrid (defaults), {tag}", half, lambda: _o3d_track(small_reg, small_cam, w_G=None)),
            (f"lightfast Eq. 7, {tag}", half, lambda: _lf_track(reg, cam, TrackingConfig(resolution_scale=0.5))),
            (f"lightfast Eq. 7, {tag}", full, lambda: _lf_track(reg, cam, TrackingConfig())),
        ]
    rows = []
    ates: dict[tuple[str, str], list[float]] = {}
    for name, res, fn in runs:
        track = fn()
        poses = track.poses
        ates[(name, res)] = [100.0 * ate_rmse(poses, gt)]
        rpe_mm, rpe_deg = _rpe(poses, gt)
        failed = "–" if track.failed is None else str(track.failed)
        rows.append((name, res, ates[(name, res)][0], _windowed_ate_cm(poses, gt), _drift_mm(poses, gt),
                     rpe_mm, rpe_deg, failed, track.ms))
        print(f"{name:45s} {res:8s} ATE {rows[-1][2]:6.2f} cm (windows {rows[-1][3]:5.2f})  drift "
              f"{rows[-1][4]:5.1f} mm/s  RPE {rpe_mm:5.2f} mm {rpe_deg:5.3f} deg  failed {failed}  "
              f"{track.ms:7.1f} ms/frame", flush=True)

    # Open3D's tensor odometry reduces its normal equations in parallel, in no fixed order: the same input does not
    # give the same trajectory twice. The headline rows again, to show how much the whole-sequence ATE moves.
    headline = [(n, r, fn) for n, r, fn in runs if n in (O3D_TENSOR, EQ7)]
    for _ in range(args.repeats - 1):
        for name, res, fn in headline:
            ates[(name, res)].append(100.0 * ate_rmse(fn().poses, gt))
            print(f"{name:45s} {res:8s} ATE, repeated: {ates[(name, res)][-1]:6.2f} cm", flush=True)

    # the same comparison over twelve orderings of the frames (the first is the table above's sequence)
    order_rows: list[tuple[str, str, list[float]]] = []
    if args.orderings:
        orders = _orderings(len(frames))
        trackers: list[tuple[str, str, Callable[[list[int]], NDArray[np.float64]]]] = [
            (O3D_TENSOR, full, lambda ix: _o3d_track([frames[i] for i in ix], cam, w_G=None).poses),
            (O3D_TENSOR, half, lambda ix: _o3d_track([small_frames[i] for i in ix], small_cam, w_G=None).poses),
            (O3D_LEGACY, full, lambda ix: _o3d_legacy_track([frames[i] for i in ix], cam).poses),
            (O3D_LEGACY, half, lambda ix: _o3d_legacy_track([small_frames[i] for i in ix], small_cam).poses),
            (EQ7, full, lambda ix: _lf_track([frames[i] for i in ix], cam, TrackingConfig()).poses),
            (EQ7, half, lambda ix: _lf_track([frames[i] for i in ix], cam, TrackingConfig(resolution_scale=0.5)).poses),
            (DEPTH_DIFF, full, lambda ix: _lf_track([frames[i] for i in ix], cam, DEPTH_DIFF_CFG()).poses),
            (DEPTH_DIFF, half,
             lambda ix: _lf_track([frames[i] for i in ix], cam, DEPTH_DIFF_CFG(resolution_scale=0.5)).poses),
        ]
        for name, res, order_fn in trackers:
            values = [100.0 * ate_rmse(order_fn(ix), gt[ix]) for ix in orders.values()]
            order_rows.append((name, res, values))
            print(f"{name:45s} {res:8s} ATE over {len(values)} orderings: mean {np.mean(values):5.2f}, "
                  f"median {np.median(values):5.2f} cm", flush=True)
    sub = evaluate_subsequences(seq, args.subsequence) if args.subsequence else None
    # every method on the same registered frames
    sub_reg = evaluate_subsequences(reg_seq, args.subsequence) | {"colour": reg_tag} if args.subsequence else {}

    numbers = seq.numbers
    gaps = sum(b - a > 1 for a, b in itertools.pairwise(numbers))
    lines = [
        "# Frame-to-frame RGB-D tracking on 7-Scenes (paper §III-D, Eq. 7)",
        "",
        f"Frames {numbers[0]}–{numbers[-1]} of `{shown_path(seq.data)}` ({len(numbers)} frames"
        + (f", {gaps} gaps in the numbering" if gaps else "")
        + ("" if seq.intrinsics_file else "; no camera-intrinsics.txt: the 7-Scenes intrinsics 585, 585, 320, 240")
        + "), chained f2f odometry, each alignment started at the constant-velocity prediction (the previous "
        "relative motion, as `rgbd_tracker_node` does) unless the row says identity start.",
    ]
    if rows:
        lines += [
            "ATE RMSE after rigid (Umeyama) alignment to the ground truth; RPE = median error of the frame-to-frame "
            "motions (against this ground truth mostly an error all four trackers share: see the own errors of the "
            "sub-sequence tables; ATE adds how the errors accumulate);",
            "ATE windows = mean ATE RMSE of the 100-frame stretches starting every 25 frames (each aligned on its "
            "own); drift = RMSE of the translation error of the motions over 30 frames (1 s, the TUM RPE). The "
            "whole-sequence ATE of chained odometry depends on how one run's small errors happen to add up: two "
            "trackers with the same per-frame and per-second errors can differ by half a centimetre there, so read it "
            "with the other columns; failed = alignments that did not converge (lightfast) or failed (Open3D legacy; "
            "Open3D tensor does not report it: –);",
            "ms/frame = wall time per aligned frame (pyramid / tensor preparation included), single process on a "
            "shared 2-core machine.",
            "",
            "| method | resolution | ATE RMSE [cm] | ATE windows [cm] | drift [mm/s] | RPE [mm] | RPE [deg] | failed "
            "| ms/frame |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|",
            *[f"| {n} | {r} | {a:.2f} | {aw:.2f} | {dr:.1f} | {t:.2f} | {d:.3f} | {f} | {m:.1f} |"
              for n, r, a, aw, dr, t, d, f, m in rows],
            "",
            f"Repeatability: the headline rows run {args.repeats} times on the same frames in this process (Open3D's "
            "tensor odometry sums its normal equations in parallel in no fixed order, so its trajectory differs from "
            "run to run; lightfast's Gauss-Newton is deterministic).",
            "",
            "| method | resolution | ATE RMSE of each run [cm] |",
            "|---|---|---|",
            *[f"| {n} | {r} | {', '.join(f'{a:.2f}' for a in ates[(n, r)])} |" for n, r, _ in headline],
        ]
    if order_rows:
        lines += [
            "",
            f"Orderings: the same frames as {len(order_rows[0][2])} sequences, whole-sequence ATE RMSE [cm] of each. "
            "Column `k/s`: every k-th frame from frame s (k = 1: 30 Hz, 2: 15 Hz, 3: 10 Hz), `rev`: the same frames "
            "reversed. The first column is the sequence of the tables above (Open3D tensor runs again, so it may "
            "differ from them in the second decimal).",
            "",
            "| method | resolution | " + " | ".join(_orderings(len(frames))) + " | mean | median |",
            "|---|---|" + "---:|" * (len(order_rows[0][2]) + 2),
            *[f"| {n} | {r} | " + " | ".join(f"{a:.2f}" for a in v)
              + f" | **{np.mean(v):.2f}** | {np.median(v):.2f} |" for n, r, v in order_rows],
        ]
    if sub is not None:
        lines += _subsequence_lines(sub, "raw frames")
        lines += _subsequence_lines(sub_reg, sub_reg["colour"])
    lines += [
        "",
        f"Generated {datetime.now(UTC).isoformat(timespec='seconds')} by `benchmarks/tracking_7scenes.py` "
        f"(Python {platform.python_version()}, NumPy {np.__version__}, Open3D {o3d.__version__}, "
        f"OpenCV {cv2.__version__}, {platform.machine()}).",
        "",
    ]
    report = "\n".join(lines)
    print(report)
    write_text_atomic(args.output, report)
    if sub is not None:
        summary = {"data": shown_path(seq.data), "first": numbers[0], "last": numbers[-1], "subsequences": sub,
                   "subsequences_registered": sub_reg}
        write_text_atomic(args.output.with_suffix(".json"), json.dumps(summary, indent=1, ensure_ascii=False) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
