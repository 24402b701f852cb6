"""benchmarks/daylight_f2m_terms.py without rendering: its perturbations, its summary and its argument errors (the
relighter and the alignment it calls are tested in their own modules)."""
from __future__ import annotations

from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from lightfast.geometry import rotation_angle_deg
from test.helpers import load_benchmark

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def terms() -> ModuleType:
    return load_benchmark("daylight_f2m_terms")


def test_perturbations_have_the_asked_size_in_random_directions(terms: ModuleType) -> None:
    rng = np.random.default_rng(0)
    Ts = [terms._perturbation(rng, 0.03, 1.5) for _ in range(20)]
    assert all(abs(np.linalg.norm(T[:3, 3]) - 0.03) < 1e-12 for T in Ts)
    assert all(abs(float(rotation_angle_deg(T[:3, :3])) - 1.5) < 1e-9 for T in Ts)
    directions = np.array([T[:3, 3] / 0.03 for T in Ts])
    assert np.linalg.norm(directions.mean(axis=0)) < 0.5  # not one direction


def test_summary_per_reference_and_term(terms: ModuleType) -> None:
    rows = [{"reference": "relit", "term": "geometry", "start_t_m": 0.03, "start_r_deg": 1.0, "t_m": t, "r_deg": 0.5,
             "accepted": ok} for t, ok in ((0.01, True), (0.02, True), (0.04, True), (0.2, True), (0.3, False))]
    s = terms.summarize(rows)["relit"]["geometry"]
    assert s["frames"] == 5 and s["accepted_pct"] == 80.0 and s["t_median_cm"] == pytest.approx(4.0)
    # the rejected 0.3 m result: the tracker keeps the start (3 cm)
    assert s["kept_t_median_cm"] == pytest.approx(3.0)
    assert s["worse_than_start_pct"] == 40.0 and s["beyond_loss_pct"] == 20.0  # 0.2 m is beyond 10 cm
    assert set(terms.summarize(rows)) == {"relit"}


def test_bad_arguments_are_one_line_errors(terms: ModuleType, tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        terms.main([str(tmp_path), "--maps", str(tmp_path), "--step", "0"])
    assert exc.value.code == 2 and "--step" in capsys.readouterr().err
    assert terms.main([str(tmp_path), "--maps", str(tmp_path)]) == 1  # no recordings
    assert "no recordings" in capsys.readouterr().err
