"""Read an indexed MCAP file chunk by chunk, checking each chunk, so that a damaged chunk costs only its own messages.

rosbags' MCAP reader (0.11) reads chunks through the summary's chunk index but checks little: garbage in a chunk
makes it raise in the middle of the iteration (a CRC mismatch, an ``OverflowError`` from a garbage record length),
or skip the rest of the chunk silently (a garbage record length that points past the chunk's end), or hand out the
garbage as message bytes. Here every chunk is located through the summary's chunk index (so one damaged chunk does
not desynchronize the rest), and checked before any of its messages is used:

- its record header agrees with the chunk index (opcode, length, times, sizes, compression);
- its data decompresses (zstd, lz4) to the indexed size, and its CRC-32 matches (if the writer stored one;
  :class:`~lightfast.bag.mcap_storage.McapStorage` always does, rosbags' writer never does);
- its records parse exactly to its end, only Schema/Channel/Message records, each message on a known channel
  with a log time inside the chunk's range, and (for a chunk without CRC) as many messages per channel as the
  message index says.

A chunk failing any check is *corrupt*: none of its messages is used, and :class:`CorruptChunk` says how many it
held (from the chunk index, which counts the messages per channel through the message index offsets). Without a
CRC, damage that stays inside a message's payload bytes is not detectable.
"""
from __future__ import annotations

import heapq
import struct
import zlib
from collections.abc import Callable, Collection, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import lz4.frame
import zstandard
from mcap.exceptions import McapError
from mcap.reader import SeekingReader

from lightfast.bag.errors import ChunkCheckError

_CHUNK_HEAD = struct.Struct("<BQQQQI")  # opcode, record length, start, end, uncompressed size, crc
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, record length, channel id, records length
_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_MESSAGE_INDEX = 0x03, 0x04, 0x05, 0x06, 0x07


@dataclass(frozen=True)
class CorruptChunk:
    """A chunk of an MCAP file that failed its checks; none of its messages was used.

    ``message_count`` counts the messages of the chunk that the read asked for (topics, time range), from the
    summary's indexes; ``None`` when they cannot tell (a file without message index, or a chunk straddling the
    requested time range whose message index is damaged too)."""

    file: Path
    offset: int
    start_ns: int
    end_ns: int
    message_count: int | None
    reason: str

    def describe(self) -> str:
        count = "unknown" if self.message_count is None else f"{self.message_count}"
        return (f"{self.file.name} chunk at byte {self.offset} (log time {self.start_ns * 1e-9:.3f}-"
                f"{self.end_ns * 1e-9:.3f} s, messages {count}): {self.reason}")


@dataclass
class SkippedChunks:
    """What a read skipped: pass one as ``skipped=`` to :meth:`~lightfast.bag.reader.BagReader.messages` to skip
    corrupt chunks instead of raising. A chunk met again (a looping replay) is counted once."""

    chunks: dict[tuple[Path, int], CorruptChunk] = field(default_factory=dict)

    def add(self, chunk: CorruptChunk) -> bool:
        """Record ``chunk``; False if it was recorded already."""
        key = (chunk.file, chunk.offset)
        if key in self.chunks:
            return False
        self.chunks[key] = chunk
        return True

    @property
    def chunk_count(self) -> int:
        return len(self.chunks)

    @property
    def message_count(self) -> int:
        """Messages known to be lost (see :attr:`exact`)."""
        return sum(c.message_count or 0 for c in self.chunks.values())

    @property
    def exact(self) -> bool:
        """Whether :attr:`message_count` is the exact number (False: a lower bound)."""
        return all(c.message_count is not None for c in self.chunks.values())

    def __bool__(self) -> bool:
        return bool(self.chunks)

    def summary(self) -> str:
        """``skipped 5 messages in 1 corrupt chunk`` (``at least 5`` when a chunk's count is unknown)."""
        return describe_skipped(self.chunks.values())

    def first(self) -> CorruptChunk | None:
        return next(iter(self.chunks.values()), None)


def describe_skipped(chunks: Collection[CorruptChunk]) -> str:
    """``skipped 5 messages in 1 corrupt chunk`` (``at least 5`` when a chunk's count is unknown)."""
    n = sum(c.message_count or 0 for c in chunks)
    count = f"{n}" if all(c.message_count is not None for c in chunks) else f"at least {n}"
    m = len(chunks)
    return f"skipped {count} message{'s' if n != 1 else ''} in {m} corrupt chunk{'s' if m != 1 else ''}"


@dataclass(frozen=True)
class ChunkRef:
    """A chunk as the summary's chunk index describes it; ``counts`` (messages per channel) comes from the
    spacing of its message index records, ``None`` if the file has no message index."""

    offset: int
    length: int
    start_ns: int
    end_ns: int
    compression: str
    compressed_size: int
    uncompressed_size: int
    index_offsets: dict[int, int]
    counts: dict[int, int] | None


@dataclass(frozen=True)
class McapIndex:
    """What the summary section of one MCAP file says: channels (id -> topic, message type) and chunks."""

    path: Path
    channels: dict[int, tuple[str, str]]
    chunks: tuple[ChunkRef, ...]

    @property
    def compressions(self) -> set[str]:
        return {c.compression for c in self.chunks}


def read_index(path: Path) -> McapIndex | None:
    """The summary of the MCAP file at ``path``; ``None`` if it has none or has messages but no chunk index (read
    such a file by scanning). Raises :class:`ChunkCheckError` if the footer or summary cannot be read."""
    try:
        with path.open("rb") as fh:
            summary = SeekingReader(fh).get_summary()
    except (McapError, OSError, ValueError, struct.error, UnicodeDecodeError, OverflowError, MemoryError) as exc:
        reason = str(exc) or type(exc).__name__
        raise ChunkCheckError(f"cannot read the MCAP summary of {path.name}: {reason}") from None
    if summary is None:
        return None
    schemas = {s.id: s.name for s in summary.schemas.values()}
    channels = {c.id: (c.topic, schemas.get(c.schema_id, "")) for c in summary.channels.values()}
    if not summary.chunk_indexes:  # no messages at all, or messages outside chunks (read those by scanning)
        empty = summary.statistics is not None and summary.statistics.message_count == 0
        return McapIndex(path, channels, ()) if empty else None
    chunks = []
    for ci in summary.chunk_indexes:
        counts: dict[int, int] | None = None
        if ci.message_index_offsets:
            ordered = sorted((off, cid) for cid, off in ci.message_index_offsets.items())
            ends = [off for off, _ in ordered[1:]] + [ci.chunk_start_offset + ci.chunk_length + ci.message_index_length]
            counts = {cid: max(0, (end - off - _INDEX_HEAD.size) // 16) for (off, cid), end in zip(ordered, ends,
                                                                                                   strict=True)}
        chunks.append(ChunkRef(ci.chunk_start_offset, ci.chunk_length, ci.message_start_time, ci.message_end_time,
                               ci.compression, ci.compressed_size, ci.uncompressed_size,
                               dict(ci.message_index_offsets), counts))
    chunks.sort(key=lambda c: (c.start_ns, c.offset))
    return McapIndex(path, channels, tuple(chunks))


def _read_exact(fh: BinaryIO, offset: int, size: int) -> bytes:
    try:
        fh.seek(offset)
        data = fh.read(size)
    except (OverflowError, MemoryError, ValueError) as exc:  # offsets or sizes from a damaged index
        raise ChunkCheckError(f"cannot read {size} bytes at byte {offset}: {type(exc).__name__}") from None
    if len(data) != size:
        raise ChunkCheckError(f"file ends inside the chunk (truncated at byte {offset + len(data)})")
    return data


def _decompress(data: bytes, compression: str, size: int) -> bytes:
    try:
        if compression == "":
            return data
        if compression == "zstd":
            return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
        if compression == "lz4":
            return bytes(lz4.frame.decompress(data))
    except (zstandard.ZstdError, RuntimeError, ValueError, MemoryError) as exc:
        raise ChunkCheckError(f"{compression} data does not decompress ({str(exc) or type(exc).__name__})") from None
    raise ChunkCheckError(f"unsupported chunk compression {compression!r}")


def read_chunk(fh: BinaryIO, ref: ChunkRef, channels: Collection[int], known: Collection[int]
               ) -> list[tuple[int, int, bytes]]:
    """The messages of one chunk as ``(log time, channel id, data)`` in log-time order (ties in file order),
    those on ``channels`` only; ``known`` are the file's channel ids. Raises :class:`ChunkCheckError` if any check
    fails (see the module doc)."""
    head = _read_exact(fh, ref.offset, _CHUNK_HEAD.size + 4)
    opcode, length, start, end, usize, crc = _CHUNK_HEAD.unpack_from(head)
    (clen,) = _U32.unpack_from(head, _CHUNK_HEAD.size)
    if opcode != _OP_CHUNK or length != ref.length - 9:
        raise ChunkCheckError("the chunk record header is damaged (opcode or length differ from the chunk index)")
    if (start, end, usize) != (ref.start_ns, ref.end_ns, ref.uncompressed_size) or clen != len(ref.compression):
        raise ChunkCheckError("the chunk header disagrees with the chunk index (times, size or compression)")
    pos = ref.offset + _CHUNK_HEAD.size + 4
    tail = _read_exact(fh, pos, clen + 8)
    (csize,) = _U64.unpack_from(tail, clen)
    if tail[:clen] != ref.compression.encode() or csize != ref.compressed_size or \
            pos + clen + 8 + csize > ref.offset + ref.length:  # (a writer may pad a record: <, not !=)
        raise ChunkCheckError("the chunk header disagrees with the chunk index (compression or compressed size)")
    raw = _decompress(_read_exact(fh, pos + clen + 8, csize), ref.compression, usize)
    if len(raw) != usize:
        raise ChunkCheckError(f"decompressed to {len(raw)} bytes instead of {usize}")
    if crc and zlib.crc32(raw) != crc:
        raise ChunkCheckError("CRC mismatch")
    # A matching CRC vouches for the bytes; without one, the message counts are a further check against damage
    return _parse_records(raw, ref, channels, known, check_counts=not crc)


def _parse_records(raw: bytes, ref: ChunkRef, wanted: Collection[int], known: Collection[int], *,
                   check_counts: bool) -> list[tuple[int, int, bytes]]:
    view = memoryview(raw)
    size = len(raw)
    pos = 0
    counts: dict[int, int] = {}
    out: list[tuple[int, int, bytes]] = []
    while pos < size:
        if pos + 9 > size:
            raise ChunkCheckError(f"a record header is cut off at byte {pos} of the chunk")
        op, length = _RECORD_HEAD.unpack_from(raw, pos)
        end = pos + 9 + length
        if end > size:
            raise ChunkCheckError(f"a record at byte {pos} of the chunk runs past its end")
        if op == _OP_MESSAGE:
            if length < _MESSAGE_HEAD.size:
                raise ChunkCheckError(f"a message record at byte {pos} of the chunk is too short")
            cid, _seq, log_time, _pub = _MESSAGE_HEAD.unpack_from(raw, pos + 9)
            if cid not in known or (ref.counts is not None and cid not in ref.counts):
                raise ChunkCheckError(f"a message at byte {pos} of the chunk is on channel {cid}, not in the index")
            if not ref.start_ns <= log_time <= ref.end_ns:
                raise ChunkCheckError(f"a message at byte {pos} of the chunk has a log time outside the chunk's range")
            counts[cid] = counts.get(cid, 0) + 1
            if cid in wanted:
                out.append((log_time, cid, bytes(view[pos + 9 + _MESSAGE_HEAD.size : end])))
        elif op not in (_OP_SCHEMA, _OP_CHANNEL):
            raise ChunkCheckError(f"unexpected record (opcode 0x{op:02x}) at byte {pos} of the chunk")
        pos = end
    if check_counts and ref.counts is not None and counts != {c: n for c, n in ref.counts.items() if n}:
        raise ChunkCheckError("its messages per channel differ from the message index")
    out.sort(key=lambda m: m[0])  # stable: ties stay in file order
    return out


def count_skipped(fh: BinaryIO, ref: ChunkRef, channels: Collection[int], start_ns: int, stop_ns: int) -> int | None:
    """How many messages of a corrupt chunk a read of ``channels`` in ``[start_ns, stop_ns)`` lost; ``None`` if
    that cannot be told. For a chunk inside the range the chunk index's counts tell; for one straddling the range's
    edge the message index records (after the chunk) give the log times, if they are intact."""
    if ref.counts is None:
        return None
    total = sum(ref.counts.get(c, 0) for c in channels)
    if start_ns <= ref.start_ns and ref.end_ns < stop_ns:
        return total
    n = 0
    try:
        for cid in channels:
            if not ref.counts.get(cid):
                continue
            head = _read_exact(fh, ref.index_offsets[cid], _INDEX_HEAD.size)
            op, length, index_cid, array_len = _INDEX_HEAD.unpack(head)
            if op != _OP_MESSAGE_INDEX or index_cid != cid or array_len != 16 * ref.counts[cid] or \
                    length != 6 + array_len:
                return None
            entries = _read_exact(fh, ref.index_offsets[cid] + _INDEX_HEAD.size, array_len)
            n += sum(1 for (t, _off) in struct.iter_unpack("<QQ", entries) if start_ns <= t < stop_ns)
    except (ChunkCheckError, KeyError):
        return None
    return n


def iter_messages(
    index: McapIndex,
    channels: Collection[int],
    start_ns: int,
    stop_ns: int,
    on_corrupt: Callable[[CorruptChunk], None],
) -> Iterator[tuple[int, int, bytes]]:
    """Messages ``(log time, channel id, data)`` of ``channels`` with ``start_ns <= log time < stop_ns``, in
    log-time order across chunks (ties: chunk order, then file order). A corrupt chunk is reported to
    ``on_corrupt`` (which may raise to stop the read) and contributes no message."""
    wanted = set(channels)
    known = set(index.channels)
    with index.path.open("rb") as fh:
        def source(ref: ChunkRef) -> Iterator[tuple[int, int, int, int, bytes]]:
            # A first entry at the chunk's start time, so that heapq.merge reads a chunk only when its turn comes.
            yield ref.start_ns, ref.offset, -1, 0, b""
            try:
                messages = read_chunk(fh, ref, wanted, known)
            except ChunkCheckError as exc:
                count = count_skipped(fh, ref, wanted, start_ns, stop_ns)
                on_corrupt(CorruptChunk(index.path, ref.offset, ref.start_ns, ref.end_ns, count, str(exc)))
                return
            for i, (t, cid, data) in enumerate(messages):
                if start_ns <= t < stop_ns:
                    yield t, ref.offset, i, cid, data

        sources = [
            source(ref) for ref in index.chunks
            if ref.end_ns >= start_ns and ref.start_ns < stop_ns
            and (ref.counts is None or any(ref.counts.get(c) for c in wanted))
        ]
        for t, _offset, i, cid, data in heapq.merge(*sources):
            if i >= 0:
                yield t, cid, data
