"""Fit the colour-constant weights of a camera from a fixed-camera time-lapse: the paper's training (§IV-A, Eq. 10)
of the images F = log R2 − α log R1 − β log R3 (§III Eq. 6–7, as :mod:`lightfast.vtr.color_constant` implements).

What the paper did: its camera's broad, overlapping channels break the narrow-band model, so it relaxes β = 1 − α
(Eq. 7) and keeps the colour-temperature constraint, β = λ3 (1/λ2 − α/λ1) (Eq. 10), leaving α free, then picks α
by "the ability to match SURF features across significant lighting changes" in time-lapses of static scenes. The
printed weights (``ColorConstantConfig`` defaults: F_v α 0.29 β 0.77, Eq. 11; F_r α −1.3 β 2.9, Eq. 12) are that
procedure's result for a Bumblebee XB3; :func:`calibrate` runs it for another camera.

* Weights: one free α; β from ``rule`` ``"eq10"`` (the paper's, with ``peak_wavelengths_nm`` of the colour
  configuration) or ``"sum1"`` (β = 1 − α: cancels a common intensity exactly, temperature only as the data
  allows). Not both free: the paper tuned one variable, and a 2-D search costs the square and fits noise of a
  40-image sequence.
* Criterion: mean **correct matches per image pair** of F_α alone (features of ``StereoConfig``, nearest
  neighbour, ratio test, mutual; correct when both keypoints lie within ``tolerance_px``, the camera being fixed:
  :func:`fixed_camera_matches`) over up to ``max_pairs`` pairs of the sequence (a seeded sample of all pairs). It
  is the paper's measure and what VT&R needs. The invariance of F over time alone is maximized by a flat image; its
  ratio to the spatial variance avoids that but does not see what a detector needs (corners that survive the 8-bit
  mapping and JPEG chroma blocks).
* Search: a grid of step ``coarse_step`` over [``alpha_min``, ``alpha_max``], then ``fine_step`` within one coarse
  step of the best; the best α of the curve wins (first on ties). An optimum on the range's end is flagged.

Input: rgb8 images of one fixed camera, all the same size (:func:`load_timelapse` reads a folder). Output:
:class:`CalibrationResult` (α, β, the curve, the printed F_v/F_r on the same pairs), written and read as YAML
(:meth:`CalibrationResult.to_yaml`, :func:`read_calibration`); :meth:`CalibrationResult.color_config` puts the
fitted weights into a :class:`~lightfast.vtr.color_constant.ColorConstantConfig` (docs/vtr.md).
"""
from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np
import yaml
from numpy.typing import NDArray

from lightfast.config import Config, ConfigError, param
from lightfast.io import read_versioned_yaml, write_text_atomic
from lightfast.vtr.color_constant import (
    ColorConstantConfig,
    color_constant,
    illuminant_exponent,
    source_weights,
    temperature_beta,
    to_uint8,
)
from lightfast.vtr.descriptor_matching import match_descriptors
from lightfast.vtr.errors import VtrInputError
from lightfast.vtr.features import FeatureExtractor, Features
from lightfast.vtr.stereo_config import StereoConfig

__all__ = [
    "FORMAT",
    "IMAGE_SUFFIXES",
    "RULES",
    "CalibrationConfig",
    "CalibrationResult",
    "WeightScore",
    "beta_for",
    "calibrate",
    "fixed_camera_matches",
    "load_timelapse",
    "read_calibration",
    "score_weights",
    "select_pairs",
]

log = logging.getLogger(__name__)

FORMAT, VERSION = "lightfast-vtr-color-calibration", 1
#: How β follows α: the paper's Eq. 10 (colour temperature cancelled) or Eq. 7's β = 1 − α (intensity cancelled).
RULES = ("eq10", "sum1")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".ppm", ".bmp", ".tif", ".tiff")
_PRINTED = ("fv", "fr")


@dataclass(frozen=True)
class CalibrationConfig(Config):
    """Options of :func:`calibrate` (module docstring)."""

    rule: str = param("eq10", description="beta from alpha: eq10 (paper Eq. 10) or sum1 (beta = 1 - alpha).",
                      choices=RULES)
    alpha_min: float = param(-2.0, description="Lower end of the alpha search range.", min=-10.0, max=10.0)
    alpha_max: float = param(2.0, description="Upper end of the alpha search range.", min=-10.0, max=10.0)
    coarse_step: float = param(0.25, description="Step of the coarse alpha grid.", min=1e-3, max=10.0)
    fine_step: float = param(0.05, description="Step of the fine alpha grid around the coarse optimum.", min=1e-3,
                             max=10.0)
    max_pairs: int = param(200, description="Image pairs scored per alpha (a seeded sample of all pairs).", min=1,
                           max=1_000_000)
    tolerance_px: float = param(4.0, description="A match is correct when its keypoints are this close, px.",
                                min=0.0, max=100.0)
    ratio: float = param(0.8, description="Lowe ratio of the descriptor matching.", min=0.05, max=1.0)
    seed: int = param(0, description="Seed of the pair sample.", min=0, max=2**31 - 1)

    def check(self) -> None:
        if not self.alpha_min < self.alpha_max:
            raise ConfigError(f"CalibrationConfig.alpha_min ({self.alpha_min}) must be below alpha_max "
                              f"({self.alpha_max})")
        if self.fine_step > self.coarse_step:
            raise ConfigError(f"CalibrationConfig.fine_step ({self.fine_step}) must not exceed coarse_step "
                              f"({self.coarse_step})")


@dataclass(frozen=True)
class WeightScore:
    """How one (α, β) did on the scored pairs: mean correct matches per pair, precision (correct / all matches)
    and mean features per image."""

    alpha: float
    beta: float
    correct_per_pair: float
    precision: float
    features_per_image: float

    def to_list(self) -> list[float]:
        return [round(self.alpha, 6), round(self.beta, 6), round(self.correct_per_pair, 4),
                round(self.precision, 4), round(self.features_per_image, 1)]


@dataclass(frozen=True)
class CalibrationResult:
    """The fitted weights (``alpha``, ``beta``, scored as ``fitted``), the whole ``curve`` (sorted by α), the
    printed F_v and F_r scored on the same pairs, and what was used (rule, feature, images, pairs, range)."""

    alpha: float
    beta: float
    rule: str
    fitted: WeightScore
    curve: tuple[WeightScore, ...]
    printed: dict[str, WeightScore]
    feature: str
    images: int
    pairs: int
    alpha_range: tuple[float, float]
    source: str = ""

    @property
    def on_range_end(self) -> bool:
        """The optimum is an end of the search range (the true one may lie beyond)."""
        return any(math.isclose(self.alpha, a, abs_tol=1e-9) for a in self.alpha_range)

    def color_config(self, source: str = "fv", base: ColorConstantConfig | None = None) -> ColorConstantConfig:
        """``base`` (default: the defaults) with the fitted weights as F_v (``source="fv"``) or F_r (``"fr"``)."""
        if source not in _PRINTED:
            raise VtrInputError(f"the fitted weights replace fv or fr, not {source!r}")
        cfg = base or ColorConstantConfig()
        if source == "fv":
            return dataclasses.replace(cfg, alpha_v=self.alpha, beta_v=self.beta)
        return dataclasses.replace(cfg, alpha_r=self.alpha, beta_r=self.beta)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT, "version": VERSION, "alpha": round(self.alpha, 6), "beta": round(self.beta, 6),
            "rule": self.rule, "illuminant_exponent": round(illuminant_exponent(self.alpha, self.beta), 6),
            "correct_per_pair": round(self.fitted.correct_per_pair, 4), "precision": round(self.fitted.precision, 4),
            "on_range_end": self.on_range_end, "feature": self.feature, "images": self.images, "pairs": self.pairs,
            "alpha_range": list(self.alpha_range), "source": self.source,
            "printed": {k: dict(zip(("alpha", "beta", "correct_per_pair", "precision", "features_per_image"),
                                    v.to_list(), strict=True)) for k, v in self.printed.items()},
            "curve_columns": ["alpha", "beta", "correct_per_pair", "precision", "features_per_image"],
            "curve": [s.to_list() for s in self.curve],
        }

    def to_yaml(self, path: str | Path | None = None) -> str:
        """The result as YAML (readable by :func:`read_calibration`); written atomically to ``path`` if given."""
        head = ("# lightfast vtr calibrate: colour-constant weights fitted on a fixed-camera time-lapse (paper "
                "§IV-A, Eq. 10).\n# Use: ColorConstantConfig(alpha_v=alpha, beta_v=beta) or alpha_r/beta_r "
                "(docs/vtr.md).\n")
        text = head + yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=None, width=120)
        if path is not None:
            write_text_atomic(path, text)
        return text


def read_calibration(path: str | Path) -> CalibrationResult:
    """A calibration written by :meth:`CalibrationResult.to_yaml`; :class:`VtrInputError` when it is not one."""
    doc = read_versioned_yaml(path, format_name=FORMAT, version=VERSION, error=VtrInputError,
                              what="a colour-constant calibration")
    try:
        def score(row: Sequence[float]) -> WeightScore:
            return WeightScore(*(float(x) for x in row))

        curve = tuple(score(r) for r in doc["curve"])
        printed = {k: score([v[c] for c in ("alpha", "beta", "correct_per_pair", "precision",
                                            "features_per_image")]) for k, v in doc["printed"].items()}
        alpha, beta = float(doc["alpha"]), float(doc["beta"])
        fitted = next((s for s in curve if math.isclose(s.alpha, alpha, abs_tol=1e-6)), None)
        if fitted is None:
            raise ValueError(f"alpha {alpha} is not on the curve")
        lo, hi = (float(x) for x in doc["alpha_range"])
        return CalibrationResult(alpha, beta, str(doc["rule"]), fitted, curve, printed, str(doc["feature"]),
                                 int(doc["images"]), int(doc["pairs"]), (lo, hi), str(doc.get("source", "")))
    except (KeyError, TypeError, ValueError) as exc:
        raise VtrInputError(f"{path}: damaged colour-constant calibration ({type(exc).__name__}: {exc})") from None


# --------------------------------------------------------------------------------------------------------------


def beta_for(alpha: float, rule: str, color: ColorConstantConfig | None = None) -> float:
    """β of ``alpha`` under ``rule``: ``"eq10"`` β = λ3 (1/λ2 − α/λ1) (the colour configuration's peak
    wavelengths), ``"sum1"`` β = 1 − α."""
    if rule == "eq10":
        return temperature_beta(alpha, (color or ColorConstantConfig()).peak_wavelengths_nm)
    if rule == "sum1":
        return 1.0 - alpha
    raise VtrInputError(f"unknown rule {rule!r} (one of {', '.join(RULES)})")


def select_pairs(n: int, max_pairs: int, seed: int = 0) -> list[tuple[int, int]]:
    """All pairs i < j of ``n`` images, or a seeded sample of ``max_pairs`` of them (sorted)."""
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    if len(pairs) <= max_pairs:
        return pairs
    keep = np.sort(np.random.default_rng(seed).choice(len(pairs), size=max_pairs, replace=False))
    return [pairs[int(k)] for k in keep]


def fixed_camera_matches(a: Features, b: Features, *, tolerance_px: float = 4.0, ratio: float = 0.8
                         ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_]]:
    """Whole-image matches of two images of a fixed camera (nearest neighbour, ratio test, mutual): the keypoints
    in ``a`` and in ``b`` and whether each match is correct (both within ``tolerance_px``: the scene point stayed
    on the same pixel)."""
    i, j, _ = match_descriptors(a.descriptors, b.descriptors, a.kind, ratio=ratio, mutual=True)
    ua, ub = a.uv[i], b.uv[j]
    return ua, ub, np.linalg.norm(ua - ub, axis=1) <= tolerance_px


def _check_images(images: Sequence[NDArray[np.uint8]]) -> list[NDArray[np.uint8]]:
    out = [np.asarray(im) for im in images]
    if len(out) < 2:
        raise VtrInputError(f"a time-lapse needs at least 2 images, got {len(out)}")
    for k, im in enumerate(out):
        if im.ndim != 3 or im.shape[2] != 3 or im.dtype != np.uint8:
            raise VtrInputError(f"image {k}: expected an (H, W, 3) rgb8 image, got {im.dtype} {im.shape}")
        if im.shape != out[0].shape:
            raise VtrInputError(f"image {k} is {im.shape[1]}x{im.shape[0]}, image 0 {out[0].shape[1]}x"
                                f"{out[0].shape[0]}: a fixed camera gives images of one size")
    return out


def _features(images: Sequence[NDArray[np.uint8]], alpha: float, beta: float, color: ColorConstantConfig,
              extractor: FeatureExtractor) -> list[Features]:
    out = []
    for rgb in images:
        cc = color_constant(rgb, alpha, beta, color)
        out.append(extractor.detect(to_uint8(cc, color), cc.valid))
    return out


def score_weights(images: Sequence[NDArray[np.uint8]], alpha: float, beta: float, pairs: Sequence[tuple[int, int]],
                  *, config: CalibrationConfig | None = None, stereo: StereoConfig | None = None,
                  color: ColorConstantConfig | None = None) -> WeightScore:
    """Correct matches per pair, precision and features per image of F with (α, β) on ``pairs`` of ``images``."""
    cfg = config or CalibrationConfig()
    imgs = _check_images(images)
    feats = _features(imgs, alpha, beta, color or ColorConstantConfig(), FeatureExtractor(stereo or StereoConfig()))
    correct = matches = 0
    for i, j in pairs:
        _, _, ok = fixed_camera_matches(feats[i], feats[j], tolerance_px=cfg.tolerance_px, ratio=cfg.ratio)
        matches += len(ok)
        correct += int(np.count_nonzero(ok))
    n = max(len(pairs), 1)
    return WeightScore(alpha, beta, correct / n, correct / matches if matches else 0.0,
                       float(np.mean([len(f) for f in feats])))


def _grid(lo: float, hi: float, step: float) -> list[float]:
    k = math.floor((hi - lo) / step + 1e-9)
    values = [lo + i * step for i in range(k + 1)]
    if hi - values[-1] > 1e-9:
        values.append(hi)
    return [round(v, 6) for v in values]


def calibrate(images: Sequence[NDArray[np.uint8]], config: CalibrationConfig | None = None, *,
              stereo: StereoConfig | None = None, color: ColorConstantConfig | None = None, source: str = "",
              progress: Callable[[WeightScore], None] | None = None) -> CalibrationResult:
    """Fit α (and β by ``config.rule``) to a fixed-camera time-lapse (module docstring); ``progress`` is called
    with every scored weight pair."""
    cfg = config or CalibrationConfig()
    st = stereo or StereoConfig()
    col = color or ColorConstantConfig()
    imgs = _check_images(images)
    pairs = select_pairs(len(imgs), cfg.max_pairs, cfg.seed)
    scores: dict[float, WeightScore] = {}

    def score(alpha: float) -> None:
        if alpha not in scores:
            s = score_weights(imgs, alpha, beta_for(alpha, cfg.rule, col), pairs, config=cfg, stereo=st, color=col)
            scores[alpha] = s
            log.info("alpha %+.3f beta %+.3f: %.2f correct matches per pair (precision %.0f %%)", s.alpha, s.beta,
                     s.correct_per_pair, 100 * s.precision)
            if progress is not None:
                progress(s)

    def best() -> float:
        ordered = sorted(scores)
        return ordered[int(np.argmax([scores[a].correct_per_pair for a in ordered]))]

    for a in _grid(cfg.alpha_min, cfg.alpha_max, cfg.coarse_step):
        score(a)
    centre = best()
    for a in _grid(max(cfg.alpha_min, centre - cfg.coarse_step), min(cfg.alpha_max, centre + cfg.coarse_step),
                   cfg.fine_step):
        score(a)
    alpha = best()
    printed = {name: score_weights(imgs, *source_weights(name, col), pairs, config=cfg, stereo=st, color=col)
               for name in _PRINTED}
    curve = tuple(scores[a] for a in sorted(scores))
    return CalibrationResult(alpha, scores[alpha].beta, cfg.rule, scores[alpha], curve, printed, st.feature,
                             len(imgs), len(pairs), (cfg.alpha_min, cfg.alpha_max), source)


def load_timelapse(folder: str | Path) -> tuple[list[Path], list[NDArray[np.uint8]]]:
    """The images of a fixed-camera time-lapse folder (files with :data:`IMAGE_SUFFIXES`, sorted by name) as rgb8;
    :class:`VtrInputError` for a missing folder, fewer than 2 images, unreadable files or mixed sizes."""
    root = Path(folder)
    if not root.is_dir():
        raise VtrInputError(f"{root} is not a directory of time-lapse images")
    paths = sorted(p for p in root.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    images: list[NDArray[np.uint8]] = []
    for p in paths:
        bgr = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if bgr is None:
            raise VtrInputError(f"{p}: not a readable image")
        if images and bgr.shape != images[0].shape:
            raise VtrInputError(f"{p} is {bgr.shape[1]}x{bgr.shape[0]}, {paths[0].name} {images[0].shape[1]}x"
                                f"{images[0].shape[0]}: a fixed camera gives images of one size")
        images.append(cast(NDArray[np.uint8], np.ascontiguousarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))))
    if len(images) < 2:
        raise VtrInputError(f"{root}: a time-lapse needs at least 2 images ({', '.join(IMAGE_SUFFIXES)}), found "
                            f"{len(images)}")
    return paths, _check_images(images)
