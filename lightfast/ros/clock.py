"""The node clock going back: a callback when ROS time jumps backwards (``/clock`` of a bag played again or looped,
a restarted simulation), through rcl's time-jump mechanism (as tf2's buffer clears itself on it)."""
from __future__ import annotations

import threading
from collections.abc import Callable

from rclpy.clock import JumpHandle, JumpThreshold, TimeJump
from rclpy.duration import Duration
from rclpy.node import Node

__all__ = ["ClockJumpLatch", "on_time_jump_back"]


def on_time_jump_back(node: Node, threshold_s: float, callback: Callable[[int, int], None]) -> JumpHandle:
    """Call ``callback(now_ns, jump_ns)`` (``jump_ns`` < 0) after the node's clock jumps back by more than
    ``threshold_s`` (at least 1 ns). Keep the returned handle as long as the node: dropping it unregisters.
    Runs in the thread that sets the clock (the executor's, for /clock): do little, hand work to a worker."""
    threshold = JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-max(1, round(threshold_s * 1e9))),
                              on_clock_change=False)
    clock = node.get_clock()

    def post(jump: TimeJump) -> None:
        callback(clock.now().nanoseconds, jump.delta.nanoseconds)

    return clock.create_jump_callback(threshold, post_callback=post)


class ClockJumpLatch:
    """The node clock's latest jump back, kept for a worker thread: the jump callback (in the thread that sets the
    clock) stores the new time and calls ``wake``; the worker :meth:`take` s it between two steps."""

    def __init__(self, node: Node, threshold_s: float, wake: Callable[[], None]) -> None:
        self._lock = threading.Lock()
        self._now_ns: int | None = None
        self._wake = wake
        self._handle = on_time_jump_back(node, threshold_s, self._on_jump)

    def _on_jump(self, now_ns: int, jump_ns: int) -> None:
        with self._lock:
            self._now_ns = now_ns
        self._wake()

    def take(self) -> int | None:
        """The node clock after its latest jump back since the last call, or ``None``."""
        with self._lock:
            now_ns, self._now_ns = self._now_ns, None
        return now_ns
