"""What-if changes to a daylight recording's input (:class:`InputChange`), for measuring why methods do (not)
separate (issue 21, point 5) and how tracking holds up when a busy node drops frames."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lightfast.eval.errors import DaylightEvalError

__all__ = ["InputChange"]

@dataclass(frozen=True)
class InputChange:
    """What-if changes to a recording's input. The defaults leave the recording as it is; ground truth and the
    protocol are unchanged.

    * ``frame_step``: track every k-th frame only (30/k Hz: larger motion between frames, a constant-velocity
      prediction that is k² times further off for the same acceleration);
    * ``depth_hole_grow_px``: grow every region without depth by this many pixels (a depth camera that loses more
      than the directly sunlit pixels, as structured light does near bright areas);
    * ``drop_rate``, ``drop_seed``: leave out each frame after the first with this probability (a node that falls
      behind and drops frames: the intervals between the frames it tracks vary), drawn from ``drop_seed``.
    """

    frame_step: int = 1
    depth_hole_grow_px: int = 0
    drop_rate: float = 0.0
    drop_seed: int = 0

    def __post_init__(self) -> None:
        if not 1 <= self.frame_step <= 30 or not 0 <= self.depth_hole_grow_px <= 100:
            raise DaylightEvalError(f"frame_step must be in [1, 30] and depth_hole_grow_px in [0, 100], got "
                                    f"{self.frame_step} and {self.depth_hole_grow_px}")
        if not 0.0 <= self.drop_rate < 1.0:
            raise DaylightEvalError(f"drop_rate must be in [0, 1), got {self.drop_rate}")

    def depth(self, depth_m: NDArray[np.float32]) -> NDArray[np.float32]:
        """``depth_m`` with its holes grown (0 = no depth)."""
        if self.depth_hole_grow_px == 0:
            return depth_m
        import cv2

        hole = (~(np.isfinite(depth_m) & (depth_m > 0))).astype(np.uint8)
        k = 2 * self.depth_hole_grow_px + 1
        grown = cv2.dilate(hole, np.ones((k, k), np.uint8)).astype(bool)
        return np.where(grown, np.float32(0.0), depth_m).astype(np.float32)

    def kept(self) -> Callable[[int], bool]:
        """Whether a busy node keeps the i-th frame offered (the first always; each other with ``1 - drop_rate``):
        call the predicate once per frame, in order (it draws from ``drop_seed``'s stream as it goes)."""
        rng = np.random.default_rng(self.drop_seed)
        return lambda i: i == 0 or self.drop_rate == 0.0 or bool(rng.random() >= self.drop_rate)
