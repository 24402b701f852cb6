"""Benchmark frame-to-frame RGB-D tracking (paper §III-D, Eq. 7) on 7-Scenes, against Open3D's hybrid odometry.

For frames ``--first``..``--last`` of ``/work/shared/data/7scenes_redkitchen_300``, at 640×480 and 320×240, in the
same run:

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

The same four main runs again on colour images registered to depth by the shift
:func:`lightfast.data.sevenscenes.colour_offset` estimates from the images alone (no ground truth): the Kinect
v1's colour and depth cameras are not registered in 7-Scenes (PROVENANCE.md).

Each chained trajectory is compared with the ground truth by ATE RMSE after a rigid Umeyama alignment
(:func:`lightfast.tracking.ate_rmse`), by the mean ATE of 100-frame windows, by the drift over 1 s (RMSE of the
translation error of 30-frame motions) and by the median frame-to-frame error (RPE);
time per frame includes the image pyramid / tensor preparation. Prints a
markdown table and writes it atomically to ``--output`` (default ``benchmarks/results/tracking_7scenes.md``).

Usage: ``.venv/bin/python benchmarks/tracking_7scenes.py [--first 0] [--last 299]``
"""
from __future__ import annotations

import argparse
import functools
import math
import platform
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
from numpy.typing import NDArray

from lightfast.camera import PinholeCamera
from lightfast.data.sevenscenes import SevenScenes, colour_offset, shift_colour
from lightfast.io import write_text_atomic
from lightfast.tracking import TrackingConfig, ate_rmse, track_sequence

DATA = Path("/work/shared/data/7scenes_redkitchen_300")
Frames = list[tuple[NDArray[np.uint8], NDArray[np.float64]]]
#: lightfast with the depth-difference geometric term (Kerl et al.; Open3D's form) at the weight ratio of Open3D's
#: legacy defaults, lambda_dep / lambda_img = 0.968 / 0.032 ~ 30 (not tuned here).
DEPTH_DIFF = "lightfast E_C + 30 E_G, depth-difference E_G"
DEPTH_DIFF_CFG = functools.partial(TrackingConfig, geometric_term="depth-difference", geometric_weight=30.0)


def _o3d_track(frames: Frames, cam: PinholeCamera, *, w_G: float | None, constant_velocity: bool = True
               ) -> tuple[NDArray[np.float64], float]:
    """Chain Open3D hybrid f2f odometry; ``w_G`` None = all defaults, else the depth-scaling emulation."""
    odo = o3d.t.pipelines.odometry
    s = 1.0 if w_G is None else math.sqrt(w_G / 1.0)  # Open3D weighs both terms 0.5: ratio 1 -> s² = w_G
    params = odo.OdometryLossParams() if w_G is None else odo.OdometryLossParams(0.07 * s, 0.05 * s, 0.1)
    K = o3d.core.Tensor(cam.K, o3d.core.Dtype.Float64)
    velocity = np.eye(4)  # the previous relative motion: both trackers start at the constant-velocity prediction
    poses = [np.eye(4)]
    prev = None
    seconds = 0.0
    for rgb, depth in frames:
        t0 = time.perf_counter()
        img = o3d.t.geometry.RGBDImage(
            o3d.t.geometry.Image(np.ascontiguousarray(rgb)),
            o3d.t.geometry.Image(np.ascontiguousarray((depth * 1000.0).astype(np.uint16))),
        )
        if prev is not None:
            init = velocity.copy()
            init[:3, 3] *= s
            res = odo.rgbd_odometry_multi_scale(
                img, prev, K, o3d.core.Tensor(init, o3d.core.Dtype.Float64), 1000.0 / s, 3.0 * s,
                method=odo.Method.Hybrid, params=params
            )
            T = res.transformation.numpy().copy()
            T[:3, 3] /= s
            velocity = T if constant_velocity else np.eye(4)
            poses.append(poses[-1] @ T)
            seconds += time.perf_counter() - t0
        prev = img
    return np.stack(poses), 1000.0 * seconds / max(len(frames) - 1, 1)


def _o3d_legacy_track(frames: Frames, cam: PinholeCamera) -> tuple[NDArray[np.float64], float]:
    """Chain Open3D's legacy hybrid odometry (default options), each step started at the constant-velocity
    prediction; a failed step keeps the prediction."""
    odo = o3d.pipelines.odometry
    intrinsic = o3d.camera.PinholeCameraIntrinsic(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy)
    option, jacobian = odo.OdometryOption(), odo.RGBDOdometryJacobianFromHybridTerm()
    velocity, poses, prev, seconds = np.eye(4), [np.eye(4)], None, 0.0
    for rgb, depth in frames:
        t0 = time.perf_counter()
        img = o3d.geometry.RGBDImage.create_from_color_and_depth(
            o3d.geometry.Image(np.ascontiguousarray(rgb)),
            o3d.geometry.Image(np.ascontiguousarray((depth * 1000.0).astype(np.uint16))),
            depth_scale=1000.0, depth_trunc=3.0, convert_rgb_to_intensity=True,
        )
        if prev is not None:
            ok, T, _ = odo.compute_rgbd_odometry(img, prev, intrinsic, velocity, jacobian, option)
            velocity = T if ok else velocity
            poses.append(poses[-1] @ velocity)
            seconds += time.perf_counter() - t0
        prev = img
    return np.stack(poses), 1000.0 * seconds / max(len(frames) - 1, 1)


def _lf_track(frames: Frames, cam: PinholeCamera, cfg: TrackingConfig, constant_velocity: bool = True
              ) -> tuple[NDArray[np.float64], float]:
    track = track_sequence(frames, cam, config=cfg, constant_velocity=constant_velocity)
    return track.poses, 1000.0 * float(np.mean(track.seconds))


def _rpe(poses: NDArray[np.float64], gt: NDArray[np.float64]) -> tuple[float, float]:
    """Median translation (mm) and rotation (deg) error of the frame-to-frame motions."""
    est = np.linalg.inv(poses[:-1]) @ poses[1:]
    true = np.linalg.inv(gt[:-1]) @ gt[1:]
    err = np.linalg.inv(true) @ est
    cos = np.clip((np.trace(err[:, :3, :3], axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    t_mm = 1000.0 * float(np.median(np.linalg.norm(err[:, :3, 3], axis=1)))
    return t_mm, float(np.degrees(np.median(np.arccos(cos))))


def _drift_mm(poses: NDArray[np.float64], gt: NDArray[np.float64], delta: int = 30) -> float:
    """RMSE (mm) of the translation error of the motions over ``delta`` frames (30 = 1 s at 30 Hz): the drift
    rate, the TUM RPE over 1 s."""
    est = np.linalg.inv(poses[:-delta]) @ poses[delta:]
    true = np.linalg.inv(gt[:-delta]) @ gt[delta:]
    err = np.linalg.inv(true) @ est
    return 1000.0 * float(np.sqrt(np.mean(np.sum(err[:, :3, 3] ** 2, axis=1))))


def _windowed_ate_cm(poses: NDArray[np.float64], gt: NDArray[np.float64], window: int = 100, step: int = 25
                     ) -> float:
    """Mean ATE RMSE (cm) over the ``window``-frame stretches starting every ``step`` frames, each aligned on its
    own: the same accumulation as the whole-sequence ATE, less dominated by how one run's drift directions add up."""
    starts = range(0, len(poses) - window + 1, step)
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
    """320×240 input for Open3D (lightfast downsamples internally with ``resolution_scale``)."""
    small = cam.scaled(0.5)
    out = [
        (
            cv2.resize(rgb, (small.width, small.height), interpolation=cv2.INTER_AREA),
            cv2.resize(d, (small.width, small.height), interpolation=cv2.INTER_NEAREST),
        )
        for rgb, d in frames
    ]
    return out, small


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--last", type=int, default=299)
    ap.add_argument("--repeats", type=int, default=3,
                    help="runs of the headline rows (Open3D tensor and lightfast Eq. 7, raw frames) for the "
                    "repeatability table")
    ap.add_argument("--orderings", action=argparse.BooleanOptionalAction, default=True,
                    help="also track twelve orderings of the same frames (forward / reversed, strides 1-3; ~15 min)")
    ap.add_argument("--output", type=Path, default=Path(__file__).parent / "results" / "tracking_7scenes.md")
    args = ap.parse_args()
    ds = SevenScenes(DATA)
    idx = [i for i in ds.indices if args.first <= i <= args.last]
    raw = [ds.frame(i) for i in idx]
    frames: Frames = [(f.rgb, f.depth_mm.astype(np.float64) / 1000.0) for f in raw]
    gt = np.stack([f.T_world_cam for f in raw])
    cam = ds.camera
    small_frames, small_cam = _resize(frames, cam)
    for scale in (1.0, 0.5):  # numba compiles on first use (and after a move of the source): not a frame's time
        track_sequence(frames[:2], cam, config=TrackingConfig(resolution_scale=scale))

    runs: list[tuple[str, str, Callable[[], tuple[NDArray[np.float64], float]]]] = [
        ("Open3D hybrid (defaults)", "640×480", lambda: _o3d_track(frames, cam, w_G=None)),
        ("Open3D hybrid, w_G=10 via depth scaling", "640×480", lambda: _o3d_track(frames, cam, w_G=10.0)),
        ("Open3D hybrid (defaults)", "320×240", lambda: _o3d_track(small_frames, small_cam, w_G=None)),
        ("Open3D legacy hybrid (defaults)", "640×480", lambda: _o3d_legacy_track(frames, cam)),
        ("Open3D legacy hybrid (defaults)", "320×240", lambda: _o3d_legacy_track(small_frames, small_cam)),
        (
            "lightfast Eq. 7 (E_C + 10 E_G)",
            "320×240",
            lambda: _lf_track(frames, cam, TrackingConfig(resolution_scale=0.5)),
        ),
        (
            "lightfast depth-only (E_G)",
            "320×240",
            lambda: _lf_track(frames, cam, TrackingConfig(resolution_scale=0.5, mode="depth-only")),
        ),
        ("lightfast Eq. 7 (E_C + 10 E_G)", "640×480", lambda: _lf_track(frames, cam, TrackingConfig())),
        (DEPTH_DIFF, "320×240", lambda: _lf_track(frames, cam, DEPTH_DIFF_CFG(resolution_scale=0.5))),
        (DEPTH_DIFF, "640×480", lambda: _lf_track(frames, cam, DEPTH_DIFF_CFG())),
        # the protocol of the earlier runs: every alignment started at identity
        ("Open3D hybrid (defaults), identity start", "640×480",
         lambda: _o3d_track(frames, cam, w_G=None, constant_velocity=False)),
        ("Open3D hybrid (defaults), identity start", "320×240",
         lambda: _o3d_track(small_frames, small_cam, w_G=None, constant_velocity=False)),
        ("lightfast Eq. 7, identity start", "320×240",
         lambda: _lf_track(frames, cam, TrackingConfig(resolution_scale=0.5), constant_velocity=False)),
        ("lightfast Eq. 7, identity start", "640×480",
         lambda: _lf_track(frames, cam, TrackingConfig(), constant_velocity=False)),
    ]
    # the Kinect v1's colour and depth cameras are not registered: the same runs on colour shifted by the offset
    # estimated from the images alone (depth edges vs colour gradients, no poses; lightfast.data.sevenscenes)
    offset = colour_offset((f.rgb, f.depth_mm) for f in raw[::20])
    reg = [(shift_colour(rgb, offset), depth) for rgb, depth in frames]
    small_reg, _ = _resize(reg, cam)
    tag = f"colour registered ({offset[0]:+d}, {offset[1]:+d}) px"
    runs += [
        (f"Open3D hybrid (defaults), {tag}", "640×480", lambda: _o3d_track(reg, cam, w_G=None)),
        (f"Open3D hybrid (defaults), {tag}", "320×240", lambda: _o3d_track(small_reg, small_cam, w_G=None)),
        (f"lightfast Eq. 7, {tag}", "320×240", lambda: _lf_track(reg, cam, TrackingConfig(resolution_scale=0.5))),
        (f"lightfast Eq. 7, {tag}", "640×480", lambda: _lf_track(reg, cam, TrackingConfig())),
    ]
    rows = []
    ates: dict[tuple[str, str], list[float]] = {}
    for name, res, fn in runs:
        poses, ms = fn()
        ates[(name, res)] = [100.0 * ate_rmse(poses, gt)]
        rpe_mm, rpe_deg = _rpe(poses, gt)
        rows.append((name, res, ates[(name, res)][0], _windowed_ate_cm(poses, gt), _drift_mm(poses, gt),
                     rpe_mm, rpe_deg, ms))
        print(f"{name:45s} {res:8s} ATE {rows[-1][2]:6.2f} cm (windows {rows[-1][3]:5.2f})  drift "
              f"{rows[-1][4]:5.1f} mm/s  RPE {rpe_mm:5.2f} mm {rpe_deg:5.3f} deg  {ms:7.1f} ms/frame", flush=True)

    # Open3D's tensor odometry reduces its normal equations in parallel, in no fixed order: the same input does not
    # give the same trajectory twice. The headline rows again, to show how much the whole-sequence ATE moves.
    headline = [(n, r, fn) for n, r, fn in runs if n in ("Open3D hybrid (defaults)", "lightfast Eq. 7 (E_C + 10 E_G)")]
    for _ in range(args.repeats - 1):
        for name, res, fn in headline:
            ates[(name, res)].append(100.0 * ate_rmse(fn()[0], gt))
            print(f"{name:45s} {res:8s} ATE, repeated: {ates[(name, res)][-1]:6.2f} cm", flush=True)

    # the same comparison over twelve orderings of the frames (the first is the table above's sequence)
    order_rows: list[tuple[str, str, list[float]]] = []
    if args.orderings:
        orders = _orderings(len(frames))
        trackers: list[tuple[str, str, Callable[[list[int]], NDArray[np.float64]]]] = [
            ("Open3D hybrid (defaults)", "640×480", lambda ix: _o3d_track([frames[i] for i in ix], cam, w_G=None)[0]),
            ("Open3D hybrid (defaults)", "320×240",
             lambda ix: _o3d_track([small_frames[i] for i in ix], small_cam, w_G=None)[0]),
            ("Open3D legacy hybrid (defaults)", "640×480",
             lambda ix: _o3d_legacy_track([frames[i] for i in ix], cam)[0]),
            ("Open3D legacy hybrid (defaults)", "320×240",
             lambda ix: _o3d_legacy_track([small_frames[i] for i in ix], small_cam)[0]),
            ("lightfast Eq. 7 (E_C + 10 E_G)", "640×480",
             lambda ix: _lf_track([frames[i] for i in ix], cam, TrackingConfig())[0]),
            ("lightfast Eq. 7 (E_C + 10 E_G)", "320×240",
             lambda ix: _lf_track([frames[i] for i in ix], cam, TrackingConfig(resolution_scale=0.5))[0]),
            (DEPTH_DIFF, "640×480", lambda ix: _lf_track([frames[i] for i in ix], cam, DEPTH_DIFF_CFG())[0]),
            (DEPTH_DIFF, "320×240",
             lambda ix: _lf_track([frames[i] for i in ix], cam, DEPTH_DIFF_CFG(resolution_scale=0.5))[0]),
        ]
        for name, res, fn in trackers:
            values = [100.0 * ate_rmse(fn(ix), gt[ix]) for ix in orders.values()]
            order_rows.append((name, res, values))
            print(f"{name:45s} {res:8s} ATE over {len(values)} orderings: mean {np.mean(values):5.2f}, "
                  f"median {np.median(values):5.2f} cm", flush=True)
    order_lines = [
        "",
        f"Orderings: the same frames as {len(order_rows[0][2])} sequences, whole-sequence ATE RMSE [cm] of each. "
        "Column `k/s`: every k-th frame from frame s (k = 1: 30 Hz, 2: 15 Hz, 3: 10 Hz), `rev`: the same frames "
        "reversed. The first column is the sequence of the tables above (Open3D tensor runs again, so it may differ "
        "from them in the second decimal).",
        "",
        "| method | resolution | " + " | ".join(_orderings(len(frames))) + " | mean | median |",
        "|---|---|" + "---:|" * (len(order_rows[0][2]) + 2),
        *[f"| {n} | {r} | " + " | ".join(f"{a:.2f}" for a in v) + f" | **{np.mean(v):.2f}** | {np.median(v):.2f} |"
          for n, r, v in order_rows],
    ] if order_rows else []

    lines = [
        "# Frame-to-frame RGB-D tracking on 7-Scenes (paper §III-D, Eq. 7)",
        "",
        f"Frames {idx[0]}–{idx[-1]} of `{DATA.name}` ({len(idx)} frames), chained f2f odometry, each "
        "alignment started at the constant-velocity prediction (the previous relative motion, as `rgbd_tracker_node` "
        "does) unless the row says identity start.",
        "ATE RMSE after rigid (Umeyama) alignment to the ground truth; RPE = median error of the frame-to-frame "
        "motions (what one f2f alignment gets wrong; ATE adds how those errors accumulate);",
        "ATE windows = mean ATE RMSE of the 100-frame stretches starting every 25 frames (each aligned on its own); "
        "drift = RMSE of the translation error of the motions over 30 frames (1 s, the TUM RPE). The whole-sequence "
        "ATE of chained odometry depends on how one run's small errors happen to add up: two trackers with the same "
        "per-frame and per-second errors can differ by half a centimetre there, so read it with the other columns;",
        "ms/frame = wall time per aligned frame (pyramid / tensor preparation included), single process on a shared "
        "2-core machine.",
        "",
        "| method | resolution | ATE RMSE [cm] | ATE windows [cm] | drift [mm/s] | RPE [mm] | RPE [deg] | ms/frame |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
        *[f"| {n} | {r} | {a:.2f} | {aw:.2f} | {dr:.1f} | {t:.2f} | {d:.3f} | {m:.1f} |"
          for n, r, a, aw, dr, t, d, m in rows],
        "",
        f"Repeatability: the headline rows run {args.repeats} times on the same frames in this process (Open3D's "
        "tensor odometry sums its normal equations in parallel in no fixed order, so its trajectory differs from run "
        "to run; lightfast's Gauss-Newton is deterministic).",
        "",
        "| method | resolution | ATE RMSE of each run [cm] |",
        "|---|---|---|",
        *[f"| {n} | {r} | {', '.join(f'{a:.2f}' for a in ates[(n, r)])} |" for n, r, _ in headline],
        *order_lines,
        "",
        f"Generated {datetime.now(UTC).isoformat(timespec='seconds')} by `benchmarks/tracking_7scenes.py` "
        f"(Python {platform.python_version()}, NumPy {np.__version__}, Open3D {o3d.__version__}, "
        f"OpenCV {cv2.__version__}, {platform.machine()}).",
        "",
    ]
    report = "\n".join(lines)
    print(report)
    write_text_atomic(args.output, report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
