"""Errors of :mod:`lightfast.bag`: every failure to read, write or replay a bag is a :class:`BagError`."""
from lightfast.errors import LightfastError


class BagError(LightfastError):
    """Root of the bag errors."""


class BagNotFoundError(BagError, FileNotFoundError):
    """No bag at the given path."""


class BagFormatError(BagError):
    """The bag is unreadable: truncated, corrupt, or of an unsupported storage format or version."""


class CorruptChunkError(BagFormatError):
    """A chunk of an MCAP file failed its checks (CRC, decompression, record structure); ``chunk`` says which
    (a :class:`lightfast.bag.mcap_chunks.CorruptChunk`)."""

    def __init__(self, message: str, chunk: object) -> None:
        super().__init__(message)
        self.chunk = chunk


class UnknownMessageTypeError(BagError):
    """A message type is not known to this installation (no definition or no Python class for it)."""


class BagExistsError(BagError, FileExistsError):
    """The output bag exists already and overwriting was not requested."""
