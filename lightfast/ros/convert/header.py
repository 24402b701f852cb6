"""``builtin_interfaces/Time`` and ``std_msgs/Header`` ↔ integer nanoseconds and frame ids.

Stamps are integer nanoseconds (``stamp_ns``), ``sec * 10**9 + nanosec`` of ``builtin_interfaces/Time``; negative
stamps give negative ``sec``, and ``sec`` must fit int32. Reading takes any object with ``sec`` and ``nanosec``
(a header: ``stamp`` and ``frame_id``); building takes ``types`` (:mod:`lightfast.ros.msgtypes`).
"""
from __future__ import annotations

import operator
from typing import Any

from lightfast.ros.errors import ConversionError
from lightfast.ros.msgtypes import RCLPY, MessageTypes

__all__ = ["make_header", "ns_to_stamp", "stamp_to_ns"]

_NS_PER_S = 1_000_000_000
_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1


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
