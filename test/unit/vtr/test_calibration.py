"""Colour-constant weights fitted from a fixed-camera time-lapse (paper §IV-A, Eq. 10): a known α is recovered from
synthetic images made with it, and ``lightfast vtr calibrate`` on a tiny folder."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from lightfast import cli
from lightfast.config import ConfigError
from lightfast.vtr import ColorConstantConfig, temperature_beta
from lightfast.vtr.calibration import (
    CalibrationConfig,
    beta_for,
    calibrate,
    load_timelapse,
    read_calibration,
    select_pairs,
)
from lightfast.vtr.errors import VtrInputError

FAST: dict[str, Any] = {"alpha_min": -1.5, "alpha_max": 1.5, "coarse_step": 0.25, "fine_step": 0.05}


def _field(rng: np.random.Generator, h: int, w: int, n: int, amp: float) -> np.ndarray:
    """Sharp-edged patches of random level: moving shadows (intensity) or light of another colour."""
    f = np.zeros((h, w), np.float32)
    for _ in range(n):
        pts = rng.integers(0, [w, h], size=(5, 2)).astype(np.int32)
        cv2.fillPoly(f, [cv2.convexHull(pts)], float(rng.uniform(-amp, amp)))
    return f


def timelapse(alpha: float, rule: str, n: int = 5, h: int = 180, w: int = 240, seed: int = 0) -> list[np.ndarray]:
    """rgb8 images of a fixed scene under changing light, for a camera whose colour-constant image with (α, β(α))
    is exactly invariant: log R_i = s_i(x) + a_i u_t(x) + b_i v_t(x) with per-image intensity (u) and colour (v)
    fields and channel exponents a, b (blue, green, red) chosen so that a2 − α a1 − β a3 = b2 − α b1 − β b3 = 0."""
    rng = np.random.default_rng(seed)
    s = np.zeros((h, w, 3), np.float32) + rng.uniform(-0.2, 0.2, 3).astype(np.float32)  # log reflectance, b g r
    for _ in range(100):
        c = rng.uniform(-0.45, 0.45, 3).tolist()
        x, y = (int(v) for v in rng.integers(0, [w, h]))
        if rng.random() < 0.5:
            cv2.rectangle(s, (x, y), (x + int(rng.integers(6, 40)), y + int(rng.integers(6, 40))), c, -1)
        else:
            cv2.ellipse(s, (x, y), (int(rng.integers(4, 25)), int(rng.integers(4, 25))), float(rng.uniform(0, 180)),
                        0, 360, c, -1)
    beta = beta_for(alpha, rule)
    if rule == "sum1":  # intensity cancels for any α; the colour of the light only for α
        a, b = np.ones(3), np.array([1.0, 2 * alpha - 1, -1.0])
    else:  # the colour temperature cancels for any α (Eq. 10, 460/530/615 nm); the intensity only for α
        a, b = np.array([1.0, alpha + beta, 1.0]), 1000.0 / np.array([460.0, 530.0, 615.0])
    out = []
    for _ in range(n):
        u = _field(rng, h, w, 8, 0.8) + rng.uniform(-0.5, 0.5)
        v = _field(rng, h, w, 8, 0.4) + rng.uniform(-0.2, 0.2)
        log_bgr = s + u[..., None] * a + v[..., None] * b
        out.append(np.clip(np.exp(log_bgr[..., ::-1]) * 90.0, 1, 254).astype(np.uint8))
    return out


@pytest.mark.parametrize(("rule", "alpha"), [("eq10", 0.1), ("sum1", -0.6)])
def test_known_alpha_is_recovered(rule: str, alpha: float) -> None:
    result = calibrate(timelapse(alpha, rule), CalibrationConfig(rule=rule, **FAST))
    assert result.alpha == pytest.approx(alpha, abs=0.051)
    assert result.beta == pytest.approx(beta_for(result.alpha, rule))
    assert not result.on_range_end
    assert result.fitted.correct_per_pair > max(p.correct_per_pair for p in result.printed.values())
    assert [s.alpha for s in result.curve] == sorted(s.alpha for s in result.curve)
    assert result.curve[0].alpha == -1.5 and result.curve[-1].alpha == 1.5


def test_rules_and_pairs() -> None:
    assert beta_for(0.29, "eq10") == pytest.approx(temperature_beta(0.29, (460.0, 530.0, 615.0)))
    assert beta_for(0.3, "sum1") == pytest.approx(0.7)
    with pytest.raises(VtrInputError):
        beta_for(0.3, "free")
    assert select_pairs(4, 100) == [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    sample = select_pairs(40, 50, seed=3)
    assert len(sample) == len(set(sample)) == 50 and sample == sorted(sample) == select_pairs(40, 50, seed=3)
    with pytest.raises(ConfigError):
        CalibrationConfig(alpha_min=1.0, alpha_max=0.0)
    with pytest.raises(ConfigError):
        CalibrationConfig(coarse_step=0.1, fine_step=0.2)


def test_bad_inputs_raise_vtr_input_errors(tmp_path: Path) -> None:
    with pytest.raises(VtrInputError, match="at least 2"):
        calibrate([np.zeros((8, 8, 3), np.uint8)])
    with pytest.raises(VtrInputError, match="one size"):
        calibrate([np.zeros((8, 8, 3), np.uint8), np.zeros((8, 9, 3), np.uint8)])
    with pytest.raises(VtrInputError, match="not a directory"):
        load_timelapse(tmp_path / "missing")
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    for name, shape in (("a.png", (8, 8, 3)), ("b.png", (8, 9, 3))):
        assert cv2.imwrite(str(mixed / name), np.full(shape, 100, np.uint8))
    with pytest.raises(VtrInputError, match=r"b\.png is 9x8, a\.png 8x8"):
        load_timelapse(mixed)
    (tmp_path / "broken.png").write_bytes(b"not a png")
    with pytest.raises(VtrInputError, match="not a readable image"):
        load_timelapse(tmp_path)
    (tmp_path / "bad.yaml").write_text("format: something-else\n")
    with pytest.raises(VtrInputError):
        read_calibration(tmp_path / "bad.yaml")


def test_cli_calibrate_writes_yaml_that_configures_the_images(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "cam"
    folder.mkdir()
    for k, rgb in enumerate(timelapse(-0.6, "sum1", n=4)):
        assert cv2.imwrite(str(folder / f"2020010{k}_120000.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    out = tmp_path / "cal" / "fit.yaml"
    code = cli.main(["vtr", "calibrate", str(folder), "-o", str(out), "--rule", "sum1", "--alpha-range=-1.5,1.5"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "alpha -0.600, beta 1.600" in printed and f"written {out}" in printed
    result = read_calibration(out)
    assert (result.alpha, result.rule, result.images, result.pairs) == (-0.6, "sum1", 4, 6)
    color = result.color_config("fr", ColorConstantConfig(normalization="percentile"))
    assert (color.alpha_r, color.beta_r, color.normalization) == (-0.6, 1.6, "percentile")
    assert (color.alpha_v, color.beta_v) == (0.29, 0.77)
    assert not list(out.parent.glob(".*"))  # written atomically: no temporary file left


def test_cli_calibrate_bad_folder_is_one_line_and_exit_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["vtr", "calibrate", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "at least 2 images" in err
