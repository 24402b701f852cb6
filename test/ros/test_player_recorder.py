"""Bag player and recorder in one process (private context, discovery off, real executor)."""
import threading
import time
from pathlib import Path

import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from lightfast.bag import BagWriter, compare_bags, default_typestore, make_qos, open_bag
from lightfast.ros.convert import stamp_to_ns
from lightfast.ros.player import PlayOptions, play_bag
from lightfast.ros.recorder import BagRecorder, drain
from lightfast.ros.spin import spin_until

TS = default_typestore()
String = TS.types["std_msgs/msg/String"]
Header = TS.types["std_msgs/msg/Header"]
Time = TS.types["builtin_interfaces/msg/Time"]
T0 = 1_700_000_000 * 10**9


def make_bag(path: Path, *, n: int = 50, period_ns: int = 10_000_000) -> Path:
    with BagWriter(path) as bag:
        bag.add_topic("/text", "std_msgs/msg/String", offered_qos=[make_qos()])
        bag.add_topic("/header", "std_msgs/msg/Header", offered_qos=[make_qos(reliable=False)])
        for i in range(n):
            bag.write_message("/text", T0 + i * period_ns, String(data=f"message {i}"))
            bag.write_message("/header", T0 + i * period_ns + 1, Header(stamp=Time(sec=i, nanosec=0), frame_id="x"))
    return path


def play_in_thread(bag: Path, node, options: PlayOptions) -> tuple[threading.Thread, dict]:
    out: dict = {}
    thread = threading.Thread(target=lambda: out.setdefault("report", play_bag(bag, node, options)), daemon=True)
    thread.start()
    return thread, out


def test_play_into_recorder_is_lossless_and_identical(tmp_path, make_node, executor) -> None:
    src = make_bag(tmp_path / "src")
    recorder = BagRecorder(make_node("recorder"), BagWriter(tmp_path / "rec"), topics=["/text"])
    player = make_node("player", spun=False)
    thread, out = play_in_thread(src, player, PlayOptions(rate=0.0, topics=("/text",), wait_for_subscribers_s=5.0))
    assert spin_until(executor, lambda: recorder.report.message_count == 50, timeout_s=20.0)
    thread.join(timeout=10)
    report = recorder.close()
    assert out["report"].published == {"/text": 50}
    assert out["report"].acknowledged
    assert report.topics["/text"].count == 50
    result = compare_bags(src, tmp_path / "rec", topics=["/text"])
    assert result.identical, result.summary()
    with open_bag(tmp_path / "rec") as bag:
        assert bag.info.topic("/text").offered_qos[0].reliability.name == "RELIABLE"


def test_rate_start_offset_and_clock(tmp_path, make_node, executor) -> None:
    src = make_bag(tmp_path / "src", n=40, period_ns=10_000_000)  # 0.39 s of bag
    sub_node = make_node("clock_listener")
    clocks: list[int] = []
    texts: list[str] = []
    sub_node.create_subscription(Clock, "/clock", lambda m: clocks.append(stamp_to_ns(m.clock)), 100)
    from std_msgs.msg import String as RclString

    sub_node.create_subscription(RclString, "/text", lambda m: texts.append(m.data),
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    from std_msgs.msg import Header as RclHeader

    sub_node.create_subscription(RclHeader, "/header", lambda m: None,
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT))
    options = PlayOptions(rate=2.0, clock_hz=100.0, start_offset_s=0.2, wait_for_subscribers_s=5.0)
    t0 = time.monotonic()
    thread, out = play_in_thread(src, make_node("player", spun=False), options)
    assert spin_until(executor, lambda: len(texts) == 20 and not thread.is_alive(), timeout_s=20.0)
    wall = time.monotonic() - t0
    report = out["report"]
    assert texts[0] == "message 20" and texts[-1] == "message 39"
    assert report.published == {"/text": 20, "/header": 20}
    assert report.bag_duration_s == pytest.approx(0.19, abs=1e-6)
    assert report.wall_duration_s == pytest.approx(0.095, abs=0.05)  # rate 2: half the bag time
    assert wall >= 0.09
    assert spin_until(executor, lambda: bool(clocks) and clocks[-1] == T0 + 390_000_001, timeout_s=5.0)
    assert clocks == sorted(clocks)
    assert clocks[0] == T0 + 200_000_000  # the first message's time: the offset skipped 0.2 s
    assert 0.0 < report.cpu_s < 5.0


def test_preroll_runs_the_clock_before_the_first_message(tmp_path, make_node, executor) -> None:
    """The clock runs from preroll_s before the first message, at the playback rate; the report's wall and CPU time
    count from the first message on."""
    src = make_bag(tmp_path / "src", n=10, period_ns=10_000_000)
    clocks: list[int] = []
    sub_node = make_node("clock_probe")
    sub_node.create_subscription(Clock, "/clock", lambda m: clocks.append(stamp_to_ns(m.clock)), 100)
    executor.add_node(sub_node)
    t0 = time.monotonic()
    player = make_node("player", spun=False)
    thread, out = play_in_thread(src, player, PlayOptions(rate=2.0, clock_hz=100.0, preroll_s=0.6))
    assert spin_until(executor, lambda: not thread.is_alive(), timeout_s=20.0)
    wall = time.monotonic() - t0
    report = out["report"]
    assert wall >= 0.3 + 0.045  # 0.6 s of preroll and 0.09 s of bag at rate 2
    assert report.wall_duration_s == pytest.approx(0.045, abs=0.04)
    assert spin_until(executor, lambda: bool(clocks) and clocks[-1] == T0 + 90_000_001, timeout_s=5.0)
    assert clocks[0] < T0  # the subscriber saw the clock run before the first message


def test_loop_until_stopped(tmp_path, make_node, executor) -> None:
    src = make_bag(tmp_path / "src", n=5, period_ns=1_000_000)
    stop = threading.Event()
    counter = {"n": 0}
    from std_msgs.msg import String as RclString

    make_node("listener").create_subscription(
        RclString, "/text", lambda m: counter.__setitem__("n", counter["n"] + 1), QoSProfile(depth=100))
    out: dict = {}
    options = PlayOptions(rate=1.0, loop=True, topics=("/text",), wait_for_subscribers_s=5.0)
    thread = threading.Thread(target=lambda: out.setdefault("r", play_bag(src, make_node("player", spun=False), options,
                                                                         stop=stop)), daemon=True)
    thread.start()
    assert spin_until(executor, lambda: counter["n"] >= 12, timeout_s=20.0)
    stop.set()
    thread.join(timeout=10)
    assert not thread.is_alive()
    assert out["r"].loops >= 3 and out["r"].interrupted


def test_recorder_records_all_topics_and_drains(tmp_path, make_node, executor) -> None:
    src = make_bag(tmp_path / "src", n=30)
    recorder = BagRecorder(make_node("recorder"), BagWriter(tmp_path / "rec", storage="sqlite3"))
    thread, _ = play_in_thread(src, make_node("player", spun=False), PlayOptions(rate=0.0, wait_for_subscribers_s=5.0))
    assert spin_until(executor, lambda: len(recorder.subscribed) == 2, timeout_s=10.0)
    thread.join(timeout=20)
    drain(lambda t: executor.spin_once(timeout_sec=t), lambda: recorder.report.message_count)
    report = recorder.close()
    assert set(report.topics) == {"/text", "/header"}
    assert report.topics["/text"].count == 30
    assert report.topics["/header"].count <= 30  # best effort: may drop, never duplicates
    with open_bag(tmp_path / "rec") as bag:
        assert bag.info.storage == "sqlite3"
        assert "/rosout" not in [t.name for t in bag.info.topics]


def test_player_skips_a_corrupt_chunk_and_reports_it(tmp_path, make_node, executor) -> None:
    """A bag with garbage in the middle of one chunk: the player publishes every other message, in order, and its
    report counts the skipped ones (from the bag's index)."""
    from std_msgs.msg import Header as RclHeader
    from std_msgs.msg import String as RclString

    from test.bag_samples import corrupt_middle_of_chunk, write_chunked_bag

    src = write_chunked_bag(tmp_path / "src")  # 30 /blob + 30 /tick in five chunks
    with open_bag(src) as bag:
        original = [(m.topic, m.log_time_ns) for m in bag.messages()]
    chunk = corrupt_middle_of_chunk(src, 2)
    lost = [m for m in original if chunk.start_ns <= m[1] <= chunk.end_ns]
    lost_ticks = [t for topic, t in lost if topic == "/tick"]
    assert lost_ticks and len(lost) < len(original)

    ticks: list[str] = []
    blobs: list[int] = []
    listener = make_node("listener")
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    listener.create_subscription(RclHeader, "/tick", lambda m: ticks.append(m.frame_id), qos)
    listener.create_subscription(RclString, "/blob", lambda m: blobs.append(int(m.data.split()[1])), qos)
    player = make_node("player", spun=False)
    thread, out = play_in_thread(src, player, PlayOptions(rate=0.0, wait_for_subscribers_s=5.0))
    expected_ticks = [f"tick {i}" for i in range(30) if T0 + i * 10_000_000 + 1 not in lost_ticks]
    expected_blobs = [i for i in range(30) if ("/blob", T0 + i * 10_000_000) not in lost]
    assert spin_until(executor, lambda: not thread.is_alive() and len(ticks) == len(expected_ticks)
                      and len(blobs) == len(expected_blobs), timeout_s=30.0)
    report = out["report"]
    assert ticks == expected_ticks
    assert blobs == expected_blobs
    assert report.published == {"/blob": 30 - (len(lost) - len(lost_ticks)), "/tick": 30 - len(lost_ticks)}
    assert report.skipped_messages == len(lost) and len(report.corrupt_chunks) == 1 and not report.complete
    assert report.corrupt_chunks[0].offset == chunk.offset
    assert report.summary().endswith(f", skipped {len(lost)} messages in 1 corrupt chunk")


def test_recorder_writes_zstd_chunks(tmp_path, make_node, executor) -> None:
    """--compression passes through the writer: the recording is smaller than the uncompressed source bag and holds
    the same payloads."""
    from test.bag_samples import write_chunked_bag

    src = write_chunked_bag(tmp_path / "src", n=20)
    recorder = BagRecorder(make_node("recorder"), BagWriter(tmp_path / "rec", compression="zstd"),
                           topics=["/blob", "/tick"])
    thread, _ = play_in_thread(src, make_node("player", spun=False), PlayOptions(rate=0.0, wait_for_subscribers_s=5.0))
    assert spin_until(executor, lambda: recorder.report.message_count == 40, timeout_s=30.0)
    thread.join(timeout=10)
    report = recorder.close()
    assert "zstd chunks" in report.summary()
    assert compare_bags(src, tmp_path / "rec").identical
    with open_bag(tmp_path / "rec") as rec, open_bag(src) as plain:
        assert (rec.info.compression, plain.info.compression) == ("zstd", "none")
        assert report.size_bytes == rec.info.size_bytes < plain.info.size_bytes / 4
