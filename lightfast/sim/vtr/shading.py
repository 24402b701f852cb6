"""Per-pixel materials and shading normals of the simulated VT&R route: the procedural texture and the compiled
shading kernel of :class:`~lightfast.sim.vtr.renderer.SpectralRenderer` (paper: Paton et al., §V; features must
exist in greyscale and in the colour-constant images of §III alike).

Every surface is a per-pixel mixture of the :data:`~lightfast.sim.vtr.spectra.BASIS` reflectance spectra, chosen
by surface kind (ground, rock, trunk, foliage), stretch, distance to the path (a dirt track on grass and in the
woods) and a world-fixed procedural texture (:class:`MipTexture`: FFT-synthesized tileable fractal noise, 4
channels, ``texture_size``² texels with a mip-map chain; sampled at two scales, 1.5 cm and 12.4 cm texels (periods
31 m and 254 m at 2048², the coarse one rotated), bilinearly in the mip level nearest to the pixel footprint) that
varies brightness *and* chromaticity (sand vs. iron-red sand vs. dark grains, green vs. dry grass vs. bare soil,
litter vs. moss, grey vs. red rock, bark, two leaf spectra).

Micro-relief below the mesh resolution (sand ripples and grains, rock roughness, bark ridges): the shading normal
is tilted by facet slopes up to the renderer's ``bump_slope`` per kind, from the texture's "mid" noise channel at
two unrelated points, mip-averaged like the albedo so that the relief smooths out with distance; sunlit surfaces
then show a shading texture that changes with the sun's direction while sky-lit shadow keeps the albedo texture
only.

:func:`shade_kernel` (Numba, releases the GIL; one chunk of pixels per thread). Inputs: ray origins (map frame, m),
hit distances (m), unit directions, triangle ids and barycentrics from Embree, the mesh and its per-vertex data.
Outputs per hit pixel: the map-frame position (m), facing geometric and shading normals, the interpolated
hemisphere fractions (sky, foliage, other) and the basis weights ``W`` (pixels × basis: mixture × brightness).
"""
from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from lightfast.sim.vtr.scene import KIND_GROUND, KIND_ROCK, KIND_TRUNK
from lightfast.sim.vtr.spectra import BASIS

__all__ = [
    "MipTexture",
    "shade_kernel",
]

_F32 = NDArray[np.float32]
_F64 = NDArray[np.float64]


class MipTexture:
    """A tileable 4-channel fractal-noise texture (values roughly uniform in [0, 1]) with a mip-map chain, sampled
    by pixel footprint."""

    BETAS = (2.2, 1.2, 1.8, 0.8)  # power-spectrum exponents: blotches, grain, mid, speckle

    def __init__(self, size: int, seed: int) -> None:
        if size < 16 or size & (size - 1):
            raise ValueError(f"texture size must be a power of two >= 16, got {size}")
        rng = np.random.default_rng([seed, 77])
        fy = np.fft.fftfreq(size)[:, None]
        fx = np.fft.rfftfreq(size)[None, :]
        f = np.hypot(fx, fy)
        f[0, 0] = 1.0
        chans = []
        for beta in self.BETAS:
            spec = np.fft.rfft2(rng.standard_normal((size, size))) * f ** (-beta / 2.0)
            spec[0, 0] = 0.0
            img = np.fft.irfft2(spec, s=(size, size)).ravel()
            ranks = np.empty(img.size)
            ranks[np.argsort(img, kind="stable")] = (np.arange(img.size) + 0.5) / img.size
            chans.append(ranks.reshape(size, size))
        level = np.stack(chans, axis=-1).astype(np.float32)
        levels = [level]
        while levels[-1].shape[0] > 1:
            a = levels[-1]
            levels.append(0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2]))
        self.size = size
        self.n_levels = len(levels)
        self.offsets = np.cumsum([0] + [lv.shape[0] ** 2 for lv in levels[:-1]]).astype(np.int64)
        self.flat = np.ascontiguousarray(np.concatenate([lv.reshape(-1, 4) for lv in levels]), dtype=np.float32)


# Column indices of the basis spectra, as compile-time constants of the shading kernel.
_SAND_LIGHT, _SAND_RED, _GRAVEL_DARK, _ROCK_GREY, _ROCK_RED, _ROCK_DARK = 0, 1, 2, 3, 4, 5
_GRASS_GREEN, _GRASS_DRY, _SOIL_BROWN, _LEAF_LITTER, _MOSS = 6, 7, 8, 9, 10
_BARK_GREY, _BARK_BROWN, _LEAF_GREEN, _LEAF_YELLOW = 11, 12, 13, 14
assert BASIS.index("leaf_yellow") == _LEAF_YELLOW and BASIS.index("moss") == _MOSS


@numba.njit(cache=True, nogil=True, inline="always")
def _smoothstep(e0: float, e1: float, x: float) -> float:
    t = min(max((x - e0) / (e1 - e0), 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


@numba.njit(cache=True, nogil=True)
def _tex_sample(tex: _F32, offsets: NDArray[np.int64], size: int, n_levels: int, u: float, v: float,
                footprint: float) -> tuple[float, float, float, float]:
    """Bilinear sample (4 channels) of the mip level nearest to ``log2(footprint)`` (texel units of level 0)."""
    lev = round(math.log2(max(footprint, 1e-6)))
    lev = min(max(lev, 0), n_levels - 1)
    n = size >> lev
    mask = n - 1
    scale = 1.0 / (1 << lev)
    x = u * scale - 0.5
    y = v * scale - 0.5
    x0 = math.floor(x)
    y0 = math.floor(y)
    fx = x - x0
    fy = y - y0
    ix0 = np.int64(x0) & mask
    iy0 = np.int64(y0) & mask
    ix1 = (ix0 + 1) & mask
    iy1 = (iy0 + 1) & mask
    base = offsets[lev]
    a00, a01 = base + iy0 * n + ix0, base + iy0 * n + ix1
    a10, a11 = base + iy1 * n + ix0, base + iy1 * n + ix1
    w00, w01, w10, w11 = (1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy
    return (w00 * tex[a00, 0] + w01 * tex[a01, 0] + w10 * tex[a10, 0] + w11 * tex[a11, 0],
            w00 * tex[a00, 1] + w01 * tex[a01, 1] + w10 * tex[a10, 1] + w11 * tex[a11, 1],
            w00 * tex[a00, 2] + w01 * tex[a01, 2] + w10 * tex[a10, 2] + w11 * tex[a11, 2],
            w00 * tex[a00, 3] + w01 * tex[a01, 3] + w10 * tex[a10, 3] + w11 * tex[a11, 3])


@numba.njit(cache=True, nogil=True)
def shade_kernel(origins: _F64, view: NDArray[np.int64], t: _F32, d: _F32, tri: NDArray[np.int64], uv: _F32,
                  faces: NDArray[np.int64], face_normals: _F32, face_kind: NDArray[np.int8], vdata: _F32,
                  smooth: NDArray[np.bool_], tex: _F32, tex_offsets: NDArray[np.int64], tex_size: int,
                  tex_levels: int, textured: bool, k_fine: float, k_coarse: float, fx_px: float,
                  bump: NDArray[np.float64], p_out: _F64, ng_out: _F32, n_out: _F32, vis_out: _F32,
                  W: _F32) -> None:
    """Per hit pixel: position, facing geometric and shading normals (with the micro-relief of ``bump``, the
    largest facet slope per surface kind), interpolated hemisphere fractions and basis weights (mixture ×
    brightness; see :class:`~lightfast.sim.vtr.renderer.SpectralRenderer`). ``W`` must be zero on entry."""
    ca, sa = math.cos(0.6) * k_coarse, math.sin(0.6) * k_coarse
    for i in range(len(t)):
        o = origins[view[i]]
        ti = t[i]
        p0 = o[0] + ti * d[i, 0]
        p1 = o[1] + ti * d[i, 1]
        p2 = o[2] + ti * d[i, 2]
        p_out[i, 0], p_out[i, 1], p_out[i, 2] = p0, p1, p2
        f = tri[i]
        kind = face_kind[f]
        g0, g1, g2 = face_normals[f, 0], face_normals[f, 1], face_normals[f, 2]
        cosv = g0 * d[i, 0] + g1 * d[i, 1] + g2 * d[i, 2]
        if cosv > 0:
            g0, g1, g2 = -g0, -g1, -g2
        cosv = abs(cosv)
        ng_out[i, 0], ng_out[i, 1], ng_out[i, 2] = g0, g1, g2
        b1, b2 = uv[i, 0], uv[i, 1]
        b0 = 1.0 - b1 - b2
        va, vb, vc = faces[f, 0], faces[f, 1], faces[f, 2]
        for c in range(3):
            vis_out[i, c] = b0 * vdata[va, 7 + c] + b1 * vdata[vb, 7 + c] + b2 * vdata[vc, 7 + c]
        if smooth[kind]:
            n0 = b0 * vdata[va, 0] + b1 * vdata[vb, 0] + b2 * vdata[vc, 0]
            n1 = b0 * vdata[va, 1] + b1 * vdata[vb, 1] + b2 * vdata[vc, 1]
            n2 = b0 * vdata[va, 2] + b1 * vdata[vb, 2] + b2 * vdata[vc, 2]
            ln = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2) + 1e-12
            n0, n1, n2 = n0 / ln, n1 / ln, n2 / ln
            if n0 * g0 + n1 * g1 + n2 * g2 < 0:
                n0, n1, n2 = -n0, -n1, -n2
        else:
            n0, n1, n2 = g0, g1, g2
        n_out[i, 0], n_out[i, 1], n_out[i, 2] = n0, n1, n2
        r0 = b0 * vdata[va, 3] + b1 * vdata[vb, 3] + b2 * vdata[vc, 3]  # sand_rock weight / object tint
        r1 = b0 * vdata[va, 4] + b1 * vdata[vb, 4] + b2 * vdata[vc, 4]  # grass weight / texture offset
        r2 = b0 * vdata[va, 5] + b1 * vdata[vb, 5] + b2 * vdata[vc, 5]  # wood weight
        track = b0 * vdata[va, 6] + b1 * vdata[vb, 6] + b2 * vdata[vc, 6]
        tint = r0
        f0 = f1 = f3 = c0 = c1 = c2 = 0.5
        if textured:
            foot = ti / fx_px / math.sqrt(max(cosv, 0.05))
            a0, a1, a2 = abs(n0), abs(n1), abs(n2)
            z = p2 * 0.25 if kind == KIND_TRUNK else p2
            u = p1 if (a0 >= a1 and a0 >= a2) else p0
            v = p1 if (a2 > a0 and a2 > a1) else z
            off = 0.0 if kind == KIND_GROUND else kind * 1234.5 + r1 * 5000.0
            f0, f1, f2, f3 = _tex_sample(tex, tex_offsets, tex_size, tex_levels, u * k_fine + off,
                                         v * k_fine + 0.37 * off, foot * k_fine)
            slope = bump[kind]
            if slope > 0.0:
                # micro-relief below the mesh resolution: facet slopes along the texture's (u, v) axes from the
                # "mid" noise channel at this point and at an unrelated one (mip-averaged like the albedo, so
                # the relief smooths out with distance), applied to the shading normal
                h2 = _tex_sample(tex, tex_offsets, tex_size, tex_levels, u * k_fine + off + 517.0,
                                 v * k_fine + 0.37 * off + 211.0, foot * k_fine)[2]
                su = slope * (2.0 * f2 - 1.0)
                sv = slope * (2.0 * h2 - 1.0)
                if a0 >= a1 and a0 >= a2:  # u = y, v = z
                    m0, m1, m2 = n0, n1 - su, n2 - sv
                elif a2 > a0 and a2 > a1:  # u = x, v = y
                    m0, m1, m2 = n0 - su, n1 - sv, n2
                else:  # u = x, v = z
                    m0, m1, m2 = n0 - su, n1, n2 - sv
                lm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2) + 1e-12
                m0, m1, m2 = m0 / lm, m1 / lm, m2 / lm
                if m0 * g0 + m1 * g1 + m2 * g2 > 0.05:  # facets stay on the visible side
                    n0, n1, n2 = m0, m1, m2
                    n_out[i, 0], n_out[i, 1], n_out[i, 2] = n0, n1, n2
            if kind <= KIND_ROCK:
                c0, c1, c2, _ = _tex_sample(tex, tex_offsets, tex_size, tex_levels, ca * u - sa * v + off + 333.0,
                                            sa * u + ca * v + 777.0, foot * k_coarse)
        flat = not textured
        if kind == KIND_GROUND:
            keep = 1.0 - track
            w = r0 * keep
            if w > 1e-4:  # sand and rock
                red = 0.0 if flat else _smoothstep(0.45, 0.75, 0.6 * c0 + 0.4 * f0)
                grav = 0.0 if flat else _smoothstep(0.82, 0.92, f3)
                wb = w * (1.0 if flat else 0.75 + 0.5 * (0.6 * f1 + 0.4 * c1))
                W[i, _SAND_LIGHT] += wb * (1 - red) * (1 - grav)
                W[i, _SAND_RED] += wb * red * (1 - grav)
                W[i, _GRAVEL_DARK] += wb * grav
            w = r1 * keep
            if w > 1e-4:  # grass
                dry = 0.0 if flat else _smoothstep(0.45, 0.75, 0.7 * c0 + 0.3 * f0)
                bare = 0.0 if flat else _smoothstep(0.85, 0.95, f3)
                wb = w * (1.0 if flat else 0.55 + 0.9 * (0.7 * f1 + 0.3 * c1))
                W[i, _GRASS_GREEN] += wb * (1 - dry) * (1 - bare)
                W[i, _GRASS_DRY] += wb * dry * (1 - bare)
                W[i, _SOIL_BROWN] += wb * bare
            w = r2 * keep
            if w > 1e-4:  # woods
                moss = 0.0 if flat else _smoothstep(0.5, 0.8, c0)
                soil = 0.0 if flat else _smoothstep(0.6, 0.8, f0)
                wb = w * (1.0 if flat else 0.6 + 0.8 * (0.7 * f1 + 0.3 * c2))
                W[i, _MOSS] += wb * moss
                W[i, _SOIL_BROWN] += wb * (1 - moss) * soil
                W[i, _LEAF_LITTER] += wb * (1 - moss) * (1 - soil)
            if track > 1e-4:  # dirt track
                gq = 0.0 if flat else _smoothstep(0.6, 0.9, f3)
                wb = track * (1.0 if flat else 0.8 + 0.4 * f1)
                W[i, _SOIL_BROWN] += wb * (1 - gq)
                W[i, _GRAVEL_DARK] += wb * gq
        elif kind == KIND_ROCK:
            red = min(max(tint + (0.0 if flat else 0.3 * (c0 - 0.5)), 0.0), 1.0)
            dark = 0.0 if flat else _smoothstep(0.8, 0.95, f3)
            wb = 1.0 if flat else 0.7 + 0.6 * (0.5 * f1 + 0.5 * f0)
            W[i, _ROCK_GREY] = wb * (1 - red) * (1 - dark)
            W[i, _ROCK_RED] = wb * red * (1 - dark)
            W[i, _ROCK_DARK] = wb * dark
        elif kind == KIND_TRUNK:
            brown = min(max(tint + (0.0 if flat else 0.6 * (f0 - 0.5)), 0.0), 1.0)
            wb = 1.0 if flat else 0.6 + 0.8 * f1
            W[i, _BARK_BROWN] = wb * brown
            W[i, _BARK_GREY] = wb * (1 - brown)
        else:
            yel = 0.0 if flat else _smoothstep(0.5, 0.9, 0.5 * tint + 0.5 * f0)
            wb = 1.0 if flat else 0.5 + 1.0 * f1
            W[i, _LEAF_GREEN] = wb * (1 - yel)
            W[i, _LEAF_YELLOW] = wb * yel
