"""The procedural daylight test scenes DS1 and DS2 (Krawez et al., RA-L 2021, §IV-A, Fig. 6): room and furniture.

Builds the room of :mod:`lightfast.sim.daylight.scene` as a :class:`~lightfast.daylight.mesh.ReflectanceMesh` in
the map frame (metres, z up): floor, ceiling and walls as single inner surfaces, the 0.3 m deep window opening
with its four *reveals*, and a window frame (jambs, rails, a central mullion and a transom; 6–8 cm members) 6 cm
inside the outer wall plane, which casts the sharp shadows the paper uses (Fig. 4).

* :func:`make_ds1` — richly textured and furnished: wooden plank floor, a rug, a table, two chairs, a book shelf
  full of book-like boxes, a sideboard, cardboard boxes, posters/pictures and a calendar, a door, a radiator.
* :func:`make_ds2` — nearly textureless: uniform matte walls, floor and ceiling, a radiator and one plain cabinet.
* :func:`make_ds3` — a sparsely furnished living room drawn from a seed (held-out: never used in development).

Reflectance comes from :mod:`lightfast.sim.daylight.textures`. Every surface is a regular grid of triangles whose
spacing follows the texture: ``resolution_m`` (default 2 cm) on furniture and floor, half of it on posters, 3/4 on
the rug, 1.5× on walls and 2.5× on the ceiling; DS2's plain surfaces use 1.5×. Front faces point into the room (room
shell) or outward (furniture boxes); boxes standing on the floor have no bottom face. Grids that meet along an edge
(a wall and its window reveals) use the same vertex positions there, and the room's walls, floor and ceiling
overlap by 2 cm behind each other, so no ray leaks through a seam. Outside the room there is no geometry.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from lightfast.daylight.mesh import ReflectanceMesh, merge_meshes
from lightfast.daylight.sun import FREIBURG, Site
from lightfast.sim.daylight.scene import RHO_MAX, RHO_MIN, ROOM_SIZE_M, Box, DaylightScene, WindowGeometry
from lightfast.sim.daylight.textures import (
    Texture,
    book_spine,
    checker,
    noisy,
    printed,
    rgb,
    rug,
    stripes,
    uniform,
    wood,
)

__all__ = [
    "make_ds1",
    "make_ds2",
    "make_ds3",
    "make_scene",
]

_WALL_T = 0.30  # wall thickness (m)
_EXT = 0.02  # the room shell overlaps itself by this much behind the corners (m)


# ----------------------------------------------------------------------------------------------------------------
# meshing


def _lines(a: float, b: float, step: float, breaks: Sequence[float] = ()) -> NDArray[np.float64]:
    """Grid positions from ``a`` to ``b``: every segment between consecutive break points divided uniformly into
    pieces no longer than ``step``."""
    pts = sorted({a, b, *[x for x in breaks if a < x < b]})
    out = [np.array([a])]
    for lo, hi in itertools.pairwise(pts):
        n = max(1, math.ceil((hi - lo) / step - 1e-9))
        out.append(np.linspace(lo, hi, n + 1)[1:])
    return np.concatenate(out)


@dataclass
class _Part:
    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]
    rho: NDArray[np.float64]


def _grid(origin: Sequence[float], eu: Sequence[float], ev: Sequence[float], us: NDArray[np.float64],
          vs: NDArray[np.float64], texture: Texture,
          hole: Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.bool_]] | None = None) -> _Part:
    """A grid of triangles over ``origin + u eu + v ev`` (front face towards ``eu × ev``); cells whose centre
    ``hole(u, v)`` marks are left out. Reflectance from ``texture(u, v)``."""
    o, eu_a, ev_a = (np.asarray(x, dtype=np.float64) for x in (origin, eu, ev))
    U, V = np.meshgrid(us, vs, indexing="ij")
    verts = o + U.reshape(-1, 1) * eu_a + V.reshape(-1, 1) * ev_a
    nu, nv = len(us), len(vs)
    i_grid, j_grid = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
    i, j = i_grid.ravel(), j_grid.ravel()
    if hole is not None:
        keep = ~hole(0.5 * (us[i] + us[i + 1]), 0.5 * (vs[j] + vs[j + 1]))
        i, j = i[keep], j[keep]
    a, b, c, d = i * nv + j, (i + 1) * nv + j, (i + 1) * nv + j + 1, i * nv + j + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    used = np.zeros(len(verts), bool)
    used[faces.ravel()] = True
    remap = np.cumsum(used) - 1
    rho = texture(U.ravel()[used], V.ravel()[used])
    return _Part(verts[used], remap[faces], rho)


def _rect(origin: Sequence[float], eu: Sequence[float], ev: Sequence[float], lu: float, lv: float, step: float,
          texture: Texture) -> _Part:
    return _grid(origin, eu, ev, _lines(0.0, lu, step), _lines(0.0, lv, step), texture)


_X, _Y, _Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


def _box(lo: Sequence[float], size: Sequence[float], step: float, textures: Texture | dict[str, Texture], *,
         bottom: bool = True, yaw_deg: float = 0.0) -> list[_Part]:
    """An axis-aligned box (front faces outward) from corner ``lo`` with ``size``, optionally rotated by
    ``yaw_deg`` about the vertical axis through its centre. ``textures``: one for all faces or per face name
    (``top bottom px nx py ny``; missing names use ``"side"`` then ``"top"``)."""
    x0, y0, z0 = lo
    sx, sy, sz = size
    x1, y1, z1 = x0 + sx, y0 + sy, z0 + sz

    def tex(name: str) -> Texture:
        if callable(textures):
            return textures
        return textures.get(name) or textures.get("side") or textures["top"]

    specs = [
        ("top", (x0, y0, z1), _X, _Y, sx, sy),
        ("px", (x1, y0, z0), _Y, _Z, sy, sz),
        ("nx", (x0, y0, z0), _Z, _Y, sz, sy),
        ("py", (x0, y1, z0), _Z, _X, sz, sx),
        ("ny", (x0, y0, z0), _X, _Z, sx, sz),
    ]
    if bottom:
        specs.append(("bottom", (x0, y0, z0), _Y, _X, sy, sx))
    parts = [_rect(o, eu, ev, lu, lv, step, tex(name)) for name, o, eu, ev, lu, lv in specs]
    if yaw_deg:
        c = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
        t = math.radians(yaw_deg)
        R = np.array([[math.cos(t), -math.sin(t), 0], [math.sin(t), math.cos(t), 0], [0, 0, 1]])
        for p in parts:
            p.vertices = (p.vertices - c) @ R.T + c
    return parts


def _finish(parts: list[_Part]) -> ReflectanceMesh:
    meshes = [ReflectanceMesh(p.vertices, p.faces, np.clip(p.rho, RHO_MIN, RHO_MAX)) for p in parts]
    return merge_meshes(meshes)


# ----------------------------------------------------------------------------------------------------------------
# the room shell with its window


@dataclass(frozen=True)
class _WindowSpec:
    x0: float = 1.4
    x1: float = 3.1
    z0: float = 0.85
    z1: float = 2.35
    frame_w: float = 0.065  # frame member width (m)
    frame_d: float = 0.07  # frame depth (m)
    outer_offset: float = 0.06  # outer face of the frame inside the outer wall plane (m)
    transom_z: float = 1.95


def _room_shell(step: float, *, wall_tex: Texture, floor_tex: Texture, ceiling_tex: Texture,
                wall_step: float, ceiling_step: float, win: _WindowSpec,
                frame_tex: Texture) -> tuple[list[_Part], WindowGeometry]:
    W, D, H = ROOM_SIZE_M
    e, T = _EXT, _WALL_T
    parts = [
        _rect((-e, -e, 0.0), _X, _Y, W + 2 * e, D + 2 * e, step, floor_tex),  # floor, normal +z
        _rect((-e, -e, H), _Y, _X, D + 2 * e, W + 2 * e, ceiling_step, ceiling_tex),  # ceiling, normal -z
        _rect((-e, D, -e), _X, _Z, W + 2 * e, H + 2 * e, wall_step, wall_tex),  # north wall, normal -y
        _rect((0.0, -e, -e), _Y, _Z, D + 2 * e, H + 2 * e, wall_step, wall_tex),  # west wall, normal +x
        _rect((W, -e, -e), _Z, _Y, H + 2 * e, D + 2 * e, wall_step, wall_tex),  # east wall, normal -x
    ]
    # south wall y = 0 (normal +y = eu × ev with eu = z, ev = x) with the window hole; its grid lines meet the
    # window edges exactly so that the reveals share the edge vertices
    zs = _lines(-e, H + e, wall_step, (win.z0, win.z1))
    xs = _lines(-e, W + e, wall_step, (win.x0, win.x1))
    # inside the opening use the reveal spacing so the seams coincide
    rz = _lines(win.z0, win.z1, step)
    rx = _lines(win.x0, win.x1, step)
    zs = np.unique(np.concatenate([zs[(zs <= win.z0) | (zs >= win.z1)], rz]))
    xs = np.unique(np.concatenate([xs[(xs <= win.x0) | (xs >= win.x1)], rx]))

    def in_hole(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.bool_]:
        return (u > win.z0) & (u < win.z1) & (v > win.x0) & (v < win.x1)

    parts.append(_grid((0.0, 0.0, 0.0), _Z, _X, zs, xs, lambda u, v: wall_tex(v, u), hole=in_hole))
    # reveals, y from -T (outside) to 0 (room), normals into the opening
    ys = _lines(-T, 0.0, step)
    reveal_tex = wall_tex
    parts += [
        _grid((0.0, 0.0, win.z0), _X, _Y, rx, ys, reveal_tex),  # sill, +z
        _grid((0.0, 0.0, win.z1), _Y, _X, ys, rx, reveal_tex),  # lintel, -z
        _grid((win.x0, 0.0, 0.0), _Y, _Z, ys, rz, reveal_tex),  # left jamb, +x
        _grid((win.x1, 0.0, 0.0), _Z, _Y, rz, ys, reveal_tex),  # right jamb, -x
    ]
    # the window frame: members embedded 5 mm into the reveals
    fy0 = -T + win.outer_offset
    fw, fd, emb = win.frame_w, win.frame_d, 0.005
    fstep = step
    xm = 0.5 * (win.x0 + win.x1)
    members = [
        ((win.x0 - emb, fy0, win.z0 - emb), (fw + emb, fd, win.z1 - win.z0 + 2 * emb)),  # left
        ((win.x1 - fw, fy0, win.z0 - emb), (fw + emb, fd, win.z1 - win.z0 + 2 * emb)),  # right
        ((win.x0, fy0, win.z0 - emb), (win.x1 - win.x0, fd, fw + emb)),  # bottom rail
        ((win.x0, fy0, win.z1 - fw), (win.x1 - win.x0, fd, fw + emb)),  # top rail
        ((xm - 0.04, fy0 - 0.005, win.z0 + fw - 0.002), (0.08, fd + 0.01, win.z1 - win.z0 - 2 * fw + 0.004)),
        ((win.x0 + fw - 0.002, fy0 - 0.003, win.transom_z - 0.03), (win.x1 - win.x0 - 2 * fw + 0.004, fd + 0.006,
                                                                     0.06)),  # transom
    ]
    for lo, size in members:
        parts += _box(lo, size, fstep, frame_tex)
    window = WindowGeometry(
        center_m=(xm, -T, 0.5 * (win.z0 + win.z1)),
        normal=(0.0, -1.0, 0.0),
        axis_u=(-1.0, 0.0, 0.0),
        axis_v=(0.0, 0.0, 1.0),
        half_u_m=0.5 * (win.x1 - win.x0),
        half_v_m=0.5 * (win.z1 - win.z0),
        wall_thickness_m=T,
        glass_depth_m=win.outer_offset + 0.5 * fd,
    )
    return parts, window


def _radiator(step: float, x0: float, width: float, plain: bool) -> list[_Part]:
    col = (0.78, 0.78, 0.76)
    tex = uniform(col) if plain else stripes([col, (0.45, 0.45, 0.45)], 0.025, along_v=False)
    side = {"top": uniform(col), "ny": uniform(col),
            "py": stripes([col, (0.42, 0.42, 0.42)], 0.025, along_v=True) if not plain else tex}
    return _box((x0, 0.04, 0.15), (width, 0.1, 0.6), step, side if not plain else tex)


# ----------------------------------------------------------------------------------------------------------------
# scenes


def make_ds1(*, resolution_m: float = 0.02, site: Site = FREIBURG, seed: int = 1) -> DaylightScene:
    """The richly textured, furnished scene DS1 (see the module docstring)."""
    r = float(resolution_m)
    rng = np.random.default_rng(seed)
    W, D, _ = ROOM_SIZE_M
    win = _WindowSpec()
    wall_tex = noisy((0.74, 0.71, 0.64), 0.06, 0.25, seed + 1)
    floor_tex = wood((0.55, 0.36, 0.2), plank_m=0.18, seed=seed + 2)
    parts, window = _room_shell(
        r, wall_tex=wall_tex, floor_tex=floor_tex, ceiling_tex=uniform((0.8, 0.8, 0.78)),
        wall_step=1.5 * r, ceiling_step=2.5 * r, win=win, frame_tex=uniform((0.72, 0.72, 0.7)))
    obstacles: list[Box] = []
    fine = 0.5 * r

    def add_box(lo: Sequence[float], size: Sequence[float], tex: Texture | dict[str, Texture], *,
                step: float = r, bottom: bool = True, yaw: float = 0.0, obstacle: bool = True) -> None:
        parts.extend(_box(lo, size, step, tex, bottom=bottom, yaw_deg=yaw))
        if obstacle:
            obstacles.append(Box(cast(tuple[float, float, float], tuple(lo)),
                                 cast(tuple[float, float, float], tuple(np.add(lo, size)))))

    # radiator under the window
    parts.extend(_radiator(r, win.x0 + 0.1, win.x1 - win.x0 - 0.2, plain=False))
    # rug in the sunlit middle of the room
    rw, rh = 2.0, 1.4
    parts.extend(_box((1.2, 1.3, 0.0), (rw, rh, 0.008), 0.75 * r, {"top": rug(rw, rh, seed + 3),
                                                                "side": uniform((0.4, 0.1, 0.08))}, bottom=False))
    # table with a wooden top, near the window so that the sun reaches it
    tx, ty, tw, td, th = 1.55, 1.0, 1.4, 0.8, 0.75
    table_wood = wood((0.62, 0.42, 0.24), plank_m=None, seed=seed + 4)
    add_box((tx, ty, th - 0.04), (tw, td, 0.04), {"top": table_wood, "bottom": uniform((0.4, 0.27, 0.16)),
                                                  "side": uniform((0.45, 0.3, 0.17))}, obstacle=False)
    for lx, ly in ((tx + 0.03, ty + 0.03), (tx + tw - 0.08, ty + 0.03), (tx + 0.03, ty + td - 0.08),
                   (tx + tw - 0.08, ty + td - 0.08)):
        add_box((lx, ly, 0.0), (0.05, 0.05, th - 0.03), uniform((0.35, 0.23, 0.13)), bottom=False, obstacle=False)
    obstacles.append(Box((tx, ty, 0.0), (tx + tw, ty + td, th)))
    # things on the table: a book stack and a box
    add_box((tx + 0.2, ty + 0.2, th), (0.3, 0.22, 0.05), {"top": printed(0.3, 0.22, seed + 5),
                                                           "side": stripes([(0.8, 0.78, 0.7), (0.6, 0.58, 0.5)],
                                                                           0.006, along_v=True)},
            step=fine, bottom=False, obstacle=False)
    add_box((tx + 0.9, ty + 0.35, th), (0.25, 0.2, 0.15), {"top": checker((0.8, 0.8, 0.78), (0.1, 0.1, 0.1), 0.025),
                                                            "side": uniform((0.7, 0.2, 0.1))},
            step=fine, bottom=False, obstacle=False)
    # two chairs
    for cx, cy, yaw, col in ((1.9, 1.95, 8.0, (0.6, 0.12, 0.1)), (2.55, 0.55, 185.0, (0.12, 0.25, 0.55))):
        seat = noisy(col, 0.25, 0.03, seed + 6)
        chair: list[_Part] = []
        chair += _box((cx, cy, 0.43), (0.42, 0.42, 0.04), r, {"top": seat, "side": uniform(col)})
        for lx, ly in ((0, 0), (0.38, 0), (0, 0.38), (0.38, 0.38)):
            chair += _box((cx + lx, cy + ly, 0.0), (0.04, 0.04, 0.44), r, uniform((0.2, 0.2, 0.2)), bottom=False)
        chair += _box((cx, cy + 0.39, 0.47), (0.42, 0.03, 0.45), r, {"ny": seat, "side": uniform(col)})
        c = np.array([cx + 0.21, cy + 0.21, 0.0])
        t = math.radians(yaw)
        R = np.array([[math.cos(t), -math.sin(t), 0], [math.sin(t), math.cos(t), 0], [0, 0, 1]])
        for p in chair:
            p.vertices = (p.vertices - c) @ R.T + c
        parts.extend(chair)
        obstacles.append(Box((cx - 0.1, cy - 0.1, 0.0), (cx + 0.52, cy + 0.52, 0.92)))
    # book shelf against the east wall
    sx0, sy0, sw, sd, sh = W - 0.36, 1.4, 0.35, 1.2, 1.9
    shelf_wood = wood((0.5, 0.34, 0.2), plank_m=None, seed=seed + 8, along_v=True)
    add_box((sx0, sy0, 0.0), (sw, 0.02, sh), shelf_wood, bottom=False, obstacle=False)
    add_box((sx0, sy0 + sd - 0.02, 0.0), (sw, 0.02, sh), shelf_wood, bottom=False, obstacle=False)
    add_box((sx0 + sw - 0.01, sy0 + 0.02, 0.0), (0.01, sd - 0.04, sh), uniform((0.4, 0.28, 0.17)), bottom=False,
            obstacle=False)
    levels = [0.05, 0.45, 0.85, 1.25, 1.65, sh - 0.02]
    for zl in levels:
        add_box((sx0, sy0 + 0.02, zl), (sw - 0.01, sd - 0.04, 0.02), shelf_wood, obstacle=False)
    obstacles.append(Box((sx0, sy0, 0.0), (W, sy0 + sd, sh)))
    palette = np.array([[0.55, 0.1, 0.08], [0.1, 0.2, 0.45], [0.15, 0.4, 0.18], [0.75, 0.6, 0.15],
                        [0.2, 0.2, 0.22], [0.8, 0.78, 0.7], [0.45, 0.15, 0.4], [0.1, 0.45, 0.5]])
    for zl in levels[:-1]:
        y = sy0 + 0.03
        while y < sy0 + sd - 0.1:
            bw = rng.uniform(0.02, 0.06)
            bh = rng.uniform(0.18, 0.33)
            bd = rng.uniform(0.15, 0.24)
            if rng.random() < 0.1:  # a gap
                y += bw * 2
                continue
            col = palette[rng.integers(len(palette))] * rng.uniform(0.8, 1.15)
            bh = min(bh, 0.37)
            spine = book_spine(col, bh, int(rng.integers(1 << 30)))
            add_box((sx0 + sw - 0.01 - bd, y, zl + 0.02), (bd, bw, bh),
                    {"nx": spine, "side": uniform(col), "top": uniform((0.85, 0.83, 0.75))},
                    step=r, bottom=False, obstacle=False)
            y += bw + 0.002
    # sideboard against the north wall with drawer fronts
    bx0, bw_, bd_, bh_ = 0.5, 1.6, 0.45, 0.8

    def drawers(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        out = wood((0.3, 0.2, 0.12), plank_m=None, seed=seed + 9)(u, v)
        edge = (np.abs((u % 0.4) - 0.0) < 0.006) | (np.abs((v % 0.27) - 0.0) < 0.006)
        knob = ((u % 0.4) - 0.2) ** 2 + ((v % 0.27) - 0.2) ** 2 < 0.012**2
        out[edge] *= 0.3
        out[knob] = (0.85, 0.8, 0.6)
        return out

    add_box((bx0, D - bd_ - 0.005, 0.0), (bw_, bd_, bh_), {"ny": drawers, "top": wood((0.35, 0.23, 0.14), plank_m=None,
                                                                              seed=seed + 10),
                                                   "side": uniform((0.3, 0.2, 0.12))}, bottom=False)
    # a vase-like box and a picture frame on the sideboard
    add_box((bx0 + 0.3, D - 0.3, bh_), (0.14, 0.14, 0.3), stripes([(0.1, 0.3, 0.6), (0.85, 0.85, 0.8)], 0.03,
                                                                  along_v=True),
            step=fine, bottom=False, obstacle=False)
    # pictures and posters (thin boxes 1.5 cm in front of the walls)
    posters = [
        # (lo, size, the face that looks into the room, style); 2 mm off the wall
        ((0.002, 1.0, 1.1), (0.015, 0.6, 0.85), "px", "poster"),
        ((0.002, 2.3, 1.2), (0.015, 0.9, 0.65), "px", "poster"),
        ((0.002, 3.6, 1.3), (0.015, 0.45, 0.6), "px", "calendar"),
        ((bx0 + 0.2, D - 0.017, 1.25), (1.2, 0.015, 0.8), "ny", "poster"),
        ((0.35, 0.002, 1.2), (0.5, 0.015, 0.7), "py", "calendar"),
        ((3.6, 0.002, 1.3), (0.6, 0.015, 0.6), "py", "poster"),
    ]
    for k, (lo, size, face, style) in enumerate(posters):
        wdt = size[1] if face == "px" else size[0]
        tex = printed(wdt, size[2], seed + 20 + k, style=style)
        # face grids: px (u, v) = (y right, z up); ny (x right, z up); py (z up, x to the viewer's left)
        face_tex = tex if face != "py" else (lambda t, w: (lambda u, v: t(w - v, u)))(tex, wdt)
        add_box(lo, size, {face: face_tex, "side": uniform((0.15, 0.12, 0.1))}, step=fine, obstacle=False)
    # a door in the north-east corner (a slightly proud panel)

    def door(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:  # u up, v along
        out = rgb((0.82, 0.8, 0.74), len(u))
        for (a0, a1, b0, b1) in ((0.15, 0.9, 0.12, 0.78), (1.1, 1.9, 0.12, 0.78)):
            edge = (((np.abs(u - a0) < 0.012) | (np.abs(u - a1) < 0.012)) & (v > b0) & (v < b1)) | (
                ((np.abs(v - b0) < 0.012) | (np.abs(v - b1) < 0.012)) & (u > a0) & (u < a1))
            out[edge] = (0.55, 0.54, 0.5)
        handle = (np.abs(u - 1.05) < 0.02) & (v > 0.72) & (v < 0.85)
        out[handle] = (0.2, 0.2, 0.2)
        return out

    add_box((2.7, D - 0.014, 0.0), (0.9, 0.012, 2.02), {"ny": lambda u, v: door(v, u),
                                                        "side": uniform((0.7, 0.7, 0.66))},
            bottom=False, obstacle=False)
    # cardboard boxes in the south-east corner
    for (lo, size, yaw) in (((3.5, 0.5, 0.0), (0.45, 0.35, 0.35), 12.0), ((3.55, 0.55, 0.35), (0.3, 0.25, 0.22),
                                                                          -20.0)):
        cardboard = noisy((0.62, 0.45, 0.27), 0.15, 0.05, seed + 30)

        def box_tex(u: NDArray[np.float64], v: NDArray[np.float64], _c: Texture = cardboard) -> NDArray[np.float64]:
            out = _c(u, v)
            out[np.abs(u - float(np.median(u))) < 0.025] = (0.75, 0.68, 0.5)
            return out

        add_box(lo, size, box_tex, step=r, bottom=False, yaw=yaw)
    mesh = _finish(parts)
    return DaylightScene("DS1", mesh, window, ROOM_SIZE_M, site, tuple(obstacles), r)


def make_ds2(*, resolution_m: float = 0.02, site: Site = FREIBURG, seed: int = 2) -> DaylightScene:
    """The nearly textureless, almost empty scene DS2 (see the module docstring)."""
    r = float(resolution_m)
    win = _WindowSpec()
    parts, window = _room_shell(
        1.5 * r, wall_tex=uniform((0.76, 0.75, 0.71)), floor_tex=uniform((0.42, 0.41, 0.38)),
        ceiling_tex=uniform((0.8, 0.8, 0.78)), wall_step=1.5 * r, ceiling_step=2.5 * r, win=win,
        frame_tex=uniform((0.72, 0.72, 0.7)))
    parts.extend(_radiator(1.5 * r, win.x0 + 0.1, win.x1 - win.x0 - 0.2, plain=True))
    lo, size = (ROOM_SIZE_M[0] - 0.5, 3.2, 0.0), (0.45, 0.9, 0.75)
    parts.extend(_box(lo, size, 1.5 * r, uniform((0.7, 0.69, 0.66)), bottom=False))
    mesh = _finish(parts)
    return DaylightScene("DS2", mesh, window, ROOM_SIZE_M, site, (Box(lo, tuple(np.add(lo, size))),), r)


def make_ds3(*, resolution_m: float = 0.02, site: Site = FREIBURG, seed: int = 3) -> DaylightScene:
    """A sparsely furnished living room, never used in development (the held-out room of issue 21): matte painted
    walls with faint roller marks, a floor of large pale tiles, a low sofa against the west wall with a picture
    above it, a plain coffee table and a wardrobe against the east wall; colours, sizes and places are drawn from
    ``seed``. In texture and geometry it lies between DS1 and DS2."""
    r = float(resolution_m)
    rng = np.random.default_rng(seed)
    W = ROOM_SIZE_M[0]
    win = _WindowSpec()
    paint = tuple(float(c) for c in rng.uniform(0.66, 0.8) * np.array([1.0, rng.uniform(0.95, 1.0),
                                                                            rng.uniform(0.86, 0.97)]))
    tile = float(rng.choice([0.45, 0.6]))
    tile_col = tuple(float(c) for c in rng.uniform(0.5, 0.62) * np.array([1.0, 0.97, 0.92]))
    tiles_noise = noisy(tile_col, 0.04, 0.2, seed + 2)

    def tiles(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        out = tiles_noise(u, v)
        grout = (np.abs((u + 0.5 * tile) % tile - 0.5 * tile) < 0.004) | (np.abs((v + 0.5 * tile) % tile - 0.5 * tile)
                                                                           < 0.004)
        out[grout] *= 0.6
        return out

    parts, window = _room_shell(
        r, wall_tex=noisy(paint, 0.035, 0.4, seed + 1), floor_tex=tiles, ceiling_tex=uniform((0.8, 0.8, 0.78)),
        wall_step=1.5 * r, ceiling_step=2.5 * r, win=win, frame_tex=uniform((0.74, 0.74, 0.72)))
    parts.extend(_radiator(1.5 * r, win.x0 + 0.1, win.x1 - win.x0 - 0.2, plain=True))
    obstacles: list[Box] = []

    def add_box(lo: Sequence[float], size: Sequence[float], tex: Texture | dict[str, Texture], *,
                obstacle: bool = True) -> None:
        parts.extend(_box(lo, size, r, tex, bottom=False))
        if obstacle:
            obstacles.append(Box(cast(tuple[float, float, float], tuple(lo)),
                                 cast(tuple[float, float, float], tuple(np.add(lo, size)))))

    # sofa against the west wall: seat block, back, two arms, in one fabric
    fabric_col = tuple(float(c) for c in rng.uniform(0.15, 0.55, 3))
    fabric = noisy(fabric_col, 0.12, 0.02, seed + 3)
    sy, sl = float(rng.uniform(1.3, 2.1)), float(rng.uniform(1.7, 2.1))
    add_box((0.22, sy + 0.15, 0.0), (0.68, sl - 0.3, 0.42), fabric, obstacle=False)
    add_box((0.005, sy, 0.0), (0.22, sl, 0.82), fabric, obstacle=False)
    add_box((0.22, sy, 0.0), (0.7, 0.15, 0.6), fabric, obstacle=False)
    add_box((0.22, sy + sl - 0.15, 0.0), (0.7, 0.15, 0.6), fabric, obstacle=False)
    obstacles.append(Box((0.0, sy, 0.0), (0.92, sy + sl, 0.82)))
    # a picture above it, 2 mm off the wall
    pw, ph = float(rng.uniform(0.6, 1.0)), float(rng.uniform(0.45, 0.7))
    add_box((0.002, sy + 0.5 * (sl - pw), 1.2), (0.015, pw, ph),
            {"px": printed(pw, ph, seed + 4), "side": uniform((0.15, 0.12, 0.1))}, obstacle=False)
    # a plain coffee table in front of the sofa
    tx, ty = float(rng.uniform(1.25, 1.6)), sy + 0.5 * sl - 0.45
    table_col = tuple(float(c) for c in rng.uniform(0.25, 0.75) * np.array([1.0, 0.9, 0.8]))
    add_box((tx, ty, 0.0), (0.55, 0.9, 0.42), uniform(table_col))
    # a wardrobe against the east wall: plain doors with one seam
    wy, ww = float(rng.uniform(1.9, 3.3)), float(rng.uniform(1.0, 1.4))
    ward_col = tuple(float(c) for c in rng.uniform(0.55, 0.85) * np.array([1.0, 0.97, 0.93]))

    def doors(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        out = rgb(ward_col, len(u))
        out[np.abs(v - 0.5 * ww) < 0.004] *= 0.5  # nx face: u up, v along y
        return out

    add_box((W - 0.6, wy, 0.0), (0.595, ww, 2.05), {"nx": doors, "side": uniform(ward_col)})
    mesh = _finish(parts)
    return DaylightScene("DS3", mesh, window, ROOM_SIZE_M, site, tuple(obstacles), r)


def make_scene(name: str, *, resolution_m: float = 0.02, site: Site = FREIBURG) -> DaylightScene:
    """``"DS1"``, ``"DS2"`` or ``"DS3"`` (the held-out room)."""
    makers = {"DS1": make_ds1, "DS2": make_ds2, "DS3": make_ds3}
    if name not in makers:
        raise ValueError(f"unknown scene {name!r}; choose one of {sorted(makers)}")
    return makers[name](resolution_m=resolution_m, site=site)
