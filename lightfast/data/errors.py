"""Errors of :mod:`lightfast.data` (public-dataset converters): every one is a :class:`DataError`; all of them are
:class:`~lightfast.errors.InputError` (a dataset folder or file that cannot be used)."""
from __future__ import annotations

from lightfast.errors import InputError, LightfastError

__all__ = ["DataError", "DatasetError"]


class DataError(LightfastError):
    """Root of the errors of :mod:`lightfast.data`."""


class DatasetError(DataError, InputError):
    """A dataset folder is missing files or holds malformed ones (:mod:`~lightfast.data.sevenscenes`)."""
