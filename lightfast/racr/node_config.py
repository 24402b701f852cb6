"""Configuration of ``racr_node`` (paper: rACR, §3): one frozen dataclass, :class:`RacrNodeConfig`, from which the
node's ROS parameters and ``config/racr_node.yaml`` are generated.

It combines the reference observation, the node's input handling and the relevant options of
:class:`~lightfast.racr.session.SessionConfig` (initialization motions, §3.2),
:class:`~lightfast.racr.initialization.InitializationConfig` (hand–eye solver),
:class:`~lightfast.racr.scheme.SchemeConfig` (§3.6), :class:`~lightfast.racr.adjustment.AdjustmentConfig` (η, §3.5),
:class:`~lightfast.racr.fast_alignment.FastAlignmentConfig` (§3.4.2) and
:class:`~lightfast.racr.fine_alignment.FineAlignmentConfig` (§3.4.3); the ``*_config()`` methods build those. The
other options of the core keep their defaults. Everything that shapes a run is read-only while the node runs; the
reporting options may change.
"""
from __future__ import annotations

from dataclasses import dataclass

from lightfast.config import ConfigError, param
from lightfast.node_options import SensorInputOptions
from lightfast.racr.adjustment import AdjustmentConfig
from lightfast.racr.fast_alignment import FastAlignmentConfig
from lightfast.racr.fine_alignment import FineAlignmentConfig
from lightfast.racr.initialization import HAND_EYE_METHODS, InitializationConfig
from lightfast.racr.scheme import SCHEME_MODES, SchemeConfig
from lightfast.racr.session import HAND_AXES, SessionConfig

__all__ = ["RacrNodeConfig"]

# The core's defaults are the node's defaults (a change there shows up in `lightfast config write --check`).
_SESSION = SessionConfig()
_INIT = InitializationConfig()
_SCHEME = SchemeConfig()
_ADJUST = AdjustmentConfig()
_FAST = FastAlignmentConfig()
_FINE = FineAlignmentConfig()


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
    # initialization (§3.2) ------------------------------------------------------------------------------------
    init_axes: tuple[str, ...] = param(
        _SESSION.init_axes, choices=tuple(HAND_AXES), read_only=True,
        description="Hand axes of the initialization screw motions, one motion each (two different axes at least).",
    )
    init_rotation_deg: float = param(
        _SESSION.init_rotation_deg, min=0.0, max=90.0, read_only=True,
        description="Rotation of each initialization motion about its hand axis, deg (OpenCV's Tsai solver needs "
        "about 17 deg or more).",
    )
    init_translation_m: float = param(
        _SESSION.init_translation_m, min=0.0, max=0.5, read_only=True,
        description="Translation of each initialization motion along its hand axis (Eq. 8), m.",
    )
    init_return: bool = param(_SESSION.init_return, read_only=True,
                              description="Follow every initialization motion by its inverse.")
    hand_eye_method: str = param(_INIT.method, choices=HAND_EYE_METHODS, read_only=True,
                                 description="OpenCV calibrateHandEye method for R_X (Eq. 4).")
    # scheme (§3.5, §3.6) --------------------------------------------------------------------------------------
    mode: str = param(_SCHEME.mode, choices=SCHEME_MODES, read_only=True,
                      description="parallel (the paper's rACR) or serial (Table 5).")
    fine_alignment: bool = param(_SCHEME.fine_alignment, read_only=True,
                                 description="Run the fine alignment after the fast one (false: rACR-F).")
    eta: float = param(_ADJUST.eta, min=0.0, read_only=True,
                       description="eta of §3.5: converged when g = ||M_B - I4||_F <= eta.")
    platform_timeout_s: float = param(
        _SCHEME.platform_timeout_s, min=0.0, read_only=True,
        description="A commanded motion without a reported stop after this long: status platform_timeout, s.",
    )
    vse_timeout_s: float = param(
        _SESSION.vse_timeout_s, min=0.0, read_only=True,
        description="After a stop, a VSE pose taken after it is awaited this long before the status warns, s.",
    )
    # fast alignment (§3.4.2) ----------------------------------------------------------------------------------
    fast_max_points: int = param(_FAST.max_points, min=0, read_only=True,
                                 description="Fast alignment: current points sampled (0 = all).")
    fast_max_iterations: int = param(_FAST.max_iterations, min=1, max=100000, read_only=True,
                                     description="Fast alignment: cap on alternations.")
    fast_kernel_initial_m: float = param(_FAST.kernel_initial_m, min=1e-6, read_only=True,
                                         description="Fast alignment: Tukey width at the start, m.")
    fast_kernel_final_m: float = param(_FAST.kernel_final_m, min=1e-6, read_only=True,
                                       description="Fast alignment: Tukey width after annealing, m.")
    normal_radius_m: float = param(_FAST.normal_radius_m, min=1e-6, read_only=True,
                                   description="Neighbourhood radius of the reference normals, m.")
    # fine alignment (§3.4.3) ----------------------------------------------------------------------------------
    fine_alpha: float = param(_FINE.alpha, min=0.0, max=1.0, read_only=True,
                              description="Fine alignment: alpha of Eq. 11 (weight of E_g).")
    fine_max_keyframes: int = param(_FINE.max_keyframes, min=2, max=64, read_only=True,
                                    description="Fine alignment: most recent keyframes used.")
    fine_max_geometric_points: int = param(_FINE.max_geometric_points, min=0, read_only=True,
                                           description="Fine alignment: current points for E_g (0 = all).")
    fine_max_photometric_points: int = param(_FINE.max_photometric_points, min=0, read_only=True,
                                             description="Fine alignment: reference points for E_p (0 = all "
                                             "visible).")
    fine_max_keyframe_points: int = param(_FINE.max_keyframe_points, min=0, read_only=True,
                                          description="Fine alignment: current points for Eq. 16 (0 = all visible).")
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

    def check(self) -> None:
        for build in (self.session_config, self.init_config, self.scheme_config, self.adjustment_config,
                      self.fast_config, self.fine_config):
            try:
                build()
            except ConfigError as exc:
                raise ConfigError(f"RacrNodeConfig: {exc}") from None

    def session_config(self) -> SessionConfig:
        return SessionConfig(init_axes=self.init_axes, init_rotation_deg=self.init_rotation_deg,
                             init_translation_m=self.init_translation_m, init_return=self.init_return,
                             vse_timeout_s=self.vse_timeout_s)

    def init_config(self) -> InitializationConfig:
        return InitializationConfig(method=self.hand_eye_method)

    def scheme_config(self) -> SchemeConfig:
        return SchemeConfig(mode=self.mode, fine_alignment=self.fine_alignment,
                            platform_timeout_s=self.platform_timeout_s)

    def adjustment_config(self) -> AdjustmentConfig:
        return AdjustmentConfig(eta=self.eta)

    def fast_config(self) -> FastAlignmentConfig:
        return FastAlignmentConfig(max_points=self.fast_max_points, max_iterations=self.fast_max_iterations,
                                   kernel_initial_m=self.fast_kernel_initial_m,
                                   kernel_final_m=self.fast_kernel_final_m, normal_radius_m=self.normal_radius_m)

    def fine_config(self) -> FineAlignmentConfig:
        return FineAlignmentConfig(alpha=self.fine_alpha, max_keyframes=self.fine_max_keyframes,
                                   max_geometric_points=self.fine_max_geometric_points,
                                   max_photometric_points=self.fine_max_photometric_points,
                                   max_keyframe_points=self.fine_max_keyframe_points)
