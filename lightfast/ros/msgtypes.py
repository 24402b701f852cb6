"""Message flavours: build ROS 2 messages either as rclpy (rosidl Python) objects or as rosbags dataclasses.

The conversions of :mod:`lightfast.ros.convert` read any message duck-typed (by field names) and build messages
through a :class:`MessageTypes` object, chosen with their ``types`` keyword:

* :data:`RCLPY` — the generated classes of the ROS 2 message packages (``sensor_msgs.msg.Image`` …), as used by
  rclpy publishers and subscriptions. Importing them does not import rclpy itself.
* :func:`rosbags_types` — the dataclasses of a rosbags typestore (default: ROS 2 Jazzy), as read from and
  written to bags with ``typestore.serialize_cdr`` / ``deserialize_cdr``.

Array fields differ between the flavours, so building goes through :meth:`MessageTypes.uint8_array` (``uint8[]``),
:meth:`MessageTypes.float64_array` (fixed ``float64[N]``) and :meth:`MessageTypes.float64_sequence`
(``float64[]``). rclpy's setters turn other values into an ``array.array``: lists element by element, and with
field checking on they first validate every element in Python (seconds for a large image). The rclpy flavour
therefore copies pixel data exactly once, from a memoryview into an ``array.array('B')``, and builds messages with
``check_fields=True`` (rosidl's constructor option), under which the setters keep an ``array.array`` as it is
instead of copying it again; afterwards the message gets the class default back, so it behaves like one built with
the plain constructor. The rosbags flavour passes NumPy arrays through, as a view of the input when it is already
a contiguous ``uint8`` array (the message then shares memory with the caller's array).

This module does not import rclpy, and imports message packages and rosbags only when first used.
"""
from __future__ import annotations

import array
import functools
import importlib
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

BytesLike = bytes | bytearray | memoryview | array.array
"""Objects whose raw bytes :meth:`MessageTypes.uint8_array` takes as they are."""

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ["RCLPY", "BytesLike", "MessageTypes", "RclpyTypes", "RosbagsTypes", "rosbags_types"]


@runtime_checkable
class MessageTypes(Protocol):
    """How to build messages of one flavour (rclpy or rosbags)."""

    name: str

    def cls(self, name: str) -> type:
        """The message class of ``name``, e.g. ``'sensor_msgs/msg/Image'``."""
        ...

    def new(self, type_name: str, /, **fields: Any) -> Any:
        """A new message of type ``type_name``. Every field should be given (rosbags dataclasses require all)."""
        ...

    def uint8_array(self, a: ArrayLike | BytesLike) -> Any:
        """The value of a ``uint8[]`` field holding the bytes of ``a`` (a uint8 array or a bytes-like object)."""
        ...

    def float64_array(self, a: ArrayLike) -> Any:
        """The value of a fixed-size ``float64[N]`` field (e.g. a covariance) from ``a``, flattened in C order."""
        ...

    def float64_sequence(self, a: ArrayLike) -> Any:
        """The value of a variable-size ``float64[]`` field (e.g. ``CameraInfo.d``) from ``a``, flattened."""
        ...


def _split_name(name: str) -> tuple[str, str, str]:
    parts = name.split("/")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"message type name must look like 'sensor_msgs/msg/Image', got {name!r}")
    return parts[0], parts[1], parts[2]


def _uint8_1d(a: ArrayLike | BytesLike) -> NDArray[np.uint8]:
    """``a`` as a C-contiguous 1-D uint8 array, without a copy when it is one already (or a bytes-like object)."""
    if isinstance(a, np.ndarray):
        if a.dtype != np.uint8:
            raise TypeError(f"uint8 array field needs dtype uint8, got {a.dtype} (use .view(np.uint8) for raw bytes)")
        return np.ascontiguousarray(a).reshape(-1)
    if isinstance(a, bytes | bytearray | memoryview | array.array):
        return np.frombuffer(a, dtype=np.uint8)
    return np.asarray(a, dtype=np.uint8).reshape(-1)


def _float64_1d(a: ArrayLike) -> NDArray[np.float64]:
    """A new contiguous 1-D float64 copy of ``a`` (messages never share memory with the caller's small arrays)."""
    return np.array(a, dtype=np.float64, copy=True).reshape(-1)


@functools.cache
def _rclpy_class(name: str) -> type:
    package, kind, type_name = _split_name(name)
    module = importlib.import_module(f"{package}.{kind}")
    try:
        return getattr(module, type_name)
    except AttributeError:
        raise LookupError(f"no message type {name!r} in module {package}.{kind}") from None


@functools.cache
def _rclpy_default_check_fields(cls: type) -> bool:
    return bool(cls()._check_fields)


class RclpyTypes:
    """The rclpy flavour: classes of the installed ROS 2 message packages (``sensor_msgs.msg`` …)."""

    name = "rclpy"

    def __repr__(self) -> str:
        return "RCLPY"

    def cls(self, name: str) -> type:
        return _rclpy_class(name)

    def new(self, type_name: str, /, **fields: Any) -> Any:
        # The setters keep an array.array (or a float64 ndarray) as it is only while the message checks its
        # fields; unchecked (the Jazzy default, ROS_PYTHON_CHECK_FIELDS unset) they copy it again. So assign with
        # checks on, then give the message the class default back so later assignments behave as usual.
        cls = self.cls(type_name)
        msg = cls(check_fields=True)
        for key, value in fields.items():
            setattr(msg, key, value)
        msg._check_fields = _rclpy_default_check_fields(cls)
        return msg

    def uint8_array(self, a: ArrayLike | BytesLike) -> array.array:
        out = array.array("B")
        out.frombytes(_uint8_1d(a).data)  # one memcpy (ndarray.data: the memoryview of the array)
        return out

    def float64_array(self, a: ArrayLike) -> NDArray[np.float64]:
        return _float64_1d(a)

    def float64_sequence(self, a: ArrayLike) -> array.array:
        out = array.array("d")
        out.frombytes(_float64_1d(a).data.cast("B"))
        return out


class RosbagsTypes:
    """The rosbags flavour: dataclasses of one rosbags typestore (arrays are NumPy arrays)."""

    name = "rosbags"

    def __init__(self, typestore: Typestore) -> None:
        self.typestore = typestore

    def __repr__(self) -> str:
        return f"RosbagsTypes({self.typestore!r})"

    def cls(self, name: str) -> type:
        _split_name(name)
        try:
            return self.typestore.types[name]
        except KeyError:
            raise LookupError(f"no message type {name!r} in the rosbags typestore") from None

    def new(self, type_name: str, /, **fields: Any) -> Any:
        return self.cls(type_name)(**fields)

    def uint8_array(self, a: ArrayLike | BytesLike) -> NDArray[np.uint8]:
        return _uint8_1d(a)

    def float64_array(self, a: ArrayLike) -> NDArray[np.float64]:
        return _float64_1d(a)

    def float64_sequence(self, a: ArrayLike) -> NDArray[np.float64]:
        return _float64_1d(a)


RCLPY: RclpyTypes = RclpyTypes()
"""The rclpy flavour (module-level instance)."""


@functools.cache
def _default_rosbags_types() -> RosbagsTypes:
    from rosbags.typesys import Stores, get_typestore

    return RosbagsTypes(get_typestore(Stores.ROS2_JAZZY))


def rosbags_types(typestore: Typestore | None = None) -> RosbagsTypes:
    """The rosbags flavour for ``typestore`` (default: the ROS 2 Jazzy typestore, created once and cached)."""
    if typestore is None:
        return _default_rosbags_types()
    return RosbagsTypes(typestore)
