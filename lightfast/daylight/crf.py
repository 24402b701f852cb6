"""Camera response function (CRF) ``f`` and its inverse, as used by the brightness estimation of paper §III-C.

Eq. 4 compares a live pixel ``I_C(u)`` with ``f(Δt · I_B(u))``: the model radiosity ``I_B`` (Eq. 3) scaled by the
exposure and mapped to an 8-bit value by the camera response ``f``; Eq. 6 instead linearizes the pixel with ``f⁻¹``.

:class:`CameraResponse` stores ``f⁻¹`` as a strictly increasing table ``inverse`` of shape (256, 3): ``inverse[v, c]``
is the *relative exposure* ``x`` that produces the pixel value ``v`` in channel ``c`` (R, G, B). Between table
entries the curve is linear, so

* ``f(x) = apply(x)`` — the piecewise linear interpolation of ``v`` over ``inverse[:, c]`` (float, not rounded);
  ``x >= inverse[255]`` saturates at 255 and ``x <= inverse[0]`` gives 0;
* ``f⁻¹(v) = linearize(v)`` — the interpolation of the table at (fractional) pixel values ``v`` in [0, 255];
* ``f'(x) = derivative(x)`` — the slope of the segment containing ``x`` (0 outside the table: a saturated pixel
  carries no gradient, which is exactly why E_crf treats over-exposure as a lower bound).

The relative exposure of a surface with radiosity ``B`` is ``x = sensitivity · exposure_s · gain · B``
(:meth:`CameraResponse.exposure`; ``exposure_s`` in seconds); ``sensitivity`` absorbs units and optics (1 when
unknown — the brightness scales of §III-C then simply absorb it). Tables calibrated from an exposure bracket
(:func:`calibrate_from_bracket`) are normalized **per channel** so that ``f⁻¹(128) = 1``: Debevec/Robertson recover
each channel only up to a factor, so the white balance between channels is unknown, and the per-channel scales of
§III-C absorb it.

Files: YAML ``format: lightfast-crf`` (exposure, gain, sensitivity and the per-channel ``inverse`` tables; the layout
is in docs/daylight.md), read with :func:`load_crf`, which also reads the ``camera.yaml`` of the simulated recordings
(one table for all channels, ``sensitivity`` per unit *radiance* ``L = B / π``, i.e. ``sensitivity / π`` per unit
radiosity: the scales s_x of §III-C then come out in the simulator's physical units). CLI: ``lightfast crf
calibrate IMAGES... --exposures T1 T2 ... -o OUT.yaml`` (:func:`calibrate_from_files`).
"""
from __future__ import annotations

import logging
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from lightfast.daylight.errors import CrfError
from lightfast.io import write_text_atomic

__all__ = [
    "CHANNELS",
    "CameraResponse",
    "calibrate_from_bracket",
    "calibrate_from_files",
    "load_crf",
    "save_crf",
]

log = logging.getLogger(__name__)

FORMAT_NAME = "lightfast-crf"
FORMAT_VERSION = 1
CHANNELS = ("r", "g", "b")
LEVELS = 256
MAX_VALUE = 255.0

F64 = NDArray[np.float64]


def _check_table(table: ArrayLike, name: str = "inverse") -> F64:
    try:
        t = np.array(table, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CrfError(f"{name} must be numeric: {exc}") from None
    if t.ndim == 1:
        t = np.repeat(t[:, None], 3, axis=1)
    if t.shape != (LEVELS, 3):
        raise CrfError(f"{name} must have shape ({LEVELS}, 3) or ({LEVELS},), got {t.shape}")
    if not np.all(np.isfinite(t)):
        raise CrfError(f"{name} contains NaN or infinite values")
    if np.any(t < 0.0):
        raise CrfError(f"{name} must be >= 0 (relative exposures), min is {t.min():.4g}")
    steps = np.diff(t, axis=0)
    if np.any(steps <= 0.0):
        c = int(np.argwhere(steps <= 0.0)[0, 1])
        v = int(np.argwhere(steps <= 0.0)[0, 0])
        raise CrfError(f"{name} must be strictly increasing; channel {CHANNELS[c]} does not rise from value {v} "
                       f"to {v + 1} ({t[v, c]:.6g} -> {t[v + 1, c]:.6g})")
    return t


def _positive(value: Any, name: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise CrfError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x) or x <= 0.0:
        raise CrfError(f"{name} must be finite and > 0, got {value!r}")
    return x


@dataclass(frozen=True, eq=False)
class CameraResponse:
    """A camera response ``f`` (per channel) at a fixed exposure; see the module docstring.

    Attributes:
        inverse: (256, 3) ``f⁻¹``: pixel value → relative exposure, strictly increasing per channel (read-only).
        exposure_s: exposure time Δt in seconds.
        gain: sensor gain (linear factor on the exposure).
        sensitivity: relative exposure per unit radiosity, second and unit gain.
    """

    inverse: F64
    exposure_s: float = 1.0
    gain: float = 1.0
    sensitivity: float = 1.0
    _slopes: F64 = field(init=False, repr=False)

    def __post_init__(self) -> None:
        t = _check_table(self.inverse)
        t.setflags(write=False)
        object.__setattr__(self, "inverse", t)
        for name in ("exposure_s", "gain", "sensitivity"):
            object.__setattr__(self, name, _positive(getattr(self, name), name))
        slopes = 1.0 / np.diff(t, axis=0)  # (255, 3) dv/dx on each segment
        slopes.setflags(write=False)
        object.__setattr__(self, "_slopes", slopes)

    # ------------------------------------------------------------------------------------------------------------
    # construction

    @classmethod
    def from_function(cls, inverse_fn: Any, *, exposure_s: float = 1.0, gain: float = 1.0,
                      sensitivity: float = 1.0) -> CameraResponse:
        """Tabulate a vectorized ``f⁻¹(v)`` (float pixel values → relative exposure) at v = 0..255."""
        values = np.arange(LEVELS, dtype=np.float64)
        return cls(np.asarray(inverse_fn(values), dtype=np.float64), exposure_s=exposure_s, gain=gain,
                   sensitivity=sensitivity)

    def with_exposure(self, *, exposure_s: float | None = None, gain: float | None = None) -> CameraResponse:
        """The same response at another exposure time and/or gain."""
        return replace(self, exposure_s=self.exposure_s if exposure_s is None else exposure_s,
                       gain=self.gain if gain is None else gain)

    # ------------------------------------------------------------------------------------------------------------
    # evaluation

    @property
    def exposure_factor(self) -> float:
        """``sensitivity · exposure_s · gain``: relative exposure per unit radiosity (the Δt of Eq. 4)."""
        return self.sensitivity * self.exposure_s * self.gain

    @property
    def saturation_exposure(self) -> F64:
        """(3,) the relative exposure at which each channel reaches 255."""
        return self.inverse[-1].copy()

    def exposure(self, radiosity: ArrayLike) -> F64:
        """Relative exposure ``x = exposure_factor · B`` of radiosity ``B`` (any shape)."""
        return np.asarray(radiosity, dtype=np.float64) * self.exposure_factor

    @staticmethod
    def _rgb(a: ArrayLike, name: str) -> F64:
        arr = np.asarray(a, dtype=np.float64)
        if arr.ndim < 1 or arr.shape[-1] != 3:
            raise CrfError(f"{name} must have shape (..., 3), got {arr.shape}")
        return arr

    def apply(self, x: ArrayLike) -> F64:
        """``f(x)``: relative exposures (..., 3) → float pixel values in [0, 255] (not rounded)."""
        xs = self._rgb(x, "exposures")
        out = np.empty(xs.shape, dtype=np.float64)
        values = np.arange(LEVELS, dtype=np.float64)
        for c in range(3):
            out[..., c] = np.interp(xs[..., c], self.inverse[:, c], values)
        return out

    def apply_radiosity(self, radiosity: ArrayLike) -> F64:
        """``f(exposure_factor · B)``: radiosity (..., 3) → float pixel values."""
        return self.apply(self.exposure(radiosity))

    def derivative(self, x: ArrayLike) -> F64:
        """``df/dx`` (..., 3): the slope of the table segment containing x; 0 below ``inverse[0]`` and at or beyond
        ``inverse[255]`` (saturation)."""
        return self.apply_and_derivative(x)[1]

    def apply_and_derivative(self, x: ArrayLike) -> tuple[F64, F64]:
        """``(f(x), f'(x))`` in one pass (what a least-squares residual and its Jacobian need)."""
        xs = self._rgb(x, "exposures")
        value = np.empty(xs.shape, dtype=np.float64)
        slope = np.empty(xs.shape, dtype=np.float64)
        for c in range(3):
            value[..., c], slope[..., c] = self.channel_and_derivative(xs[..., c], c)
        return value, slope

    def channel_table(self, channel: int) -> tuple[F64, F64]:
        """``(f⁻¹ table (256,), slopes (255,))`` of one channel, contiguous: ``f`` is linear between the table's
        entries with these slopes (what jitted callers of the response need)."""
        return np.ascontiguousarray(self.inverse[:, channel]), np.ascontiguousarray(self._slopes[:, channel])

    def channel_and_derivative(self, x: NDArray[np.floating], channel: int) -> tuple[F64, F64]:
        """``(f_c(x), f_c'(x))`` of one colour channel ``c`` for exposures ``x`` of any shape."""
        table = self.inverse[:, channel]
        k = np.searchsorted(table, x, side="right") - 1  # segment index; -1 below, 255 at/after the top
        inside = (k >= 0) & (k < LEVELS - 1)
        kk = np.clip(k, 0, LEVELS - 2)
        s = self._slopes[kk, channel]
        v = kk + (x - table[kk]) * s
        return np.where(inside, v, np.where(k < 0, 0.0, MAX_VALUE)), np.where(inside, s, 0.0)

    def linearize(self, pixels: ArrayLike) -> F64:
        """``f⁻¹``: pixel values (..., 3) (uint8 or float, clipped to [0, 255]) → relative exposures."""
        p = np.clip(self._rgb(pixels, "pixels"), 0.0, MAX_VALUE)
        out = np.empty(p.shape, dtype=np.float64)
        values = np.arange(LEVELS, dtype=np.float64)
        for c in range(3):
            out[..., c] = np.interp(p[..., c], values, self.inverse[:, c])
        return out

    def radiosity(self, pixels: ArrayLike) -> F64:
        """``I_B^live = f⁻¹(I_C) / Δt`` of Eq. 6 (with Δt = :attr:`exposure_factor`)."""
        return self.linearize(pixels) / self.exposure_factor

    # ------------------------------------------------------------------------------------------------------------
    # serialization

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "exposure_s": float(self.exposure_s),
            "gain": float(self.gain),
            "sensitivity": float(self.sensitivity),
            "inverse": {name: [float(v) for v in self.inverse[:, c]] for c, name in enumerate(CHANNELS)},
        }

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any], *, source: str = "<dict>") -> CameraResponse:
        """Build from a lightfast-crf mapping or a simulator ``camera.yaml`` mapping (see the module docstring)."""
        if not isinstance(doc, Mapping):
            raise CrfError(f"{source}: expected a YAML mapping, got {type(doc).__name__}")
        if doc.get("format") == FORMAT_NAME:
            version = doc.get("version")
            if version != FORMAT_VERSION:
                raise CrfError(f"{source}: unsupported {FORMAT_NAME} version {version!r} "
                               f"(this lightfast reads version {FORMAT_VERSION})")
            inv = doc.get("inverse")
            if not isinstance(inv, Mapping) or set(inv) != set(CHANNELS):
                raise CrfError(f"{source}: 'inverse' must map r, g, b to {LEVELS} values each")
            try:
                table = np.stack([np.asarray(inv[c], dtype=np.float64) for c in CHANNELS], axis=1)
            except (TypeError, ValueError) as exc:
                raise CrfError(f"{source}: bad 'inverse' table: {exc}") from None
            try:
                return cls(table, exposure_s=doc.get("exposure_s", 1.0), gain=doc.get("gain", 1.0),
                           sensitivity=doc.get("sensitivity", 1.0))
            except CrfError as exc:
                raise CrfError(f"{source}: {exc}") from None
        if "inverse_crf" in doc and "crf_model" in doc:
            return cls._from_sim_camera(doc, source)
        raise CrfError(f"{source}: not a camera response (expected 'format: {FORMAT_NAME}' or a simulator "
                       "camera.yaml with 'inverse_crf')")

    @classmethod
    def _from_sim_camera(cls, doc: Mapping[str, Any], source: str) -> CameraResponse:
        try:
            table = np.asarray(doc["inverse_crf"], dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise CrfError(f"{source}: bad 'inverse_crf': {exc}") from None
        try:
            per_radiance = _positive(doc.get("sensitivity", 1.0), "sensitivity")
            return cls(table, exposure_s=doc.get("exposure_s", 1.0), gain=doc.get("gain", 1.0),
                       sensitivity=per_radiance / math.pi)  # L = B / π for a Lambertian surface
        except CrfError as exc:
            raise CrfError(f"{source}: {exc}") from None


def load_crf(path: str | os.PathLike[str]) -> CameraResponse:
    """Load a camera response from a lightfast-crf YAML file or a simulator ``camera.yaml``."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise CrfError(f"cannot read camera response {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise CrfError(f"{path} is not a camera response (not text)") from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise CrfError(f"{path}: invalid YAML: {str(exc).splitlines()[0]}") from None
    return CameraResponse.from_dict(doc, source=str(path))


def save_crf(crf: CameraResponse, path: str | os.PathLike[str], *, description: str | None = None) -> Path:
    """Write ``crf`` as lightfast-crf YAML (atomically); returns the path."""
    path = Path(path)
    doc = crf.to_dict()
    if description:
        doc = {"description": description, **doc}
    write_text_atomic(path, yaml.safe_dump(doc, sort_keys=False, width=120))
    return path


# ----------------------------------------------------------------------------------------------------------------
# calibration from an exposure bracket


def _monotonize(table: F64) -> F64:
    """Force each column strictly increasing (calibration noise can make the ends flat or non-monotonic)."""
    t = np.maximum.accumulate(np.maximum(table, 0.0), axis=0)
    span = np.maximum(t[-1] - t[0], 1e-12)
    return t + np.arange(LEVELS)[:, None] * (1e-9 * span)  # break ties by a negligible ramp


def _fill_gaps(table: F64, method: str) -> F64:
    """Fill values the calibration could not determine (NaN/inf, e.g. Robertson at never-seen pixel values): linear
    interpolation inside, ``f⁻¹(0) = 0`` below, the last slope above."""
    out = table.copy()
    values = np.arange(LEVELS, dtype=np.float64)
    for c in range(3):
        ok = np.isfinite(out[:, c])
        if np.count_nonzero(ok) < 16 or not ok[128]:
            raise CrfError(f"{method} calibration left channel {CHANNELS[c]} undetermined at "
                           f"{LEVELS - np.count_nonzero(ok)} of {LEVELS} values (check the bracket covers the range)")
        if ok.all():
            continue
        xs, ys = values[ok], out[ok, c]
        if not ok[0]:
            xs, ys = np.r_[0.0, xs], np.r_[0.0, ys]
        top = int(xs[-1])
        out[:, c] = np.interp(values, xs, ys)
        if top < LEVELS - 1:
            slope = (ys[-1] - ys[-2]) / (xs[-1] - xs[-2])
            out[top + 1:, c] = ys[-1] + slope * (values[top + 1:] - top)
    return out


def calibrate_from_bracket(
    images: Sequence[ArrayLike],
    exposures_s: Sequence[float],
    *,
    method: Literal["debevec", "robertson"] = "debevec",
    samples: int = 70,
    smoothness: float = 10.0,
    max_iter: int = 30,
    exposure_s: float | None = None,
    gain: float = 1.0,
) -> CameraResponse:
    """Recover ``f⁻¹`` from a static scene shot at several exposure times (OpenCV Debevec or Robertson).

    Args:
        images: RGB images ``(H, W, 3)`` uint8 of the same static scene, all the same shape.
        exposures_s: exposure time of each image, seconds (> 0).
        method: ``"debevec"`` (``cv2.createCalibrateDebevec``, ``samples`` points, ``smoothness`` = λ) or
            ``"robertson"`` (``cv2.createCalibrateRobertson``, ``max_iter`` iterations).
        exposure_s: the exposure to store in the result (default: the median of ``exposures_s``).
        gain: the gain to store.

    Returns:
        A :class:`CameraResponse` whose table is normalized per channel to ``f⁻¹(128) = 1`` and made strictly
        increasing; ``sensitivity`` = 1.
    """
    import cv2  # local: only calibration needs OpenCV

    if len(images) < 2:
        raise CrfError(f"need at least 2 images in the bracket, got {len(images)}")
    if len(images) != len(exposures_s):
        raise CrfError(f"{len(images)} images but {len(exposures_s)} exposure times")
    times = np.array([_positive(t, "exposure time") for t in exposures_s], dtype=np.float32)
    if len(np.unique(times)) < 2:
        raise CrfError("the bracket needs at least two different exposure times")
    bgr: list[NDArray[Any]] = []
    for i, img in enumerate(images):
        a = np.asarray(img)
        if a.dtype != np.uint8:
            raise CrfError(f"image {i} must be uint8, got {a.dtype}")
        if a.ndim != 3 or a.shape[2] != 3:
            raise CrfError(f"image {i} must have shape (H, W, 3), got {a.shape}")
        if bgr and a.shape != bgr[0].shape:
            raise CrfError(f"image {i} has shape {a.shape}, image 0 has {bgr[0].shape}")
        bgr.append(np.ascontiguousarray(a[..., ::-1]))
    calib: cv2.CalibrateCRF
    if method == "debevec":
        if samples < 2:
            raise CrfError(f"samples must be >= 2, got {samples}")
        calib = cv2.createCalibrateDebevec(int(samples), float(smoothness), False)
    elif method == "robertson":
        calib = cv2.createCalibrateRobertson(int(max_iter), 0.001)
    else:
        raise CrfError(f"unknown calibration method {method!r} (use 'debevec' or 'robertson')")
    try:
        response = calib.process(bgr, times)
    except cv2.error as exc:
        raise CrfError(f"OpenCV {method} calibration failed: {str(exc).strip().splitlines()[-1]}") from None
    table = _fill_gaps(np.asarray(response, dtype=np.float64).reshape(LEVELS, 3)[:, ::-1], method)  # BGR → RGB
    if np.any(table[128] <= 0.0):
        raise CrfError(f"{method} calibration produced an unusable response (check the bracket covers the range)")
    table = _monotonize(table / table[128])
    table = table / table[128]
    log.debug("calibrated %s response from %d images", method, len(bgr))
    return CameraResponse(table, exposure_s=float(np.median(times)) if exposure_s is None else exposure_s,
                          gain=gain)


def calibrate_from_files(
    paths: Sequence[str | os.PathLike[str]],
    exposures_s: Sequence[float],
    output: str | os.PathLike[str],
    *,
    method: Literal["debevec", "robertson"] = "debevec",
    samples: int = 70,
    smoothness: float = 10.0,
    exposure_s: float | None = None,
    gain: float = 1.0,
) -> CameraResponse:
    """Read an exposure bracket from image files (8-bit colour), calibrate it (:func:`calibrate_from_bracket`) and
    write the response to ``output`` (:func:`save_crf`, described by its images); returns the response. Backs
    ``lightfast crf calibrate``."""
    import cv2

    images = []
    for p in map(Path, paths):
        img = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if img is None:
            raise CrfError(f"cannot read image {p}")
        images.append(img[..., ::-1])
    crf = calibrate_from_bracket(images, exposures_s, method=method, samples=samples, smoothness=smoothness,
                                 exposure_s=exposure_s, gain=gain)
    save_crf(crf, output, description=f"{method} calibration from {len(images)} images: "
             + ", ".join(f"{Path(p).name}@{t:g}s" for p, t in zip(paths, exposures_s, strict=True)))
    log.info("wrote %s", output)
    return crf
