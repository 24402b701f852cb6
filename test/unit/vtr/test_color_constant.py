"""Tests of the colour-constant images of paper §III (Eq. 5–7, 10) and §IV-A (Eq. 11–12):
:mod:`lightfast.vtr.color_constant`."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lightfast.config import ConfigError
from lightfast.vtr import (
    ColorConstantConfig,
    VtrError,
    color_constant,
    constrained_weights,
    fixed_range,
    greyscale,
    illuminant_exponent,
    image_sources,
    source_weights,
    temperature_beta,
    to_uint8,
)

PEAK_NM = (460.0, 530.0, 615.0)
C2 = 1.4388e-2  # h c / k_B, m K


def _random_rgb(seed: int = 0, shape: tuple[int, int] = (32, 48), lo: float = 5.0, hi: float = 120.0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(lo, hi, size=shape + (3,)).astype(np.float64)


def _plus_beta(rgb: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    """Eq. 6 as printed, F = log R2 − α log R1 + β log R3 (R1 blue = channel 2, R3 red = channel 0)."""
    logs = np.log(rgb)
    return logs[..., 1] - alpha * logs[..., 2] + beta * logs[..., 0]


def _max_shift_under_scaling(f, rgb: np.ndarray, k: float) -> float:
    return float(np.max(np.abs(f(rgb * k) - f(rgb))))


def _wien_scene(temperature_k: float, intensity: float, reflectance: np.ndarray) -> np.ndarray:
    """Narrow-band sensor at the peak wavelengths under a Wien black body (Eq. 2 and 4), as rgb (red first)."""
    lam = np.array(PEAK_NM) * 1e-9  # blue, green, red
    spd = lam**-5 * np.exp(-C2 / (temperature_k * lam))
    spd_ref = lam[1] ** -5 * np.exp(-C2 / (5500.0 * lam[1]))  # a fixed unit, the same for every temperature
    bgr = intensity * reflectance * (spd / spd_ref)
    return bgr[..., ::-1]  # -> r, g, b


# ---------------------------------------------------------------------------------------------------------------
# Weights


def test_constrained_weights_follow_eq7():
    alpha, beta = constrained_weights(PEAK_NM)
    assert beta == pytest.approx(1.0 - alpha)
    l1, l2, l3 = PEAK_NM
    assert 1 / l2 == pytest.approx(alpha / l1 + beta / l3)
    assert alpha == pytest.approx(0.4760, abs=1e-4)  # Table III prints 0.42, which violates its own Eq. 7
    # Table III's F'_v and F'_r rows are consistent with Eq. 7
    assert constrained_weights((402.0, 544.0, 635.0))[0] == pytest.approx(0.29, abs=0.005)
    a_r, b_r = constrained_weights((728.0, 544.0, 635.0))
    assert (a_r, b_r) == (pytest.approx(-1.3, abs=0.02), pytest.approx(2.3, abs=0.02))


def test_paper_fv_fr_weights_satisfy_eq10_not_the_intensity_constraint():
    cfg = ColorConstantConfig()
    for name, (alpha, beta), residual in (("fv", (0.29, 0.77), -0.06), ("fr", (-1.3, 2.9), -0.6)):
        assert source_weights(name, cfg) == (alpha, beta)
        assert temperature_beta(alpha, PEAK_NM) == pytest.approx(beta, abs=0.005)  # Eq. 10 with Table II's λ
        assert illuminant_exponent(alpha, beta) == pytest.approx(residual)  # β ≠ 1 − α
    assert illuminant_exponent(*source_weights("peak", cfg)) == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(VtrError):
        source_weights("grey", cfg)


# ---------------------------------------------------------------------------------------------------------------
# F


def test_f_uses_blue_green_red_order_and_minus_beta():
    rgb = np.array([[[10, 20, 40]]], dtype=np.uint8)  # red 10, green 20, blue 40
    for alpha, beta in ((0.29, 0.77), (-1.3, 2.9)):
        f = color_constant(rgb, alpha, beta).values[0, 0]
        assert f == pytest.approx(math.log(20) - alpha * math.log(40) - beta * math.log(10), rel=1e-5)


@pytest.mark.parametrize("k", [0.25, 0.5, 3.0, 7.5])
def test_constrained_image_is_invariant_to_channel_scaling(k: float):
    rgb = _random_rgb()
    alpha, beta = constrained_weights(PEAK_NM)
    cfg = ColorConstantConfig(saturation_level=1e4)
    ours = _max_shift_under_scaling(lambda x: color_constant(x, alpha, beta, cfg).values, rgb, k)
    assert ours < 1e-5
    # the same check rejects Eq. 6 as printed ("+β"): its intensity term survives with exponent 2 − 2α
    printed = _max_shift_under_scaling(lambda x: _plus_beta(x, alpha, beta), rgb, k)
    assert printed == pytest.approx(abs((2 - 2 * alpha) * math.log(k)), rel=1e-6)
    assert printed > 0.1


def test_uint8_path_matches_float_path_and_is_invariant_to_exact_doubling():
    rgb = np.random.default_rng(1).integers(1, 128, size=(20, 30, 3)).astype(np.uint8)
    alpha, beta = constrained_weights(PEAK_NM)
    a = color_constant(rgb, alpha, beta)
    b = color_constant(rgb.astype(np.float32), alpha, beta)
    np.testing.assert_allclose(a.values, b.values, atol=1e-5)
    c = color_constant((rgb * 2).astype(np.uint8), alpha, beta)
    np.testing.assert_allclose(a.values, c.values, atol=1e-5)


def test_peak_image_cancels_black_body_temperature_and_intensity():
    refl = np.random.default_rng(2).uniform(0.05, 0.9, size=(50, 3))
    alpha, beta = constrained_weights(PEAK_NM)
    alpha_v, beta_v = source_weights("fv")
    cfg = ColorConstantConfig(saturation_level=1e9, min_valid=1e-6)
    base = _wien_scene(5500.0, 100.0, refl)[None]
    for temperature, intensity in ((2500.0, 7.0), (10000.0, 300.0)):
        other = _wien_scene(temperature, intensity, refl)[None]
        peak_shift = color_constant(other, alpha, beta, cfg).values - color_constant(base, alpha, beta, cfg).values
        assert np.max(np.abs(peak_shift)) < 1e-4
        # F_v keeps the temperature constraint (Eq. 10, to the rounding of β_v) but not the intensity one:
        fv_base = color_constant(base, alpha_v, beta_v, cfg).values
        fv_shift = color_constant(other, alpha_v, beta_v, cfg).values - fv_base
        assert np.ptp(fv_shift) < 1e-4  # the same shift for every surface
        # intensity part of Eq. 5 plus the temperature part left by rounding β_v = 0.7727 (Eq. 10) to 0.77
        l1, l2, l3 = (x * 1e-9 for x in PEAK_NM)
        rounding = -C2 * (1 / temperature - 1 / 5500.0) * (1 / l2 - alpha_v / l1 - beta_v / l3)
        expected = illuminant_exponent(alpha_v, beta_v) * math.log(intensity / 100.0) + rounding
        assert float(fv_shift.mean()) == pytest.approx(expected, abs=1e-4)


def test_zero_saturated_and_non_finite_pixels_are_masked_and_finite():
    rgb = np.full((4, 5, 3), 100, dtype=np.uint8)
    rgb[0, 0] = (0, 50, 50)
    rgb[1, 1] = (50, 0, 50)
    rgb[2, 2] = (50, 50, 255)
    rgb[3, 3] = (0, 0, 0)
    for name in ("fv", "fr", "peak"):
        out = color_constant(rgb, *source_weights(name))
        assert out.values.dtype == np.float32 and np.all(np.isfinite(out.values))
        assert out.valid.sum() == rgb.shape[0] * rgb.shape[1] - 4
        assert not out.valid[0, 0] and not out.valid[1, 1] and not out.valid[2, 2] and not out.valid[3, 3]
    f = np.full((3, 3, 3), 0.5, dtype=np.float32)
    f[0, 0, 0], f[1, 1, 1], f[2, 2, 2] = np.nan, np.inf, -1.0
    out = color_constant(f, 0.29, 0.77, ColorConstantConfig(min_valid=1e-3, saturation_level=1.0))
    assert np.all(np.isfinite(out.values)) and out.valid.sum() == 6
    assert np.all(to_uint8(out) >= 0)


def test_black_frame_is_all_invalid_without_errors():
    black = np.zeros((24, 32, 3), dtype=np.uint8)
    for norm in ("fixed", "percentile"):
        sources = image_sources(black, ColorConstantConfig(normalization=norm), ("grey", "fv", "fr", "peak"))
        assert not sources["fv"].valid.any() and sources["grey"].valid.all()
        for s in sources.values():
            assert s.image.dtype == np.uint8 and s.image.shape == (24, 32)


def test_bad_inputs_raise_vtr_errors():
    with pytest.raises(VtrError):
        color_constant(np.zeros((4, 4), dtype=np.uint8), 0.3, 0.7)  # mono8 where rgb8 is expected
    with pytest.raises(VtrError):
        color_constant(np.zeros((4, 4, 4), dtype=np.uint8), 0.3, 0.7)
    with pytest.raises(VtrError):
        color_constant(np.ones((4, 4, 3), dtype=np.uint8), float("nan"), 0.7)
    with pytest.raises(VtrError):
        image_sources(np.ones((4, 4, 3), dtype=np.uint8), sources=("grey", "hsv"))
    with pytest.raises(VtrError):
        constrained_weights((500.0, 530.0, 500.0))
    with pytest.raises(ConfigError):
        ColorConstantConfig(peak_wavelengths_nm=(460.0, 615.0))
    with pytest.raises(ConfigError):
        ColorConstantConfig(min_valid=300.0)
    with pytest.raises(ConfigError):
        ColorConstantConfig(normalization="minmax")


# ---------------------------------------------------------------------------------------------------------------
# 8-bit mapping


def test_fixed_range_formula():
    cfg = ColorConstantConfig(log_chroma_range=0.5)
    lo, hi = fixed_range(0.29, 0.77, cfg)
    assert lo == pytest.approx(-0.06 * math.log(255) - 1.06 * 0.5)
    assert hi == pytest.approx(0.0 + 1.06 * 0.5)
    lo, hi = fixed_range(-1.3, 2.9, cfg)
    assert (lo, hi) == (pytest.approx(-0.6 * math.log(255) - 2.1), pytest.approx(2.1))
    alpha, beta = constrained_weights(PEAK_NM)
    assert fixed_range(alpha, beta, cfg) == (pytest.approx(-0.5), pytest.approx(0.5))


def test_fixed_mapping_is_affine_clipped_and_lighting_invariant_for_the_peak_image():
    alpha, beta = constrained_weights(PEAK_NM)
    cfg = ColorConstantConfig()
    lo, hi = fixed_range(alpha, beta, cfg)
    values = np.array([[lo - 1.0, lo, 0.5 * (lo + hi), hi, hi + 1.0]], dtype=np.float32)
    img = color_constant(np.full((1, 5, 3), 100, np.uint8), alpha, beta)
    mapped = to_uint8(type(img)(values=values, valid=img.valid, alpha=alpha, beta=beta), cfg)
    assert mapped.tolist() == [[0, 0, 128, 255, 255]]
    # a surface keeps its 8-bit value when the light dims fourfold (exact on 8-bit levels divisible by 4)
    rgb = (np.random.default_rng(3).integers(1, 63, size=(16, 16, 3)) * 4).astype(np.uint8)
    bright = image_sources(rgb, cfg, ("peak",))["peak"].image
    dim = image_sources((rgb // 4).astype(np.uint8), cfg, ("peak",))["peak"].image
    np.testing.assert_array_equal(bright, dim)


def test_percentile_mapping_spans_the_8_bit_range():
    rgb = np.random.default_rng(4).integers(1, 255, size=(64, 64, 3)).astype(np.uint8)
    cfg = ColorConstantConfig(normalization="percentile", percentiles=(1.0, 99.0))
    img = image_sources(rgb, cfg, ("fv",))["fv"].image
    assert img.min() == 0 and img.max() == 255
    assert 0.005 < np.mean(img == 0) < 0.03 and 0.005 < np.mean(img == 255) < 0.03


def test_greyscale_luma_and_green():
    rgb = np.zeros((2, 2, 3), np.uint8)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 200, 100, 50
    assert greyscale(rgb)[0, 0] == round(0.299 * 200 + 0.587 * 100 + 0.114 * 50)
    assert greyscale(rgb, ColorConstantConfig(grey="green"))[0, 0] == 100
    unit = ColorConstantConfig(min_valid=1e-3, saturation_level=1.0)
    assert greyscale(rgb.astype(np.float32) / 255.0, unit)[0, 0] == 124
