"""Damaged MCAP bags: a corrupt chunk is detected (CRC, decompression, record structure), raises one clear line
by default, or is skipped and counted; every other message still reads back intact; ``bag info`` still works."""
from __future__ import annotations

import struct
from pathlib import Path

import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from lightfast.bag import BagFormatError, CorruptChunkError, SkippedChunks, compare_bags, open_bag
from test.bag_samples import (
    PERIOD_NS,
    T0,
    TS,
    Header,
    String,
    Time,
    chunks,
    corrupt_middle_of_chunk,
    mcap_file,
    overwrite,
    write_chunked_bag,
)


def payloads(path: Path, **kwargs) -> list[tuple[str, int, bytes]]:
    with open_bag(path) as bag:
        return [(m.topic, m.log_time_ns, m.data) for m in bag.messages(**kwargs)]


def in_chunk(messages: list[tuple[str, int, bytes]], chunk) -> list[tuple[str, int, bytes]]:
    return [m for m in messages if chunk.start_ns <= m[1] <= chunk.end_ns]


@pytest.mark.parametrize("compression", ["none", "zstd", "lz4"])
def test_a_corrupt_chunk_is_skipped_and_counted(tmp_path: Path, compression: str) -> None:
    good = write_chunked_bag(tmp_path / "good", compression=compression)
    bad = write_chunked_bag(tmp_path / "bad", compression=compression)
    assert len(chunks(bad)) >= 4
    original = payloads(good)
    chunk = corrupt_middle_of_chunk(bad, 2)
    lost = in_chunk(original, chunk)
    assert 0 < len(lost) < len(original)

    # by default: one clear line naming the chunk
    with open_bag(bad) as bag, pytest.raises(CorruptChunkError) as info:
        list(bag.messages())
    text = str(info.value)
    assert "\n" not in text and f"chunk at byte {chunk.offset}" in text and f"messages {len(lost)}" in text
    assert info.value.chunk.message_count == len(lost)

    # skipping: everything else, byte-identical and in order; the skip counted
    skipped = SkippedChunks()
    with open_bag(bad) as bag:
        got = [(m.topic, m.log_time_ns, m.data) for m in bag.messages(skipped=skipped)]
    assert got == [m for m in original if m not in lost]
    assert (skipped.chunk_count, skipped.message_count, skipped.exact) == (1, len(lost), True)
    assert skipped.summary() == f"skipped {len(lost)} messages in 1 corrupt chunk"
    reason = skipped.first().reason
    assert reason == "CRC mismatch" if compression == "none" else ("CRC mismatch" in reason or "decompress" in reason)

    # reading again with the same record (a looping replay) counts the chunk once
    with open_bag(bad) as bag:
        assert len(list(bag.messages(skipped=skipped))) == len(got)
    assert skipped.chunk_count == 1

    # one topic: only that topic's lost messages count
    only_ticks = SkippedChunks()
    assert len(payloads(bad, topics=["/tick"], skipped=only_ticks)) == 30 - len(in_chunk(
        [m for m in original if m[0] == "/tick"], chunk))
    assert only_ticks.message_count == sum(1 for m in lost if m[0] == "/tick")

    # info reads the summary only: it works and still tells the indexed counts
    with open_bag(bad) as bag:
        assert bag.info.message_count == 60


def test_a_start_inside_the_corrupt_chunk_counts_from_the_message_index(tmp_path: Path) -> None:
    bad = write_chunked_bag(tmp_path / "bad")
    original = payloads(bad)
    chunk = corrupt_middle_of_chunk(bad, 1)
    lost = in_chunk(original, chunk)
    start = lost[len(lost) // 2][1]  # half of the chunk lies before the requested range
    skipped = SkippedChunks()
    got = payloads(bad, start_ns=start, skipped=skipped)
    assert got == [m for m in original if m[1] >= start and m not in lost]
    assert skipped.message_count == sum(1 for m in lost if m[1] >= start) < len(lost)
    assert skipped.exact


def test_damage_across_two_chunks_counts_both(tmp_path: Path) -> None:
    bad = write_chunked_bag(tmp_path / "bad")
    original = payloads(bad)
    first, second = chunks(bad)[1:3]
    overwrite(bad, first.offset + first.length - 2000, 4000)  # the end of one chunk, the start of the next
    skipped = SkippedChunks()
    got = payloads(bad, skipped=skipped)
    lost = in_chunk(original, first) + in_chunk(original, second)
    assert got == [m for m in original if m not in lost]
    assert skipped.summary() == f"skipped {len(lost)} messages in 2 corrupt chunks"


def write_rosbags_bag(path: Path, n: int = 30) -> Path:
    """A bag from rosbags' own MCAP writer: uncompressed chunks without CRC (how lightfast wrote bags before)."""
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        blob = writer.add_connection("/blob", "std_msgs/msg/String", typestore=TS)
        tick = writer.add_connection("/tick", "std_msgs/msg/Header", typestore=TS)
        for i in range(n):
            t = T0 + i * PERIOD_NS
            writer.write(blob, t, TS.serialize_cdr(String(data=f"blob {i:04d} " * 20_000), "std_msgs/msg/String"))
            writer.write(tick, t + 1, TS.serialize_cdr(Header(stamp=Time(sec=i, nanosec=0), frame_id="t"),
                                                       "std_msgs/msg/Header"))
    return path


def test_without_crcs_damaged_record_structure_is_still_detected(tmp_path: Path) -> None:
    """rosbags' writer stores no chunk CRC: damage over a record header is found by the structure checks (rosbags'
    own reader raises an OverflowError mid-read on this file, or skips the chunk's rest silently)."""
    bag = write_rosbags_bag(tmp_path / "bag")
    original = payloads(bag)
    chunk = chunks(bag)[2]
    with mcap_file(bag).open("rb") as fh:  # the first record inside the chunk (uncompressed): damage its header
        fh.seek(chunk.offset + 9 + 24)
        assert struct.unpack("<I", fh.read(4))[0] == 0  # no CRC
    overwrite(bag, chunk.data_offset, 64)
    skipped = SkippedChunks()
    got = payloads(bag, skipped=skipped)
    lost = in_chunk(original, chunk)
    assert got == [m for m in original if m not in lost]
    assert skipped.message_count == len(lost) > 0
    assert "record" in skipped.first().reason or "message" in skipped.first().reason


def test_truncated_and_garbage_files_are_one_clear_line(tmp_path: Path) -> None:
    bag = write_chunked_bag(tmp_path / "bag")
    data = mcap_file(bag).read_bytes()
    mcap_file(bag).write_bytes(data[: len(data) // 2])
    with pytest.raises(BagFormatError, match=r"cannot read bag: bag\.mcap is truncated or its end is damaged"):
        open_bag(bag)
    other = write_chunked_bag(tmp_path / "other")
    overwrite(other, len(mcap_file(other).read_bytes()) - 30, 30)  # the footer
    with pytest.raises(BagFormatError, match="cannot read bag") as info:
        open_bag(other)
    assert "\n" not in str(info.value)


def test_intact_bags_compare_identical_through_the_checked_reader(tmp_path: Path) -> None:
    a = write_chunked_bag(tmp_path / "a")
    b = write_rosbags_bag(tmp_path / "b")
    assert compare_bags(a, a).identical
    skipped = SkippedChunks()
    with open_bag(b) as bag:
        assert len(list(bag.messages(skipped=skipped))) == 60 and not skipped
