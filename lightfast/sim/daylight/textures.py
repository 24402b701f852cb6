"""Procedural reflectance textures (the materials of the daylight test room), vectorized over vertices.

A :data:`Texture` maps local surface coordinates ``(u_m, v_m)`` in metres (N,) each to an (N, 3) **linear** RGB
diffuse reflectance (not sRGB; the mesh builder clips it to [0.03, 0.9]): uniform colours, value noise and its
fractal sum, wood grain with planks and joints, stripes, checkers, printed-like posters and calendars, a rug and
book spines. Everything is deterministic in its ``seed``.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Texture",
    "book_spine",
    "checker",
    "fbm",
    "noisy",
    "printed",
    "rgb",
    "rug",
    "stripes",
    "uniform",
    "value_noise",
    "wood",
]

Texture = Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]]
"""``texture(u_m, v_m) -> (N, 3)`` reflectance from local surface coordinates in metres."""


def _hash01(ix: NDArray[np.int64], iy: NDArray[np.int64], seed: int) -> NDArray[np.float64]:
    """A deterministic pseudo-random value in [0, 1) per integer lattice point."""
    h = (ix.astype(np.uint64) * np.uint64(374761393) + iy.astype(np.uint64) * np.uint64(668265263)
         + np.uint64(seed * 2654435761 % (1 << 32))) & np.uint64(0xFFFFFFFF)
    h = ((h ^ (h >> np.uint64(13))) * np.uint64(1274126177)) & np.uint64(0xFFFFFFFF)
    h ^= h >> np.uint64(16)
    return h.astype(np.float64) / 4294967296.0


def value_noise(u: NDArray[np.float64], v: NDArray[np.float64], seed: int) -> NDArray[np.float64]:
    """Smooth 2-D value noise in [0, 1] with unit lattice spacing."""
    iu, iv = np.floor(u), np.floor(v)
    fu, fv = u - iu, v - iv
    iu, iv = iu.astype(np.int64), iv.astype(np.int64)
    su, sv = fu * fu * (3 - 2 * fu), fv * fv * (3 - 2 * fv)
    a, b = _hash01(iu, iv, seed), _hash01(iu + 1, iv, seed)
    c, d = _hash01(iu, iv + 1, seed), _hash01(iu + 1, iv + 1, seed)
    return (a * (1 - su) + b * su) * (1 - sv) + (c * (1 - su) + d * su) * sv


def fbm(u: NDArray[np.float64], v: NDArray[np.float64], seed: int, octaves: int = 4) -> NDArray[np.float64]:
    """Fractal value noise in about [0, 1] (octaves of :func:`value_noise`, halving amplitude)."""
    total, amp, norm = np.zeros_like(u), 1.0, 0.0
    for k in range(octaves):
        total += amp * value_noise(u * 2.0**k, v * 2.0**k, seed + 101 * k)
        norm += amp
        amp *= 0.5
    return total / norm


def rgb(c: ArrayLike, n: int) -> NDArray[np.float64]:
    """The colour ``c`` repeated as an (n, 3) array (a writable copy)."""
    return np.broadcast_to(np.asarray(c, dtype=np.float64), (n, 3)).copy()


def uniform(color: Sequence[float]) -> Texture:
    return lambda u, v: rgb(color, len(u))


def noisy(color: Sequence[float], amount: float, scale_m: float, seed: int) -> Texture:
    """``color`` modulated by ±``amount`` (relative) of fractal noise with features of ``scale_m``."""
    def tex(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        n = fbm(u / scale_m, v / scale_m, seed) - 0.5
        return rgb(color, len(u)) * (1.0 + 2.0 * amount * n)[:, None]
    return tex


def wood(base: Sequence[float], *, plank_m: float | None, seed: int, along_v: bool = False) -> Texture:
    """Wood grain along u (or v): rings distorted by noise, optional planks of width ``plank_m`` with jittered
    tone and dark joints."""
    base_arr = np.asarray(base, dtype=np.float64)

    def tex(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        a, b = (v, u) if along_v else (u, v)
        offset = np.zeros_like(a)
        tone = np.ones_like(a)
        joint = np.zeros_like(a, dtype=bool)
        if plank_m:
            k = np.floor(b / plank_m)
            offset = _hash01(k.astype(np.int64), np.zeros_like(k, dtype=np.int64), seed) * 7.0
            tone = 0.8 + 0.4 * _hash01(k.astype(np.int64), np.ones_like(k, dtype=np.int64), seed)
            frac = b / plank_m - k
            joint = (frac < 0.04) | (frac > 0.96)
            # staggered butt joints every 1.2 m
            seg = (a + offset * 0.17) / 1.2
            joint |= np.abs(seg - np.round(seg)) < 0.01
        warp = fbm(a / 0.35 + offset, b / 0.05, seed + 7, 3)
        rings = 0.5 + 0.5 * np.sin(2 * math.pi * (b / 0.013 + 6.0 * warp))
        streak = fbm(a / 0.6 + offset, b / 0.01, seed + 13, 2)
        m = (0.72 + 0.22 * rings + 0.25 * (streak - 0.5)) * tone
        out = base_arr[None, :] * m[:, None]
        out[joint] *= 0.45
        return out
    return tex


def stripes(colors: Sequence[Sequence[float]], width_m: float, *, along_v: bool = False) -> Texture:
    cols = np.asarray(colors, dtype=np.float64)

    def tex(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        a = v if along_v else u
        return cols[np.floor(a / width_m).astype(np.int64) % len(cols)]
    return tex


def checker(c0: Sequence[float], c1: Sequence[float], size_m: float) -> Texture:
    def tex(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        k = (np.floor(u / size_m) + np.floor(v / size_m)).astype(np.int64) % 2
        return np.where(k[:, None] == 0, np.asarray(c0), np.asarray(c1))
    return tex


def printed(width_m: float, height_m: float, seed: int, *, style: str = "poster") -> Texture:
    """A printed-like sheet: coloured blocks, discs and lines of 'text' (dark dashes) on a light background, or
    (style ``"calendar"``) a grid of day cells with numbers-like blobs."""
    rng = np.random.default_rng(seed)
    bg = np.array([0.78, 0.76, 0.70]) * rng.uniform(0.9, 1.1)
    shapes: list[tuple[str, tuple[float, ...], NDArray[np.float64]]] = []
    palette = np.array([[0.7, 0.12, 0.08], [0.1, 0.25, 0.6], [0.85, 0.6, 0.1], [0.1, 0.45, 0.2],
                        [0.35, 0.1, 0.45], [0.05, 0.05, 0.06], [0.8, 0.4, 0.5]])
    if style == "calendar":
        shapes.append(("rect", (0.05, 0.62 * height_m, width_m - 0.05, height_m - 0.05), palette[rng.integers(7)]))
        cw, ch = (width_m - 0.08) / 7, (0.55 * height_m - 0.04) / 5
        for i in range(7):
            for j in range(5):
                x0, y0 = 0.04 + i * cw, 0.04 + j * ch
                shapes.append(("frame", (x0, y0, x0 + cw, y0 + ch, 0.006), np.array([0.15, 0.15, 0.18])))
                shapes.append(("rect", (x0 + 0.2 * cw, y0 + 0.55 * ch, x0 + 0.55 * cw, y0 + 0.85 * ch),
                               np.array([0.1, 0.1, 0.12]) if i < 5 else np.array([0.6, 0.1, 0.1])))
    else:
        img_h = rng.uniform(0.45, 0.65) * height_m
        shapes.append(("rect", (0.05, height_m - img_h - 0.05, width_m - 0.05, height_m - 0.05),
                       palette[rng.integers(7)] * 0.8 + 0.1))
        for _ in range(rng.integers(3, 7)):
            cx, cy = rng.uniform(0.1, width_m - 0.1), rng.uniform(height_m - img_h, height_m - 0.1)
            r = rng.uniform(0.04, 0.18) * min(width_m, img_h)
            kind = "disc" if rng.random() < 0.5 else "rect"
            geom = (cx, cy, r) if kind == "disc" else (cx - r, cy - r * 0.7, cx + r, cy + r * 0.7)
            shapes.append((kind, geom, palette[rng.integers(7)]))
        y = height_m - img_h - 0.1
        line_h = rng.uniform(0.018, 0.03)
        while y > 0.06:
            x = 0.06
            while x < width_m - 0.1:
                w = rng.uniform(0.03, 0.12)
                shapes.append(("rect", (x, y, min(x + w, width_m - 0.06), y + line_h), np.array([0.06, 0.06, 0.07])))
                x += w + rng.uniform(0.015, 0.03)
            y -= line_h * rng.uniform(1.8, 2.6)

    def tex(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        out = rgb(bg, len(u))
        for kind, g, col in shapes:
            if kind == "rect":
                m = (u >= g[0]) & (u <= g[2]) & (v >= g[1]) & (v <= g[3])
            elif kind == "disc":
                m = (u - g[0]) ** 2 + (v - g[1]) ** 2 <= g[2] ** 2
            else:  # frame: the border of a rectangle
                inside = (u >= g[0]) & (u <= g[2]) & (v >= g[1]) & (v <= g[3])
                inner = (u >= g[0] + g[4]) & (u <= g[2] - g[4]) & (v >= g[1] + g[4]) & (v <= g[3] - g[4])
                m = inside & ~inner
            out[m] = col
        return out
    return tex


def rug(width_m: float, height_m: float, seed: int) -> Texture:
    """A patterned rug: border bands, a diamond lattice and woven noise."""
    c_border, c_band = np.array([0.45, 0.08, 0.07]), np.array([0.8, 0.65, 0.35])
    c_a, c_b = np.array([0.12, 0.18, 0.4]), np.array([0.7, 0.55, 0.3])

    def tex(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        d = np.minimum(np.minimum(u, width_m - u), np.minimum(v, height_m - v))
        diamond = (np.abs((u % 0.3) - 0.15) + np.abs((v % 0.3) - 0.15)) < 0.09
        out = np.where(diamond[:, None], c_b, c_a)
        out = np.where((d < 0.18)[:, None], c_band, out)
        out = np.where((d < 0.12)[:, None], c_border, out)
        out = np.where(((d > 0.05) & (d < 0.07))[:, None], c_band, out)
        weave = 0.85 + 0.3 * fbm(u / 0.02, v / 0.02, seed, 2)
        return out * weave[:, None]
    return tex


def book_spine(color: NDArray[np.float64], height_m: float, seed: int) -> Texture:
    """A book spine on a face whose u axis points up: a light label band and a dark line."""
    rng = np.random.default_rng(seed)
    band = (rng.uniform(0.55, 0.7), rng.uniform(0.75, 0.85))
    light = np.clip(color * 0.4 + 0.5, 0, 1)

    def tex(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        out = rgb(color, len(u))
        hv = u / height_m
        out[(hv > band[0]) & (hv < band[1])] = light
        out[(hv > 0.1) & (hv < 0.13)] *= 0.4
        return out
    return tex

