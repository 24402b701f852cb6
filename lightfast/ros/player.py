"""Replay a bag onto live topics: serialized CDR straight from the bag, in log-time order, optionally with /clock.

Library first: :func:`play_bag` publishes from an existing node (so tests can run it on a private context);
``lightfast bag play`` wraps it. The player is paced by the bag's log times scaled by ``rate`` (``0`` = as fast as
possible), can wait for subscribers before the first message, and at the end waits until reliable subscribers
acknowledged everything, so a fast replay still loses nothing.

A corrupt chunk of an MCAP bag (see :mod:`lightfast.bag.mcap_chunks`) does not end the replay: its messages are
skipped, the rest is played, and the report counts what was skipped (:attr:`PlayReport.corrupt_chunks`); the
caller decides whether an incomplete replay is a failure (``lightfast bag play`` exits 5 unless --skip-corrupt).
"""
from __future__ import annotations

import logging
import os
import threading
import time
from collections import Counter
from dataclasses import dataclass

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from lightfast.bag.errors import BagError
from lightfast.bag.mcap_chunks import CorruptChunk, SkippedChunks, describe_skipped
from lightfast.bag.reader import BagReader, open_bag
from lightfast.config import Config, param
from lightfast.ros.convert import ns_to_stamp
from lightfast.ros.qos import CLOCK_QOS, playback_qos
from lightfast.ros.runtime import message_class

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlayOptions(Config):
    """How to replay a bag."""

    rate: float = param(1.0, description="Playback speed relative to the recording; 0 plays as fast as possible.",
                        min=0.0)
    loop: bool = param(False, description="Start over when the bag ends (until interrupted, or max_loops).")
    max_loops: int = param(0, description="With loop: stop after this many plays of the bag; 0 = no limit.", min=0)
    clock_hz: float = param(0.0, description="Publish /clock (bag time) at this rate and before every message, for "
                            "nodes with use_sim_time; 0 disables /clock.", min=0.0)
    topics: tuple[str, ...] = param((), description="Topics to play; empty plays every topic.")
    preroll_s: float = param(0.0, description="With /clock: before the first message, run the clock from this many "
                             "seconds before it (at the playback rate, real time for rate 0), so nodes on sim time "
                             "can get ready (e.g. a first sun update).", min=0.0, max=3600.0)
    start_offset_s: float = param(0.0, description="Skip this many seconds from the start of the bag.", min=0.0)
    wait_for_subscribers_s: float = param(0.0, description="Before playing, wait up to this long until every "
                                          "topic has a subscriber; 0 does not wait.", min=0.0)
    ack_timeout_s: float = param(30.0, description="At the end, wait up to this long for reliable subscribers to "
                                 "acknowledge every message.", min=0.0)
    qos_depth: int = param(0, description="Publisher history depth; 0 keeps all (a reliable subscriber loses "
                           "nothing), N keeps the last N.", min=0)
    reliability: str = param("", description="Publish with this reliability instead of what the recorded "
                             "publishers offered (best_effort: like a camera driver with sensor-data QoS).",
                             choices=("", "reliable", "best_effort"))


@dataclass(frozen=True)
class PlayReport:
    """What a replay did. ``wall_duration_s`` and ``cpu_s`` (the CPU time of the player's process, all threads) count
    from the first message on: the wait for subscribers and the clock preroll are not in them. ``realtime_factor`` is
    bag time played over that wall time. ``corrupt_chunks`` are the bag's chunks that failed their checks and were
    skipped (each counted once, also when looping)."""

    published: dict[str, int]
    bag_duration_s: float
    wall_duration_s: float
    loops: int
    acknowledged: bool
    interrupted: bool
    cpu_s: float = 0.0
    corrupt_chunks: tuple[CorruptChunk, ...] = ()

    @property
    def message_count(self) -> int:
        return sum(self.published.values())

    @property
    def skipped_messages(self) -> int:
        """Messages of the played topics lost in corrupt chunks (a lower bound if a chunk's count is unknown)."""
        return sum(c.message_count or 0 for c in self.corrupt_chunks)

    @property
    def complete(self) -> bool:
        """No corrupt chunk was skipped."""
        return not self.corrupt_chunks

    def skipped_summary(self) -> str:
        """``skipped 5 messages in 1 corrupt chunk`` ('' if nothing was skipped)."""
        return describe_skipped(self.corrupt_chunks) if self.corrupt_chunks else ""

    @property
    def realtime_factor(self) -> float:
        return self.bag_duration_s / self.wall_duration_s if self.wall_duration_s > 0 else float("inf")

    def summary(self) -> str:
        rate = f"{self.realtime_factor:.2f}x real time" if self.wall_duration_s > 0 else "instant"
        flags = "" if self.acknowledged else ", NOT all acknowledged"
        flags += ", interrupted" if self.interrupted else ""
        skipped = f", {self.skipped_summary()}" if self.corrupt_chunks else ""
        return (
            f"played {self.message_count} messages on {len(self.published)} topics, {self.bag_duration_s:.2f} s of "
            f"bag in {self.wall_duration_s:.2f} s ({rate}{flags}), {self.cpu_s:.2f} s CPU{skipped}"
        )


class _ClockPublisher:
    def __init__(self, node: Node, hz: float) -> None:
        self.publisher = node.create_publisher(Clock, "/clock", CLOCK_QOS) if hz > 0 else None
        self.period_s = 1.0 / hz if hz > 0 else float("inf")
        self.last_wall = 0.0

    def publish(self, bag_time_ns: int) -> None:
        if self.publisher is not None:
            self.publisher.publish(Clock(clock=ns_to_stamp(bag_time_ns)))
            self.last_wall = time.monotonic()


def _wait_for_subscribers(publishers: dict[str, Publisher], timeout_s: float, stop: threading.Event) -> None:
    deadline = time.monotonic() + timeout_s
    while not stop.is_set():
        waiting = [t for t, p in publishers.items() if p.get_subscription_count() == 0]
        if not waiting:
            return
        if time.monotonic() >= deadline:
            log.warning("no subscriber after %.1f s on: %s", timeout_s, ", ".join(waiting))
            return
        stop.wait(0.01)


def _preroll(clock: _ClockPublisher, first_ns: int, options: PlayOptions, stop: threading.Event) -> None:
    """Publish /clock from ``preroll_s`` before ``first_ns`` up to it, at the playback rate."""
    rate = options.rate if options.rate > 0 else 1.0
    span_ns = int(options.preroll_s * 1e9)
    wall0 = time.monotonic()
    while not stop.is_set():
        elapsed_ns = int((time.monotonic() - wall0) * rate * 1e9)
        if elapsed_ns >= span_ns:
            break
        clock.publish(first_ns - span_ns + elapsed_ns)
        stop.wait(clock.period_s)


def play_bag(
    bag: str | os.PathLike[str] | BagReader,
    node: Node,
    options: PlayOptions | None = None,
    *,
    stop: threading.Event | None = None,
) -> PlayReport:
    """Replay ``bag`` through publishers created on ``node``; ``stop`` ends the replay early.

    The publishers are created and destroyed on the calling thread: ``node`` needs no spinning, and must not be in an
    executor that another thread is spinning (rclpy raises ``InvalidHandle`` there when an entity is destroyed while
    the executor waits on it)."""
    options = options or PlayOptions()
    stop = stop or threading.Event()
    reader = bag if isinstance(bag, BagReader) else open_bag(bag)
    try:
        return _play(reader, node, options, stop)
    finally:
        if reader is not bag:
            reader.close()


def _play(reader: BagReader, node: Node, options: PlayOptions, stop: threading.Event) -> PlayReport:
    info = reader.info
    topics = reader.select_topics(options.topics or None)
    publishers: dict[str, Publisher] = {}
    for name in topics:
        topic = info.topic(name)
        if topic.serialization_format != "cdr":
            raise BagError(f"{name}: cannot play serialization format {topic.serialization_format!r} (only cdr)")
        publishers[name] = node.create_publisher(
            message_class(topic.msgtype), name,
            playback_qos(topic.offered_qos, depth=options.qos_depth, reliability=options.reliability or None)
        )
    clock = _ClockPublisher(node, options.clock_hz)
    if options.wait_for_subscribers_s > 0:
        _wait_for_subscribers(publishers, options.wait_for_subscribers_s, stop)

    start_ns = info.start_ns + int(options.start_offset_s * 1e9)
    published: Counter[str] = Counter({t: 0 for t in topics})
    skipped = SkippedChunks()
    loops = 0
    bag_time_played_ns = 0
    wall_start: float | None = None  # wall and CPU time from the first message on
    cpu_start = 0.0
    while not stop.is_set():
        loops += 1
        first_ns: int | None = None
        last_ns = start_ns
        wall0 = time.monotonic()
        for msg in reader.messages(topics=topics, start_ns=start_ns, skipped=skipped):
            if first_ns is None:
                first_ns = msg.log_time_ns
                if loops == 1 and options.preroll_s > 0 and clock.publisher is not None:
                    _preroll(clock, first_ns, options, stop)
                    wall0 = time.monotonic()
                if wall_start is None:
                    wall_start, cpu_start = time.monotonic(), time.process_time()
                log.info("playing from bag time %d (loop %d)", first_ns, loops)
                clock.publish(first_ns)
            if options.rate > 0:
                target = wall0 + (msg.log_time_ns - first_ns) * 1e-9 / options.rate
                while (remaining := target - time.monotonic()) > 0 and not stop.is_set():
                    if clock.publisher is not None and time.monotonic() - clock.last_wall >= clock.period_s:
                        elapsed_bag_ns = int((time.monotonic() - wall0) * options.rate * 1e9)
                        clock.publish(first_ns + elapsed_bag_ns)
                    stop.wait(min(remaining, clock.period_s))
            if stop.is_set():
                break
            if msg.log_time_ns > last_ns or clock.last_wall == 0.0:
                clock.publish(msg.log_time_ns)
            publishers[msg.topic].publish(msg.data)
            published[msg.topic] += 1
            last_ns = msg.log_time_ns
        if first_ns is not None:
            bag_time_played_ns += last_ns - first_ns
        if not options.loop or first_ns is None or 0 < options.max_loops <= loops:
            break
    wall_s = time.monotonic() - wall_start if wall_start is not None else 0.0
    cpu_s = time.process_time() - cpu_start if wall_start is not None else 0.0

    acknowledged = True
    for name, pub in publishers.items():
        if pub.qos_profile.reliability == ReliabilityPolicy.RELIABLE and options.ack_timeout_s > 0:
            if not pub.wait_for_all_acked(Duration(seconds=options.ack_timeout_s)):
                log.warning("%s: not every message was acknowledged within %.1f s", name, options.ack_timeout_s)
                acknowledged = False
    for pub in publishers.values():
        node.destroy_publisher(pub)
    if clock.publisher is not None:
        node.destroy_publisher(clock.publisher)
    return PlayReport(
        published=dict(published),
        bag_duration_s=bag_time_played_ns * 1e-9,
        wall_duration_s=wall_s,
        loops=loops,
        acknowledged=acknowledged,
        interrupted=stop.is_set(),
        cpu_s=cpu_s,
        corrupt_chunks=tuple(skipped.chunks.values()),
    )
