"""Errors of :mod:`lightfast.eval` (the evaluations of the papers' tables): every one is an :class:`EvalError`
and an :class:`~lightfast.errors.InputError` -- an evaluation input that is missing or inconsistent."""
from __future__ import annotations

from lightfast.errors import InputError, LightfastError

__all__ = ["DaylightEvalError", "EvalError", "RacrEvalError", "RecordingError", "VtrEvalError"]


class EvalError(LightfastError):
    """Root of the errors of :mod:`lightfast.eval`."""


class DaylightEvalError(EvalError, InputError):
    """A daylight-evaluation input is missing or inconsistent (recording directory, lighting map, method name)
    (:mod:`~lightfast.eval.daylight`)."""


class RacrEvalError(EvalError, InputError):
    """An rACR-evaluation input is missing or inconsistent (scene directory, method or lighting name, option)
    (:mod:`~lightfast.eval.racr`)."""


class RecordingError(EvalError, InputError):
    """A recording cannot be scored (missing topics, no poses) (:mod:`~lightfast.eval.recording`)."""


class VtrEvalError(EvalError, InputError):
    """A VT&R-evaluation input is missing or inconsistent (simulation directory, run, mode)
    (:mod:`~lightfast.eval.vtr`)."""
