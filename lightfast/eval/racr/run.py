"""One run of the rACR evaluation (paper §5) on one simulated scene, in simulated time: :func:`run_one`.

Everything the method sees comes from the simulated devices (platform, VSE stand-in); the ground truth is read only
to place the platform and to score the result.

1. *Start:* the camera at ``T_world_camref · T_camref_cam0`` (:func:`initial_offset`: the scene's own offset for
   repeat 0, else a seeded draw of 5–12 cm along a random direction and 4–10° about a random axis); every method of
   a (scene, lighting, repeat) starts there with the same noise seeds (§5.2.1). The VSE stand-in renders under the
   session lighting (``similar`` or ``varied``), the reference was captured under ``reference``.
2. *Initialization (§3.2, Eq. 4–8):* ``init_motions`` out-and-back excursions about the hand's x, y, z axes in turn;
   :func:`~lightfast.racr.initialize` gives X̂ (``T_cam_hand``) and the real scale ŝ (m per VSE unit) from the
   reported hand motions and the VSE's (monocular, drifting, noisy) camera motions; their duration is
   ``time_init_s``.
3. *VSE scaling (§3.3):* every VSE observation (semi-dense cloud, pose ``T_vse_cam``, keyframes) is put in metres by
   ŝ, images in [0, 1].
4. *Alignment loop (§3.5–3.6):* :class:`~lightfast.racr.RacrScheme` driven by explicit alignment jobs in a
   discrete-event simulation. The VSE publishes one frame (1/15 s) after every platform stop, and
   ``vse_idle_period_s`` after the scheme ran out of work; jobs are charged the paper's or their measured duration,
   motions :func:`~lightfast.sim.racr_platform.motion_duration_s`. Parallel mode aligns while the platform moves;
   serial mode aligns nothing while it moves and each stop waits for the newest observation's fast and fine
   alignment. Stop: g ≤ η, ``max_adjustments``, ``max_time_s``, a refused motion, or nothing left to wait for.
5. *ACR* (:class:`~lightfast.racr.AcrBaseline`): the image rendered under the session lighting at the true camera
   against the reference image; ``acr_step_s`` plus the motion per iteration, up to ``acr_max_iterations``; a failed
   estimate ends the run where the camera is.
6. *Score:* the AFD (:meth:`~lightfast.sim.racr.RacrScene.afd`, px) of the final true camera against the
   reference; success if < 3 px. Output: a :class:`~lightfast.eval.racr.records.RunRecord` traced after every motion.
"""
from __future__ import annotations

import hashlib
import logging
import math
import time
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lightfast.eval.errors import RacrEvalError
from lightfast.eval.racr.protocol import AFD_SUCCESS_PX, METHODS, RacrEvalConfig, protocol_hash
from lightfast.eval.racr.records import RunRecord, TracePoint
from lightfast.geometry import inverse, make_transform, rotation_angle_deg, so3_exp
from lightfast.racr import (
    AcrBaseline,
    AcrConfig,
    AdjustmentConfig,
    FastAlignmentConfig,
    FineAlignmentConfig,
    InitializationConfig,
    Keyframe,
    RacrError,
    RacrScheme,
    ReferenceCloud,
    SchemeConfig,
    initialize,
    relative_motions,
)
from lightfast.sim.errors import PlatformError
from lightfast.sim.racr_platform import PlatformSimulator, VseObservation, VseStandIn

log = logging.getLogger(__name__)

Array = NDArray[np.float64]


def _seed(scene: str, lighting: str, repeat: int) -> int:
    """The run's seed: the same for every method of a (scene, lighting, repeat)."""
    return int.from_bytes(hashlib.sha256(f"{scene}/{lighting}/{repeat}".encode()).digest()[:4], "little")


def initial_offset(scene: Any, repeat: int) -> Array:
    """``T_camref_cam0`` of a repeat: the scene's own for repeat 0, else a seeded draw from the same ranges."""
    if repeat == 0:
        return np.array(scene.truth.T_camref_cam0, dtype=np.float64)
    rng = np.random.default_rng([int(scene.spec.name[1:]), repeat, 99])
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    return make_transform(so3_exp(axis * math.radians(rng.uniform(4.0, 10.0))), rng.uniform(0.05, 0.12) * direction)


def _errors(scene: Any, T_world_cam: Array) -> tuple[float, float, float]:
    """(AFD px, position error mm, rotation error deg) of a camera pose against the reference (truth)."""
    T_ref = scene.truth.T_world_camref
    return (scene.afd(T_world_cam).afd_px, 1e3 * float(np.linalg.norm(T_world_cam[:3, 3] - T_ref[:3, 3])),
            float(rotation_angle_deg(T_world_cam[:3, :3], T_ref[:3, :3])))


def _trace_point(scene: Any, platform: PlatformSimulator, index: int, t: float, g: float = math.nan) -> TracePoint:
    afd, pos, rot = _errors(scene, platform.true_camera_pose)
    return TracePoint(index, t, afd, pos, rot, g)


class _Session:
    """The simulated devices of one run: platform (true X), VSE stand-in under the session lighting."""

    def __init__(self, scene: Any, lighting: str, repeat: int, config: RacrEvalConfig) -> None:
        self.scene = scene
        seed = _seed(scene.spec.name, lighting, repeat)
        X = scene.truth.T_cam_hand
        T_world_cam0 = scene.truth.T_world_camref @ initial_offset(scene, repeat)
        self.platform = PlatformSimulator(T_world_cam0 @ X, X, config=scene.platform_config,
                                          T_world_base=scene.truth.T_world_base, seed=seed)
        vse_config = replace(scene.vse_config, keyframe_baseline_m=config.vse_keyframe_baseline_m)
        self.vse: VseStandIn = scene.make_vse(lighting, seed=seed + 1, config=vse_config)
        self.lighting = lighting
        self.seed = seed


def _init_motion(k: int, config: RacrEvalConfig) -> Array:
    axis = np.eye(3)[k % 3]
    return make_transform(so3_exp(axis * math.radians(config.init_rotation_deg)),
                          config.init_translation_m * axis)


def _initialize(session: _Session, config: RacrEvalConfig) -> tuple[Array, float, float, dict[str, Any]]:
    """§3.2 from the platform's own excursions: returns ``(X̂, ŝ, simulated seconds, details)``."""
    plat, vse = session.platform, session.vse
    hand = [plat.reported_hand_pose]
    cam = [vse.pose(plat.true_camera_pose)]
    seconds = 0.0
    for k in range(config.init_motions):
        M = _init_motion(k, config)
        for motion in (M, inverse(M)):
            seconds += plat.execute(motion)
            hand.append(plat.reported_hand_pose)
            cam.append(vse.pose(plat.true_camera_pose))
    result = initialize(relative_motions(np.stack(cam)), relative_motions(np.stack(hand)),
                        config=InitializationConfig(method=config.init_method))
    X_hat = result.T_cam_hand
    if config.handeye_error_deg > 0.0:  # §3.7 study: rotate R̂_X by a known angle about a seeded random axis
        rng = np.random.default_rng(session.seed + 7)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        X_hat = make_transform(so3_exp(axis * math.radians(config.handeye_error_deg)) @ X_hat[:3, :3], X_hat[:3, 3])
    X = plat.truth_T_cam_hand
    s_true = session.vse.scale_m_per_vse
    details = {
        "scale_estimated": result.scale_m_per_vse, "scale_true": s_true,
        "scale_error_rel": result.scale_m_per_vse / s_true - 1.0,
        "handeye_rotation_error_deg": float(rotation_angle_deg(X_hat[:3, :3], X[:3, :3])),
        "handeye_angle_difference_deg": abs(float(rotation_angle_deg(X_hat[:3, :3]))
                                            - float(rotation_angle_deg(X[:3, :3]))),
        "handeye_translation_error_mm": 1e3 * float(np.linalg.norm(X_hat[:3, 3] - X[:3, 3])),
    }
    return X_hat, result.scale_m_per_vse, seconds, details


def _to_scheme(obs: VseObservation, s: float) -> tuple[Array, Array, Array, list[Keyframe]]:
    """A VSE observation in real scale (§3.3): points and poses times ŝ, images in [0, 1]."""
    def scaled(T: Array) -> Array:
        out = np.array(T, dtype=np.float64)
        out[:3, 3] *= s
        return out

    kfs = [Keyframe(k.image.astype(np.float64) / 255.0, scaled(k.T_vse_cam), k.camera) for k in obs.keyframes]
    return s * obs.points_vse.astype(np.float64), obs.intensity.astype(np.float64), scaled(obs.T_vse_cam), kfs


def _scheme_configs(method: str, config: RacrEvalConfig) -> tuple[SchemeConfig, FastAlignmentConfig,
                                                                   FineAlignmentConfig]:
    spec = METHODS[method]
    assert spec is not None
    mode, fine, refine, scale = spec
    return (SchemeConfig(mode=mode, fine_alignment=fine), FastAlignmentConfig(estimate_scale=scale),
            FineAlignmentConfig(refine_keyframes=refine, estimate_scale=scale))


def _run_racr(scene: Any, session: _Session, method: str, config: RacrEvalConfig,
              record: RunRecord) -> None:
    plat, vse = session.platform, session.vse
    try:
        X_hat, s_hat, t_init, details = _initialize(session, config)
    except RacrError as exc:
        record.stop_reason = f"initialization failed: {exc}"
        return
    record.time_init_s = t_init
    record.details.update(details)
    scheme_cfg, fast_cfg, fine_cfg = _scheme_configs(method, config)
    ref = scene.reference
    reference = ReferenceCloud.from_config(np.asarray(ref.points_m, np.float64), fast_cfg)
    now = [0.0]
    scheme = RacrScheme(reference, ref.T_ref_camref, X_hat, config=scheme_cfg, fast_config=fast_cfg,
                        fine_config=fine_cfg, adjustment_config=AdjustmentConfig(eta=config.eta),
                        clock=lambda: now[0])

    def observe() -> None:
        pts, inten, T_A, kfs = _to_scheme(vse.observe(plat.true_camera_pose, stamp_s=now[0]), s_hat)
        try:
            scheme.add_vse_observation(pts, inten, T_A, kfs, stamp=now[0])
        except RacrError as exc:  # an unusable cloud: the VSE publishes again later
            log.debug("VSE observation refused: %s", exc)

    record.trace.append(_trace_point(scene, plat, 0, 0.0))
    observe()
    job, job_end = None, math.inf
    arrival: float | None = None
    next_obs: float | None = None
    reason = "time limit"
    while now[0] <= config.max_time_s:
        if job is None:
            job = scheme.next_alignment_job()
            if job is not None:
                job.run()
                cost = job.seconds if config.job_cost == "measured" else (
                    config.fine_s if job.kind == "fine" else config.fast_s * job.alignments)
                job_end = now[0] + cost
        if arrival is None:
            step = scheme.next_hand_motion()
            if step is not None:
                if step.converged:
                    record.converged = True
                    reason = "converged"
                    break
                if record.adjustments >= config.max_adjustments:
                    reason = "adjustment limit"
                    break
                scheme.add_platform_pose(plat.reported_hand_pose, moving=True, stamp=now[0])
                try:
                    arrival = now[0] + plat.execute(step.M_hand)
                except PlatformError as exc:
                    reason = f"platform refused the motion: {exc}"
                    break
                record.adjustments += 1
                record.trace.append(TracePoint(record.adjustments, arrival, *_errors(scene, plat.true_camera_pose),
                                               g=step.g))
                next_obs = None
                continue
        if job is None and arrival is None and next_obs is None:
            next_obs = now[0] + config.vse_idle_period_s  # nothing to do: wait for the VSE's next output
        now[0] = min(job_end if job is not None else math.inf, arrival if arrival is not None else math.inf,
                     next_obs if next_obs is not None else math.inf)
        if not math.isfinite(now[0]):
            reason = "stalled"
            break
        if job is not None and now[0] >= job_end:
            scheme.commit(job)
            job, job_end = None, math.inf
        if arrival is not None and now[0] >= arrival:
            arrival = None
            scheme.add_platform_pose(plat.reported_hand_pose, moving=False, stamp=now[0])
            next_obs = now[0] + config.vse_frame_s
        elif next_obs is not None and now[0] >= next_obs:
            next_obs = None
            observe()
    record.stop_reason = reason
    record.time_loop_s = min(now[0], config.max_time_s)
    st = scheme.status
    record.details.update({
        "fast_alignments": st.fast_alignments, "fine_alignments": st.fine_alignments,
        "alignment_failures": st.alignment_failures, "observations": st.observations,
        "dropped_observations": st.dropped_observations, "last_alignment_error": st.last_alignment_error,
        "final_g": st.g, "sigma_p": st.sigma,
    })


def _run_acr(scene: Any, session: _Session, config: RacrEvalConfig, record: RunRecord) -> None:
    plat = session.platform
    ref = scene.reference
    record.trace.append(_trace_point(scene, plat, 0, 0.0))
    t = 0.0
    reason = "iteration limit"
    try:
        acr = AcrBaseline(ref.image, ref.camera, AcrConfig())
    except RacrError as exc:
        record.stop_reason = f"ACR cannot start: {exc}"
        return
    rng = np.random.default_rng(session.seed + 3)
    for _ in range(config.acr_max_iterations):
        image = scene.render(plat.true_camera_pose, session.lighting, seed=int(rng.integers(1 << 31))).image
        t += config.acr_step_s
        try:
            step = acr.step(image)
        except RacrError as exc:
            reason = f"ACR failed: {exc}"
            break
        if step.converged:
            record.converged = True
            reason = "converged"
            break
        if t > config.max_time_s:
            reason = "time limit"
            break
        try:
            t += plat.execute(step.M_hand)
        except PlatformError as exc:
            reason = f"platform refused the motion: {exc}"
            break
        record.adjustments += 1
        record.trace.append(_trace_point(scene, plat, record.adjustments, t))
    record.stop_reason = reason
    record.time_loop_s = t
    record.details.update({"acr_halvings": acr.halvings, "acr_step_m": acr.step_m})


def run_one(scene: Any, lighting: str, method: str, repeat: int = 0,
            config: RacrEvalConfig | None = None) -> RunRecord:
    """One run of the protocol (module documentation) on a loaded :class:`~lightfast.sim.racr.RacrScene`."""
    config = config or RacrEvalConfig()
    if method not in METHODS:
        raise RacrEvalError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    if lighting not in scene.lightings:
        raise RacrEvalError(f"scene {scene.spec.name} has no lighting {lighting!r}")
    wall0 = time.perf_counter()
    session = _Session(scene, lighting, repeat, config)
    afd0 = scene.afd(session.platform.true_camera_pose).afd_px
    record = RunRecord(scene.spec.name, scene.spec.kind, lighting, method, repeat, protocol_hash(config),
                       math.inf, False, afd0, 0, False, "", 0.0, 0.0, 0.0)
    if method == "acr":
        _run_acr(scene, session, config, record)
    else:
        _run_racr(scene, session, method, config, record)
    record.afd_px = scene.afd(session.platform.true_camera_pose).afd_px
    record.success = bool(record.afd_px < AFD_SUCCESS_PX)
    record.wall_s = time.perf_counter() - wall0
    return record
