"""The base of lightfast's nodes: what every node does the same way, so that a node's module only wires.

A :class:`LightfastNode` declares its parameters from its configuration dataclass (:class:`ConfigParameters`:
descriptions, ranges, validated run-time changes, unknown names reported), logs problems throttled per kind
(:class:`~lightfast.ros.diagnostics.ProblemLog`) and what core components report (:meth:`LightfastNode.report`),
publishes its status as a ``DiagnosticArray`` on its status topic
(the node's counters in every status), and announces itself on ``/lightfast/ready`` once it can take data.
"""
from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from typing import Any, Generic, TypeVar

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.publisher import Publisher

from lightfast.config import Config
from lightfast.ros.diagnostics import Level, ProblemLog, diagnostic_array, diagnostic_status, log_at
from lightfast.ros.params import ConfigParameters
from lightfast.ros.qos import OUTPUT_QOS
from lightfast.ros.ready import announce_ready
from lightfast.ros.worker import StepWorker
from lightfast.status import Log, Problem, Report

__all__ = ["LightfastNode"]

C = TypeVar("C", bound=Config)


class LightfastNode(Node, Generic[C]):
    """A node with a configuration dataclass ``config_class`` and a status topic (``status_topic``; ``None``: the
    node publishes no status). Subclasses call :meth:`announce_ready` at the end of their ``__init__``."""

    def __init__(self, name: str, config_class: type[C], *, status_topic: str | None, **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.params: ConfigParameters[C] = ConfigParameters(self, config_class)
        self.problems = ProblemLog(self.log)
        self.stats: dict[str, int] = {"bad_inputs": 0}
        self.status_pub: Publisher | None = (
            self.create_publisher(DiagnosticArray, status_topic, OUTPUT_QOS) if status_topic else None)
        self._ready_pub: Publisher | None = None
        #: the latest status (level, message): a heartbeat repeats it
        self.last_status: tuple[Level, str] = (Level.OK, "starting")
        self._workers: list[StepWorker] = []

    def log(self, level: Level, text: str) -> None:
        """A log line at the severity of a status level."""
        log_at(self.get_logger(), level, text)

    def now_ns(self) -> int:
        """The node's clock (ROS time: sim time on ``use_sim_time``), ns."""
        return self.get_clock().now().nanoseconds

    def status_values(self) -> dict[str, Any]:
        """``key: value`` pairs every status carries (the counters; nodes add their state)."""
        return dict(self.stats)

    def publish_status(self, level: Level, message: str, values: Mapping[str, Any] | None = None, *,
                       stamp_ns: int | None = None) -> None:
        """One status: :meth:`status_values` and ``values`` (which win), stamped ``stamp_ns`` (the input it is
        about) or now."""
        self.last_status = (level, message)
        if self.status_pub is None:
            return
        stamp = self.now_ns() if stamp_ns is None else stamp_ns
        status = diagnostic_status(self.get_name(), level, message, {**self.status_values(), **(values or {})})
        self.status_pub.publish(diagnostic_array(stamp, [status]))

    def problem(self, key: str, text: str, level: Level = Level.WARN, *, stamp_ns: int | None = None,
                values: Mapping[str, Any] | None = None, count: bool = True) -> None:
        """Bad input or a failed step: counted (``bad_inputs``), a log line throttled per ``key``, a status; the
        node carries on."""
        if count:
            self.stats["bad_inputs"] += 1
        self.problems.report(key, text, level)
        self.publish_status(level, text, values, stamp_ns=stamp_ns)

    def report(self, report: Report) -> None:
        """What a core component reported (:mod:`lightfast.status`): a problem counted, logged throttled and
        published as a status; a log line (throttled per key when it has one); a status published."""
        if isinstance(report, Problem):
            self.problem(report.key, report.text, report.level, stamp_ns=report.stamp_ns, values=report.values,
                         count=report.counted)
        elif isinstance(report, Log):
            if report.key is None:
                self.log(report.level, report.text)
            else:
                self.problems.report(report.key, report.text, report.level)
        else:
            self.publish_status(report.level, report.message, report.values, stamp_ns=report.stamp_ns)

    def start_worker(self, name: str, step: Callable[[], bool], *,
                     period_s: Callable[[], float] | None = None) -> StepWorker:
        """A :class:`~lightfast.ros.worker.StepWorker` thread for the node's heavy steps (the one threading model of
        lightfast's nodes: callbacks convert and queue, workers compute). A step that raises is an ``internal``
        problem (ERROR) and the worker carries on; :meth:`destroy_node` stops the workers."""
        worker = StepWorker(name, step, self._on_worker_error, period_s=period_s)
        self._workers.append(worker)
        return worker

    def _on_worker_error(self, exc: Exception) -> None:
        self.problem("internal", f"{threading.current_thread().name} step failed: {exc!r}", Level.ERROR)

    def stop_workers(self) -> None:
        """Stop the workers (after their current step)."""
        for worker in self._workers:
            worker.stop()

    def destroy_node(self) -> None:
        self.stop_workers()
        super().destroy_node()

    def announce_ready(self) -> None:
        """Announce on ``/lightfast/ready`` that the node can take data (for ``lightfast wait-ready``)."""
        self._ready_pub = announce_ready(self)
