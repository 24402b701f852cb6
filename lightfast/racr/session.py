"""One rACR relocalization run as a robot driver sees it (paper §3.2 then §3.3–3.6): the initialization motions,
the hand–eye and real-scale initialization, then the scheme. ROS-free; ``racr_node`` feeds it messages as arrays
and publishes what it returns.

1. **Initialization motions (§3.2).** The session issues ``init_motions`` hand motions itself: for every axis
   ``a`` of ``init_axes`` (hand frame) a screw motion ``M_B = ⟨exp(θ a), d a⟩`` (rotation ``init_rotation_deg``
   about ``a`` and translation ``init_translation_m`` along it: Eq. 8 needs a translation along the rotation axis),
   followed by its inverse when ``init_return`` (the camera ends where it started, near the reference, which the
   fast alignment's start guess assumes). Each motion is paired with the camera motion the VSE saw,
   ``M_A = T_vse_cam(before)⁻¹ · T_vse_cam(after)`` (VSE units), and the hand motion the platform reported,
   ``M_B = T_base_hand(before)⁻¹ · T_base_hand(after)`` (metres). "After" means: the platform reported a stop
   (:meth:`RacrSession.platform_stopped`) stamped at or after the command, and then the VSE delivered a pose
   stamped after that stop.
2. **Initialization (§3.2, Eq. 4–8):** :func:`~lightfast.racr.initialization.initialize` gives ``X = T_cam_hand``
   and the real scale ``s``. Degenerate motions (e.g. a platform that only translates) or motions that do not
   correspond end the session in stage ``initialization_failed``: no further motion is issued.
3. **The scheme (§3.3–3.6):** a :class:`~lightfast.racr.scheme.RacrScheme` with X, started with its alignment
   thread, and the first observation taken after the last initialization motion (the fast alignment's start guess
   puts that camera at the reference pose); every VSE input is scaled by ``s`` (§3.3: ``P = s · P_VSE``,
   ``t_A = s · t_VSE``, keyframe translations alike) before it is handed on; platform stops are ``moving=False``
   poses. Hand motions come from :meth:`RacrScheme.next_hand_motion` until it reports convergence (``g ≤ η``).
4. **The self-check** (:mod:`lightfast.racr.self_check`, not in the paper): the estimate is checked against the
   reference image; a failed check with a correction ``δ`` (where the image puts the camera) moves the camera by
   it (``kind`` ``correction``, stage ``correcting``) and checks again, up to ``corrections`` times. Then the run
   is over (``converged``, ``failed`` or ``ambiguous``): no further motion is issued.

Time: stamps are seconds on the injected ``clock`` (the node's ROS clock). A command is issued at ``clock()``; no
motion is computed from a camera pose taken before its stop. No simulator truth is read. Bad input raises
:class:`~lightfast.racr.errors.RacrError` subclasses; :attr:`RacrSession.status` says what it waits for.
"""
from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.config import Config, ConfigError, param
from lightfast.geometry import make_transform, rotation_angle_deg, so3_exp
from lightfast.racr.adjustment import AdjustmentConfig, _inverse, _rigid, camera_pose_in_reference, motion_gap
from lightfast.racr.alignment_job import finite_vse_cloud
from lightfast.racr.errors import InitializationError, RacrError
from lightfast.racr.fast_alignment import FastAlignmentConfig, ReferenceCloud
from lightfast.racr.fine import FineAlignmentConfig, Keyframe
from lightfast.racr.initialization import HandEyeResult, InitializationConfig, initialize
from lightfast.racr.scheme import RacrScheme, SchemeConfig, SchemeStatus
from lightfast.racr.self_check import SelfCheck
from lightfast.racr.verification import ReferenceView, Verification, VerificationConfig

__all__ = [
    "HAND_AXES",
    "SESSION_STAGES",
    "MotionCommand",
    "RacrSession",
    "SessionConfig",
    "SessionStatus",
    "initialization_motions",
]

logger = logging.getLogger(__name__)

Array = NDArray[np.float64]

HAND_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
#: Stages before the scheme runs; after that the stage is the scheme's (``SCHEME_STAGES``: aligning, ready,
#: moving, converged, platform_timeout, failed).
SESSION_STAGES = ("waiting_for_platform", "waiting_for_vse", "initializing", "initialization_failed", "correcting",
                  "ambiguous")


@dataclass(frozen=True)
class SessionConfig(Config):
    """The initialization motions (§3.2) and the waits of one rACR run."""

    init_axes: tuple[str, ...] = param(
        ("x", "y"), description="Hand axes of the initialization screw motions, one motion each (at least two "
        "different axes: parallel rotation axes do not determine X).", choices=tuple(HAND_AXES),
    )
    init_rotation_deg: float = param(
        20.0, description="Rotation of each initialization motion about its hand axis, deg (OpenCV's Tsai solver "
        "needs about 17 deg or more; 0 makes pure translations, which cannot determine X).", min=0.0, max=90.0,
    )
    init_translation_m: float = param(
        0.02, description="Translation of each initialization motion along its hand axis (Eq. 8 needs it), m.",
        min=0.0, max=0.5,
    )
    init_return: bool = param(
        True, description="Follow every initialization motion by its inverse, so the camera ends where it started "
        "(the inverse motions are used for the initialization too).",
    )
    vse_timeout_s: float = param(
        30.0, description="After a platform stop, a VSE pose stamped after it is awaited this long before the "
        "status warns, s.", min=0.0,
    )

    def check(self) -> None:
        if not self.init_axes:
            raise ConfigError("SessionConfig.init_axes: give at least one hand axis")

    @property
    def init_motions(self) -> int:
        return len(self.init_axes) * (2 if self.init_return else 1)


def initialization_motions(config: SessionConfig) -> list[Array]:
    """The hand motions ``M_B = T_hand_hand'`` of the initialization, in order (see the module docstring)."""
    out: list[Array] = []
    theta = math.radians(config.init_rotation_deg)
    for name in config.init_axes:
        a = np.asarray(HAND_AXES[name], dtype=np.float64)
        M = make_transform(so3_exp(theta * a), config.init_translation_m * a)
        out.append(M)
        if config.init_return:
            out.append(_inverse(M))
    return out


@dataclass(frozen=True)
class MotionCommand:
    """A hand motion to execute: ``M_hand = T_hand_hand'`` (the platform moves as ``T_base_hand · M_hand``),
    issued at ``stamp`` (clock seconds). ``kind``: ``initialization`` or ``adjustment``; ``index``: 1-based count
    of the commands of this session; for adjustments ``g`` (Eq. 3's gap) and ``T_ref_cam``, the camera pose in the
    reference frame the motion was computed from."""

    M_hand: Array
    kind: str
    index: int
    stamp: float
    g: float | None = None
    T_ref_cam: Array | None = None

    def describe(self) -> str:
        """One line: kind, index, length (cm), angle (deg) and g."""
        t, angle = float(np.linalg.norm(self.M_hand[:3, 3])), float(rotation_angle_deg(self.M_hand[:3, :3]))
        g = "" if self.g is None else f", g={self.g:.3g}"
        return f"{self.kind} motion {self.index}: {100 * t:.2f} cm, {angle:.2f} deg{g}"


@dataclass(frozen=True)
class SessionStatus:
    """A snapshot for ``/racr/status``: ``stage`` (:data:`SESSION_STAGES` or the scheme's), a one-line
    ``message`` and its ``level`` (``ok``, ``warn``, ``error``), the initialization's progress and outcome, and
    the scheme's status once it runs."""

    stage: str
    level: str
    message: str
    time_s: float
    motions_issued: int
    init_motions_done: int
    init_motions_total: int
    scale_m_per_vse: float | None
    T_cam_hand: Array | None
    hand_eye: HandEyeResult | None
    init_error: str | None
    scheme: SchemeStatus | None
    vse_poses: int
    vse_observations: int
    platform_stops: int
    last_vse_stamp: float | None
    last_platform_stamp: float | None


@dataclass
class _VseObservation:
    stamp: float
    points: Array
    intensities: Array | None
    T_vse_cam: Array
    keyframes: tuple[Keyframe, ...]


def _check_observation(points_vse: ArrayLike, intensities: ArrayLike | None,
                       keyframes: Sequence[Keyframe | Sequence[object]]) -> tuple[Array, Array | None,
                                                                                    tuple[Keyframe, ...]]:
    """Shape, finiteness and keyframe checks of a VSE observation (the scheme's rules): rows with a non-finite
    coordinate or intensity are dropped; fewer than 30 left raises :class:`AlignmentError`."""
    pts, inten, _ = finite_vse_cloud(points_vse, intensities)
    return pts, inten, tuple(Keyframe.coerce(k) for k in keyframes)


def _scaled_pose(T: Array, s: float) -> Array:
    out = T.copy()
    out[:3, 3] *= s
    return out


class RacrSession:
    """One rACR run against a reference observation; see the module documentation.

    ``reference_points_m`` ``(m, 3)``: the reference cloud (metres, reference frame); ``T_ref_camref``: the
    reference camera pose. ``clock``: seconds, the time base of every stamp.
    """

    def __init__(
        self,
        reference_points_m: ArrayLike,
        T_ref_camref: ArrayLike,
        *,
        config: SessionConfig | None = None,
        scheme_config: SchemeConfig | None = None,
        fast_config: FastAlignmentConfig | None = None,
        fine_config: FineAlignmentConfig | None = None,
        adjustment_config: AdjustmentConfig | None = None,
        init_config: InitializationConfig | None = None,
        clock: Callable[[], float] = time.monotonic,
        threaded: bool = True,
        reference_image: ArrayLike | None = None,
        reference_camera: PinholeCamera | None = None,
        verification_config: VerificationConfig | None = None,
    ) -> None:
        self.config = config or SessionConfig()
        #: the scheme aligns in its own thread; False: the caller runs its jobs (``scheme.next_alignment_job``,
        #: ``job.run()``, ``scheme.commit``), e.g. an evaluation in simulated time
        self.threaded = threaded
        self.scheme_config = scheme_config or SchemeConfig()
        self.fast_config = fast_config or FastAlignmentConfig()
        self.fine_config = fine_config or FineAlignmentConfig()
        self.adjustment_config = adjustment_config or AdjustmentConfig()
        self.init_config = init_config or InitializationConfig()
        self._T_ref_camref = _rigid(T_ref_camref, "T_ref_camref")
        # built once here (normals, KD-tree): refuses an empty or non-finite reference at once
        self._reference = ReferenceCloud.from_config(reference_points_m, self.fast_config)
        self._clock = clock
        self._plan = initialization_motions(self.config)
        self.verification_config = verification_config or VerificationConfig()
        #: the reference image and its depth from the cloud, for the convergence self-check (None: no check)
        self._view = None if reference_image is None or reference_camera is None or not \
            self.verification_config.enabled else ReferenceView(reference_points_m, self._T_ref_camref,
                                                                reference_image, reference_camera,
                                                                self.verification_config)
        self.verification: Verification | None = None

        self._lock = threading.RLock()
        self._vse_pose: tuple[Array, float] | None = None  # latest raw (VSE units)
        self._observation: _VseObservation | None = None  # latest raw
        self._hand: tuple[Array, float] | None = None  # latest reported hand pose
        self._counts = {"vse_poses": 0, "vse_observations": 0, "stops": 0}
        self._motions_issued = 0
        # initialization state
        self._pending: float | None = None  # stamp of the command not yet followed by a stop
        self._last_stop: float | None = None
        self._before: tuple[Array, Array] | None = None  # (T_vse_cam, T_base_hand) before the current motion
        self._after_hand: Array | None = None  # the hand pose reported with the stop
        self._pairs_A: list[Array] = []
        self._pairs_B: list[Array] = []
        self._hand_eye: HandEyeResult | None = None
        self._init_error: str | None = None
        self._scheme: RacrScheme | None = None
        self._converged = False
        self._check: SelfCheck | None = None  # the self-check, from the scheme's convergence on (module docstring)

    # ------------------------------------------------------------------ lifecycle
    def stop(self, timeout: float | None = 30.0) -> None:
        """Stop the scheme's alignment thread (if it runs); re-raises an error that stopped it
        (:class:`~lightfast.racr.errors.SchemeError`)."""
        scheme = self._scheme
        if scheme is not None:
            scheme.stop(timeout)

    @property
    def scheme(self) -> RacrScheme | None:
        return self._scheme

    @property
    def reference(self) -> ReferenceCloud:
        return self._reference

    # ------------------------------------------------------------------ inputs
    def add_vse_pose(self, T_vse_cam: ArrayLike, *, stamp: float) -> None:
        """A VSE camera pose ``T_vse_cam`` (VSE frame and units) stamped ``stamp``."""
        T = _rigid(T_vse_cam, "T_vse_cam")
        with self._lock:
            self._counts["vse_poses"] += 1
            self._set_vse_pose(T, float(stamp))
            scheme, s = self._scheme, self._scale
        if scheme is not None and s is not None:
            scheme.add_vse_pose(_scaled_pose(T, s), stamp=float(stamp))

    def add_vse_observation(
        self,
        points_vse: ArrayLike,
        intensities: ArrayLike | None,
        T_vse_cam: ArrayLike,
        keyframes: Sequence[tuple[ArrayLike, ArrayLike, PinholeCamera]],
        *,
        stamp: float,
    ) -> None:
        """A VSE output: the cloud ``(n, 3)`` in VSE units with per-point intensities (or None), the camera pose
        ``T_vse_cam`` and keyframes ``(image, T_vse_cam, camera)`` (poses in VSE units; image values in the units
        of the intensities). Raises :class:`AlignmentError` / :class:`AdjustmentError` for unusable input."""
        T = _rigid(T_vse_cam, "T_vse_cam")
        pts, inten, kfs = _check_observation(points_vse, intensities, keyframes)
        obs = _VseObservation(float(stamp), pts, inten, T, kfs)
        with self._lock:
            self._counts["vse_observations"] += 1
            self._counts["vse_poses"] += 1
            self._observation = obs
            self._set_vse_pose(T, obs.stamp)
            scheme = self._scheme
            scaled = self._scale_observation(obs) if scheme is not None else None
        if scheme is not None and scaled is not None:
            self._hand_to_scheme(scheme, scaled)

    def add_platform_pose(self, T_base_hand: ArrayLike, *, stamp: float) -> None:
        """The platform's reported hand pose ``T_base_hand`` (metres), e.g. streamed at a fixed rate."""
        T = _rigid(T_base_hand, "T_base_hand")
        with self._lock:
            if self._hand is None or stamp >= self._hand[1]:
                self._hand = (T, float(stamp))
            scheme = self._scheme
        if scheme is not None:
            scheme.add_platform_pose(T, moving=True, stamp=float(stamp))  # stored only: no stop

    def platform_stopped(self, T_base_hand: ArrayLike, *, stamp: float) -> None:
        """The platform came to rest at ``stamp`` with the reported hand pose ``T_base_hand`` (the end of a motion,
        or a refused one). Ends the command issued at or before ``stamp``."""
        T = _rigid(T_base_hand, "T_base_hand")
        t = float(stamp)
        with self._lock:
            self._counts["stops"] += 1
            if self._hand is None or t >= self._hand[1]:
                self._hand = (T, t)
            scheme = self._scheme
            if scheme is None and self._pending is not None and t >= self._pending:
                self._pending = None
                self._last_stop = t
                self._after_hand = T
            if self._check is not None:
                self._check.stopped(t)
        if scheme is not None:
            scheme.add_platform_pose(T, moving=False, stamp=t)

    def _set_vse_pose(self, T: Array, stamp: float) -> None:
        if self._vse_pose is None or stamp >= self._vse_pose[1]:
            self._vse_pose = (T, stamp)

    # ------------------------------------------------------------------ motions
    def next_hand_motion(self) -> MotionCommand | None:
        """The next hand motion to execute, or None (waiting for the platform or the VSE, aligning, converged,
        failed). Call it periodically; a returned command must be executed (its stop reported) before the next.
        Once the scheme reported convergence (g ≤ η) the run is over: no further motion is issued. Re-raises, as
        :class:`~lightfast.racr.errors.SchemeError`, an error that stopped the alignment thread."""
        with self._lock:
            scheme = self._scheme
            if scheme is None:
                return self._next_initialization_motion()
            if self._converged:
                return None  # relocalized: the run is over
            check, obs = self._check, self._observation
            correcting = check is not None and check.corrections > 0
            if check is not None and correcting and not check.ready(None if obs is None else obs.stamp):
                return None
        if correcting:  # the check again, after a correction motion (outside the lock: it matches images)
            verification = self._verify()
            with self._lock:
                return self._conclude(verification, None)
        step = scheme.next_hand_motion()
        if step is None:
            return None
        if step.converged:
            st = scheme.status
            with self._lock:
                if self._view is not None and st.T_ref_cur is not None and st.sigma is not None and \
                        self._scale is not None:
                    self._check = SelfCheck(self._view, self._reference, self.fast_config, st.T_ref_cur, st.sigma,
                                            self._scale)
            verification = self._verify()
            with self._lock:
                return self._conclude(verification, step.g)
        with self._lock:
            self._motions_issued += 1
            return MotionCommand(step.M_hand.copy(), "adjustment", self._motions_issued, self._clock(), step.g,
                                 step.T_ref_cam.copy())

    def _next_initialization_motion(self) -> MotionCommand | None:
        if self._init_error is not None or self._pending is not None:
            return None
        if self._hand is None or self._vse_pose is None:
            return None
        if self._before is not None:  # a motion has ended: wait for a VSE pose taken after the stop
            assert self._last_stop is not None and self._after_hand is not None
            T_vse, t_vse = self._vse_pose
            if t_vse <= self._last_stop:
                return None
            T_vse0, T_hand0 = self._before
            self._pairs_A.append(_inverse(T_vse0) @ T_vse)
            self._pairs_B.append(_inverse(T_hand0) @ self._after_hand)
            self._before = None
        done = len(self._pairs_A)
        if done >= len(self._plan):
            self._finish_initialization()
            return None
        self._before = (self._vse_pose[0].copy(), self._hand[0].copy())
        now = self._clock()
        self._pending = now
        self._motions_issued += 1
        logger.debug("initialization motion %d of %d issued", done + 1, len(self._plan))
        return MotionCommand(self._plan[done].copy(), "initialization", self._motions_issued, now)

    def _finish_initialization(self) -> None:
        try:
            result = initialize(np.stack(self._pairs_A), np.stack(self._pairs_B), config=self.init_config)
        except InitializationError as exc:
            self._init_error = f"{type(exc).__name__}: {exc}"
            logger.warning("rACR initialization failed: %s", exc)
            return
        result = self._hand_eye_result(result)
        self._hand_eye = result
        logger.info("rACR initialization: s=%.6g m per VSE unit, residuals %.3g deg / %.3g m",
                    result.scale_m_per_vse, result.rotation_residual_deg, result.translation_residual_m)
        scheme = RacrScheme(self._reference, self._T_ref_camref, result.T_cam_hand, config=self.scheme_config,
                            fast_config=self.fast_config, fine_config=self.fine_config,
                            adjustment_config=self.adjustment_config, clock=self._clock)
        if self.threaded:
            scheme.start()
        self._scheme = scheme
        obs = self._observation
        if obs is not None and self._last_stop is not None and obs.stamp <= self._last_stop:
            obs = None  # taken before the last initialization motion ended: the next one starts the alignment
        if obs is not None:
            scaled = self._scale_observation(obs)
            self._hand_to_scheme(scheme, scaled)
        if self._vse_pose is not None and (obs is None or self._vse_pose[1] > obs.stamp):
            scheme.add_vse_pose(_scaled_pose(self._vse_pose[0], result.scale_m_per_vse), stamp=self._vse_pose[1])

    # ------------------------------------------------------------------ self-check (module docstring, 4.)
    def _verify(self) -> Verification | None:
        """The self-check on the latest observation; None without a reference image."""
        check, obs = self._check, self._observation
        if check is None or obs is None:
            return None
        return check.check(obs.points, obs.T_vse_cam, obs.keyframes)

    def _conclude(self, verification: Verification | None, g: float | None) -> MotionCommand | None:
        """After a check (lock held): a correction motion when the check failed with a correction and some are
        left, else the end of the run with this verdict."""
        check = self._check
        if check is not None and verification is not None:
            motion, now = None, self._clock()
            if self._vse_pose is not None and self._hand_eye is not None:
                motion = check.correction(verification, self._vse_pose[0], self._hand_eye.T_cam_hand, now)
            if motion is not None:
                self.verification = verification
                self._motions_issued += 1
                logger.info("rACR self-check failed (%s): correction %d of %d", verification.describe(),
                            check.corrections, self.verification_config.corrections)
                M, T_ref_cam = motion
                return MotionCommand(M, "correction", self._motions_issued, now, motion_gap(M), T_ref_cam)
            verification = check.final(verification)
        self._converged = True
        self.verification = verification
        logger.info("rACR converged%s%s", "" if g is None else f": g={g:.3g}",
                    "" if verification is None else f"; {verification.describe()}")
        return None

    def _hand_eye_result(self, result: HandEyeResult) -> HandEyeResult:
        """The initialization's result as the scheme gets it: unchanged here; a study of the method's sensitivity
        (§3.7: an error injected into X) overrides this."""
        return result

    @property
    def _scale(self) -> float | None:
        return None if self._hand_eye is None else self._hand_eye.scale_m_per_vse

    def _scale_observation(self, obs: _VseObservation) -> _VseObservation:
        s = self._scale
        assert s is not None
        kfs = tuple(Keyframe(k.image, _scaled_pose(np.array(k.T_cur_cam), s), k.camera) for k in obs.keyframes)
        return _VseObservation(obs.stamp, obs.points * s, obs.intensities, _scaled_pose(obs.T_vse_cam, s), kfs)

    @staticmethod
    def _hand_to_scheme(scheme: RacrScheme, obs: _VseObservation) -> None:
        scheme.add_vse_observation(obs.points, obs.intensities, obs.T_vse_cam, obs.keyframes, stamp=obs.stamp)

    # ------------------------------------------------------------------ inspection
    def aligned_cloud(self) -> tuple[NDArray[np.float32], NDArray[np.float32] | None] | None:
        """The observation of the latest estimate mapped into the reference frame by it,
        ``p_ref = R_p (σ_p s p_VSE) + t_p`` (float32 metres) with its intensities; None before an estimate."""
        with self._lock:
            scheme = self._scheme
        aligned = None if scheme is None else scheme.aligned_observation()
        if aligned is None:
            return None
        pts, inten = aligned
        return pts.astype(np.float32), None if inten is None else inten.astype(np.float32)

    def camera_pose_in_reference(self) -> Array | None:
        """The current camera pose in the reference frame from the latest VSE pose and estimate (§3.1's T̃_A),
        or None before an estimate."""
        with self._lock:
            scheme, pose, s = self._scheme, self._vse_pose, self._scale
        if scheme is None or pose is None or s is None:
            return None
        st = scheme.status
        if st.T_ref_cur is None or st.sigma is None:
            return None
        try:
            return camera_pose_in_reference(_scaled_pose(pose[0], s), st.T_ref_cur, st.sigma)
        except RacrError:
            return None

    @property
    def status(self) -> SessionStatus:
        """What the session does and waits for (does not raise)."""
        with self._lock:
            now = self._clock()
            scheme = self._scheme
            sst = scheme.status if scheme is not None else None
            stage, level, message = self._describe(now, sst)
            he = self._hand_eye
            return SessionStatus(
                stage=stage, level=level, message=message, time_s=now, motions_issued=self._motions_issued,
                init_motions_done=len(self._pairs_A), init_motions_total=len(self._plan),
                scale_m_per_vse=None if he is None else he.scale_m_per_vse,
                T_cam_hand=None if he is None else he.T_cam_hand.copy(), hand_eye=he, init_error=self._init_error,
                scheme=sst, vse_poses=self._counts["vse_poses"], vse_observations=self._counts["vse_observations"],
                platform_stops=self._counts["stops"],
                last_vse_stamp=None if self._vse_pose is None else self._vse_pose[1],
                last_platform_stamp=None if self._hand is None else self._hand[1],
            )

    def _describe(self, now: float, sst: SchemeStatus | None) -> tuple[str, str, str]:
        total = len(self._plan)
        done = len(self._pairs_A)
        timeout = self.scheme_config.platform_timeout_s
        v = self.verification
        check = self._check
        if check is not None and check.corrections > 0 and not self._converged and v is not None:
            moving = "moving" if check.issued is not None else "checking again"
            return "correcting", "warn", (f"converged to a wrong pose ({v.describe()}): correction {check.corrections}"
                                          f" of {self.verification_config.corrections} {moving}")
        if sst is not None and sst.stage == "converged" and v is not None and v.verdict != "verified":
            g = "" if sst.g is None else f" (g={sst.g:.3g} after {sst.adjustments} adjustments)"
            if v.verdict == "failed":
                return "failed", "error", f"converged to a wrong pose{g}: {v.describe()}"
            return "ambiguous", "warn", f"converged{g} but {v.describe()}"
        if sst is not None:
            stage, level, message = self._describe_scheme(sst)
            return stage, level, message if v is None or stage != "converged" else f"{message}; {v.describe()}"
        if self._init_error is not None:
            return "initialization_failed", "error", f"initialization failed (no motion will be issued): " \
                                                     f"{self._init_error}"
        if self._hand is None:
            return "waiting_for_platform", "warn", "waiting for the platform's hand pose"
        if self._vse_pose is None:
            return "waiting_for_vse", "warn", "waiting for the VSE's first camera pose"
        if self._pending is not None:
            waited = now - self._pending
            if waited > timeout:
                return "platform_timeout", "error", (
                    f"initialization motion {done + 1} of {total}: the platform has not reported a stop "
                    f"{waited:.1f} s after the command (platform_timeout_s={timeout:g})")
            return "initializing", "ok", f"initialization motion {done + 1} of {total} executing"
        if self._before is not None and self._last_stop is not None:
            waited = now - self._last_stop
            level = "warn" if waited > self.config.vse_timeout_s else "ok"
            return "initializing", level, (f"initialization motion {done + 1} of {total} done: waiting for a VSE "
                                           f"pose taken after the stop ({waited:.1f} s)")
        return "initializing", "ok", f"initialization: {done} of {total} motions done"

    @staticmethod
    def _describe_scheme(sst: SchemeStatus) -> tuple[str, str, str]:
        st = sst.stage
        g = "" if sst.g is None else f", g={sst.g:.3g}"
        if st == "failed":
            return st, "error", f"the alignment thread stopped: {sst.error}"
        if st == "platform_timeout":
            return st, "error", f"the platform has not reported a stop after adjustment {sst.adjustments}"
        if st == "converged":
            return st, "ok", f"converged after {sst.adjustments} adjustments{g}"
        if st == "moving":
            return st, "ok", f"adjustment {sst.adjustments} executing{g}"
        if st == "aligning":
            if sst.observations == 0:
                return st, "warn", "waiting for a usable VSE cloud"
            if sst.last_alignment_error and sst.T_ref_cur is None:
                return st, "warn", f"aligning; last alignment failed: {sst.last_alignment_error}"
            return st, "ok", f"aligning ({sst.fast_alignments} fast, {sst.fine_alignments} fine so far)"
        if st == "waiting_for_vse":
            return st, "warn", "waiting for a VSE observation"
        return st, "ok", f"a motion can be computed ({sst.fast_alignments} fast, {sst.fine_alignments} fine " \
                         f"alignments{g})"
