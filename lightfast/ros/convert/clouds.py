"""``sensor_msgs/PointCloud2`` ↔ NumPy structured point arrays.

Point clouds become 1-D structured arrays with one named field per ``PointField`` (``count > 1`` gives a subarray
field) and ``itemsize == point_step``. Organized clouds (``height > 1``) are flattened row by row, so point
``(row, col)`` is element ``row * width + col``; pass ``height=msg.height`` back to :func:`numpy_to_pointcloud2`
to rebuild the organisation. Coordinates are in the cloud's ``header.frame_id``, in metres by ROS convention.
Reading is a view of the message buffer for unpadded rows in native byte order, a native copy otherwise; writing
emits little-endian, unpadded rows.
"""
from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.ros.convert.header import make_header
from lightfast.ros.convert.images import _byte_buffer
from lightfast.ros.errors import PointCloudConversionError
from lightfast.ros.msgtypes import RCLPY, MessageTypes

__all__ = [
    "PointCloud2Fields",
    "PointFieldSpec",
    "numpy_to_pointcloud2",
    "pointcloud2_fields",
    "pointcloud2_to_numpy",
    "xyz_to_pointcloud2",
]

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

