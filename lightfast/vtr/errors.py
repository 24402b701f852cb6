"""Errors of :mod:`lightfast.vtr` (colour-constant stereo VT&R, paper §III–IV): every deliberate failure is a
:class:`VtrError`, and an :class:`~lightfast.errors.InputError` (bad images, calibration or map) or an
:class:`~lightfast.errors.InternalError` (a pipeline used out of order)."""
from __future__ import annotations

from lightfast.errors import InputError, InternalError, LightfastError

__all__ = [
    "MapCorruptError",
    "MapError",
    "MapExistsError",
    "MapNotFoundError",
    "MapVersionError",
    "VtrError",
    "VtrInputError",
    "VtrStateError",
]


class VtrError(LightfastError):
    """Root of the VT&R errors: bad images or calibration, mismatched stereo pairs, unusable inputs or maps."""


class VtrInputError(VtrError, InputError, ValueError):
    """An input array or matrix has the wrong shape, dtype, size or values (e.g. left/right sizes differ), or there
    is no input at all (a teach finished without a frame: nothing to save)."""


class VtrStateError(VtrError, InternalError):
    """A teach or map writer was used after it finished, was aborted or closed."""


# --- the teach map (lightfast.vtr.map_store) ------------------------------------------------------------------

class MapError(VtrError, InputError):
    """A teach map cannot be used (root of the map errors)."""


class MapNotFoundError(MapError, FileNotFoundError):
    """No complete map at the path: the directory or its manifest is missing (e.g. a teach that never finished)."""


class MapVersionError(MapError):
    """The directory holds another format or a map version this code does not read."""


class MapCorruptError(MapError):
    """The map is inconsistent: unreadable manifest, missing/truncated/altered keyframe file, wrong shapes..."""


class MapExistsError(MapError, FileExistsError):
    """A map exists at the path and overwriting was not allowed."""
