"""Errors of :mod:`lightfast.bag`: every failure to read, write or replay a bag is a :class:`BagError`; all of them
are :class:`~lightfast.errors.InputError` (a missing, damaged or unsupported bag, an output that exists)."""
from lightfast.errors import InputError, LightfastError


class BagError(LightfastError):
    """Root of the bag errors."""


class BagNotFoundError(BagError, InputError, FileNotFoundError):
    """No bag at the given path."""


class BagFormatError(BagError, InputError):
    """The bag is unreadable: truncated, corrupt, or of an unsupported storage format or version."""


class CorruptChunkError(BagFormatError):
    """A chunk of an MCAP file failed its checks (CRC, decompression, record structure); ``chunk`` says which
    (a :class:`lightfast.bag.mcap_chunks.CorruptChunk`)."""

    def __init__(self, message: str, chunk: object) -> None:
        super().__init__(message)
        self.chunk = chunk


class ChunkCheckError(BagFormatError):
    """Internal to :mod:`lightfast.bag`: an MCAP chunk, its index or the file's summary failed a check (the reason
    is the message). :mod:`~lightfast.bag.mcap_chunks` raises it and the reader turns it into a skipped chunk, a
    :class:`CorruptChunkError` or a fallback to rosbags; it does not leave the package."""


class UnknownMessageTypeError(BagError, InputError):
    """A message type is not known to this installation (no definition or no Python class for it)."""


class BagExistsError(BagError, InputError, FileExistsError):
    """The output bag exists already and overwriting was not requested."""
