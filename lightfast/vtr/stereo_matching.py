"""Left–right matching of a rectified stereo pair and sub-pixel disparities: the stereo step of the colour-constant
VT&R front end (paper §IV-B, Fig. 3–4), per image source. Pixels of the rectified images; d = u_left − u_right (px).

Two ways, chosen by ``StereoConfig.stereo_matching``; both enforce the epipolar and disparity constraints:

* **Row search** (``"search"``, the default; :func:`search_stereo`, a numba kernel): features in the left image only;
  each left keypoint (rounded to a pixel) is searched along its row of the right image over the integer disparities
  [max(``min_disparity_px``, 0), ``max_disparity_px``] by the ZNCC of (2·``search_radius_px``+1)² patches. A match is
  kept when its ZNCC is at least ``search_min_zncc``, unique (1 − best < ``search_uniqueness`` · (1 − the best more
  than 1 px away)), not correlating better one row up or down (epipolar) and left–right consistent (the right patch
  searched back along the left row lands within 1 px of the keypoint). Patches flatter than 2 grey levels (standard
  deviation) are not searched. It replaces the right-image detection, and relies on a correct rectification.
* **Descriptor matching** (``"descriptor"``; :func:`match_stereo`): features in both images; a pair (i, j) is
  admissible when |v_i − v_j| ≤ ``max_row_diff_px`` and ``min_disparity_px`` ≤ u_i − u_j ≤ ``max_disparity_px``
  (the raw column difference: with different principal points it includes cx_l − cx_r). Admissible pairs are listed
  without the N×M matrix (:func:`stereo_candidates`: right features sorted by row, binary search per left row band);
  the nearest admissible descriptor wins with Lowe's ratio (``ratio``) against the second nearest admissible one,
  the mutual check (``mutual``) and a largest distance (``orb_max_distance`` / ``sift_max_distance``: a feature
  often has a single admissible candidate, which passes any ratio test).

With ``subpixel`` the disparity is refined by 1-D block matching on the source image (:func:`refine_disparity`:
zero-mean SSD at round(d) ± ``subpixel_search_px``, ± 2 after the row search, a parabola, two Lucas–Kanade steps);
the front end drops matches whose refinement fails. Why the row search is the default, with measurements:
``docs/vtr.md``.
"""
from __future__ import annotations

import math
from typing import Final, cast

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

from lightfast.vtr.descriptor_matching import match_descriptors
from lightfast.vtr.errors import VtrInputError
from lightfast.vtr.features import Features
from lightfast.vtr.stereo_config import StereoConfig

__all__ = ["match_stereo", "refine_disparity", "search_stereo", "stereo_candidates"]

#: Patches flatter than this grey-level standard deviation are not searched (``stereo_matching="search"``).
_MIN_TEXTURE: Final = 2.0


def stereo_candidates(
    uv_left: NDArray[np.float32], uv_right: NDArray[np.float32], config: StereoConfig | None = None
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """All (left, right) index pairs that satisfy the epipolar and disparity constraints (module docstring),
    without forming the N×M matrix: right features sorted by row, the row band of every left feature found by
    binary search and expanded to pairs, then filtered by disparity."""
    c = config or StereoConfig()
    order = np.argsort(uv_right[:, 1], kind="stable")
    rows_r = uv_right[order, 1]
    lo = np.searchsorted(rows_r, uv_left[:, 1] - c.max_row_diff_px, side="left")
    hi = np.searchsorted(rows_r, uv_left[:, 1] + c.max_row_diff_px, side="right")
    counts = hi - lo
    total = int(counts.sum())
    il = np.repeat(np.arange(uv_left.shape[0]), counts)
    offsets = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    ir = order[np.repeat(lo, counts) + offsets]
    disparity = uv_left[il, 0] - uv_right[ir, 0]
    ok = (disparity >= c.min_disparity_px) & (disparity <= c.max_disparity_px)
    return il[ok], ir[ok]


def match_stereo(
    left: Features, right: Features, config: StereoConfig | None = None
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float32]]:
    """Left–right matches on rectified images under the epipolar and disparity constraints (module docstring).
    Returns indices into ``left`` and ``right`` and the descriptor distances."""
    c = config or StereoConfig()
    if left.kind != right.kind:
        raise VtrInputError(f"cannot match {left.kind} features with {right.kind} features")
    candidates = stereo_candidates(left.uv, right.uv, c)
    return match_descriptors(
        left.descriptors, right.descriptors, left.kind, ratio=c.ratio, mutual=c.mutual, candidates=candidates,
        max_distance=c.orb_max_distance if left.kind == "orb" else c.sift_max_distance,
    )


@numba.njit(cache=True, nogil=True, inline="always")
def _box_var(sum_b: NDArray[np.float64], sq_b: NDArray[np.float64], y0: int, x0: int, side: int) -> float:
    """Sum of squared deviations from the mean of the side×side patch at (y0, x0) (top-left), from the integral
    images of the values and their squares."""
    y1, x1 = y0 + side, x0 + side
    s1 = sum_b[y1, x1] - sum_b[y0, x1] - sum_b[y1, x0] + sum_b[y0, x0]
    s2 = sq_b[y1, x1] - sq_b[y0, x1] - sq_b[y1, x0] + sq_b[y0, x0]
    return s2 - s1 * s1 / (side * side)


@numba.njit(cache=True, nogil=True)
def _zncc_row_search(a: NDArray[np.float32], b: NDArray[np.float32], sum_b: NDArray[np.float64],
                     sq_b: NDArray[np.float64], us: NDArray[np.int64], vs: NDArray[np.int64], d_lo: int, d_hi: int,
                     r: int, direction: int, min_texture: float
                     ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """For each pixel (us[k], vs[k]) of image ``a``: the disparity d ∈ [d_lo, d_hi] whose patch of ``b`` at column
    us[k] + direction·d on the same rows has the highest ZNCC with the (2r+1)² patch of ``a``, that ZNCC and the
    highest ZNCC more than 1 px away from it (−2 where there is none). Patches of ``a`` flatter than
    ``min_texture`` (grey-level standard deviation), outside ``a``, without a candidate inside ``b``, or whose best
    patch of ``b`` correlates better one row up or down (rows not aligned: the epipolar constraint) give d = −1.
    ``sum_b`` / ``sq_b`` are the (H+1, W+1) integral images of ``b`` and ``b²``. The candidate columns are visited
    in ascending order in the innermost loop (vectorized by LLVM), one patch row at a time."""
    n = us.size
    h, w = a.shape
    side = 2 * r + 1
    npx = side * side
    best_d = np.full(n, -1, np.int64)
    best_z = np.full(n, -2.0)
    second_z = np.full(n, -2.0)
    patch = np.empty((side, side), np.float32)
    dot = np.empty(d_hi - d_lo + 1, np.float32)
    for k in range(n):
        u, v = us[k], vs[k]
        if v - r < 0 or v + r >= h or u - r < 0 or u + r >= w:
            continue
        # admissible patch centres in b, ascending: columns c = u + direction·d with r <= c < w - r
        if direction > 0:
            c0, c1 = u + d_lo, u + d_hi
        else:
            c0, c1 = u - d_hi, u - d_lo
        c0 = max(c0, r)
        c1 = min(c1, w - 1 - r)
        if c1 < c0:
            continue
        nc = c1 - c0 + 1
        mean = 0.0
        for i in range(side):
            for j in range(side):
                mean += a[v - r + i, u - r + j]
        mean /= npx
        var = 0.0
        for i in range(side):
            for j in range(side):
                x = a[v - r + i, u - r + j] - mean
                patch[i, j] = x
                var += x * x
        if var < min_texture * min_texture * npx:
            continue
        norm_a = math.sqrt(var)
        dot[:nc] = 0.0
        for i in range(side):
            row = b[v - r + i]
            for j in range(side):
                p = patch[i, j]
                seg = row[c0 - r + j:c0 - r + j + nc]  # a slice: its index q >= 0 needs no wraparound check
                for q in range(nc):
                    dot[q] += p * seg[q]
        best, arg = -2.0, -1
        for q in range(nc):
            var_b = _box_var(sum_b, sq_b, v - r, c0 + q - r, side)
            z = dot[q] / (norm_a * math.sqrt(var_b)) if var_b > 1e-6 else -2.0
            dot[q] = z
            if z > best:
                best, arg = z, q
        if arg < 0:
            continue
        second = -2.0
        for q in range(nc):
            if abs(q - arg) > 1 and dot[q] > second:
                second = dot[q]
        c = c0 + arg
        # epipolar check: the match must not correlate better one row up or down (misaligned rows)
        row_peak = True
        for dv in (-1, 1):
            y0 = v - r + dv
            if y0 < 0 or y0 + side > h:
                continue
            var_b = _box_var(sum_b, sq_b, y0, c - r, side)
            if var_b <= 1e-6:
                continue
            acc = 0.0
            for i in range(side):
                for j in range(side):
                    acc += patch[i, j] * b[y0 + i, c - r + j]
            if acc / (norm_a * math.sqrt(var_b)) > best:
                row_peak = False
        if not row_peak:
            continue
        best_d[k] = (c - u) * direction
        best_z[k] = best
        second_z[k] = second
    return best_d, best_z, second_z


def search_stereo(
    left: NDArray[np.uint8], right: NDArray[np.uint8], uv_left: NDArray[np.float32],
    config: StereoConfig | None = None,
) -> tuple[NDArray[np.intp], NDArray[np.float32], NDArray[np.float32]]:
    """Left–right matches of left keypoints by ZNCC block matching along their rows of the right image (rectified
    pair; ``stereo_matching="search"``): for each keypoint (rounded to a pixel) the integer disparity in
    [max(``min_disparity_px``, 0), ``max_disparity_px``] with the highest ZNCC of the (2·``search_radius_px``+1)²
    patches, kept when that ZNCC is at least ``search_min_zncc``, higher than at the same column one row up and
    down (epipolar), unique (1 − best < ``search_uniqueness`` · (1 − best more than 1 px away)) and left–right
    consistent (searching the right patch back along the left row lands within 1 px of the keypoint). Returns the
    indices of the matched keypoints, their integer disparities and 1 − ZNCC (the match's distance);
    :func:`refine_disparity` makes them sub-pixel."""
    c = config or StereoConfig()
    if left.shape != right.shape or left.ndim != 2:
        raise VtrInputError(f"search_stereo needs two (H, W) images of one size, got {left.shape} and {right.shape}")
    n = uv_left.shape[0]
    d_lo, d_hi = max(math.ceil(c.min_disparity_px), 0), math.floor(c.max_disparity_px)
    if n == 0 or d_hi < d_lo:
        return np.zeros(0, np.intp), np.zeros(0, np.float32), np.zeros(0, np.float32)
    r = c.search_radius_px
    a, b = left.astype(np.float32), right.astype(np.float32)
    us = np.rint(uv_left[:, 0]).astype(np.int64)
    vs = np.rint(uv_left[:, 1]).astype(np.int64)
    sum_r, sq_r = cast(tuple[NDArray[np.float64], NDArray[np.float64]],
                       cv2.integral2(right, sdepth=cv2.CV_64F, sqdepth=cv2.CV_64F))
    d, z, second = _zncc_row_search(a, b, sum_r, sq_r, us, vs, d_lo, d_hi, r, -1, _MIN_TEXTURE)
    ok = (d >= 0) & (z >= c.search_min_zncc) & (1.0 - z < c.search_uniqueness * (1.0 - second))
    idx = np.flatnonzero(ok)
    if idx.size:  # left-right consistency: the right patch searched back along the left row
        sum_l, sq_l = cast(tuple[NDArray[np.float64], NDArray[np.float64]],
                           cv2.integral2(left, sdepth=cv2.CV_64F, sqdepth=cv2.CV_64F))
        back, _, _ = _zncc_row_search(b, a, sum_l, sq_l, us[idx] - d[idx], vs[idx], d_lo, d_hi, r, 1, _MIN_TEXTURE)
        idx = idx[(back >= 0) & (np.abs(back - d[idx]) <= 1)]
    return idx.astype(np.intp), d[idx].astype(np.float32), (1.0 - z[idx]).astype(np.float32)


def _lerp_columns(strip: NDArray[np.float32], idx: NDArray[np.intp], f: NDArray[np.float32]) -> NDArray[np.float32]:
    """Linear interpolation along the last axis of ``strip`` (N, P, S) at columns ``idx + f`` (idx: (N, 1, Q)
    integer start columns, f: (N, 1, 1) fractions), (N, P, Q)."""
    n, p, width = strip.shape
    flat = (np.arange(n * p, dtype=np.intp) * width).reshape(n, p, 1) + idx  # (N, P, Q) indices into the ravel
    a = np.take(strip, flat)
    b = np.take(strip, flat + 1)
    b -= a
    b *= f
    a += b
    return a


def refine_disparity(
    left: NDArray[np.uint8],
    right: NDArray[np.uint8],
    uv_left: NDArray[np.float32],
    disparity: NDArray[np.float32],
    radius: int = 3,
    search: int = 2,
    iterations: int = 2,
) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Sub-pixel disparities by 1-D block matching on rectified images, vectorized over all matches.

    For each match the (2·radius+1)² patch of ``left`` centred at the rounded left keypoint is compared (zero-mean
    SSD) with the patches of ``right`` on the same rows at disparities round(d) + k, k ∈ [−search, search]; a
    parabola through the best k and its neighbours gives the sub-pixel start, and ``iterations`` 1-D Gauss–Newton
    (Lucas–Kanade) steps on the linearly interpolated right patch remove the parabola's pixel-locking bias.
    The disparity found is that of the rounded left pixel, used for the keypoint (locally constant disparity).
    Returns the refined disparities and a mask of refined matches; the others keep their input disparity (patch
    outside an image, best k at the edge of the search range, flat cost, or a Gauss–Newton step beyond 1 px).
    """
    h, w = left.shape
    n = uv_left.shape[0]
    if n == 0:
        return disparity.astype(np.float32, copy=True), np.zeros(0, bool)
    u0 = np.rint(uv_left[:, 0]).astype(np.intp)
    v0 = np.rint(uv_left[:, 1]).astype(np.intp)
    d0 = np.rint(disparity).astype(np.intp)
    offs = np.arange(-radius, radius + 1)
    ks = np.arange(-search, search + 1)
    inside = (
        (v0 - radius >= 0) & (v0 + radius < h) & (u0 - radius >= 0) & (u0 + radius < w)
        & (u0 - d0 - search - radius - 1 >= 0) & (u0 - d0 + search + radius + 1 < w)
    )
    # Everything is read from two small gathers (no whole-image conversions): the left patch (N, P, P) and a strip
    # of the right image around round(d) on the same rows, (N, P, S), wide enough for the block matching over ks
    # and the Gauss-Newton steps (the local column of right column u0 - d + o is m0 + o - (d - d0)).
    m0 = search + radius + 3
    width = 2 * m0 + 1
    rows_v = np.clip(v0[:, None] + offs[None, :], 0, h - 1) * w  # (N, P) flat row offsets
    lp = left.reshape(-1)[rows_v[:, :, None] + np.clip(u0[:, None, None] + offs, 0, w - 1)].astype(np.float32)
    lp -= lp.mean(axis=(1, 2), keepdims=True)
    cols = np.clip((u0 - d0 - m0)[:, None] + np.arange(width)[None, :], 0, w - 1)  # (N, S)
    strip = right.reshape(-1)[rows_v[:, :, None] + cols[:, None, :]].astype(np.float32)  # (N, P, S)
    # block matching: right column u0 - (d0 + k) + o has the local column m0 - k + o
    rp = np.stack([strip[:, :, m0 - k - radius:m0 - k + radius + 1] for k in ks], axis=1)  # (N, K, P, P)
    rp -= rp.mean(axis=(2, 3), keepdims=True)
    rp -= lp[:, None]
    cost = np.einsum("nkij,nkij->nk", rp, rp)  # (N, K) zero-mean SSD
    kbest = np.argmin(cost, axis=1)
    interior = (kbest > 0) & (kbest < ks.size - 1)
    kc = np.clip(kbest, 1, ks.size - 2)
    rows = np.arange(n)
    cm, c0, cp = cost[rows, kc - 1], cost[rows, kc], cost[rows, kc + 1]
    denom = cm - 2.0 * c0 + cp
    ok = inside & interior & (denom > 1e-6)
    d = (d0 + ks[kc]).astype(np.float64) + np.where(ok, 0.5 * (cm - cp) / np.where(ok, denom, 1.0), 0.0)
    d_start = d.copy()
    # central-difference gradient of the strip (linear interpolation of it = difference of interpolated neighbours)
    grad = np.zeros_like(strip)
    grad[:, :, 1:-1] = 0.5 * (strip[:, :, 2:] - strip[:, :, :-2])
    for _ in range(iterations):
        x = m0 - radius - (d - d0)  # local column of the patch's first pixel, per match
        i0 = np.clip(np.floor(x).astype(np.intp), 0, width - 2 * radius - 2)
        f = (x - i0).astype(np.float32)[:, None, None]
        idx = (i0[:, None] + np.arange(2 * radius + 1)[None, :])[:, None, :]  # (N, 1, P)
        rs = _lerp_columns(strip, idx, f)
        gs = _lerp_columns(grad, idx, f)
        rs -= rs.mean(axis=(1, 2), keepdims=True)
        gs -= gs.mean(axis=(1, 2), keepdims=True)
        r = rs - lp  # residual; d(r)/d(d) = -gx
        hess = np.einsum("nij,nij->n", gs, gs)
        step = np.where(hess > 1e-6, np.einsum("nij,nij->n", gs, r) / np.maximum(hess, 1e-6), 0.0)
        d = np.where(ok, d + step, d)
    ok &= np.abs(d - d_start) <= 1.0
    out = np.where(ok, d, disparity).astype(np.float32)
    return out, ok
