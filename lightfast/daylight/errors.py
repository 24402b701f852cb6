"""Errors of :mod:`lightfast.daylight` (Krawez et al., RA-L 2021): every one is a :class:`DaylightError`, and an
:class:`~lightfast.errors.InputError` (a mesh, site, file or array that cannot be used; also a ``ValueError``
where it was one before) or an :class:`~lightfast.errors.InternalError` (the radiosity did not converge)."""
from __future__ import annotations

from lightfast.errors import ConfigError, InputError, InternalError, LightfastError

__all__ = [
    "BrightnessError",
    "CrfError",
    "DaylightError",
    "LightingMapError",
    "LightingMapVersionError",
    "LightsError",
    "MeshError",
    "OpeningsError",
    "RadiosityError",
    "RadiosityFileError",
    "SiteError",
    "SunPositionError",
]


class DaylightError(LightfastError):
    """Root of the errors of :mod:`lightfast.daylight`."""


class BrightnessError(DaylightError, InputError, ValueError):
    """Invalid input to brightness estimation or relighting (shapes, poses, components, methods)
    (:mod:`~lightfast.daylight.brightness`, :mod:`~lightfast.daylight.relight`)."""


class CrfError(DaylightError, InputError, ValueError):
    """A camera response that cannot be built, loaded or calibrated (bad table, bad file, bad bracket)
    (:mod:`~lightfast.daylight.crf`)."""


class LightingMapError(DaylightError, InputError):
    """A lighting map that cannot be made or used: bad input, wrong version, mesh mismatch, damaged files
    (:mod:`~lightfast.daylight.lighting_map`)."""


class LightingMapVersionError(LightingMapError):
    """A lighting map written by another format version of lightfast: prepare it again
    (:mod:`~lightfast.daylight.lighting_map`)."""


class LightsError(DaylightError, InputError, ValueError):
    """Invalid light-set input: wrong shapes, non-unit directions, negative weights, bad sample counts
    (:mod:`~lightfast.daylight.lights`)."""


class MeshError(DaylightError, InputError, ValueError):
    """A mesh that cannot be used: unreadable file, missing reflectance, degenerate or non-manifold geometry
    (:mod:`~lightfast.daylight.mesh`, :mod:`~lightfast.daylight.patches`)."""


class OpeningsError(DaylightError, InputError, ValueError):
    """An openings file or opening that cannot be used (:mod:`~lightfast.daylight.openings`)."""


class RadiosityFileError(DaylightError, InputError, ValueError):
    """A radiosity export or points file that cannot be read or used (:mod:`~lightfast.daylight.radiosity_export`)."""


class RadiosityError(DaylightError, InternalError):
    """The transport could not be computed (e.g. the iteration diverged) (:mod:`~lightfast.daylight.radiosity`)."""


class SiteError(DaylightError, ConfigError):
    """An invalid site: a value out of range, an unknown time zone, or an unreadable or malformed site file
    (:mod:`~lightfast.daylight.sun`).

    Also a :class:`~lightfast.errors.ConfigError` (a site is a :class:`~lightfast.config.Config`), hence an
    :class:`~lightfast.errors.InputError` and a ``ValueError``.
    """


class SunPositionError(DaylightError, InputError, ValueError):
    """Times :func:`~lightfast.daylight.sun.sun_position` cannot use: naive datetimes, NaT, a non-finite
    ``delta_t_s``."""
