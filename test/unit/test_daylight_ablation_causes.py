"""benchmarks/daylight_ablation_causes.py without running the tracker: its variants, its argument errors and its
motion table on real poses (the evaluations it runs are tested in test_eval_daylight.py)."""
from __future__ import annotations

import dataclasses
from pathlib import Path
from types import ModuleType

import pytest

from lightfast.eval.daylight import InputChange
from lightfast.tracking.pipeline import TrackerConfig
from test.helpers import load_benchmark

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def causes() -> ModuleType:
    return load_benchmark("daylight_ablation_causes")


def test_each_variant_changes_one_thing_and_survives_the_option_list(causes: ModuleType) -> None:
    names = ",".join(causes.VARIANTS).split(",")
    assert names == list(causes.VARIANTS)  # --variants is comma-separated
    base_tracker, base_inputs = causes.VARIANTS["as recorded"]
    assert base_tracker == TrackerConfig() and base_inputs == InputChange()
    for name, (tracker, inputs) in causes.VARIANTS.items():
        prior = tracker.pose_prior_weight != base_tracker.pose_prior_weight
        unchecked = (tracker.max_f2m_correction_m, tracker.max_f2m_correction_deg) != (
            base_tracker.max_f2m_correction_m, base_tracker.max_f2m_correction_deg)
        assert tracker == dataclasses.replace(base_tracker, pose_prior_weight=tracker.pose_prior_weight,
                                              max_f2m_correction_m=tracker.max_f2m_correction_m,
                                              max_f2m_correction_deg=tracker.max_f2m_correction_deg), name
        changed = prior + unchecked + (inputs.frame_step != 1) + (inputs.depth_hole_grow_px != 0)
        assert changed == (0 if name == "as recorded" else 2 if " + " in name else 1), name


def test_unknown_variant_is_an_argument_error(causes: ModuleType, tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as exc:
        causes.main([str(tmp_path), "--variants", "magic"])
    assert exc.value.code == 2


def test_motion_table_of_real_hand_held_poses(causes: ModuleType, tmp_path: Path) -> None:
    rows = causes._motion(tmp_path, [])
    if not rows:
        pytest.skip("7-Scenes frames not found in ../shared")
    real = rows[0]
    assert "7-Scenes" in real["poses"] and len(real["cv_err_cm"]) == 3
    assert 0.1 < real["motion_cm"][0] < 5.0  # hand-held at 30 Hz: millimetres to centimetres per frame
    assert real["cv_err_cm"][0] < real["motion_cm"][0]  # constant velocity predicts better than standing still
    assert rows[1]["motion_cm"][0] > 1.5 * real["motion_cm"][0]  # every second frame: about twice the motion
