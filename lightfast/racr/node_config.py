"""Configuration of ``racr_node`` (paper: rACR, §3): one frozen dataclass, :class:`RacrNodeConfig`, from which the
node's ROS parameters and ``config/racr_node.yaml`` are generated.

It holds the reference observation, the node's input handling and output, and the core configurations as
sections (dotted parameters, e.g. ``scheme.mode``, ``adjustment.eta``): :class:`~lightfast.racr.session.SessionConfig`
(``session``: initialization motions, §3.2), :class:`~lightfast.racr.initialization.InitializationConfig`
(``initialization``: hand–eye solver), :class:`~lightfast.racr.scheme.SchemeConfig` (``scheme``, §3.6),
:class:`~lightfast.racr.adjustment.AdjustmentConfig` (``adjustment``: η, §3.5),
:class:`~lightfast.racr.fast_alignment.FastAlignmentConfig` (``fast``, §3.4.2) and
:class:`~lightfast.racr.fine.FineAlignmentConfig` (``fine``, §3.4.3), each defaulting to the core's
defaults. Everything that shapes a run is read-only while the node runs; the reporting options may change.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from lightfast.config import param
from lightfast.errors import LightfastError
from lightfast.node_options import SensorInputOptions
from lightfast.racr.adjustment import AdjustmentConfig
from lightfast.racr.fast_alignment import FastAlignmentConfig
from lightfast.racr.fine import FineAlignmentConfig
from lightfast.racr.initialization import InitializationConfig
from lightfast.racr.reference import ReferenceObservation, load_reference
from lightfast.racr.scheme import SchemeConfig
from lightfast.racr.session import RacrSession, SessionConfig
from lightfast.racr.verification import VerificationConfig

__all__ = ["RacrNodeConfig", "ReferenceLoader"]

# The core's defaults are the node's defaults (test_config pins it).
_SESSION = SessionConfig()
_INIT = InitializationConfig()
_SCHEME = SchemeConfig()
_ADJUST = AdjustmentConfig()
_FAST = FastAlignmentConfig()
_FINE = FineAlignmentConfig()
_VERIFY = VerificationConfig()


@dataclass(frozen=True)
class RacrNodeConfig(SensorInputOptions):
    """Parameters of ``racr_node`` (module docstring)."""

    # reference observation ------------------------------------------------------------------------------------
    reference_path: str = param(
        "", description="Reference observation directory (format lightfast-racr-reference: reference.yaml, "
        "points.npz, image.png), required. While it cannot be loaded the node reports why and retries.",
        read_only=True,
    )
    reference_scene: str = param(
        "", description="Refuse a reference observation made for another scene than this one (empty: accept any).",
        read_only=True,
    )
    reference_retry_s: float = param(2.0, description="While the reference cannot be loaded, retry this often, s.",
                                     min=0.05, max=3600.0)
    # the core components, as sections (everything that shapes a run: read-only while the node runs) -----------
    session: SessionConfig = param(_SESSION, read_only=True, description="Initialization motions (§3.2) and the "
                                   "wait for the VSE after a stop.")
    initialization: InitializationConfig = param(_INIT, read_only=True, description="Hand-eye and scale solver "
                                                 "(Eq. 4-8).")
    scheme: SchemeConfig = param(_SCHEME, read_only=True, description="Parallel or serial scheme (§3.6), fine "
                                 "alignment on or off, platform timeout.")
    adjustment: AdjustmentConfig = param(_ADJUST, read_only=True, description="Adjustment and convergence (eta, "
                                         "§3.5).")
    fast: FastAlignmentConfig = param(_FAST, read_only=True, description="Fast alignment (§3.4.2).")
    fine: FineAlignmentConfig = param(_FINE, read_only=True, description="Fine alignment (§3.4.3).")
    verification: VerificationConfig = param(_VERIFY, read_only=True, description="Self-check of a convergence "
                                             "against the reference image (failed or ambiguous instead of "
                                             "converged).")
    # input ----------------------------------------------------------------------------------------------------
    keyframes_per_cloud: int = param(
        4, description="A /vse/points cloud waits for this many keyframes stamped like it (image + pose).", min=0,
        max=64, read_only=True,
    )
    input_wait_s: float = param(
        2.0, description="A cloud waits this long for its pose, keyframes and camera_info before it is used with "
        "what arrived (or reported and dropped without a pose), s.", min=0.0, max=60.0,
    )
    # output ---------------------------------------------------------------------------------------------------
    adjust_period_s: float = param(0.1, description="How often the node asks for the next hand motion, s.",
                                   min=0.001, max=10.0, read_only=True)
    status_period_s: float = param(1.0, description="Heartbeat of /racr/status (it is also published on every "
                                   "change of stage), s.", min=0.05, max=60.0, read_only=True)
    aligned_cloud_max_points: int = param(
        20000, description="Points of /racr/aligned_cloud (a fixed subsample; 0 = all, -1 = do not publish).",
        min=-1,
    )

    def start_session(self, reference: ReferenceObservation, clock: Callable[[], float], *, threaded: bool = True,
                      session_class: Callable[..., RacrSession] = RacrSession) -> RacrSession:
        """The session of a run against ``reference`` with this configuration (what ``racr_node`` and the
        evaluation run); ``clock`` gives the time in seconds; ``threaded``: see :class:`RacrSession`."""
        return session_class(reference.points_m, reference.T_ref_camref, config=self.session,
                             scheme_config=self.scheme, fast_config=self.fast, fine_config=self.fine,
                             adjustment_config=self.adjustment, init_config=self.initialization, clock=clock,
                             threaded=threaded, reference_image=reference.image,
                             reference_camera=reference.camera, verification_config=self.verification)


@dataclass
class ReferenceLoader:
    """The reference of a run (``reference_path``, ``reference_scene``) and its session, loaded on the first
    :meth:`attempt` and retried every ``reference_retry_s`` (``now_s``: a monotonic clock) while that fails."""

    config: RacrNodeConfig
    error: str | None = None  # why the last attempt failed
    _last_attempt_s: float | None = None

    @property
    def path(self) -> Path:
        return Path(self.config.reference_path).expanduser()

    def forget_attempts(self) -> None:
        """The next :meth:`attempt` tries at once."""
        self._last_attempt_s = None

    def attempt(self, now_s: float, clock: Callable[[], float]) -> tuple[ReferenceObservation, RacrSession] | None:
        """The reference and a new session on it, or None (not tried now, or failed: :attr:`error` says why)."""
        if self._last_attempt_s is not None and now_s - self._last_attempt_s < self.config.reference_retry_s:
            return None
        self._last_attempt_s = now_s
        try:
            reference = load_reference(self.path, scene=self.config.reference_scene or None)
            session = self.config.start_session(reference, clock)
        except (LightfastError, OSError) as exc:
            self.error = f"reference {self.path}: {exc}"
            return None
        self.error = None
        return reference, session
