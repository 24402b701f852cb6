"""One run of the rACR evaluation (paper §5) on one simulated scene, in simulated time: :func:`run_one`.

Everything the method sees comes from the simulated devices (platform, VSE stand-in); the ground truth is read only
to place the platform and to score the result.

1. *Start:* the camera at ``T_world_camref · T_camref_cam0`` (:func:`initial_offset`: the scene's own offset for
   repeat 0, else a seeded draw of 5–12 cm along a random direction and 4–10° about a random axis); every method of
   a (scene, lighting, repeat) starts there with the same noise seeds (§5.2.1). The VSE stand-in renders under the
   session lighting (``similar`` or ``varied``), the reference was captured under ``reference``.
2. *rACR* is :class:`~lightfast.racr.session.RacrSession`, the code ``racr_node`` runs, with the method's node
   configuration (:func:`~lightfast.eval.racr.protocol.method_config`), on a simulated clock and without its
   alignment thread: the session issues its initialization motions (§3.2) and then the adjustments (§3.5–3.6); the
   platform executes them (:func:`~lightfast.sim.racr_platform.motion_duration_s`) and reports its stop; the VSE
   publishes one frame (1/15 s) after every stop and ``vse_idle_period_s`` after the session ran out of work;
   alignment jobs are run here and charged the paper's or their measured duration (parallel: while the platform
   moves; serial: the scheme waits for them). Stop: the session's stage ``converged`` (or a failure stage),
   ``max_adjustments``, ``max_time_s``, a refused motion, or nothing left to wait for.
3. *ACR* (:class:`~lightfast.racr.AcrBaseline`): the image rendered under the session lighting at the true camera
   against the reference image; ``acr_step_s`` plus the motion per iteration, up to ``acr_max_iterations``; a failed
   estimate ends the run where the camera is.
4. *Score:* the AFD (:meth:`~lightfast.sim.racr.RacrScene.afd`, px) of the final true camera against the
   reference; success if < 3 px; ``reported`` is the method's own verdict (the session's final stage). Output: a
   :class:`~lightfast.eval.racr.records.RunRecord` traced after every motion.
"""
from __future__ import annotations

import functools
import hashlib
import logging
import math
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lightfast.eval.errors import RacrEvalError
from lightfast.eval.racr.protocol import AFD_SUCCESS_PX, METHODS, RacrEvalConfig, method_config
from lightfast.eval.racr.records import RunRecord, TracePoint
from lightfast.geometry import make_transform, rotation_angle_deg, so3_exp
from lightfast.racr import AcrBaseline, AcrConfig, RacrError
from lightfast.racr.initialization import HandEyeResult
from lightfast.racr.node_config import RacrNodeConfig
from lightfast.racr.session import RacrSession
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


class _Devices:
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


class _PerturbedSession(RacrSession):
    """The §3.7 study: the session with a known rotation error injected into the X of its initialization."""

    def __init__(self, *args: Any, error_deg: float, seed: int, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.error_deg, self.seed = error_deg, seed

    def _hand_eye_result(self, result: HandEyeResult) -> HandEyeResult:
        rng = np.random.default_rng(self.seed + 7)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        X = result.T_cam_hand
        X_err = make_transform(so3_exp(axis * math.radians(self.error_deg)) @ X[:3, :3], X[:3, 3])
        return replace(result, T_cam_hand=X_err)


def _observation(obs: VseObservation) -> tuple[Array, Array, Array, list[tuple[Array, Array, Any]]]:
    """A VSE observation as the node reads it from the VSE's topics: cloud and poses in VSE units, intensities and
    keyframe images in [0, 1] (mono8 / 255)."""
    kfs = [(k.image.astype(np.float64) / 255.0, np.asarray(k.T_vse_cam, np.float64), k.camera)
           for k in obs.keyframes]
    return obs.points_vse.astype(np.float64), obs.intensity.astype(np.float64), obs.T_vse_cam, kfs


def _initialization_details(session: _Devices, racr: RacrSession) -> dict[str, Any]:
    """The initialization's errors against the truth (scale, hand–eye), for the record."""
    he = racr.status.hand_eye
    if he is None:
        return {}
    X_hat, X, s_true = he.T_cam_hand, session.platform.truth_T_cam_hand, session.vse.scale_m_per_vse
    return {
        "scale_estimated": he.scale_m_per_vse, "scale_true": s_true, "scale_error_rel": he.scale_m_per_vse / s_true - 1,
        "handeye_rotation_error_deg": float(rotation_angle_deg(X_hat[:3, :3], X[:3, :3])),
        "handeye_angle_difference_deg": abs(float(rotation_angle_deg(X_hat[:3, :3]))
                                            - float(rotation_angle_deg(X[:3, :3]))),
        "handeye_translation_error_mm": 1e3 * float(np.linalg.norm(X_hat[:3, 3] - X[:3, 3])),
    }


_ENDED = ("converged", "ambiguous", "initialization_failed", "failed", "platform_timeout")


def _run_racr(scene: Any, devices: _Devices, node: RacrNodeConfig, config: RacrEvalConfig,
              record: RunRecord) -> None:
    plat, vse = devices.platform, devices.vse
    now = [0.0]
    session_class: Callable[..., RacrSession] = RacrSession
    if config.handeye_error_deg > 0.0:
        session_class = functools.partial(_PerturbedSession, error_deg=config.handeye_error_deg, seed=devices.seed)
    racr = node.start_session(scene.reference, clock=lambda: now[0], threaded=False, session_class=session_class)

    def observe() -> None:
        try:
            points, intensity, T_vse_cam, kfs = _observation(vse.observe(plat.true_camera_pose, stamp_s=now[0]))
            racr.add_vse_observation(points, intensity, T_vse_cam, kfs, stamp=now[0])
        except RacrError as exc:  # an unusable cloud: the VSE publishes again later
            log.debug("VSE observation refused: %s", exc)

    racr.add_platform_pose(plat.reported_hand_pose, stamp=0.0)
    observe()
    job, job_end = None, math.inf
    arrival: float | None = None
    next_obs: float | None = None
    reason = "time limit"
    while now[0] <= config.max_time_s:
        scheme = racr.scheme
        if scheme is not None and not record.trace:  # the initialization is over: the loop starts
            record.time_init_s = now[0]
            record.details.update(_initialization_details(devices, racr))
            record.trace.append(TracePoint(0, now[0], *_errors(scene, plat.true_camera_pose)))
        if racr.status.stage in _ENDED:
            reason = racr.status.stage
            break
        if job is None and scheme is not None:
            job = scheme.next_alignment_job()
            if job is not None:
                job.run()
                cost = job.seconds if config.job_cost == "measured" else (
                    config.fine_s if job.kind == "fine" else config.fast_s * job.alignments)
                job_end = now[0] + cost
        if arrival is None:
            cmd = racr.next_hand_motion()
            if cmd is not None:
                if cmd.kind != "initialization" and record.adjustments >= config.max_adjustments:
                    reason = "adjustment limit"
                    break
                try:
                    arrival = now[0] + plat.execute(cmd.M_hand)
                except PlatformError as exc:
                    reason = f"platform refused the motion: {exc}"
                    break
                if cmd.kind != "initialization":  # an adjustment, or a correction of the self-check
                    record.adjustments += 1
                    record.trace.append(TracePoint(record.adjustments, arrival - record.time_init_s,
                                                   *_errors(scene, plat.true_camera_pose), g=cmd.g or math.nan))
                next_obs = None
                continue
            if racr.status.stage in _ENDED:
                continue
        if job is None and arrival is None and next_obs is None:
            next_obs = now[0] + config.vse_idle_period_s  # nothing to do: wait for the VSE's next output
        now[0] = min(job_end if job is not None else math.inf, arrival if arrival is not None else math.inf,
                     next_obs if next_obs is not None else math.inf)
        if not math.isfinite(now[0]):
            reason = "stalled"
            break
        if job is not None and scheme is not None and now[0] >= job_end:
            scheme.commit(job)
            job, job_end = None, math.inf
        if arrival is not None and now[0] >= arrival:
            arrival = None
            racr.platform_stopped(plat.reported_hand_pose, stamp=now[0])
            next_obs = now[0] + config.vse_frame_s
        elif next_obs is not None and now[0] >= next_obs:
            next_obs = None
            observe()
    st = racr.status
    record.stop_reason = f"{reason}: {st.message}" if reason in _ENDED and reason != "converged" else reason
    record.converged = st.stage == "converged"
    record.reported = st.stage
    record.time_loop_s = min(now[0], config.max_time_s) - record.time_init_s
    if not record.trace:  # the initialization never finished
        record.time_init_s = min(now[0], config.max_time_s)
        record.time_loop_s = 0.0
        record.trace.append(TracePoint(0, 0.0, *_errors(scene, plat.true_camera_pose)))
    sch = st.scheme
    if sch is not None:
        record.details.update({
            "fast_alignments": sch.fast_alignments, "fine_alignments": sch.fine_alignments,
            "alignment_failures": sch.alignment_failures, "observations": sch.observations,
            "dropped_observations": sch.dropped_observations, "last_alignment_error": sch.last_alignment_error,
            "final_g": sch.g, "sigma_p": sch.sigma,
        })
    if st.init_error:
        record.details["init_error"] = st.init_error
    v = racr.verification
    if v is not None:  # the self-check's evidence, to study its verdicts against the truth
        record.details["verification"] = {
            "verdict": v.verdict, "matches": v.matches, "agreeing": v.agreeing,
            "other_pose_inliers": v.other_pose_inliers, "disagreement_px": v.disagreement_px,
            "corrections": v.corrections,
            "shift": None if v.shift is None else asdict(v.shift),
            "restarts": None if v.restarts is None else asdict(v.restarts)}


def _run_acr(scene: Any, session: _Devices, config: RacrEvalConfig, record: RunRecord) -> None:
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


def run_one(scene: Any, lighting: str, method: str, repeat: int = 0, config: RacrEvalConfig | None = None,
            node: RacrNodeConfig | None = None, key: str = "") -> RunRecord:
    """One run of the protocol (module documentation) on a loaded :class:`~lightfast.sim.racr.RacrScene`; ``node``:
    the rACR node's configuration the methods start from (default: the node's defaults); ``key``: the record's."""
    config = config or RacrEvalConfig()
    if method not in METHODS:
        raise RacrEvalError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    if lighting not in scene.lightings:
        raise RacrEvalError(f"scene {scene.spec.name} has no lighting {lighting!r}")
    wall0 = time.perf_counter()
    devices = _Devices(scene, lighting, repeat, config)
    afd0 = scene.afd(devices.platform.true_camera_pose).afd_px
    record = RunRecord(scene.spec.name, scene.spec.kind, lighting, method, repeat, key, math.inf, False, afd0, 0,
                       False, "", 0.0, 0.0, 0.0)
    if method == "acr":
        _run_acr(scene, devices, config, record)
        record.reported = "converged" if record.converged else "stopped"
    else:
        _run_racr(scene, devices, method_config(method, node or RacrNodeConfig(), config), config, record)
    record.afd_px = scene.afd(devices.platform.true_camera_pose).afd_px
    record.success = bool(record.afd_px < AFD_SUCCESS_PX)
    record.wall_s = time.perf_counter() - wall0
    return record
