"""rosbag2 bags without the ros2 CLI: read (MCAP and sqlite3), write MCAP atomically (optionally with zstd or lz4
chunk compression), inspect and compare; corrupt MCAP chunks are detected and can be skipped and counted.

This package is ROS-free (rosbags and mcap only); replaying onto and recording from live topics is in
:mod:`lightfast.ros.player` and :mod:`lightfast.ros.recorder`.
"""
from lightfast.bag.compare import BagComparison, TopicComparison, compare_bags
from lightfast.bag.errors import (
    BagError,
    BagExistsError,
    BagFormatError,
    BagNotFoundError,
    CorruptChunkError,
    UnknownMessageTypeError,
)
from lightfast.bag.mcap_chunks import CorruptChunk, SkippedChunks
from lightfast.bag.reader import BagInfo, BagMessage, BagReader, TopicInfo, open_bag
from lightfast.bag.writer import BagWriter, default_typestore, make_qos

__all__ = [
    "BagComparison",
    "BagError",
    "BagExistsError",
    "BagFormatError",
    "BagInfo",
    "BagMessage",
    "BagNotFoundError",
    "BagReader",
    "BagWriter",
    "CorruptChunk",
    "CorruptChunkError",
    "SkippedChunks",
    "TopicComparison",
    "TopicInfo",
    "UnknownMessageTypeError",
    "compare_bags",
    "default_typestore",
    "make_qos",
    "open_bag",
]
