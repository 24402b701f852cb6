"""Bags for the compression and corruption tests: several MCAP chunks, and a way to damage one of them."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mcap.reader import make_reader

from lightfast.bag import BagWriter, default_typestore

TS = default_typestore()
String = TS.types["std_msgs/msg/String"]
Header = TS.types["std_msgs/msg/Header"]
Time = TS.types["builtin_interfaces/msg/Time"]
T0 = 1_700_000_000 * 10**9
PERIOD_NS = 10_000_000


def write_chunked_bag(path: Path, *, n: int = 30, blob_bytes: int = 200_000, compression: str = "none") -> Path:
    """``n`` messages on /blob (a String of ``blob_bytes`` characters, different each) and ``n`` on /tick (a Header),
    10 ms apart: about 6 of each per 1-MiB chunk, so ``n = 30`` gives five chunks."""
    with BagWriter(path, compression=compression) as bag:
        bag.add_topic("/blob", "std_msgs/msg/String")
        bag.add_topic("/tick", "std_msgs/msg/Header")
        for i in range(n):
            t = T0 + i * PERIOD_NS
            bag.write_message("/blob", t, String(data=(f"blob {i:04d} " * (blob_bytes // 10 + 1))[:blob_bytes]))
            bag.write_message("/tick", t + 1, Header(stamp=Time(sec=i, nanosec=0), frame_id=f"tick {i}"))
    return path


@dataclass(frozen=True)
class Chunk:
    """A chunk of an MCAP file, from its chunk index."""

    offset: int
    length: int
    start_ns: int
    end_ns: int
    data_offset: int  # where the chunk's (compressed) records start in the file


def mcap_file(bag: Path) -> Path:
    return bag if bag.is_file() else next(bag.glob("*.mcap"))


def chunks(bag: Path) -> list[Chunk]:
    with mcap_file(bag).open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    out = []
    for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        header = 9 + 8 + 8 + 8 + 4 + 4 + len(ci.compression) + 8
        out.append(Chunk(ci.chunk_start_offset, ci.chunk_length, ci.message_start_time, ci.message_end_time,
                         ci.chunk_start_offset + header))
    return out


def overwrite(bag: Path, offset: int, size: int, *, seed: int = 0) -> None:
    """Overwrite ``size`` bytes at ``offset`` of the bag's MCAP file with random bytes (in place)."""
    garbage = np.random.default_rng(seed).integers(0, 256, size, dtype=np.uint8).tobytes()
    with mcap_file(bag).open("r+b") as fh:
        fh.seek(offset)
        original = fh.read(size)
        assert original != garbage
        fh.seek(offset)
        fh.write(garbage)


def corrupt_middle_of_chunk(bag: Path, index: int, size: int = 1000, *, seed: int = 0) -> Chunk:
    """Overwrite ``size`` bytes in the middle of chunk ``index``'s data with random bytes; returns that chunk."""
    chunk = chunks(bag)[index]
    middle = (chunk.data_offset + chunk.offset + chunk.length) // 2
    assert chunk.data_offset < middle - size // 2 and middle + size // 2 < chunk.offset + chunk.length
    overwrite(bag, middle - size // 2, size, seed=seed)
    return chunk
