"""Bag writing and reading without ROS: round trips, ordering, storage formats, and clear errors."""
import shutil
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.typesys import Stores, get_typestore

from lightfast.bag import (
    BagExistsError,
    BagFormatError,
    BagNotFoundError,
    BagWriter,
    UnknownMessageTypeError,
    compare_bags,
    default_typestore,
    make_qos,
    open_bag,
)
from lightfast.bag.errors import BagError

TS = default_typestore()
Header = TS.types["std_msgs/msg/Header"]
Time = TS.types["builtin_interfaces/msg/Time"]
String = TS.types["std_msgs/msg/String"]


def header(i: int) -> object:
    return Header(stamp=Time(sec=i, nanosec=0), frame_id=f"f{i}")


def write_sample(path: Path, *, storage: str = "mcap", n: int = 20) -> Path:
    with BagWriter(path, storage=storage) as bag:
        bag.add_topic("/header", "std_msgs/msg/Header", offered_qos=[make_qos(transient_local=True)])
        bag.add_topic("/text", "std_msgs/msg/String")
        # written out of order on purpose: readers must return log-time order
        for i in reversed(range(n)):
            bag.write_message("/header", 1_000 + 10 * i, header(i))
            bag.write_message("/text", 1_005 + 10 * i, String(data=f"m{i}"))
    return path


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_round_trip_in_log_time_order(tmp_path: Path, storage: str) -> None:
    path = write_sample(tmp_path / "bag", storage=storage)
    with open_bag(path) as bag:
        info = bag.info
        assert info.storage == storage
        assert info.message_count == 40
        assert (info.start_ns, info.end_ns) == (1_000, 1_195)
        assert [t.name for t in info.topics] == ["/header", "/text"]
        assert info.topic("/header").offered_qos[0].durability.name == "TRANSIENT_LOCAL"
        messages = list(bag.messages())
        times = [m.log_time_ns for m in messages]
        assert times == sorted(times)
        assert bag.deserialize(messages[1]).data == "m0"
        assert [bag.deserialize(m).frame_id for m in bag.messages(topics=["/header"], start_ns=1_100)] == [
            f"f{i}" for i in range(10, 20)
        ]
        assert "std_msgs/msg/Header" in info.format()


def test_mcap_is_self_describing(tmp_path: Path) -> None:
    """The MCAP file embeds message definitions: the mcap library decodes it without our typestore."""
    path = write_sample(tmp_path / "bag")
    with (path / "bag.mcap").open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        decoded = [(channel.topic, msg) for _, channel, _, msg in reader.iter_decoded_messages()]
    assert len(decoded) == 40
    texts = [msg.data for topic, msg in decoded if topic == "/text"]
    assert texts == [f"m{i}" for i in range(20)]


def test_bare_mcap_file_and_directory_agree(tmp_path: Path) -> None:
    path = write_sample(tmp_path / "bag")
    bare = tmp_path / "copy.mcap"
    shutil.copy(path / "bag.mcap", bare)
    assert compare_bags(path, bare).identical
    with open_bag(path / "bag.mcap") as bag:  # a storage file inside a bag directory reads the directory
        assert bag.path == path


def test_writer_is_atomic_and_refuses_overwrite(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    with pytest.raises(RuntimeError), BagWriter(path) as bag:
        bag.add_topic("/text", "std_msgs/msg/String")
        bag.write_message("/text", 1, String(data="x"))
        raise RuntimeError("crash")
    assert list(tmp_path.iterdir()) == []  # nothing half-written left behind
    write_sample(path)
    with pytest.raises(BagExistsError):
        BagWriter(path)
    write_sample(path.parent / "other", n=3)
    with BagWriter(path, overwrite=True) as bag:
        bag.add_topic("/text", "std_msgs/msg/String")
    with open_bag(path) as bag:
        assert bag.info.message_count == 0


def test_unknown_types_need_a_definition(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "bag", typestore=get_typestore(Stores.ROS2_JAZZY)) as bag:
        with pytest.raises(UnknownMessageTypeError, match="no message definition for foo_msgs/msg/Bar"):
            bag.add_topic("/bar", "foo_msgs/msg/Bar")
        bag.add_topic("/bar2", "foo_msgs/msg/Baz", msgdef="int32 value\nstring name\n")
        cls = bag.typestore.types["foo_msgs/msg/Baz"]
        bag.write_message("/bar2", 5, cls(value=3, name="n"))
    with open_bag(tmp_path / "bag") as bag:
        assert bag.info.topic("/bar2").msgtype == "foo_msgs/msg/Baz"
        assert "int32 value" in bag.info.topic("/bar2").msgdef


def test_errors_are_one_clear_line(tmp_path: Path) -> None:
    with pytest.raises(BagNotFoundError, match="no bag at"):
        open_bag(tmp_path / "missing")
    (tmp_path / "empty_dir").mkdir()
    with pytest.raises(BagFormatError, match=r"without metadata\.yaml"):
        open_bag(tmp_path / "empty_dir")
    path = write_sample(tmp_path / "bag")
    data = (path / "bag.mcap").read_bytes()
    (path / "bag.mcap").write_bytes(data[: len(data) // 2])
    with pytest.raises(BagFormatError) as info:
        with open_bag(path) as bag:
            list(bag.messages())
    assert "\n" not in str(info.value)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    with pytest.raises(BagFormatError):
        open_bag(junk)
    with open_bag(write_sample(tmp_path / "ok")) as bag, pytest.raises(BagError, match="no topic"):
        list(bag.messages(topics=["/nope"]))


def test_compare_detects_drops_and_changes(tmp_path: Path) -> None:
    a = write_sample(tmp_path / "a")
    with BagWriter(tmp_path / "b") as bag:
        bag.add_topic("/header", "std_msgs/msg/Header")
        bag.add_topic("/text", "std_msgs/msg/String")
        for i in range(20):
            bag.write_message("/header", 5 + i, header(i))
            if i != 7:
                bag.write_message("/text", 5 + i, String(data=f"m{i}" if i != 3 else "changed"))
    result = compare_bags(a, tmp_path / "b")
    by_topic = {t.topic: t for t in result.topics}
    assert by_topic["/header"].identical_payloads
    assert by_topic["/text"].count_b == 19 and by_topic["/text"].first_mismatch == 3
    assert result.dropped == 1 and not result.identical
    assert "19/20" in result.summary()
    assert compare_bags(a, a).identical


def test_images_survive_the_bag(tmp_path: Path) -> None:
    Image = TS.types["sensor_msgs/msg/Image"]
    rng = np.random.default_rng(0)
    img = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    with BagWriter(tmp_path / "bag") as bag:
        bag.add_topic("/img", "sensor_msgs/msg/Image")
        bag.write_message("/img", 1, Image(header=header(0), height=48, width=64, encoding="rgb8", is_bigendian=0,
                                           step=192, data=img.reshape(-1)))
    with open_bag(tmp_path / "bag") as bag:
        msg = bag.deserialize(next(bag.messages()))
    np.testing.assert_array_equal(msg.data.reshape(48, 64, 3), img)
