"""Procedural surface appearance of the simulated rACR scenes (paper §5.1: textured subjects whose appearance
changes with the light): solid noise, surface canvases and materials.

* Noise: :func:`value_noise3` (smooth 3-D value noise in [0, 1], unit lattice spacing) and :func:`fbm3` (fractal,
  largest features ``scale_m``) of world points ``p`` (N, 3) in metres; :func:`hash3` a value in [0, 1) per
  integer lattice point.
* :class:`Canvas`: a float32 raster over a surface's coordinates ``(u, v)`` in metres (column ``u / px_m``, row
  ``(size_v − v) / px_m``: OpenCV drawings, y down, appear upright), sampled bilinearly. A one-channel canvas is a
  relief height map in metres (:func:`add_relief` raises or carves a mask with bevelled walls, :func:`text_lines`
  draws Hershey-font inscriptions); a four-channel one is an RGBA decal (printed labels).
* Materials (:data:`Material`): ``f(p (N, 3) m, h (N,) relief height m, uv (N, 2) m) → linear RGB albedo (N, 3)``,
  from solid noise at several scales so texture runs on across edges: stone (5 cm blotches, 4 mm grain, 1.5 mm
  speckles, grime in carved recesses, optional lichen), painted metal (mottling, scratches to bare metal, rust),
  metal, wood grain, plaster (stains) and outdoor paving slabs.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Canvas",
    "Material",
    "add_relief",
    "blur",
    "fbm3",
    "hash3",
    "mask",
    "metal",
    "paint",
    "paving",
    "plaster",
    "profile",
    "stone",
    "text_lines",
    "value_noise3",
    "wood",
    "words",
]

F64 = NDArray[np.float64]


# ================================================================================================================
# procedural noise and canvases


def hash3(ix: NDArray[np.int64], iy: NDArray[np.int64], iz: NDArray[np.int64], seed: int) -> F64:
    """A deterministic pseudo-random value in [0, 1) per integer lattice point."""
    m = np.uint64(0xFFFFFFFF)
    h = (ix.astype(np.uint64) * np.uint64(374761393) + iy.astype(np.uint64) * np.uint64(668265263)
         + iz.astype(np.uint64) * np.uint64(2147483647) + np.uint64((seed * 2654435761) % (1 << 32))) & m
    h = ((h ^ (h >> np.uint64(13))) * np.uint64(1274126177)) & m
    h ^= h >> np.uint64(16)
    return h.astype(np.float64) / 4294967296.0


def value_noise3(p: F64, seed: int) -> F64:
    """Smooth 3-D value noise in [0, 1] with unit lattice spacing at points ``p`` (N, 3)."""
    fl = np.floor(p)
    f = p - fl
    i = fl.astype(np.int64)
    s = f * f * (3.0 - 2.0 * f)
    out = np.zeros(len(p))
    for dx in (0, 1):
        wx = s[:, 0] if dx else 1.0 - s[:, 0]
        for dy in (0, 1):
            wy = s[:, 1] if dy else 1.0 - s[:, 1]
            for dz in (0, 1):
                wz = s[:, 2] if dz else 1.0 - s[:, 2]
                out += wx * wy * wz * hash3(i[:, 0] + dx, i[:, 1] + dy, i[:, 2] + dz, seed)
    return out


def fbm3(p: F64, scale_m: float, seed: int, octaves: int = 3) -> F64:
    """Fractal 3-D value noise in about [0, 1] with largest features of ``scale_m``."""
    total, amp, norm = np.zeros(len(p)), 1.0, 0.0
    q = p / scale_m
    for k in range(octaves):
        total += amp * value_noise3(q * 2.0**k + 17.3 * k, seed + 101 * k)
        norm += amp
        amp *= 0.5
    return total / norm


@dataclass
class Canvas:
    """A raster over surface coordinates ``(u, v)`` in metres: column ``u / px_m``, row ``(size_v − v) / px_m``
    (so drawings made with OpenCV, y down, appear upright on a surface whose v axis points up)."""

    data: NDArray[np.float32]  # (H, W) or (H, W, C)
    px_m: float
    wrap_u: bool = False

    @classmethod
    def blank(cls, size_u: float, size_v: float, px_m: float, channels: int = 0, *, wrap_u: bool = False) -> Canvas:
        w, h = max(2, math.ceil(size_u / px_m)), max(2, math.ceil(size_v / px_m))
        shape = (h, w) if channels == 0 else (h, w, channels)
        return cls(np.zeros(shape, np.float32), px_m, wrap_u)

    @property
    def size_v(self) -> float:
        return self.data.shape[0] * self.px_m

    def px(self, u_m: float, v_m: float) -> tuple[int, int]:
        """OpenCV point (x, y) of the surface coordinates."""
        return round(u_m / self.px_m), round((self.size_v - v_m) / self.px_m)

    def sample(self, u: F64, v: F64) -> F64:
        img = self.data
        H, W = img.shape[:2]
        x = u / self.px_m - 0.5
        y = (self.size_v - v) / self.px_m - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
        if self.wrap_u:
            xa, xb = x0 % W, (x0 + 1) % W
        else:
            xa, xb = np.clip(x0, 0, W - 1), np.clip(x0 + 1, 0, W - 1)
        ya, yb = np.clip(y0, 0, H - 1), np.clip(y0 + 1, 0, H - 1)
        if img.ndim == 3:
            fx, fy = fx[:, None], fy[:, None]
        return ((img[ya, xa] * (1 - fx) + img[ya, xb] * fx) * (1 - fy)
                + (img[yb, xa] * (1 - fx) + img[yb, xb] * fx) * fy).astype(np.float64)


def blur(a: NDArray[np.float32], sigma: float) -> NDArray[np.float32]:
    """``cv2.GaussianBlur`` of a canvas' data, the kernel size from ``sigma`` (float32 in, float32 out)."""
    return cast(NDArray[np.float32], cv2.GaussianBlur(a, (0, 0), sigma))


def mask(canvas: Canvas) -> NDArray[np.uint8]:
    return np.zeros(canvas.data.shape[:2], np.uint8)


def profile(mask: NDArray[np.uint8], px_m: float, width_m: float) -> NDArray[np.float32]:
    """0 outside the mask, rising to 1 at ``width_m`` inside it (distance transform: bevelled / V-cut walls)."""
    d = cv2.distanceTransform((mask > 0).astype(np.uint8), cv2.DIST_L2, 5) * px_m
    return np.clip(d / max(width_m, 1e-9), 0.0, 1.0).astype(np.float32)


def add_relief(canvas: Canvas, mask: NDArray[np.uint8], height_m: float, width_m: float) -> None:
    """Raise (height > 0) or carve (height < 0) the masked area with bevelled walls ``width_m`` wide."""
    canvas.data += height_m * profile(mask, canvas.px_m, width_m)


def text_lines(canvas: Canvas, mask: NDArray[np.uint8], lines: Sequence[str], box: tuple[float, float, float, float],
                font: int, thickness_m: float) -> None:
    """Draw text lines filling the box ``(u0, v0, u1, v1)`` (metres), centred, into ``mask``."""
    u0, v0, u1, v1 = box
    n = len(lines)
    line_h = (v1 - v0) / n
    th = max(1, round(thickness_m / canvas.px_m))
    for k, text in enumerate(lines):
        (tw, tht), _ = cv2.getTextSize(text, font, 1.0, th)
        scale = min((u1 - u0) / canvas.px_m / max(tw, 1), 0.62 * line_h / canvas.px_m / max(tht, 1))
        (tw, tht), _ = cv2.getTextSize(text, font, scale, th)
        cx = 0.5 * (u0 + u1) / canvas.px_m
        v_base = v1 - (k + 0.78) * line_h
        _, y = canvas.px(0.0, v_base)
        cv2.putText(mask, text, (int(cx - tw / 2), y), font, scale, 255, th, cv2.LINE_AA)


_WORDS = ("SENATVS", "POPVLVS", "ROMANVS", "IMPERATOR", "AVGVSTVS", "ANNO", "DOMINI", "MDCCLXXI", "PAX", "LVX",
          "TEMPLVM", "FORTVNA", "VIRTVS", "MEMORIA", "AETERNA", "CIVITAS", "NOVA", "AQVA", "TERRA", "SOL", "LVNA",
          "VIA", "PORTA", "MAGNA", "REGIO", "XII", "IV", "DCCC", "FECIT", "OPVS", "HIC", "EST", "SACRVM")
FONTS = (cv2.FONT_HERSHEY_COMPLEX, cv2.FONT_HERSHEY_TRIPLEX, cv2.FONT_HERSHEY_DUPLEX, cv2.FONT_HERSHEY_SIMPLEX)


def words(rng: np.random.Generator, n: int) -> str:
    return " ".join(_WORDS[int(i)] for i in rng.integers(0, len(_WORDS), n))


# ================================================================================================================
# materials: albedo from position, relief height and surface coordinates

Material = Callable[[F64, F64, F64], F64]


def _rgb(c: ArrayLike) -> F64:
    return np.asarray(c, dtype=np.float64)


def stone(base: ArrayLike, seed: int, *, contrast: float = 0.22, lichen: float = 0.0,
          grime: float = 0.45) -> Material:
    """Stone: blotches (5 cm), grain (4 mm), dark/bright speckles (1.5 mm), grime in recesses, optional lichen."""
    b = _rgb(base)

    def f(p: F64, h: F64, uv: F64) -> F64:
        m = (1.0 - contrast + 2.0 * contrast * fbm3(p, 0.05, seed)) * (0.86 + 0.28 * fbm3(p, 0.004, seed + 1, 2))
        sp = value_noise3(p / 0.0015, seed + 2)
        m = m * np.where(sp > 0.86, 0.62, 1.0) * np.where(sp < 0.07, 1.25, 1.0)
        m = m * (1.0 - grime * np.clip(-h / 0.004, 0.0, 1.0))
        rho = b[None, :] * m[:, None]
        if lichen > 0.0:
            lm = np.clip((fbm3(p, 0.07, seed + 3) - (1.0 - lichen)) / 0.08, 0.0, 1.0)[:, None]
            moss = np.array([0.30, 0.33, 0.16]) * (0.7 + 0.6 * fbm3(p, 0.006, seed + 4, 2))[:, None]
            rho = rho * (1 - lm) + lm * moss
        return rho
    return f


def paint(base: ArrayLike, seed: int, *, rust: float = 0.0, scratches: float = 0.5) -> Material:
    """Painted metal: slight mottling, scratches down to bare metal, rust stains, grime in recesses."""
    b = _rgb(base)

    def f(p: F64, h: F64, uv: F64) -> F64:
        m = 0.9 + 0.2 * fbm3(p, 0.02, seed, 2) + 0.08 * (value_noise3(p / 0.002, seed + 1) - 0.5)
        rho = b[None, :] * m[:, None]
        if scratches > 0.0:
            q = p * np.array([1 / 0.0012, 1 / 0.03, 1 / 0.0012])
            s = np.abs(value_noise3(q, seed + 2) - 0.5) < 0.012 * scratches
            q2 = p * np.array([1 / 0.03, 1 / 0.0012, 1 / 0.0012]) + 3.1
            s |= np.abs(value_noise3(q2, seed + 5) - 0.5) < 0.01 * scratches
            rho[s] = np.array([0.42, 0.42, 0.44])
        if rust > 0.0:
            r = np.clip((fbm3(p, 0.04, seed + 3) - (1.0 - rust)) / 0.1, 0.0, 1.0)[:, None]
            rho = rho * (1 - r) + r * np.array([0.32, 0.15, 0.07]) * (0.6 + 0.8 * fbm3(p, 0.003, seed + 4, 2))[:, None]
        return rho * (1.0 - 0.4 * np.clip(-h / 0.004, 0.0, 1.0))[:, None]
    return f


def metal(base: ArrayLike, seed: int) -> Material:
    b = _rgb(base)

    def f(p: F64, h: F64, uv: F64) -> F64:
        return b[None, :] * (0.8 + 0.4 * fbm3(p, 0.005, seed, 2))[:, None]
    return f


def wood(base: ArrayLike, seed: int, *, axis: int = 0) -> Material:
    """Wood grain along the world ``axis``: distorted rings and streaks."""
    b = _rgb(base)

    def f(p: F64, h: F64, uv: F64) -> F64:
        o = [k for k in range(3) if k != axis]
        r = np.sqrt(p[:, o[0]] ** 2 + (p[:, o[1]] + 0.7) ** 2)
        rings = 0.5 + 0.5 * np.sin(2 * math.pi * (r / 0.007 + 5.0 * fbm3(p, 0.25, seed, 2)))
        streak = fbm3(p * np.where(np.arange(3) == axis, 0.05, 1.0), 0.004, seed + 1, 2)
        m = 0.72 + 0.2 * rings + 0.3 * (streak - 0.5)
        return b[None, :] * m[:, None] * (1.0 - 0.4 * np.clip(-h / 0.004, 0.0, 1.0))[:, None]
    return f


def plaster(base: ArrayLike, seed: int) -> Material:
    b = _rgb(base)

    def f(p: F64, h: F64, uv: F64) -> F64:
        m = 0.82 + 0.22 * fbm3(p, 0.15, seed) + 0.1 * (fbm3(p, 0.005, seed + 1, 2) - 0.5)
        stain = np.clip((fbm3(p, 0.1, seed + 2) - 0.66) / 0.1, 0.0, 1.0) * 0.25
        return b[None, :] * (m * (1 - stain))[:, None]
    return f


def paving(seed: int, tile_m: float = 0.3) -> Material:
    """Outdoor paving: square slabs of varying tone, dark joints, gravel speckle."""
    def f(p: F64, h: F64, uv: F64) -> F64:
        ix, iy = np.floor(p[:, 0] / tile_m).astype(np.int64), np.floor(p[:, 1] / tile_m).astype(np.int64)
        tone = 0.75 + 0.5 * hash3(ix, iy, np.zeros_like(ix), seed)
        fx, fy = p[:, 0] / tile_m - ix, p[:, 1] / tile_m - iy
        joint = (np.minimum(fx, 1 - fx) < 0.025) | (np.minimum(fy, 1 - fy) < 0.025)
        m = tone * (0.8 + 0.35 * fbm3(p, 0.006, seed + 1, 2)) * (0.85 + 0.3 * fbm3(p, 0.12, seed + 2))
        m = np.where(joint, 0.35, m)
        return np.array([0.36, 0.34, 0.31])[None, :] * m[:, None]
    return f
