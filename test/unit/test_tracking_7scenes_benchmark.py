"""``benchmarks/tracking_7scenes.py --data DIR --first N --last M`` on a 7-Scenes folder other than the shared one
(issue 21): frame numbers that start at 500, ``.color.png`` as in the 7-Scenes download, a reduced size (fast), and
a folder without ``camera-intrinsics.txt`` (the download has none: the 7-Scenes intrinsics stand in)."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from types import ModuleType

import cv2
import numpy as np
import pytest

from test.helpers import load_benchmark

ROOT = Path(__file__).resolve().parents[2]
FIRST = 500  # the fake folder's first frame number


def _benchmark() -> ModuleType:
    return load_benchmark("tracking_7scenes")


def _fake_sequence(src: Path, dst: Path, count: int, scale: float, intrinsics: bool) -> Path:
    """Frames 0.. of ``src`` renumbered from ``FIRST`` into ``dst``, resized by ``scale``, colour as PNG."""
    dst.mkdir()
    for k in range(count):
        a, b = src / f"frame-{k:06d}", dst / f"frame-{FIRST + k:06d}"
        rgb = cv2.imread(f"{a}.color.jpg", cv2.IMREAD_COLOR)
        depth = cv2.imread(f"{a}.depth.png", cv2.IMREAD_UNCHANGED)
        size = (round(rgb.shape[1] * scale), round(rgb.shape[0] * scale))
        cv2.imwrite(f"{b}.color.png", cv2.resize(rgb, size, interpolation=cv2.INTER_AREA))
        cv2.imwrite(f"{b}.depth.png", cv2.resize(depth, size, interpolation=cv2.INTER_NEAREST))
        shutil.copyfile(f"{a}.pose.txt", f"{b}.pose.txt")
    if intrinsics:
        K = np.loadtxt(src / "camera-intrinsics.txt")
        K[:2, :2] *= scale
        K[:2, 2] = (K[:2, 2] + 0.5) * scale - 0.5  # pixel-centre convention, as PinholeCamera.scaled
        np.savetxt(dst / "camera-intrinsics.txt", K)
    return dst


def test_the_benchmark_runs_on_another_folder_numbered_from_500(sevenscenes_dir: Path, tmp_path: Path) -> None:
    bench = _benchmark()
    data = _fake_sequence(sevenscenes_dir, tmp_path / "seq-02", 10, 0.25, intrinsics=True)
    out = tmp_path / "out" / "tracking.md"
    argv = ["--data", str(data), "--first", str(FIRST + 2), "--last", str(FIRST + 9), "--subsequence", "4",
            "--no-main", "--no-orderings", "--output", str(out)]
    assert bench.main(argv) == 0
    summary = json.loads(out.with_suffix(".json").read_text())
    assert (summary["first"], summary["last"]) == (FIRST + 2, FIRST + 9)
    for sub in (summary["subsequences"], summary["subsequences_registered"]):  # raw and registered colour
        assert sub["stretches"] == [[FIRST + 2, FIRST + 5], [FIRST + 6, FIRST + 9]]
        assert {(r["method"], r["resolution"]) for r in sub["rows"]} == {
            (m, size) for m in (bench.O3D_TENSOR, bench.O3D_LEGACY, bench.O3D_TENSOR_SKIP, bench.O3D_LEGACY_SKIP,
                                bench.EQ7, bench.DEPTH_DIFF)
            for size in ("160×120", "80×60")}
        for row in sub["rows"]:
            assert len(row["ate_cm"]) == 2 and all(math.isfinite(a) and a < 5.0 for a in row["ate_cm"]), row
            lightfast = row["method"].startswith("lightfast")
            assert ("ahead_of_both" in row) == ("ahead_of_both_same_rule" in row) == lightfast
            assert ("own_cm" in row) == (row["method"] in bench.HAT_METHODS)
            assert all(0.0 <= a <= 5.0 for a in row.get("own_cm", [])), row
        assert [h["resolution"] for h in sub["own_errors"]] == ["160×120", "80×60"]
        assert all(len(h["ground_truth_cm"]) == 2 for h in sub["own_errors"])
    assert summary["subsequences_registered"]["colour"].startswith("colour registered (scale 0.")
    report = out.read_text()
    assert f"Frames {FIRST + 2}–{FIRST + 9} of `" in report and "## Sub-sequences of 4 frames" in report
    assert "own error" in report and "The ground truth's share" in report
    with pytest.raises(SystemExit, match=r"holds 10 numbered 500\.\.509"):
        bench.main(["--data", str(data), "--first", "0", "--last", "299", "--output", str(out)])


def test_a_folder_without_intrinsics_gets_the_7scenes_ones(sevenscenes_dir: Path, tmp_path: Path) -> None:
    bench = _benchmark()
    data = _fake_sequence(sevenscenes_dir, tmp_path / "seq-03", 2, 1.0, intrinsics=False)
    seq = bench.load_sequence(data)
    assert seq.numbers == [FIRST, FIRST + 1] and not seq.intrinsics_file
    assert (seq.cam.fx, seq.cam.fy, seq.cam.cx, seq.cam.cy) == (585.0, 585.0, 320.0, 240.0)
    np.testing.assert_allclose(seq.gt[1], np.loadtxt(sevenscenes_dir / "frame-000001.pose.txt"), atol=1e-3)
    assert bench.subsequences(10, 4) == [range(0, 4), range(4, 8)] and bench.subsequences(3, 150) == [range(3)]
