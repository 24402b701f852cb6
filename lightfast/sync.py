"""Pairing two message streams by stamp, like ``message_filters.TimeSynchronizer`` (not in the PyPI wheels): exactly,
or within a tolerance ``slop_ns`` for drivers that stamp the two streams apart (``ApproximateTimeSynchronizer``'s
"slop"; here the closest waiting partner within it is taken at once, which is unambiguous while the slop is below
half the frame period).

Nothing here imports rclpy; callers running callbacks on several threads hold their own lock around it.
"""
from __future__ import annotations

from collections import OrderedDict
from typing import Generic, TypeVar

__all__ = ["ExactTimePairs"]

A = TypeVar("A")
B = TypeVar("B")


class ExactTimePairs(Generic[A, B]):
    """Items of two streams (``first``, ``second``) matched by equal integer stamps (or, with ``slop_ns`` > 0, the
    waiting partner closest in stamp within ``slop_ns``), either side arriving first.

    Each side keeps at most ``capacity`` unmatched items; beyond that its oldest (by arrival) is dropped and
    counted in :attr:`dropped`. A second item with a stamp already waiting on the same side replaces it.
    """

    def __init__(self, capacity: int, slop_ns: int = 0) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        if slop_ns < 0:
            raise ValueError(f"slop_ns must be >= 0, got {slop_ns}")
        self.capacity = int(capacity)
        self.slop_ns = int(slop_ns)
        self._first: OrderedDict[int, A] = OrderedDict()
        self._second: OrderedDict[int, B] = OrderedDict()
        self.dropped = 0

    def __len__(self) -> int:
        """Unmatched items waiting on both sides."""
        return len(self._first) + len(self._second)

    def _add(self, own: OrderedDict, other: OrderedDict, stamp: int, item: object) -> object | None:
        if stamp in other:
            return other.pop(stamp)
        if self.slop_ns and other:
            closest = min(other, key=lambda s: abs(s - stamp))
            if abs(closest - stamp) <= self.slop_ns:
                return other.pop(closest)
        own[stamp] = item
        own.move_to_end(stamp)
        while len(own) > self.capacity:
            own.popitem(last=False)
            self.dropped += 1
        return None

    def add_first(self, stamp_ns: int, item: A) -> tuple[A, B] | None:
        """Add an item of the first stream; returns ``(item, partner)`` when its partner was waiting."""
        partner = self._add(self._first, self._second, int(stamp_ns), item)
        return None if partner is None else (item, partner)  # type: ignore[return-value]

    def add_second(self, stamp_ns: int, item: B) -> tuple[A, B] | None:
        """Add an item of the second stream; returns ``(partner, item)`` when its partner was waiting."""
        partner = self._add(self._second, self._first, int(stamp_ns), item)
        return None if partner is None else (partner, item)  # type: ignore[return-value]

    def clear(self) -> None:
        self._first.clear()
        self._second.clear()
