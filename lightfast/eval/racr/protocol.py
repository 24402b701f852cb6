"""The protocol of ``lightfast eval racr`` (paper §5): the compared methods, the simulation's parameters and what
decides a run's key.

Every rACR method is the node's own session (:class:`~lightfast.racr.session.RacrSession`, built by
:meth:`~lightfast.racr.node_config.RacrNodeConfig.start_session`) with the node's configuration — its defaults, or a
``racr_node`` parameter file — changed only as a method says (:data:`METHODS`: ``racr-serial`` sets
``scheme.mode: serial``; the §5.4 ablations ``racr-p`` without Eq. 16, ``racr-f`` without the fine alignment,
``racr-s`` with σ_p fixed at 1) and with ``adjustment.eta`` set to :attr:`RacrEvalConfig.eta`. ``acr`` is the ACR
baseline. Relocalization lightings: ``similar`` and ``varied`` (:mod:`lightfast.sim.racr`). Success: AFD <
``AFD_SUCCESS_PX`` = 3 px.

:class:`RacrEvalConfig` (seconds of simulated time, metres, degrees): the durations charged — alignment jobs at the
paper's durations (fast 0.2 s, fine 5 s, §3.6) or their measured CPU time, one ACR estimate 4.8 s (Table 3), one VSE
frame 1/15 s —, the stop rule (η, adjustment and time limits) and the hand–eye error injected for the §3.7 study.
VSE keyframes are spread ``vse_keyframe_baseline_m`` = 8 cm, the spread of the map a DSO builds during the
initialization motions (docs/racr_evaluation.md). η: the paper's 1e-4 is below what the simulated sensors resolve
(VSE pose jitter 0.02° / 0.2 mm, platform repeatability 0.005° / 0.05 mm), so no run would stop by itself; ``eta``
(default 2e-3) changes when a run stops, never how it is scored.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from lightfast.config import Config, param, replace_config
from lightfast.eval.cache import code_version
from lightfast.eval.errors import RacrEvalError
from lightfast.racr.node_config import RacrNodeConfig

#: method → changes of the node's configuration (dotted parameter names); ``acr`` is the baseline
METHODS: dict[str, dict[str, Any] | None] = {
    "racr": {},
    "racr-serial": {"scheme.mode": "serial"},
    "racr-p": {"fine.refine_keyframes": False},
    "racr-f": {"scheme.fine_alignment": False},
    "racr-s": {"fast.estimate_scale": False, "fine.estimate_scale": False},
    "acr": None,
}
LABELS = {"racr": "rACR", "racr-serial": "rACR (serial)", "racr-p": "rACR-P", "racr-f": "rACR-F",
          "racr-s": "rACR-S", "acr": "ACR"}
LIGHTINGS = ("similar", "varied")
ABLATION = ("racr", "racr-p", "racr-f", "racr-s")
PROTOCOL_VERSION = 3
AFD_SUCCESS_PX = 3.0


@dataclass(frozen=True)
class RacrEvalConfig(Config):
    """The simulation protocol of ``lightfast eval racr`` (see the module documentation)."""

    job_cost: str = param("paper", description="Simulated duration of an alignment job: the paper's (fast 0.2 s, "
                          "fine 5 s) or its measured CPU time.", choices=("paper", "measured"))
    fast_s: float = param(0.2, description="Simulated duration of one fast alignment (paper: 5 Hz), s.", min=0.0)
    fine_s: float = param(5.0, description="Simulated duration of one fine alignment (paper: 5 s), s.", min=0.0)
    acr_step_s: float = param(4.8, description="Simulated duration of one ACR pose estimate (paper Table 3), s.",
                              min=0.0)
    vse_frame_s: float = param(1.0 / 15.0, description="VSE frame period (DSO: 15 FPS), s.", min=0.0)
    vse_keyframe_baseline_m: float = param(
        0.08, description="Spread of the VSE's keyframes around the camera (VseConfig.keyframe_baseline_m; module "
        "notes), m.", min=0.0)
    vse_idle_period_s: float = param(1.0, description="A new VSE observation this long after the scheme ran out of "
                                     "work, s.", min=0.01)
    eta: float = param(2e-3, description="Stop threshold of g = ||M_B - I4|| (module notes: the paper's 1e-4 is "
                       "below the simulated sensors' noise).", min=0.0)
    max_adjustments: int = param(20, description="Most platform motions of one run.", min=1)
    max_time_s: float = param(600.0, description="Most simulated loop time of one run, s.", min=1.0)
    acr_max_iterations: int = param(30, description="Most ACR iterations.", min=1)
    handeye_error_deg: float = param(0.0, description="Extra rotation error injected into the estimated hand-eye "
                                     "X (the section 3.7 study), deg.", min=0.0, max=180.0)


def method_config(method: str, node: RacrNodeConfig, config: RacrEvalConfig) -> RacrNodeConfig:
    """The node configuration a method runs: ``node`` with the method's changes and the protocol's η."""
    changes = METHODS[method]
    if changes is None:
        raise RacrEvalError(f"{method} is not a configuration of the rACR session")
    return replace_config(node, {**changes, "adjustment.eta": config.eta})


#: The code a run executes (its version is part of the run's key).
CODE = ("racr", "eval/racr", "sim/racr", "sim/racr_platform.py", "sim/sky_model.py", "geometry", "camera.py",
        "raycast.py", "config.py")


def protocol_parts(config: RacrEvalConfig, node: RacrNodeConfig) -> dict[str, Any]:
    """What every run of an evaluation shares: the protocol version, its configuration, the node configuration
    and the code version."""
    return {"version": PROTOCOL_VERSION, "config": config.to_dict(), "node": node.to_dict(),
            "code": code_version(*CODE)}
