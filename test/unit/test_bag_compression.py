"""MCAP chunk compression (zstd, lz4): smaller bags on real camera frames that read back identical through
lightfast, rosbags and mcap + mcap_ros2; chunk CRCs; ``bag info`` states the compression."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader

from lightfast.bag import BagWriter, compare_bags, default_typestore, open_bag
from lightfast.bag.errors import BagError
from lightfast.data.sevenscenes import SevenScenes
from lightfast.ros.convert import numpy_to_image
from lightfast.ros.msgtypes import rosbags_types
from test.bag_samples import mcap_file

T0 = 1_370_088_000 * 10**9
FRAMES = 12


@pytest.fixture(scope="module")
def frames(sevenscenes_dir: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Real 7-Scenes frames at 320x240: rgb8 and depth in metres (float32, NaN where invalid)."""
    data = SevenScenes(sevenscenes_dir)
    out = []
    for index in data.indices[:FRAMES]:
        frame = data.frame(index)
        rgb = cv2.resize(frame.rgb, (320, 240), interpolation=cv2.INTER_AREA)
        depth = cv2.resize(frame.depth_mm, (320, 240), interpolation=cv2.INTER_NEAREST).astype(np.float32) / 1000
        depth[depth == 0] = np.nan
        out.append((rgb, depth))
    return out


def write_frames(path: Path, frames: list[tuple[np.ndarray, np.ndarray]], compression: str) -> Path:
    types = rosbags_types()
    with BagWriter(path, compression=compression) as bag:
        bag.add_topic("/color", "sensor_msgs/msg/Image")
        bag.add_topic("/depth", "sensor_msgs/msg/Image")
        for i, (rgb, depth) in enumerate(frames):
            t = T0 + i * 33_333_333
            bag.write_message("/color", t, numpy_to_image(rgb, "rgb8", stamp_ns=t, frame_id="cam", types=types))
            bag.write_message("/depth", t, numpy_to_image(depth, "32FC1", stamp_ns=t, frame_id="cam", types=types))
    return path


def bag_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.iterdir())


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_compressed_bag_is_smaller_and_reads_back_identical(tmp_path: Path, frames, compression: str) -> None:
    plain = write_frames(tmp_path / "plain", frames, "none")
    packed = write_frames(tmp_path / "packed", frames, compression)
    assert bag_bytes(packed) < 0.9 * bag_bytes(plain), (bag_bytes(packed), bag_bytes(plain))

    # lightfast's reader: the same serialized payloads in the same order
    result = compare_bags(plain, packed)
    assert result.identical and result.topics[0].count_b == FRAMES, result.summary()
    with open_bag(packed) as bag:
        assert (bag.info.compression, bag.info.compression_mode) == (compression, "chunks")
        assert f"Compression:       {compression} (chunks)" in bag.info.format()
        depth = next(m for m in bag.messages(topics=["/depth"]))
        np.testing.assert_array_equal(np.frombuffer(bag.deserialize(depth).data, np.float32).reshape(240, 320),
                                      frames[0][1])
    with open_bag(plain) as bag:
        assert (bag.info.compression, bag.info.compression_mode) == ("none", "")
        assert "Compression:       none\n" in bag.info.format()
        plain_payloads = [(m.topic, m.log_time_ns, m.data) for m in bag.messages()]

    # rosbags' reader, straight on the bag directory
    with Reader(packed) as reader:
        assert not reader.compression_mode  # chunk compression, not rosbag2's file/message modes
        got = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
    assert got == plain_payloads

    # the reference mcap library with the ROS 2 decoder: decoded images equal the frames
    with mcap_file(packed).open("rb") as fh:
        decoded = [(ch.topic, msg) for _, ch, _, msg in make_reader(fh, decoder_factories=[DecoderFactory()])
                   .iter_decoded_messages()]
    colors = [m for topic, m in decoded if topic == "/color"]
    depths = [m for topic, m in decoded if topic == "/depth"]
    assert len(colors) == len(depths) == FRAMES
    for (rgb, depth), c, d in zip(frames, colors, depths, strict=True):
        np.testing.assert_array_equal(np.frombuffer(bytes(c.data), np.uint8).reshape(240, 320, 3), rgb)
        np.testing.assert_array_equal(np.frombuffer(bytes(d.data), np.float32).reshape(240, 320), depth)


@pytest.mark.parametrize("compression", ["none", "zstd"])
def test_every_chunk_has_a_crc_and_the_metadata_says_no_rosbag2_compression(tmp_path: Path, frames,
                                                                          compression: str) -> None:
    bag = write_frames(tmp_path / "bag", frames, compression)
    with mcap_file(bag).open("rb") as fh:
        chunks = [r for r in StreamReader(fh, emit_chunks=True).records if isinstance(r, Chunk)]
    assert len(chunks) > 1
    assert all(c.compression == ("" if compression == "none" else compression) for c in chunks)
    assert all(c.uncompressed_crc != 0 for c in chunks)
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["compression_mode"] == "" and meta["compression_format"] == ""  # what rosbag2's MCAP presets write
    assert meta["message_count"] == 2 * FRAMES


def test_compression_choices_are_checked(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="unknown compression 'gzip'; choose one of none, zstd, lz4"):
        BagWriter(tmp_path / "a", compression="gzip")
    with pytest.raises(BagError, match="needs mcap storage"):
        BagWriter(tmp_path / "b", storage="sqlite3", compression="zstd")
    assert list(tmp_path.iterdir()) == []  # nothing left behind


def test_sqlite3_bags_report_no_compression(tmp_path: Path) -> None:
    String = default_typestore().types["std_msgs/msg/String"]
    with BagWriter(tmp_path / "bag", storage="sqlite3") as bag:
        bag.add_topic("/text", "std_msgs/msg/String")
        bag.write_message("/text", 1, String(data="x"))
    with open_bag(tmp_path / "bag") as bag:
        assert bag.info.compression == "none" and [m.topic for m in bag.messages()] == ["/text"]
