"""Input stamps against the node's clock: refuse what comes from the future, notice time going back.

Nodes on real robots see three kinds of bad time: a stamp far ahead of the node's clock (another host's clock out
of sync, a driver bug), a stream going back a little (a reordered message) and a stream going back a lot (a bag
played again or looped, a restarted simulation). :class:`StampGuard` tells them apart for one input stream, with
the thresholds of :class:`~lightfast.node_options.StampOptions`; the node decides what a jump resets.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

from lightfast.node_options import StampOptions

__all__ = ["StampGuard", "StampVerdict"]


class StampVerdict(enum.Enum):
    OK = "ok"
    AHEAD = "ahead"  # more than max_stamp_ahead_s ahead of the clock: refuse, remember nothing
    OUT_OF_ORDER = "out of order"  # not after the previous stamp, by less than time_jump_back_s: drop
    JUMPED_BACK = "jumped back"  # before the previous stamp by more than time_jump_back_s: reset, then use it


@dataclass
class StampGuard:
    """Classifies the stamps of one input stream; remembers the newest accepted one.

    The clock ``now_ns`` is the node's (ROS time: sim time on ``use_sim_time``); ``now_ns <= 0`` (sim time before
    the first /clock message) skips the check against the clock.
    """

    options: StampOptions
    last_ns: int | None = None

    def check(self, stamp_ns: int, now_ns: int) -> StampVerdict:
        """The verdict on ``stamp_ns``; :meth:`accept` it once the input was used."""
        ahead_ns = round(self.options.max_stamp_ahead_s * 1e9)
        if ahead_ns > 0 and now_ns > 0 and stamp_ns - now_ns > ahead_ns:
            return StampVerdict.AHEAD
        if self.last_ns is not None and stamp_ns <= self.last_ns:
            if self.last_ns - stamp_ns <= round(self.options.time_jump_back_s * 1e9):
                return StampVerdict.OUT_OF_ORDER
            return StampVerdict.JUMPED_BACK
        return StampVerdict.OK

    def accept(self, stamp_ns: int) -> None:
        """``stamp_ns`` was used: it is the newest stamp now."""
        self.last_ns = int(stamp_ns)

    def clock_jumped_back(self, now_ns: int) -> bool:
        """After the node's clock jumped back to ``now_ns``: whether this stream's newest stamp lies beyond the
        new time (the stream still has to restart; then it is forgotten), or the data restarted already."""
        stale = self.last_ns is not None and self.last_ns - now_ns > round(self.options.time_jump_back_s * 1e9)
        if stale:
            self.last_ns = None
        return stale

    def reset(self) -> None:
        self.last_ns = None

    def describe(self, verdict: StampVerdict, stamp_ns: int, now_ns: int) -> str:
        """One line on a refused or jumping stamp, naming the option that decides."""
        if verdict is StampVerdict.AHEAD:
            return (f"stamped {(stamp_ns - now_ns) * 1e-9:.3f} s ahead of this node's clock (max_stamp_ahead_s "
                    f"{self.options.max_stamp_ahead_s:g}): clocks out of sync, or a bogus stamp; refused")
        if verdict is StampVerdict.OUT_OF_ORDER:
            return "not after the previous input's stamp (out of order); dropped"
        return f"stamp went back (more than time_jump_back_s {self.options.time_jump_back_s:g} s)"
