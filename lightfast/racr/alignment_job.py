"""The alignment thread's unit of work in the rACR scheme (paper §3.4, run by the alignment thread of §3.6).

* :func:`finite_vse_cloud`: a VSE cloud ``(n, 3)`` (current-cloud frame, metres once the real scale s is applied,
  §3.3) and its intensities ``(n,)`` without the rows holding a non-finite value; at least 30 points must remain.
* ``_Observation``: one VSE output as the scheme keeps it — the cloud, the intensities, the camera pose
  ``T_cur_cam`` = T_A (camera-to-current-cloud, rigid 4×4) and the current keyframes, with its sequence number
  and stamp (seconds on the scheme's clock).
* :class:`AlignmentJob`: one fast alignment (Eq. 12–15: warm, or a cold start over several start poses keeping
  the best plausible result) or one fine alignment (Eq. 16–18) of one observation, from ``T_init`` = ``T_p``
  (rigid 4×4, current-cloud frame to reference frame, metres) and ``sigma_init`` = ``σ_p``.
  :meth:`AlignmentJob.run` computes without touching the scheme (safe outside its lock);
  :meth:`~lightfast.racr.scheme.RacrScheme.commit` publishes its ``result``
  (:class:`~lightfast.racr.fast_alignment.FastAlignmentResult` or :class:`~lightfast.racr.fine.FineAlignmentResult`)
  or its ``error`` (:class:`~lightfast.racr.errors.RacrError`; also a fast result whose fitness is below
  ``FastAlignmentConfig.min_fitness``, which fast_align never reports converged).
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.racr.errors import AlignmentError, RacrError
from lightfast.racr.fast_alignment import (
    FastAlignmentConfig,
    FastAlignmentResult,
    ReferenceCloud,
    fast_align,
    fast_align_best,
)
from lightfast.racr.fine import FineAlignmentConfig, FineAlignmentResult, Keyframe, fine_align

__all__ = ["AlignmentJob", "finite_vse_cloud"]

Array = NDArray[np.float64]

_MIN_POINTS = 30


def finite_vse_cloud(points: ArrayLike, intensities: ArrayLike | None) -> tuple[Array, Array | None,
                                                                              NDArray[np.bool_]]:
    """A VSE cloud ``(n, 3)`` and its intensities ``(n,)`` (or None) without the rows that hold a non-finite
    coordinate or intensity; also returns the kept-rows mask. Bad shapes, or fewer than 30 points left, raise
    :class:`AlignmentError`."""
    try:
        pts = np.array(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise AlignmentError(f"the VSE cloud must be an (n, 3) array: {exc}") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise AlignmentError(f"the VSE cloud must have shape (n, 3), got {pts.shape}")
    ok = np.all(np.isfinite(pts), axis=1)
    inten = None
    if intensities is not None:
        try:
            inten = np.array(intensities, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise AlignmentError(f"the VSE intensities must be an (n,) array: {exc}") from None
        if inten.shape != (len(pts),):
            raise AlignmentError(f"the VSE intensities must have shape ({len(pts)},), got {inten.shape}")
        ok &= np.isfinite(inten)
        inten = inten[ok]
    pts = pts[ok]
    if len(pts) < _MIN_POINTS:
        raise AlignmentError(
            f"the VSE cloud has {len(pts)} finite points (of {len(ok)}); at least {_MIN_POINTS} are needed"
        )
    return pts, inten, ok


@dataclass
class _Observation:
    seq: int
    stamp: float
    points: Array
    intensities: Array | None
    T_cur_cam: Array
    keyframes: tuple[Keyframe, ...]
    fast_converged: bool = False
    done: bool = False


class AlignmentJob:
    """One unit of the alignment thread's work on one observation: a fast alignment (warm or cold) or a fine
    alignment. :meth:`run` computes without touching the scheme (safe outside its lock);
    :meth:`~lightfast.racr.scheme.RacrScheme.commit` publishes the result."""

    def __init__(
        self,
        kind: str,
        observation: _Observation,
        reference: ReferenceCloud,
        T_init: Array,
        sigma_init: float,
        fast_config: FastAlignmentConfig,
        fine_config: FineAlignmentConfig,
        starts: Sequence[Array] = (),
        max_scale_change: float | None = None,
    ) -> None:
        self.kind = kind
        self._starts = tuple(starts)
        self._max_scale_change = max_scale_change
        self._obs = observation
        self._reference = reference
        self._T_init = T_init
        self._sigma_init = sigma_init
        self._fast_config = fast_config
        self._fine_config = fine_config
        self.result: FastAlignmentResult | FineAlignmentResult | None = None
        self.error: RacrError | None = None
        self.seconds = 0.0
        #: fast alignments this job runs (a cold start tries several starts; see ``SchemeConfig.start_*``)
        self.alignments = max(1, len(self._starts)) if kind == "fast" else 1

    @property
    def observation_stamp(self) -> float:
        return self._obs.stamp

    def run(self) -> AlignmentJob:
        """Run the alignment. A :class:`RacrError` (bad or non-overlapping data) is kept in :attr:`error`; anything
        else propagates."""
        start = time.perf_counter()
        try:
            if self.kind == "fine":
                self.result = fine_align(
                    self._obs.points, self._reference, self._obs.keyframes, T_ref_cur_init=self._T_init,
                    sigma_init=self._sigma_init, intensities=self._obs.intensities, config=self._fine_config,
                )
            elif self._starts:
                self.result, _ = fast_align_best(self._obs.points, self._reference, self._starts,
                                                 sigma_init=self._sigma_init, config=self._fast_config,
                                                 align=fast_align,
                                                 max_scale_change=self._max_scale_change)
            else:
                self.result = fast_align(
                    self._obs.points, self._reference, T_ref_cur_init=self._T_init, sigma_init=self._sigma_init,
                    config=self._fast_config,
                )
            fitness = self.result.fitness if isinstance(self.result, FastAlignmentResult) else 1.0
            if fitness < self._fast_config.min_fitness:
                # never published: the scheme would otherwise call it converged once a re-run ends where it ended
                self.result = None
                raise AlignmentError(
                    f"the fast alignment ended on a fit of {fitness:.3f} of the sampled points, below min_fitness="
                    f"{self._fast_config.min_fitness}: a wrong local minimum or too little overlap")
        except RacrError as exc:
            self.error = exc
        self.seconds = time.perf_counter() - start
        return self
