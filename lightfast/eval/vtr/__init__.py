"""The VT&R field-trial evaluation of paper §VI (Table I, Fig. 7) on the simulated day schedule: ``lightfast eval
vtr SIM_DIR OUT``.

Input: a directory written by ``lightfast sim vtr`` (one teach run and any number of repeats; see
:mod:`lightfast.sim.vtr.recordings`). The map is taught once from the teach run and every repeat run is repeated in
every mode (``fused``, ``grey``, ``mcmanus``) through the pipelines ``vtr_localizer_node`` runs, with its
parameters; the method sees the bags' images and camera matrices only. The ground truth (``truth.csv``) is read only
to score: autonomy by distance (the Table I metric), distance driven on VO (m, the Fig. 7 CDF) and the localization
error (m, deg). Outputs in ``OUT``: a Table-I-style markdown table, per-run and per-frame CSVs, a JSON summary, CDF
and inlier plots, rewritten after every finished (run, mode); finished results are kept and reused.

- :mod:`~lightfast.eval.vtr.inputs`: the simulated runs, their stereo pairs and their ground truth;
- :mod:`~lightfast.eval.vtr.scoring`: per-frame records and the metrics (autonomy, distance on VO, errors, CDF);
- :mod:`~lightfast.eval.vtr.runs`: teach, repeat, keep and resume (:func:`evaluate_vtr`);
- :mod:`~lightfast.eval.vtr.report`: tables, CSVs, JSON and plots.
"""
from lightfast.eval.vtr.inputs import SimRun, Truth, load_truth, sim_runs, stereo_frames
from lightfast.eval.vtr.report import FIG7_RUNS, details_markdown, table_markdown, verdict, write_outputs
from lightfast.eval.vtr.runs import EVAL_FORMAT, evaluate_vtr, run_repeat, teach_map
from lightfast.eval.vtr.scoring import GROSS_ERROR_M, REPORTED_SOURCES, FrameRecord, RepeatRun, cdf, overall

__all__ = [
    "EVAL_FORMAT",
    "FIG7_RUNS",
    "GROSS_ERROR_M",
    "REPORTED_SOURCES",
    "FrameRecord",
    "RepeatRun",
    "SimRun",
    "Truth",
    "cdf",
    "details_markdown",
    "evaluate_vtr",
    "load_truth",
    "overall",
    "run_repeat",
    "sim_runs",
    "stereo_frames",
    "table_markdown",
    "teach_map",
    "verdict",
    "write_outputs",
]
