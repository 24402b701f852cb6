"""What a core component reports — a :class:`Problem`, a :class:`Log` line, a :class:`Status` — and its
:class:`Level`, shared by the core and the nodes.

The core never logs: it returns or hands over these, and a node (``lightfast.ros.node.LightfastNode.report``) logs
them, counts problems and publishes statuses. The levels are those of ``diagnostic_msgs/DiagnosticStatus.level``.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

__all__ = ["Level", "Log", "Problem", "Report", "Status"]


class Level(IntEnum):
    """``DiagnosticStatus.level`` values."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


@dataclass(frozen=True)
class Problem:
    """Bad input or a failed step: counted (unless ``counted`` is False: a state, not an input), logged throttled
    per ``key``, and a status with ``values``."""

    key: str
    text: str
    level: Level = Level.WARN
    stamp_ns: int | None = None
    values: Mapping[str, Any] = field(default_factory=dict)
    counted: bool = True


@dataclass(frozen=True)
class Log:
    """A log line (throttled per ``key`` when one is given)."""

    text: str
    level: Level = Level.OK
    key: str | None = None


@dataclass(frozen=True)
class Status:
    """A status with its values."""

    level: Level
    message: str
    values: Mapping[str, Any] = field(default_factory=dict)
    stamp_ns: int | None = None


Report = Problem | Log | Status
