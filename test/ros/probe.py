"""The status methods shared by the node-test probes (test_daylight_relight_node.py, test_vtr_localizer_node.py)."""
from __future__ import annotations

from collections.abc import Callable

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import Executor

from lightfast.ros.diagnostics import Level, diagnostic_level, diagnostic_values
from lightfast.ros.spin import spin_until

Status = tuple[Level, str, dict[str, str]]


class StatusProbe:
    """Base of a test node that spins ``executor`` and collects a node's ``DiagnosticArray`` messages in ``status``;
    ``timeout_s`` is the default wait of :meth:`spin_until` and :meth:`wait_status`."""

    executor: Executor
    status: list[DiagnosticArray]
    timeout_s: float

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float | None = None) -> bool:
        return spin_until(self.executor, predicate, self.timeout_s if timeout_s is None else timeout_s)

    def statuses(self) -> list[Status]:
        return [(diagnostic_level(s), s.message, diagnostic_values(s)) for a in self.status for s in a.status]

    def wait_status(self, predicate: Callable[[Level, str, dict[str, str]], bool],
                    timeout_s: float | None = None) -> Status:
        def found() -> Status | None:
            return next((s for s in self.statuses() if predicate(*s)), None)
        assert self.spin_until(lambda: found() is not None, timeout_s), self.statuses()[-5:]
        result = found()
        assert result is not None
        return result
