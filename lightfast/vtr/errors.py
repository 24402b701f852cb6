"""Errors of :mod:`lightfast.vtr` (colour-constant stereo VT&R, paper §III–IV): every deliberate failure is a
:class:`VtrError`."""
from __future__ import annotations

from lightfast.errors import LightfastError


class VtrError(LightfastError):
    """Root of the VT&R errors: bad images or calibration, mismatched stereo pairs, unusable inputs."""


class VtrInputError(VtrError, ValueError):
    """An input array or matrix has the wrong shape, dtype, size or values (e.g. left/right sizes differ)."""
