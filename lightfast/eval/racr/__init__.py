"""The rACR evaluation of paper §5 (Tables 2/4 and 5, Fig. 8, Fig. 12(b), the §3.7 study) on the simulated scenes
S01–S20: ``lightfast eval racr SCENES_DIR OUT``.

Every (scene, lighting, method, repeat) runs as a discrete-event simulation in **simulated time** (platform
motions, VSE frames and alignment jobs are charged simulated durations in s; the wall clock only decides how long
the evaluation takes) and is scored against the simulator's truth by the AFD (px; success below 3 px). The full
protocol and its design notes are in docs/racr_evaluation.md.

- :mod:`~lightfast.eval.racr.protocol`: the methods (configurations of the node's session), lightings,
  :class:`RacrEvalConfig` and what keys a run;
- :mod:`~lightfast.eval.racr.run`: one run — start pose, the node's session (initialization §3.2, scaling §3.3,
  scheme §3.5–3.6) in simulated time or ACR, the score (:func:`run_one`);
- :mod:`~lightfast.eval.racr.records`: the run record and the per-run cache in ``OUT/runs/``, keyed by content;
- :mod:`~lightfast.eval.racr.evaluate`: every missing run, resumable (:func:`evaluate_racr`);
- :mod:`~lightfast.eval.racr.aggregate` and :mod:`~lightfast.eval.racr.report`: statistics, tables, CSV, JSON,
  plots;
- :mod:`~lightfast.eval.racr.convergence`: the convergence condition of §3.7.
"""
from lightfast.eval.racr.aggregate import common_runs, done_means, paired, summarize
from lightfast.eval.racr.convergence import (
    ConvergenceTrial,
    convergence_condition_markdown,
    convergence_condition_study,
    run_convergence_study,
)
from lightfast.eval.racr.evaluate import cached_scene, evaluate_racr
from lightfast.eval.racr.protocol import (
    ABLATION,
    AFD_SUCCESS_PX,
    LABELS,
    LIGHTINGS,
    METHODS,
    PROTOCOL_VERSION,
    RacrEvalConfig,
    method_config,
)
from lightfast.eval.racr.records import RunRecord, TracePoint, load_records
from lightfast.eval.racr.report import speed_markdown, table_markdown, write_outputs
from lightfast.eval.racr.run import initial_offset, run_one

__all__ = [
    "ABLATION",
    "AFD_SUCCESS_PX",
    "LABELS",
    "LIGHTINGS",
    "METHODS",
    "PROTOCOL_VERSION",
    "ConvergenceTrial",
    "RacrEvalConfig",
    "RunRecord",
    "TracePoint",
    "cached_scene",
    "common_runs",
    "convergence_condition_markdown",
    "convergence_condition_study",
    "done_means",
    "evaluate_racr",
    "initial_offset",
    "load_records",
    "method_config",
    "paired",
    "run_convergence_study",
    "run_one",
    "speed_markdown",
    "summarize",
    "table_markdown",
    "write_outputs",
]
