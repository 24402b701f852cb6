"""Conversions between ROS 2 messages and NumPy arrays, for rclpy messages and rosbags messages alike.

Reading is duck-typed: any object with the message's field names works (rclpy messages, rosbags dataclasses,
test doubles). Building takes the keyword ``types`` (:mod:`lightfast.ros.msgtypes`): :data:`~.msgtypes.RCLPY`
(default) or ``rosbags_types()``. Nothing here imports rclpy.

Conventions

* Stamps are integer nanoseconds (``stamp_ns``), ``sec * 10**9 + nanosec`` of ``builtin_interfaces/Time``.
* Images (``sensor_msgs/Image``) become arrays ``(H, W)`` for one channel and ``(H, W, C)`` otherwise, rows top to
  bottom, in the message's channel order (``rgb8`` is RGB, ``bgr8`` BGR; nothing is reordered). Depth images:
  ``16UC1`` is ``uint16`` in millimetres with 0 meaning invalid (no return); ``32FC1`` is ``float32`` in metres
  with NaN (or 0) meaning invalid. No unit conversion happens here. Reading is zero-copy (the array is a view
  of the message buffer, honouring ``step`` row padding) whenever the data is in native byte order; big-endian
  data is byte-swapped into a native copy. Writing emits little-endian (``is_bigendian=0``), unpadded rows.
* Point clouds (``sensor_msgs/PointCloud2``) become 1-D structured arrays with one named field per
  ``PointField`` (``count > 1`` gives a subarray field) and ``itemsize == point_step``. Organized clouds
  (``height > 1``) are flattened row by row, so point ``(row, col)`` is element ``row * width + col``; pass
  ``height=msg.height`` back to :func:`numpy_to_pointcloud2` to rebuild the organisation. Coordinates are in the
  cloud's ``header.frame_id``, in metres by ROS convention.
* Poses are 4×4 homogeneous transforms ``T_frame_child`` in float64 (metres), mapping points of the child frame
  into the parent frame: for ``PoseStamped`` the parent is ``header.frame_id``; for ``Odometry`` the pose maps
  ``child_frame_id`` into ``header.frame_id`` (the twist is expressed in ``child_frame_id``). Quaternions are
  ``(x, y, z, w)``; written quaternions have ``w >= 0``.
* Cameras: :class:`lightfast.camera.PinholeCamera` models rectified images only (REP-103 optical frame). A
  ``CameraInfo`` converts only if its distortion coefficients are all zero; the intrinsics come from ``K``.
"""
from __future__ import annotations

import itertools
import operator
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from lightfast.camera import PinholeCamera
from lightfast.errors import CameraModelError
from lightfast.ros.errors import (
    CameraInfoError,
    ConversionError,
    ImageConversionError,
    PointCloudConversionError,
    PoseConversionError,
)
from lightfast.ros.msgtypes import RCLPY, MessageTypes

__all__ = [
    "COLOR_ENCODINGS",
    "IMAGE_ENCODINGS",
    "QUATERNION_NORM_TOLERANCE",
    "ROTATION_TOLERANCE",
    "SUPPORTED_DISTORTION_MODELS",
    "CameraInfoReader",
    "ImageEncoding",
    "ImageFields",
    "PointCloud2Fields",
    "PointFieldSpec",
    "camera_from_camera_info",
    "camera_info_from_camera",
    "image_fields",
    "image_to_numpy",
    "image_to_rgb",
    "make_header",
    "matrix_to_odometry",
    "matrix_to_pose",
    "matrix_to_pose_stamped",
    "ns_to_stamp",
    "numpy_to_image",
    "numpy_to_pointcloud2",
    "odometry_to_matrix",
    "pointcloud2_fields",
    "pointcloud2_to_numpy",
    "pose_stamped_to_matrix",
    "pose_to_matrix",
    "pose_with_covariance_to_matrix",
    "stamp_to_ns",
    "xyz_to_pointcloud2",
]

_NS_PER_S = 1_000_000_000
_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1


def _byte_buffer(data: Any) -> NDArray[np.uint8]:
    """The bytes of a ``uint8[]`` field as a 1-D uint8 array, a view whenever the field exposes a buffer."""
    if isinstance(data, np.ndarray):
        if data.dtype.itemsize == 1 and data.ndim == 1 and data.flags.c_contiguous:
            return data.view(np.uint8)
        return np.ascontiguousarray(data, dtype=np.uint8).reshape(-1)
    try:
        return np.frombuffer(data, dtype=np.uint8)  # array.array('B') (rclpy), bytes, memoryview
    except (TypeError, ValueError):
        return np.asarray(data, dtype=np.uint8).reshape(-1)  # a list of ints


# ------------------------------------------------------------------------------------------------------ stamps


def stamp_to_ns(stamp: Any) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time`` (anything with ``sec`` and ``nanosec``)."""
    sec, nanosec = int(stamp.sec), int(stamp.nanosec)
    if not 0 <= nanosec < _NS_PER_S:
        raise ConversionError(f"Time.nanosec={nanosec} must be in [0, 1e9)")
    return sec * _NS_PER_S + nanosec


def ns_to_stamp(ns: int, *, types: MessageTypes = RCLPY) -> Any:
    """A ``builtin_interfaces/Time`` for integer nanoseconds ``ns`` (negative values give negative ``sec``)."""
    try:
        ns = operator.index(ns)
    except TypeError:
        raise TypeError(f"stamp must be integer nanoseconds, got {type(ns).__name__} {ns!r}") from None
    sec, nanosec = divmod(ns, _NS_PER_S)
    if not _INT32_MIN <= sec <= _INT32_MAX:
        raise ConversionError(f"stamp {ns} ns is outside builtin_interfaces/Time (int32 seconds)")
    return types.new("builtin_interfaces/msg/Time", sec=int(sec), nanosec=int(nanosec))


def make_header(stamp_ns: int, frame_id: str, *, types: MessageTypes = RCLPY) -> Any:
    """A ``std_msgs/Header`` with stamp ``stamp_ns`` (integer nanoseconds) and ``frame_id``."""
    if not isinstance(frame_id, str):
        raise TypeError(f"frame_id must be a str, got {type(frame_id).__name__}")
    return types.new("std_msgs/msg/Header", stamp=ns_to_stamp(stamp_ns, types=types), frame_id=frame_id)


def _header_of(msg: Any) -> tuple[int, str]:
    return stamp_to_ns(msg.header.stamp), str(msg.header.frame_id)


# ------------------------------------------------------------------------------------------------------ images


class ImageEncoding(NamedTuple):
    """Element dtype (native byte order) and channel count of an ``Image.encoding``."""

    dtype: np.dtype
    channels: int


IMAGE_ENCODINGS: Mapping[str, ImageEncoding] = MappingProxyType(
    {
        "rgb8": ImageEncoding(np.dtype(np.uint8), 3),
        "bgr8": ImageEncoding(np.dtype(np.uint8), 3),
        "rgba8": ImageEncoding(np.dtype(np.uint8), 4),
        "bgra8": ImageEncoding(np.dtype(np.uint8), 4),
        "mono8": ImageEncoding(np.dtype(np.uint8), 1),
        "8UC1": ImageEncoding(np.dtype(np.uint8), 1),
        "8UC3": ImageEncoding(np.dtype(np.uint8), 3),
        "mono16": ImageEncoding(np.dtype(np.uint16), 1),
        "16UC1": ImageEncoding(np.dtype(np.uint16), 1),  # depth in millimetres, 0 = invalid
        "32FC1": ImageEncoding(np.dtype(np.float32), 1),  # depth in metres, NaN (or 0) = invalid
    }
)
"""Supported ``Image.encoding`` values: element dtype (native order) and number of channels."""


class ImageFields(NamedTuple):
    """The fields of a ``sensor_msgs/Image`` (without header) for an array, in any message flavour."""

    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: NDArray[np.uint8]
    """Contiguous 1-D uint8 bytes, a view of the input array when it was contiguous little-endian already."""


def _image_encoding(encoding: Any, what: str) -> ImageEncoding:
    spec = IMAGE_ENCODINGS.get(encoding) if isinstance(encoding, str) else None
    if spec is None:
        raise ImageConversionError(f"{what}={encoding!r} is not supported (supported: {', '.join(IMAGE_ENCODINGS)})")
    return spec


def image_to_numpy(msg: Any) -> NDArray[Any]:
    """The pixels of a ``sensor_msgs/Image`` as ``(H, W)`` (one channel) or ``(H, W, C)`` array.

    The dtype follows the encoding (:data:`IMAGE_ENCODINGS`). For native-endian data the result is a view of
    ``msg.data`` (no copy; writable exactly when the message buffer is), rows ``step`` bytes apart; big-endian
    multi-byte data is byte-swapped into a new native array. Raises :class:`ImageConversionError` for unknown
    encodings, bad sizes, ``step`` or ``is_bigendian`` values and data of the wrong length.
    """
    spec = _image_encoding(msg.encoding, "Image.encoding")
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    for name, value in (("height", height), ("width", width)):
        if value <= 0:
            raise ImageConversionError(f"Image.{name}={value} must be > 0")
    is_bigendian = msg.is_bigendian
    if is_bigendian not in (0, 1):
        raise ImageConversionError(f"Image.is_bigendian={is_bigendian!r} must be 0 or 1")
    itemsize = spec.dtype.itemsize
    pixel_bytes = itemsize * spec.channels
    row_bytes = width * pixel_bytes
    if step < row_bytes:
        raise ImageConversionError(f"Image.step={step} is smaller than width*bytes_per_pixel={row_bytes}")
    buf = _byte_buffer(msg.data)
    if buf.size != step * height:
        raise ImageConversionError(f"len(Image.data)={buf.size} does not equal step*height={step * height}")
    dtype = spec.dtype.newbyteorder(">" if is_bigendian else "<")
    if spec.channels == 1:
        shape: tuple[int, ...] = (height, width)
        strides: tuple[int, ...] = (step, itemsize)
    else:
        shape, strides = (height, width, spec.channels), (step, pixel_bytes, itemsize)
    out = np.ndarray(shape, dtype=dtype, buffer=buf, strides=strides)
    if not dtype.isnative:
        out = out.astype(dtype.newbyteorder("="))
    return out


#: Colour encodings real camera drivers send, and the channel order that makes each RGB.
_TO_RGB: Mapping[str, slice | list[int]] = MappingProxyType(
    {"rgb8": slice(None), "bgr8": [2, 1, 0], "rgba8": slice(0, 3), "bgra8": [2, 1, 0]}
)
COLOR_ENCODINGS = tuple(_TO_RGB)
"""Colour encodings :func:`image_to_rgb` takes."""


def image_to_rgb(msg: Any, *, allow_mono: bool = False) -> NDArray[np.uint8]:
    """The pixels of a colour ``sensor_msgs/Image`` as ``(H, W, 3)`` RGB uint8, whatever channel order the driver
    sent (:data:`COLOR_ENCODINGS`); with ``allow_mono`` a ``mono8`` image comes as ``(H, W)`` grey. A view of the
    message for ``rgb8`` (and ``mono8``), a copy otherwise. Raises :class:`ImageConversionError` naming the
    encoding for anything else."""
    encoding = msg.encoding
    if allow_mono and encoding == "mono8":
        return image_to_numpy(msg)
    order = _TO_RGB.get(encoding) if isinstance(encoding, str) else None
    if order is None:
        accepted = ", ".join(COLOR_ENCODINGS + (("mono8",) if allow_mono else ()))
        raise ImageConversionError(f"colour image encoding {encoding!r} is not supported (accepted: {accepted})")
    pixels = image_to_numpy(msg)
    if encoding == "rgb8":
        return pixels
    return np.ascontiguousarray(pixels[:, :, order])


def image_fields(array: ArrayLike, encoding: str) -> ImageFields:
    """Validate ``array`` against ``encoding`` and return the ``Image`` fields (little-endian, unpadded rows).

    ``array`` must have the encoding's dtype (any byte order) and shape ``(H, W, C)`` with the encoding's
    channel count ``C``; one-channel encodings take ``(H, W)`` or ``(H, W, 1)``. ``H`` and ``W`` must be > 0.
    """
    spec = _image_encoding(encoding, "encoding")
    a = np.asarray(array)
    if a.dtype.fields is not None or a.dtype.newbyteorder("=") != spec.dtype:
        raise ImageConversionError(f"encoding {encoding!r} needs dtype {spec.dtype}, got {a.dtype}")
    if spec.channels == 1 and a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    expected = "(H, W)" if spec.channels == 1 else f"(H, W, {spec.channels})"
    if a.ndim != (2 if spec.channels == 1 else 3) or (spec.channels > 1 and a.shape[2] != spec.channels):
        raise ImageConversionError(f"encoding {encoding!r} needs an array of shape {expected}, got {a.shape}")
    height, width = a.shape[:2]
    if height <= 0 or width <= 0:
        raise ImageConversionError(f"image array of shape {a.shape} is empty; height and width must be > 0")
    a = np.ascontiguousarray(a, dtype=spec.dtype.newbyteorder("<"))
    step = width * spec.channels * spec.dtype.itemsize
    return ImageFields(int(height), int(width), encoding, 0, int(step), a.reshape(-1).view(np.uint8))


def numpy_to_image(
    array: ArrayLike, encoding: str, *, stamp_ns: int = 0, frame_id: str = "", types: MessageTypes = RCLPY
) -> Any:
    """A ``sensor_msgs/Image`` holding ``array`` (see :func:`image_fields` for the accepted arrays).

    The rclpy flavour copies the pixels once; the rosbags flavour's ``data`` may be a view of ``array``.
    """
    f = image_fields(array, encoding)
    return types.new(
        "sensor_msgs/msg/Image",
        header=make_header(stamp_ns, frame_id, types=types),
        height=f.height,
        width=f.width,
        encoding=f.encoding,
        is_bigendian=f.is_bigendian,
        step=f.step,
        data=types.uint8_array(f.data),
    )


# ------------------------------------------------------------------------------------------------ point clouds

_POINTFIELD_DTYPES: Mapping[int, np.dtype] = MappingProxyType(
    {
        1: np.dtype(np.int8),  # PointField.INT8
        2: np.dtype(np.uint8),  # UINT8
        3: np.dtype(np.int16),  # INT16
        4: np.dtype(np.uint16),  # UINT16
        5: np.dtype(np.int32),  # INT32
        6: np.dtype(np.uint32),  # UINT32
        7: np.dtype(np.float32),  # FLOAT32
        8: np.dtype(np.float64),  # FLOAT64
    }
)
_DTYPE_POINTFIELDS: Mapping[np.dtype, int] = MappingProxyType({dt: code for code, dt in _POINTFIELD_DTYPES.items()})


class PointFieldSpec(NamedTuple):
    """One ``sensor_msgs/PointField``, independent of the message flavour."""

    name: str
    offset: int
    datatype: int
    count: int = 1  # type: ignore[assignment]  # the PointField name; shadows tuple.count on purpose


class PointCloud2Fields(NamedTuple):
    """The fields of a ``sensor_msgs/PointCloud2`` (without header) for a structured array."""

    height: int
    width: int
    fields: tuple[PointFieldSpec, ...]
    is_bigendian: bool
    point_step: int
    row_step: int
    data: NDArray[np.uint8]
    """Contiguous 1-D uint8 bytes, a view of the input array when it was contiguous little-endian already."""
    is_dense: bool


def _cloud_dtype(fields: Iterable[Any], point_step: int, *, bigendian: bool) -> np.dtype:
    """The structured dtype of ``PointField`` s (duck-typed) with ``itemsize == point_step``, validated."""
    if point_step <= 0:
        raise PointCloudConversionError(f"PointCloud2.point_step={point_step} must be > 0")
    order: Literal[">", "<"] = ">" if bigendian else "<"
    names: list[str] = []
    formats: list[Any] = []
    offsets: list[int] = []
    extents: list[tuple[int, int, str]] = []
    for i, field in enumerate(fields):
        name = field.name
        what = f"PointCloud2.fields[{i}] (name={name!r})"
        if not isinstance(name, str) or not name:
            raise PointCloudConversionError(f"{what}: name must be a non-empty string")
        if name in names:
            raise PointCloudConversionError(f"{what}: duplicate field name {name!r}")
        datatype, offset, count = int(field.datatype), int(field.offset), int(field.count)
        base = _POINTFIELD_DTYPES.get(datatype)
        if base is None:
            raise PointCloudConversionError(
                f"{what}: datatype={datatype} is not a PointField datatype (1=INT8 … 8=FLOAT64)"
            )
        if count < 1:
            raise PointCloudConversionError(f"{what}: count={count} must be >= 1")
        size = base.itemsize * count
        if offset < 0 or offset + size > point_step:
            raise PointCloudConversionError(
                f"{what}: offset={offset} + {size} bytes lies outside point_step={point_step}"
            )
        names.append(name)
        base = base.newbyteorder(order)
        formats.append(base if count == 1 else (base, (count,)))
        offsets.append(offset)
        extents.append((offset, offset + size, name))
    if not names:
        raise PointCloudConversionError("PointCloud2.fields is empty")
    extents.sort()
    for (_, end, name), (start, _, next_name) in itertools.pairwise(extents):
        if start < end:
            raise PointCloudConversionError(
                f"PointCloud2.fields {name!r} and {next_name!r} overlap ({name!r} ends at byte {end}, "
                f"{next_name!r} starts at {start})"
            )
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step})


def _native(dtype: np.dtype) -> np.dtype:
    names = list(dtype.names or ())
    fields: Mapping[str, Any] = dtype.fields or {}  # None only for a dtype without names: then no loop runs
    formats = []
    for name in names:
        fdt = fields[name][0]
        base = fdt.base.newbyteorder("=")
        formats.append(base if not fdt.shape else (base, fdt.shape))
    offsets = [fields[name][1] for name in names]
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": dtype.itemsize})


def pointcloud2_to_numpy(msg: Any) -> NDArray[np.void]:
    """The points of a ``sensor_msgs/PointCloud2`` as a structured array of shape ``(height * width,)``.

    The dtype has one field per ``PointField`` at its offset (``count > 1`` → subarray ``(count,)``) and
    ``itemsize == point_step`` (padding bytes included). Organized clouds keep their row-major order. The result
    is a view of ``msg.data`` when rows are unpadded (``row_step == width * point_step``) and the data is in
    native byte order; otherwise a native-order copy. Raises :class:`PointCloudConversionError` for unknown
    datatypes, overlapping or out-of-bounds fields, duplicate names and inconsistent sizes.
    """
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    is_bigendian = msg.is_bigendian
    if is_bigendian not in (0, 1):
        raise PointCloudConversionError(f"PointCloud2.is_bigendian={is_bigendian!r} must be 0 or 1 (a bool)")
    for name, value in (("height", height), ("width", width)):
        if value < 0:
            raise PointCloudConversionError(f"PointCloud2.{name}={value} must be >= 0")
    dtype = _cloud_dtype(msg.fields, point_step, bigendian=bool(is_bigendian))
    if row_step < width * point_step:
        raise PointCloudConversionError(
            f"PointCloud2.row_step={row_step} is smaller than width*point_step={width * point_step}"
        )
    buf = _byte_buffer(msg.data)
    if buf.size != row_step * height:
        raise PointCloudConversionError(
            f"len(PointCloud2.data)={buf.size} does not equal row_step*height={row_step * height}"
        )
    native = _native(dtype)
    count = height * width
    if count == 0:
        return np.empty(0, dtype=native)
    if row_step == width * point_step:
        out = np.ndarray((count,), dtype=dtype, buffer=buf)
    else:
        out = np.ndarray((height, width), dtype=dtype, buffer=buf, strides=(row_step, point_step)).reshape(-1)
    # dtype.isnative is not enough: NumPy reports subarray fields of the other byte order as native.
    assert dtype.fields is not None and dtype.names is not None  # _cloud_dtype builds a structured dtype
    if any(not dtype.fields[name][0].base.isnative for name in dtype.names):
        out = out.astype(native)
    return out


def pointcloud2_fields(
    structured_array: ArrayLike, *, height: int = 1, is_dense: bool | None = None
) -> PointCloud2Fields:
    """Validate a structured point array and return the ``PointCloud2`` fields (little-endian, unpadded rows).

    ``structured_array`` is 1-D ``(N,)`` with ``N`` divisible by ``height`` (organized clouds in row-major
    order), or 2-D ``(height, width)`` (then ``height`` must be 1 or ``shape[0]``). Each field's base type must
    be one of the ``PointField`` types (int8/16/32, uint8/16/32, float32/64, any byte order), optionally with a
    1-D subarray (``count``). ``point_step`` is the dtype's ``itemsize``. ``is_dense`` defaults to "every
    floating-point value is finite".
    """
    a = np.asarray(structured_array)
    names = a.dtype.names
    if not names:
        raise PointCloudConversionError(f"point array needs a structured dtype with named fields, got {a.dtype}")
    if a.ndim == 2:
        if height not in (1, a.shape[0]):
            raise PointCloudConversionError(f"height={height} contradicts the point array's shape {a.shape}")
        height = a.shape[0]
    elif a.ndim != 1:
        raise PointCloudConversionError(f"point array must be 1-D (N,) or 2-D (height, width), got {a.shape}")
    if height < 1 or a.size % height:
        raise PointCloudConversionError(f"height={height} must be >= 1 and divide the number of points {a.size}")
    specs: list[PointFieldSpec] = []
    formats: list[Any] = []
    offsets: list[int] = []
    fields = a.dtype.fields
    assert fields is not None  # a dtype with names has fields
    for name in names:
        fdt, offset = fields[name][:2]
        base = fdt.base
        datatype = _DTYPE_POINTFIELDS.get(base.newbyteorder("=")) if base.fields is None else None
        if datatype is None or len(fdt.shape) > 1:
            raise PointCloudConversionError(
                f"point field {name!r} has dtype {fdt}; PointCloud2 supports (u)int8/16/32 and float32/64, "
                "optionally with a 1-D count"
            )
        count = fdt.shape[0] if fdt.shape else 1
        specs.append(PointFieldSpec(name, int(offset), datatype, int(count)))
        little = base.newbyteorder("<")
        formats.append(little if not fdt.shape else (little, fdt.shape))
        offsets.append(int(offset))
    little_dtype = np.dtype(
        {"names": list(names), "formats": formats, "offsets": offsets, "itemsize": a.dtype.itemsize}
    )
    flat = np.ascontiguousarray(a.reshape(-1), dtype=little_dtype)
    if is_dense is None:
        little_fields = little_dtype.fields
        assert little_fields is not None  # built from names above
        is_dense = all(
            bool(np.isfinite(flat[name]).all()) for name in names if little_fields[name][0].base.kind == "f"
        )
    width = a.size // height
    point_step = a.dtype.itemsize
    return PointCloud2Fields(
        height=int(height),
        width=int(width),
        fields=tuple(specs),
        is_bigendian=False,
        point_step=int(point_step),
        row_step=int(width * point_step),
        data=flat.view(np.uint8).reshape(-1),
        is_dense=bool(is_dense),
    )


def numpy_to_pointcloud2(
    structured_array: ArrayLike,
    *,
    stamp_ns: int = 0,
    frame_id: str = "",
    types: MessageTypes = RCLPY,
    height: int = 1,
    is_dense: bool | None = None,
) -> Any:
    """A ``sensor_msgs/PointCloud2`` holding a structured point array (see :func:`pointcloud2_fields`)."""
    f = pointcloud2_fields(structured_array, height=height, is_dense=is_dense)
    fields = [
        types.new("sensor_msgs/msg/PointField", name=s.name, offset=s.offset, datatype=s.datatype, count=s.count)
        for s in f.fields
    ]
    return types.new(
        "sensor_msgs/msg/PointCloud2",
        header=make_header(stamp_ns, frame_id, types=types),
        height=f.height,
        width=f.width,
        fields=fields,
        is_bigendian=f.is_bigendian,
        point_step=f.point_step,
        row_step=f.row_step,
        data=types.uint8_array(f.data),
        is_dense=f.is_dense,
    )


def xyz_to_pointcloud2(
    xyz: ArrayLike,
    *,
    stamp_ns: int = 0,
    frame_id: str = "",
    types: MessageTypes = RCLPY,
    extra_fields: Mapping[str, ArrayLike] | None = None,
) -> Any:
    """An unorganized ``PointCloud2`` with float32 fields ``x, y, z`` (metres) from an ``(N, 3)`` array.

    ``extra_fields`` maps further field names to arrays ``(N,)`` or ``(N, count)`` of a ``PointField`` type,
    e.g. ``{"intensity": np.float32 array}``; they follow ``x, y, z`` in the point layout.
    """
    points = np.asarray(xyz)
    if points.ndim != 2 or points.shape[1] != 3:
        raise PointCloudConversionError(f"xyz must have shape (N, 3), got {points.shape}")
    extras = {name: np.asarray(values) for name, values in (extra_fields or {}).items()}
    layout: list[tuple[Any, ...]] = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    for name, values in extras.items():
        if name in ("x", "y", "z"):
            raise PointCloudConversionError(f"extra field {name!r} clashes with the x, y, z fields")
        if values.ndim not in (1, 2) or values.shape[0] != points.shape[0]:
            raise PointCloudConversionError(
                f"extra field {name!r} must have shape (N,) or (N, count) with N={points.shape[0]}, got {values.shape}"
            )
        layout.append((name, values.dtype, values.shape[1:]))
    try:
        cloud = np.empty(points.shape[0], dtype=np.dtype(layout))
    except (TypeError, ValueError) as exc:
        raise PointCloudConversionError(f"invalid extra fields: {exc}") from exc
    for axis, name in enumerate("xyz"):
        cloud[name] = points[:, axis]
    for name, values in extras.items():
        cloud[name] = values
    return numpy_to_pointcloud2(cloud, stamp_ns=stamp_ns, frame_id=frame_id, types=types)


# ------------------------------------------------------------------------------------------------------- poses

QUATERNION_NORM_TOLERANCE = 1e-3
"""Quaternions with ``|norm - 1| <= QUATERNION_NORM_TOLERANCE`` are normalized; others are rejected."""

ROTATION_TOLERANCE = 1e-5
"""Largest ``|RᵀR - I|`` element (and ``|det R - 1|``) accepted for the rotation part of a transform."""


def _vector3(v: Any) -> NDArray[np.float64]:
    return np.array([float(v.x), float(v.y), float(v.z)])


def _pose_to_matrix(pose: Any, what: str) -> NDArray[np.float64]:
    p = _vector3(pose.position)
    o = pose.orientation
    q = np.array([float(o.x), float(o.y), float(o.z), float(o.w)])
    if not np.all(np.isfinite(p)):
        raise PoseConversionError(f"{what}.position={p.tolist()} is not finite")
    if not np.all(np.isfinite(q)):
        raise PoseConversionError(f"{what}.orientation={q.tolist()} is not finite")
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise PoseConversionError(
            f"{what}.orientation (x, y, z, w)={q.tolist()} has norm {norm:.6g}, not a unit quaternion "
            f"(tolerance {QUATERNION_NORM_TOLERANCE})"
        )
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(q / norm).as_matrix()
    T[:3, 3] = p
    return T


def pose_to_matrix(pose: Any) -> NDArray[np.float64]:
    """The 4×4 transform of a ``geometry_msgs/Pose`` (metres). Near-unit quaternions are normalized."""
    return _pose_to_matrix(pose, "Pose")


def _split_transform(T: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    M = np.asarray(T, dtype=np.float64)
    if M.shape != (4, 4):
        raise PoseConversionError(f"transform must have shape (4, 4), got {M.shape}")
    if not np.all(np.isfinite(M)):
        raise PoseConversionError("transform has non-finite entries")
    if np.max(np.abs(M[3] - [0.0, 0.0, 0.0, 1.0])) > ROTATION_TOLERANCE:
        raise PoseConversionError(f"transform's last row must be [0, 0, 0, 1], got {M[3].tolist()}")
    R = M[:3, :3]
    orthogonality = float(np.max(np.abs(R.T @ R - np.eye(3))))
    det = float(np.linalg.det(R))
    if orthogonality > ROTATION_TOLERANCE or abs(det - 1.0) > ROTATION_TOLERANCE:
        raise PoseConversionError(
            f"transform's rotation part is not a rotation: max |RᵀR - I| = {orthogonality:.3g}, det = {det:.6g} "
            f"(tolerance {ROTATION_TOLERANCE})"
        )
    return R, M[:3, 3]


def matrix_to_pose(T: ArrayLike, *, types: MessageTypes = RCLPY) -> Any:
    """A ``geometry_msgs/Pose`` of a 4×4 rigid transform (quaternion with ``w >= 0``).

    Raises :class:`PoseConversionError` unless the rotation part is a rotation within :data:`ROTATION_TOLERANCE`.
    """
    R, t = _split_transform(T)
    x, y, z, w = (float(c) for c in Rotation.from_matrix(R).as_quat(canonical=True))
    return types.new(
        "geometry_msgs/msg/Pose",
        position=types.new("geometry_msgs/msg/Point", x=float(t[0]), y=float(t[1]), z=float(t[2])),
        orientation=types.new("geometry_msgs/msg/Quaternion", x=x, y=y, z=z, w=w),
    )


def pose_stamped_to_matrix(msg: Any) -> tuple[NDArray[np.float64], int, str]:
    """``(T_frame_pose, stamp_ns, frame_id)`` of a ``geometry_msgs/PoseStamped``."""
    stamp_ns, frame_id = _header_of(msg)
    return _pose_to_matrix(msg.pose, "PoseStamped.pose"), stamp_ns, frame_id


def pose_with_covariance_to_matrix(msg: Any) -> tuple[NDArray[np.float64], int, str]:
    """``(T_frame_pose, stamp_ns, frame_id)`` of a ``geometry_msgs/PoseWithCovarianceStamped`` (RViz's
    ``/initialpose``); the covariance is not read."""
    stamp_ns, frame_id = _header_of(msg)
    return _pose_to_matrix(msg.pose.pose, "PoseWithCovarianceStamped.pose.pose"), stamp_ns, frame_id


def matrix_to_pose_stamped(T: ArrayLike, *, stamp_ns: int, frame_id: str, types: MessageTypes = RCLPY) -> Any:
    """A ``geometry_msgs/PoseStamped`` of the transform ``T`` expressed in ``frame_id``."""
    return types.new(
        "geometry_msgs/msg/PoseStamped",
        header=make_header(stamp_ns, frame_id, types=types),
        pose=matrix_to_pose(T, types=types),
    )


def odometry_to_matrix(msg: Any) -> tuple[NDArray[np.float64], int, str, str]:
    """``(T_frame_child, stamp_ns, frame_id, child_frame_id)`` of a ``nav_msgs/Odometry``."""
    stamp_ns, frame_id = _header_of(msg)
    return _pose_to_matrix(msg.pose.pose, "Odometry.pose.pose"), stamp_ns, frame_id, str(msg.child_frame_id)


def _optional_array(value: ArrayLike | None, name: str, shapes: tuple[tuple[int, ...], ...]) -> NDArray[np.float64]:
    if value is None:
        return np.zeros(shapes[0])
    a = np.asarray(value, dtype=np.float64)
    if a.shape not in shapes:
        raise PoseConversionError(f"{name} must have shape {' or '.join(map(str, shapes))}, got {a.shape}")
    return a


def matrix_to_odometry(
    T: ArrayLike,
    *,
    stamp_ns: int,
    frame_id: str,
    child_frame_id: str,
    twist_linear: ArrayLike | None = None,
    twist_angular: ArrayLike | None = None,
    pose_covariance: ArrayLike | None = None,
    twist_covariance: ArrayLike | None = None,
    types: MessageTypes = RCLPY,
) -> Any:
    """A ``nav_msgs/Odometry`` with pose ``T`` (``child_frame_id`` in ``frame_id``).

    The twist (m/s, rad/s) is in ``child_frame_id``; covariances are ``(6, 6)`` or ``(36,)``, row-major over
    ``(x, y, z, rot_x, rot_y, rot_z)``. Omitted values are zeros (a zero covariance means "unknown").
    """
    linear = _optional_array(twist_linear, "twist_linear", ((3,),))
    angular = _optional_array(twist_angular, "twist_angular", ((3,),))
    pose_cov = _optional_array(pose_covariance, "pose_covariance", ((36,), (6, 6)))
    twist_cov = _optional_array(twist_covariance, "twist_covariance", ((36,), (6, 6)))

    def vector3(v: NDArray[np.float64]) -> Any:
        return types.new("geometry_msgs/msg/Vector3", x=float(v[0]), y=float(v[1]), z=float(v[2]))

    twist = types.new("geometry_msgs/msg/Twist", linear=vector3(linear), angular=vector3(angular))
    return types.new(
        "nav_msgs/msg/Odometry",
        header=make_header(stamp_ns, frame_id, types=types),
        child_frame_id=child_frame_id,
        pose=types.new(
            "geometry_msgs/msg/PoseWithCovariance",
            pose=matrix_to_pose(T, types=types),
            covariance=types.float64_array(pose_cov),
        ),
        twist=types.new(
            "geometry_msgs/msg/TwistWithCovariance", twist=twist, covariance=types.float64_array(twist_cov)
        ),
    )


# ------------------------------------------------------------------------------------------------------ cameras

SUPPORTED_DISTORTION_MODELS = ("plumb_bob", "rational_polynomial", "equidistant", "")
"""Distortion models accepted by :func:`camera_from_camera_info`, and only with all-zero coefficients."""


def camera_from_camera_info(msg: Any) -> PinholeCamera:
    """The :class:`~lightfast.camera.PinholeCamera` of a ``sensor_msgs/CameraInfo`` of rectified images.

    Requires ``width, height > 0``, a distortion model in :data:`SUPPORTED_DISTORTION_MODELS` with every
    coefficient of ``D`` zero (or ``D`` empty), no binning (``binning_x/y`` 0 or 1) and a full-image ROI; else
    :class:`CameraInfoError`. The intrinsics come from ``K`` (``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``). ``P`` is
    only checked for the projection-matrix layout when it is non-zero: for a rectified stereo pair
    ``P[:3, :3]`` legitimately differs from ``K``, and ``R`` is ignored.
    """
    width, height = int(msg.width), int(msg.height)
    if width <= 0 or height <= 0:
        raise CameraInfoError(f"CameraInfo.width={width} and height={height} must be > 0 (camera not calibrated?)")
    model = str(msg.distortion_model)
    d = np.asarray(msg.d, dtype=np.float64).reshape(-1)
    if model not in SUPPORTED_DISTORTION_MODELS or np.any(d != 0.0):
        raise CameraInfoError(
            f"CameraInfo.distortion_model={model!r} with D={d.tolist()} is not supported: lightfast models ideal "
            "pinhole cameras only, so images must be rectified (e.g. by image_proc) and described by a CameraInfo "
            "whose distortion coefficients are all zero"
        )
    for name in ("binning_x", "binning_y"):
        binning = int(getattr(msg, name, 0))
        if binning not in (0, 1):
            raise CameraInfoError(f"CameraInfo.{name}={binning} is not supported (only 0 or 1)")
    roi = getattr(msg, "roi", None)
    if roi is not None:
        roi_values = (int(roi.x_offset), int(roi.y_offset), int(roi.width), int(roi.height))
        if roi_values not in ((0, 0, 0, 0), (0, 0, width, height)):
            raise CameraInfoError(
                f"CameraInfo.roi (x_offset, y_offset, width, height)={roi_values} is not supported (full image only)"
            )
    k = np.asarray(msg.k, dtype=np.float64).reshape(-1)
    if k.size != 9 or not np.all(np.isfinite(k)):
        raise CameraInfoError(f"CameraInfo.k must be 9 finite numbers (row-major 3x3), got {k.tolist()}")
    p = np.asarray(msg.p, dtype=np.float64).reshape(-1)
    if p.size != 12:
        raise CameraInfoError(f"CameraInfo.p must have 12 elements (row-major 3x4), got {p.size}")
    if np.any(p != 0.0):
        P = p.reshape(3, 4)
        if (
            not np.all(np.isfinite(P))
            or not np.array_equal(P[2], [0.0, 0.0, 1.0, 0.0])
            or P[0, 1] != 0.0
            or P[1, 0] != 0.0
            or P[0, 0] <= 0.0
            or P[1, 1] <= 0.0
        ):
            raise CameraInfoError(
                f"CameraInfo.p={P.tolist()} is not a projection matrix [[fx', 0, cx', Tx], [0, fy', cy', Ty], "
                "[0, 0, 1, 0]]"
            )
    try:
        return PinholeCamera.from_matrix(k.reshape(3, 3), width, height)
    except CameraModelError as exc:
        raise CameraInfoError(f"CameraInfo.k: {exc}") from exc


class CameraInfoReader:
    """:func:`camera_from_camera_info` that keeps its last result: a driver sends the same ``CameraInfo`` with every
    image, and a node that converts each one spends more on the checks than on anything else it does per message."""

    def __init__(self) -> None:
        self._key: tuple[Any, ...] | None = None
        self._camera: PinholeCamera | None = None

    def __call__(self, msg: Any) -> PinholeCamera:
        roi = getattr(msg, "roi", None)
        key = (int(msg.width), int(msg.height), str(msg.distortion_model), bytes(np.asarray(msg.d, np.float64)),
               bytes(np.asarray(msg.k, np.float64)), bytes(np.asarray(msg.p, np.float64)),
               getattr(msg, "binning_x", 0), getattr(msg, "binning_y", 0),
               None if roi is None else (roi.x_offset, roi.y_offset, roi.width, roi.height))
        if key != self._key or self._camera is None:
            self._camera = camera_from_camera_info(msg)  # raises before the key is kept
            self._key = key
        return self._camera


def camera_info_from_camera(
    camera: PinholeCamera, *, stamp_ns: int = 0, frame_id: str = "", types: MessageTypes = RCLPY
) -> Any:
    """A ``sensor_msgs/CameraInfo`` for ``camera``: ``K``, ``P = [K | 0]``, ``R = I``, ``D = 0`` (plumb_bob)."""
    K = camera.K
    P = np.hstack([K, np.zeros((3, 1))])
    return types.new(
        "sensor_msgs/msg/CameraInfo",
        header=make_header(stamp_ns, frame_id, types=types),
        height=int(camera.height),
        width=int(camera.width),
        distortion_model="plumb_bob",
        d=types.float64_sequence(np.zeros(5)),
        k=types.float64_array(K),
        r=types.float64_array(np.eye(3)),
        p=types.float64_array(P),
        binning_x=0,
        binning_y=0,
        roi=types.new(
            "sensor_msgs/msg/RegionOfInterest", x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )
