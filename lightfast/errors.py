"""The exception tree of lightfast: one root, :class:`LightfastError`, and two markers of whose fault an error is.

Layout: each subpackage has one ``errors.py`` holding every error class of that subpackage, all under one root
(:class:`~lightfast.bag.errors.BagError`, :class:`~lightfast.daylight.errors.DaylightError`,
:class:`~lightfast.data.errors.DatasetError`, :class:`~lightfast.eval.errors.EvalError`,
:class:`~lightfast.racr.errors.RacrError`, :class:`~lightfast.ros.errors.RosError`,
:class:`~lightfast.sim.errors.SimError`, :class:`~lightfast.tracking.errors.TrackingError`,
:class:`~lightfast.vtr.errors.VtrError`), which derives from :class:`LightfastError`. The errors of the top-level
modules (``config``, ``camera``, ``geometry``, ``raycast``) are defined here. ``test/unit/test_error_tree.py``
checks all of this.

Every concrete error is also one of:

* :class:`InputError` -- the data, file, message or value given was bad (malformed, inconsistent, out of range,
  missing, unsupported). Expected in operation: a node logs WARN and skips that input; the CLI prints one line and
  exits 1. Most of them are also a ``ValueError`` (callers and tests rely on ``except ValueError``), the
  missing/existing-file ones a ``FileNotFoundError``/``FileExistsError``.
* :class:`InternalError` -- a step failed that should not have (a computation diverged, a worker thread died, an
  external program or the middleware failed, a timeout). A node logs ERROR; the CLI exits 1 as well (the exit-code
  table of the CLI reserves 3 for errors that are not lightfast errors at all, i.e. bugs with a traceback).
"""


class LightfastError(Exception):
    """Base class of every error lightfast raises on purpose. CLIs map it to a one-line message and exit code 1."""


class InputError(LightfastError):
    """Marker: the input was bad (a node warns and skips it). Combine with a subpackage root, e.g.
    ``class CrfError(DaylightError, InputError, ValueError)``."""


class InternalError(LightfastError):
    """Marker: a step failed that should not have (a node reports ERROR). Combine with a subpackage root, e.g.
    ``class RadiosityError(DaylightError, InternalError)``."""


# --- errors of the top-level modules --------------------------------------------------------------------------

class ConfigError(InputError, ValueError):
    """A configuration value is missing, of the wrong type, out of range, or unknown (:mod:`lightfast.config`;
    importable from there too)."""


class CameraModelError(InputError, ValueError):
    """An invalid or unsupported camera model (bad intrinsics, non-zero distortion we cannot model)
    (:mod:`lightfast.camera`)."""


class GeometryError(InputError, ValueError):
    """An invalid geometric input: wrong shape, non-finite values, not a rotation or transform, bad quaternion
    (:mod:`lightfast.geometry`)."""


class RaycastError(InputError, ValueError):
    """Invalid input to the ray caster: a bad mesh or bad rays (shape, non-finite values, zero directions)
    (:mod:`lightfast.raycast`)."""
