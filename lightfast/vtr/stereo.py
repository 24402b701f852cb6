"""Stereo front end of colour-constant VT&R: paper §IV-B (Fig. 3 and Fig. 4), per image source.

Per rectified stereo pair and per image source (greyscale, F_v, F_r of :mod:`lightfast.vtr.color_constant`):
features are extracted in the left and right image, matched left to right under the epipolar and disparity
constraints of rectified images, and triangulated into 3-D landmarks in the left camera frame (metres) — the
"3D keypoints" that Fig. 3/4 then match against the map.

Features
--------
The paper uses SURF, which is non-free and absent from the pip OpenCV wheels. SIFT and ORB were measured on this
machine (2 shared cores, loaded; OpenCV 4.14) — the default is **ORB**, for speed:

* speed: detect + describe one 640×471 / 704×547 image: ORB 18–23 ms, SIFT 147–207 ms (median,
  ``benchmarks/results/vtr_timelapse.md``); this front end on one 640×480 pair with three sources (6 images,
  matching, refinement, triangulation): ORB 0.20–0.24 s, SIFT 0.9–1.2 s. The issue's goal of ≥ 10 Hz for VO plus
  three-source localization on 2 cores is out of reach with SIFT (six extractions alone take ~1 s);
* repeatability across lighting (real webcam time-lapse, 2005 image pairs, 1000 features, correct = same pixel
  ± 4 px): mean correct matches per pair, all pairs, ORB vs SIFT: grey 98.2 vs 87.6, F_v 2.9 vs 1.2, F_r 4.9 vs
  1.4 (fixed 8-bit mapping); but on the quarter of pairs with the largest lighting change SIFT holds up better on
  greyscale: 35.7 vs 26.8 correct, 5 % vs 28 % of pairs below the paper's 6 matches;
* stereo accuracy on the synthetic pair of ``test/unit/vtr/test_stereo.py`` (with the sub-pixel refinement
  below; disparities 8–48 px): median depth error 0.16–0.19 % (ORB) and 0.12–0.14 % (SIFT), 95th percentile
  ~0.6 % and largest 2 % for both.

SIFT stays selectable (``feature="sift"``) where robustness to extreme lighting matters more than the frame rate;
with SIFT prefer ``ColorConstantConfig(normalization="percentile")`` (see :mod:`lightfast.vtr.color_constant`).

Left–right matching
-------------------
Two ways, chosen by ``stereo_matching``; both enforce the epipolar and disparity constraints of rectified images.

**Row search** (``"search"``, the default; :func:`search_stereo`, a numba kernel): features are detected in the
left image only; each left keypoint (rounded to a pixel) is searched along its row of the right image over the
integer disparities [max(``min_disparity_px``, 0), ``max_disparity_px``] by the ZNCC of (2·``search_radius_px``+1)²
patches. A match is kept when its ZNCC is at least ``search_min_zncc``; when it is unique (1 − best <
``search_uniqueness`` · (1 − the best more than 1 px away), which drops repetitive texture); when the same column
one row up or down correlates less (rows aligned: the epipolar constraint); and when the right patch, searched back
along the left row, lands within 1 px of the keypoint (left–right consistency). Patches flatter than 2 grey levels
(standard deviation) are not searched, and the matched right pixel must be valid. Why: detection is the front end's
largest cost (six ORB extractions were 64 % of a fused repeat frame at 640×480), and the search replaces the three
right-image extractions and the descriptor matching. It also triangulates more of the left keypoints (simulated
route, 320×240: ~750 vs ~430 greyscale landmarks per frame; synthetic pair of ``test/unit/vtr/test_stereo.py``:
~990 vs ~700 of 1000, same depth accuracy), and more landmarks localize better (``lightfast eval vtr``: fused
autonomy 99.92 → 99.94 %, median localization error lower on 9 of 10 repeats; see the README). Its weakness: on
a pair with misaligned rows a smooth texture still correlates on the wrong row at some disparity (6 px off: 8 % of
the landmarks survive vs none with descriptors), so it relies on a correct rectification.

**Descriptor matching** (``"descriptor"``; all vectorized, no Python loop over features): features are detected
in both images; for left feature i and right feature j, a pair is admissible when

* epipolar: |v_i − v_j| ≤ ``max_row_diff_px`` (rectified rows);
* disparity: ``min_disparity_px`` ≤ d = u_i − u_j ≤ ``max_disparity_px`` (d is the raw column difference; with
  ``P_right`` having a different principal point than ``P_left`` the zero-depth offset cx_l − cx_r is part of d).

Among the admissible candidates, the nearest descriptor (L2 for SIFT, Hamming for ORB) wins if it passes Lowe's
ratio test against the second nearest *admissible* candidate (``ratio``), if i is also the nearest admissible left
feature of j (``mutual``) and if its distance is at most ``orb_max_distance`` / ``sift_max_distance``. The last
test matters because a feature often has a single admissible candidate, which passes any ratio test: on the
synthetic pair of ``test/unit/vtr/test_stereo.py`` 90 % of correct ORB matches are within 46 bits and 99 % within
77, while 90 % of the wrong matches of a pair with misaligned rows are above 62 (SIFT: 90 % / 99 % of correct
matches within 92 / 230, 99 % of wrong ones above 297). Admissible pairs are enumerated without forming the N×M
matrix (:func:`stereo_candidates`: right features sorted by row, binary search for each left row band).
With ``subpixel`` (both ways) the disparity is refined by 1-D block matching on the source image
(:func:`refine_disparity`: zero-mean SSD at round(d) ± ``subpixel_search_px``, ± 2 after the row search, parabola,
two Lucas–Kanade steps); matches whose refinement fails (no interior minimum, patch outside the image) are dropped.

Triangulation
-------------
From the ``camera_info``-style 3×4 projection matrices of the *rectified* pair (``P`` of sensor_msgs/CameraInfo,
[fx 0 cx Tx; 0 fy cy Ty; 0 0 1 0], usually Tx_left = 0 and Tx_right = −fx·B; fx, fy, cy and Ty must agree, cx may
differ): the closed-form solution of the linear triangulation for rectified rows, Z = (Tx_l − Tx_r) /
(u_l − u_r − cx_l + cx_r), expressed in the left camera frame (see :func:`triangulate`). Points
outside [``min_depth_m``, ``max_depth_m``] or whose refined disparity left the admissible range are dropped.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, cast

import cv2
import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.config import Config, ConfigError, param
from lightfast.vtr.color_constant import ColorConstantConfig, SourceImage, image_sources
from lightfast.vtr.errors import VtrInputError

__all__ = [
    "FEATURE_CHOICE",
    "FEATURE_TYPES",
    "STEREO_MATCHING",
    "FeatureExtractor",
    "Features",
    "NearestMatches",
    "StereoConfig",
    "StereoFeatures",
    "StereoFrontEnd",
    "check_projection",
    "check_stereo_pair",
    "descriptor_distances",
    "match_descriptors",
    "match_stereo",
    "pair_distances",
    "refine_disparity",
    "search_stereo",
    "stereo_candidates",
    "triangulate",
]

log = logging.getLogger(__name__)

FEATURE_TYPES: Final = ("orb", "sift")
STEREO_MATCHING: Final = ("descriptor", "search")

#: Why the default feature type is ORB (numbers in the module docstring).
FEATURE_CHOICE: Final = (
    "ORB: ~8x faster than SIFT here (18-23 ms vs 147-207 ms per image), needed for >= 10 Hz with six extractions "
    "per stereo frame on 2 cores; more correct matches across lighting over all time-lapse pairs, but SIFT is more "
    "robust on the largest lighting changes (greyscale: 5 % vs 28 % of pairs below 6 correct matches)."
)


@dataclass(frozen=True)
class StereoConfig(Config):
    """Options of the stereo front end (paper §IV-B, Fig. 3–4): features, left–right matching, triangulation."""

    feature: str = param("orb", description="Feature type (SURF is non-free in pip OpenCV).", choices=FEATURE_TYPES)
    max_features: int = param(1000, description="Features kept per image (strongest first).", min=10, max=100000)
    orb_fast_threshold: int = param(
        10, description="ORB FAST threshold, 8-bit levels (OpenCV default 20).", min=1, max=255
    )
    orb_levels: int = param(8, description="ORB pyramid levels.", min=1, max=16)
    orb_scale_factor: float = param(1.2, description="ORB pyramid scale factor.", min=1.01, max=2.0)
    sift_contrast_threshold: float = param(
        0.04, description="SIFT contrast threshold (OpenCV default 0.04).", min=0.0, max=1.0
    )
    mask_erosion_px: int = param(
        4, description="Invalid pixels (zero/saturated) are grown by this before detection, px.", min=0, max=64
    )
    min_disparity_px: float = param(0.5, description="Smallest admissible disparity u_l - u_r, px.", min=-1000.0)
    max_disparity_px: float = param(160.0, description="Largest admissible disparity u_l - u_r, px.", min=0.0)
    max_row_diff_px: float = param(
        1.5, description="Epipolar constraint: largest row difference of a match on rectified images, px.", min=0.0
    )
    ratio: float = param(
        0.8, description="Lowe ratio test: best / second-best admissible descriptor distance below this.", min=0.0,
        max=1.0,
    )
    mutual: bool = param(True, description="Keep only mutually nearest admissible left-right pairs.")
    stereo_matching: str = param(
        "search", description="Left-right matching: 'descriptor' detects features in the right image too and "
        "matches descriptors under the epipolar and disparity constraints; 'search' finds each left keypoint along "
        "its row of the right image by ZNCC block matching (no right-image detection).", choices=STEREO_MATCHING,
    )
    search_radius_px: int = param(
        4, description="'search': half size of the ZNCC patch, px.", min=1, max=15
    )
    search_min_zncc: float = param(
        0.8, description="'search': smallest ZNCC of an accepted left-right match.", min=-1.0, max=1.0
    )
    search_uniqueness: float = param(
        0.7, description="'search': (1 - best ZNCC) must be below this times (1 - best ZNCC more than 1 px away).",
        min=0.0, max=1.0,
    )
    orb_max_distance: float = param(
        64.0, description="ORB: largest Hamming distance of a left-right match (of 256 bits).", min=0.0
    )
    sift_max_distance: float = param(
        250.0, description="SIFT: largest Euclidean distance of a left-right match (descriptor norm ~512).", min=0.0
    )
    subpixel: bool = param(
        True, description="Refine disparities by 1-D block matching (parabola + Lucas-Kanade); drop failures."
    )
    subpixel_radius_px: int = param(3, description="Half size of the block-matching patch, px.", min=1, max=15)
    subpixel_search_px: int = param(
        4, description="Block matching searches round(d) +- this many pixels (ORB keypoints of coarse pyramid "
        "levels are off by a few px).", min=1, max=32
    )
    min_depth_m: float = param(0.1, description="Landmarks nearer than this are dropped, m.", min=0.0)
    max_depth_m: float = param(200.0, description="Landmarks farther than this are dropped, m.", min=0.0)

    @property
    def detects_right(self) -> bool:
        """Whether the left–right matching needs features of the right image (``"descriptor"``; not the search)."""
        return self.stereo_matching == "descriptor"

    def check(self) -> None:
        if self.max_disparity_px <= self.min_disparity_px:
            raise ConfigError(
                f"StereoConfig.max_disparity_px ({self.max_disparity_px}) must exceed min_disparity_px "
                f"({self.min_disparity_px})"
            )
        if self.max_depth_m <= self.min_depth_m:
            raise ConfigError(
                f"StereoConfig.max_depth_m ({self.max_depth_m}) must exceed min_depth_m ({self.min_depth_m})"
            )


@dataclass(frozen=True)
class Features:
    """Keypoints of one image: pixel positions ``uv`` (N, 2) float32 (u right, v down; OpenCV's pixel-centre
    convention) and descriptors (N, D): float32 for SIFT, packed uint8 bits for ORB."""

    uv: NDArray[np.float32]
    descriptors: NDArray[np.generic]
    kind: str

    def __len__(self) -> int:
        return int(self.uv.shape[0])


@dataclass(frozen=True)
class StereoFeatures:
    """Triangulated left–right matches of one image source.

    ``points`` (N, 3) are in the left (rectified) camera frame, metres; ``descriptors`` are the left image's;
    ``distance`` the left–right descriptor distance; ``disparity`` = u_left − u_right after refinement.
    """

    source: str
    uv_left: NDArray[np.float32]
    uv_right: NDArray[np.float32]
    disparity: NDArray[np.float32]
    points: NDArray[np.float64]
    descriptors: NDArray[np.generic]
    distance: NDArray[np.float32]
    kind: str

    def __len__(self) -> int:
        return int(self.uv_left.shape[0])


# --------------------------------------------------------------------------------------------------------------
# Features


class FeatureExtractor:
    """Detects and describes features in 8-bit images with OpenCV (one detector object, not thread-safe)."""

    def __init__(self, config: StereoConfig | None = None) -> None:
        self.config = config or StereoConfig()
        c = self.config
        self._detector: cv2.Feature2D
        if c.feature == "orb":
            self._detector = cv2.ORB.create(
                nfeatures=c.max_features,
                scaleFactor=c.orb_scale_factor,
                nlevels=c.orb_levels,
                fastThreshold=c.orb_fast_threshold,
            )
        else:
            self._detector = cv2.SIFT.create(nfeatures=c.max_features, contrastThreshold=c.sift_contrast_threshold)

    @property
    def kind(self) -> str:
        return self.config.feature

    def empty(self) -> Features:
        dim, dtype = (32, np.uint8) if self.kind == "orb" else (128, np.float32)
        return Features(np.zeros((0, 2), np.float32), np.zeros((0, dim), dtype), self.kind)

    def detect(self, image: NDArray[np.uint8], valid: NDArray[np.bool_] | None = None) -> Features:
        """Features of an (H, W) uint8 image; with ``valid``, none within ``mask_erosion_px`` of an invalid pixel."""
        img = np.asarray(image)
        if img.ndim != 2 or img.dtype != np.uint8:
            raise VtrInputError(f"feature detection needs an (H, W) uint8 image, got {img.dtype} {img.shape}")
        mask: NDArray[np.uint8] | None = None
        if valid is not None:
            v = np.asarray(valid)
            if v.shape != img.shape:
                raise VtrInputError(f"mask shape {v.shape} differs from the image shape {img.shape}")
            if not v.all():
                mask = v.astype(np.uint8)
                r = self.config.mask_erosion_px
                if r > 0:
                    mask = cast(NDArray[np.uint8],
                                cv2.erode(mask, cv2.getStructuringElement(cv2.MORPH_RECT, (2 * r + 1, 2 * r + 1))))
                if not mask.any():
                    return self.empty()
        kps, desc = self._detector.detectAndCompute(np.ascontiguousarray(img), mask)
        if desc is None or len(kps) == 0:
            return self.empty()
        # an (N, 2) float32 array at run time (the stubs say a sequence of points)
        uv = cast(NDArray[np.float32], cv2.KeyPoint.convert(kps)).astype(np.float32).reshape(-1, 2)
        dtype = np.uint8 if self.kind == "orb" else np.float32
        return Features(uv, np.ascontiguousarray(desc, dtype=dtype), self.kind)


# --------------------------------------------------------------------------------------------------------------
# Matching

#: Patches flatter than this grey-level standard deviation are not searched (``stereo_matching="search"``).
_MIN_TEXTURE: Final = 2.0

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


# --------------------------------------------------------------------------------------------------------------
# Triangulation


def check_projection(P: ArrayLike, name: str = "P") -> NDArray[np.float64]:
    """A rectified ``camera_info`` projection matrix as (3, 4) float64: finite, [fx 0 cx Tx; 0 fy cy Ty; 0 0 1 0]
    with fx, fy > 0. Raises VtrInputError."""
    m = np.asarray(P, dtype=np.float64)
    if m.size == 12:
        m = m.reshape(3, 4)
    if m.shape != (3, 4):
        raise VtrInputError(f"{name} must be a finite 3x4 projection matrix, got shape {np.shape(P)}")
    v = m.tolist()  # plain floats: these checks run several times per frame
    if not all(math.isfinite(x) for row in v for x in row):
        raise VtrInputError(f"{name} must be a finite 3x4 projection matrix, got non-finite values")
    if not all(math.isclose(a, b, rel_tol=1e-5, abs_tol=1e-8) for a, b in zip(v[2], (0.0, 0.0, 1.0, 0.0),
                                                                             strict=True)) \
            or v[0][1] != 0.0 or v[1][0] != 0.0 or v[0][0] <= 0.0 or v[1][1] <= 0.0:
        raise VtrInputError(f"{name} is not a rectified projection matrix [fx 0 cx Tx; 0 fy cy Ty; 0 0 1 0]: {m}")
    return m


def check_stereo_pair(P_left: ArrayLike, P_right: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Both projection matrices checked (:func:`check_projection`) and consistent with a rectified pair: equal
    fx, fy, cy and Ty (rows align), different Tx (a baseline). Raises VtrInputError."""
    Pl, Pr = check_projection(P_left, "P_left"), check_projection(P_right, "P_right")
    for (r, c), what in (((0, 0), "fx"), ((1, 1), "fy"), ((1, 2), "cy"), ((1, 3), "Ty")):
        a, b = float(Pl[r, c]), float(Pr[r, c])
        if abs(a - b) > 1e-9 + 1e-6 * abs(b):  # np.isclose(a, b, rtol=1e-6, atol=1e-9)
            raise VtrInputError(f"P_left and P_right are not a rectified pair: {what} differs ({a} vs {b})")
    if abs(float(Pl[0, 3]) - float(Pr[0, 3])) <= 1e-12:
        raise VtrInputError("P_left and P_right have the same Tx: no stereo baseline")
    return Pl, Pr


def triangulate(
    P_left: ArrayLike, P_right: ArrayLike, uv_left: ArrayLike, uv_right: ArrayLike
) -> NDArray[np.float64]:
    """Landmarks (N, 3) in the left camera frame, metres, from matched pixels of a rectified pair.

    With P = [f 0 cx Tx; 0 fy cy Ty; 0 0 1 0] for both cameras (X in their shared frame):
    u_l − u_r = (cx_l − cx_r) + (Tx_l − Tx_r)/Z, so Z = (Tx_l − Tx_r) / (u_l − u_r − cx_l + cx_r),
    X = ((u_l − cx_l) Z − Tx_l)/f, Y = ((v_l − cy) Z − Ty)/fy — the exact solution of the linear (DLT) system for
    rectified rows (v_right is not used) — then moved into the left camera frame by adding K⁻¹ P_left[:, 3] =
    (Tx_l/f, Ty/fy, 0), which leaves X_left = (u_l − cx_l) Z/f, Y_left = (v_l − cy) Z/fy. Rows whose effective
    disparity has the wrong sign or is zero (points at or beyond infinity) are NaN.
    """
    return _triangulate(*check_stereo_pair(P_left, P_right), uv_left, uv_right)


def _triangulate(Pl: NDArray[np.float64], Pr: NDArray[np.float64], uv_left: ArrayLike, uv_right: ArrayLike
                 ) -> NDArray[np.float64]:
    """:func:`triangulate` with checked projection matrices."""
    a = np.asarray(uv_left, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(uv_right, dtype=np.float64).reshape(-1, 2)
    if a.shape != b.shape:
        raise VtrInputError(f"uv_left {a.shape} and uv_right {b.shape} differ")
    f, fy, cy = Pl[0, 0], Pl[1, 1], Pl[1, 2]
    d_eff = (a[:, 0] - b[:, 0]) - (Pl[0, 2] - Pr[0, 2])
    fb = Pl[0, 3] - Pr[0, 3]  # = f·B
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(d_eff * np.sign(fb) > 0, fb / d_eff, np.nan)
    x = (a[:, 0] - Pl[0, 2]) * z / f  # in the left camera frame: the Tx_l/f shift cancels
    y = (a[:, 1] - cy) * z / fy
    return np.stack([x, y, z], axis=1)


# --------------------------------------------------------------------------------------------------------------
# Front end


class StereoFrontEnd:
    """Per-source stereo landmarks of a rectified rgb8 stereo pair (paper Fig. 4, up to the map matching)."""

    def __init__(
        self,
        config: StereoConfig | None = None,
        color: ColorConstantConfig | None = None,
        sources: tuple[str, ...] = ("grey", "fv", "fr"),
    ) -> None:
        self.config = config or StereoConfig()
        self.color = color or ColorConstantConfig()
        self.sources = tuple(sources)
        self.extractor = FeatureExtractor(self.config)

    def source_features(self, left: SourceImage, right: SourceImage, P_left: ArrayLike, P_right: ArrayLike
                        ) -> StereoFeatures:
        """Detect, match left to right, refine and triangulate one image source."""
        if left.image.shape != right.image.shape:
            raise VtrInputError(f"left image {left.image.shape} and right image {right.image.shape} differ in size")
        Pl, Pr = check_stereo_pair(P_left, P_right)
        fl = self.extractor.detect(left.image, left.valid)
        fr = self.extractor.detect(right.image, right.valid) if self.config.detects_right else None
        return self.landmarks(left, right, fl, fr, Pl, Pr)

    def landmarks(self, left: SourceImage, right: SourceImage, fl: Features, fr: Features | None,
                  P_left: ArrayLike, P_right: ArrayLike) -> StereoFeatures:
        """:meth:`source_features` after the detection: match the left features ``fl`` of one image source to the
        right features ``fr`` (``"descriptor"``) or search them in the right image (``"search"``, ``fr`` unused),
        refine and triangulate."""
        c = self.config
        if left.image.shape != right.image.shape:
            raise VtrInputError(f"left image {left.image.shape} and right image {right.image.shape} differ in size")
        Pl, Pr = check_stereo_pair(P_left, P_right)
        if c.detects_right:
            if fr is None:
                raise VtrInputError("descriptor left-right matching needs the right image's features")
            il, ir, dist = match_stereo(fl, fr, c)
            uvl, uvr = fl.uv[il], fr.uv[ir]
            disp = (uvl[:, 0] - uvr[:, 0]).astype(np.float32)
        else:
            il, disp, dist = search_stereo(left.image, right.image, fl.uv, c)
            uvl = fl.uv[il]
            if right.valid is not None and len(il):  # the right pixel must be valid, as a right detection's is
                v = np.rint(uvl[:, 1]).astype(np.intp)
                u = np.rint(uvl[:, 0] - disp).astype(np.intp)
                keep = right.valid[v, u]
                il, disp, dist, uvl = il[keep], disp[keep], dist[keep], uvl[keep]
            uvr = np.stack([uvl[:, 0] - disp, uvl[:, 1]], axis=1).astype(np.float32)
        if c.subpixel and len(il):
            # the row search's integer disparity is already the best one: refine around it only (the descriptor
            # matches of coarse ORB levels can be a few pixels off)
            search = c.subpixel_search_px if c.detects_right else min(c.subpixel_search_px, 2)
            disp, refined = refine_disparity(left.image, right.image, uvl, disp, radius=c.subpixel_radius_px,
                                             search=search)
            uvr = np.stack([uvl[:, 0] - disp, uvr[:, 1]], axis=1).astype(np.float32)
        else:
            refined = np.ones(len(il), bool)
        pts = _triangulate(Pl, Pr, uvl, uvr)
        with np.errstate(invalid="ignore"):
            ok = (
                np.all(np.isfinite(pts), axis=1) & (pts[:, 2] >= c.min_depth_m) & (pts[:, 2] <= c.max_depth_m)
                & (disp >= c.min_disparity_px) & (disp <= c.max_disparity_px) & refined
            )
        log.debug("%s: %d left features, %d matches, %d landmarks", left.name, len(fl), len(il), int(ok.sum()))
        return StereoFeatures(
            source=left.name,
            uv_left=uvl[ok],
            uv_right=uvr[ok],
            disparity=disp[ok],
            points=pts[ok],
            descriptors=fl.descriptors[il[ok]],
            distance=dist[ok],
            kind=fl.kind,
        )

    def process(
        self, left_rgb: NDArray[np.generic], right_rgb: NDArray[np.generic], P_left: ArrayLike, P_right: ArrayLike
    ) -> dict[str, StereoFeatures]:
        """Landmarks of every configured source for one rectified (H, W, 3) rgb stereo pair."""
        left_a, right_a = np.asarray(left_rgb), np.asarray(right_rgb)
        if left_a.shape != right_a.shape:
            raise VtrInputError(f"left image {left_a.shape} and right image {right_a.shape} differ in size")
        Pl, Pr = check_stereo_pair(P_left, P_right)
        ls = image_sources(left_a, self.color, self.sources)
        rs = image_sources(right_a, self.color, self.sources)
        return {name: self.source_features(ls[name], rs[name], Pl, Pr) for name in self.sources}
