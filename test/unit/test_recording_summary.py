"""The live run's summary (`lightfast eval recording`, printed by scripts/demo.sh): what it says about f2m."""
from __future__ import annotations

import numpy as np

from lightfast.eval.recording import RecordingScore


def _score(poses: int, f2m: int) -> RecordingScore:
    return RecordingScore(frames=300, poses=poses, f2m=f2m, rmse_m=0.017, loss_ratio=0.0, fps=30.0,
                          latency_ms=np.array([40.0, 80.0]))


def test_summary_explains_a_low_f2m_share() -> None:
    text = _score(297, 235).summary()
    assert "f2m 235 (79.1 %)" in text
    assert "only 79 % refined by f2m" in text and "did not keep up" in text


def test_summary_is_quiet_when_f2m_keeps_up() -> None:
    assert "refined by f2m:" not in _score(300, 290).summary()
    assert "refined by f2m:" not in _score(0, 0).summary()
