"""Errors of :mod:`lightfast.bag`: every failure to read, write or replay a bag is a :class:`BagError`."""
from lightfast.errors import LightfastError


class BagError(LightfastError):
    """Root of the bag errors."""


class BagNotFoundError(BagError, FileNotFoundError):
    """No bag at the given path."""


class BagFormatError(BagError):
    """The bag is unreadable: truncated, corrupt, or of an unsupported storage format or version."""


class UnknownMessageTypeError(BagError):
    """A message type is not known to this installation (no definition or no Python class for it)."""


class BagExistsError(BagError, FileExistsError):
    """The output bag exists already and overwriting was not requested."""
