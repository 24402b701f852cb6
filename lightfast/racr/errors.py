"""Errors of the rACR core (paper: rACR, Section 3): one root, :class:`RacrError`, and one subclass per step.

The core raises these, never prints or exits; ``racr_node`` turns them into ``/racr/status`` and logs.
"""
from __future__ import annotations

from lightfast.errors import LightfastError

__all__ = ["AdjustmentError", "AlignmentError", "DegenerateMotionError", "InitializationError", "RacrError"]


class RacrError(LightfastError, ValueError):
    """Root of every error of :mod:`lightfast.racr`."""


class InitializationError(RacrError):
    """Hand–eye / real-scale initialization (§3.2) got unusable input: wrong shapes, non-finite or non-rigid
    motions, camera and hand motions that do not correspond, a non-positive scale, OpenCV without
    ``calibrateHandEye``."""


class DegenerateMotionError(InitializationError):
    """The platform motions do not determine X or s (§3.2): too few motions, (almost) pure translations, parallel
    rotation axes, or no motion with a translation along its rotation axis (Eq. 8)."""


class AlignmentError(RacrError):
    """Scale-aware point-cloud alignment (§3.4) cannot run or diverged: empty or non-finite clouds, too few
    correspondences (no overlap at the initial guess), degenerate geometry, a scale that left its bounds."""


class AdjustmentError(RacrError):
    """The hand motion of Eq. 3 (§3.5) cannot be computed: non-rigid or non-finite poses, a non-positive scale."""
