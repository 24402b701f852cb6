"""Errors of the rACR core (paper: rACR, Section 3): one root, :class:`RacrError`, and one subclass per step.

The core raises these, never prints or exits; ``racr_node`` turns them into ``/racr/status`` and logs. The step
errors are :class:`~lightfast.errors.InputError` (and ``ValueError``): data that cannot be used (bad shapes,
degenerate motions, clouds that do not overlap); :class:`SchemeError` is an
:class:`~lightfast.errors.InternalError`.
"""
from __future__ import annotations

from lightfast.errors import InputError, InternalError, LightfastError

__all__ = [
    "AcrError",
    "AdjustmentError",
    "AlignmentError",
    "DegenerateMotionError",
    "InitializationError",
    "RacrError",
    "ReferenceFileError",
    "SchemeError",
]


class RacrError(LightfastError):
    """Root of every error of :mod:`lightfast.racr`."""


class InitializationError(RacrError, InputError, ValueError):
    """Hand–eye / real-scale initialization (§3.2) got unusable input: wrong shapes, non-finite or non-rigid
    motions, camera and hand motions that do not correspond, a non-positive scale, OpenCV without
    ``calibrateHandEye``."""


class DegenerateMotionError(InitializationError):
    """The platform motions do not determine X or s (§3.2): too few motions, (almost) pure translations, parallel
    rotation axes, or no motion with a translation along its rotation axis (Eq. 8)."""


class AlignmentError(RacrError, InputError, ValueError):
    """Scale-aware point-cloud alignment (§3.4) cannot run or diverged: empty or non-finite clouds, too few
    correspondences (no overlap at the initial guess), degenerate geometry, a scale that left its bounds."""


class AdjustmentError(RacrError, InputError, ValueError):
    """The hand motion of Eq. 3 (§3.5) cannot be computed: non-rigid or non-finite poses, a non-positive scale."""


class AcrError(RacrError, InputError, ValueError):
    """The ACR baseline (:mod:`~lightfast.racr.acr_baseline`) cannot estimate a relative pose: bad images, too few
    SIFT matches or RANSAC inliers."""


class SchemeError(RacrError, InternalError):
    """The alignment thread of :mod:`~lightfast.racr.scheme` stopped on an unexpected error (the original is the
    ``__cause__``), or the scheme was used out of order (started twice, stepped while its thread runs)."""


class ReferenceFileError(RacrError, InputError, ValueError):
    """A reference observation directory is missing, half-written, damaged or made for another scene."""
