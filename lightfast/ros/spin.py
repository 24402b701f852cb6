"""Spinning helpers: wait on a condition while an executor processes callbacks, never with bare sleeps."""
from __future__ import annotations

import time
from collections.abc import Callable

from rclpy.executors import Executor


def spin_until(
    executor: Executor, predicate: Callable[[], bool], timeout_s: float, *, step_s: float = 0.01
) -> bool:
    """Spin ``executor`` until ``predicate()`` holds or ``timeout_s`` passes; return the predicate's last value."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        remaining = deadline - time.monotonic()
        if remaining <= 0.0:
            return bool(predicate())
        executor.spin_once(timeout_sec=min(step_s, remaining))
    return True
