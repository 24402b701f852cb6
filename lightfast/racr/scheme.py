"""The rACR scheme (paper §3.6): VSE input, an alignment thread that never stops refining, and the adjustment loop;
plus the serial scheme the paper compares it with (Table 5). ROS-free.

:class:`RacrScheme` owns the state shared by the paper's three threads and runs the alignment thread itself:

* **VSE input** (:meth:`~RacrScheme.add_vse_observation`, :meth:`~RacrScheme.add_vse_pose`): the latest current
  cloud P ``(n, 3)`` with its intensities and keyframes, and the latest camera pose ``T_A = T_cur_cam`` (4×4), in
  the current-cloud frame with the real scale s applied (§3.3, metres). A latest-wins slot: a cloud superseded
  before its alignment finished is dropped (``status.dropped_observations``).
* **Alignment thread** (§3.4): on the newest observation the fast alignment (Eq. 12–15), warm-started from the
  last estimate (a cold start the first time: ``T_ref_cur_init`` / ``sigma_init`` and eight turned or shifted
  variants, :func:`~lightfast.racr.fast_alignment.fast_align_best`), repeated until it converges or settles; then
  the fine alignment (Eq. 16–18). Each result becomes the latest ``(T_p, σ_p)``. Its units of work are
  :class:`~lightfast.racr.alignment_job.AlignmentJob`.
* **Adjustment** (§3.5, :meth:`~RacrScheme.next_hand_motion`, called whenever the platform is idle): Eq. 3 from
  the latest ``T_A``, ``T_p``, ``σ_p`` and ``X`` gives the hand motion ``M̂_B`` (4×4, hand frame, metres) and
  ``g``; ``g ≤ η`` means converged. One motion per platform stop: the next one needs a reported stop
  (:meth:`~RacrScheme.add_platform_pose` with ``moving=False``) and a VSE pose stamped after it.

Modes (``SchemeConfig.mode``): ``"parallel"`` (the paper's rACR) aligns all the time, also while the platform
moves; ``"serial"`` (Table 5: "alternately conducting point cloud alignment and motion execution in one thread")
aligns nothing while the platform moves and offers the next motion only once the newest observation is aligned to
convergence (fast, then fine).

Time: every stamp and timeout uses the injected ``clock`` (seconds). A discrete-event simulator can run the
alignment without the thread (:meth:`~RacrScheme.next_alignment_job`, :meth:`AlignmentJob.run`,
:meth:`~RacrScheme.commit`). Errors: bad input raises at the call; an alignment's
:class:`~lightfast.racr.errors.RacrError` is logged and shown in :attr:`~RacrScheme.status`; anything else stops the
thread and is re-raised as :class:`SchemeError` by the next call. Details: ``docs/racr.md``.
"""
from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.config import Config, param
from lightfast.geometry import make_transform, so3_exp
from lightfast.racr.adjustment import AdjustmentConfig, AdjustmentStep, _inverse, _rigid, adjustment_step
from lightfast.racr.alignment_job import AlignmentJob, _Observation, finite_vse_cloud
from lightfast.racr.errors import AlignmentError, SchemeError
from lightfast.racr.fast_alignment import FastAlignmentConfig, FastAlignmentResult, ReferenceCloud
from lightfast.racr.fine import FineAlignmentConfig, Keyframe

__all__ = [
    "SCHEME_MODES",
    "SCHEME_STAGES",
    "RacrScheme",
    "SchemeConfig",
    "SchemeStatus",
]

logger = logging.getLogger(__name__)

Array = NDArray[np.float64]

SCHEME_MODES = ("parallel", "serial")
#: ``status.stage``: no observation yet; aligning (no motion possible yet, or serial after a stop); a motion can be
#: computed; a motion is being executed; converged (g ≤ η); the platform did not report a stop within
#: ``platform_timeout_s``; the thread died (see ``status.error``).
SCHEME_STAGES = ("waiting_for_vse", "aligning", "ready", "moving", "converged", "platform_timeout", "failed")
#: Fast-alignment results remembered to recognize a cycle (see :meth:`RacrScheme._settled`).
_SETTLE_HISTORY = 4


@dataclass(frozen=True)
class SchemeConfig(Config):
    """Options of the rACR scheme (paper §3.6)."""

    mode: str = param("parallel", description="parallel (the paper's rACR) or serial (Table 5's comparison).",
                      choices=SCHEME_MODES)
    fine_alignment: bool = param(True, description="Run the fine alignment after the fast one (False: rACR-F).")
    warm_match_gate: float = param(
        2.0, description="Warm-started fast alignments weight their matches by nearest-neighbour distance "
        "(FastAlignmentConfig.match_gate; 0 = off). Not on cold starts: far from the solution it cut the matches "
        "that lead there (simulated S05/S07 diverged).", min=0.0,
    )
    platform_timeout_s: float = param(
        60.0, description="No stop reported this long after a motion was issued: stage platform_timeout, s.", min=0.0
    )
    start_rotation_deg: float = param(
        6.0, description="Cold start: also try the first guess with the current camera turned by +-this about its x "
        "and y axes, keeping the best-fitting fast alignment (0: these four not tried), deg.", min=0.0, max=45.0,
    )
    start_translation_m: float = param(
        0.06, description="Cold start: ... and shifted by +-this along its x and y axes (0: not tried), m.", min=0.0,
    )
    start_max_scale_change: float = param(
        0.2, description="Cold start: discard fast alignments whose |log sigma_p| (sigma_init = 1 after the real "
        "scale) exceeds this (a collapsed scale fits deceptively well).", min=0.0,
    )
    settle_factor: float = param(
        10.0, description="A fast alignment that ends within this many times its tolerances of its previous result "
        "on the same cloud counts as converged.", min=1.0,
    )
    idle_wait_s: float = param(0.05, description="The thread's longest sleep while it has nothing to align, s.",
                               min=0.001, max=10.0)


@dataclass(frozen=True)
class SchemeStatus:
    """A snapshot of :class:`RacrScheme` (for ``/racr/status`` and logs). Transforms are copies; ``T_ref_cur`` and
    ``sigma`` are the latest estimate (None before the first fast alignment) and ``estimate_kind`` says which
    alignment produced it ("fast" or "fine")."""

    stage: str
    mode: str
    time_s: float
    T_ref_cur: Array | None
    sigma: float | None
    estimate_kind: str | None
    estimate_stamp: float | None
    g: float | None
    converged: bool
    adjustments: int
    observations: int
    dropped_observations: int
    fast_alignments: int
    fine_alignments: int
    alignment_failures: int
    last_alignment_error: str | None
    error: str | None


@dataclass
class _Estimate:
    T_ref_cur: Array
    sigma: float
    kind: str  # "fast" or "fine"
    seq: int  # the observation it was computed on
    stamp: float  # when it was published
    usable: bool  # a converged fast alignment or a fine one has been reached (motions may be issued)
    complete: bool  # the alignment of observation ``seq`` has finished (fine done or failed, or fine disabled)
    observation: _Observation  # the cloud it was computed on (``seq`` moves on when a failed fine step keeps it)


class RacrScheme:
    """The rACR scheme of §3.6 around a reference observation; see the module documentation.

    ``reference``: the reference cloud P_ref (a :class:`ReferenceCloud`, or points ``(m, 3)`` in metres, prepared
    with ``fast_config``'s normal options). ``T_ref_camref``: the reference camera pose T_A^ref (camera-to-reference,
    metres). ``T_cam_hand``: X from the initialization (§3.2). ``T_ref_cur_init`` / ``sigma_init``: the first fast
    alignment's start; by default σ_p = 1 (the real scale is applied) and T_p such that the current camera of the
    first observation sits at the reference pose, ``T_p = T_A^ref ⟨R_A, t_A⟩⁻¹`` (rACR starts near the reference).
    ``clock``: the time source of every stamp and timeout, seconds.
    """

    def __init__(
        self,
        reference: ReferenceCloud | ArrayLike,
        T_ref_camref: ArrayLike,
        T_cam_hand: ArrayLike,
        *,
        config: SchemeConfig | None = None,
        fast_config: FastAlignmentConfig | None = None,
        fine_config: FineAlignmentConfig | None = None,
        adjustment_config: AdjustmentConfig | None = None,
        T_ref_cur_init: ArrayLike | None = None,
        sigma_init: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.config = config if config is not None else SchemeConfig()
        self.fast_config = fast_config if fast_config is not None else FastAlignmentConfig()
        self.fine_config = fine_config if fine_config is not None else FineAlignmentConfig()
        self.adjustment_config = adjustment_config if adjustment_config is not None else AdjustmentConfig()
        for value, cls in ((self.config, SchemeConfig), (self.fast_config, FastAlignmentConfig),
                           (self.fine_config, FineAlignmentConfig), (self.adjustment_config, AdjustmentConfig)):
            if not isinstance(value, cls):
                raise SchemeError(f"expected a {cls.__name__}, got {type(value).__name__}")
        self._warm_config = replace(self.fast_config, kernel_initial_m=self.fast_config.kernel_final_m,
                                    match_gate=self.config.warm_match_gate)
        self._reference = (
            reference if isinstance(reference, ReferenceCloud) else ReferenceCloud.from_config(reference,
                                                                                                self.fast_config)
        )
        self._T_ref_camref = _rigid(T_ref_camref, "T_ref_camref")
        self._X = _rigid(T_cam_hand, "T_cam_hand")
        self._T_init = None if T_ref_cur_init is None else _rigid(T_ref_cur_init, "T_ref_cur_init")
        if not (np.isfinite(sigma_init) and sigma_init > 0.0):
            raise AlignmentError(f"sigma_init must be positive and finite, got {sigma_init!r}")
        self._sigma_init = float(sigma_init)
        self._clock = clock

        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._obs: _Observation | None = None  # the VSE input: the newest observation wins
        self._seq = 0
        self._dropped = 0
        self._pose: tuple[Array, float] | None = None  # latest (T_cur_cam, stamp)
        self._estimate: _Estimate | None = None
        self._pending_since: float | None = None  # stamp of the last issued motion until the platform stops
        self._last_stop = -np.inf
        self._platform_pose: tuple[Array, float] | None = None
        self._g: float | None = None
        self._converged = False
        self._adjustments = 0
        self._counts = {"fast": 0, "fine": 0, "failures": 0}
        self._fast_converged = False
        self._fast_history: deque[tuple[int, Array, float]] = deque(maxlen=_SETTLE_HISTORY)
        self._last_alignment_error: str | None = None
        self._timeout_logged = False
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._fatal: BaseException | None = None
        self._fatal_raised = False

    # ------------------------------------------------------------------ thread
    def start(self) -> RacrScheme:
        """Start the alignment thread (not a daemon: :meth:`stop` it, or use the scheme as a context manager).
        A stopped scheme can be started again."""
        with self._lock:
            if self._thread is not None:
                raise SchemeError("the alignment thread was already started")
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="racr-alignment", daemon=False)
            self._thread.start()
        return self

    def stop(self, timeout: float | None = 30.0) -> None:
        """Stop and join the alignment thread (the running alignment finishes first), then re-raise, as
        :class:`SchemeError`, an error that stopped it and was not raised yet."""
        thread = self._thread
        self._stop.set()
        with self._wake:
            self._wake.notify_all()
        if thread is not None:
            thread.join(timeout)
            if thread.is_alive():
                raise SchemeError(f"the alignment thread did not stop within {timeout} s")
            self._thread = None
        self._raise_fatal()

    @property
    def running(self) -> bool:
        """Whether the alignment thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def __enter__(self) -> RacrScheme:
        return self.start()

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc is None:
            self.stop()
        else:  # do not mask the exception in flight
            try:
                self.stop()
            except SchemeError:
                logger.exception("rACR alignment thread error while handling another exception")

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                job = self._next_job()
                if job is None:
                    with self._wake:
                        if not self._stop.is_set():
                            self._wake.wait(self.config.idle_wait_s)
                    continue
                self.commit(job.run())
        except BaseException as exc:  # surfaced on the caller side by _raise_fatal
            logger.exception("rACR alignment thread stopped")
            with self._lock:
                self._fatal = exc

    def _raise_fatal(self) -> None:
        with self._lock:
            exc, already = self._fatal, self._fatal_raised
            if exc is not None:
                self._fatal_raised = True
        if exc is not None and not already:
            raise SchemeError(f"the rACR alignment thread stopped: {type(exc).__name__}: {exc}") from exc

    # ------------------------------------------------------------------ inputs
    def add_vse_observation(
        self,
        points_cur: ArrayLike,
        intensities: ArrayLike | None,
        T_cur_cam: ArrayLike,
        keyframes: Sequence[Keyframe | Sequence[object]],
        *,
        stamp: float | None = None,
    ) -> None:
        """A new VSE output (§3.3): the current cloud ``(n, 3)`` with the real scale applied, each point's intensity
        ``(n,)`` (or None), the camera pose ``T_cur_cam`` = T_A and the keyframes (``Keyframe`` or ``(image,
        T_cur_cam, camera)``). Rows with a non-finite coordinate or intensity are dropped; fewer than 30 points
        left, bad shapes, a non-rigid pose or an invalid keyframe raise (and nothing is queued)."""
        self._raise_fatal()
        pts, inten, ok = finite_vse_cloud(points_cur, intensities)
        if not np.all(ok):
            logger.debug("dropped %d non-finite VSE points of %d", int(np.count_nonzero(~ok)), len(ok))
        T = _rigid(T_cur_cam, "T_cur_cam")
        kfs = tuple(Keyframe.coerce(k) for k in keyframes)
        with self._wake:
            t = self._clock() if stamp is None else float(stamp)
            self._seq += 1
            if self._obs is not None and not self._obs.done:
                self._dropped += 1  # superseded before its alignment finished
            self._obs = _Observation(self._seq, t, pts, inten, T, kfs)
            self._set_pose(T, t)
            self._wake.notify_all()

    def add_vse_pose(self, T_cur_cam: ArrayLike, *, stamp: float | None = None) -> None:
        """A new VSE camera pose T_A (current-cloud frame, real scale applied) without a new cloud."""
        self._raise_fatal()
        T = _rigid(T_cur_cam, "T_cur_cam")
        with self._wake:
            self._set_pose(T, self._clock() if stamp is None else float(stamp))
            self._wake.notify_all()

    def _set_pose(self, T: Array, stamp: float) -> None:
        if self._pose is None or stamp >= self._pose[1]:
            self._pose = (T, stamp)

    def add_platform_pose(self, T_base_hand: ArrayLike, *, moving: bool = False, stamp: float | None = None) -> None:
        """The platform's reported hand pose; ``moving=False`` after a motion was issued marks its end (the
        platform stopped), from which the next motion's camera pose must be newer."""
        self._raise_fatal()
        T = _rigid(T_base_hand, "T_base_hand")
        with self._wake:
            t = self._clock() if stamp is None else float(stamp)
            self._platform_pose = (T, t)
            if not moving and self._pending_since is not None and t >= self._pending_since:
                self._pending_since = None
                self._last_stop = t
                self._timeout_logged = False
            self._wake.notify_all()

    # ------------------------------------------------------------------ adjustment (§3.5)
    def next_hand_motion(self) -> AdjustmentStep | None:
        """The next hand motion M̂_B (Eq. 3) from the latest T_A, T_p, σ_p, or None when none can be issued yet:
        no converged fast alignment; a motion still executing (no stop reported); no VSE pose newer than the last
        stop; in serial mode, the newest observation not aligned to completion yet. A step with ``converged=True``
        (g ≤ η) must not be executed; otherwise the scheme now waits for the platform to stop."""
        self._raise_fatal()
        with self._wake:
            now = self._clock()
            if self._pending_since is not None:
                if now - self._pending_since > self.config.platform_timeout_s and not self._timeout_logged:
                    logger.warning(
                        "the platform has not reported a stop %.1f s after the last motion was issued",
                        now - self._pending_since,
                    )
                    self._timeout_logged = True
                return None
            est = self._estimate
            if est is None or not est.usable or self._pose is None or self._pose[1] <= self._last_stop:
                return None
            if self.config.mode == "serial" and not self._aligned_to_completion():
                return None
            step = adjustment_step(self._pose[0], est.T_ref_cur, est.sigma, self._T_ref_camref, self._X,
                                   config=self.adjustment_config)
            self._g = step.g
            self._converged = step.converged
            if not step.converged:
                self._pending_since = now
                self._adjustments += 1
                logger.debug("adjustment %d: g=%.3g from a %s estimate", self._adjustments, step.g, est.kind)
            self._wake.notify_all()
            return step

    # ------------------------------------------------------------------ alignment (§3.4)
    def next_alignment_job(self) -> AlignmentJob | None:
        """The alignment thread's next job at this moment (None: nothing to do now). For discrete-event simulators
        that run the scheme without its thread; :meth:`AlignmentJob.run` then :meth:`commit`."""
        if self.running:
            raise SchemeError("next_alignment_job() is for schemes without a running thread")
        self._raise_fatal()
        return self._next_job()

    def _next_job(self) -> AlignmentJob | None:
        with self._lock:
            obs = self._obs
            if obs is None or obs.done:
                return None
            if self.config.mode == "serial" and self._pending_since is not None:
                return None  # the serial scheme stands still while the platform moves
            est = self._estimate
            if est is None:
                T0 = self._T_init if self._T_init is not None else self._start_guess(obs.T_cur_cam)
                return AlignmentJob("fast", obs, self._reference, T0, self._sigma_init, self.fast_config,
                                    self.fine_config, starts=self._cold_starts(T0, obs.T_cur_cam),
                                    max_scale_change=self.config.start_max_scale_change)
            # after a converged fast alignment, refine (on the newest cloud: it differs little from the one the
            # fast alignment saw, and a VSE that streams clouds faster than a fine alignment runs must not starve it)
            kind = "fine" if self.config.fine_alignment and est.kind == "fast" and self._fast_converged else "fast"
            return AlignmentJob(kind, obs, self._reference, est.T_ref_cur, est.sigma, self._warm_config,
                                self.fine_config)

    def _aligned_to_completion(self) -> bool:
        """Serial mode: the newest observation has been aligned as far as it goes (caller holds the lock)."""
        est = self._estimate
        return self._obs is not None and self._obs.done and est is not None and est.complete

    def _cold_starts(self, T0: Array, T_cur_cam: Array) -> tuple[Array, ...]:
        """``T0`` and, per ``start_rotation_deg`` / ``start_translation_m``, the same guess with the current camera
        turned about / shifted along its x and y axes: ``T0 ⟨R_A, σ t_A⟩ D ⟨R_A, σ t_A⟩⁻¹``."""
        cfg = self.config
        moves = []
        for axis in np.eye(3)[:2]:
            for sign in (1.0, -1.0):
                if cfg.start_rotation_deg > 0.0:
                    moves.append(make_transform(so3_exp(sign * np.radians(cfg.start_rotation_deg) * axis), np.zeros(3)))
                if cfg.start_translation_m > 0.0:
                    moves.append(make_transform(np.eye(3), sign * cfg.start_translation_m * axis))
        if not moves:
            return ()
        A = T_cur_cam.copy()
        A[:3, 3] *= self._sigma_init
        A_inv = _inverse(A)
        return (T0, *(T0 @ A @ D @ A_inv for D in moves))

    def _start_guess(self, T_cur_cam: Array) -> Array:
        """T_p putting the current camera at the reference pose: ``T_A^ref ⟨R_A, σ t_A⟩⁻¹``."""
        scaled = T_cur_cam.copy()
        scaled[:3, 3] *= self._sigma_init
        return self._T_ref_camref @ _inverse(scaled)

    def commit(self, job: AlignmentJob) -> None:
        """Publish a finished job: the new estimate, or the failure in the status."""
        with self._wake:
            obs = job._obs
            now = self._clock()
            est = self._estimate
            if job.error is not None:
                self._counts["failures"] += 1
                self._last_alignment_error = f"{job.kind} alignment: {job.error}"
                logger.warning("rACR %s alignment failed on observation %d: %s", job.kind, obs.seq, job.error)
                obs.done = True  # do not retry the same data; wait for the next observation
                if est is not None and job.kind == "fine":
                    self._fast_converged = False
                    est.seq, est.complete = obs.seq, True  # the fast result stands
                self._wake.notify_all()
                return
            result = job.result
            assert result is not None
            self._counts[job.kind] += 1
            if isinstance(result, FastAlignmentResult):
                converged = result.converged or self._settled(obs.seq, result)
                self._fast_history.append((obs.seq, result.T_ref_cur.copy(), result.sigma))
                self._fast_converged = converged
                complete = converged and not self.config.fine_alignment
                obs.done = complete
                usable = converged or (est is not None and est.usable)
                self._estimate = _Estimate(result.T_ref_cur.copy(), result.sigma, "fast", obs.seq, now, usable,
                                           complete, obs)
                if not converged:
                    logger.debug("fast alignment not converged after %d iterations; continuing", result.iterations)
                elif not result.converged:
                    logger.debug("fast alignment settled: it repeats its last result on this cloud")
            else:
                self._fast_converged = False
                self._estimate = _Estimate(result.T_ref_cur.copy(), result.sigma, "fine", obs.seq, now, True, True,
                                           obs)
                obs.done = True
            self._wake.notify_all()

    def _settled(self, seq: int, result: FastAlignmentResult) -> bool:
        """A fast alignment that ran out of iterations on the same cloud and ended where one of its last
        ``_SETTLE_HISTORY`` runs on that cloud ended (within ``settle_factor`` times the tolerances τ_T, τ_σ) has
        converged for all purposes: the robust ICP can cycle between a few nearly equal states without ever
        meeting τ_T = 1e-4 (seen on real-density clouds, and as a 3-cycle on a simulated one)."""
        k = self.config.settle_factor
        for prev_seq, T_prev, sigma_prev in self._fast_history:
            if prev_seq != seq:
                continue
            dR = T_prev[:3, :3].T @ result.T_ref_cur[:3, :3]
            dt = result.T_ref_cur[:3, 3] - T_prev[:3, 3]
            change = float(np.sqrt(np.sum((dR - np.eye(3)) ** 2) + np.sum(dt**2)))
            if (change <= k * self.fast_config.pose_tolerance
                    and abs(result.sigma - sigma_prev) <= k * self.fast_config.scale_tolerance):
                return True
        return False

    def aligned_observation(self) -> tuple[Array, Array | None] | None:
        """The cloud the current estimate was computed on, mapped into the reference frame by it:
        ``(p_ref = R (σ p) + t (N, 3), intensities)``; None before an estimate. (Mapping the newest cloud instead
        shifts it by whatever the camera moved since the estimate's cloud was taken.)"""
        with self._lock:
            est = self._estimate
        if est is None:
            return None
        R, t = est.T_ref_cur[:3, :3], est.T_ref_cur[:3, 3]
        return (est.sigma * est.observation.points) @ R.T + t, est.observation.intensities

    # ------------------------------------------------------------------ status
    @property
    def status(self) -> SchemeStatus:
        """A snapshot of the scheme's state (does not raise; a dead thread shows as stage ``failed``)."""
        with self._lock:
            now = self._clock()
            est = self._estimate
            if self._fatal is not None:
                stage = "failed"
            elif self._converged:
                stage = "converged"
            elif self._pending_since is not None:
                stage = "platform_timeout" if now - self._pending_since > self.config.platform_timeout_s else "moving"
            elif self._pose is None:
                stage = "waiting_for_vse"
            elif est is None or not est.usable or (self.config.mode == "serial" and not self._aligned_to_completion()):
                stage = "aligning"
            else:
                stage = "ready"
            return SchemeStatus(
                stage=stage,
                mode=self.config.mode,
                time_s=now,
                T_ref_cur=None if est is None else est.T_ref_cur.copy(),
                sigma=None if est is None else est.sigma,
                estimate_kind=None if est is None else est.kind,
                estimate_stamp=None if est is None else est.stamp,
                g=self._g,
                converged=self._converged,
                adjustments=self._adjustments,
                observations=self._seq,
                dropped_observations=self._dropped,
                fast_alignments=self._counts["fast"],
                fine_alignments=self._counts["fine"],
                alignment_failures=self._counts["failures"],
                last_alignment_error=self._last_alignment_error,
                error=None if self._fatal is None else f"{type(self._fatal).__name__}: {self._fatal}",
            )
