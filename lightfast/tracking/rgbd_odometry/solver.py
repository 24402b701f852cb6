"""Gauss–Newton on SE(3) for Eq. 7 of paper §III-D, coarse to fine, and the f2f / f2m entry points.

Left increments ``T ← exp(ξ) T``, ``ξ = (ρ, φ)`` in m and rad (see :mod:`lightfast.geometry`), on a
``pyramid_levels`` image pyramid (:mod:`~lightfast.tracking.rgbd_odometry.pyramid`), coarse to fine down to
``finest_level``, ``iterations`` per level, early stop when ``|ξ| < step_tolerance``; each step solves the normal
equations of :mod:`~lightfast.tracking.rgbd_odometry.kernels`.

Optionally a prior ``½ λ N |log(T T₀⁻¹)|²`` at the start pose ``T₀`` (``pose_prior_weight`` λ per associated pixel,
N of them, so it does not depend on the resolution; off by default here). Not in Eq. 7: the tracker
(:class:`lightfast.tracking.pipeline.TrackerConfig`) turns it on for f2f, where ``T₀`` is the constant-velocity
prediction, like the motion prior of Kerl et al. (ICRA 2013): a view of one plain wall, or of a wall and the
floor, leaves directions that neither term constrains, and there Gauss–Newton follows noise.

:func:`align` solves Eq. 7 for one (source = live, target = reference) pair of images, :func:`align_frames` for
frames prepared once, :func:`track_sequence` chains f2f alignments into ``T_world_cam`` poses (m), :func:`warm_up`
compiles the numba kernels. Images as in :mod:`~lightfast.tracking.rgbd_odometry.pyramid`; the result
``T_target_source`` (4×4, m) maps source camera coordinates into target camera coordinates (REP-103 optical).
"""
from __future__ import annotations

import math
import time
from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.geometry import se3_exp, se3_log
from lightfast.tracking.errors import TrackingInputError
from lightfast.tracking.rgbd_odometry.config import AlignResult, SequenceTrack, TrackingConfig
from lightfast.tracking.rgbd_odometry.kernels import _Terms, linearize
from lightfast.tracking.rgbd_odometry.pyramid import RGBDFrame, _Level, _prepare, prepare_frame, repeated_input

__all__ = ["MOTION_PRIORS", "MOTION_PRIOR_MAX_GAP_S", "MotionPrior", "align", "align_frames", "predict_motion",
           "track_sequence", "warm_up"]

_MIN_CORRESPONDENCES = 50
#: Frames further apart than this (s) get no constant-velocity prediction: the f2f alignment starts at identity.
MOTION_PRIOR_MAX_GAP_S = 0.5
_FRAME_PERIOD_NS = 1_000_000_000 // 30  # track_sequence without stamps: 30 Hz (7-Scenes, the paper's recordings)
_SAME_INTERVAL_NS = 1_000  # intervals this close are equal (stamps of 30 Hz frames in ns differ by their rounding)
#: Starts of an f2f alignment (:class:`MotionPrior`).
MOTION_PRIORS = ("constant-velocity", "last-motion", "none")


def predict_motion(T_last: ArrayLike, dt_last_ns: int, dt_ns: int,
                   max_gap_s: float = MOTION_PRIOR_MAX_GAP_S) -> NDArray[np.float64]:
    """The constant-velocity prediction of the motion ``T_prev_cur`` over ``dt_ns`` from the last measured motion
    ``T_last`` over ``dt_last_ns``: ``exp(dt / dt_last · log T_last)`` (the same twist per second), ``T_last``
    itself when the two intervals are equal (to 1 µs). A frame that comes after frames were dropped is predicted over
    its whole interval rather than one frame's; identity when either interval is not positive or ``dt_ns`` exceeds
    ``max_gap_s`` (no prediction across a long gap). The trackers measure intervals from the previous frame received,
    also when its depth repeated its predecessor's (not aligned): in 7-Scenes, where the Kinect's unsynchronised
    streams repeat a depth image, the ground truth moves about one frame's motion from the frame before the repeat
    to the one after it, not two."""
    T = np.asarray(T_last, dtype=np.float64)
    if abs(dt_ns - dt_last_ns) <= _SAME_INTERVAL_NS and dt_ns > 0:
        return T.copy()
    if dt_last_ns <= 0 or dt_ns <= 0 or dt_ns > max_gap_s * 1e9:
        return np.eye(4)
    return se3_exp(se3_log(T) * (dt_ns / dt_last_ns))


class MotionPrior:
    """The start of an f2f alignment from the last motion measured (§III-D does not say; the trackers' rule, kept in
    one place for ``rgbd_tracker_node`` and :func:`track_sequence`): ``constant-velocity`` predicts over the frame's
    interval (:func:`predict_motion`), ``last-motion`` repeats the last motion whatever the interval (as DVO and
    ORB-SLAM predict), ``none`` starts at identity. An alignment that did not converge, or a reset, forgets the
    motion: the next one starts at identity."""

    def __init__(self, rule: str = "constant-velocity", max_gap_s: float = MOTION_PRIOR_MAX_GAP_S) -> None:
        if rule not in MOTION_PRIORS:
            raise TrackingInputError(f"motion prior must be one of {MOTION_PRIORS}, got {rule!r}")
        self.rule, self.max_gap_s = rule, float(max_gap_s)
        self.reset()

    def reset(self) -> None:
        """Forget the last motion."""
        self._T_last, self._dt_last_ns = np.eye(4), 0

    def predict(self, dt_ns: int) -> NDArray[np.float64]:
        """The start ``T_prev_cur`` of the alignment of a frame ``dt_ns`` after the previous one."""
        if self.rule == "last-motion":
            return self._T_last.copy()
        if self.rule == "none":
            return np.eye(4)
        return predict_motion(self._T_last, self._dt_last_ns, dt_ns, self.max_gap_s)

    def measured(self, T_prev_cur: NDArray[np.float64], dt_ns: int, converged: bool) -> None:
        """Record an alignment's motion over ``dt_ns``; one that did not converge is not a measurement."""
        if converged:
            self._T_last, self._dt_last_ns = np.asarray(T_prev_cur, dtype=np.float64), int(dt_ns)
        else:
            self.reset()


def _align_pyramids(
    src: tuple[_Level, ...],
    tgt: tuple[_Level, ...],
    init: NDArray[np.float64],
    cfg: TrackingConfig,
    use_color: bool,
    use_depth: bool,
    finest_level: int | None = None,
) -> AlignResult:
    """Gauss–Newton coarse to fine over the level pairs ``(src[k], tgt[k])`` from the coarsest down to
    ``finest_level`` (default ``cfg.finest_level``)."""
    finest = cfg.finest_level if finest_level is None else finest_level
    T = init.copy()
    init_inv = np.linalg.inv(init)
    total_iterations = 0
    level_converged = False
    terms = _Terms(np.zeros((6, 6)), np.zeros(6), 0, 0, math.inf)
    for level in reversed(range(finest, cfg.pyramid_levels)):
        n_iter = cfg.iterations[cfg.pyramid_levels - 1 - level]
        level_converged = False
        for _ in range(n_iter):
            terms = linearize(src[level], tgt[level], T, cfg, use_color, use_depth)
            if terms.count < _MIN_CORRESPONDENCES:
                break
            H, b = terms.H, terms.b
            if cfg.pose_prior_weight > 0.0:  # ½ eᵀΛe, e = log(T init⁻¹): stay put where the data says nothing
                lam = cfg.pose_prior_weight * terms.count  # per associated pixel: resolution-independent
                H = H + lam * np.eye(6)
                b = b + lam * se3_log(T @ init_inv)
            try:
                xi = np.linalg.solve(H, -b)
            except np.linalg.LinAlgError:
                break
            if not np.all(np.isfinite(xi)):
                break
            T = se3_exp(xi) @ T
            total_iterations += 1
            if float(np.linalg.norm(xi)) < cfg.step_tolerance:
                level_converged = True
                break
        else:
            # iteration budget used up: accept if the last step was small relative to the motion scale
            level_converged = terms.count >= _MIN_CORRESPONDENCES and float(np.linalg.norm(xi)) < 1e-3
    # statistics of the last linearisation at the finest level (before its final, small step)
    final = terms if total_iterations else linearize(src[finest], tgt[finest], T, cfg, use_color, use_depth)
    n_valid = max(len(src[finest].points), 1)
    inlier_ratio = final.inliers / n_valid
    converged = level_converged and final.count >= _MIN_CORRESPONDENCES and inlier_ratio >= cfg.min_inlier_ratio
    residual = final.cost if final.count else math.inf
    return AlignResult(T, bool(converged), total_iterations, float(inlier_ratio), float(residual))


def _resolve_terms(cfg: TrackingConfig, use_color: bool | None, use_depth: bool | None) -> tuple[bool, bool]:
    color = cfg.mode != "depth-only" if use_color is None else bool(use_color)
    depth = True if use_depth is None else bool(use_depth)
    if not (color or depth):
        raise TrackingInputError("align needs at least one of use_color / use_depth")
    return color, depth


def _check_init(init: ArrayLike | None) -> NDArray[np.float64]:
    T = np.eye(4) if init is None else np.asarray(init, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise TrackingInputError(f"init_T_target_source must be a finite 4x4 matrix, got shape {T.shape}")
    return T


def align(
    source_rgb: ArrayLike,
    source_depth_m: ArrayLike,
    target_rgb: ArrayLike,
    target_depth_m: ArrayLike,
    camera: PinholeCamera,
    *,
    init_T_target_source: ArrayLike | None = None,
    config: TrackingConfig | None = None,
    use_color: bool | None = None,
    use_depth: bool | None = None,
) -> AlignResult:
    """Align a live (source) RGB-D frame to a reference (target) one by minimising Eq. 7 of paper §III-D.

    Colour images are ``(H, W, 3)`` RGB (uint8, or float in [0, 1]) or ``(H, W)`` grey; depth images ``(H, W)``
    float metres (0 / NaN / outside ``[min_depth_m, max_depth_m]`` invalid); both at ``camera``'s full size (the
    ``resolution_scale`` is applied here). ``use_color`` (E_C) defaults to ``config.mode != "depth-only"``,
    ``use_depth`` (E_G) to True; the live depth is always used for data association.

    Raises :class:`TrackingError` on mismatched sizes, non-metric depth, or an image without valid depth.
    """
    cfg = TrackingConfig() if config is None else config
    color, depth = _resolve_terms(cfg, use_color, use_depth)
    init = _check_init(init_T_target_source)
    src = _prepare(source_rgb, source_depth_m, camera, cfg, "source")
    tgt = _prepare(target_rgb, target_depth_m, camera, cfg, "target")
    return _align_pyramids(src.levels, tgt.levels, init, cfg, color, depth)


def align_frames(
    source: RGBDFrame,
    target: RGBDFrame,
    *,
    init_T_target_source: ArrayLike | None = None,
    config: TrackingConfig | None = None,
    use_color: bool | None = None,
    use_depth: bool | None = None,
) -> AlignResult:
    """:func:`align` on frames prepared once by :func:`prepare_frame` (a live frame serves as the f2f source,
    then as the f2f target of the next frame, and as the f2m source against the reference).

    The target may be rendered at half the source's resolution (a reference at ``reference_scale`` 0.5): then
    source level ``k ≥ 1`` is aligned to target level ``k − 1``, of the same resolution, and the alignment stops at
    source level 1 (the reference's resolution) whatever ``finest_level`` says. (Pairing level ``k`` with level
    ``k`` instead started the alignment on a quarter-size target whose coarsest level, 40×30 for a 320×240 camera,
    left a plain room corner unconstrained. Projecting the full-resolution source level into the half-resolution
    target as well, four source points per target pixel, doubled the cost of f2m for no accuracy; the measurements
    are in docs/daylight.md, "Direct RGB-D tracking".)"""
    cfg = TrackingConfig() if config is None else config
    color, depth = _resolve_terms(cfg, use_color, use_depth)
    init = _check_init(init_T_target_source)
    for role, frame in (("source", source), ("target", target)):
        if (frame.pyramid_levels, frame.resolution_scale) != (cfg.pyramid_levels, cfg.resolution_scale):
            raise TrackingInputError(
                f"{role} frame was prepared with pyramid_levels={frame.pyramid_levels}, resolution_scale="
                f"{frame.resolution_scale}; this alignment uses {cfg.pyramid_levels}, {cfg.resolution_scale}"
            )
    if target.camera not in (source.camera, source.camera.scaled(0.5)):
        raise TrackingInputError(f"the target camera must be the source camera or the source camera at half "
                                 f"resolution: source {source.camera}, target {target.camera}")
    if target.camera == source.camera:
        return _align_pyramids(source.levels, target.levels, init, cfg, color, depth)
    # half resolution: same-size levels together; the full-resolution source level has no partner
    levels = (target.levels[0], *target.levels[:-1])
    return _align_pyramids(source.levels, levels, init, cfg, color, depth, max(cfg.finest_level, 1))


def track_sequence(
    frames: Iterable[tuple[ArrayLike, ArrayLike]],
    camera: PinholeCamera,
    *,
    config: TrackingConfig | None = None,
    T_world_first: ArrayLike | None = None,
    use_color: bool | None = None,
    use_depth: bool | None = None,
    motion_prior: str = "constant-velocity",
    stamps_ns: Sequence[int] | None = None,
) -> SequenceTrack:
    """Frame-to-frame tracking (the f2f step of §III-D) over ``(rgb, depth_m)`` frames; each frame is aligned to
    its predecessor, starting where :class:`MotionPrior` ``motion_prior`` puts it over the frames' ``stamps_ns``
    (default 1/30 s apart), as ``rgbd_tracker_node`` does, and the relative motions are
    chained from ``T_world_first``. A frame whose depth image repeats its predecessor's (:func:`repeated_input`) is
    not aligned (its ``results`` entry is None): it keeps the predecessor's pose, and the next frame is aligned to the
    predecessor; a frame whose colour image alone repeats is aligned by E_G alone. As ``rgbd_tracker_node`` does."""
    cfg = TrackingConfig() if config is None else config
    color, depth = _resolve_terms(cfg, use_color, use_depth)
    T_world = _check_init(T_world_first)
    poses = []
    results: list[AlignResult | None] = []
    seconds: list[float] = []
    prev: RGBDFrame | None = None
    last_stamp = 0  # of the previous frame, also when its depth repeated prev's
    prior = MotionPrior(motion_prior)
    for i, (rgb, depth_m) in enumerate(frames):
        t0 = time.perf_counter()
        stamp = i * _FRAME_PERIOD_NS if stamps_ns is None else int(stamps_ns[i])
        cur = _prepare(rgb, depth_m, camera, cfg, f"frame {i}")
        res = None
        if prev is not None:
            repeated = repeated_input(cur, prev)
            if repeated != "depth":
                init = prior.predict(stamp - last_stamp)
                res = _align_pyramids(cur.levels, prev.levels, init, cfg, color and repeated != "colour", depth)
                T_world = T_world @ res.T_target_source
                prior.measured(res.T_target_source, stamp - last_stamp, res.converged)
            results.append(res)
            seconds.append(time.perf_counter() - t0)
        poses.append(T_world.copy())
        if prev is None or res is not None:  # a repeated depth image leaves the predecessor the target
            prev = cur
        last_stamp = stamp
    if not poses:
        raise TrackingInputError("track_sequence got no frames")
    return SequenceTrack(np.stack(poses), tuple(results), np.asarray(seconds))


def warm_up(config: TrackingConfig | None = None) -> float:
    """Run every jitted kernel once on a tiny synthetic frame (a slanted plane with a colour ramp) with ``config``'s
    pyramid, so that a node's first live frame does not pay for numba's loading or compiling; returns seconds."""
    cfg = TrackingConfig() if config is None else config
    t0 = time.perf_counter()
    size = max(16, 8 * 2 ** (cfg.pyramid_levels - 1) * (2 if cfg.resolution_scale != 1.0 else 1))
    camera = PinholeCamera(size, size, float(size), float(size), (size - 1) / 2, (size - 1) / 2)
    v, u = np.mgrid[0:size, 0:size].astype(np.float32) / size
    depth = (0.5 * (cfg.min_depth_m + cfg.max_depth_m) * (1.0 + 0.05 * u + 0.03 * v)).astype(np.float32)
    rgb = (np.stack([u, v, 0.5 * (u + v)], axis=-1) * 255).astype(np.uint8)
    frame = prepare_frame(rgb, depth, camera, config=cfg, name="warm-up frame")
    align_frames(frame, frame, config=cfg, use_color=True, use_depth=True)
    return time.perf_counter() - t0
