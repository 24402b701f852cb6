"""The MCAP storage behind :class:`~lightfast.bag.writer.BagWriter`: rosbags' ``Writer`` front end (connections,
QoS, ``metadata.yaml``) over the reference ``mcap`` library's writer, which adds what rosbags' own MCAP storage
lacks: chunk compression with zstd or lz4, and a CRC-32 of every chunk.

Chunk compression is what rosbag2's MCAP plugin does with ``--storage-preset-profile zstd_fast`` (or a storage
config's ``compression``): each chunk of records is compressed inside the MCAP file, the file stays a plain MCAP file
that every MCAP reader (rosbags, ``mcap``, Foxglove, ``ros2 bag``) reads, and ``metadata.yaml`` says no rosbag2
compression (``compression_mode: ''``). rosbag2's own ``--compression-mode file|message`` is not used: it makes
the storage file unreadable to plain MCAP readers.

The chunk CRCs let a reader tell a damaged chunk from a good one (see :mod:`lightfast.bag.mcap_chunks`); rosbags'
storage writes 0 ("no CRC"), so damage inside a payload of such a bag goes unnoticed.
"""
from __future__ import annotations

from importlib.metadata import version
from pathlib import Path
from typing import BinaryIO

from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.interfaces import Connection, MessageDefinitionFormat
from rosbags.rosbag2.enums import CompressionMode

#: Chunk compression choices (``none`` writes uncompressed chunks, still with CRCs).
COMPRESSIONS: dict[str, CompressionType] = {
    "none": CompressionType.NONE,
    "zstd": CompressionType.ZSTD,  # zstandard's default level 3
    "lz4": CompressionType.LZ4,  # lz4 frame, default level
}
#: Chunks close once they hold more than this many bytes (uncompressed), as rosbags' and mcap's writers do.
CHUNK_SIZE = 1024 * 1024


class McapStorage:
    """A storage plugin for :class:`rosbags.rosbag2.Writer` (its ``StorageWriter`` protocol) that writes
    ``<bag>/<bag>.mcap`` with the ``ros2`` profile through :class:`mcap.writer.Writer`."""

    def __init__(self, path: Path, compression_mode: CompressionMode, *, compression: str = "none",
                 chunk_size: int = CHUNK_SIZE) -> None:
        del compression_mode  # rosbag2's file/message modes are never used here
        self.path = path / f"{path.name}.mcap"
        self._file: BinaryIO = self.path.open("xb")
        self._mcap = McapWriter(self._file, chunk_size=chunk_size, compression=COMPRESSIONS[compression],
                                enable_crcs=True)
        self._mcap.start(profile="ros2", library=f"lightfast; rosbags-{version('rosbags')}; "
                         f"mcap-python-{version('mcap')}")
        self._schemas: dict[str, int] = {}
        self._channels: dict[int, int] = {}

    def add_msgtype(self, connection: Connection) -> None:
        encoding = "ros2idl" if connection.msgdef.format == MessageDefinitionFormat.IDL else "ros2msg"
        self._schemas[connection.msgtype] = self._mcap.register_schema(
            name=connection.msgtype, encoding=encoding, data=connection.msgdef.data.encode()
        )

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        self._channels[connection.id] = self._mcap.register_channel(
            topic=connection.topic,
            message_encoding=getattr(connection.ext, "serialization_format", "cdr"),
            schema_id=self._schemas[connection.msgtype],
            metadata={"offered_qos_profiles": offered_qos_profiles},
        )

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        # mcap annotates data as bytes but only takes its len() and writes it: a memoryview is written without a copy
        self._mcap.add_message(self._channels[connection.id], log_time=timestamp,
                               data=data, publish_time=timestamp)  # type: ignore[arg-type]

    def close(self, version: int, metadata: str) -> None:
        """Finish the last chunk, add rosbag2's metadata record, write the summary and footer."""
        del version
        self._mcap.flush()  # the last chunk, then the metadata record
        self._mcap.add_metadata("rosbag2", {"serialized_metadata": metadata})
        self._mcap.finish()
        self._file.close()

    def abort(self) -> None:
        self._file.close()
