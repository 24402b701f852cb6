"""A node's worker thread: the heavy step of a node runs here, not in an executor callback.

Input callbacks only queue messages and :meth:`StepWorker.wake` the worker, so the executor keeps taking messages
off DDS while a frame is being processed (in a callback, later inputs waited in the DDS history behind each frame:
daylight_relight_node's coarse poses arrived 230 ms late). rclpy's MultiThreadedExecutor would do the same at about
a third of the process's CPU for its own bookkeeping.
"""
from __future__ import annotations

import threading
from collections.abc import Callable

__all__ = ["StepWorker"]


class StepWorker:
    """A daemon thread that runs ``step`` whenever woken, and every ``period_s()`` seconds if given, until
    :meth:`stop`.

    ``step`` returns whether work is left; it then runs again at once. An exception in a step goes to
    ``on_error`` and the worker carries on: a dead worker thread would silence its node without a word.
    """

    def __init__(self, name: str, step: Callable[[], bool], on_error: Callable[[Exception], None], *,
                 period_s: Callable[[], float] | None = None) -> None:
        self._step = step
        self._on_error = on_error
        self._period_s = period_s
        self._wake = threading.Event()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    @property
    def name(self) -> str:
        return self._thread.name

    def wake(self) -> None:
        """Run the step soon (again, if it is running now)."""
        self._wake.set()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop after the current step; wait up to ``timeout_s`` for it (not when called from the worker itself)."""
        self._stopping.set()
        self._wake.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=timeout_s)

    def _run(self) -> None:
        while not self._stopping.is_set():
            self._wake.wait(self._period_s() if self._period_s is not None else None)
            self._wake.clear()  # before the step: a wake-up during the step runs it again
            more = True
            while more and not self._stopping.is_set():
                try:
                    more = self._step()
                except Exception as exc:  # the safety net of the class docstring
                    if self._stopping.is_set():  # the node is going away: its publishers may be gone already
                        return
                    self._on_error(exc)
                    more = False
