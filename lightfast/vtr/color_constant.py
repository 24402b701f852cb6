"""Colour-constant greyscale images from an RGB camera: paper §III (Eq. 1–7, 10) and §IV-A (Eq. 11–12, Tables II–III).

Model (§III, Eq. 5): with narrow channel sensitivities at peak wavelengths λ_i and a black-body illuminant (Wien),
log R_i = log(a·n I) + log(S(λ_i) C1 λ_i⁻⁵) − C2 / (T λ_i). The image is the weighted log difference (Eq. 6)

    F = log R2 − α log R1 − β log R3                                                        (implemented form)

with R1, R2, R3 the responses ordered by wavelength: **blue, green, red** (rgb8 input: channels 2, 1, 0). The paper
prints "+β"; only "−β" cancels the illuminant intensity under its constraints (Eq. 7: 1/λ2 = α/λ1 + β/λ3 and
β = 1 − α), so "−β" is implemented (tested by scaling all channels).

* F_v (α 0.29, β 0.77, Eq. 11) and F_r (α −1.3, β 2.9, Eq. 12): the paper's weights keep the colour-temperature
  constraint (Eq. 10, :func:`temperature_beta`) but not β = 1 − α, so the illuminant intensity survives with
  exponent 1 − α − β (:func:`illuminant_exponent`: −0.06 for F_v, −0.6 for F_r);
* the fully constrained **peak** image (Eq. 7, :func:`constrained_weights`, from the configured wavelengths);
* greyscale: Rec. 601 luma (``cv2.COLOR_RGB2GRAY``) by default, ``grey="green"`` the green channel (Fig. 1).

Inputs: (H, W, 3) rgb images, uint8 or float (``saturation_level`` is the top of the range). A pixel is invalid when
any channel is below ``min_valid``, at or above ``saturation_level`` or not finite; invalid pixels get the F of a
neutral grey at the middle of the log range and are reported in a mask — nothing NaN or infinite leaves this module.
Outputs: F (float32, natural-log units) with its mask (:class:`ColorConstantImage`, :func:`color_constant`), and the
8-bit images with masks for feature extraction (:class:`SourceImage`, :func:`image_sources`, :func:`to_uint8`).

Mapping to 8 bit: by default (``normalization="fixed"``) one affine map per (α, β), the same for every image, so a
surface gives the same grey level at noon and at dusk: with e = 1 − α − β, m = ``min_valid``, s =
``saturation_level`` and c = ``log_chroma_range``, [lo, hi] = [min(e log m, e log s) − (|α| + |β|) c,
max(e log m, e log s) + (|α| + |β|) c] (:func:`fixed_range`) goes linearly onto [0, 255], clipped.
``"percentile"`` maps the 1st/99th percentiles of this image's valid F instead (prefer it with SIFT). The derivation,
the check of the paper's weights and the measurements behind these choices: ``docs/vtr.md``.
"""
from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass
from typing import Final, cast

import cv2
import numpy as np
from numpy.typing import NDArray

from lightfast.config import Config, ConfigError, param
from lightfast.vtr.errors import VtrInputError

__all__ = [
    "SOURCES",
    "ColorConstantConfig",
    "ColorConstantImage",
    "SourceImage",
    "color_constant",
    "constrained_weights",
    "fixed_range",
    "greyscale",
    "illuminant_exponent",
    "image_sources",
    "source_weights",
    "temperature_beta",
    "to_uint8",
]

log = logging.getLogger(__name__)

#: Image sources of the lighting-resistant pipeline (§IV-B, Fig. 4) plus the constrained peak image (§IV-A).
SOURCES: Final = ("grey", "fv", "fr", "peak")
_RGB_BLUE, _RGB_GREEN, _RGB_RED = 2, 1, 0  # R1, R2, R3 (ordered by wavelength) in an rgb8 image


@dataclass(frozen=True)
class ColorConstantConfig(Config):
    """Options of the colour-constant images (paper §III Eq. 6–7, §IV-A Eq. 10–12)."""

    alpha_v: float = param(0.29, description="alpha of the vegetation image F_v (Eq. 11, Table II).", min=-10, max=10)
    beta_v: float = param(0.77, description="beta of the vegetation image F_v (Eq. 11, Table II).", min=-10, max=10)
    alpha_r: float = param(-1.3, description="alpha of the rocks/sand image F_r (Eq. 12, Table II).", min=-10, max=10)
    beta_r: float = param(2.9, description="beta of the rocks/sand image F_r (Eq. 12, Table II).", min=-10, max=10)
    peak_wavelengths_nm: tuple[float, ...] = param(
        (460.0, 530.0, 615.0),
        description="Peak wavelengths of the blue, green, red channels for the constrained peak image (Eq. 7), nm.",
        min=100.0,
        max=2000.0,
    )
    grey: str = param(
        "luma", description="Greyscale source: Rec. 601 luma or the green channel.", choices=("luma", "green")
    )
    min_valid: float = param(
        1.0, description="A pixel with any channel below this is invalid (zero, log undefined).", min=1e-6
    )
    saturation_level: float = param(
        255.0, description="A pixel with any channel at or above this is saturated and invalid.", min=1e-6
    )
    normalization: str = param(
        "fixed",
        description="8-bit mapping of F: fixed affine range per (alpha, beta), or per-image percentiles.",
        choices=("fixed", "percentile"),
    )
    log_chroma_range: float = param(
        0.5, description="Fixed mapping: assumed bound c of |log(G/B)| and |log(G/R)| (natural log).", min=0.01
    )
    percentiles: tuple[float, ...] = param(
        (1.0, 99.0), description="Percentile mapping: F percentiles mapped to 0 and 255.", min=0.0, max=100.0
    )

    def check(self) -> None:
        lam = self.peak_wavelengths_nm
        if len(lam) != 3 or lam[0] == lam[2]:
            raise ConfigError(
                f"ColorConstantConfig.peak_wavelengths_nm must be 3 values with the first != the last, got {lam}"
            )
        if self.saturation_level <= self.min_valid:
            raise ConfigError(
                f"ColorConstantConfig.saturation_level ({self.saturation_level}) must exceed "
                f"min_valid ({self.min_valid})"
            )
        if len(self.percentiles) != 2 or not self.percentiles[0] < self.percentiles[1]:
            raise ConfigError(
                f"ColorConstantConfig.percentiles must be (low, high) with low < high, got {self.percentiles}"
            )


@dataclass(frozen=True)
class ColorConstantImage:
    """F of Eq. 6 per pixel (float32, finite everywhere) and the mask of valid pixels (see module docstring)."""

    values: NDArray[np.float32]
    valid: NDArray[np.bool_]
    alpha: float
    beta: float


@dataclass(frozen=True)
class SourceImage:
    """One image source for feature extraction: 8-bit image and the mask of pixels whose value is meaningful."""

    name: str
    image: NDArray[np.uint8]
    valid: NDArray[np.bool_]


# --------------------------------------------------------------------------------------------------------------
# Weights


def _wavelengths(wavelengths_nm: tuple[float, ...] | list[float]) -> tuple[float, float, float]:
    lam = tuple(float(x) for x in wavelengths_nm)
    if len(lam) != 3 or not all(math.isfinite(x) and x > 0 for x in lam) or lam[0] == lam[2]:
        raise VtrInputError(f"need three positive wavelengths (R1, R2, R3) with R1 != R3, got {wavelengths_nm}")
    return lam


def constrained_weights(wavelengths_nm: tuple[float, ...] | list[float]) -> tuple[float, float]:
    """(α, β) satisfying both constraints of Eq. 7 for peak wavelengths (λ1, λ2, λ3):
    α = (1/λ2 − 1/λ3) / (1/λ1 − 1/λ3), β = 1 − α. Units cancel (any length unit). λ1 need not be the shortest:
    Table III's F'_r puts the nominal "blue" wavelength at 728 nm (→ α = −1.31)."""
    l1, l2, l3 = _wavelengths(wavelengths_nm)
    alpha = (1.0 / l2 - 1.0 / l3) / (1.0 / l1 - 1.0 / l3)
    return alpha, 1.0 - alpha


def temperature_beta(alpha: float, wavelengths_nm: tuple[float, ...] | list[float]) -> float:
    """β of Eq. 10, β = λ3 (1/λ2 − α/λ1): cancels the colour temperature (first constraint of Eq. 7) for any α."""
    l1, l2, l3 = _wavelengths(wavelengths_nm)
    return l3 * (1.0 / l2 - alpha / l1)


def illuminant_exponent(alpha: float, beta: float) -> float:
    """1 − α − β: scaling all channels by k adds this times log k to F (0 under the second constraint of Eq. 7)."""
    return 1.0 - alpha - beta


def source_weights(name: str, config: ColorConstantConfig | None = None) -> tuple[float, float]:
    """(α, β) of a colour-constant source: ``"fv"`` (Eq. 11), ``"fr"`` (Eq. 12) or ``"peak"`` (Eq. 7)."""
    cfg = config or ColorConstantConfig()
    if name == "fv":
        return cfg.alpha_v, cfg.beta_v
    if name == "fr":
        return cfg.alpha_r, cfg.beta_r
    if name == "peak":
        return constrained_weights(cfg.peak_wavelengths_nm)
    raise VtrInputError(f"unknown colour-constant source {name!r} (one of fv, fr, peak)")


# --------------------------------------------------------------------------------------------------------------
# Images


def _check_rgb(rgb: NDArray[np.generic]) -> NDArray[np.generic]:
    a = np.asarray(rgb)
    if a.ndim != 3 or a.shape[2] != 3:
        raise VtrInputError(f"expected an (H, W, 3) rgb image, got shape {a.shape}")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise VtrInputError(f"empty image of shape {a.shape}")
    if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)) or a.dtype == np.bool_:
        raise VtrInputError(f"expected an integer or float rgb image, got dtype {a.dtype}")
    return a


def _fill_value(alpha: float, beta: float, cfg: ColorConstantConfig) -> float:
    return illuminant_exponent(alpha, beta) * 0.5 * (math.log(cfg.min_valid) + math.log(cfg.saturation_level))


def color_constant(
    rgb: NDArray[np.generic], alpha: float, beta: float, config: ColorConstantConfig | None = None
) -> ColorConstantImage:
    """F = log R2 − α log R1 − β log R3 (Eq. 6 with the sign that cancels the intensity, see module docstring)
    of an (H, W, 3) **rgb** image (R1 = blue = channel 2, R3 = red = channel 0), natural log, float32.

    Invalid pixels (a channel < ``min_valid``, ≥ ``saturation_level`` or not finite) are ``False`` in ``valid``
    and hold the neutral fill value; the result never contains NaN or infinity.
    """
    cfg = config or ColorConstantConfig()
    if not (math.isfinite(alpha) and math.isfinite(beta)):
        raise VtrInputError(f"alpha and beta must be finite, got {alpha}, {beta}")
    a = _check_rgb(rgb)
    lo, hi = cfg.min_valid, cfg.saturation_level
    if a.dtype == np.uint8:
        # 256-entry tables: the log and the validity of every 8-bit level (fast, exact)
        levels = np.arange(256, dtype=np.float64)
        table = np.log(np.clip(levels, lo, hi)).astype(np.float32)
        ok_table = (levels >= lo) & (levels < hi)
        ch = (a[..., _RGB_BLUE], a[..., _RGB_GREEN], a[..., _RGB_RED])
        l1, l2, l3 = (table[c] for c in ch)
        valid = ok_table[ch[0]] & ok_table[ch[1]] & ok_table[ch[2]]
    else:
        x = a.astype(np.float32, copy=False)
        finite = np.isfinite(x)
        valid = np.all(finite & (x >= lo) & (x < hi), axis=2)
        with np.errstate(invalid="ignore"):
            x = np.log(np.clip(np.where(finite, x, lo), lo, hi)).astype(np.float32, copy=False)
        l1, l2, l3 = x[..., _RGB_BLUE], x[..., _RGB_GREEN], x[..., _RGB_RED]
    values = l2 - np.float32(alpha) * l1 - np.float32(beta) * l3
    values[~valid] = np.float32(_fill_value(alpha, beta, cfg))
    return ColorConstantImage(values=values.astype(np.float32, copy=False), valid=valid, alpha=alpha, beta=beta)


def fixed_range(alpha: float, beta: float, config: ColorConstantConfig | None = None) -> tuple[float, float]:
    """The F interval the fixed 8-bit mapping sends to [0, 255] (module docstring): the intensity part
    (1 − α − β) log R2 over log R2 ∈ [log min_valid, log saturation_level], widened by (|α| + |β|)·c for the
    chromatic part α log(R2/R1) + β log(R2/R3) with |log ratios| ≤ c = ``log_chroma_range``."""
    cfg = config or ColorConstantConfig()
    e = illuminant_exponent(alpha, beta)
    ends = (e * math.log(cfg.min_valid), e * math.log(cfg.saturation_level))
    chroma = (abs(alpha) + abs(beta)) * cfg.log_chroma_range
    return min(ends) - chroma, max(ends) + chroma


def to_uint8(image: ColorConstantImage, config: ColorConstantConfig | None = None) -> NDArray[np.uint8]:
    """Map F to 8 bit for feature extraction (``normalization`` of the config, see module docstring).

    ``"percentile"`` falls back to the fixed range when fewer than 100 pixels are valid or the percentiles
    coincide (e.g. a black frame).
    """
    cfg = config or ColorConstantConfig()
    lo, hi = fixed_range(image.alpha, image.beta, cfg)
    if cfg.normalization == "percentile":
        v = image.values[image.valid]
        if v.size >= 100:
            p_lo, p_hi = (float(p) for p in np.percentile(v, cfg.percentiles))
            if p_hi - p_lo > 1e-6:
                lo, hi = p_lo, p_hi
            else:
                log.debug("percentile range collapsed (%g); using the fixed range", p_hi - p_lo)
        else:
            log.debug("only %d valid pixels; using the fixed range", v.size)
    scale = np.float32(255.0 / (hi - lo))
    out = (image.values - np.float32(lo)) * scale + np.float32(0.5)
    return np.clip(out, 0.0, 255.0).astype(np.uint8)


def greyscale(rgb: NDArray[np.generic], config: ColorConstantConfig | None = None) -> NDArray[np.uint8]:
    """8-bit greyscale of an rgb image: Rec. 601 luma or the green channel (``grey``). Non-uint8 input is scaled
    by 255 / ``saturation_level`` and clipped (non-finite values become 0)."""
    cfg = config or ColorConstantConfig()
    a = _check_rgb(rgb)
    if a.dtype != np.uint8:
        x = np.nan_to_num(a.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
        x *= np.float32(255.0 / cfg.saturation_level)
        a = np.clip(x + 0.5, 0, 255).astype(np.uint8)
    if cfg.grey == "green":
        return np.ascontiguousarray(a[..., _RGB_GREEN])
    return cast(NDArray[np.uint8], cv2.cvtColor(np.ascontiguousarray(a), cv2.COLOR_RGB2GRAY))


def image_sources(
    rgb: NDArray[np.generic],
    config: ColorConstantConfig | None = None,
    sources: tuple[str, ...] = ("grey", "fv", "fr"),
) -> dict[str, SourceImage]:
    """The 8-bit image sources of Fig. 4 (default: greyscale, F_v, F_r; ``"peak"`` adds the Eq. 7 image).

    The greyscale mask is all ``True`` (saturated and black pixels are genuine greyscale appearance); the
    colour-constant masks are those of :func:`color_constant`.
    """
    cfg = config or ColorConstantConfig()
    unknown = [s for s in sources if s not in SOURCES]
    if unknown:
        raise VtrInputError(f"unknown image source(s) {unknown}; known: {list(SOURCES)}")
    a = _check_rgb(rgb)
    if a.dtype == np.uint8 and cfg.normalization == "fixed":
        return _image_sources_uint8(cast(NDArray[np.uint8], a), cfg, tuple(sources))
    out: dict[str, SourceImage] = {}
    for name in sources:
        if name == "grey":
            grey = greyscale(rgb, cfg)
            out[name] = SourceImage(name, grey, np.ones(grey.shape, dtype=bool))
        else:
            alpha, beta = source_weights(name, cfg)
            cc = color_constant(rgb, alpha, beta, cfg)
            out[name] = SourceImage(name, to_uint8(cc, cfg), cc.valid)
    return out


@functools.lru_cache(maxsize=32)
def _source_tables(name: str, cfg: ColorConstantConfig) -> tuple[NDArray[np.float32], NDArray[np.float32],
                                                                NDArray[np.float32], int]:
    """Per-channel float32 tables (for G, B, R levels) whose sum is the fixed 8-bit mapping of F before clipping
    and truncation, (F − lo)·255/(hi − lo) + 0.5, and the 8-bit value of the invalid-pixel fill."""
    alpha, beta = source_weights(name, cfg)
    lo, hi = fixed_range(alpha, beta, cfg)
    scale = 255.0 / (hi - lo)
    log_level = np.log(np.clip(np.arange(256, dtype=np.float64), cfg.min_valid, cfg.saturation_level))
    t_g = ((log_level - lo) * scale + 0.5).astype(np.float32)
    t_b = (-alpha * scale * log_level).astype(np.float32)
    t_r = (-beta * scale * log_level).astype(np.float32)
    fill = int(np.clip((_fill_value(alpha, beta, cfg) - lo) * scale + 0.5, 0.0, 255.0))
    return t_g, t_b, t_r, fill


def _image_sources_uint8(rgb: NDArray[np.uint8], cfg: ColorConstantConfig, sources: tuple[str, ...]
                         ) -> dict[str, SourceImage]:
    """:func:`image_sources` for rgb8 input and the fixed mapping, by table lookups: the channels are split once,
    the validity mask (it does not depend on α, β) is computed once, and each colour-constant source is the sum of
    three per-channel tables (:func:`_source_tables`) — the same mapping as :func:`to_uint8` of
    :func:`color_constant` (up to float rounding: at most one level, on values at a rounding boundary)."""
    out: dict[str, SourceImage] = {}
    red, green, blue = cv2.split(np.ascontiguousarray(rgb))
    valid: NDArray[np.bool_] | None = None
    for name in sources:
        if name == "grey":
            grey = greyscale(rgb, cfg)
            out[name] = SourceImage(name, grey, np.ones(grey.shape, dtype=bool))
            continue
        if valid is None:
            levels = np.arange(256, dtype=np.float64)
            ok = ((levels >= cfg.min_valid) & (levels < cfg.saturation_level)).astype(np.uint8)
            r_ok, g_ok, b_ok = (cast(NDArray[np.uint8], cv2.LUT(c, ok)) for c in (red, green, blue))
            valid = (r_ok & g_ok & b_ok).astype(bool)
        t_g, t_b, t_r, fill = _source_tables(name, cfg)
        f = cv2.add(cv2.add(cv2.LUT(green, t_g), cv2.LUT(blue, t_b)), cv2.LUT(red, t_r))
        image = np.clip(f, 0.0, 255.0, out=f).astype(np.uint8)
        image[~valid] = fill
        out[name] = SourceImage(name, image, valid)
    return out

