"""Record live topics into an MCAP bag: raw (serialized) subscriptions, nothing deserialized.

Library first: :class:`BagRecorder` subscribes on an existing node and writes through a
:class:`~lightfast.bag.writer.BagWriter`; ``lightfast bag record`` wraps it with signal handling, so SIGINT or
SIGTERM closes a valid bag holding every message the subscriptions had delivered.

Topics are discovered from the ROS graph periodically; a topic's subscription QoS adapts to its publishers
(reliable and KEEP_ALL when they are all reliable, transient-local when they all are). Each message's log time is
the node clock's time at reception (ROS time, so ``use_sim_time`` makes it bag time). The writer's chunk
compression (``BagWriter(..., compression="zstd")``) applies as written; the report states it and the bag's size.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from rclpy.node import Node
from rclpy.subscription import Subscription

from lightfast.bag.errors import UnknownMessageTypeError
from lightfast.bag.writer import BagWriter, register_msgdef
from lightfast.ros.qos import qos_to_bag, recording_qos
from lightfast.ros.runtime import message_class

log = logging.getLogger(__name__)

#: Topics every ROS 2 node publishes on; not recorded unless asked for by name.
DEFAULT_EXCLUDES = ("/rosout", "/parameter_events")


@dataclass
class TopicStats:
    msgtype: str
    count: int = 0
    first_ns: int = 0
    last_ns: int = 0

    @property
    def rate_hz(self) -> float:
        span = (self.last_ns - self.first_ns) * 1e-9
        return (self.count - 1) / span if self.count > 1 and span > 0 else 0.0


@dataclass
class RecordReport:
    path: Path
    topics: dict[str, TopicStats] = field(default_factory=dict)
    compression: str = "none"
    size_bytes: int | None = None  # of the finished bag (set by BagRecorder.close)

    @property
    def message_count(self) -> int:
        return sum(s.count for s in self.topics.values())

    def summary(self) -> str:
        parts = [f"{name} {s.count} @ {s.rate_hz:.1f} Hz" for name, s in sorted(self.topics.items())]
        details = [f"{self.size_bytes / 1e6:.1f} MB"] if self.size_bytes is not None else []
        details += [f"{self.compression} chunks"] if self.compression != "none" else []
        where = f"{self.path}" + (f" ({', '.join(details)})" if details else "")
        return f"recorded {self.message_count} messages on {len(self.topics)} topics to {where}: " + "; ".join(parts)


def _load_msgdef(msgtype: str) -> str:
    """The ros2msg definition of ``msgtype`` from the ROS installation's share directory, with dependencies."""
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

    pkg, _, name = msgtype.split("/")
    try:
        return (Path(get_package_share_directory(pkg)) / "msg" / f"{name}.msg").read_text()
    except (PackageNotFoundError, OSError, ValueError):
        raise UnknownMessageTypeError(f"no message definition for {msgtype} in this ROS installation") from None


class BagRecorder:
    """Subscribe to topics on ``node`` and write every message received into ``writer``.

    ``topics`` lists the topics to record (recorded as soon as a publisher appears); ``None`` records every topic
    but :data:`DEFAULT_EXCLUDES`. Call :meth:`discover` (a timer on the node does it every
    ``discovery_period_s``) and spin the node's executor; :meth:`close` finishes the bag.
    """

    def __init__(
        self,
        node: Node,
        writer: BagWriter,
        *,
        topics: Sequence[str] | None = None,
        exclude: Sequence[str] = DEFAULT_EXCLUDES,
        discovery_period_s: float = 0.2,
        on_message: Callable[[str], None] | None = None,
    ) -> None:
        self.node = node
        self.writer = writer
        self.topics = None if topics is None else tuple(dict.fromkeys(topics))
        self.exclude = set(exclude)
        self.on_message = on_message
        self.report = RecordReport(path=writer.path, compression=writer.compression)
        self._subscriptions: dict[str, Subscription] = {}
        self._skipped: set[str] = set()
        self._closed = False
        self.discover()
        self._timer = node.create_timer(discovery_period_s, self.discover)

    @property
    def subscribed(self) -> tuple[str, ...]:
        return tuple(self._subscriptions)

    def discover(self) -> None:
        """Subscribe to every wanted topic that has appeared in the graph since the last call."""
        if self._closed:
            return
        for name, types in self.node.get_topic_names_and_types():
            if name in self._subscriptions or name in self._skipped:
                continue
            if self.topics is None and name in self.exclude:
                continue
            if self.topics is not None and name not in self.topics:
                continue
            if len(types) != 1:
                log.warning("not recording %s: it has several types %s", name, types)
                self._skipped.add(name)
                continue
            try:
                self._subscribe(name, types[0])
            except UnknownMessageTypeError as exc:
                log.warning("not recording %s: %s", name, exc)
                self._skipped.add(name)

    def _subscribe(self, name: str, msgtype: str) -> None:
        cls = message_class(msgtype)
        if msgtype not in self.writer.typestore.types:
            register_msgdef(self.writer.typestore, msgtype, _load_msgdef(msgtype))
        offered = [info.qos_profile for info in self.node.get_publishers_info_by_topic(name)]
        if not offered:
            return  # no publisher yet (the graph can list a topic a moment before its endpoints)
        self.writer.add_topic(name, msgtype, offered_qos=[qos_to_bag(q) for q in offered])
        stats = self.report.topics.setdefault(name, TopicStats(msgtype))
        clock = self.node.get_clock()

        def callback(data: bytes) -> None:
            if self._closed:
                return
            now_ns = clock.now().nanoseconds
            self.writer.write(name, now_ns, data)
            if stats.count == 0:
                stats.first_ns = now_ns
            stats.count += 1
            stats.last_ns = now_ns
            if self.on_message is not None:
                self.on_message(name)

        self._subscriptions[name] = self.node.create_subscription(
            cls, name, callback, recording_qos(offered), raw=True
        )
        log.info("recording %s [%s]", name, msgtype)

    def close(self) -> RecordReport:
        """Stop recording and finish the bag. Messages delivered to the callbacks so far are all in it."""
        if not self._closed:
            self._closed = True
            self.node.destroy_timer(self._timer)
            for sub in self._subscriptions.values():
                self.node.destroy_subscription(sub)
            self.report.path = self.writer.close()
            files = [self.report.path] if self.report.path.is_file() else list(self.report.path.iterdir())
            self.report.size_bytes = sum(p.stat().st_size for p in files if p.is_file())
        return self.report


def drain(spin_once: Callable[[float], None], count: Callable[[], int], *, max_s: float = 30.0,
          idle_spins: int = 3) -> None:
    """On shutdown, write what the subscriptions have already received: spin without waiting until
    ``idle_spins`` spins in a row deliver nothing (the queues are empty), at most ``max_s`` seconds.

    Only emptiness ends it, not a pause in arrivals: a loaded machine may take a while per message."""
    deadline = time.monotonic() + max_s
    idle = 0
    while idle < idle_spins and time.monotonic() < deadline:
        before = count()
        spin_once(0.0)
        idle = idle + 1 if count() == before else 0
