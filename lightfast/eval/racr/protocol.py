"""The protocol of ``lightfast eval racr`` (paper §5): the compared methods, the simulation's parameters and the hash
that names a protocol's records.

Methods: ``racr`` (parallel scheme, §3.6), ``racr-serial``, the ablations of §5.4 — ``racr-p`` without Eq. 16
(``FineAlignmentConfig.refine_keyframes=False``), ``racr-f`` without the fine alignment
(``SchemeConfig.fine_alignment=False``), ``racr-s`` with σ_p fixed at 1 (``estimate_scale`` off in both alignments:
the real scale ŝ of the initialization is all it has) — and ``acr``, the ACR baseline. Relocalization lightings:
``similar`` and ``varied`` (:mod:`lightfast.sim.racr`). Success: AFD < ``AFD_SUCCESS_PX`` = 3 px.

:class:`RacrEvalConfig` (seconds of simulated time, metres, degrees): the durations charged — alignment jobs at the
paper's durations (fast 0.2 s = 5 Hz, fine 5 s, §3.6) or their measured CPU time, one ACR estimate 4.8 s (Table 3),
one VSE frame 1/15 s (DSO's 15 FPS) —, the stop rule (η, adjustment and time limits), the initialization excursions
(§3.2) and the hand–eye error injected for the §3.7 study.

VSE keyframes: the scene's VSE stand-in spreads its keyframes 3 cm around the camera; the evaluation uses
``vse_keyframe_baseline_m`` = 8 cm, the spread of the map a DSO builds during the initialization excursions and the
first adjustment. With 3 cm the photometric term of the fine alignment is nearly blind (a 1 mm depth change moves a
point by f·b·Δz/z² ≈ 0.016 px between keyframes at 1 m); docs/racr_evaluation.md has the measured effect.

η: the paper's η = 1e-4 is below what this simulator can resolve (the VSE stand-in's independent pose jitter of
0.02° and 0.2 mm per pose, the platform's repeatability floor of 0.005° and 0.05 mm per axis and motion), so with it
no run would ever stop by itself. ``eta`` (default 2e-3, ≈ 0.08° / 1.4 mm of motion left) is the stop threshold
used; it changes when a run stops, never how it is scored.

:func:`protocol_hash` names the records' directory ``OUT/runs/<hash>/``.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

from lightfast.config import Config, param
from lightfast.racr import FastAlignmentConfig, FineAlignmentConfig, SchemeConfig

#: method → (scheme mode, fine alignment, Eq. 16 keyframe refinement, scale estimation); ``acr`` is the baseline
METHODS: dict[str, tuple[str, bool, bool, bool] | None] = {
    "racr": ("parallel", True, True, True),
    "racr-serial": ("serial", True, True, True),
    "racr-p": ("parallel", True, False, True),
    "racr-f": ("parallel", False, True, True),
    "racr-s": ("parallel", True, True, False),
    "acr": None,
}
LABELS = {"racr": "rACR", "racr-serial": "rACR (serial)", "racr-p": "rACR-P", "racr-f": "rACR-F",
          "racr-s": "rACR-S", "acr": "ACR"}
LIGHTINGS = ("similar", "varied")
ABLATION = ("racr", "racr-p", "racr-f", "racr-s")
PROTOCOL_VERSION = 2
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
    init_motions: int = param(3, description="Initialization excursions (out and back), about hand x, y, z.",
                              min=2, max=6)
    init_rotation_deg: float = param(10.0, description="Rotation of an initialization excursion, deg.", min=1.0)
    init_translation_m: float = param(0.02, description="Translation along the rotation axis of an excursion, m.",
                                      min=0.0)
    init_method: str = param("park", description="Hand-eye solver of the initialization (OpenCV's Tsai needs "
                             "rotations above ~17 deg).", choices=("tsai", "park", "horaud", "andreff"))
    acr_max_iterations: int = param(30, description="Most ACR iterations.", min=1)
    handeye_error_deg: float = param(0.0, description="Extra rotation error injected into the estimated hand-eye "
                                     "X (the section 3.7 study), deg.", min=0.0, max=180.0)


def protocol_hash(config: RacrEvalConfig) -> str:
    """The records' directory name: the protocol and the method's own default configuration (a changed default —
    a new option of the alignments — gets new records instead of mixing with runs of the old method)."""
    method = {c.__name__: c().to_dict() for c in (SchemeConfig, FastAlignmentConfig, FineAlignmentConfig)}
    doc = {"version": PROTOCOL_VERSION, "config": config.to_dict(), "method": method}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:12]

