"""Errors of :mod:`lightfast.sim` (simulators and reference renderers): every one is a :class:`SimError`, and an
:class:`~lightfast.errors.InputError` (a scene, room or command that cannot be used; also a ``ValueError``) or an
:class:`~lightfast.errors.InternalError` (Radiance missing or failing)."""
from __future__ import annotations

from lightfast.errors import InputError, InternalError, LightfastError

__all__ = ["PlatformError", "RacrSimError", "RadianceError", "SimError", "ValidationRoomError"]


class SimError(LightfastError):
    """Root of the errors of :mod:`lightfast.sim`."""


class PlatformError(SimError, InputError, ValueError):
    """The simulated platform refuses a command: not a finite rigid transform, or beyond its motion limits
    (:mod:`~lightfast.sim.racr_platform`)."""


class RacrSimError(SimError, InputError, ValueError):
    """A scene or reference file that cannot be used (missing, half-written, wrong format or version), or bad
    simulator input (:mod:`~lightfast.sim.racr`)."""


class RadianceError(SimError, InternalError, RuntimeError):
    """Radiance is missing, failed, or returned something unexpected (:mod:`~lightfast.sim.radiance_oracle`)."""


class ValidationRoomError(SimError, InputError, ValueError):
    """Room parameters that do not describe a valid room (window larger than its wall, negative sizes...)
    (:mod:`~lightfast.sim.validation_rooms`)."""
