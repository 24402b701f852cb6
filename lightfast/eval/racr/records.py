"""The run record of ``lightfast eval racr`` (paper §5) and the per-run cache.

A :class:`RunRecord` is one (scene, lighting, method, repeat) run: the final and the initial AFD (px, against the
simulator's truth), success (AFD < 3 px), the adjustments, why the run stopped, the simulated loop and
initialization time (s), the wall time (s), one :class:`TracePoint` per motion (simulated time in s, AFD in px, the
camera's true position error in mm and rotation error in deg against the reference pose, rACR's gap g) and the
method's details (scale and hand–eye errors, alignment counts).

Cache: each record is a JSON file ``OUT/runs/<scene>_<lighting>_<method>_r<repeat>.<key>.json`` whose key
(:func:`lightfast.eval.cache.run_key`) hashes what decides the run: the scene's content, the method's
configuration, the protocol and the code version (:func:`~lightfast.eval.racr.protocol.protocol_parts`);
:func:`load_records` reads them back, and an evaluation reuses a record only for its exact key. ``reported`` is the
method's own verdict (``converged``, ``failed``, ``ambiguous``, …), to compare with the truth's.
"""
from __future__ import annotations

import json
import logging
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from lightfast.eval.racr.protocol import AFD_SUCCESS_PX

log = logging.getLogger(__name__)


@dataclass
class TracePoint:
    """State after one motion (or at the start, ``index`` 0): simulated loop time, the truth's AFD and camera
    error, and rACR's own gap g of the motion just issued (NaN for ACR and the start)."""

    index: int
    time_s: float
    afd_px: float
    position_error_mm: float
    rotation_error_deg: float
    g: float = math.nan


@dataclass
class RunRecord:
    """One (scene, lighting, method, repeat) run."""

    scene: str
    kind: str
    lighting: str
    method: str
    repeat: int
    key: str
    afd_px: float
    success: bool
    afd_initial_px: float
    adjustments: int
    converged: bool
    stop_reason: str
    time_loop_s: float
    time_init_s: float
    wall_s: float
    trace: list[TracePoint] = field(default_factory=list)
    details: dict[str, Any] = field(default_factory=dict)
    reported: str = ""

    @property
    def time_total_s(self) -> float:
        return self.time_init_s + self.time_loop_s

    @property
    def time_to_success_s(self) -> float:
        """Simulated loop time at which the truth's AFD first fell below 3 px (inf if never)."""
        return next((p.time_s for p in self.trace if p.afd_px < AFD_SUCCESS_PX), math.inf)

    @property
    def name(self) -> str:
        return f"{self.scene}_{self.lighting}_{self.method}_r{self.repeat}"

    @property
    def self_reported_failure(self) -> bool:
        """The method said it did not relocalize (anything but ``converged``)."""
        return self.reported != "converged"

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["time_total_s"] = self.time_total_s
        d["time_to_success_s"] = self.time_to_success_s
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RunRecord:
        """A record as :meth:`to_dict` gave it, or as read back from JSON, where non-finite floats are ``null``."""
        d = _nan_for_null(cls, d)
        d.pop("time_total_s", None)
        d.pop("time_to_success_s", None)
        d["trace"] = [TracePoint(**_nan_for_null(TracePoint, t)) for t in d.get("trace", [])]
        return cls(**d)


def _nan_for_null(cls: type, d: dict[str, Any]) -> dict[str, Any]:
    """``d`` with the ``None`` of ``cls``'s float fields as NaN (JSON has no NaN: records are written with
    :func:`lightfast.io.json_finite`)."""
    d = dict(d)
    for f in fields(cls):
        if f.type == "float" and f.name in d and d[f.name] is None:
            d[f.name] = math.nan
    return d


def record_path(out_dir: Path, record: RunRecord) -> Path:
    return out_dir / "runs" / f"{record.name}.{record.key}.json"


def load_records(out_dir: Path, keys: set[str] | None = None) -> list[RunRecord]:
    """The run records in ``out_dir/runs/`` (those with one of ``keys`` if given)."""
    runs = []
    for p in sorted((out_dir / "runs").glob("*.json")):
        if keys is not None and p.name.rsplit(".", 2)[-2] not in keys:
            continue
        try:
            runs.append(RunRecord.from_dict(json.loads(p.read_text())))
        except (OSError, ValueError, TypeError) as exc:
            log.warning("ignoring unreadable run record %s: %s", p, exc)
    return runs
