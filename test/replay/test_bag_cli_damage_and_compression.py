"""`lightfast bag` as a subprocess on damaged and on compressed bags: play skips a corrupt chunk, prints one warning
line and exits 5 (0 with --skip-corrupt, still reporting it); info works and --check finds the damage; record
--compression zstd writes a smaller bag of the same images."""
from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import Image

from lightfast.bag import open_bag
from lightfast.data.sevenscenes import SevenScenes
from lightfast.ros.convert import image_to_numpy, numpy_to_image
from lightfast.ros.spin import spin_until
from test.bag_samples import corrupt_middle_of_chunk, write_chunked_bag
from test.helpers import LIGHTFAST, bounded_process, child_env, run_bounded


def damaged_bag(path: Path) -> tuple[Path, int]:
    """The five-chunk sample bag with garbage in the middle of its third chunk; returns it and the lost count."""
    bag = write_chunked_bag(path)
    with open_bag(bag) as b:
        times = [m.log_time_ns for m in b.messages()]
    chunk = corrupt_middle_of_chunk(bag, 2)
    return bag, sum(1 for t in times if chunk.start_ns <= t <= chunk.end_ns)


def test_play_a_damaged_bag_warns_in_one_line_and_exits_5(tmp_path: Path, domain_id: int) -> None:
    bag, lost = damaged_bag(tmp_path / "bag")
    skipped = f"skipped {lost} messages in 1 corrupt chunk"
    env = child_env(domain_id)

    strict = run_bounded([*LIGHTFAST, "bag", "play", str(bag), "--rate", "0"], timeout_s=120, env=env)
    assert strict.returncode == 5, strict.stderr
    lines = strict.stderr.strip().splitlines()
    assert len(lines) == 1, strict.stderr
    assert lines[0].startswith(f"lightfast: warning: {bag}: {skipped}; first: bag.mcap chunk at byte ")
    assert "CRC mismatch" in lines[0] and lines[0].endswith("the replay is incomplete")
    assert re.search(rf"played {60 - lost} messages on 2 topics, .*, {skipped}$", strict.stdout.strip())

    accepted = run_bounded([*LIGHTFAST, "bag", "play", str(bag), "--rate", "0", "--skip-corrupt"], timeout_s=120,
                           env=env)
    assert accepted.returncode == 0, accepted.stderr
    assert accepted.stdout.strip().endswith(skipped)
    assert accepted.stderr.strip().endswith("accepted (--skip-corrupt)")
    assert "Traceback" not in strict.stderr + accepted.stderr


def test_info_works_on_a_damaged_bag_and_check_finds_the_damage(tmp_path: Path) -> None:
    bag, lost = damaged_bag(tmp_path / "bag")
    info = run_bounded([*LIGHTFAST, "bag", "info", str(bag)], timeout_s=60)
    assert info.returncode == 0 and info.stderr == ""
    assert re.search(r"Messages:\s+60\n", info.stdout) and "Compression:       none" in info.stdout
    check = run_bounded([*LIGHTFAST, "bag", "info", "--check", str(bag)], timeout_s=60)
    assert check.returncode == 5
    assert f"Check:             {60 - lost} messages read, skipped {lost} messages in 1 corrupt chunk" in check.stdout
    assert len(check.stderr.strip().splitlines()) == 1 and "the bag is damaged" in check.stderr
    intact = write_chunked_bag(tmp_path / "intact")
    ok = run_bounded([*LIGHTFAST, "bag", "info", "--check", str(intact)], timeout_s=60)
    assert ok.returncode == 0 and "Check:             60 messages read, no corrupt chunk" in ok.stdout


def test_record_with_zstd_compression(tmp_path: Path, sevenscenes_dir: Path, domain_id: int, make_node,
                                      executor) -> None:
    """`lightfast bag record --compression zstd` of real camera frames: a zstd-chunked bag, smaller than the
    frames' raw bytes (by ~10 % only: downscaled JPEG-decoded rgb8 compresses poorly; see
    benchmarks/results/bag_compression.md), holding exactly the published images (read by lightfast and rosbags)."""
    data = SevenScenes(sevenscenes_dir)
    frames = [cv2.resize(data.frame(i).rgb, (320, 240), interpolation=cv2.INTER_AREA) for i in data.indices[:20]]
    node = make_node("camera")
    pub = node.create_publisher(Image, "/camera", QoSProfile(history=HistoryPolicy.KEEP_ALL,
                                                             reliability=ReliabilityPolicy.RELIABLE))
    out = tmp_path / "rec"
    cmd = [*LIGHTFAST, "bag", "record", "-o", str(out), "--compression", "zstd", "--max-messages", "20", "/camera"]
    with bounded_process(cmd, timeout_s=120, env=child_env(domain_id)) as rec:
        assert spin_until(executor, lambda: pub.get_subscription_count() == 1, timeout_s=60)
        for i, rgb in enumerate(frames):
            pub.publish(numpy_to_image(rgb, "rgb8", stamp_ns=i, frame_id="cam"))
        assert spin_until(executor, lambda: rec.poll() is not None, timeout_s=60)
        rec_out, rec_err = rec.communicate(timeout=30)
    assert rec.returncode == 0, rec_err
    assert re.search(r"recorded 20 messages on 1 topics to .*\([\d.]+ MB, zstd chunks\)", rec_out)
    raw_bytes = sum(f.nbytes for f in frames)
    with open_bag(out) as bag:
        assert (bag.info.compression, bag.info.compression_mode) == ("zstd", "chunks")
        assert bag.info.size_bytes < raw_bytes  # uncompressed it would be the pixels plus headers and indexes
        images = [image_to_numpy(bag.deserialize(m)) for m in bag.messages()]
    assert len(images) == 20
    for got, want in zip(images, frames, strict=True):
        np.testing.assert_array_equal(got, want)
    with Reader(out) as reader:
        assert sum(1 for _ in reader.messages()) == 20
