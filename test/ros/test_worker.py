"""The nodes' worker thread (lightfast.ros.worker)."""
from __future__ import annotations

import threading
import time

from lightfast.ros.worker import StepWorker


def wait_for(predicate, timeout_s: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.005)
    return False


def test_worker_steps_until_no_work_is_left_and_survives_errors() -> None:
    queue = [1, 2, "bad", 3]
    done: list[int] = []
    errors: list[Exception] = []

    def step() -> bool:
        item = queue.pop(0)
        if item == "bad":
            raise ValueError("bad item")
        done.append(item)
        return bool(queue)

    worker = StepWorker("test-worker", step, errors.append)
    assert not done  # nothing runs before a wake-up
    worker.wake()
    assert wait_for(lambda: done == [1, 2] and len(errors) == 1)
    assert isinstance(errors[0], ValueError) and worker.name == "test-worker"
    worker.wake()  # the error ended that round; the worker still runs the next
    assert wait_for(lambda: done == [1, 2, 3])
    worker.stop()
    assert not any(t.name == "test-worker" for t in threading.enumerate())


def test_periodic_worker_runs_without_wake_ups_and_stops_promptly() -> None:
    calls: list[float] = []

    def tick() -> bool:
        calls.append(time.monotonic())
        return False

    worker = StepWorker("ticker", tick, lambda exc: None, period_s=lambda: 0.02)
    assert wait_for(lambda: len(calls) >= 3)
    t0 = time.monotonic()
    worker.stop()
    assert time.monotonic() - t0 < 1.0


def test_a_step_failing_after_stop_is_not_reported() -> None:
    """A step still running when the node stops may fail on its dead context; that is not an error to report."""
    release, errors = threading.Event(), []

    def step() -> bool:
        release.wait(5.0)
        raise RuntimeError("publisher's context is invalid")

    worker = StepWorker("stopping", step, errors.append)
    worker.wake()
    time.sleep(0.05)
    worker.stop(timeout_s=0.05)  # the step is still inside
    release.set()
    assert wait_for(lambda: not any(t.name == "stopping" for t in threading.enumerate()))
    assert errors == []
