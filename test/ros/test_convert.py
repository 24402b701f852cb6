"""Tests of lightfast.ros.convert: message <-> NumPy for rclpy and rosbags messages, and through CDR.

These import the ROS message packages and rclpy.serialization but need no rclpy context or executor.
"""
from __future__ import annotations

import array
import subprocess
import sys
from typing import Any

import numpy as np
import pytest
import sensor_msgs.msg
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message

from lightfast.camera import PinholeCamera
from lightfast.errors import LightfastError
from lightfast.ros.convert import (
    IMAGE_ENCODINGS,
    CameraInfoReader,
    camera_from_camera_info,
    camera_info_from_camera,
    image_fields,
    image_to_numpy,
    make_header,
    matrix_to_odometry,
    matrix_to_pose,
    matrix_to_pose_stamped,
    ns_to_stamp,
    numpy_to_image,
    numpy_to_pointcloud2,
    odometry_to_matrix,
    pointcloud2_fields,
    pointcloud2_to_numpy,
    pose_stamped_to_matrix,
    pose_to_matrix,
    stamp_to_ns,
    undistorter_from_camera_info,
    xyz_to_pointcloud2,
)
from lightfast.ros.errors import (
    CameraInfoError,
    ConversionError,
    ImageConversionError,
    PointCloudConversionError,
    PoseConversionError,
)
from lightfast.ros.msgtypes import RCLPY, MessageTypes, rosbags_types

ROSBAGS = rosbags_types()
TYPESTORE = ROSBAGS.typestore
FLAVOURS: dict[str, MessageTypes] = {"rclpy": RCLPY, "rosbags": ROSBAGS}
ENCODINGS = list(IMAGE_ENCODINGS)
PROPERTY = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])

flavour_param = pytest.mark.parametrize("flavour", list(FLAVOURS))
stamps = st.integers(0, 2**31 * 10**9 - 1)  # builtin_interfaces/Time has int32 seconds


def _bytes_of(data: Any) -> np.ndarray:
    """The message buffer of a uint8[] field (array.array for rclpy, ndarray for rosbags) as a uint8 array."""
    return np.frombuffer(data, dtype=np.uint8)


def _assert_same_bits(actual: np.ndarray, expected: np.ndarray) -> None:
    assert actual.shape == expected.shape
    assert actual.dtype == expected.dtype
    assert actual.dtype.isnative
    assert np.ascontiguousarray(actual).tobytes() == np.ascontiguousarray(expected).tobytes()


# ------------------------------------------------------------------------------------------------------ stamps


@flavour_param
@PROPERTY
@given(ns=st.integers(-(2**31) * 10**9, 2**31 * 10**9 - 1))
def test_stamp_round_trip(flavour: str, ns: int) -> None:
    stamp = ns_to_stamp(ns, types=FLAVOURS[flavour])
    assert 0 <= stamp.nanosec < 10**9
    assert stamp_to_ns(stamp) == ns


def test_stamp_rejects_floats_out_of_range_and_bad_nanosec() -> None:
    with pytest.raises(TypeError, match="integer nanoseconds"):
        ns_to_stamp(1.5e9)  # type: ignore[arg-type]
    with pytest.raises(ConversionError, match="int32"):
        ns_to_stamp(2**31 * 10**9)
    stamp = ns_to_stamp(0, types=ROSBAGS)
    stamp.nanosec = 10**9
    with pytest.raises(ConversionError, match=r"Time\.nanosec=1000000000"):
        stamp_to_ns(stamp)


@flavour_param
def test_make_header(flavour: str) -> None:
    header = make_header(1_700_000_000_123_456_789, "camera_optical", types=FLAVOURS[flavour])
    assert (header.stamp.sec, header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert header.frame_id == "camera_optical"


# ------------------------------------------------------------------------------------------------------ images


def _image_shape(encoding: str, height: int, width: int) -> tuple[int, ...]:
    channels = IMAGE_ENCODINGS[encoding].channels
    return (height, width) if channels == 1 else (height, width, channels)


@st.composite
def image_arrays(draw: st.DrawFn, encoding: str) -> np.ndarray:
    """Arrays of any bit pattern (NaNs and infinities included for 32FC1), sizes from 1x1."""
    height, width = draw(st.integers(1, 9)), draw(st.integers(1, 9))
    shape = _image_shape(encoding, height, width)
    dtype = IMAGE_ENCODINGS[encoding].dtype
    nbytes = int(np.prod(shape)) * dtype.itemsize
    raw = draw(st.binary(min_size=nbytes, max_size=nbytes))
    return np.frombuffer(raw, dtype=dtype).reshape(shape).copy()


def _padded_image(msg: Any, pad: int, fill: int, types: MessageTypes) -> Any:
    """A copy of ``msg`` whose rows carry ``pad`` extra bytes of value ``fill`` (``step`` grows by ``pad``)."""
    rows = _bytes_of(msg.data).reshape(msg.height, msg.step)
    padded = np.full((msg.height, msg.step + pad), fill, dtype=np.uint8)
    padded[:, : msg.step] = rows
    return types.new(
        "sensor_msgs/msg/Image",
        header=make_header(stamp_to_ns(msg.header.stamp), msg.header.frame_id, types=types),
        height=msg.height,
        width=msg.width,
        encoding=msg.encoding,
        is_bigendian=msg.is_bigendian,
        step=msg.step + pad,
        data=types.uint8_array(padded),
    )


@pytest.mark.parametrize("encoding", ENCODINGS)
@flavour_param
@PROPERTY
@given(data=st.data())
def test_image_round_trip(flavour: str, encoding: str, data: st.DataObject) -> None:
    types = FLAVOURS[flavour]
    pixels = data.draw(image_arrays(encoding))
    stamp_ns = data.draw(stamps)
    msg = numpy_to_image(pixels, encoding, stamp_ns=stamp_ns, frame_id="cam", types=types)
    pixel_bytes = IMAGE_ENCODINGS[encoding].dtype.itemsize * IMAGE_ENCODINGS[encoding].channels
    assert (msg.height, msg.width, msg.encoding) == (pixels.shape[0], pixels.shape[1], encoding)
    assert (msg.is_bigendian, msg.step) == (0, pixels.shape[1] * pixel_bytes)
    assert stamp_to_ns(msg.header.stamp) == stamp_ns and msg.header.frame_id == "cam"
    out = image_to_numpy(msg)
    _assert_same_bits(out, pixels)
    assert np.shares_memory(out, _bytes_of(msg.data))

    pad = data.draw(st.integers(1, 7))
    padded = _padded_image(msg, pad, data.draw(st.integers(0, 255)), types)
    out = image_to_numpy(padded)
    _assert_same_bits(out, pixels)
    assert np.shares_memory(out, _bytes_of(padded.data)), "native data with row padding must still be zero-copy"


@pytest.mark.parametrize("encoding", ENCODINGS)
@PROPERTY
@given(data=st.data())
def test_image_round_trip_through_cdr(encoding: str, data: st.DataObject) -> None:
    pixels = data.draw(image_arrays(encoding))
    pad = data.draw(st.integers(0, 5))
    bag_msg = numpy_to_image(pixels, encoding, stamp_ns=42, frame_id="cam", types=ROSBAGS)
    if pad:
        bag_msg = _padded_image(bag_msg, pad, 0xAB, ROSBAGS)
    cdr = TYPESTORE.serialize_cdr(bag_msg, "sensor_msgs/msg/Image")
    ros_msg = deserialize_message(bytes(cdr), sensor_msgs.msg.Image)
    _assert_same_bits(image_to_numpy(ros_msg), pixels)
    assert stamp_to_ns(ros_msg.header.stamp) == 42

    back = TYPESTORE.deserialize_cdr(serialize_message(ros_msg), "sensor_msgs/msg/Image")
    _assert_same_bits(image_to_numpy(back), pixels)

    rclpy_msg = numpy_to_image(pixels, encoding, types=RCLPY)
    from_rclpy = TYPESTORE.deserialize_cdr(serialize_message(rclpy_msg), "sensor_msgs/msg/Image")
    _assert_same_bits(image_to_numpy(from_rclpy), pixels)


def test_image_message_buffers_per_flavour() -> None:
    pixels = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    rclpy_msg = numpy_to_image(pixels, "rgb8", types=RCLPY)
    assert isinstance(rclpy_msg, sensor_msgs.msg.Image)
    assert isinstance(rclpy_msg.data, array.array) and rclpy_msg.data.typecode == "B"
    assert not np.shares_memory(_bytes_of(rclpy_msg.data), pixels), "rclpy data is one copy of the pixels"
    bag_msg = numpy_to_image(pixels, "rgb8", types=ROSBAGS)
    assert isinstance(bag_msg.data, np.ndarray) and bag_msg.data.dtype == np.uint8 and bag_msg.data.ndim == 1
    assert np.shares_memory(bag_msg.data, pixels), "rosbags data is a view of a contiguous input"


def test_image_to_numpy_views_the_rclpy_buffer() -> None:
    msg = numpy_to_image(np.zeros((4, 5), dtype=np.uint16), "16UC1", types=RCLPY)
    out = image_to_numpy(msg)
    out[1, 2] = 0x1234
    assert np.frombuffer(msg.data, dtype="<u2").reshape(4, 5)[1, 2] == 0x1234


@pytest.mark.parametrize("encoding", ["16UC1", "mono16", "32FC1"])
@flavour_param
@PROPERTY
@given(data=st.data())
def test_big_endian_images_are_swapped_to_native(flavour: str, encoding: str, data: st.DataObject) -> None:
    types = FLAVOURS[flavour]
    dtype = IMAGE_ENCODINGS[encoding].dtype
    height, width, pad = data.draw(st.integers(1, 6)), data.draw(st.integers(1, 6)), data.draw(st.integers(0, 3))
    if dtype.kind == "f":
        elements = st.floats(0.0, 100.0, width=32) | st.just(float("nan"))
    else:
        elements = st.integers(0, 2**16 - 1)
    values = np.array(data.draw(st.lists(elements, min_size=height * width, max_size=height * width)), dtype=dtype)
    depth = values.reshape(height, width)
    rows = np.zeros((height, width * dtype.itemsize + pad), dtype=np.uint8)
    big_endian_bytes = np.frombuffer(depth.astype(dtype.newbyteorder(">")).tobytes(), np.uint8)
    rows[:, : width * dtype.itemsize] = big_endian_bytes.reshape(height, -1)
    msg = types.new(
        "sensor_msgs/msg/Image",
        header=make_header(0, "depth", types=types),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=1,
        step=rows.shape[1],
        data=types.uint8_array(rows),
    )
    out = image_to_numpy(msg)
    assert out.dtype == dtype and out.dtype.isnative
    assert np.array_equal(out, depth, equal_nan=True)
    if sys.byteorder == "little":
        assert not np.shares_memory(out, _bytes_of(msg.data))


def test_known_big_endian_depth_value() -> None:
    msg = numpy_to_image(np.zeros((1, 1), np.uint16), "16UC1", types=ROSBAGS)
    msg.is_bigendian, msg.data = 1, np.array([0x01, 0x02], dtype=np.uint8)
    assert image_to_numpy(msg)[0, 0] == 0x0102  # 258 mm


def test_image_fields_outputs_little_endian_contiguous_bytes() -> None:
    depth = np.array([[1, 2], [3, 0x0102]], dtype=">u2")
    fields = image_fields(depth, "16UC1")
    assert (fields.height, fields.width, fields.encoding, fields.is_bigendian, fields.step) == (2, 2, "16UC1", 0, 4)
    assert fields.data.dtype == np.uint8 and fields.data.ndim == 1 and fields.data.flags.c_contiguous
    assert fields.data.tolist() == [1, 0, 2, 0, 3, 0, 2, 1]
    one_channel = image_fields(np.zeros((3, 4, 1), np.float32), "32FC1")
    assert (one_channel.height, one_channel.width, one_channel.step) == (3, 4, 16)
    strided = np.zeros((4, 6, 3), np.uint8)[:, ::2]
    assert image_fields(strided, "bgr8").data.size == 4 * 3 * 3


@pytest.mark.parametrize(
    ("array", "encoding", "match"),
    [
        (np.zeros((2, 2), np.float64), "32FC1", "needs dtype float32"),
        (np.zeros((2, 2), np.uint8), "16UC1", "needs dtype uint16"),
        (np.zeros((2, 2), np.uint8), "rgb8", r"shape \(H, W, 3\)"),
        (np.zeros((2, 2, 4), np.uint8), "rgb8", r"shape \(H, W, 3\)"),
        (np.zeros((2, 2, 3), np.uint8), "mono8", r"shape \(H, W\)"),
        (np.zeros((0, 2, 3), np.uint8), "rgb8", "empty"),
        (np.zeros((2, 2), np.uint8), "yuv422", "encoding='yuv422' is not supported"),
    ],
)
def test_image_fields_rejects_mismatched_arrays(array: np.ndarray, encoding: str, match: str) -> None:
    with pytest.raises(ImageConversionError, match=match):
        image_fields(array, encoding)


def _image_msg(types: MessageTypes, **overrides: Any) -> Any:
    fields: dict[str, Any] = dict(
        header=make_header(0, "cam", types=types),
        height=4,
        width=640,
        encoding="rgb8",
        is_bigendian=0,
        step=1920,
        data=types.uint8_array(np.zeros(4 * 1920, np.uint8)),
    )
    fields.update(overrides)
    return types.new("sensor_msgs/msg/Image", **fields)


@flavour_param
@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"step": 100}, r"Image\.step=100 is smaller than width\*bytes_per_pixel=1920"),
        ({"data": np.zeros(4 * 1920 - 1, np.uint8)}, r"len\(Image\.data\)=7679 does not equal step\*height=7680"),
        ({"step": 1924}, r"len\(Image\.data\)=7680 does not equal step\*height=7696"),
        ({"encoding": "bayer_rggb8"}, r"Image\.encoding='bayer_rggb8' is not supported"),
        ({"encoding": ""}, r"Image\.encoding='' is not supported"),
        ({"is_bigendian": 2}, r"Image\.is_bigendian=2 must be 0 or 1"),
        ({"height": 0, "data": np.zeros(0, np.uint8)}, r"Image\.height=0 must be > 0"),
        ({"width": 0}, r"Image\.width=0 must be > 0"),
    ],
)
def test_malformed_images_raise(flavour: str, overrides: dict[str, Any], match: str) -> None:
    types = FLAVOURS[flavour]
    if "data" in overrides:
        overrides = {**overrides, "data": types.uint8_array(overrides["data"])}
    msg = _image_msg(types, **overrides)
    with pytest.raises(ImageConversionError, match=match) as info:
        image_to_numpy(msg)
    assert isinstance(info.value, ValueError) and isinstance(info.value, LightfastError)


def test_image_to_numpy_is_duck_typed() -> None:
    class FakeImage:
        height, width, encoding, is_bigendian, step = 2, 2, "mono8", 0, 3
        data = bytes([1, 2, 99, 3, 4, 99])

    out = image_to_numpy(FakeImage())
    assert out.tolist() == [[1, 2], [3, 4]]
    assert not out.flags.writeable  # a view of immutable bytes


# ------------------------------------------------------------------------------------------------ point clouds

_FIELD_TYPES = ["<f4", "<u4", "<u1", "<f8", "<i2", "<i1", "<u2", "<i4"]


@st.composite
def cloud_dtypes(draw: st.DrawFn) -> np.dtype:
    """Structured point dtypes: 1–5 fields of PointField types, count 1–3, gaps between fields, tail padding."""
    names = draw(
        st.lists(st.text("xyzabcdefgh_", min_size=1, max_size=5), min_size=1, max_size=5, unique=True)
    )
    formats: list[Any] = []
    offsets: list[int] = []
    offset = 0
    for _ in names:
        base = np.dtype(draw(st.sampled_from(_FIELD_TYPES)))
        count = draw(st.integers(1, 3))
        offset += draw(st.integers(0, 3))
        formats.append(base if count == 1 else (base, (count,)))
        offsets.append(offset)
        offset += base.itemsize * count
    itemsize = offset + draw(st.integers(0, 5))
    order = draw(st.permutations(range(len(names))))  # field order need not follow offsets
    return np.dtype(
        {
            "names": [names[i] for i in order],
            "formats": [formats[i] for i in order],
            "offsets": [offsets[i] for i in order],
            "itemsize": itemsize,
        }
    )


@st.composite
def clouds(draw: st.DrawFn) -> tuple[np.ndarray, int]:
    """``(points, height)``: random bit patterns, 1–3 rows of 0–6 points."""
    dtype = draw(cloud_dtypes())
    height, width = draw(st.integers(1, 3)), draw(st.integers(0, 6))
    nbytes = height * width * dtype.itemsize
    raw = draw(st.binary(min_size=nbytes, max_size=nbytes))
    return np.frombuffer(raw, dtype=dtype).copy(), height


def _assert_same_points(actual: np.ndarray, expected: np.ndarray) -> None:
    assert actual.shape == expected.shape
    assert actual.dtype.names == expected.dtype.names
    assert actual.dtype.itemsize == expected.dtype.itemsize
    for name in expected.dtype.names:
        assert actual.dtype.fields[name] == expected.dtype.fields[name]
        assert actual[name].tobytes() == expected[name].tobytes(), name


def _cloud_msg(types: MessageTypes, points_msg: Any, **overrides: Any) -> Any:
    """A copy of a PointCloud2 message with some fields replaced."""
    fields: dict[str, Any] = {
        name: getattr(points_msg, name)
        for name in ("height", "width", "is_bigendian", "point_step", "row_step", "is_dense")
    }
    fields["fields"] = [
        types.new("sensor_msgs/msg/PointField", name=f.name, offset=f.offset, datatype=f.datatype, count=f.count)
        for f in points_msg.fields
    ]
    fields["data"] = types.uint8_array(_bytes_of(points_msg.data))
    fields["header"] = make_header(0, "lidar", types=types)
    fields.update(overrides)
    return types.new("sensor_msgs/msg/PointCloud2", **fields)


@flavour_param
@PROPERTY
@given(cloud=clouds(), data=st.data())
def test_pointcloud2_round_trip(flavour: str, cloud: tuple[np.ndarray, int], data: st.DataObject) -> None:
    types = FLAVOURS[flavour]
    points, height = cloud
    msg = numpy_to_pointcloud2(points, height=height, stamp_ns=7, frame_id="lidar", types=types)
    assert (msg.height, msg.width) == (height, points.size // height)
    assert msg.point_step == points.dtype.itemsize and msg.row_step == msg.width * msg.point_step
    assert msg.is_bigendian is False or msg.is_bigendian == 0
    assert stamp_to_ns(msg.header.stamp) == 7 and msg.header.frame_id == "lidar"
    out = pointcloud2_to_numpy(msg)
    _assert_same_points(out, points)
    assert out.tobytes() == points.tobytes(), "point padding bytes survive a native round trip"
    if points.size:
        assert np.shares_memory(out, _bytes_of(msg.data))

    pad = data.draw(st.integers(1, 9))
    rows = np.full((msg.height, msg.row_step + pad), 0xEE, dtype=np.uint8)
    rows[:, : msg.row_step] = _bytes_of(msg.data).reshape(msg.height, msg.row_step)
    padded = _cloud_msg(types, msg, row_step=msg.row_step + pad, data=types.uint8_array(rows))
    _assert_same_points(pointcloud2_to_numpy(padded), points)

    big = points.astype(points.dtype.newbyteorder(">"))
    big_msg = _cloud_msg(types, msg, is_bigendian=True, data=types.uint8_array(big.view(np.uint8).reshape(-1)))
    big_out = pointcloud2_to_numpy(big_msg)
    assert big_out.dtype.isnative
    _assert_same_points(big_out, points)


@PROPERTY
@given(cloud=clouds())
def test_pointcloud2_round_trip_through_cdr(cloud: tuple[np.ndarray, int]) -> None:
    points, height = cloud
    bag_msg = numpy_to_pointcloud2(points, height=height, types=ROSBAGS)
    ros_msg = deserialize_message(
        bytes(TYPESTORE.serialize_cdr(bag_msg, "sensor_msgs/msg/PointCloud2")), sensor_msgs.msg.PointCloud2
    )
    _assert_same_points(pointcloud2_to_numpy(ros_msg), points)
    back = TYPESTORE.deserialize_cdr(serialize_message(ros_msg), "sensor_msgs/msg/PointCloud2")
    _assert_same_points(pointcloud2_to_numpy(back), points)


def test_organized_cloud_keeps_row_major_order_and_2d_input() -> None:
    grid = np.zeros((2, 3), dtype=[("x", "<f4"), ("ring", "<u2")])
    grid["x"] = np.arange(6, dtype=np.float32).reshape(2, 3)
    msg = numpy_to_pointcloud2(grid, types=ROSBAGS)
    assert (msg.height, msg.width, msg.row_step) == (2, 3, 3 * grid.dtype.itemsize)
    flat = pointcloud2_to_numpy(msg)
    assert flat.shape == (6,)
    assert flat["x"].tolist() == [0, 1, 2, 3, 4, 5]  # point (row, col) is element row * width + col
    with pytest.raises(PointCloudConversionError, match="height=3"):
        numpy_to_pointcloud2(grid, height=3)
    with pytest.raises(PointCloudConversionError, match="divide"):
        numpy_to_pointcloud2(flat, height=4)


def test_pointcloud2_fields_describe_the_layout() -> None:
    dtype = np.dtype({"names": ["x", "normal"], "formats": ["<f4", ("<f8", (3,))], "offsets": [0, 8], "itemsize": 40})
    points = np.zeros(4, dtype=dtype)
    points["x"][2] = np.nan
    f = pointcloud2_fields(points, height=2)
    assert (f.height, f.width, f.point_step, f.row_step, f.is_bigendian) == (2, 2, 40, 80, False)
    assert [tuple(s) for s in f.fields] == [("x", 0, 7, 1), ("normal", 8, 8, 3)]
    assert f.is_dense is False
    assert f.data.dtype == np.uint8 and f.data.shape == (160,)
    assert pointcloud2_fields(points, is_dense=True).is_dense is True


@pytest.mark.parametrize(
    ("array", "match"),
    [
        (np.zeros(3, np.float32), "structured dtype"),
        (np.zeros(3, dtype=[("x", "<i8")]), "'x' has dtype int64"),
        (np.zeros(3, dtype=[("c", "<c8")]), "'c' has dtype complex64"),
        (np.zeros(3, dtype=[("m", "<f4", (2, 2))]), "'m' has dtype"),
        (np.zeros((1, 2, 3), dtype=[("x", "<f4")]), "1-D"),
    ],
)
def test_pointcloud2_fields_rejects_unsupported_arrays(array: np.ndarray, match: str) -> None:
    with pytest.raises(PointCloudConversionError, match=match):
        pointcloud2_fields(array)


def _point_field(types: MessageTypes, name: str, offset: int, datatype: int, count: int = 1) -> Any:
    return types.new("sensor_msgs/msg/PointField", name=name, offset=offset, datatype=datatype, count=count)


@flavour_param
@pytest.mark.parametrize(
    ("fields", "overrides", "match"),
    [
        ([("x", 0, 7), ("flags", 4, 9)], {}, r"fields\[1\] \(name='flags'\): datatype=9 is not a PointField datatype"),
        ([("x", 0, 7), ("y", 2, 7)], {}, r"'x' and 'y' overlap"),
        ([("x", 0, 7), ("z", 6, 7)], {}, r"fields\[1\] \(name='z'\): offset=6 \+ 4 bytes lies outside point_step=8"),
        ([("x", 0, 7), ("x", 4, 7)], {}, r"fields\[1\] \(name='x'\): duplicate field name 'x'"),
        ([("x", 0, 7), ("y", 4, 7, 0)], {}, r"fields\[1\] \(name='y'\): count=0"),
        ([], {}, r"PointCloud2\.fields is empty"),
        ([("x", 0, 7)], {"row_step": 24}, r"len\(PointCloud2\.data\)=32 does not equal row_step\*height=48"),
        ([("x", 0, 7)], {"row_step": 8}, r"PointCloud2\.row_step=8 is smaller than width\*point_step=16"),
        ([("x", 0, 7)], {"point_step": 0, "row_step": 0}, r"PointCloud2\.point_step=0 must be > 0"),
    ],
)
def test_malformed_pointclouds_raise(
    flavour: str, fields: list[tuple[Any, ...]], overrides: dict[str, Any], match: str
) -> None:
    types = FLAVOURS[flavour]
    values: dict[str, Any] = dict(
        header=make_header(0, "lidar", types=types),
        height=2,
        width=2,
        fields=[_point_field(types, *f) for f in fields],
        is_bigendian=False,
        point_step=8,
        row_step=16,
        data=types.uint8_array(np.zeros(32, np.uint8)),
        is_dense=True,
    )
    values.update(overrides)
    with pytest.raises(PointCloudConversionError, match=match) as info:
        pointcloud2_to_numpy(types.new("sensor_msgs/msg/PointCloud2", **values))
    assert isinstance(info.value, ValueError) and isinstance(info.value, LightfastError)


@flavour_param
def test_xyz_to_pointcloud2(flavour: str) -> None:
    xyz = np.array([[0.0, 1.0, 2.0], [3.0, np.nan, 5.0]])
    intensity = np.array([0.5, 0.25], dtype=np.float32)
    msg = xyz_to_pointcloud2(
        xyz, frame_id="map", extra_fields={"intensity": intensity}, types=FLAVOURS[flavour]
    )
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == [
        ("x", 0, 7, 1),
        ("y", 4, 7, 1),
        ("z", 8, 7, 1),
        ("intensity", 12, 7, 1),
    ]
    assert not msg.is_dense
    points = pointcloud2_to_numpy(msg)
    np.testing.assert_array_equal(np.stack([points["x"], points["y"], points["z"]], axis=1), xyz.astype(np.float32))
    np.testing.assert_array_equal(points["intensity"], intensity)
    with pytest.raises(PointCloudConversionError, match=r"shape \(N, 3\)"):
        xyz_to_pointcloud2(np.zeros((4, 2)))
    with pytest.raises(PointCloudConversionError, match="'x' clashes"):
        xyz_to_pointcloud2(np.zeros((4, 3)), extra_fields={"x": np.zeros(4, np.float32)})
    with pytest.raises(PointCloudConversionError, match="'ring' has dtype int64"):
        xyz_to_pointcloud2(np.zeros((4, 3)), extra_fields={"ring": np.zeros(4, np.int64)})


# ------------------------------------------------------------------------------------------------------- poses


def _quat_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Rotation matrix of a unit quaternion (x, y, z, w), written out independently of scipy."""
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


unit_quaternions = (
    st.tuples(*[st.floats(-1.0, 1.0) for _ in range(4)])
    .filter(lambda q: np.linalg.norm(q) > 0.1)
    .map(lambda q: tuple(np.asarray(q) / np.linalg.norm(q)))
)
translations = st.tuples(*[st.floats(-1e3, 1e3) for _ in range(3)])


def _transform(q: tuple[float, ...], t: tuple[float, ...]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = _quat_matrix(*q)
    T[:3, 3] = t
    return T


def _pose_msg(types: MessageTypes, q: tuple[float, ...], t: tuple[float, ...] = (0.0, 0.0, 0.0)) -> Any:
    return types.new(
        "geometry_msgs/msg/Pose",
        position=types.new("geometry_msgs/msg/Point", x=t[0], y=t[1], z=t[2]),
        orientation=types.new("geometry_msgs/msg/Quaternion", x=q[0], y=q[1], z=q[2], w=q[3]),
    )


@flavour_param
@PROPERTY
@given(q=unit_quaternions, t=translations)
def test_pose_round_trip(flavour: str, q: tuple[float, ...], t: tuple[float, ...]) -> None:
    types = FLAVOURS[flavour]
    T = pose_to_matrix(_pose_msg(types, q, t))
    np.testing.assert_allclose(T, _transform(q, t), atol=1e-9)
    pose = matrix_to_pose(T, types=types)
    written = np.array([pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w])
    assert written[3] >= 0.0
    np.testing.assert_allclose(abs(written @ np.asarray(q)), 1.0, atol=1e-9)  # same rotation, up to sign
    np.testing.assert_allclose(pose_to_matrix(pose), T, atol=1e-9)


def test_pose_quaternion_convention() -> None:
    s = np.sqrt(0.5)
    T = pose_to_matrix(_pose_msg(ROSBAGS, (0.0, 0.0, s, s), (1.0, 2.0, 3.0)))  # +90° about z
    np.testing.assert_allclose(T[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(T[:, 3], [1, 2, 3, 1])
    pose = matrix_to_pose(T, types=RCLPY)
    np.testing.assert_allclose([pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w],
                               [0, 0, s, s], atol=1e-12)


@flavour_param
@PROPERTY
@given(
    q=unit_quaternions,
    t=translations,
    stamp_ns=stamps,
    twist=st.tuples(*[st.floats(-10, 10) for _ in range(6)]),
    cov=st.lists(st.floats(-1e3, 1e3), min_size=72, max_size=72),
)
def test_stamped_pose_and_odometry_round_trip(
    flavour: str, q: tuple[float, ...], t: tuple[float, ...], stamp_ns: int, twist: tuple[float, ...],
    cov: list[float],
) -> None:
    types = FLAVOURS[flavour]
    T = _transform(q, t)
    ps = matrix_to_pose_stamped(T, stamp_ns=stamp_ns, frame_id="map", types=types)
    T2, stamp2, frame = pose_stamped_to_matrix(ps)
    np.testing.assert_allclose(T2, T, atol=1e-9)
    assert (stamp2, frame) == (stamp_ns, "map")

    pose_cov = np.asarray(cov[:36]).reshape(6, 6)
    odom = matrix_to_odometry(
        T, stamp_ns=stamp_ns, frame_id="odom", child_frame_id="base_link", twist_linear=twist[:3],
        twist_angular=twist[3:], pose_covariance=pose_cov, twist_covariance=cov[36:], types=types,
    )
    T3, stamp3, frame3, child = odometry_to_matrix(odom)
    np.testing.assert_allclose(T3, T, atol=1e-9)
    assert (stamp3, frame3, child) == (stamp_ns, "odom", "base_link")
    np.testing.assert_array_equal(np.asarray(odom.pose.covariance), pose_cov.reshape(-1))
    np.testing.assert_array_equal(np.asarray(odom.twist.covariance), cov[36:])
    lin, ang = odom.twist.twist.linear, odom.twist.twist.angular
    assert (lin.x, lin.y, lin.z, ang.x, ang.y, ang.z) == twist


def test_odometry_defaults_and_bad_shapes() -> None:
    odom = matrix_to_odometry(np.eye(4), stamp_ns=0, frame_id="odom", child_frame_id="base_link", types=ROSBAGS)
    assert not np.any(odom.pose.covariance) and odom.pose.covariance.shape == (36,)
    with pytest.raises(PoseConversionError, match="pose_covariance must have shape"):
        matrix_to_odometry(np.eye(4), stamp_ns=0, frame_id="o", child_frame_id="b", pose_covariance=np.eye(3))
    with pytest.raises(PoseConversionError, match="twist_linear must have shape"):
        matrix_to_odometry(np.eye(4), stamp_ns=0, frame_id="o", child_frame_id="b", twist_linear=[1.0, 2.0])


@flavour_param
@pytest.mark.parametrize(
    ("q", "match"),
    [
        ((0.0, 0.0, 0.0, 0.5), r"Pose\.orientation .* has norm 0\.5, not a unit quaternion"),
        ((0.0, 0.0, 0.0, 0.0), r"Pose\.orientation .* has norm 0,"),
        ((0.0, 0.0, 0.0, 1.01), r"has norm 1\.01"),
        ((0.0, float("nan"), 0.0, 1.0), r"Pose\.orientation=.* is not finite"),
    ],
)
def test_non_unit_quaternions_raise(flavour: str, q: tuple[float, ...], match: str) -> None:
    with pytest.raises(PoseConversionError, match=match):
        pose_to_matrix(_pose_msg(FLAVOURS[flavour], q))


def test_near_unit_quaternion_is_normalized_and_field_named_in_odometry() -> None:
    T = pose_to_matrix(_pose_msg(ROSBAGS, (0.0, 0.0, 0.0, 1.0005)))
    np.testing.assert_allclose(T, np.eye(4), atol=1e-12)
    odom = matrix_to_odometry(np.eye(4), stamp_ns=0, frame_id="odom", child_frame_id="base", types=ROSBAGS)
    odom.pose.pose.orientation.w = 2.0
    with pytest.raises(PoseConversionError, match=r"Odometry\.pose\.pose\.orientation"):
        odometry_to_matrix(odom)


@pytest.mark.parametrize(
    ("T", "match"),
    [
        (np.diag([2.0, 2.0, 2.0, 1.0]), "not a rotation"),
        (np.diag([1.0, 1.0, -1.0, 1.0]), "not a rotation"),  # a reflection
        (np.array([[1, 0.1, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float), "not a rotation"),
        (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]], dtype=float), "last row"),
        (np.eye(3), r"shape \(4, 4\)"),
        (np.full((4, 4), np.nan), "non-finite"),
    ],
)
def test_matrix_to_pose_rejects_non_rigid_transforms(T: np.ndarray, match: str) -> None:
    with pytest.raises(PoseConversionError, match=match):
        matrix_to_pose(T)


# ------------------------------------------------------------------------------------------------------ cameras


cameras = st.builds(
    PinholeCamera,
    width=st.integers(1, 4096),
    height=st.integers(1, 4096),
    fx=st.floats(1.0, 5000.0),
    fy=st.floats(1.0, 5000.0),
    cx=st.floats(-100.0, 4000.0),
    cy=st.floats(-100.0, 4000.0),
)


@flavour_param
@PROPERTY
@given(camera=cameras, stamp_ns=stamps)
def test_camera_info_round_trip(flavour: str, camera: PinholeCamera, stamp_ns: int) -> None:
    msg = camera_info_from_camera(camera, stamp_ns=stamp_ns, frame_id="cam_optical", types=FLAVOURS[flavour])
    assert (msg.width, msg.height, msg.distortion_model) == (camera.width, camera.height, "plumb_bob")
    np.testing.assert_array_equal(np.asarray(msg.k).reshape(3, 3), camera.K)
    np.testing.assert_array_equal(np.asarray(msg.p).reshape(3, 4), np.hstack([camera.K, np.zeros((3, 1))]))
    np.testing.assert_array_equal(np.asarray(msg.r).reshape(3, 3), np.eye(3))
    assert list(msg.d) == [0.0] * 5
    assert stamp_to_ns(msg.header.stamp) == stamp_ns and msg.header.frame_id == "cam_optical"
    assert camera_from_camera_info(msg) == camera


def test_camera_info_through_cdr() -> None:
    camera = PinholeCamera(640, 480, 525.0, 524.0, 319.5, 239.5)
    bag_msg = camera_info_from_camera(camera, types=ROSBAGS)
    ros_msg = deserialize_message(
        bytes(TYPESTORE.serialize_cdr(bag_msg, "sensor_msgs/msg/CameraInfo")), sensor_msgs.msg.CameraInfo
    )
    assert camera_from_camera_info(ros_msg) == camera
    back = TYPESTORE.deserialize_cdr(serialize_message(camera_info_from_camera(camera)), "sensor_msgs/msg/CameraInfo")
    assert camera_from_camera_info(back) == camera


@pytest.mark.parametrize("model", ["plumb_bob", "rational_polynomial", "equidistant", ""])
@pytest.mark.parametrize("n_coefficients", [0, 4, 5, 8])
def test_zero_distortion_is_accepted(model: str, n_coefficients: int) -> None:
    msg = camera_info_from_camera(PinholeCamera(64, 48, 50.0, 50.0, 32.0, 24.0), types=ROSBAGS)
    msg.distortion_model, msg.d = model, np.zeros(n_coefficients)
    assert camera_from_camera_info(msg).fx == 50.0


@flavour_param
@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"d": [-0.28, 0.07, 0.0, 0.0, 0.0]},
         r"model='plumb_bob' with D=\[-0\.28, 0\.07.*rectified images.*undistort true"),
        ({"distortion_model": "fisheye"}, r"distortion_model='fisheye' .* not supported"),
        ({"distortion_model": "equidistant", "d": [0.0, 0.0, 0.0, 0.1]}, r"'equidistant' .* rectified"),
        ({"d": [0.0, float("nan"), 0.0, 0.0, 0.0]}, r"D=\[0\.0, nan"),
        ({"width": 0}, r"CameraInfo\.width=0 and height=48 must be > 0"),
        ({"k": [50.0, 1.0, 32.0, 0.0, 50.0, 24.0, 0.0, 0.0, 1.0]}, r"CameraInfo\.k: K must be"),
        ({"k": [0.0] * 9}, r"CameraInfo\.k"),
        ({"p": [50.0, 0.0, 32.0, 0.0, 0.0, 50.0, 24.0, 0.0, 0.0, 0.0, 0.0, 0.0]}, r"CameraInfo\.p=.* not a projection"),
        ({"binning_x": 2}, r"CameraInfo\.binning_x=2"),
    ],
)
def test_unsupported_camera_infos_raise(flavour: str, change: dict[str, Any], match: str) -> None:
    types = FLAVOURS[flavour]
    msg = camera_info_from_camera(PinholeCamera(64, 48, 50.0, 50.0, 32.0, 24.0), types=types)
    for key, value in change.items():
        if key in ("k", "p"):
            value = types.float64_array(value)
        elif key == "d":
            value = types.float64_sequence(value)
        setattr(msg, key, value)
    with pytest.raises(CameraInfoError, match=match) as info:
        camera_from_camera_info(msg)
    assert isinstance(info.value, ValueError) and isinstance(info.value, LightfastError)


@flavour_param
@pytest.mark.parametrize(("model", "d"), [("plumb_bob", [-0.28, 0.07, 0.001, 0.0, 0.0]),
                                          ("plumb_bob", [-0.1] + [0.0] * 3),
                                          ("rational_polynomial", [0.4, -2.5, 0.0, 0.0, 1.4, 0.3, -2.3, 1.3]),
                                          ("equidistant", [0.05, -0.01, 0.0, 0.0])])
def test_a_distorted_camera_converts_with_its_undistorter_when_the_node_undistorts(flavour: str, model: str,
                                                                                   d: list[float]) -> None:
    types = FLAVOURS[flavour]
    camera = PinholeCamera(64, 48, 50.0, 51.0, 32.0, 24.0)
    msg = camera_info_from_camera(camera, types=types)
    msg.distortion_model, msg.d = model, types.float64_sequence(d)
    with pytest.raises(CameraInfoError, match="rectified images"):
        camera_from_camera_info(msg)
    assert camera_from_camera_info(msg, undistort=True) == camera
    u = undistorter_from_camera_info(msg)
    assert u is not None and (u.camera, u.model, u.coefficients) == (camera, model, tuple(d))
    reader = CameraInfoReader(undistort=True)
    assert reader(msg) == camera and reader.undistorter is not None and reader.undistorter.coefficients == tuple(d)
    msg.d = types.float64_sequence([0.0] * len(d))  # the driver sends an undistorted camera from now on
    assert reader(msg) == camera and reader.undistorter is None
    assert undistorter_from_camera_info(msg) is None


@pytest.mark.parametrize(("model", "d", "match"), [("plumb_bob", [0.1, 0.0, 0.0], r"CameraInfo\.d: .*4 or 5"),
                                                   ("fisheye", [0.1] * 4, "undistorts plumb_bob, rational_polynomial")])
def test_a_lens_it_cannot_undistort_is_refused_in_one_line(model: str, d: list[float], match: str) -> None:
    msg = camera_info_from_camera(PinholeCamera(64, 48, 50.0, 50.0, 32.0, 24.0), types=ROSBAGS)
    msg.distortion_model, msg.d = model, np.asarray(d)
    reader = CameraInfoReader(undistort=True)
    with pytest.raises(CameraInfoError, match=match):
        reader(msg)
    assert reader.undistorter is None


def test_zero_projection_matrix_is_allowed() -> None:
    msg = camera_info_from_camera(PinholeCamera(64, 48, 50.0, 50.0, 32.0, 24.0), types=ROSBAGS)
    msg.p = np.zeros(12)
    assert camera_from_camera_info(msg).cx == 32.0


# -------------------------------------------------------------------------------------------------- packaging


def test_conversions_do_not_import_rclpy() -> None:
    code = (
        "import sys, numpy as np\n"
        "from lightfast.ros.convert import numpy_to_image, image_to_numpy, matrix_to_odometry\n"
        "from lightfast.ros.msgtypes import RCLPY\n"
        "assert 'rclpy' not in sys.modules, 'import'\n"
        "image_to_numpy(numpy_to_image(np.zeros((2, 2, 3), np.uint8), 'rgb8', types=RCLPY))\n"
        "matrix_to_odometry(np.eye(4), stamp_ns=1, frame_id='a', child_frame_id='b', types=RCLPY)\n"
        "assert 'rclpy' not in sys.modules, 'use'\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr


def test_rclpy_flavour_copies_pixels_once() -> None:
    data = RCLPY.uint8_array(np.arange(12, dtype=np.uint8))
    assert isinstance(data, array.array) and data.tolist() == list(range(12))
    msg = RCLPY.new("sensor_msgs/msg/Image", height=3, width=4, encoding="mono8", step=4, data=data)
    assert msg.data is data, "the setter must keep the array.array, not copy it again"
    covariance = RCLPY.float64_array(np.eye(6))
    assert RCLPY.new("geometry_msgs/msg/PoseWithCovariance", covariance=covariance).covariance is covariance


def test_rclpy_messages_keep_default_field_checking() -> None:
    msg = numpy_to_image(np.zeros((2, 2), np.uint8), "mono8", types=RCLPY)
    assert msg._check_fields == sensor_msgs.msg.Image()._check_fields


def test_camera_info_reader_keeps_the_last_camera_until_the_message_changes() -> None:
    read = CameraInfoReader()
    cam = PinholeCamera(64, 48, 50.0, 50.0, 32.0, 24.0)
    first = read(camera_info_from_camera(cam))
    assert first == cam and read(camera_info_from_camera(cam)) is first  # same contents: not converted again
    bad = camera_info_from_camera(cam)
    bad.d = array.array("d", [-0.28, 0.07, 0.0, 0.0, 0.0])
    with pytest.raises(CameraInfoError):
        read(bad)
    with pytest.raises(CameraInfoError):  # a bad message is never remembered as good
        read(bad)
    other = PinholeCamera(64, 48, 51.0, 50.0, 32.0, 24.0)
    assert read(camera_info_from_camera(other)) == other
    assert read(camera_info_from_camera(cam)) == cam
