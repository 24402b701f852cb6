"""Errors of :mod:`lightfast.tracking` (camera tracking, paper §III-D): every one is a :class:`TrackingError`; all
of them are :class:`~lightfast.errors.InputError` (and ``ValueError``): frames, poses or trajectories that cannot
be used."""
from __future__ import annotations

from lightfast.errors import InputError, LightfastError

__all__ = ["MetricsError", "TrackingError", "TrackingInputError"]


class TrackingError(LightfastError):
    """Root of the errors of :mod:`lightfast.tracking`."""


class TrackingInputError(TrackingError, InputError, ValueError):
    """Inputs that cannot be aligned or tracked: wrong shapes or sizes, no valid depth, nothing to optimise, a
    frame out of order, unknown or no longer pending, no start pose (:mod:`~lightfast.tracking.rgbd_odometry`,
    :mod:`~lightfast.tracking.pipeline`)."""


class MetricsError(TrackingError, InputError, ValueError):
    """Trajectories that cannot be compared (shape mismatch, too few poses, non-finite values)
    (:mod:`~lightfast.tracking.metrics`)."""
