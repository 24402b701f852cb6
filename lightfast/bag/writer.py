"""Write rosbag2 bags (MCAP by default, sqlite3 on request) with rosbags, atomically.

The bag is built under a hidden temporary directory beside the target and moved into place by :meth:`close`, so
a reader never sees a half-written bag at the target path. The MCAP file embeds each topic's message definition,
so ``ros2 bag``, Foxglove, rosbags and ``mcap`` can all read it. MCAP files are written through
:class:`~lightfast.bag.mcap_storage.McapStorage`: every chunk carries a CRC, and ``compression="zstd"`` or ``"lz4"``
compresses the chunks (rosbag2's MCAP chunk compression; the file stays readable by any MCAP reader).
"""
from __future__ import annotations

import functools
import os
import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, Final

from rosbags.interfaces import Connection, Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.errors import WriterError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from lightfast.bag.errors import BagError, BagExistsError, UnknownMessageTypeError
from lightfast.bag.mcap_storage import COMPRESSIONS, McapStorage

ROSBAG2_VERSION: Final = 9  # the metadata version of ROS 2 Jazzy's rosbag2
STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}


@functools.cache
def default_typestore() -> Typestore:
    """The ROS 2 Jazzy typestore (message definitions of the standard interfaces)."""
    return get_typestore(Stores.ROS2_JAZZY)


def make_qos(
    *, reliable: bool = True, transient_local: bool = False, keep_all: bool = False, depth: int = 10
) -> Qos:
    """A rosbags QoS record (the form bags store offered QoS profiles in)."""
    default = QosTime(0, 0)  # 0 means the RMW default: no deadline, infinite lifespan and lease
    return Qos(
        history=QosHistory.KEEP_ALL if keep_all else QosHistory.KEEP_LAST,
        depth=0 if keep_all else depth,
        reliability=QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
        durability=QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
        deadline=default,
        lifespan=default,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=default,
        avoid_ros_namespace_conventions=False,
    )


class BagWriter:
    """Write serialized messages into a new bag at ``path`` (a rosbag2 directory).

    ``with BagWriter(path) as bag: bag.add_topic(...); bag.write(...)`` — on a clean exit the bag is closed and
    moved into place; on an exception it is discarded (call :meth:`close` yourself to keep what was written).
    ``compression`` (``"none"``, ``"zstd"``, ``"lz4"``; MCAP storage only) compresses the MCAP file's chunks.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        storage: str = "mcap",
        overwrite: bool = False,
        typestore: Typestore | None = None,
        compression: str = "none",
    ) -> None:
        self.path = Path(path)
        if storage not in STORAGES:
            raise BagError(f"unknown storage {storage!r}; choose one of {sorted(STORAGES)}")
        if compression not in COMPRESSIONS:
            raise BagError(f"unknown compression {compression!r}; choose one of {', '.join(COMPRESSIONS)}")
        if compression != "none" and storage != "mcap":
            raise BagError(f"compression {compression} needs mcap storage ({storage} has no chunk compression)")
        if self.path.exists() and not overwrite:
            raise BagExistsError(f"{self.path} exists already (choose another path or allow overwriting)")
        self.storage = storage
        self.compression = compression
        self.overwrite = overwrite
        self.typestore = typestore or default_typestore()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", suffix=".partial", dir=self.path.parent))
        self._writer = Writer(self._tmp / self.path.name, version=ROSBAG2_VERSION, storage_plugin=STORAGES[storage])
        if storage == "mcap":
            # rosbags' Writer keeps its front end (connections, QoS, metadata.yaml); the MCAP file comes from
            # McapStorage (chunk CRCs, chunk compression). The plugin table is looked up per instance at open().
            self._writer.STORAGE_PLUGINS = {
                **Writer.STORAGE_PLUGINS,
                # rosbags types the table as classes; it only calls the entry, so a factory works
                StoragePlugin.MCAP: functools.partial(McapStorage, compression=compression),  # type: ignore[dict-item]
            }
        try:
            self._writer.open()
        except Exception:
            shutil.rmtree(self._tmp, ignore_errors=True)
            raise
        self._connections: dict[str, Connection] = {}
        self.counts: dict[str, int] = {}
        self._closed = False

    @property
    def partial_path(self) -> Path:
        """Where the bag is being written until :meth:`close` moves it to :attr:`path`."""
        return self._tmp / self.path.name

    def add_topic(
        self, topic: str, msgtype: str, *, offered_qos: Sequence[Qos] = (), msgdef: str | None = None
    ) -> None:
        """Declare a topic. ``msgdef`` (ros2msg text) is needed only for types the typestore does not know."""
        if topic in self._connections:
            raise BagError(f"topic {topic} was added twice")
        if msgtype not in self.typestore.types:
            if not msgdef:
                raise UnknownMessageTypeError(f"no message definition for {msgtype} (topic {topic})")
            register_msgdef(self.typestore, msgtype, msgdef)
        try:
            conn = self._writer.add_connection(
                topic, msgtype, typestore=self.typestore, offered_qos_profiles=list(offered_qos)
            )
        except WriterError as exc:
            raise BagError(f"cannot add topic {topic}: {exc}") from None
        self._connections[topic] = conn
        self.counts[topic] = 0

    def has_topic(self, topic: str) -> bool:
        return topic in self._connections

    def write(self, topic: str, log_time_ns: int, data: bytes | memoryview) -> None:
        """Append one serialized (CDR) message with its log time in nanoseconds."""
        try:
            conn = self._connections[topic]
        except KeyError:
            raise BagError(f"topic {topic} was not added to the bag") from None
        self._writer.write(conn, int(log_time_ns), data)
        self.counts[topic] += 1

    def write_message(self, topic: str, log_time_ns: int, message: Any) -> None:
        """Serialize a rosbags message object (see :func:`default_typestore`) as Fast CDR would, and append it."""
        conn = self._connections.get(topic)
        if conn is None:
            raise BagError(f"topic {topic} was not added to the bag")
        data: bytes | memoryview = self.typestore.serialize_cdr(message, conn.msgtype)
        if pad := -len(data) % 4:
            # Fast CDR (what rclpy and every live publisher use) pads a payload to a multiple of 4 bytes; doing the
            # same keeps a converted bag byte-identical to one recorded from live topics.
            data = bytes(data) + bytes(pad)
        self.write(topic, log_time_ns, data)

    def close(self) -> Path:
        """Finish the bag (summary, metadata.yaml) and move it to :attr:`path`. Returns the path."""
        if self._closed:
            return self.path
        self._closed = True
        self._writer.close()
        if self.path.exists():
            if not self.overwrite:
                raise BagExistsError(f"{self.path} appeared while writing; the bag is left at {self.partial_path}")
            shutil.rmtree(self.path) if self.path.is_dir() else self.path.unlink()
        os.replace(self.partial_path, self.path)
        shutil.rmtree(self._tmp, ignore_errors=True)
        return self.path

    def abort(self) -> None:
        """Discard the bag being written."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.close()
        except Exception:
            pass
        shutil.rmtree(self._tmp, ignore_errors=True)

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def register_msgdef(typestore: Typestore, msgtype: str, msgdef: str) -> None:
    """Register a message type from its ros2msg definition (with dependencies in ``===`` ``MSG:`` sections)."""
    from rosbags.typesys import get_types_from_msg

    try:
        typestore.register(get_types_from_msg(msgdef, msgtype))
    except Exception as exc:  # rosbags raises parser-specific errors
        raise UnknownMessageTypeError(f"cannot parse the message definition of {msgtype}: {exc}") from None
