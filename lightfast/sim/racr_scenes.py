"""Simulated rACR scenes (paper §5.1): 20 textured scenes with 3-D micro-structure, their lighting, an Embree
renderer, the AFD metric and the scene files written by ``lightfast sim racr``.

Everything here is the *simulator and evaluation* side. rACR itself reads only a scene's ``reference/``
directory (:func:`load_reference`) and, at run time, what the platform and the VSE stand-in
(:mod:`lightfast.sim.racr_platform`) publish: images, a scaled point cloud, VSE poses and reported hand poses.

Scenes
------
S01–S10 are indoor scenes on a wooden table in front of a plaster wall, lit by a point light (an LED on an arm);
S11–S20 are outdoor scenes on paving, lit by the sun and the sky at a site and local time (two of them, S14 and
S15, are relocalized at night under a floodlight, the paper's day–night scenes). The subjects are built from
procedural triangle meshes, z up, the subject's front facing −y:

========  ============================================================================================
recipe    geometry
========  ============================================================================================
panel     carved relief panel: raised frame with a carved meander or rope groove, raised rosette or
          scrolls with carved veins, a carved inscription line; sandstone, marble, wood or plaster
tablet    inscription tablet / stele: carved border, 4–6 lines of V-cut letters (Hershey fonts), pits
cabinet   equipment cabinet: door seam, vent slots, raised name plate, labels, hex bolts, a pipe with
          flanges and bolt circles, a gauge
motor     electric motor / pump: finned body (lathe with displaced fins), end shields with bolt circles,
          shaft and coupling, feet, terminal box with bolts and labels
stupa     stupa: plinth with carved niches, drum with a carved band, bell dome with a lotus-petal band,
          harmika, ringed spire, finial
facade    stone facade: staggered blocks with recessed joints and bevels, a carved emblem block with an
          inscription, a cornice with dentils
bogie     train bogie side: frame plate with lightening holes, ribs and stamped text, wheels with carved
          rings, axle boxes with bolts and labels, coil springs, rails on ballast
========  ============================================================================================

Surfaces carry per-vertex linear RGB albedo from solid (3-D) value noise at several scales (blotches, grain,
1.5 mm speckles), grime in carved recesses, paint with scratches and rust, and printed labels. Detailed surfaces
use a vertex step of ``resolution_m`` (default 2.5 mm), backdrops a coarser one; a scene has 150–350 k triangles
at the default resolution.

Lighting (:class:`LightingSpec` → :class:`Lighting`)
----------------------------------------------------
Each scene has three variants: ``reference`` (the reference observation), ``similar`` (a small change) and
``varied`` (a large one). Indoor: a point light at "clock" position ``clock_h`` around the reference camera's
axis (12 = above, 3 = right as seen by the camera), tilted ``tilt_deg`` off that axis at ``distance_m`` from the
subject: reference 12 o'clock at 30–40° (front light), similar 11 or 1 o'clock, varied a side light at 2, 3, 9 or
10 o'clock at 65–78° (grazing, long shadows). Irradiance ``I cos θ / r²`` with a shadow ray, plus a uniform room
radiance of ``ambient_frac`` of the front irradiance. Outdoor: the sun from the NREL SPA
(:func:`lightfast.daylight.sun.sun_position`) at the scene's site and local time, clear-sky DNI/DHI from pvlib
with the sun's colour (:mod:`lightfast.sim.sky_model`), ``sun_transmittance`` < 1 for haze/cloud (dims the sun,
adds an overcast component); similar = the same time of day a few days later with a slightly different
transmittance, varied = another time of day (the sun on the other side) or night with a floodlight.

Sky and room light use a per-vertex visibility cache: for 64 fixed Fibonacci directions each vertex stores
whether a ray leaves the scene (ambient occlusion); a vertex's ambient irradiance is
``Σ_k cos⁺θ_k (V_k L(ω_k) + (1 − V_k) L_bounce) 4π/64`` with the sky radiance (CIE clear sky + ground glow) or
the room radiance ``L``, and a crude one-bounce radiance ``L_bounce`` for blocked directions.

Renderer (:class:`RacrRenderer`)
--------------------------------
One primary ray per pixel (Embree, batched, threads), barycentric interpolation of albedo, shading normal and
ambient irradiance, one shadow ray per lit pixel towards the point light or the sun (hard shadows), radiance
``L = ρ/π (E_direct + E_ambient)``; rays that miss see the sky (outdoor) or the room. The camera
(:class:`SensorModel`): fixed exposure per session (auto-exposed once per lighting at scene generation: the 98th
percentile of the probe's luminance maps to 0.8 of saturation), Gaussian shot noise (full well 8000 e⁻) and read
noise, sRGB transfer, 8 bits. Intrinsics: fx = fy = 525 px at 640 × 480 (Kinect-like), scaled for other sizes.

AFD (:func:`afd`, the paper's metric)
-------------------------------------
The average feature-point displacement between the final and the reference image, computed from the truth: a
regular grid of ``AFD_GRID`` pixels of the reference image is cast onto the scene (the fixed scene points), the
points are projected with the reference and the final camera pose, and the mean pixel distance over the points
visible in both (in the image, in front, not occluded) is the AFD. Success: AFD < 3 px.

Files (:func:`generate_racr_set`, ``lightfast sim racr OUT``)
------------------------------------------------------------
Per scene ``OUT/S01/`` (built under a temporary name and renamed when complete)::

    scene.yaml      simulator setup: format, scene info, camera intrinsics, lighting variants (resolved: light
                    position or sun azimuth/elevation, exposure), the initial pose offset T_camref_cam0, the
                    platform and VSE configurations; ``truth:`` holds X = T_cam_hand, T_world_base and the VSE's
                    monocular scale (rACR must not read this section, nor this file)
    mesh.ply        the scene mesh with linear RGB albedo (truth geometry, simulator only)
    reference/      THE REFERENCE OBSERVATION, the only input rACR reads (format ``lightfast-racr-reference``,
                    version 1, written atomically):
                      reference.yaml  format, version, scene name, lighting, frame, intrinsics, T_ref_camref
                      points.npz      points_m (N, 3) float32 (frame ``reference``, metres), intensity (N,)
                                      float32 grey value in [0, 1] (np.load(allow_pickle=False))
                      image.png       the reference image, 8-bit RGB
    truth.yaml      evaluation truth: T_world_camref, T_world_cam0, T_world_ref (the reference cloud's frame),
                    X, the VSE scale, the AFD grid (pixels and world points)
    preview/        PNGs for a human: the reference view under the varied lighting, the initial view under the
                    similar and the varied lighting
    scene.json      manifest, written last: parameter hash, format version, SHA-256 of every file, statistics

A scene directory whose manifest matches the parameters and whose files match their hashes is reused.
"""
from __future__ import annotations

import dataclasses
import datetime as dt
import hashlib
import itertools
import json
import logging
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.daylight.errors import MeshError
from lightfast.daylight.mesh import ReflectanceMesh, load_ply, save_ply
from lightfast.daylight.sun import Site, sun_position
from lightfast.geometry import inverse, make_transform, so3_exp
from lightfast.io import atomic_directory, write_bytes_atomic, write_text_atomic
from lightfast.progress import track
from lightfast.racr.reference import (
    REFERENCE_VERSION,
    ReferenceObservation,
    camera_from_dict,
    camera_to_dict,
    load_reference,
    matrix_from,
    matrix_to_list,
    png_bytes,
    write_reference,
    yaml_text,
)
from lightfast.raycast import RayCaster
from lightfast.sim.errors import RacrSimError
from lightfast.sim.racr_platform import PlatformConfig, PlatformSimulator, VseConfig, VseStandIn
from lightfast.sim.sky_model import (
    CLEAR_SKY_RGB,
    LUMA,
    OVERCAST_SKY_RGB,
    SkyState,
    clear_sky_irradiance,
    float3,
    sun_rgb,
)

__all__ = [
    "AFD_GRID",
    "AFD_SUCCESS_PX",
    "FORMAT_VERSION",
    "AfdResult",
    "Lighting",
    "LightingSpec",
    "RacrRenderer",
    "RacrScene",
    "RacrSceneSpec",
    "RenderResult",
    "SceneTruth",
    "SensorModel",
    "afd",
    "afd_grid_points",
    "build_scene",
    "camera_for_size",
    "generate_racr_set",
    "load_scene",
    "look_at",
    "make_reference",
    "resolve_lighting",
    "scene_complete",
    "scene_specs",
    "write_scene",
]

log = logging.getLogger(__name__)

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]

#: Version of the scene directory layout (scene.yaml, truth.yaml, manifest); bump when outputs change.
FORMAT_VERSION = 1
#: Format name and version of the reference observation directory.
#: AFD grid (columns, rows) of reference pixels, and the success threshold (paper: AFD < 3).
AFD_GRID = (24, 18)
AFD_SUCCESS_PX = 3.0
#: Number of fixed directions of the ambient visibility cache.
AMBIENT_DIRECTIONS = 64
DEFAULT_RESOLUTION_M = 0.0025
_EPS_M = 2e-4


# ================================================================================================================
# procedural noise and canvases


def _hash3(ix: NDArray[np.int64], iy: NDArray[np.int64], iz: NDArray[np.int64], seed: int) -> F64:
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
                out += wx * wy * wz * _hash3(i[:, 0] + dx, i[:, 1] + dy, i[:, 2] + dz, seed)
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


def _blur(a: NDArray[np.float32], sigma: float) -> NDArray[np.float32]:
    """``cv2.GaussianBlur`` of a canvas' data, the kernel size from ``sigma`` (float32 in, float32 out)."""
    return cast(NDArray[np.float32], cv2.GaussianBlur(a, (0, 0), sigma))


def _mask(canvas: Canvas) -> NDArray[np.uint8]:
    return np.zeros(canvas.data.shape[:2], np.uint8)


def _profile(mask: NDArray[np.uint8], px_m: float, width_m: float) -> NDArray[np.float32]:
    """0 outside the mask, rising to 1 at ``width_m`` inside it (distance transform: bevelled / V-cut walls)."""
    d = cv2.distanceTransform((mask > 0).astype(np.uint8), cv2.DIST_L2, 5) * px_m
    return np.clip(d / max(width_m, 1e-9), 0.0, 1.0).astype(np.float32)


def _add_relief(canvas: Canvas, mask: NDArray[np.uint8], height_m: float, width_m: float) -> None:
    """Raise (height > 0) or carve (height < 0) the masked area with bevelled walls ``width_m`` wide."""
    canvas.data += height_m * _profile(mask, canvas.px_m, width_m)


def _text_lines(canvas: Canvas, mask: NDArray[np.uint8], lines: Sequence[str], box: tuple[float, float, float, float],
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
_FONTS = (cv2.FONT_HERSHEY_COMPLEX, cv2.FONT_HERSHEY_TRIPLEX, cv2.FONT_HERSHEY_DUPLEX, cv2.FONT_HERSHEY_SIMPLEX)


def _words(rng: np.random.Generator, n: int) -> str:
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
        tone = 0.75 + 0.5 * _hash3(ix, iy, np.zeros_like(ix), seed)
        fx, fy = p[:, 0] / tile_m - ix, p[:, 1] / tile_m - iy
        joint = (np.minimum(fx, 1 - fx) < 0.025) | (np.minimum(fy, 1 - fy) < 0.025)
        m = tone * (0.8 + 0.35 * fbm3(p, 0.006, seed + 1, 2)) * (0.85 + 0.3 * fbm3(p, 0.12, seed + 2))
        m = np.where(joint, 0.35, m)
        return np.array([0.36, 0.34, 0.31])[None, :] * m[:, None]
    return f


# ================================================================================================================
# mesh builder


@dataclass
class _Part:
    vertices: F64
    faces: NDArray[np.int64]
    rho: F64


def _grid_faces(nu: int, nv: int, wrap_u: bool) -> NDArray[np.int64]:
    """Two triangles per cell of an ``nu × nv`` vertex grid (u-major); front side is ∂u × ∂v."""
    iu = np.arange(nu if wrap_u else nu - 1)
    i_grid, j_grid = np.meshgrid(iu, np.arange(nv - 1), indexing="ij")
    i, j = i_grid.ravel(), j_grid.ravel()
    i1 = (i + 1) % nu
    a, b, c, d = i * nv + j, i1 * nv + j, i1 * nv + j + 1, i * nv + j + 1
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _lines(a: float, b: float, step: float) -> F64:
    n = max(1, math.ceil((b - a) / step - 1e-9))
    return np.linspace(a, b, n + 1)


def _unit(v: ArrayLike) -> F64:
    a = np.asarray(v, dtype=np.float64)
    return a / np.linalg.norm(a)


def _taper(x: F64, length: float, margin: float) -> F64:
    """0 at both ends of [0, length], 1 beyond ``margin`` from them (smoothstep)."""
    if margin <= 0.0:
        return np.ones_like(x)
    t = np.clip(np.minimum(x, length - x) / margin, 0.0, 1.0)
    return t * t * (3 - 2 * t)


class _Builder:
    """Collects mesh parts. ``res`` is the vertex step of detailed surfaces, ``coarse`` of backdrops."""

    def __init__(self, res: float, seed: int) -> None:
        self.res = float(res)
        self.coarse = max(5.0 * self.res, 0.012)
        self.base_res = self.res
        self.seed = seed
        self.parts: list[_Part] = []

    def scale_detail(self, factor: float) -> None:
        """Coarsen the detail step for large subjects seen from further away (same pixels per vertex)."""
        self.res = self.base_res * max(1.0, factor)

    def _add(self, P: F64, h: F64, uv: F64, material: Material, decal: Canvas | None, wrap_u: bool,
             nu: int, nv: int) -> None:
        flat = P.reshape(-1, 3)
        rho = material(flat, h.reshape(-1), uv.reshape(-1, 2))
        if decal is not None:
            d = decal.sample(uv[..., 0].reshape(-1), uv[..., 1].reshape(-1))
            a = d[:, 3:4]
            rho = rho * (1 - a) + d[:, :3] * a
        self.parts.append(_Part(flat, _grid_faces(nu, nv, wrap_u), rho))

    def surface(self, origin: Sequence[float], eu: Sequence[float], ev: Sequence[float], size_u: float,
                size_v: float, material: Material, *, step: float | None = None, relief: Canvas | None = None,
                decal: Canvas | None = None, rough_m: float = 0.0, taper_m: float = 0.004) -> None:
        """A flat rectangle ``origin + u eu + v ev`` (front side ``eu × ev``) displaced along its normal by the
        ``relief`` canvas and a fine roughness, both faded out within ``taper_m`` of the edges (no cracks)."""
        step = step or self.res
        o, a, b = np.asarray(origin, float), _unit(eu), _unit(ev)
        n = np.cross(a, b)
        us, vs = _lines(0.0, size_u, step), _lines(0.0, size_v, step)
        U, V = np.meshgrid(us, vs, indexing="ij")
        h = np.zeros_like(U)
        if relief is not None:
            h += relief.sample(U.ravel(), V.ravel()).reshape(U.shape)
        P0 = o + U[..., None] * a + V[..., None] * b
        if rough_m > 0.0:
            h += rough_m * (fbm3(P0.reshape(-1, 3), 0.01, self.seed + 77, 3).reshape(U.shape) - 0.5)
        h *= _taper(U, size_u, taper_m) * _taper(V, size_v, taper_m)
        P = P0 + h[..., None] * n
        self._add(P, h, np.stack([U, V], -1), material, decal, False, len(us), len(vs))

    def lathe(self, center: ArrayLike, axis: ArrayLike, ref: ArrayLike,
              profile: Sequence[tuple[float, float]], material: Material, *, step: float | None = None,
              n_theta: int | None = None, relief: Canvas | None = None, rough_m: float = 0.0,
              taper_m: float = 0.003) -> None:
        """A surface of revolution of the polyline ``profile`` of ``(r, z)`` points (one smooth section; start a
        new section for a hard edge). Front side: outward when the profile runs counter-clockwise in the (r, z)
        half-plane (e.g. up a cylinder wall, then inwards over its top). ``relief`` is sampled at
        ``u = θ · r_max`` (wrapping) and ``v`` = arc length from the profile's start."""
        step = step or self.res
        c, ax = np.asarray(center, float), _unit(axis)
        e1 = _unit(np.asarray(ref, float) - np.dot(ref, ax) * ax)
        e2 = np.cross(ax, e1)
        prof = np.asarray(profile, dtype=np.float64)
        seg = np.linalg.norm(np.diff(prof, axis=0), axis=1)
        s_knots = np.concatenate([[0.0], np.cumsum(seg)])
        length = float(s_knots[-1])
        # sample every profile segment on its own so that the profile's corners are kept
        ss = np.unique(np.concatenate([_lines(a, b2, step) for a, b2 in itertools.pairwise(s_knots)
                                       if b2 > a]))
        r = np.interp(ss, s_knots, prof[:, 0])
        z = np.interp(ss, s_knots, prof[:, 1])
        # outward normal in (r, z): (dz, -dr) of the local tangent
        dr, dz = np.gradient(r, ss), np.gradient(z, ss)
        nn = np.hypot(dr, dz)
        nr, nz = dz / np.maximum(nn, 1e-12), -dr / np.maximum(nn, 1e-12)
        rmax = float(prof[:, 0].max())
        if n_theta is None:
            n_theta = max(12, math.ceil(2 * math.pi * rmax / step))
        th = 2 * math.pi * np.arange(n_theta) / n_theta
        T, S = np.meshgrid(th, ss, indexing="ij")
        R, Z = np.meshgrid(th, r, indexing="ij")[1], np.meshgrid(th, z, indexing="ij")[1]
        NR, NZ = np.meshgrid(th, nr, indexing="ij")[1], np.meshgrid(th, nz, indexing="ij")[1]
        U = T * rmax
        h = np.zeros_like(T)
        if relief is not None:
            h += relief.sample(U.ravel(), S.ravel()).reshape(T.shape)
        radial = np.cos(T)[..., None] * e1 + np.sin(T)[..., None] * e2
        P0 = c + R[..., None] * radial + Z[..., None] * ax
        if rough_m > 0.0:
            h += rough_m * (fbm3(P0.reshape(-1, 3), 0.01, self.seed + 78, 3).reshape(T.shape) - 0.5)
        h *= _taper(S, length, taper_m)
        P = P0 + (h * NR)[..., None] * radial + (h * NZ)[..., None] * ax
        self._add(P, h, np.stack([U, S], -1), material, None, True, n_theta, len(ss))

    def box(self, lo: Sequence[float], size: Sequence[float], material: Material, *, step: float | None = None,
            front: dict[str, Any] | None = None, bottom: bool = False, R: F64 | None = None,
            pivot: Sequence[float] | None = None) -> None:
        """An axis-aligned box from corner ``lo`` (faces outward); the front face (−y) may get ``front`` keyword
        arguments for :meth:`surface` (relief, decal, step). Rotated by ``R`` about ``pivot`` when given."""
        x0, y0, z0 = lo
        sx, sy, sz = size
        x1, y1, z1 = x0 + sx, y0 + sy, z0 + sz
        ex, ey, ez = (1.0, 0, 0), (0, 1.0, 0), (0, 0, 1.0)
        first = len(self.parts)
        st = step or self.res
        fr = dict(front or {})
        fr.setdefault("step", st)
        self.surface((x0, y0, z0), ex, ez, sx, sz, fr.pop("material", material), **fr)  # front (-y)
        self.surface((x1, y1, z0), (-1.0, 0, 0), ez, sx, sz, material, step=st)  # back (+y)
        self.surface((x0, y1, z0), (0, -1.0, 0), ez, sy, sz, material, step=st)  # -x
        self.surface((x1, y0, z0), ey, ez, sy, sz, material, step=st)  # +x
        self.surface((x0, y0, z1), ex, ey, sx, sy, material, step=st)  # top
        if bottom:
            self.surface((x0, y1, z0), ex, (0, -1.0, 0), sx, sy, material, step=st)
        if R is not None:
            pv = np.asarray(pivot if pivot is not None else (x0 + sx / 2, y0 + sy / 2, z0), float)
            for p in self.parts[first:]:
                p.vertices = (p.vertices - pv) @ np.asarray(R).T + pv

    def bolt(self, pos: ArrayLike, normal: ArrayLike, radius: float, material: Material, *,
             height: float | None = None, washer: bool = True) -> None:
        """A hex bolt head (and washer) standing on a surface at ``pos`` with outward ``normal``."""
        n = _unit(normal)
        ref = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
        hgt = height if height is not None else 0.7 * radius
        z0 = 0.0
        if washer:
            w = 0.25 * radius
            self.lathe(pos, n, ref, [(1.5 * radius, 0.0), (1.5 * radius, w), (0.0, w)], material,
                       step=self.res, n_theta=max(12, int(2 * math.pi * 1.5 * radius / self.res)), taper_m=0.0)
            z0 = w
        self.lathe(np.asarray(pos, float) + z0 * n, n, ref, [(radius, 0.0), (radius, hgt)], material, n_theta=6,
                   step=self.res, taper_m=0.0)
        self.lathe(np.asarray(pos, float) + z0 * n, n, ref, [(radius, hgt), (0.6 * radius, 1.15 * hgt),
                                                             (0.0, 1.15 * hgt)], material, n_theta=6,
                   step=self.res, taper_m=0.0)

    def bolt_circle(self, center: Sequence[float], normal: Sequence[float], ref: Sequence[float], circle_r: float,
                    n: int, radius: float, material: Material) -> None:
        nn = _unit(normal)
        e1 = _unit(np.asarray(ref, float) - np.dot(ref, nn) * nn)
        e2 = np.cross(nn, e1)
        for k in range(n):
            a = 2 * math.pi * (k + 0.5) / n
            self.bolt(np.asarray(center, float) + circle_r * (math.cos(a) * e1 + math.sin(a) * e2), nn, radius,
                      material)

    def finish(self) -> ReflectanceMesh:
        v = np.concatenate([p.vertices for p in self.parts])
        offs = np.cumsum([0] + [len(p.vertices) for p in self.parts[:-1]])
        f = np.concatenate([p.faces + o for p, o in zip(self.parts, offs, strict=True)])
        rho = np.concatenate([p.rho for p in self.parts])
        # round to what the PLY file holds (float32), drop degenerate triangles
        v = v.astype(np.float32).astype(np.float64)
        rho = np.clip(rho, 0.02, 0.95).astype(np.float32).astype(np.float64)
        area2 = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
        f = f[area2 > 1e-12]
        return ReflectanceMesh(v, f, rho)


# ================================================================================================================
# scene recipes: each returns (target point, base camera distance)


def _indoor_set(b: _Builder, rng: np.random.Generator, seed: int) -> None:
    """Wooden table top (z = 0) and a plaster wall behind (y = 0.35)."""
    tone = rng.uniform(0.8, 1.1)
    b.surface((-0.75, -0.7, 0.0), (1, 0, 0), (0, 1, 0), 1.5, 1.05, wood(np.array([0.45, 0.28, 0.15]) * tone, seed + 1),
              step=b.coarse, taper_m=0.0)
    b.surface((-0.85, 0.35, 0.0), (1, 0, 0), (0, 0, 1), 1.7, 1.1,
              plaster(np.array([0.72, 0.70, 0.64]) * rng.uniform(0.85, 1.05), seed + 2), step=b.coarse,
              taper_m=0.0)


def _outdoor_set(b: _Builder, rng: np.random.Generator, seed: int, size: float = 3.2) -> None:
    b.surface((-size / 2, -size / 2 - 0.4, 0.0), (1, 0, 0), (0, 1, 0), size, size, paving(seed + 1),
              step=b.coarse, taper_m=0.0)


def _stone_color(rng: np.random.Generator) -> tuple[F64, str]:
    name = str(rng.choice(["sandstone", "marble", "granite", "limestone", "slate", "red sandstone"]))
    base = {"sandstone": (0.62, 0.52, 0.38), "marble": (0.78, 0.77, 0.73), "granite": (0.52, 0.50, 0.49),
            "limestone": (0.70, 0.66, 0.56), "slate": (0.28, 0.29, 0.31), "red sandstone": (0.55, 0.33, 0.25)}[name]
    return np.asarray(base) * rng.uniform(0.9, 1.08), name


def _panel(b: _Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    W, H, T = rng.uniform(0.46, 0.6), rng.uniform(0.32, 0.42), 0.045
    z0 = 0.0 if not outdoor else 0.35
    base, mname = _stone_color(rng)
    if not outdoor and rng.random() < 0.3:
        mat, mname = wood(np.array([0.55, 0.36, 0.2]), seed + 5, axis=0), "wood"
    else:
        mat = stone(base, seed + 5, lichen=0.25 if outdoor else 0.0)
    cv = Canvas.blank(W, H, 0.001)
    frame = _mask(cv)
    bw = rng.uniform(0.025, 0.035)
    cv2.rectangle(frame, cv.px(0.004, H - 0.004), cv.px(W - 0.004, 0.004), 255, -1)
    cv2.rectangle(frame, cv.px(bw, H - bw), cv.px(W - bw, bw), 0, -1)
    _add_relief(cv, frame, 0.004, 0.003)
    groove = _mask(cv)
    style = str(rng.choice(["meander", "rope", "beads"]))
    m = bw / 2
    if style == "meander":
        for vv in (m, H - m):
            pts, u, k = [], m, 0
            while u < W - m:
                lo, hi = cv.px(u, vv - 0.005), cv.px(u, vv + 0.005)
                pts += [lo, hi] if k % 2 == 0 else [hi, lo]
                u += 0.008
                k += 1
            cv2.polylines(groove, [np.array(pts, np.int32)], False, 255, 2, cv2.LINE_AA)
    elif style == "rope":
        for u in np.arange(m, W - m, 0.009):
            for vv in (m, H - m):
                cv2.ellipse(groove, cv.px(u, vv), (6, 3), 35, 0, 360, 255, 1, cv2.LINE_AA)
    else:
        for u in np.arange(m, W - m, 0.012):
            for vv in (m, H - m):
                cv2.circle(groove, cv.px(u, vv), 4, 255, -1, cv2.LINE_AA)
    _add_relief(cv, groove, -0.003, 0.0015)
    motif = _mask(cv)
    veins = _mask(cv)
    kind = str(rng.choice(["rosette", "scroll"]))
    cu, cvv = W / 2 + rng.uniform(-0.03, 0.03), H / 2 + 0.02
    if kind == "rosette":
        R = min(W, H) * rng.uniform(0.26, 0.32)
        npet = int(rng.integers(6, 12))
        cv2.circle(motif, cv.px(cu, cvv), int(0.22 * R / cv.px_m), 255, -1, cv2.LINE_AA)
        for k in range(npet):
            a = 2 * math.pi * k / npet
            pc = (cu + 0.6 * R * math.cos(a), cvv + 0.6 * R * math.sin(a))
            cv2.ellipse(motif, cv.px(*pc), (int(0.38 * R / cv.px_m), int(0.14 * R / cv.px_m)),
                        -math.degrees(a), 0, 360, 255, -1, cv2.LINE_AA)
            cv2.line(veins, cv.px(cu + 0.3 * R * math.cos(a), cvv + 0.3 * R * math.sin(a)),
                     cv.px(cu + 0.9 * R * math.cos(a), cvv + 0.9 * R * math.sin(a)), 255, 2, cv2.LINE_AA)
        cv2.circle(veins, cv.px(cu, cvv), int(1.05 * R / cv.px_m), 255, 2, cv2.LINE_AA)
        cv2.circle(veins, cv.px(cu, cvv), int(0.12 * R / cv.px_m), 255, 2, cv2.LINE_AA)
    else:
        for _ in range(int(rng.integers(3, 6))):
            t = np.linspace(0, 1, 80)
            p0 = np.array([rng.uniform(bw + 0.03, W - bw - 0.03), rng.uniform(bw + 0.08, H - bw - 0.03)])
            ang, rad = rng.uniform(0, 2 * math.pi), rng.uniform(0.04, 0.09)
            spiral = p0 + (rad * (1 - 0.8 * t))[:, None] * np.stack([np.cos(ang + 5 * t), np.sin(ang + 5 * t)], 1)
            poly = np.array([cv.px(*q) for q in spiral], np.int32)
            cv2.polylines(motif, [poly], False, 255, int(0.012 / cv.px_m), cv2.LINE_AA)
            cv2.polylines(veins, [poly], False, 255, 2, cv2.LINE_AA)
            for q in spiral[10::14]:
                cv2.ellipse(motif, cv.px(*q), (11, 5), rng.uniform(0, 180), 0, 360, 255, -1, cv2.LINE_AA)
    _add_relief(cv, motif, 0.0035, 0.0025)
    _add_relief(cv, veins, -0.0018, 0.001)
    text = _mask(cv)
    _text_lines(cv, text, [_words(rng, 3)], (bw + 0.015, bw + 0.006, W - bw - 0.015, bw + 0.04),
                _FONTS[int(rng.integers(0, 3))], 0.0018)
    _add_relief(cv, text, -0.002, 0.001)
    cv.data = _blur(cv.data, 0.6)
    if outdoor:
        b.box((-W / 2 - 0.05, -T / 2 - 0.05, 0.0), (W + 0.1, T + 0.1, z0), stone(base * 0.85, seed + 9),
              step=b.coarse, front={"rough_m": 0.002})
    b.box((-W / 2, -T / 2, z0), (W, T, H), mat, step=3 * b.res, front={"relief": cv, "rough_m": 0.0006,
                                                                        "step": b.res})
    return np.array([0.0, -T / 2, z0 + H / 2]), 1.12 * W, f"carved {mname} relief panel ({kind}, {style} border)"


def _tablet(b: _Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    if outdoor:
        W, H, T, z0 = rng.uniform(0.5, 0.62), rng.uniform(0.6, 0.75), 0.12, 0.12
        b.scale_detail(1.3)
    else:
        W, H, T, z0 = rng.uniform(0.42, 0.52), rng.uniform(0.3, 0.38), 0.05, 0.0
    base, mname = _stone_color(rng)
    mat = stone(base, seed + 5, lichen=0.3 if outdoor else 0.0, contrast=0.18)
    cv = Canvas.blank(W, H, 0.001)
    border = _mask(cv)
    inset = 0.022
    cv2.rectangle(border, cv.px(inset, H - inset), cv.px(W - inset, inset), 255, 4, cv2.LINE_AA)
    _add_relief(cv, border, -0.003, 0.002)
    text = _mask(cv)
    n = int(rng.integers(4, 7))
    font = _FONTS[int(rng.integers(0, 4))]
    top = H - inset - 0.015
    title_h = (top - inset - 0.01) / (n + 1) * 1.6
    _text_lines(cv, text, [_words(rng, 2)], (inset + 0.03, top - title_h, W - inset - 0.03, top), font, 0.003)
    _text_lines(cv, text, [_words(rng, int(rng.integers(2, 4))) for _ in range(n)],
                (inset + 0.02, inset + 0.012, W - inset - 0.02, top - title_h - 0.004), font, 0.0019)
    _add_relief(cv, text, -0.0028, 0.0012)
    pits = _mask(cv)
    for _ in range(int(rng.integers(40, 120))):
        cv2.circle(pits, cv.px(rng.uniform(0, W), rng.uniform(0, H)), int(rng.integers(1, 4)), 255, -1)
    _add_relief(cv, pits, -0.0012, 0.001)
    cv.data = _blur(cv.data, 0.6)
    if outdoor:
        b.box((-W / 2 - 0.06, -T / 2 - 0.06, 0.0), (W + 0.12, T + 0.12, z0), stone(base * 0.8, seed + 9),
              step=b.coarse, front={"rough_m": 0.002})
    b.box((-W / 2, -T / 2, z0), (W, T, H), mat, step=3 * b.res, front={"relief": cv, "rough_m": 0.0008,
                                                                        "step": b.res})
    return (np.array([0.0, -T / 2, z0 + H / 2]), 1.1 * max(W, H * 1.2),
            f"{mname} {'stele' if outdoor else 'tablet'} with a carved inscription")


def _decal_label(size_u: float, size_v: float, lines: Sequence[str], bg: Sequence[float], fg: Sequence[float],
                 px: float = 0.0005, font: int = cv2.FONT_HERSHEY_SIMPLEX) -> Canvas:
    """An RGBA label canvas: background ``bg`` with text ``fg`` (alpha 1 inside)."""
    c = Canvas.blank(size_u, size_v, px, channels=4)
    c.data[..., :3] = np.asarray(bg, np.float32)
    c.data[..., 3] = 1.0
    m = _mask(c)
    _text_lines(c, m, lines, (0.1 * size_u, 0.1 * size_v, 0.9 * size_u, 0.9 * size_v), font, 0.4 * 0.001)
    a = (m.astype(np.float32) / 255.0)[..., None]
    c.data[..., :3] = c.data[..., :3] * (1 - a) + np.asarray(fg, np.float32) * a
    return c


def _place_decal(target: Canvas, label: Canvas, u0: float, v0: float) -> None:
    """Paste an RGBA ``label`` into the RGBA ``target`` with its lower-left corner at (u0, v0) (same px size)."""
    h, w = label.data.shape[:2]
    x, y = target.px(u0, v0)
    y0 = y - h
    ys, xs = slice(max(y0, 0), min(y, target.data.shape[0])), slice(max(x, 0), min(x + w, target.data.shape[1]))
    sub = label.data[ys.start - y0: ys.stop - y0, xs.start - x: xs.stop - x]
    target.data[ys, xs] = sub


def _cabinet(b: _Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    W, H, D = rng.uniform(0.38, 0.48), rng.uniform(0.45, 0.56), 0.22
    z0 = 0.1 if outdoor else 0.0
    colors = {"grey": (0.45, 0.47, 0.48), "orange": (0.75, 0.33, 0.08), "green": (0.2, 0.38, 0.25),
              "blue": (0.15, 0.25, 0.45), "beige": (0.7, 0.66, 0.55)}
    cname = str(rng.choice(list(colors)))
    mat = paint(colors[cname], seed + 5, rust=0.25 if outdoor else 0.05, scratches=0.8)
    steel = metal((0.45, 0.45, 0.47), seed + 6)
    cv = Canvas.blank(W, H, 0.001)
    seam = _mask(cv)
    ins = 0.02
    cv2.rectangle(seam, cv.px(ins, H - ins), cv.px(W - ins, ins), 255, 2, cv2.LINE_AA)
    _add_relief(cv, seam, -0.004, 0.0008)
    vents = _mask(cv)
    n_slots = int(rng.integers(6, 11))
    for k in range(n_slots):
        v = H - ins - 0.03 - k * 0.014
        cv2.rectangle(vents, cv.px(ins + 0.04, v), cv.px(W * 0.55, v - 0.006), 255, -1)
    _add_relief(cv, vents, -0.005, 0.0015)
    plate = _mask(cv)
    pu0, pv0, pw, ph = W * 0.18, H * 0.32, W * 0.5, 0.08
    cv2.rectangle(plate, cv.px(pu0, pv0 + ph), cv.px(pu0 + pw, pv0), 255, -1)
    _add_relief(cv, plate, 0.0015, 0.0008)
    ptext = _mask(cv)
    _text_lines(cv, ptext, [f"TYPE {int(rng.integers(100, 999))}-{_words(rng, 1)[:3]}",
                            f"{int(rng.integers(200, 690))} V  {int(rng.integers(5, 60))} A"],
                (pu0 + 0.01, pv0 + 0.01, pu0 + pw - 0.01, pv0 + ph - 0.01), cv2.FONT_HERSHEY_SIMPLEX, 0.0012)
    _add_relief(cv, ptext, -0.001, 0.0006)
    key = _mask(cv)
    cv2.circle(key, cv.px(W - ins - 0.035, H * 0.5), 6, 255, -1, cv2.LINE_AA)
    _add_relief(cv, key, -0.004, 0.001)
    cv.data = _blur(cv.data, 0.5)
    decal = Canvas.blank(W, H, 0.0005, channels=4)
    warn = _decal_label(0.12, 0.05, ["DANGER", f"{int(rng.integers(2, 20)) * 100} VOLT"], (0.85, 0.7, 0.05),
                        (0.03, 0.03, 0.03))
    _place_decal(decal, warn, W * 0.6, H * 0.66)
    lab = _decal_label(pw - 0.004, ph - 0.004, [""], (0.75, 0.76, 0.74), (0.05, 0.05, 0.05))
    lab.data[..., 3] = 0.85
    _place_decal(decal, lab, pu0 + 0.002, pv0 + 0.002)
    ser = _decal_label(0.1, 0.02, [f"SN {int(rng.integers(10**5, 10**6))}"], (0.92, 0.92, 0.9), (0.0, 0.0, 0.0))
    _place_decal(decal, ser, ins + 0.03, ins + 0.02)
    if outdoor:
        b.box((-W / 2 - 0.04, -D / 2 - 0.04, 0.0), (W + 0.08, D + 0.08, z0), stone((0.5, 0.5, 0.48), seed + 9),
              step=b.coarse, front={"rough_m": 0.002})
    b.box((-W / 2, -D / 2, z0), (W, D, H), mat, step=3 * b.res,
          front={"relief": cv, "decal": decal, "rough_m": 0.0002, "step": b.res})
    y_front = -D / 2
    for u, v in ((ins + 0.012, ins + 0.012), (W - ins - 0.012, ins + 0.012), (ins + 0.012, H - ins - 0.012),
                 (W - ins - 0.012, H - ins - 0.012), (pu0 + 0.008, pv0 + ph / 2), (pu0 + pw - 0.008, pv0 + ph / 2)):
        b.bolt((-W / 2 + u, y_front, z0 + v), (0, -1, 0), 0.0055, steel)
    b.box((W / 2 - ins - 0.05, y_front - 0.025, z0 + H * 0.42), (0.018, 0.025, 0.1), steel, step=b.res)
    for v in (H * 0.2, H * 0.8):  # hinges
        b.lathe((-W / 2 + 0.008, y_front - 0.008, z0 + v - 0.03), (0, 0, 1), (1, 0, 0),
                [(0.008, 0.0), (0.008, 0.06), (0.0, 0.06)], steel)
    # pipe with flanges in front of the cabinet, along x
    pr = rng.uniform(0.022, 0.032)
    py, pz = y_front - 0.09, z0 + 0.05 + pr
    pipe_mat = paint((0.6, 0.55, 0.1) if rng.random() < 0.5 else (0.5, 0.1, 0.08), seed + 11, rust=0.35)
    b.lathe((-W / 2 - 0.1, py, pz), (1, 0, 0), (0, 1, 0), [(pr, 0.0), (pr, W + 0.2)], pipe_mat, rough_m=0.0003)
    for xf in (-W / 4, W / 4):
        fr = pr + 0.025
        b.lathe((xf - 0.01, py, pz), (1, 0, 0), (0, 1, 0), [(pr, 0.0), (fr, 0.0)], pipe_mat, taper_m=0.0)
        b.lathe((xf - 0.01, py, pz), (1, 0, 0), (0, 1, 0), [(fr, 0.0), (fr, 0.02)], pipe_mat, taper_m=0.0)
        b.lathe((xf - 0.01, py, pz), (1, 0, 0), (0, 1, 0), [(fr, 0.02), (pr, 0.02)], pipe_mat, taper_m=0.0)
        b.bolt_circle((xf + 0.01, py, pz), (1, 0, 0), (0, 0, 1), pr + 0.015, 6, 0.004, steel)
        b.bolt_circle((xf - 0.01, py, pz), (-1, 0, 0), (0, 0, 1), pr + 0.015, 6, 0.004, steel)
    # gauge on the cabinet side facing the camera
    gx, gz = W / 2 - ins - 0.06, z0 + H * 0.18
    b.lathe((-W / 2 + gx, y_front, gz), (0, -1, 0), (1, 0, 0), [(0.03, 0.0), (0.03, 0.015)], steel, taper_m=0.0)
    gl = Canvas.blank(2 * math.pi * 0.03, 0.05, 0.0005, wrap_u=True)
    ticks = _mask(gl)
    for k in range(40):
        uu = 2 * math.pi * 0.03 * (k / 40)
        cv2.line(ticks, gl.px(uu, 0.001), gl.px(uu, 0.006 if k % 5 else 0.01), 255, 1)
    _add_relief(gl, ticks, -0.0006, 0.0003)
    b.lathe((-W / 2 + gx, y_front - 0.015, gz), (0, -1, 0), (1, 0, 0), [(0.03, 0.0), (0.0, 0.0)],
            metal((0.85, 0.85, 0.82), seed + 12), relief=gl, taper_m=0.0)
    return np.array([0.0, y_front, z0 + H * 0.5]), 1.6 * W, f"{cname} equipment cabinet with a flanged pipe"


def _motor(b: _Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    R, L = rng.uniform(0.09, 0.12), rng.uniform(0.3, 0.38)
    zc = R + 0.05
    colors = {"blue": (0.12, 0.22, 0.42), "green": (0.18, 0.33, 0.22), "grey": (0.42, 0.44, 0.45),
              "red": (0.5, 0.1, 0.08)}
    cname = str(rng.choice(list(colors)))
    mat = paint(colors[cname], seed + 5, rust=0.3 if outdoor else 0.05)
    steel = metal((0.5, 0.5, 0.52), seed + 6)
    fins = Canvas.blank(2 * math.pi * R, L, 0.001, wrap_u=True)
    fm = _mask(fins)
    pitch = rng.uniform(0.011, 0.015)
    for u in np.arange(0, 2 * math.pi * R, pitch):
        cv2.rectangle(fm, fins.px(u, L - 0.03), fins.px(u + 0.4 * pitch, 0.03), 255, -1)
    _add_relief(fins, fm, 0.008, 0.0025)
    x0 = -L / 2
    b.lathe((x0, 0.0, zc), (1, 0, 0), (0, 0, 1), [(R, 0.0), (R, L)], mat, relief=fins, rough_m=0.0003)
    # end shields with bolt circles, shaft and coupling
    for xe, sgn in ((x0, -1.0), (x0 + L, 1.0)):
        ax = (sgn, 0.0, 0.0)
        b.lathe((xe, 0, zc), ax, (0, 0, 1), [(R + 0.008, 0.0), (R + 0.008, 0.02), (R * 0.55, 0.035), (R * 0.5, 0.045),
                                             (0.0, 0.045)], mat)
        b.bolt_circle((xe + sgn * 0.02, 0, zc), ax, (0, 0, 1), R - 0.004, 8, 0.005, steel)
    b.lathe((x0 + L + 0.045, 0, zc), (1, 0, 0), (0, 0, 1), [(0.018, 0.0), (0.018, 0.06)], steel)
    b.lathe((x0 + L + 0.105, 0, zc), (1, 0, 0), (0, 0, 1), [(0.0, 0.0), (0.05, 0.0), (0.05, 0.045), (0.0, 0.045)],
            steel, n_theta=int(2 * math.pi * 0.05 / b.res))
    b.bolt_circle((x0 + L + 0.15, 0, zc), (1, 0, 0), (0, 0, 1), 0.035, 6, 0.0045, steel)
    # feet
    for xf in (x0 + 0.05, x0 + L - 0.09):
        b.box((xf, -R - 0.02, 0.0), (0.04, 2 * R + 0.04, zc - R * 0.7), mat, step=b.res * 2)
        for yy in (-R, R):
            b.bolt((xf + 0.02, yy, zc - R * 0.7), (0, 0, 1), 0.006, steel)
    # terminal box on top, with a label and bolts
    tw, td, th = 0.11, 0.1, 0.07
    tz = zc + R + 0.004
    lab = Canvas.blank(tw, th, 0.0005, channels=4)
    _place_decal(lab, _decal_label(tw * 0.8, th * 0.5, [f"M{int(rng.integers(1, 9))} {int(rng.integers(1, 90))}kW",
                                                        "IP55"], (0.9, 0.9, 0.88), (0.0, 0, 0)), tw * 0.1, th * 0.25)
    b.box((-tw / 2, -td / 2, tz - 0.01), (tw, td, th), mat, step=b.res * 1.5, front={"decal": lab, "step": b.res})
    for u in (-tw / 2 + 0.01, tw / 2 - 0.01):
        for v in (-td / 2 + 0.01, td / 2 - 0.01):
            b.bolt((u, v, tz - 0.01 + th), (0, 0, 1), 0.004, steel)
    # name plate on the body facing the camera
    npl = _decal_label(0.09, 0.05, [f"NO {int(rng.integers(1000, 9999))}", f"{int(rng.integers(900, 3000))} RPM",
                                    "50 HZ"], (0.78, 0.78, 0.74), (0.02, 0.02, 0.02))
    b.box((-0.045, -R - 0.012, zc - 0.025), (0.09, 0.004, 0.05), steel, step=b.res,
          front={"decal": npl, "step": b.res / 2 if b.res > 0.002 else b.res})
    base = None
    if outdoor:
        base = stone((0.5, 0.5, 0.48), seed + 9)
        b.box((x0 - 0.08, -R - 0.1, -0.001), (L + 0.35, 2 * R + 0.2, 0.002), base, step=b.coarse)
    return np.array([0.03, -R, zc]), 1.2 * (L + 0.15), f"{cname} finned motor with coupling and terminal box"


def _stupa(b: _Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    k = rng.uniform(1.0, 1.25) if outdoor else rng.uniform(0.55, 0.7)
    b.scale_detail(1.25 * k)
    base, mname = _stone_color(rng)
    mat = stone(base, seed + 5, lichen=0.3 if outdoor else 0.0)
    # plinth with carved niches on the front
    P, Ph = 0.5 * k, 0.1 * k
    cv = Canvas.blank(P, Ph, 0.001)
    nm = _mask(cv)
    nn = int(rng.integers(5, 9))
    for i in range(nn):
        u = (i + 0.5) * P / nn
        cv2.rectangle(nm, cv.px(u - 0.35 * P / nn, Ph * 0.8), cv.px(u + 0.35 * P / nn, Ph * 0.2), 255, -1)
        cv2.circle(nm, cv.px(u, Ph * 0.8), int(0.35 * P / nn / 0.001), 255, -1)
    _add_relief(cv, nm, -0.006 * k, 0.003)
    fig = _mask(cv)
    for i in range(nn):
        u = (i + 0.5) * P / nn
        cv2.ellipse(fig, cv.px(u, Ph * 0.45), (int(0.12 * P / nn / 0.001), int(0.2 * Ph / 0.001)), 0, 0, 360, 255,
                    -1, cv2.LINE_AA)
        cv2.circle(fig, cv.px(u, Ph * 0.72), int(0.07 * P / nn / 0.001), 255, -1, cv2.LINE_AA)
    _add_relief(cv, fig, 0.004 * k, 0.002)
    cv.data = _blur(cv.data, 0.6)
    b.box((-P / 2, -P / 2, 0.0), (P, P, Ph), mat, step=3 * b.res, front={"relief": cv, "rough_m": 0.001,
                                                                           "step": b.res})
    z = Ph
    Rd, hd = 0.19 * k, 0.06 * k
    band = Canvas.blank(2 * math.pi * Rd, hd, 0.001, wrap_u=True)
    bm = _mask(band)
    pts = [band.px(u, hd * (0.25 if i % 2 else 0.75)) for i, u in enumerate(np.arange(0, 2 * math.pi * Rd, 0.015))]
    cv2.polylines(bm, [np.array(pts, np.int32)], False, 255, 3, cv2.LINE_AA)
    for u in np.arange(0.0075, 2 * math.pi * Rd, 0.015):
        cv2.circle(bm, band.px(u, hd * (0.75 if round(u / 0.015) % 2 else 0.25)), 3, 255, -1)
    _add_relief(band, bm, -0.003, 0.0015)
    b.lathe((0, 0, z), (0, 0, 1), (1, 0, 0), [(Rd, 0.0), (Rd, hd)], mat, relief=band, rough_m=0.0008)
    b.lathe((0, 0, z + hd), (0, 0, 1), (1, 0, 0), [(Rd, 0.0), (0.95 * Rd, 0.0)], mat)
    z += hd
    # bell dome
    Rb = 0.93 * Rd
    t = np.linspace(0, 1, 24)
    prof = [(Rb * (1.0 + 0.06 * math.sin(math.pi * q)) * math.cos(0.5 * math.pi * q) ** 0.8 + 1e-4,
             0.22 * k * math.sin(0.5 * math.pi * q)) for q in t]
    s_len = float(np.sum(np.linalg.norm(np.diff(np.asarray(prof), axis=0), axis=1)))
    petals = Canvas.blank(2 * math.pi * Rb * 1.06, s_len, 0.001, wrap_u=True)
    pm = _mask(petals)
    npt = int(rng.integers(16, 28))
    pw = 2 * math.pi * Rb * 1.06 / npt
    for i in range(npt):
        u = (i + 0.5) * pw
        cv2.ellipse(pm, petals.px(u, 0.05 * k), (int(0.42 * pw / 0.001), int(0.04 * k / 0.001)), 0, 180, 360, 255,
                    2, cv2.LINE_AA)
        cv2.line(pm, petals.px(u, 0.012 * k), petals.px(u, 0.045 * k), 255, 1, cv2.LINE_AA)
    cv2.line(pm, petals.px(0, 0.1 * k), petals.px(2 * math.pi * Rb * 1.06, 0.1 * k), 255, 3, cv2.LINE_AA)
    _add_relief(petals, pm, -0.0028, 0.0012)
    b.lathe((0, 0, z), (0, 0, 1), (1, 0, 0), prof, mat, relief=petals, rough_m=0.0008)
    z += 0.22 * k
    hw = 0.08 * k
    b.box((-hw / 2, -hw / 2, z - 0.01 * k), (hw, hw, 0.05 * k), mat, step=b.res * 1.5, front={"rough_m": 0.0008})
    z += 0.04 * k
    # ringed spire
    Ls = 0.2 * k
    rings = Canvas.blank(2 * math.pi * 0.035 * k, Ls, 0.001, wrap_u=True)
    rm = _mask(rings)
    for i in range(7):
        v = (i + 0.5) * Ls / 7
        cv2.rectangle(rm, rings.px(0, v + 0.006 * k), rings.px(2 * math.pi * 0.035 * k, v - 0.006 * k), 255, -1)
    _add_relief(rings, rm, 0.006 * k, 0.002)
    b.lathe((0, 0, z), (0, 0, 1), (1, 0, 0), [(0.035 * k, 0.0), (0.02 * k, Ls), (0.0, Ls)], mat, relief=rings,
            taper_m=0.01)
    b.lathe((0, 0, z + Ls), (0, 0, 1), (1, 0, 0),
            [(1e-4, 0.0)] + [(0.02 * k * math.sin(math.pi * q), 0.04 * k * (1 - math.cos(math.pi * q)) / 2)
                             for q in np.linspace(0.05, 1, 10)], metal((0.55, 0.45, 0.2), seed + 7))
    return np.array([0.0, -0.1 * k, 0.3 * k]), 1.5 * 0.5 * k + 0.15, f"{mname} stupa (scale {k:.2f})"


def _facade(b: _Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    W, H, D = rng.uniform(0.9, 1.1), rng.uniform(0.75, 0.9), 0.25
    b.scale_detail(1.8)
    base, mname = _stone_color(rng)
    mat = stone(base, seed + 5, lichen=0.3, contrast=0.12)
    cv = Canvas.blank(W, H, 0.001)
    tone = Canvas.blank(W, H, 0.001, channels=4)
    joints = _mask(cv)
    bh = rng.uniform(0.12, 0.16)
    bl = rng.uniform(0.26, 0.34)
    blocks = np.zeros(joints.shape, np.int32)
    nrow = math.ceil(H / bh)
    bid = 1
    for r in range(nrow):
        off = (r % 2) * bl / 2
        u = -off
        while u < W:
            x0, y1 = cv.px(max(u, 0), r * bh)
            x1, y0 = cv.px(min(u + bl, W), (r + 1) * bh)
            cv2.rectangle(blocks, (x0, y0), (x1, y1), bid, -1)
            u += bl
            bid += 1
    edges = cv2.morphologyEx((blocks > 0).astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8))
    diff = (cv2.Sobel(blocks.astype(np.float32), cv2.CV_32F, 1, 0) != 0) | (
        cv2.Sobel(blocks.astype(np.float32), cv2.CV_32F, 0, 1) != 0)
    joints[diff | (edges > 0)] = 255
    joints = cast(NDArray[np.uint8], cv2.dilate(joints, np.ones((5, 5), np.uint8)))
    solid = (255 - joints).astype(np.uint8)
    offs = _hash3(np.arange(bid + 1), np.zeros(bid + 1, np.int64), np.zeros(bid + 1, np.int64), seed)
    cv.data += (_profile(solid, 0.001, 0.008) * 0.008 + _profile(solid, 0.001, 0.008) * (offs[blocks] - 0.5) * 0.004)
    tone.data[..., 3] = 0.0
    # emblem block: carved rosette and inscription
    eu, ev = W / 2, H * 0.55
    em = _mask(cv)
    cv2.circle(em, cv.px(eu, ev), int(0.06 / 0.001), 255, 3, cv2.LINE_AA)
    for k in range(12):
        a = 2 * math.pi * k / 12
        cv2.line(em, cv.px(eu + 0.015 * math.cos(a), ev + 0.015 * math.sin(a)),
                 cv.px(eu + 0.052 * math.cos(a), ev + 0.052 * math.sin(a)), 255, 3, cv2.LINE_AA)
    _text_lines(cv, em, [_words(rng, 2)], (eu - 0.2, ev - 0.11, eu + 0.2, ev - 0.07), _FONTS[0], 0.002)
    _add_relief(cv, em, -0.003, 0.0012)
    cv.data = _blur(cv.data, 0.6)
    # per-block tone as a translucent decal
    tone_rgb = 0.8 + 0.4 * _hash3(np.arange(bid + 1), np.ones(bid + 1, np.int64), np.zeros(bid + 1, np.int64), seed)
    tone.data[..., :3] = (base[None, None, :] * tone_rgb[blocks][..., None]).astype(np.float32)
    tone.data[..., 3] = np.where(blocks > 0, 0.45, 0.0)
    b.box((-W / 2, -D / 2, 0.0), (W, D, H), mat, step=3 * b.res,
          front={"relief": cv, "decal": tone, "rough_m": 0.0015, "step": b.res})
    # cornice with dentils
    cw, ch = W + 0.06, 0.06
    cc = Canvas.blank(cw, ch, 0.001)
    dm = _mask(cc)
    for u in np.arange(0.01, cw, 0.03):
        cv2.rectangle(dm, cc.px(u, ch * 0.45), cc.px(u + 0.015, 0.003), 255, -1)
    _add_relief(cc, dm, 0.006, 0.001)
    b.box((-cw / 2, -D / 2 - 0.04, H), (cw, D + 0.04, ch), mat, step=3 * b.res,
          front={"relief": cc, "rough_m": 0.001, "step": b.res})
    return np.array([0.0, -D / 2, H * 0.5]), 0.95 * W, f"{mname} facade with carved emblem and cornice"


def _bogie(b: _Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    Lf, Hf, Tf = rng.uniform(0.9, 1.05), rng.uniform(0.22, 0.28), 0.04
    Rw = rng.uniform(0.2, 0.24)
    b.scale_detail(1.8)
    zf = Rw + 0.08
    yf = -0.12
    body = paint((0.12, 0.12, 0.13) if rng.random() < 0.6 else (0.3, 0.16, 0.1), seed + 5, rust=0.35)
    steel = metal((0.5, 0.5, 0.5), seed + 6)
    cv = Canvas.blank(Lf, Hf, 0.001)
    holes = _mask(cv)
    for u in np.linspace(0.18, Lf - 0.18, 3):
        cv2.ellipse(holes, cv.px(u, Hf / 2), (int(0.07 / 0.001), int(0.45 * Hf / 0.001)), 0, 0, 360, 255, -1,
                    cv2.LINE_AA)
    _add_relief(cv, holes, -0.01, 0.006)
    ribs = _mask(cv)
    cv2.line(ribs, cv.px(0.02, Hf - 0.015), cv.px(Lf - 0.02, Hf - 0.015), 255, 6)
    cv2.line(ribs, cv.px(0.02, 0.015), cv.px(Lf - 0.02, 0.015), 255, 6)
    _add_relief(cv, ribs, 0.004, 0.002)
    txt = _mask(cv)
    _text_lines(cv, txt, [f"{int(rng.integers(10, 99))}-{int(rng.integers(1000, 9999))} {_words(rng, 1)}"],
                (Lf * 0.35, Hf * 0.05, Lf * 0.65, Hf * 0.22), cv2.FONT_HERSHEY_SIMPLEX, 0.002)
    _add_relief(cv, txt, 0.0015, 0.0008)
    cv.data = _blur(cv.data, 0.6)
    b.box((-Lf / 2, yf, zf), (Lf, Tf, Hf), body, step=3 * b.res, front={"relief": cv, "rough_m": 0.0004,
                                                                         "step": b.res})
    for u in np.linspace(0.04, Lf - 0.04, 14):
        for v in (0.035, Hf - 0.035):
            b.bolt((-Lf / 2 + u, yf, zf + v), (0, -1, 0), 0.006, steel)
    # wheels (axis towards the camera, -y) behind the frame
    wx = Lf / 2 - 0.2
    for xw in (-wx, wx):
        wc = Canvas.blank(2 * math.pi * Rw, Rw, 0.001, wrap_u=True)
        wm = _mask(wc)
        for v in (0.03, 0.06, Rw - 0.08):
            cv2.line(wm, wc.px(0, v), wc.px(2 * math.pi * Rw, v), 255, 3)
        _add_relief(wc, wm, -0.003, 0.0015)
        c = (xw, yf + Tf + 0.02, Rw)
        b.lathe(c, (0, -1, 0), (1, 0, 0), [(Rw + 0.02, -0.1), (Rw + 0.02, -0.09), (Rw, -0.08), (Rw, 0.0)], steel)
        b.lathe(c, (0, -1, 0), (1, 0, 0), [(Rw, 0.0), (0.07, 0.0)], steel, relief=wc)
        b.lathe(c, (0, -1, 0), (1, 0, 0), [(0.07, 0.0), (0.07, 0.05), (0.0, 0.05)], steel)
        # axle box in front of the frame with bolts and a label
        lab = Canvas.blank(0.12, 0.1, 0.0005, channels=4)
        _place_decal(lab, _decal_label(0.08, 0.03, [f"AXLE {int(rng.integers(1, 9))}"], (0.85, 0.8, 0.2),
                                       (0.0, 0.0, 0.0)), 0.02, 0.06)
        b.box((xw - 0.06, yf - 0.09, Rw - 0.05), (0.12, 0.09, 0.1), body, step=b.res * 1.5,
              front={"decal": lab, "step": b.res})
        for du in (-0.045, 0.045):
            for dv in (-0.035, 0.035):
                b.bolt((xw + du, yf - 0.09, Rw + dv), (0, -1, 0), 0.006, steel)
        # coil spring above the axle box: stacked tori
        for i in range(5):
            zc = Rw + 0.065 + i * 0.022
            tor = [(0.045 + 0.009 * math.cos(a), 0.009 * math.sin(a)) for a in np.linspace(-math.pi, math.pi, 17)]
            b.lathe((xw, yf - 0.045, zc), (0, 0, 1), (1, 0, 0), tor, paint((0.55, 0.45, 0.1), seed + 7, rust=0.4),
                    taper_m=0.0)
    # rails and sleepers
    for yr in (yf + Tf + 0.07, 1.5):
        b.box((-1.2, yr - 0.035, -0.02), (2.4, 0.07, 0.02), steel, step=b.coarse / 2)
    for x in np.arange(-1.1, 1.2, 0.6):
        b.box((x - 0.12, -0.45, -0.02), (0.24, 2.2, 0.035), wood((0.3, 0.22, 0.15), seed + 8, axis=1), step=b.coarse)
    return np.array([0.0, yf, zf * 0.85]), 0.9 * Lf, "train bogie side frame with wheels, springs and axle boxes"


_RECIPES: dict[str, Callable[[_Builder, np.random.Generator, int, bool], tuple[F64, float, str]]] = {
    "panel": _panel, "tablet": _tablet, "cabinet": _cabinet, "motor": _motor, "stupa": _stupa,
    "facade": _facade, "bogie": _bogie,
}
_INDOOR = ("panel", "tablet", "cabinet", "motor", "panel", "stupa", "tablet", "cabinet", "motor", "panel")
_OUTDOOR = ("stupa", "tablet", "facade", "bogie", "cabinet", "facade", "stupa", "tablet", "motor", "bogie")


# ================================================================================================================
# lighting


@dataclass(frozen=True)
class LightingSpec:
    """One lighting condition (see the module docstring). ``kind`` is ``"point"`` (a point light, optionally
    placed by ``clock_h``/``tilt_deg``/``distance_m`` around the reference view) or ``"daylight"`` (sun + sky at
    ``time_local``, ISO local time at the scene's site). ``exposure`` is the camera's normalized exposure per unit
    radiance for a session under this light (None: set by auto-exposure at scene generation)."""

    name: str
    kind: str
    description: str = ""
    clock_h: float | None = None
    tilt_deg: float | None = None
    distance_m: float | None = None
    position_m: tuple[float, float, float] | None = None
    intensity_w_sr: float = 1.0
    color_rgb: tuple[float, float, float] = (1.0, 0.95, 0.88)
    ambient_frac: float = 0.06
    time_local: str | None = None
    sun_transmittance: float = 1.0
    sun_azimuth_deg: float | None = None
    sun_elevation_deg: float | None = None
    exposure: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> LightingSpec:
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise RacrSimError(f"unknown lighting key(s): {sorted(unknown)}")
        kw: dict[str, Any] = {k: (tuple(float(x) for x in v) if isinstance(v, list) else v) for k, v in d.items()}
        return cls(**kw)


@dataclass(frozen=True, eq=False)
class Lighting:
    """A resolved lighting condition: everything the renderer needs, in physical units (linear RGB)."""

    spec: LightingSpec
    point_position_m: F64 | None
    point_intensity_rgb: F64
    sun_direction: F64 | None
    sun_irradiance_rgb: F64
    sky: SkyState | None
    ambient_rgb: F64
    bounce_rgb: F64

    def environment(self, directions: F64) -> F64:
        """Radiance ``(N, 3)`` seen along unit directions that leave the scene."""
        out = np.broadcast_to(self.ambient_rgb, (len(directions), 3)).copy()
        if self.sky is not None:
            out += self.sky.radiance(directions)
        return out


def resolve_lighting(spec: LightingSpec, site: Site | None) -> Lighting:
    """Physical light of ``spec`` (the sun position from the NREL SPA for daylight)."""
    if spec.kind == "point":
        if spec.position_m is None:
            raise RacrSimError(f"lighting {spec.name!r}: a point light needs a position")
        col = np.asarray(spec.color_rgb, float)
        col = col / float(LUMA @ col)
        intensity = spec.intensity_w_sr * col
        d = spec.distance_m or 1.0
        amb = spec.ambient_frac * intensity / (d * d) / math.pi
        return Lighting(spec, np.asarray(spec.position_m, float), intensity, None, np.zeros(3), None, amb, 0.5 * amb)
    if spec.kind == "daylight":
        if site is None or spec.time_local is None:
            raise RacrSimError(f"lighting {spec.name!r}: daylight needs a site and a local time")
        when = dt.datetime.fromisoformat(spec.time_local).replace(tzinfo=site.zone)
        pos = sun_position(site, when)
        el = float(pos.elevation_deg)
        sdir = np.asarray(pos.direction_map, float)
        cs = clear_sky_irradiance(el, altitude_m=site.altitude_m)
        a = float(spec.sun_transmittance)
        dni = cs.dni_wm2 * a * sun_rgb(el) if el > 0 else np.zeros(3)
        clear = cs.dhi_wm2 * (1.0 - 0.2 * (1.0 - a)) * np.asarray(CLEAR_SKY_RGB)
        over = 0.3 * (1.0 - a) * cs.dni_wm2 * max(math.sin(math.radians(el)), 0.0) * np.asarray(OVERCAST_SKY_RGB)
        sky = SkyState(tuple(sdir), tuple(dni), tuple(clear), tuple(over))
        night = np.full(3, 1e-3)
        bounce = 0.5 * 0.3 * sky.ghi_rgb / math.pi + night
        return Lighting(spec, None, np.zeros(3), sdir, dni, sky, night, bounce)
    raise RacrSimError(f"lighting {spec.name!r}: unknown kind {spec.kind!r} (point or daylight)")


def _clock_position(target: F64, T_world_cam: F64, clock_h: float, tilt_deg: float, distance_m: float) -> F64:
    """Point-light position at ``clock_h`` (12 = above, 3 = right, as the camera sees it), ``tilt_deg`` off the
    axis from the target to the camera."""
    a = _unit(T_world_cam[:3, 3] - target)
    up = -T_world_cam[:3, 1]
    up = _unit(up - np.dot(up, a) * a)
    right = np.cross(up, a)
    right = -right if np.dot(right, T_world_cam[:3, 0]) < 0 else right
    phi = math.radians(30.0 * clock_h)
    t = math.radians(tilt_deg)
    d = math.cos(t) * a + math.sin(t) * (math.cos(phi) * up + math.sin(phi) * right)
    return target + distance_m * d


# ================================================================================================================
# renderer


def camera_for_size(width: int, height: int) -> PinholeCamera:
    """Kinect-like intrinsics (fx = fy = 525 px at 640 × 480), scaled to ``width × height``."""
    return PinholeCamera(int(width), int(height), 525.0 * width / 640.0, 525.0 * height / 480.0,
                         width / 2.0 - 0.5, height / 2.0 - 0.5)


def look_at(position: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> F64:
    """``T_world_cam`` (optical frame: x right, y down, z forward) at ``position`` looking at ``target``."""
    p, t = np.asarray(position, float), np.asarray(target, float)
    z = _unit(t - p)
    x = np.cross(z, np.asarray(up, float))
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, np.array([0.0, 1.0, 0.0]))
    x = _unit(x)
    y = np.cross(z, x)
    return make_transform(np.stack([x, y, z], axis=1), p)


@dataclass(frozen=True)
class SensorModel:
    """The camera sensor: normalized exposure ``x = exposure · L`` (x = 1 saturates), Gaussian shot noise on
    ``x · full_well_e`` electrons and read noise, sRGB transfer curve, 8 bits."""

    exposure: float = 1.0
    full_well_e: float = 8000.0
    read_noise_e: float = 4.0

    def capture(self, radiance: F32, rng: np.random.Generator) -> NDArray[np.uint8]:
        x = np.asarray(radiance, np.float32) * np.float32(self.exposure)
        e = np.clip(x, 0.0, 2.0) * np.float32(self.full_well_e)
        sigma = np.sqrt(e + np.float32(self.read_noise_e**2))  # shot (Poisson ~ Gaussian) and read noise
        e += sigma * rng.standard_normal(e.shape, dtype=np.float32)
        x = np.clip(e * np.float32(1.0 / self.full_well_e), 0.0, 1.0)
        v = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
        return np.round(v * 255.0).astype(np.uint8)


@dataclass(frozen=True, eq=False)
class RenderResult:
    """A rendered frame: ``image`` (H, W, 3) uint8 (None without a sensor), linear ``radiance`` (H, W, 3)
    float32, z-depth ``depth_m`` (H, W) float32 (0 where nothing was hit), ``hit`` and ``shadow`` (H, W) bool
    (``shadow``: facing the point light or sun but occluded; evaluation and tests only)."""

    image: NDArray[np.uint8] | None
    radiance: F32
    depth_m: F32
    hit: NDArray[np.bool_]
    shadow: NDArray[np.bool_]


def _fibonacci_sphere(n: int) -> F64:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = math.pi * (1.0 + 5**0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


class RacrRenderer:
    """Embree renderer of a :class:`ReflectanceMesh` under a :class:`Lighting` (see the module docstring)."""

    def __init__(self, mesh: ReflectanceMesh, *, num_threads: int | None = None,
                 ambient_directions: int = AMBIENT_DIRECTIONS) -> None:
        self.mesh = mesh
        self.caster = RayCaster(mesh.vertices_m, mesh.faces, num_threads=num_threads)
        self._faces = mesh.faces
        self._face_normals32 = self.caster.face_normals.astype(np.float32)
        self._vnormals = mesh.vertex_normals.astype(np.float32)
        self._rho = mesh.reflectance.astype(np.float32)
        self._dirs = _fibonacci_sphere(ambient_directions)
        self._vis: NDArray[np.bool_] | None = None
        self._ambient: dict[Any, F32] = {}
        self._rays: dict[PinholeCamera, F64] = {}

    def ambient_visibility(self) -> NDArray[np.bool_]:
        """(V, K) whether direction k escapes from vertex v (only for directions above the vertex's tangent plane;
        others False). Computed once (V · K / 2 occlusion rays)."""
        if self._vis is None:
            n = self._vnormals.astype(np.float64)
            V, K = len(n), len(self._dirs)
            vis = np.zeros((V, K), bool)
            p = self.mesh.vertices_m
            chunk = max(1, 400_000 // K)
            for s in range(0, V, chunk):
                nn, pp = n[s:s + chunk], p[s:s + chunk]
                cos = nn @ self._dirs.T
                vi, ki = np.nonzero(cos > 0.02)
                org = pp[vi] + _EPS_M * nn[vi] + 1e-4 * self._dirs[ki]
                occ = self.caster.occluded(org, self._dirs[ki])
                block = np.zeros((len(nn), K), bool)
                block[vi, ki] = ~occ
                vis[s:s + chunk] = block
            self._vis = vis
        return self._vis

    def vertex_ambient(self, lighting: Lighting) -> F32:
        """Ambient (sky or room) irradiance per vertex (V, 3), cached per lighting."""
        key = lighting.spec
        if key not in self._ambient:
            vis = self.ambient_visibility()
            L = lighting.environment(self._dirs) * (4 * math.pi / len(self._dirs))
            Lb = lighting.bounce_rgb * (4 * math.pi / len(self._dirs))
            n = self._vnormals.astype(np.float64)
            out = np.empty((len(n), 3), np.float32)
            chunk = 100_000
            for s in range(0, len(n), chunk):
                cos = np.clip(n[s:s + chunk] @ self._dirs.T, 0.0, None)
                v = vis[s:s + chunk]
                out[s:s + chunk] = (cos * v) @ L + ((cos * ~v).sum(axis=1))[:, None] * Lb[None, :]
            if len(self._ambient) > 16:
                self._ambient.clear()
            self._ambient[key] = out
        return self._ambient[key]

    def _camera_rays(self, camera: PinholeCamera) -> F64:
        if camera not in self._rays:
            self._rays[camera] = camera.ray_directions().reshape(-1, 3)
        return self._rays[camera]

    def _attributes(self, lighting: Lighting) -> F32:
        """Per-vertex (V, 9) float32: albedo, shading normal, ambient irradiance (cached per lighting)."""
        key = ("attr", lighting.spec)
        if key not in self._ambient:
            self._ambient[key] = np.ascontiguousarray(
                np.concatenate([self._rho, self._vnormals, self.vertex_ambient(lighting)], axis=1))
        return self._ambient[key]

    def render(self, T_world_cam: ArrayLike, camera: PinholeCamera, lighting: Lighting, *,
               sensor: SensorModel | None = None, rng: np.random.Generator | None = None,
               shadows: bool = True) -> RenderResult:
        """Render the view of ``camera`` at ``T_world_cam`` (see the module docstring). ``sensor`` None gives no
        ``image`` (radiance only); ``rng`` drives the sensor noise (default seed 0)."""
        T = np.asarray(T_world_cam, dtype=np.float64)
        R, t = T[:3, :3], T[:3, 3]
        H, W = camera.height, camera.width
        d_cam = self._camera_rays(camera)
        d = np.einsum("ij,kj->ik", d_cam, R)  # (not d_cam @ R.T: BLAS threads are slow for N x 3 @ 3 x 3)
        hits = self.caster.intersect(t, d)
        hi = np.flatnonzero(hits.hit)
        radiance: NDArray[np.float32] = np.zeros((H * W, 3), np.float32)
        shadow = np.zeros(H * W, bool)
        if len(hi):
            tri = hits.triangle_id[hi]
            f = self._faces[tri]
            uv = hits.barycentric_uv[hi]
            u, v = uv[:, 0:1], uv[:, 1:2]
            attr = self._attributes(lighting)
            a = attr[f[:, 0]]
            a += u * (attr[f[:, 1]] - a) + v * (attr[f[:, 2]] - a)
            rho, ns, e_amb = a[:, :3], a[:, 3:6], a[:, 6:9]
            dh = d[hi].astype(np.float32)
            pts = (t + d[hi] * hits.distance_m[hi, None]).astype(np.float32)
            ng = self._face_normals32[tri]
            ng *= np.where(np.einsum("ij,ij->i", ng, dh) > 0, -1.0, 1.0).astype(np.float32)[:, None]
            ns /= np.maximum(np.linalg.norm(ns, axis=1, keepdims=True), 1e-12)
            back = np.einsum("ij,ij->i", ns, dh) > 0
            ns[back] = ng[back]
            direct = np.zeros((len(hi), 3), np.float32)
            occ = np.zeros(len(hi), bool)
            facing = np.zeros(len(hi), bool)
            if lighting.point_position_m is not None:
                ldir = lighting.point_position_m.astype(np.float32) - pts
                r2 = np.einsum("ij,ij->i", ldir, ldir)
                r = np.sqrt(r2)
                ldir /= r[:, None]
                cos = np.einsum("ij,ij->i", ns, ldir)
                facing = (cos > 0) & (np.einsum("ij,ij->i", ng, ldir) > 0)
                k = np.flatnonzero(facing)
                if shadows and len(k):
                    occ[k] = self.caster.occluded(pts[k] + _EPS_M * ng[k], ldir[k], t_far_m=r[k] - 2 * _EPS_M)
                e = np.where(facing & ~occ, cos / r2, 0.0).astype(np.float32)
                direct = e[:, None] * lighting.point_intensity_rgb.astype(np.float32)
            elif lighting.sun_direction is not None and np.any(lighting.sun_irradiance_rgb > 0):
                s = lighting.sun_direction.astype(np.float32)
                cos = ns @ s
                facing = (cos > 0) & (ng @ s > 0)
                k = np.flatnonzero(facing)
                if shadows and len(k):
                    occ[k] = self.caster.occluded(pts[k] + _EPS_M * ng[k], s)
                e = np.where(facing & ~occ, cos, 0.0).astype(np.float32)
                direct = e[:, None] * lighting.sun_irradiance_rgb.astype(np.float32)
            shadow[hi] = facing & occ
            radiance[hi] = rho * np.float32(1.0 / math.pi) * (direct + e_amb)
        mi = np.flatnonzero(~hits.hit)
        if len(mi):
            radiance[mi] = lighting.environment(d[mi])
        depth = np.where(hits.hit, hits.distance_m * d_cam[:, 2].astype(np.float32), 0.0).astype(np.float32)
        radiance = radiance.reshape(H, W, 3)
        image = None
        if sensor is not None:
            image = sensor.capture(radiance, rng if rng is not None else np.random.default_rng(0))
        return RenderResult(image, radiance, depth.reshape(H, W), hits.hit.reshape(H, W), shadow.reshape(H, W))

    def auto_exposure(self, T_world_cam: ArrayLike, camera: PinholeCamera, lighting: Lighting, *,
                      percentile: float = 98.0, target: float = 0.8) -> float:
        """Exposure that maps the ``percentile`` of the scene luminance (a 160-px-wide probe) to ``target``."""
        probe = camera.scaled(min(1.0, 160.0 / camera.width))
        out = self.render(T_world_cam, probe, lighting)
        lum = out.radiance[out.hit] @ LUMA.astype(np.float32)
        if lum.size == 0:
            lum = out.radiance.reshape(-1, 3) @ LUMA.astype(np.float32)
        q = float(np.percentile(lum, percentile)) if lum.size else 1.0
        return float(target / max(q, 1e-12))


# ================================================================================================================
# AFD (evaluation)


@dataclass(frozen=True)
class AfdResult:
    """Average feature-point displacement (px) over the grid points visible in both images; ``success`` if
    ``afd_px < 3``. ``afd_px`` is inf when no grid point is visible in the final image."""

    afd_px: float
    n_points: int
    n_visible: int
    success: bool


def afd_grid_points(caster: RayCaster, camera: PinholeCamera, T_world_camref: ArrayLike, *,
                    grid: tuple[int, int] = AFD_GRID) -> tuple[F64, F64]:
    """The fixed scene points of the AFD: cast a regular ``grid`` (columns, rows) of reference pixels (cell
    centres) onto the scene. Returns ``(points_world (N, 3), pixels_ref (N, 2))`` for the pixels that hit."""
    T = np.asarray(T_world_camref, float)
    cols, rows = grid
    us = (np.arange(cols) + 0.5) * camera.width / cols - 0.5
    vs = (np.arange(rows) + 0.5) * camera.height / rows - 0.5
    U, V = np.meshgrid(us, vs)
    uv = np.stack([U.ravel(), V.ravel()], axis=1)
    d = camera.backproject(uv, np.ones(len(uv))) @ T[:3, :3].T
    hits = caster.intersect(T[:3, 3], d)
    return hits.points()[hits.hit], uv[hits.hit]


def afd(points_world: ArrayLike, T_world_camref: ArrayLike, T_world_cam: ArrayLike, camera: PinholeCamera, *,
        caster: RayCaster | None = None, occlusion_tol_m: float = 2e-3) -> AfdResult:
    """AFD between the reference camera ``T_world_camref`` and the final camera ``T_world_cam`` (see the module
    docstring). With ``caster``, points hidden from the final camera are left out."""
    P = np.asarray(points_world, float).reshape(-1, 3)

    def project(T: F64) -> tuple[F64, NDArray[np.bool_]]:
        Ti = inverse(np.asarray(T, float))
        pc = P @ Ti[:3, :3].T + Ti[:3, 3]
        uv, front = camera.project(pc)
        return uv, front & camera.in_image(uv)

    uv_r, ok_r = project(np.asarray(T_world_camref, float))
    uv_f, ok_f = project(np.asarray(T_world_cam, float))
    ok = ok_r & ok_f
    if caster is not None and np.any(ok):
        c = np.asarray(T_world_cam, float)[:3, 3]
        k = np.flatnonzero(ok)
        dvec = P[k] - c
        dist = np.linalg.norm(dvec, axis=1)
        hits = caster.intersect(np.broadcast_to(c, dvec.shape), dvec)
        ok[k] = hits.distance_m >= dist - occlusion_tol_m
    n_vis = int(np.count_nonzero(ok))
    if n_vis == 0:
        return AfdResult(math.inf, len(P), 0, False)
    val = float(np.mean(np.linalg.norm(uv_f[ok] - uv_r[ok], axis=1)))
    return AfdResult(val, len(P), n_vis, val < AFD_SUCCESS_PX)


# ================================================================================================================
# scene specification and the built scene


@dataclass(frozen=True)
class RacrSceneSpec:
    """Everything that defines a scene before it is built (scene.yaml's ``scene`` section)."""

    name: str
    kind: str
    recipe: str
    seed: int
    lighting: tuple[LightingSpec, ...]
    site: dict[str, Any] | None = None
    camera_azimuth_deg: float = 0.0
    camera_elevation_deg: float = 15.0
    camera_distance_scale: float = 1.0
    initial_translation_m: float = 0.08
    initial_rotation_deg: float = 6.0
    handeye_rotation_deg: float = 25.0
    handeye_translation_m: float = 0.08
    vse_scale_m_per_vse: float = 1.0
    description: str = ""

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "lighting"}
        d["lighting"] = [lt.to_dict() for lt in self.lighting]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RacrSceneSpec:
        d = dict(d)
        d["lighting"] = tuple(LightingSpec.from_dict(x) for x in d.get("lighting", ()))
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise RacrSimError(f"unknown scene key(s): {sorted(unknown)}")
        return cls(**d)

    def site_obj(self) -> Site | None:
        return Site(**self.site) if self.site else None


_SITES = {
    "beijing": dict(latitude_deg=39.99, longitude_deg=116.27, altitude_m=50.0, timezone="Asia/Shanghai"),
    "freiburg": dict(latitude_deg=48.0, longitude_deg=7.85, altitude_m=278.0, timezone="Europe/Berlin"),
    "tianjin": dict(latitude_deg=39.1, longitude_deg=117.17, altitude_m=5.0, timezone="Asia/Shanghai"),
}


def scene_specs(seed: int = 0) -> tuple[RacrSceneSpec, ...]:
    """The 20 scenes S01–S20 (S01–S10 indoor, S11–S20 outdoor), deterministic for ``seed``."""
    specs = []
    for i in range(20):
        rng = np.random.default_rng([seed, i, 7])
        name = f"S{i + 1:02d}"
        outdoor = i >= 10
        recipe = (_OUTDOOR if outdoor else _INDOOR)[i % 10]
        common: dict[str, Any] = dict(
            camera_azimuth_deg=round(float(rng.uniform(-20, 20)), 2),
            camera_elevation_deg=round(float(rng.uniform(8, 25)), 2),
            camera_distance_scale=round(float(rng.uniform(0.95, 1.1)), 3),
            initial_translation_m=round(float(rng.uniform(0.05, 0.12)), 4),
            initial_rotation_deg=round(float(rng.uniform(4.0, 10.0)), 2),
            handeye_rotation_deg=round(float(rng.uniform(15.0, 40.0)), 2),
            handeye_translation_m=round(float(rng.uniform(0.04, 0.12)), 4),
            vse_scale_m_per_vse=round(float(np.exp(rng.uniform(math.log(0.3), math.log(3.0)))), 4),
        )
        if not outdoor:
            dist = round(float(rng.uniform(0.9, 1.3)), 3)
            inten = 1.0
            ref_tilt = round(float(rng.uniform(30, 40)), 1)
            sim_clock = float(rng.choice([11.0, 1.0]))
            var_clock = float(rng.choice([2.0, 3.0, 9.0, 10.0]))  # lower clock positions: under the table
            lights = (
                LightingSpec("reference", "point", "front light (12 o'clock)", 12.0, ref_tilt, dist,
                             intensity_w_sr=inten),
                LightingSpec("similar", "point", f"front light ({sim_clock:g} o'clock)", sim_clock,
                             round(ref_tilt + float(rng.uniform(-3, 5)), 1), dist, intensity_w_sr=inten),
                LightingSpec("varied", "point", f"side light ({var_clock:g} o'clock, grazing)", var_clock,
                             round(float(rng.uniform(65, 78)), 1), dist, intensity_w_sr=inten),
            )
            specs.append(RacrSceneSpec(name, "indoor", recipe, int(rng.integers(1 << 30)), lights,
                                       description="", **common))
            continue
        site_name = str(rng.choice(list(_SITES)))
        site = dict(_SITES[site_name], heading_deg=round(float(rng.uniform(-25, 25)), 2))
        month = int(rng.integers(4, 10))
        day = int(rng.integers(1, 20))
        morning = bool(rng.random() < 0.5)
        h_ref = float(rng.uniform(9.0, 10.5)) if morning else float(rng.uniform(14.0, 15.5))
        h_var = float(rng.uniform(14.5, 16.0)) if morning else float(rng.uniform(8.5, 10.0))

        def iso(day_: int, hour: float, month: int = month) -> str:
            hh, mm = int(hour), round((hour - int(hour)) * 60) % 60
            return f"2021-{month:02d}-{day_:02d}T{hh:02d}:{mm:02d}:00"

        ref = LightingSpec("reference", "daylight", "clear sky", time_local=iso(day, h_ref),
                           sun_transmittance=1.0)
        sim = LightingSpec("similar", "daylight", "same time of day, days later, light haze",
                           time_local=iso(day + int(rng.integers(2, 8)), h_ref + float(rng.uniform(-0.25, 0.25))),
                           sun_transmittance=round(float(rng.uniform(0.8, 0.95)), 3))
        if name in ("S14", "S15"):
            var = LightingSpec("varied", "point", "night, floodlight from the side",
                               clock_h=float(rng.choice([3.0, 9.0])), tilt_deg=round(float(rng.uniform(55, 70)), 1),
                               distance_m=2.5, intensity_w_sr=1.0, color_rgb=(1.0, 0.85, 0.65), ambient_frac=0.01)
        else:
            var = LightingSpec("varied", "daylight", "other time of day (sun on the other side)",
                               time_local=iso(day + int(rng.integers(3, 10)), h_var),
                               sun_transmittance=round(float(rng.uniform(0.85, 1.0)), 3))
        specs.append(RacrSceneSpec(name, "outdoor", recipe, int(rng.integers(1 << 30)), (ref, sim, var),
                                   site=site, description="", **common))
    return tuple(specs)


@dataclass(frozen=True, eq=False)
class SceneTruth:
    """Truth of a scene (truth.yaml): poses in the world frame, X, the VSE scale and the AFD grid."""

    T_world_camref: F64
    T_camref_cam0: F64
    T_cam_hand: F64
    T_world_base: F64
    T_world_ref: F64
    vse_scale_m_per_vse: float
    afd_points_world: F64
    afd_pixels_ref: F64
    target_m: F64 = field(default_factory=lambda: np.zeros(3))

    @property
    def T_world_cam0(self) -> F64:
        return self.T_world_camref @ self.T_camref_cam0


@dataclass(eq=False)
class RacrScene:
    """A built (or loaded) scene: spec, mesh, camera, resolved lighting variants, truth, reference."""

    spec: RacrSceneSpec
    mesh: ReflectanceMesh
    camera: PinholeCamera
    lightings: dict[str, LightingSpec]
    truth: SceneTruth
    platform_config: PlatformConfig = field(default_factory=PlatformConfig)
    vse_config: VseConfig = field(default_factory=VseConfig)
    reference: ReferenceObservation | None = None
    description: str = ""
    resolution_m: float = DEFAULT_RESOLUTION_M

    @cached_property
    def renderer(self) -> RacrRenderer:
        return RacrRenderer(self.mesh)

    @property
    def site(self) -> Site | None:
        return self.spec.site_obj()

    def lighting(self, name: str) -> Lighting:
        """The resolved lighting variant ``name`` (reference, similar, varied)."""
        if name not in self.lightings:
            raise RacrSimError(f"scene {self.spec.name}: no lighting {name!r} (have {sorted(self.lightings)})")
        cache = self.__dict__.setdefault("_resolved", {})
        spec = self.lightings[name]
        if cache.get(name, (None,))[0] != spec:
            cache[name] = (spec, resolve_lighting(spec, self.site))
        return cache[name][1]

    def sensor(self, name: str) -> SensorModel:
        exp = self.lightings[name].exposure
        return SensorModel(exposure=1.0 if exp is None else float(exp))

    def render(self, T_world_cam: ArrayLike, lighting: str, *, camera: PinholeCamera | None = None,
               seed: int = 0) -> RenderResult:
        return self.renderer.render(T_world_cam, camera or self.camera, self.lighting(lighting),
                                    sensor=self.sensor(lighting), rng=np.random.default_rng(seed))

    def make_platform(self, config: PlatformConfig | None = None, *, seed: int = 0) -> PlatformSimulator:
        """The platform at the scene's initial pose (camera at ``T_world_cam0``) with the true X."""
        X = self.truth.T_cam_hand
        return PlatformSimulator(self.truth.T_world_cam0 @ X, X, config=config or self.platform_config,
                                 T_world_base=self.truth.T_world_base, seed=seed)

    def make_vse(self, lighting: str = "varied", *, config: VseConfig | None = None, seed: int = 0,
                 scale_m_per_vse: float | None = None) -> VseStandIn:
        """A VSE stand-in for a session under ``lighting`` with the scene's monocular scale."""
        return VseStandIn(self.renderer, self.camera, self.lighting(lighting), sensor=self.sensor(lighting),
                          scale_m_per_vse=scale_m_per_vse or self.truth.vse_scale_m_per_vse,
                          config=config or self.vse_config, seed=seed)

    def add_clock_lighting(self, clock_h: float, *, tilt_deg: float | None = None, name: str | None = None) -> str:
        """Add a point-light variant at ``clock_h`` o'clock around the reference view (paper Fig. 7: the reference
        under 12 o'clock, relocalization under 1–12 o'clock), tilted like the ``varied`` light unless
        ``tilt_deg``; auto-exposed at the initial pose. Indoor scenes only. Returns the variant's name."""
        ref = self.lightings["reference"]
        if ref.kind != "point":
            raise RacrSimError(f"scene {self.spec.name}: clock lighting needs a point-light (indoor) scene")
        var = self.lightings.get("varied", ref)
        tilt = float(tilt_deg if tilt_deg is not None else (var.tilt_deg or 70.0))
        dist = float(ref.distance_m or 1.0)
        pos = _clock_position(self.truth.target_m, self.truth.T_world_camref, clock_h, tilt, dist)
        name = name or f"clock{clock_h:g}"
        spec = replace(ref, name=name, description=f"point light at {clock_h:g} o'clock", clock_h=float(clock_h),
                       tilt_deg=tilt, position_m=float3(np.round(pos, 6)), exposure=None)
        exp = self.renderer.auto_exposure(self.truth.T_world_cam0, self.camera, resolve_lighting(spec, None))
        self.lightings[name] = replace(spec, exposure=float(f"{exp:.6g}"))
        return name

    def afd(self, T_world_cam: ArrayLike) -> AfdResult:
        """AFD of a final camera pose against the reference pose (truth)."""
        return afd(self.truth.afd_points_world, self.truth.T_world_camref, T_world_cam, self.camera,
                   caster=self.renderer.caster)


def _random_rotation(rng: np.random.Generator, angle_deg: float) -> F64:
    axis = _unit(rng.normal(size=3))
    return so3_exp(axis * math.radians(angle_deg))


def _handeye(rng: np.random.Generator, angle_deg: float, trans_m: float) -> F64:
    """X = T_cam_hand: the hand flange a few cm behind/above the camera, rotated by ``angle_deg``."""
    R = _random_rotation(rng, angle_deg)
    t = trans_m * _unit(rng.normal(size=3) + np.array([0.0, -0.5, -1.0]))
    return make_transform(R, t)


def build_scene(spec: RacrSceneSpec, *, width: int = 640, height: int = 480,
                resolution_m: float = DEFAULT_RESOLUTION_M, reference: bool = True,
                vse_config: VseConfig | None = None, platform_config: PlatformConfig | None = None) -> RacrScene:
    """Build the mesh, camera, lighting, truth and (unless ``reference`` is False) the reference observation of
    ``spec``. Deterministic."""
    if spec.recipe not in _RECIPES:
        raise RacrSimError(f"unknown scene recipe {spec.recipe!r} (have {sorted(_RECIPES)})")
    rng = np.random.default_rng([spec.seed, 1])
    b = _Builder(resolution_m, spec.seed % 100000)
    outdoor = spec.kind == "outdoor"
    (_outdoor_set if outdoor else _indoor_set)(b, rng, spec.seed % 100000)
    target, dist, desc = _RECIPES[spec.recipe](b, rng, spec.seed % 100000 + 11, outdoor)
    mesh = b.finish()
    camera = camera_for_size(width, height)
    # reference camera: in front of the subject (-y), azimuth and elevation from the spec
    d = dist * spec.camera_distance_scale
    az, el = math.radians(spec.camera_azimuth_deg), math.radians(spec.camera_elevation_deg)
    pos = target + d * np.array([math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el)])
    T_world_camref = look_at(pos, target)
    prng = np.random.default_rng([spec.seed, 2])
    tdir = _unit(prng.normal(size=3))
    T_camref_cam0 = make_transform(_random_rotation(prng, spec.initial_rotation_deg),
                                   spec.initial_translation_m * tdir)
    X = _handeye(prng, spec.handeye_rotation_deg, spec.handeye_translation_m)
    T_world_base = make_transform(so3_exp([0.0, 0.0, prng.uniform(-math.pi, math.pi)]),
                                  target + np.array([prng.uniform(-0.3, 0.3), -d - 0.5, -0.1]))
    T_world_ref = make_transform(_random_rotation(prng, prng.uniform(20, 170)), prng.normal(size=3))
    renderer = RacrRenderer(mesh)
    site = spec.site_obj()
    lightings: dict[str, LightingSpec] = {}
    for lt in spec.lighting:
        if lt.kind == "point" and lt.position_m is None:
            pos_l = _clock_position(target, T_world_camref, lt.clock_h or 12.0, lt.tilt_deg or 35.0,
                                    lt.distance_m or 1.0)
            lt = replace(lt, position_m=float3(np.round(pos_l, 6)))
        if lt.kind == "daylight":
            if site is None or lt.time_local is None:
                raise RacrSimError(f"lighting {lt.name!r}: daylight needs a site and a local time")
            sp = sun_position(site, dt.datetime.fromisoformat(lt.time_local).replace(tzinfo=site.zone))
            lt = replace(lt, sun_azimuth_deg=round(float(sp.azimuth_deg), 3),
                         sun_elevation_deg=round(float(sp.elevation_deg), 3))
        if lt.exposure is None:
            at = T_world_camref if lt.name == "reference" else T_world_camref @ T_camref_cam0
            exp = renderer.auto_exposure(at, camera, resolve_lighting(lt, site))
            lt = replace(lt, exposure=float(f"{exp:.6g}"))
        lightings[lt.name] = lt
    pts, pix = afd_grid_points(renderer.caster, camera, T_world_camref)
    truth = SceneTruth(T_world_camref, T_camref_cam0, X, T_world_base, T_world_ref, spec.vse_scale_m_per_vse,
                       pts, pix, np.asarray(target, float))
    scene = RacrScene(spec, mesh, camera, lightings, truth, platform_config or PlatformConfig(),
                      vse_config or VseConfig(), None, desc, resolution_m)
    scene.__dict__["renderer"] = renderer
    if reference:
        scene.reference = make_reference(scene, seed=spec.seed % 1000)
    return scene


def make_reference(scene: RacrScene, *, seed: int = 0, lighting: str = "reference") -> ReferenceObservation:
    """The reference observation: a metric VSE cloud in frame ``reference`` around the reference pose, and the
    reference image at exactly that pose."""
    tr = scene.truth
    vse = VseStandIn(scene.renderer, scene.camera, scene.lighting(lighting), sensor=scene.sensor(lighting),
                     scale_m_per_vse=1.0, config=replace(scene.vse_config, drift_rotation_deg_per_m=0.0,
                                                         drift_translation_per_m=0.0, drift_scale_per_m=0.0,
                                                         pose_noise_deg=0.0, pose_noise_m=0.0),
                     T_world_vse=tr.T_world_ref, seed=seed)
    obs = vse.observe(tr.T_world_camref)
    img = scene.render(tr.T_world_camref, lighting, seed=seed + 1).image
    assert img is not None
    return ReferenceObservation(scene.spec.name, lighting, scene.camera, inverse(tr.T_world_ref) @ tr.T_world_camref,
                                obs.points_vse, obs.intensity, img)


# ================================================================================================================
# files


def _readable(root: Path) -> None:
    """Temporary files and directories are private (0600/0700); give the published tree the usual modes."""
    for p in [root, *root.rglob("*")]:
        p.chmod(0o755 if p.is_dir() else 0o644)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _scene_doc(scene: RacrScene) -> dict[str, Any]:
    tr = scene.truth
    from lightfast.geometry import rotation_angle_deg

    return {
        "format": "lightfast-racr-scene", "format_version": FORMAT_VERSION,
        "name": scene.spec.name, "kind": scene.spec.kind, "description": scene.description,
        "resolution_m": scene.resolution_m,
        "mesh": {"file": "mesh.ply", "vertices": scene.mesh.num_vertices, "triangles": scene.mesh.num_faces},
        "camera": camera_to_dict(scene.camera),
        "lighting": {k: v.to_dict() for k, v in scene.lightings.items()},
        "initial_offset": {
            "description": "true initial camera pose relative to the reference camera (simulator setup)",
            "T_camref_cam0": matrix_to_list(tr.T_camref_cam0),
            "translation_m": float(np.linalg.norm(tr.T_camref_cam0[:3, 3])),
            "rotation_deg": float(rotation_angle_deg(tr.T_camref_cam0)),
        },
        "platform": scene.platform_config.to_dict(),
        "vse": scene.vse_config.to_dict(),
        "reference": "reference",
        "spec": scene.spec.to_dict(),
        "truth": {
            "note": "simulator truth: rACR must not read this section",
            "T_cam_hand": matrix_to_list(tr.T_cam_hand), "T_world_base": matrix_to_list(tr.T_world_base),
            "vse_scale_m_per_vse": tr.vse_scale_m_per_vse,
        },
    }


def _truth_doc(scene: RacrScene) -> dict[str, Any]:
    tr = scene.truth
    return {
        "format": "lightfast-racr-truth", "format_version": FORMAT_VERSION, "scene": scene.spec.name,
        "T_world_camref": matrix_to_list(tr.T_world_camref), "T_world_cam0": matrix_to_list(tr.T_world_cam0),
        "T_camref_cam0": matrix_to_list(tr.T_camref_cam0), "T_world_ref": matrix_to_list(tr.T_world_ref),
        "T_cam_hand": matrix_to_list(tr.T_cam_hand), "T_world_base": matrix_to_list(tr.T_world_base),
        "vse_scale_m_per_vse": tr.vse_scale_m_per_vse, "target_m": [float(x) for x in tr.target_m],
        "afd": {"grid": list(AFD_GRID), "success_px": AFD_SUCCESS_PX,
                "pixels_ref": [[float(x) for x in r] for r in tr.afd_pixels_ref],
                "points_world": [[float(x) for x in r] for r in tr.afd_points_world]},
    }


def write_scene(scene: RacrScene, path: str | os.PathLike[str], *, params_hash: str = "",
                previews: bool = True, stats: dict[str, Any] | None = None) -> Path:
    """Write the scene directory (see the module docstring) under a temporary name and move it into place."""
    if scene.reference is None:
        raise RacrSimError(f"scene {scene.spec.name}: no reference observation to write")
    path = Path(path)
    with atomic_directory(path, overwrite=True) as tmp:
        save_ply(scene.mesh, tmp / "mesh.ply")
        write_text_atomic(tmp / "scene.yaml", "# lightfast rACR simulated scene (simulator setup; rACR reads only "
                                              "reference/)\n" + yaml_text(_scene_doc(scene)))
        write_text_atomic(tmp / "truth.yaml", "# lightfast rACR scene truth: evaluation only\n"
                          + yaml_text(_truth_doc(scene)))
        write_reference(scene.reference, tmp / "reference")
        if previews:
            tr = scene.truth
            for name, T, lt in (("reference_varied", tr.T_world_camref, "varied"),
                                ("initial_similar", tr.T_world_cam0, "similar"),
                                ("initial_varied", tr.T_world_cam0, "varied")):
                img = scene.render(T, lt, seed=3).image
                assert img is not None
                write_bytes_atomic(tmp / "preview" / f"{name}.png", png_bytes(img, error=RacrSimError))
        files = sorted(p for p in tmp.rglob("*") if p.is_file())
        manifest = {
            "format": "lightfast-racr-scene-manifest", "format_version": FORMAT_VERSION,
            "scene": scene.spec.name, "params_hash": params_hash,
            "files": {str(p.relative_to(tmp)): {"sha256": _sha256(p), "bytes": p.stat().st_size} for p in files},
            "stats": stats or {},
        }
        write_text_atomic(tmp / "scene.json", json.dumps(manifest, indent=1) + "\n")
        _readable(tmp)
    return path


def scene_complete(path: str | os.PathLike[str], params_hash: str | None = None) -> bool:
    """True when ``path`` holds a complete scene directory: manifest present (with ``params_hash`` if given) and
    every listed file present with its size and SHA-256."""
    path = Path(path)
    try:
        man = json.loads((path / "scene.json").read_text())
        if man.get("format_version") != FORMAT_VERSION:
            return False
        if params_hash is not None and man.get("params_hash") != params_hash:
            return False
        files = man["files"]
        for rel, info in files.items():
            p = path / rel
            if not p.is_file() or p.stat().st_size != info["bytes"] or _sha256(p) != info["sha256"]:
                return False
        return {"scene.yaml", "truth.yaml", "mesh.ply", "reference/reference.yaml"} <= set(files)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return False


def load_scene(path: str | os.PathLike[str], *, verify: bool = True) -> RacrScene:
    """Load a scene directory written by :func:`write_scene` (simulator and evaluation side)."""
    path = Path(path)
    if verify and not scene_complete(path):
        raise RacrSimError(f"{path}: not a complete rACR scene directory (missing or half-written; regenerate it "
                           "with `lightfast sim racr`)")
    try:
        doc = yaml.safe_load((path / "scene.yaml").read_text())
        tdoc = yaml.safe_load((path / "truth.yaml").read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise RacrSimError(f"{path}: cannot read scene files: {exc}") from None
    if not isinstance(doc, dict) or doc.get("format") != "lightfast-racr-scene" or \
            doc.get("format_version") != FORMAT_VERSION:
        raise RacrSimError(f"{path}/scene.yaml: not a lightfast-racr-scene version {FORMAT_VERSION}")
    try:
        mesh = load_ply(path / "mesh.ply")
    except MeshError as exc:
        raise RacrSimError(f"{path}: {exc}") from None
    try:
        spec = RacrSceneSpec.from_dict(doc["spec"])
        afd_doc = tdoc["afd"]
        def mat(x: Any, name: str, shape: tuple[int, ...] = (4, 4)) -> F64:
            return matrix_from(x, name, shape, error=RacrSimError)

        truth = SceneTruth(
            mat(tdoc["T_world_camref"], "T_world_camref"), mat(tdoc["T_camref_cam0"], "T_camref_cam0"),
            mat(doc["truth"]["T_cam_hand"], "T_cam_hand"), mat(doc["truth"]["T_world_base"], "T_world_base"),
            mat(tdoc["T_world_ref"], "T_world_ref"), float(doc["truth"]["vse_scale_m_per_vse"]),
            np.asarray(afd_doc["points_world"], float).reshape(-1, 3),
            np.asarray(afd_doc["pixels_ref"], float).reshape(-1, 2), mat(tdoc["target_m"], "target_m", (3,)))
        lightings = {k: LightingSpec.from_dict(v) for k, v in doc["lighting"].items()}
        camera = camera_from_dict(doc["camera"], str(path), error=RacrSimError)
        platform, vse = PlatformConfig(**doc["platform"]), VseConfig(**doc["vse"])
        resolution = float(doc["resolution_m"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise RacrSimError(f"{path}: malformed scene.yaml or truth.yaml: {type(exc).__name__}: {exc}") from None
    ref = load_reference(path / str(doc.get("reference", "reference")), scene=spec.name)
    return RacrScene(spec, ReflectanceMesh(mesh.vertices_m, mesh.faces, mesh.reflectance), camera, lightings, truth,
                     platform, vse, ref, str(doc.get("description", "")), resolution)


def _params_hash(spec: RacrSceneSpec, width: int, height: int, resolution_m: float) -> str:
    doc = {"format_version": FORMAT_VERSION, "reference_version": REFERENCE_VERSION, "spec": spec.to_dict(),
           "width": width, "height": height, "resolution_m": resolution_m,
           "platform": PlatformConfig().to_dict(), "vse": VseConfig().to_dict()}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:16]


def generate_racr_set(out_dir: str | os.PathLike[str], *, scenes: Sequence[str] | None = None, count: int | None = None,
                      width: int = 640, height: int = 480, resolution_m: float = DEFAULT_RESOLUTION_M, seed: int = 0,
                      force: bool = False, progress: bool = False, previews: bool = True) -> list[Path]:
    """Write the scene directories (default all 20; ``scenes`` names or the first ``count``) into ``out_dir``.
    Complete directories with the same parameters are reused unless ``force``. Returns the scene directories."""
    specs = scene_specs(seed)
    by_name = {s.name: s for s in specs}
    if scenes:
        unknown = [n for n in scenes if n not in by_name]
        if unknown:
            raise RacrSimError(f"unknown scene(s) {unknown}; choose from S01..S20")
        chosen = [by_name[n] for n in scenes]
    else:
        chosen = list(specs[: count if count is not None else len(specs)])
    if width < 16 or height < 16:
        raise RacrSimError(f"image size must be at least 16x16, got {width}x{height}")
    if not resolution_m > 0:
        raise RacrSimError(f"resolution must be > 0, got {resolution_m}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    dirs: list[Path] = []
    for spec in track(chosen, desc="rACR scenes", enabled=progress, unit="scene"):
        d = out / spec.name
        digest = _params_hash(spec, width, height, resolution_m)
        if not force and scene_complete(d, digest):
            log.info("%s: complete, reused", spec.name)
            dirs.append(d)
            continue
        t0 = time.perf_counter()
        scene = build_scene(spec, width=width, height=height, resolution_m=resolution_m)
        t1 = time.perf_counter()
        stats = {"vertices": scene.mesh.num_vertices, "triangles": scene.mesh.num_faces,
                 "reference_points": len(scene.reference.points_m) if scene.reference else 0,
                 "seconds_build": round(t1 - t0, 3)}
        write_scene(scene, d, params_hash=digest, previews=previews, stats=stats)
        log.info("%s: %s, %d triangles, %.1f s", spec.name, scene.description, scene.mesh.num_faces,
                 time.perf_counter() - t0)
        dirs.append(d)
    return dirs
