"""Pairing two streams by stamp (lightfast.sync): exactly, or within a slop for drivers that stamp them apart."""
from __future__ import annotations

import pytest

from lightfast.sync import ExactTimePairs

MS = 1_000_000


def test_exact_pairs_in_either_order_and_the_oldest_unmatched_are_dropped() -> None:
    pairs: ExactTimePairs[str, str] = ExactTimePairs(capacity=2)
    assert pairs.add_first(10, "c10") is None
    assert pairs.add_second(10, "d10") == ("c10", "d10")
    assert pairs.add_second(20, "d20") is None
    assert pairs.add_first(20, "c20") == ("c20", "d20")
    assert pairs.add_first(21, "c21") is None  # 1 ns apart is not the same stamp
    assert pairs.add_second(22, "d22") is None and len(pairs) == 2
    for s in (30, 40):
        pairs.add_first(s, f"c{s}")
    assert pairs.dropped == 1 and pairs.add_second(21, "d21") is None  # c21 was the oldest: gone


def test_with_a_slop_the_closest_partner_within_it_is_taken() -> None:
    pairs: ExactTimePairs[str, str] = ExactTimePairs(capacity=10, slop_ns=10 * MS)
    assert pairs.add_first(100 * MS, "c100") is None
    assert pairs.add_first(133 * MS, "c133") is None
    assert pairs.add_second(137 * MS, "d137") == ("c133", "d137")  # c133 is 4 ms away, c100 37 ms
    assert pairs.add_second(111 * MS, "d111") is None  # 11 ms from c100: beyond the slop
    assert pairs.add_second(95 * MS, "d95") == ("c100", "d95")
    assert pairs.add_first(166 * MS, "c166") is None and len(pairs) == 2  # d111 and c166 wait


def test_a_negative_slop_is_refused() -> None:
    with pytest.raises(ValueError, match="slop_ns"):
        ExactTimePairs(capacity=1, slop_ns=-1)
