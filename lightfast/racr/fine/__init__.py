"""Fine-grained scale-aware alignment of rACR (paper §3.4.3, Eq. 10–11 and 16–18), from the fast alignment's result.

It minimises Eq. 11, ``α E_g + (1 − α) E_p``, over the relative pose ``T_p = T_ref_cur`` (rigid 4×4, current-cloud
frame to reference frame, metres) and scale ``σ_p`` (``p_ref ≈ R_p (σ_p p) + t_p``, Eq. 9), after refining the
current keyframe poses (Eq. 16). One module per concept:

* :mod:`~lightfast.racr.fine.config` — :class:`FineAlignmentConfig`;
* :mod:`~lightfast.racr.fine.keyframes` — the current keyframes (§3.4.1), their image sampling and projection,
  and the self-occlusion z-buffer (§3.4.3, :func:`nearest_per_pixel`);
* :mod:`~lightfast.racr.fine.objective` — E_g (Eq. 9) and E_p (Eq. 10) residuals and Jacobians, Eq. 11 as a
  normalised Huber objective;
* :mod:`~lightfast.racr.fine.optimization` — the Levenberg–Marquardt solves of Eq. 16, 17 and 18;
* :mod:`~lightfast.racr.fine.align` — :func:`fine_align` (the outer loop) and :class:`FineAlignmentResult`.

Design, deviations from the paper and what was measured: ``docs/racr.md``; run time:
``benchmarks/results/racr_fine_alignment.md``.
"""
from __future__ import annotations

from lightfast.racr.fine.align import FineAlignmentResult, fine_align
from lightfast.racr.fine.config import LM_METHODS, SCALE_UPDATES, FineAlignmentConfig
from lightfast.racr.fine.keyframes import Keyframe, nearest_per_pixel

__all__ = [
    "LM_METHODS",
    "SCALE_UPDATES",
    "FineAlignmentConfig",
    "FineAlignmentResult",
    "Keyframe",
    "fine_align",
    "nearest_per_pixel",
]
