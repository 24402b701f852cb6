"""Compare two bags topic by topic: message counts and whether the serialized payloads are identical.

Used by the round-trip tests (record → play → record must give byte-identical CDR payloads) and by the demo's
summary line (messages received versus played, drops).
"""
from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable
from dataclasses import dataclass

from lightfast.bag.reader import open_bag


@dataclass(frozen=True)
class TopicComparison:
    """One topic in both bags: counts, rates, and whether the payload sequences are byte-identical."""

    topic: str
    msgtype: str
    count_a: int
    count_b: int
    rate_a_hz: float
    rate_b_hz: float
    identical_payloads: bool
    first_mismatch: int | None  # index of the first differing payload, if any

    @property
    def dropped(self) -> int:
        return max(0, self.count_a - self.count_b)


@dataclass(frozen=True)
class BagComparison:
    topics: tuple[TopicComparison, ...]
    only_in_a: tuple[str, ...]
    only_in_b: tuple[str, ...]

    @property
    def identical(self) -> bool:
        """Same topics, same counts and the same payload bytes in the same order on every topic."""
        return not self.only_in_a and not self.only_in_b and all(
            t.identical_payloads and t.count_a == t.count_b for t in self.topics
        )

    @property
    def dropped(self) -> int:
        return sum(t.dropped for t in self.topics)

    def summary(self) -> str:
        """One line: per topic received/played counts and rates, total drops, payload identity."""
        parts = [
            f"{t.topic} {t.count_b}/{t.count_a} @ {t.rate_b_hz:.1f} Hz" + ("" if t.identical_payloads else " (differs)")
            for t in self.topics
        ]
        missing = [f"{name} 0/?" for name in self.only_in_a]
        total_a = sum(t.count_a for t in self.topics)
        total_b = sum(t.count_b for t in self.topics)
        verdict = "payloads identical" if self.identical else "payloads differ"
        return (
            f"{total_b}/{total_a} messages on {len(self.topics)} topics, {self.dropped} dropped, {verdict}: "
            + "; ".join(parts + missing)
        )


def _digests(path: str | os.PathLike[str], topics: Iterable[str]) -> tuple[dict[str, list[bytes]], dict[str, float]]:
    with open_bag(path) as bag:
        names = list(topics)
        digests: dict[str, list[bytes]] = {t: [] for t in names}
        first: dict[str, int] = {}
        last: dict[str, int] = {}
        for m in bag.messages(topics=names):
            digests[m.topic].append(hashlib.blake2b(m.data, digest_size=16).digest())
            first.setdefault(m.topic, m.log_time_ns)
            last[m.topic] = m.log_time_ns
    rates = {
        t: (len(d) - 1) / ((last[t] - first[t]) * 1e-9) if len(d) > 1 and last[t] > first[t] else 0.0
        for t, d in digests.items()
    }
    return digests, rates


def compare_bags(
    a: str | os.PathLike[str], b: str | os.PathLike[str], *, topics: Iterable[str] | None = None
) -> BagComparison:
    """Compare bag ``a`` (reference, e.g. what was played) with ``b`` (e.g. what was recorded)."""
    with open_bag(a) as bag_a, open_bag(b) as bag_b:
        types_a = {t.name: t.msgtype for t in bag_a.info.topics}
        types_b = {t.name: t.msgtype for t in bag_b.info.topics}
    selected = list(topics) if topics is not None else sorted(types_a)
    common = [t for t in selected if t in types_a and t in types_b]
    da, ra = _digests(a, common)
    db, rb = _digests(b, common)
    rows = []
    for t in common:
        mismatch = next((i for i, (x, y) in enumerate(zip(da[t], db[t], strict=False)) if x != y), None)
        rows.append(
            TopicComparison(
                topic=t,
                msgtype=types_a[t],
                count_a=len(da[t]),
                count_b=len(db[t]),
                rate_a_hz=ra[t],
                rate_b_hz=rb[t],
                identical_payloads=mismatch is None and len(da[t]) == len(db[t]),
                first_mismatch=mismatch,
            )
        )
    return BagComparison(
        topics=tuple(rows),
        only_in_a=tuple(t for t in selected if t in types_a and t not in types_b),
        only_in_b=tuple(sorted(t for t in types_b if t not in types_a)) if topics is None else (),
    )
