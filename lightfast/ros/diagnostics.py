"""Node status as ``diagnostic_msgs/DiagnosticArray`` and throttled problem reports; for rclpy and rosbags alike.

A node publishes its state as one :func:`diagnostic_status` (level, one-line message, ``key: value`` strings) in a
:func:`diagnostic_array`; :func:`diagnostic_values` and :func:`diagnostic_level` read such a status back (duck-typed,
e.g. in tests or evaluations). :class:`ProblemLog` throttles repeated reports per kind of problem, so that a stream
of bad messages logs one line per period and kind instead of one per message. Nothing here imports rclpy.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from lightfast.ros.convert import make_header
from lightfast.ros.msgtypes import RCLPY, MessageTypes
from lightfast.status import Level

__all__ = [
    "Level",
    "ProblemLog",
    "diagnostic_array",
    "diagnostic_level",
    "diagnostic_status",
    "diagnostic_values",
    "format_value",
    "log_at",
]


def format_value(value: Any) -> str:
    """A ``KeyValue.value`` string: floats with 6 significant digits, bools as true/false, None as empty."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def diagnostic_status(
    name: str,
    level: int,
    message: str,
    values: Mapping[str, Any] | None = None,
    *,
    hardware_id: str = "",
    types: MessageTypes = RCLPY,
) -> Any:
    """A ``diagnostic_msgs/DiagnosticStatus``; ``values`` become ``KeyValue`` strings (:func:`format_value`)."""
    lvl = int(Level(level))
    key_values = [types.new("diagnostic_msgs/msg/KeyValue", key=str(k), value=format_value(v))
                  for k, v in (values or {}).items()]
    return types.new(
        "diagnostic_msgs/msg/DiagnosticStatus",
        level=bytes([lvl]) if types.name == "rclpy" else lvl,  # rclpy maps the byte type to bytes of length 1
        name=name,
        message=message,
        hardware_id=hardware_id,
        values=key_values,
    )


def diagnostic_array(stamp_ns: int, statuses: Iterable[Any], *, frame_id: str = "",
                     types: MessageTypes = RCLPY) -> Any:
    """A ``diagnostic_msgs/DiagnosticArray`` holding ``statuses``."""
    return types.new("diagnostic_msgs/msg/DiagnosticArray", header=make_header(stamp_ns, frame_id, types=types),
                     status=list(statuses))


def diagnostic_level(status: Any) -> Level:
    """The level of a ``DiagnosticStatus`` (bytes in rclpy, int in rosbags)."""
    level = status.level
    return Level(level[0] if isinstance(level, bytes | bytearray) else int(level))


def diagnostic_values(status: Any) -> dict[str, str]:
    """The ``key: value`` strings of a ``DiagnosticStatus``."""
    return {str(kv.key): str(kv.value) for kv in status.values}


def log_at(logger: Any, level: Level, text: str) -> None:
    """Log ``text`` on an rclpy logger at the severity of a status ``level``. One call site per severity: rclpy
    refuses a call site that is used with several severities."""
    if level == Level.OK:
        logger.info(text)
    elif level == Level.WARN:
        logger.warning(text)
    else:
        logger.error(text)


class ProblemLog:
    """Throttled problem reports: at most one line per ``period_s`` (monotonic time) for each ``key``.

    ``emit(level, text)`` does the logging, e.g. ``lambda level, text: logger.warning(text)``. A line after a quiet
    period says how many reports of that kind were suppressed since the previous line.
    """

    def __init__(self, emit: Callable[[Level, str], None], *, period_s: float = 5.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.emit = emit
        self.period_s = float(period_s)
        self._clock = clock
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def report(self, key: str, text: str, level: Level = Level.WARN) -> bool:
        """Report a problem of kind ``key``; returns whether a line was logged."""
        now = self._clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period_s:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
            return False
        suppressed = self._suppressed.pop(key, 0)
        self._last[key] = now
        self.emit(level, text + (f" ({suppressed} similar suppressed)" if suppressed else ""))
        return True
