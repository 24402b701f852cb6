"""Descriptor distances and nearest-neighbour matching of colour-constant VT&R (paper §IV-B, Fig. 3–4), shared by
the left–right stereo matching, the VO and the map localization.

Distances between descriptor sets a (N, D) and b (M, D): Hamming for ORB (packed uint8 bits; XOR and popcount of
64-bit words, a jitted kernel for listed pairs), Euclidean for SIFT (float32); :func:`descriptor_distances` gives
all N×M of them, :func:`pair_distances` those of candidate pairs only.

:func:`match_descriptors`: over all pairs or over candidate pairs (e.g. those admissible under the epipolar and
disparity constraints, or within a radius of a predicted pixel), the nearest b of each a is kept when it passes
Lowe's ratio test against the second-nearest candidate, the mutual check (a is also the nearest of b) and a largest
distance. Outputs: index arrays into a and b and the distances (float32; bits for ORB). :class:`NearestMatches`
keeps the per-row and per-column parts of an all-pairs matching, so that the mutual matches of several descriptor
sets matched together are combined without matching again (the whole-map search matches each keyframe once and
combines the matches per keyframe window).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, cast

import numba
import numpy as np
from numpy.typing import NDArray

from lightfast.vtr.errors import VtrInputError

__all__ = ["NearestMatches", "descriptor_distances", "match_descriptors", "pair_distances"]

_POPCOUNT: Final = np.unpackbits(np.arange(256, dtype=np.uint8)[:, None], axis=1).sum(axis=1).astype(np.float32)


def descriptor_distances(a: NDArray[np.generic], b: NDArray[np.generic], kind: str) -> NDArray[np.float32]:
    """All pairwise descriptor distances (N, M), float32: Euclidean for ``"sift"`` (one matrix product), Hamming
    for ``"orb"`` (packed uint8 bits: XOR and popcount of 64-bit words, broadcast over all pairs)."""
    if kind == "orb":
        _check_orb(a, b)
        if a.shape[1] % 8 == 0:
            wa = np.ascontiguousarray(a).view(np.uint64)
            wb = np.ascontiguousarray(b).view(np.uint64)
            d = np.zeros((len(a), len(b)), np.uint16)
            for k in range(wa.shape[1]):  # over the 64-bit words of a descriptor (4 for ORB), not over features
                d += np.bitwise_count(wa[:, k, None] ^ wb[None, :, k])
            return d.astype(np.float32)
        ba = np.unpackbits(cast(NDArray[np.uint8], a), axis=1).astype(np.float32)  # uint8: _check_orb
        bb = np.unpackbits(cast(NDArray[np.uint8], b), axis=1).astype(np.float32)
        return np.rint(ba.sum(axis=1)[:, None] + bb.sum(axis=1)[None, :] - 2.0 * (ba @ bb.T)).astype(np.float32)
    if kind == "sift":
        fa, fb = a.astype(np.float32, copy=False), b.astype(np.float32, copy=False)
        d2 = (fa * fa).sum(axis=1)[:, None] + (fb * fb).sum(axis=1)[None, :] - 2.0 * (fa @ fb.T)
        return np.sqrt(np.maximum(d2, 0.0)).astype(np.float32, copy=False)
    raise VtrInputError(f"unknown descriptor kind {kind!r}")


def pair_distances(
    a: NDArray[np.generic], b: NDArray[np.generic], ia: NDArray[np.intp], ib: NDArray[np.intp], kind: str
) -> NDArray[np.float32]:
    """Descriptor distances of the pairs (a[ia[k]], b[ib[k]]) only (Hamming by XOR and popcount of 64-bit words,
    or Euclidean)."""
    if kind == "orb":
        _check_orb(a, b)
        if a.shape[1] % 8 == 0:
            wa = np.ascontiguousarray(a).view(np.uint64)
            wb = np.ascontiguousarray(b).view(np.uint64)
            return _hamming_pairs(wa, wb, np.asarray(ia, np.int64), np.asarray(ib, np.int64))
        return _POPCOUNT[np.bitwise_xor(a[ia], b[ib])].sum(axis=1)
    if kind == "sift":
        diff = a[ia].astype(np.float32, copy=False) - b[ib].astype(np.float32, copy=False)
        return np.sqrt(np.einsum("ij,ij->i", diff, diff)).astype(np.float32, copy=False)
    raise VtrInputError(f"unknown descriptor kind {kind!r}")


@numba.njit(cache=True, nogil=True)
def _hamming_pairs(wa: NDArray[np.uint64], wb: NDArray[np.uint64], ia: NDArray[np.int64], ib: NDArray[np.int64]
                   ) -> NDArray[np.float32]:
    """Hamming distances of the descriptor pairs (wa[ia[k]], wb[ib[k]]) (64-bit words; SWAR popcount), without
    gathering the pairs' descriptors into temporary arrays."""
    out = np.empty(ia.size, np.float32)
    m1, m2, m4 = np.uint64(0x5555555555555555), np.uint64(0x3333333333333333), np.uint64(0x0F0F0F0F0F0F0F0F)
    h01 = np.uint64(0x0101010101010101)
    for k in range(ia.size):
        x, y = wa[ia[k]], wb[ib[k]]
        total = 0
        for t in range(wa.shape[1]):
            v = x[t] ^ y[t]
            v = v - ((v >> np.uint64(1)) & m1)
            v = (v & m2) + ((v >> np.uint64(2)) & m2)
            v = (v + (v >> np.uint64(4))) & m4
            total += int((v * h01) >> np.uint64(56))
        out[k] = total
    return out


def _check_orb(a: NDArray[np.generic], b: NDArray[np.generic]) -> None:
    if a.dtype != np.uint8 or b.dtype != np.uint8:
        raise VtrInputError("ORB descriptors must be packed uint8 bits")


def _select_matches(
    ia: NDArray[np.intp], ib: NDArray[np.intp], d: NDArray[np.float32], m: int, ratio: float, mutual: bool
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float32]]:
    """Nearest neighbour + ratio test + mutual check over candidate pairs (ia, ib, d), vectorized by sorting
    single int64 keys: (a-index, distance) for the nearest and second-nearest neighbour of every a, (b-index,
    distance, a-index) for the nearest a of every b (ties: the smallest a-index). Distances enter the keys as
    integers: Hamming distances as they are, others by their rank."""
    if ia.size == 0:
        return ia.astype(np.intp), ib.astype(np.intp), d.astype(np.float32)
    dk = d.astype(np.int64)
    if not np.array_equal(dk, d):  # non-integer distances (SIFT): their ranks keep the order and the ties
        _, dk = np.unique(d, return_inverse=True)
        dk = dk.astype(np.int64).reshape(-1)
    big = int(dk.max()) + 2
    na = int(ia.max()) + 1
    ia64, ib64 = ia.astype(np.int64), ib.astype(np.int64)
    order = np.argsort(ia64 * big + dk)
    ia_s, ib_s, d_s = ia[order], ib[order], d[order]
    first = np.flatnonzero(np.r_[True, ia_s[1:] != ia_s[:-1]])
    nxt = first + 1
    has_second = nxt < ia_s.size
    has_second[has_second] = ia_s[nxt[has_second]] == ia_s[first[has_second]]
    d2 = np.full(first.size, np.inf, np.float32)
    d2[has_second] = d_s[nxt[has_second]]
    i, j, d1 = ia_s[first], ib_s[first], d_s[first]
    keep = d1 < np.float32(ratio) * d2  # no second candidate: passes; ties fail
    if mutual:
        if float(m) * big * na < 2.0**62:
            order_b = np.argsort((ib64 * big + dk) * na + ia64)
        else:  # keys would overflow int64
            order_b = np.lexsort((ia, dk, ib))
        ib_b = ib[order_b]
        firsts_b = order_b[np.r_[True, ib_b[1:] != ib_b[:-1]]]
        best_a_of_b = np.full(m, -1, np.intp)
        best_a_of_b[ib[firsts_b]] = ia[firsts_b]
        keep &= best_a_of_b[j] == i
    return i[keep], j[keep], d1[keep]


@dataclass(frozen=True)
class NearestMatches:
    """All-pairs (unguided) nearest neighbours from descriptor set ``a`` (N, D) to ``b`` (M, D): per row of ``a`` its
    nearest ``b`` (``best``), that distance (``d1``) and whether it passes the ratio test and the distance limit
    (``ok``); per ``b`` its nearest row of ``a`` (``col_arg``, first on ties) and that distance (``col_min``, inf
    without rows). The mutual check needs the rows of every set matched together, which :meth:`mutual` computes
    from the parts: a row's nearest ``b`` and ratio test do not depend on the other rows."""

    best: NDArray[np.intp]
    d1: NDArray[np.float32]
    ok: NDArray[np.bool_]
    col_min: NDArray[np.float32]
    col_arg: NDArray[np.intp]

    @classmethod
    def of(cls, a: NDArray[np.generic], b: NDArray[np.generic], kind: str, *, ratio: float,
           max_distance: float) -> NearestMatches:
        n, m = len(a), len(b)
        if n == 0 or m == 0:
            return cls(np.zeros(n, np.intp), np.full(n, np.inf, np.float32), np.zeros(n, bool),
                       np.full(m, np.inf, np.float32), np.zeros(m, np.intp))
        d = descriptor_distances(a, b, kind)
        best = np.argmin(d, axis=1)
        d1 = d[np.arange(n), best]
        ok = d1 <= max_distance
        if m >= 2:
            ok &= d1 < np.float32(ratio) * np.partition(d, 1, axis=1)[:, 1]
        col_arg = np.argmin(d, axis=0)
        return cls(best, d1, ok, d[col_arg, np.arange(m)], col_arg)

    @staticmethod
    def mutual(parts: Sequence[NearestMatches]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Mutual matches ``(rows, b indices)`` of the parts' rows concatenated in order (all against the same
        ``b``): exactly those of matching the concatenation at once — a ``b``'s nearest row is the nearest of the
        parts' nearest ones, the first part on ties as ``argmin`` over the concatenation."""
        best = np.concatenate([p.best for p in parts])
        ok = np.concatenate([p.ok for p in parts])
        if not ok.any():
            return np.zeros(0, np.intp), np.zeros(0, np.intp)
        offsets = np.cumsum([0] + [len(p.best) for p in parts])
        col_min = np.stack([p.col_min for p in parts])
        first = np.argmin(col_min, axis=0)
        nearest_row = offsets[first] + np.stack([p.col_arg for p in parts])[first, np.arange(col_min.shape[1])]
        keep = ok & (nearest_row[best] == np.arange(best.size))
        return np.flatnonzero(keep), best[keep]


def match_descriptors(
    a: NDArray[np.generic],
    b: NDArray[np.generic],
    kind: str,
    *,
    ratio: float = 0.8,
    mutual: bool = True,
    candidates: tuple[NDArray[np.intp], NDArray[np.intp]] | None = None,
    max_distance: float = math.inf,
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float32]]:
    """Nearest-neighbour matches from descriptor set ``a`` (N, D) to ``b`` (M, D).

    Only the ``candidates`` pairs (index arrays into ``a`` and ``b``; default: all N·M pairs, by one matrix
    product) are considered. A match (i, j) is kept when its distance is below ``ratio`` times the second-nearest
    candidate distance of i (no second candidate: passes), with ``mutual`` when i is also j's nearest candidate,
    and when its distance is at most ``max_distance``. Returns indices into ``a`` and ``b`` and the distances,
    ordered by i.

    With candidates and a finite ``max_distance``, pairs farther than ``max_distance / ratio`` are dropped before
    the selection; the result is the same (such a pair can neither be a kept match nor decide one: as a second
    nearest it passes the ratio test of any kept match, and a j whose nearest i is that far has no kept match),
    but the sorting handles far fewer pairs (most candidate pairs of guided matching are unrelated features).
    """
    n, m = len(a), len(b)
    if n == 0 or m == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0, np.float32)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
        raise VtrInputError(f"descriptor shapes {a.shape} and {b.shape} do not match")
    if candidates is None:
        nearest = NearestMatches.of(a, b, kind, ratio=ratio, max_distance=max_distance)
        if mutual:
            i, j = NearestMatches.mutual([nearest])
            return i, j, nearest.d1[i]
        i = np.flatnonzero(nearest.ok)
        return i, nearest.best[i], nearest.d1[i]
    ia, ib = (np.asarray(c, dtype=np.intp) for c in candidates)
    if ia.shape != ib.shape or ia.ndim != 1:
        raise VtrInputError("candidates must be two index arrays of the same length")
    if ia.size and (ia.min() < 0 or ia.max() >= n or ib.min() < 0 or ib.max() >= m):
        raise VtrInputError("candidate indices out of range")
    d = pair_distances(a, b, ia, ib, kind)
    if math.isfinite(max_distance) and ratio > 0.0:
        near = d <= max_distance / ratio
        ia, ib, d = ia[near], ib[near], d[near]
    i, j, d1 = _select_matches(ia, ib, d, m, ratio, mutual)
    keep = d1 <= max_distance
    return i[keep], j[keep], d1[keep]
