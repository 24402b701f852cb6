"""Read rosbag2 bags (MCAP or sqlite3 storage; a bag directory or a bare ``.mcap``/``.db3`` file) with rosbags.

Messages come as serialized CDR bytes in log-time order across topics, the order ``ros2 bag play`` uses. Every
failure (missing path, truncated or corrupt file, unsupported version) is raised as a
:class:`~lightfast.bag.errors.BagError` subclass with a one-line message.

Indexed MCAP files (what rosbag2, rosbags and :class:`~lightfast.bag.writer.BagWriter` write) are read chunk by
chunk with :mod:`lightfast.bag.mcap_chunks`, which checks every chunk (CRC, decompression, record structure against
the indexes) before using its messages. A corrupt chunk raises :class:`~lightfast.bag.errors.CorruptChunkError`,
or, with ``messages(skipped=SkippedChunks())``, is skipped and counted. Other storage (sqlite3, rosbag2's file or
message compression, MCAP files without a chunk index) is read by rosbags.
"""
from __future__ import annotations

import logging
import os
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import yaml
from rosbags.interfaces import Connection, Qos
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.errors import ReaderError

from lightfast.bag.errors import (
    BagError,
    BagFormatError,
    BagNotFoundError,
    ChunkCheckError,
    CorruptChunkError,
    UnknownMessageTypeError,
)
from lightfast.bag.mcap_chunks import CorruptChunk, McapIndex, SkippedChunks, iter_messages, read_index

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag: name, type, message count, the QoS profiles its publishers offered, its definition."""

    name: str
    msgtype: str
    message_count: int
    serialization_format: str
    offered_qos: tuple[Qos, ...]
    msgdef: str


@dataclass(frozen=True)
class BagInfo:
    """Summary of a bag, like ``ros2 bag info``. Times are nanoseconds since the epoch of the bag's clock."""

    path: Path
    storage: str
    version: int | None
    start_ns: int
    end_ns: int
    message_count: int
    size_bytes: int
    topics: tuple[TopicInfo, ...]
    compression: str = "none"  # "none", "zstd", "lz4" (several: "lz4, zstd"), "unknown" (MCAP without chunk index)
    compression_mode: str = ""  # "chunks" (MCAP chunk compression), "file" or "message" (rosbag2's modes)

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns) if self.message_count else 0

    def topic(self, name: str) -> TopicInfo:
        for t in self.topics:
            if t.name == name:
                return t
        raise BagError(f"{self.path}: no topic {name!r} (topics: {', '.join(t.name for t in self.topics)})")

    def format(self) -> str:
        """A human-readable multi-line summary."""
        duration_s = self.duration_ns * 1e-9
        lines = [
            f"Files:             {self.path}",
            f"Storage:           {self.storage}" + (f" (rosbag2 version {self.version})" if self.version else ""),
            f"Bag size:          {_human_size(self.size_bytes)}",
            f"Compression:       {self.compression}" + (f" ({self.compression_mode})" if self.compression_mode else ""),
            f"Duration:          {duration_s:.3f} s",
            f"Start:             {self.start_ns * 1e-9:.9f}",
            f"End:               {self.end_ns * 1e-9:.9f}",
            f"Messages:          {self.message_count}",
            "Topic information:",
        ]
        width = max((len(t.name) for t in self.topics), default=0)
        for t in self.topics:
            rate = "       - Hz"
            if duration_s > 0 and t.message_count > 1:
                rate = f"{(t.message_count - 1) / duration_s:8.2f} Hz"
            qos = ", ".join(
                sorted({f"{q.reliability.name.lower()}/{q.durability.name.lower()}" for q in t.offered_qos})
            )
            lines.append(
                f"  {t.name:<{width}}  {t.msgtype:<32} {t.message_count:7d} msgs {rate}"
                f"  {t.serialization_format}" + (f"  qos {qos}" if qos else "")
            )
        return "\n".join(lines)


@dataclass(frozen=True, slots=True)
class BagMessage:
    """One serialized message: its topic, type, log time (ns) and CDR bytes."""

    topic: str
    msgtype: str
    log_time_ns: int
    data: bytes


def _human_size(n: int) -> str:
    size = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            return f"{size:.1f} {unit}" if unit != "B" else f"{n} B"
        size /= 1024
    raise AssertionError("unreachable")


def _resolve_path(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if not p.exists():
        raise BagNotFoundError(f"no bag at {p}")
    # A storage file inside a bag directory: read the directory, so metadata (QoS, counts) is used.
    if p.is_file() and (p.parent / "metadata.yaml").is_file():
        return p.parent
    if p.is_dir() and not (p / "metadata.yaml").is_file():
        raise BagFormatError(f"{p} is a directory without metadata.yaml, not a rosbag2 bag")
    if p.is_file() and p.suffix not in (".mcap", ".db3"):
        raise BagFormatError(f"{p}: unsupported bag file (expected a rosbag2 directory, .mcap or .db3)")
    return p


class BagReader:
    """An open bag. Use :func:`open_bag` (a context manager)."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = _resolve_path(path)
        try:
            self._reader = Reader(self.path)
            self._reader.open()
        except BagError:
            raise
        except (ReaderError, OSError, KeyError, ValueError, IndexError, EOFError, OverflowError, struct.error) as exc:
            raise BagFormatError(f"{self.path}: cannot read bag: {_truncation(self.path) or _reason(exc)}") from None
        self._meta = _metadata(self.path)
        self._mcap = self._read_mcap_indexes()
        self._info = self._make_info()

    def _storage_files(self) -> list[Path]:
        if self.path.is_file():
            return [self.path]
        names = self._meta.get("relative_file_paths") or []
        return [self.path / Path(str(n)).name for n in names]

    def _read_mcap_indexes(self) -> list[McapIndex] | None:
        """The chunk indexes of the bag's MCAP files, or None if rosbags has to read the bag (sqlite3, rosbag2's
        file or message compression, an MCAP file without chunk index)."""
        if str(self._meta.get("compression_mode") or "").lower() not in ("", "none"):
            return None
        files = self._storage_files()
        if not files or any(f.suffix != ".mcap" for f in files):
            return None
        indexes = []
        for f in files:
            try:
                index = read_index(f)
            except ChunkCheckError as exc:
                log.warning("%s; reading it with rosbags", exc)
                return None
            if index is None:
                return None
            indexes.append(index)
        return indexes

    def _make_info(self) -> BagInfo:
        r = self._reader
        by_topic: dict[str, list[Connection]] = {}
        for c in r.connections:
            by_topic.setdefault(c.topic, []).append(c)
        topics = []
        for name, conns in by_topic.items():
            types = {c.msgtype for c in conns}
            if len(types) > 1:
                raise BagFormatError(f"{self.path}: topic {name} has several types {sorted(types)}")
            qos: list[Qos] = []
            for c in conns:
                qos.extend(getattr(c.ext, "offered_qos_profiles", []) or [])
            topics.append(
                TopicInfo(
                    name=name,
                    msgtype=conns[0].msgtype,
                    message_count=sum(c.msgcount for c in conns),
                    serialization_format=getattr(conns[0].ext, "serialization_format", "cdr"),
                    offered_qos=tuple(qos),
                    msgdef=conns[0].msgdef.data if conns[0].msgdef else "",
                )
            )
        files = [self.path] if self.path.is_file() else [p for p in self.path.iterdir() if p.is_file()]
        version = None
        storage = self.path.suffix.lstrip(".") or "mcap"
        if self.path.is_dir():
            version = self._meta.get("version")
            storage = next((p.suffix.lstrip(".") for p in files if p.suffix in (".mcap", ".db3")), storage)
        storage = {"db3": "sqlite3"}.get(storage, storage)
        compression, compression_mode = "none", ""
        mode = str(self._meta.get("compression_mode") or "").lower()
        if mode not in ("", "none"):
            compression, compression_mode = str(self._meta.get("compression_format") or "?"), mode
        elif self._mcap is not None:
            kinds = sorted(set().union(*(i.compressions for i in self._mcap)) - {""})
            if kinds:
                compression, compression_mode = ", ".join(kinds), "chunks"
        elif storage == "mcap":
            compression = "unknown"  # no chunk index to tell (rosbags reads such a file by scanning it)
        count = r.message_count
        return BagInfo(
            path=self.path,
            storage=storage,
            version=version,
            start_ns=r.start_time if count else 0,
            end_ns=r.end_time - 1 if count else 0,  # rosbags reports the exclusive end
            message_count=count,
            size_bytes=sum(p.stat().st_size for p in files),
            topics=tuple(sorted(topics, key=lambda t: t.name)),
            compression=compression,
            compression_mode=compression_mode,
        )

    @property
    def info(self) -> BagInfo:
        return self._info

    def select_topics(self, topics: Iterable[str] | None) -> list[str]:
        """Validate a topic selection (``None`` = all); unknown topics are an error naming the known ones."""
        known = [t.name for t in self._info.topics]
        if topics is None:
            return known
        wanted = list(dict.fromkeys(topics))
        missing = [t for t in wanted if t not in known]
        if missing:
            raise BagError(f"{self.path}: no topic(s) {', '.join(missing)} (topics: {', '.join(known)})")
        return wanted

    def messages(
        self,
        *,
        topics: Iterable[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
        skipped: SkippedChunks | None = None,
    ) -> Iterator[BagMessage]:
        """Serialized messages of ``topics`` (default all) with ``start_ns <= log time < stop_ns``, in log-time
        order.

        A corrupt MCAP chunk raises :class:`~lightfast.bag.errors.CorruptChunkError`; with ``skipped`` given, its
        messages are skipped instead and the chunk is recorded there (the read goes on with the next chunk)."""
        names = set(self.select_topics(topics))
        if self._mcap is None:
            yield from self._rosbags_messages(names, start_ns, stop_ns)
            return
        types = {t.name: t.msgtype for t in self._info.topics}

        def on_corrupt(chunk: CorruptChunk) -> None:
            if skipped is None:
                raise CorruptChunkError(f"{self.path}: corrupt {chunk.describe()}", chunk)
            if skipped.add(chunk):
                log.info("%s: skipping corrupt %s", self.path, chunk.describe())

        start = 0 if start_ns is None else start_ns
        stop = 2**64 if stop_ns is None else stop_ns
        for index in self._mcap:
            channels = {cid for cid, (topic, _) in index.channels.items() if topic in names}
            if not channels:
                continue
            try:
                for t_ns, cid, data in iter_messages(index, channels, start, stop, on_corrupt):
                    topic, msgtype = index.channels[cid]
                    yield BagMessage(topic, types.get(topic, msgtype), t_ns, data)
            except OSError as exc:
                raise BagFormatError(f"{index.path}: cannot read: {_reason(exc)}") from None

    def _rosbags_messages(self, names: set[str], start_ns: int | None, stop_ns: int | None) -> Iterator[BagMessage]:
        conns = [c for c in self._reader.connections if c.topic in names]
        if not conns:
            return
        try:
            for conn, t_ns, data in self._reader.messages(connections=conns, start=start_ns, stop=stop_ns):
                yield BagMessage(conn.topic, conn.msgtype, t_ns, bytes(data))
        except (ReaderError, OSError, KeyError, ValueError, IndexError, EOFError, AssertionError, OverflowError,
                struct.error) as exc:
            raise BagFormatError(f"{self.path}: bag is damaged or truncated: {_reason(exc)}") from None

    def deserialize(self, message: BagMessage) -> Any:
        """Deserialize a message into a rosbags message object (fields as in the ROS message)."""
        from lightfast.bag.writer import default_typestore

        store = default_typestore()
        if message.msgtype not in store.types:
            raise UnknownMessageTypeError(f"message type {message.msgtype} on {message.topic} is not known to rosbags")
        try:
            return store.deserialize_cdr(message.data, message.msgtype)
        except Exception as exc:  # rosbags raises assorted errors on bad CDR
            raise BagFormatError(f"{message.topic}: cannot deserialize {message.msgtype}: {_reason(exc)}") from None

    def close(self) -> None:
        try:
            self._reader.close()
        except Exception:  # closing a damaged bag must not mask the original error
            log.debug("error while closing %s", self.path, exc_info=True)

    def __enter__(self) -> BagReader:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def _reason(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


def _metadata(path: Path) -> dict[str, Any]:
    """``rosbag2_bagfile_information`` of a bag directory's metadata.yaml ({} for a bare storage file)."""
    if not path.is_dir():
        return {}
    try:
        meta = yaml.safe_load((path / "metadata.yaml").read_text()) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise BagFormatError(f"{path}: cannot read metadata.yaml: {_reason(exc)}") from None
    info = meta.get("rosbag2_bagfile_information") if isinstance(meta, dict) else None
    return info if isinstance(info, dict) else {}


def _truncation(path: Path) -> str | None:
    """A reason if an MCAP file of the bag does not end with the MCAP magic (a cut-off file), else None."""
    files = [path] if path.is_file() else sorted(path.glob("*.mcap"))
    for f in files:
        try:
            with f.open("rb") as fh:
                size = fh.seek(0, os.SEEK_END)
                fh.seek(max(0, size - 8))
                tail = fh.read(8)
        except OSError:
            continue
        if size >= 8 and tail != b"\x89MCAP0\r\n":
            return (f"{f.name} is truncated or its end is damaged (no MCAP footer after {size} bytes; "
                    "was its writer killed?)")
    return None


def open_bag(path: str | os.PathLike[str]) -> BagReader:
    """Open a bag for reading (``with open_bag(path) as bag: ...``)."""
    return BagReader(path)
