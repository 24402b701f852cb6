"""``sensor_msgs/Image`` ↔ NumPy pixel arrays.

Images become arrays ``(H, W)`` for one channel and ``(H, W, C)`` otherwise, rows top to bottom, in the message's
channel order (``rgb8`` is RGB, ``bgr8`` BGR; nothing is reordered, except by :func:`image_to_rgb`). Depth images:
``16UC1`` is ``uint16`` in millimetres with 0 meaning invalid (no return); ``32FC1`` is ``float32`` in metres with
NaN (or 0) meaning invalid. No unit conversion happens here but in :func:`depth_to_metres` (either depth encoding
as float32 metres). Pixels are in the camera's optical frame (``header.frame_id``). Reading is zero-copy (the array
is a view of the message buffer, honouring ``step`` row padding) whenever the data is in native byte order;
big-endian data is byte-swapped into a native copy. Writing emits little-endian (``is_bigendian=0``), unpadded rows.
"""
from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.ros.convert.header import make_header
from lightfast.ros.errors import ImageConversionError
from lightfast.ros.msgtypes import RCLPY, MessageTypes

__all__ = [
    "COLOR_ENCODINGS",
    "IMAGE_ENCODINGS",
    "ImageEncoding",
    "ImageFields",
    "depth_to_metres",
    "image_fields",
    "image_to_numpy",
    "image_to_rgb",
    "numpy_to_image",
]


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


def depth_to_metres(msg: Any) -> NDArray[np.float32]:
    """A depth ``sensor_msgs/Image`` as float32 metres: ``32FC1`` as it is (NaN or 0 invalid), ``16UC1``
    millimetres scaled (0 stays invalid). Raises :class:`ImageConversionError` for any other encoding."""
    if msg.encoding == "32FC1":
        return image_to_numpy(msg)
    if msg.encoding == "16UC1":
        return image_to_numpy(msg).astype(np.float32) * np.float32(0.001)
    raise ImageConversionError(f"depth image encoding {msg.encoding!r} is not supported (need 32FC1 m or 16UC1 mm)")


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

