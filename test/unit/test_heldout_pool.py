"""benchmarks/heldout.py --pool: issue 19's goals judged over rounds of the same method (a confirmation round is
judged with the round it confirms, benchmarks/results/HELDOUT.md)."""
from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _heldout() -> ModuleType:
    spec = importlib.util.spec_from_file_location("heldout", ROOT / "benchmarks" / "heldout.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _vtr_round(routes: dict[str, float], false_accepts: int = 0) -> dict[str, Any]:
    """A round whose fused repeats lost ``routes[r]`` metres strictly on 3000 m per route (grey 100 m each)."""
    per_route = {r: {"fused": {"distance_m": 3000.0, "manual_strict_m": m, "manual_m": m / 2},
                     "grey": {"distance_m": 3000.0, "manual_strict_m": 100.0, "manual_m": 90.0}}
                 for r, m in routes.items()}
    fused = 1 - sum(routes.values()) / (3000.0 * len(routes))
    return {"routes": [int(r) for r in routes], "per_route": per_route, "fused_strict_autonomy": fused,
            "grey_strict_autonomy": 1 - 100 / 3000, "false_accepts_over_5m": false_accepts,
            "machine": {"date": "2026-11-29"}}


def test_vtr_rounds_pool_by_distance_and_one_round_above_the_goal_does_not_carry_a_round_below() -> None:
    pool = _heldout().pool_vtr([_vtr_round({"1": 0.8, "2": 2.4}), _vtr_round({"3": 1.5, "4": 9.0})])
    assert pool["routes"] == [1, 2, 3, 4]
    assert pool["fused_strict_autonomy"] == pytest.approx(1 - 13.7 / 12000)
    assert pool["fused_manual_strict_m"] == pytest.approx(13.7)
    assert pool["grey_strict_autonomy"] == pytest.approx(1 - 400 / 12000)
    assert pool["fused_published_autonomy"] == pytest.approx(1 - 6.85 / 12000)
    assert not pool["goals_met"]["fused_strict_autonomy >= 0.999"]  # 99.886 %: the first round alone met it
    assert pool["goals_met"]["false_accepts_over_5m == 0"]
    good = _heldout().pool_vtr([_vtr_round({"1": 0.8, "2": 2.4}), _vtr_round({"3": 1.5, "4": 1.0}, 1)])
    assert good["goals_met"] == {"fused_strict_autonomy >= 0.999": True, "false_accepts_over_5m == 0": False}


def test_vtr_rounds_that_share_a_route_are_refused() -> None:
    with pytest.raises(ValueError, match="share a route"):
        _heldout().pool_vtr([_vtr_round({"1": 0.8}), _vtr_round({"1": 0.8})])


def _racr_round(seeds: list[int], fails: list[str], median: float, speedup: float) -> dict[str, Any]:
    """40 varied runs, one failure per entry of ``fails`` (what the method reported)."""
    failures = [{"seed": seeds[0], "scene": f"S{i:02d}", "afd_px": 9.0, "reported": r} for i, r in enumerate(fails)]
    return {"seeds": seeds, "scenes": 40, "success_rate": 1 - len(fails) / 40, "median_afd_px": median,
            "self_reported_failure_rate": sum(r != "converged" for r in fails) / len(fails) if fails else None,
            "parallel_speedup": speedup, "machine": {"date": "2026-11-29"},
            "per_method": {"racr/varied": {"runs": 40, "median_afd_px": median, "failures": failures},
                           "acr/varied": {"runs": 40, "failures": failures * 20}}}


def test_racr_rounds_pool_counts_and_bound_the_median() -> None:
    pool = _heldout().pool_racr([_racr_round([1, 2], ["failed"], 0.57, 1.58),
                                 _racr_round([3, 4], ["ambiguous", "converged", "failed"], 1.6, 1.3)])
    assert pool["runs"] == 80 and pool["scenes"] == 80 and pool["seeds"] == [1, 2, 3, 4]
    assert pool["success_rate"] == pytest.approx(76 / 80)
    assert pool["self_reported_failure_rate"] == pytest.approx(3 / 4)
    assert pool["median_afd_px"] == [0.57, 1.6]
    assert pool["acr_success_rate"] == pytest.approx(0.0)
    assert pool["goals_met"] == {"success_rate >= 0.95": True, "median_afd_px <= 1.5": False,
                                 "self_reported_failure_rate >= 0.9": False,
                                 "parallel_speedup >= 1.4 in every round": False}


def test_pool_cli_writes_json_and_table_and_refuses_a_bad_file_in_one_line(tmp_path: Path) -> None:
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps(_vtr_round({"1": 0.8, "2": 2.4})))
    b.write_text(json.dumps(_vtr_round({"3": 1.5, "4": 1.0})))
    out = tmp_path / "pooled" / "p.json"
    cmd = [sys.executable, str(ROOT / "benchmarks" / "heldout.py"), "vtr", "--pool", str(a), str(b), "--out", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(out.read_text())["goals_met"]["fused_strict_autonomy >= 0.999"] is True
    assert "| **all 4** | **99.95 %**" in out.with_suffix(".md").read_text()
    b.write_text("{}")
    bad = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert bad.returncode == 1 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
