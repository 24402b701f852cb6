"""Synthetic rooms for validating the daylight radiosity against a reference renderer, and surface sampling.

Conventions: metres; z is up; the floor is at ``z = 0`` and the room's interior is the box
``[0, X] × [0, Y] × [0, Z]`` with walls aligned to the x/y axes. The walls are named by the map frame of
:mod:`lightfast.daylight.mesh` (x east, y north): ``"south"`` is the wall ``y = 0``, ``"north"`` ``y = Y``,
``"west"`` ``x = 0``, ``"east"`` ``x = X`` (``"-y"``, ``"+y"``, ``"-x"``, ``"+x"`` are accepted as well).

Every planar part is a separate, internally welded grid of right triangles whose longest edge (the diagonal) is at
most ``tessellation_m``; parts are not welded to each other, so vertices on a crease keep the normal of their own
plane. All front faces (counter-clockwise) face the room's air: room surfaces face inwards, furniture outwards.
The room is closed except for the window opening; the wall has a thickness, so the opening has four reveals (sill,
head, two jambs) that end at the outer wall plane. There is no outside geometry (no outer wall face, no ground):
outside the opening there is only the light model's sky and ground sphere.

Reflectances are linear RGB diffuse albedo in [0, 1].
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.daylight.mesh import ReflectanceMesh, merge_meshes
from lightfast.raycast import RayCaster
from lightfast.sim.errors import ValidationRoomError

RGB = tuple[float, float, float]
Window = tuple[float, float, float, str]  # (width, height, sill height, wall)

DEFAULT_SIZE_M: tuple[float, float, float] = (4.5, 4.8, 2.9)
DEFAULT_WINDOW: Window = (1.6, 1.5, 0.8, "south")
FLOOR_RHO: RGB = (0.32, 0.26, 0.20)
WALL_RHO: RGB = (0.62, 0.60, 0.55)
CEILING_RHO: RGB = (0.80, 0.80, 0.77)
FRAME_RHO: RGB = (0.75, 0.75, 0.72)
TABLE_RHO: RGB = (0.45, 0.32, 0.22)
BOX_RHO: RGB = (0.25, 0.35, 0.55)
SHELF_RHO: RGB = (0.55, 0.50, 0.42)

_Z = np.array([0.0, 0.0, 1.0])
# wall name -> (corner, along-wall axis a, inward normal d) with a × d = +z; the corner is in units of (X, Y)
_WALLS: dict[str, tuple[tuple[float, float], tuple[float, float, float], tuple[float, float, float]]] = {
    "south": ((0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    "east": ((1.0, 0.0), (0.0, 1.0, 0.0), (-1.0, 0.0, 0.0)),
    "north": ((1.0, 1.0), (-1.0, 0.0, 0.0), (0.0, -1.0, 0.0)),
    "west": ((0.0, 1.0), (0.0, -1.0, 0.0), (1.0, 0.0, 0.0)),
}
_ALIASES = {"-y": "south", "+y": "north", "-x": "west", "+x": "east", "y-": "south", "y+": "north", "x-": "west",
            "x+": "east"}


class _WallFrame:
    """A wall's local frame: ``a`` along the wall (length ``length``), ``d`` into the room (depth ``depth``), z up;
    ``a × d = z`` so layouts in (a, d) are never mirrored."""

    def __init__(self, name: str, size: tuple[float, float, float]) -> None:
        key = _ALIASES.get(name.strip().lower(), name.strip().lower())
        if key not in _WALLS:
            raise ValidationRoomError(f"unknown wall {name!r}: use one of {sorted(_WALLS)} or ±x/±y")
        corner, a, d = _WALLS[key]
        X, Y, _ = size
        self.name = key
        self.corner = np.array([corner[0] * X, corner[1] * Y, 0.0])
        self.a = np.array(a)
        self.d = np.array(d)
        self.length = X if abs(a[0]) > 0 else Y
        self.depth = Y if abs(a[0]) > 0 else X

    def to_world(self, a: float, d: float, z: float) -> NDArray[np.float64]:
        return self.corner + a * self.a + d * self.d + z * _Z


def _subdivide(breaks: Sequence[float], step: float) -> NDArray[np.float64]:
    """Sorted unique breakpoints, each interval split into equal parts no longer than ``step``."""
    b = np.unique(np.round(np.asarray(breaks, dtype=np.float64), 9))
    out = [b[:1]]
    for lo, hi in itertools.pairwise(b):
        k = max(1, math.ceil((hi - lo) / step - 1e-9))
        out.append(np.linspace(lo, hi, k + 1)[1:])
    return np.concatenate(out)


def _rect(origin: ArrayLike, eu: ArrayLike, ev: ArrayLike, extent_u: float, extent_v: float, rho: ArrayLike,
          tessellation_m: float, holes: Sequence[tuple[float, float, float, float]] = ()) -> ReflectanceMesh:
    """A planar rectangle ``origin + u·eu + v·ev`` (``u ∈ [0, extent_u]``, ``v ∈ [0, extent_v]``) with rectangular
    holes ``(u0, u1, v0, v1)``, front face towards ``eu × ev``. Cells are at most ``tessellation_m/√2`` on a side,
    so no triangle edge exceeds ``tessellation_m``."""
    o, eu, ev = (np.asarray(x, dtype=np.float64) for x in (origin, eu, ev))
    step = tessellation_m / math.sqrt(2.0)
    us = _subdivide([0.0, extent_u, *[h[0] for h in holes], *[h[1] for h in holes]], step)
    vs = _subdivide([0.0, extent_v, *[h[2] for h in holes], *[h[3] for h in holes]], step)
    uc, vc = 0.5 * (us[:-1] + us[1:]), 0.5 * (vs[:-1] + vs[1:])
    keep = np.ones((len(uc), len(vc)), dtype=bool)
    for u0, u1, v0, v1 in holes:
        keep &= ~(((uc > u0) & (uc < u1))[:, None] & ((vc > v0) & (vc < v1))[None, :])
    iu, iv = np.nonzero(keep)
    nv = len(vs)
    a = iu * nv + iv
    b = (iu + 1) * nv + iv
    c = (iu + 1) * nv + iv + 1
    d = iu * nv + iv + 1
    faces = np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])
    used, faces = np.unique(faces, return_inverse=True)
    faces = faces.reshape(-1, 3)
    gu, gv = np.meshgrid(us, vs, indexing="ij")
    grid = o + gu.reshape(-1, 1) * eu + gv.reshape(-1, 1) * ev
    verts = grid[used]
    refl = np.broadcast_to(np.asarray(rho, dtype=np.float64), verts.shape).copy()
    return ReflectanceMesh(verts, faces, refl)


def _box(lo: ArrayLike, hi: ArrayLike, rho: ArrayLike, tessellation_m: float,
         omit: Sequence[ArrayLike] = ()) -> list[ReflectanceMesh]:
    """An axis-aligned box with outward front faces; faces whose outward normal is in ``omit`` (unit axis vectors,
    e.g. the side resting on the floor) are left out."""
    lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
    size = hi - lo
    omitted = {tuple(np.round(np.asarray(o, dtype=np.float64), 6)) for o in omit}
    parts = []
    for axis in range(3):
        i, j = (axis + 1) % 3, (axis + 2) % 3  # e_i × e_j = e_axis
        ei, ej = np.eye(3)[i], np.eye(3)[j]
        for sign in (-1.0, 1.0):
            normal = sign * np.eye(3)[axis]
            if tuple(np.round(normal, 6)) in omitted:
                continue
            origin = lo.copy()
            if sign > 0:
                origin[axis] = hi[axis]
                parts.append(_rect(origin, ei, ej, size[i], size[j], rho, tessellation_m))
            else:
                parts.append(_rect(origin, ej, ei, size[j], size[i], rho, tessellation_m))
    return parts


def _check_sizes(size_m: Sequence[float], window: Window, wall_thickness_m: float, tessellation_m: float) -> None:
    if len(size_m) != 3 or min(size_m) <= 0:
        raise ValidationRoomError(f"size_m must be three positive lengths, got {size_m!r}")
    if wall_thickness_m <= 0 or tessellation_m <= 0:
        raise ValidationRoomError("wall_thickness_m and tessellation_m must be positive")
    if len(window) != 4:
        raise ValidationRoomError(f"window must be (width, height, sill height, wall), got {window!r}")


def _room_shell(size_m: Sequence[float], window: Window, wall_thickness_m: float, floor_rho: ArrayLike,
                wall_rho: ArrayLike, ceiling_rho: ArrayLike, tessellation_m: float
                ) -> tuple[list[ReflectanceMesh], _WallFrame, tuple[float, float, float, float]]:
    _check_sizes(size_m, window, wall_thickness_m, tessellation_m)
    X, Y, Z = (float(s) for s in size_m)
    width, height, sill, wall_name = float(window[0]), float(window[1]), float(window[2]), str(window[3])
    win_wall = _WallFrame(wall_name, (X, Y, Z))
    if width <= 0 or height <= 0 or sill <= 0 or width >= win_wall.length or sill + height >= Z:
        raise ValidationRoomError(
            f"window {window!r} must have positive size and sill and fit inside its {win_wall.length:g} × {Z:g} m "
            "wall with some wall around it"
        )
    t = tessellation_m
    parts = [
        _rect((0.0, 0.0, 0.0), (1, 0, 0), (0, 1, 0), X, Y, floor_rho, t),  # floor, normal +z
        _rect((0.0, 0.0, Z), (0, 1, 0), (1, 0, 0), Y, X, ceiling_rho, t),  # ceiling, normal -z
    ]
    a0 = 0.5 * (win_wall.length - width)
    opening = (a0, a0 + width, sill, sill + height)  # in the window wall's (a, z)
    for name in _WALLS:
        w = _WallFrame(name, (X, Y, Z))
        # rectangle u along -a from the wall's far end, v = z: (-a) × z = d (inward)
        origin = w.to_world(w.length, 0.0, 0.0)
        holes = []
        if name == win_wall.name:
            holes = [(w.length - opening[1], w.length - opening[0], opening[2], opening[3])]
        parts.append(_rect(origin, -w.a, _Z, w.length, Z, wall_rho, t, holes))
    # reveals: the opening's sides, from the inner wall plane outwards (-d) through the wall thickness
    w, th = win_wall, wall_thickness_m
    out = -w.d
    a_lo, a_hi, z_lo, z_hi = opening
    parts += [
        _rect(w.to_world(a_lo, 0, z_lo), out, w.a, th, width, wall_rho, t),  # sill: (-d) × a = +z
        _rect(w.to_world(a_lo, 0, z_hi), w.a, out, width, th, wall_rho, t),  # head: a × (-d) = -z
        _rect(w.to_world(a_lo, 0, z_lo), _Z, out, height, th, wall_rho, t),  # jamb at a_lo: z × (-d) = +a
        _rect(w.to_world(a_hi, 0, z_lo), out, _Z, th, height, wall_rho, t),  # jamb at a_hi: (-d) × z = -a
    ]
    return parts, win_wall, opening


def box_room_with_window(
    *,
    size_m: tuple[float, float, float] = DEFAULT_SIZE_M,
    window: Window = DEFAULT_WINDOW,
    wall_thickness_m: float = 0.2,
    floor_reflectance: RGB = FLOOR_RHO,
    wall_reflectance: RGB = WALL_RHO,
    ceiling_reflectance: RGB = CEILING_RHO,
    tessellation_m: float = 0.1,
) -> ReflectanceMesh:
    """An empty box room ``[0, X] × [0, Y] × [0, Z]`` (``size_m``) with one window opening.

    ``window = (width, height, sill height, wall)``: the opening is centred along its wall, ``sill height`` above
    the floor; ``wall`` is ``"south" | "north" | "east" | "west"`` (or ``"-y" | "+y" | "+x" | "-x"``). The reveals
    share the wall reflectance. No triangle edge is longer than ``tessellation_m``.
    """
    parts, _, _ = _room_shell(tuple(size_m), window, wall_thickness_m, floor_reflectance, wall_reflectance,
                              ceiling_reflectance, tessellation_m)
    return merge_meshes(parts)


def furnished_room(
    *,
    size_m: tuple[float, float, float] = DEFAULT_SIZE_M,
    window: Window = DEFAULT_WINDOW,
    wall_thickness_m: float = 0.2,
    mullion_width_m: float = 0.07,
    floor_reflectance: RGB = FLOOR_RHO,
    wall_reflectance: RGB = WALL_RHO,
    ceiling_reflectance: RGB = CEILING_RHO,
    frame_reflectance: RGB = FRAME_RHO,
    tessellation_m: float = 0.1,
) -> ReflectanceMesh:
    """:func:`box_room_with_window` plus a window cross and furniture that cast sharp shadows.

    * Window cross: a vertical mullion and a horizontal transom (square section ``mullion_width_m``) through the
      centre of the opening, halfway through the wall; the transom is two pieces that end at the mullion.
    * A table (1.2 × 0.8 m, top at 0.72–0.76 m, four 5 cm legs) 1.2 m into the room, centred on the window, so the
      sun through the window shades the floor under it.
    * A 0.5 m cube on the floor, beside the window axis, 2.6 m into the room.
    * A 1.2 × 0.4 × 1.8 m shelf block against the wall opposite the window.
    * A 1.2 m × 0.3 m wall shelf board (3 cm thick) at 1.4 m on a side wall (on the right when facing the window
      from inside; the west wall for a south window).

    The layout is given relative to the window wall, so it stays furnished sensibly whichever wall holds the
    window; the room must be at least about 3.5 m deep and 3.5 m wide for the pieces not to collide.
    """
    size = tuple(float(s) for s in size_m)
    parts, w, opening = _room_shell(size, window, wall_thickness_m, floor_reflectance, wall_reflectance,
                                    ceiling_reflectance, tessellation_m)
    L, D, Z = w.length, w.depth, size[2]
    if L < 3.5 or D < 3.5 or Z < 2.0:
        raise ValidationRoomError(f"furnished_room needs a room at least 3.5 × 3.5 × 2.0 m, got {size}")
    if not 0.0 < mullion_width_m < 0.5 * min(opening[1] - opening[0], opening[3] - opening[2]):
        raise ValidationRoomError(f"mullion_width_m {mullion_width_m} does not fit the window")
    t = tessellation_m
    m = 0.5 * mullion_width_m
    a_lo, a_hi, z_lo, z_hi = opening
    ac, zc, dc = 0.5 * (a_lo + a_hi), 0.5 * (z_lo + z_hi), -0.5 * wall_thickness_m

    def box(a0: float, a1: float, d0: float, d1: float, z0: float, z1: float, rho: RGB,
            omit_local: Sequence[str] = ()) -> list[ReflectanceMesh]:
        """A box given in the window wall's frame (a along the wall, d into the room); omit by local name."""
        local = {"+a": w.a, "-a": -w.a, "+d": w.d, "-d": -w.d, "+z": _Z, "-z": -_Z}
        lo, hi = w.to_world(a0, d0, z0), w.to_world(a1, d1, z1)
        return _box(lo, hi, rho, t, [local[k] for k in omit_local])

    rho_f = frame_reflectance
    # window cross: mullion full height (ends hidden in sill/head), transom pieces end at jambs and mullion
    parts += box(ac - m, ac + m, dc - m, dc + m, z_lo, z_hi, rho_f, ("-z", "+z"))
    parts += box(a_lo, ac - m, dc - m, dc + m, zc - m, zc + m, rho_f, ("-a", "+a"))
    parts += box(ac + m, a_hi, dc - m, dc + m, zc - m, zc + m, rho_f, ("-a", "+a"))
    # table: top and legs (legs end under the top and on the floor)
    ta0, ta1, td0, td1 = ac - 0.6, ac + 0.6, 1.2, 2.0
    parts += box(ta0, ta1, td0, td1, 0.72, 0.76, TABLE_RHO)
    for la, ld in ((ta0 + 0.05, td0 + 0.05), (ta1 - 0.10, td0 + 0.05), (ta0 + 0.05, td1 - 0.10),
                   (ta1 - 0.10, td1 - 0.10)):
        parts += box(la, la + 0.05, ld, ld + 0.05, 0.0, 0.72, TABLE_RHO, ("-z", "+z"))
    # cube on the floor, to the right of the window axis
    ca = min(ac + 1.2, L - 0.7)
    parts += box(ca, ca + 0.5, 2.6, 3.1, 0.0, 0.5, BOX_RHO, ("-z",))
    # shelf block against the opposite wall (its back and bottom are hidden)
    sa = max(0.3, ac - 1.75)
    parts += box(sa, sa + 1.2, D - 0.4, D, 0.0, 1.8, SHELF_RHO, ("-z", "+d"))
    # wall shelf board on the side wall at a = 0
    parts += box(0.0, 0.3, 1.5, 2.7, 1.40, 1.43, SHELF_RHO, ("-a",))
    return merge_meshes(parts)


def _tint(rng: np.random.Generator, lo: float, hi: float) -> RGB:
    """A linear RGB albedo: a grey level in [lo, hi] with each channel varied by up to ±15 %."""
    grey = rng.uniform(lo, hi)
    r, g, b = np.clip(grey * rng.uniform(0.85, 1.15, 3), 0.02, 0.95)
    return float(r), float(g), float(b)


def random_room(seed: int, *, window_wall: str = "south", tessellation_m: float = 0.05,
                max_tries: int = 200) -> ReflectanceMesh:
    """A furnished room drawn from ``seed``, for validation on rooms no development saw.

    Drawn: the size (3.8–6 × 3.8–6 × 2.5–3.2 m), the window on ``window_wall`` (0.9–2.4 m wide, 1.0–1.8 m high,
    sill 0.4–1.1 m, wall 0.15–0.4 m thick) with a cross (bar 4–10 cm, at 30–70 % of the wall's depth, transom at
    35–65 % of the height) whose bars stand on the sill and end on the reveals, every albedo, and furniture that
    touches the room: a table (closed top on four closed legs standing on the floor), a cabinet standing on the
    floor with its back against a side wall, a box against the wall opposite the window, a shelf board on the other
    side wall and, on half the seeds, a low box under the window against the window wall. Furniture boxes are closed
    (their faces lie on the floor and walls they touch: the junctions of issue 21). Pieces do not overlap.
    """
    rng = np.random.default_rng(seed)
    X, Y = rng.uniform(3.8, 6.0, 2)
    Z = rng.uniform(2.5, 3.2)
    size = (float(X), float(Y), float(Z))
    w = _WallFrame(window_wall, size)
    width = rng.uniform(0.9, min(2.4, w.length - 1.4))
    height = rng.uniform(1.0, min(1.8, Z - 1.0))
    sill = rng.uniform(0.4, min(1.1, Z - height - 0.3))
    thickness = rng.uniform(0.15, 0.4)
    wall_rho = _tint(rng, 0.45, 0.85)
    parts, w, opening = _room_shell(size, (width, height, sill, window_wall), thickness, _tint(rng, 0.12, 0.5),
                                    wall_rho, _tint(rng, 0.7, 0.9), tessellation_m)
    L, D = w.length, w.depth
    t = tessellation_m

    def box(a0: float, a1: float, d0: float, d1: float, z0: float, z1: float, rho: RGB) -> list[ReflectanceMesh]:
        return _box(w.to_world(a0, d0, z0), w.to_world(a1, d1, z1), rho, t)

    a_lo, a_hi, z_lo, z_hi = opening
    m = 0.5 * rng.uniform(0.04, 0.10)
    dc = -rng.uniform(0.3, 0.7) * thickness
    ac = a_lo + rng.uniform(0.35, 0.65) * (a_hi - a_lo)
    zc = z_lo + rng.uniform(0.35, 0.65) * (z_hi - z_lo)
    frame = _tint(rng, 0.5, 0.85)
    parts += box(ac - m, ac + m, dc - m, dc + m, z_lo, z_hi, frame)
    parts += box(a_lo, ac - m, dc - m, dc + m, zc - m, zc + m, frame)
    parts += box(ac + m, a_hi, dc - m, dc + m, zc - m, zc + m, frame)

    placed: list[tuple[float, float, float, float]] = []  # footprints (a0, a1, d0, d1) with 5 cm clearance

    def place(draw: Callable[[], tuple[float, float, float, float]]) -> tuple[float, float, float, float]:
        for _ in range(max_tries):
            a0, a1, d0, d1 = draw()
            if 0.0 <= a0 < a1 <= L and 0.0 <= d0 < d1 <= D and not any(
                    a0 < b1 + 0.05 and b0 < a1 + 0.05 and d0 < e1 + 0.05 and e0 < d1 + 0.05
                    for b0, b1, e0, e1 in placed):
                placed.append((a0, a1, d0, d1))
                return a0, a1, d0, d1
        raise ValidationRoomError(f"seed {seed}: could not place the furniture in a {L:.2f} × {D:.2f} m room")

    if rng.random() < 0.5:  # a low box under the window, against the window wall
        bw, bh = rng.uniform(0.6, 1.0) * width, rng.uniform(0.2, 0.8) * sill
        a0, a1, d0, d1 = place(lambda: (0.5 * (L - bw), 0.5 * (L + bw), 0.0, float(rng.uniform(0.1, 0.3))))
        parts += box(a0, a1, d0, d1, 0.0, bh, _tint(rng, 0.3, 0.8))
    tw, tdp, th = rng.uniform(0.8, 1.6), rng.uniform(0.6, 1.0), rng.uniform(0.68, 0.78)
    a0, a1, d0, d1 = place(lambda: (a := float(rng.uniform(0.3, L - tw - 0.3)), a + tw,
                                    d := float(rng.uniform(0.6, max(0.7, D - tdp - 1.0))), d + tdp))
    table = _tint(rng, 0.15, 0.6)
    parts += box(a0, a1, d0, d1, th - 0.04, th, table)
    leg = rng.uniform(0.04, 0.07)
    for la, ld in ((a0 + 0.03, d0 + 0.03), (a1 - 0.03 - leg, d0 + 0.03), (a0 + 0.03, d1 - 0.03 - leg),
                   (a1 - 0.03 - leg, d1 - 0.03 - leg)):
        parts += box(la, la + leg, ld, ld + leg, 0.0, th - 0.04, table)
    side = 0.0 if rng.random() < 0.5 else L
    cw, cd, ch = rng.uniform(0.6, 1.5), rng.uniform(0.35, 0.6), rng.uniform(0.8, 2.2)
    a0, a1, d0, d1 = place(lambda: ((0.0, cd) if side == 0.0 else (L - cd, L)) +
                           ((d := float(rng.uniform(0.4, D - cw - 0.2))), d + cw))
    parts += box(a0, a1, d0, d1, 0.0, ch, _tint(rng, 0.2, 0.7))
    bs = rng.uniform(0.3, 0.7)
    a0, a1, d0, d1 = place(lambda: ((a := float(rng.uniform(0.2, L - bs - 0.2))), a + bs, D - bs, D))
    parts += box(a0, a1, d0, d1, 0.0, bs * rng.uniform(0.7, 1.3), _tint(rng, 0.15, 0.7))
    sl, sz = rng.uniform(0.8, 1.5), rng.uniform(1.2, min(1.9, Z - 0.4))
    sd = float(rng.uniform(0.3, max(0.4, D - sl - 0.3)))
    other = L if side == 0.0 else 0.0
    board = (other - 0.3, other) if other else (0.0, 0.3)
    parts += box(board[0], board[1], sd, sd + sl, sz, sz + 0.03, _tint(rng, 0.3, 0.7))
    return merge_meshes(parts)


def _point_segment_dist(p: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    ab = b - a
    s = np.clip(np.sum((p - a) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - (a + s[:, None] * ab), axis=1)


def _point_triangle_dist(p: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64],
                         c: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance of each point to its triangle (row-wise)."""
    n = np.cross(b - a, c - a)
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    h = np.sum((p - a) * n, axis=1)
    q = p - h[:, None] * n
    inside = np.ones(len(p), dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.sum(np.cross(v - u, q - u) * n, axis=1) >= 0.0
    edge = np.minimum(np.minimum(_point_segment_dist(p, a, b), _point_segment_dist(p, b, c)),
                      _point_segment_dist(p, c, a))
    return np.where(inside, np.abs(h), edge)


def _near_creases(mesh: ReflectanceMesh, points: NDArray[np.float64], face_idx: NDArray[np.int64],
                  threshold: float | NDArray[np.float64], *, chunk: int = 64) -> NDArray[np.bool_]:
    """True where a point lies within ``threshold`` (one for all, or one per point) of a triangle not in its own
    plane, or of a boundary edge."""
    v, f = mesh.vertices_m, mesh.faces
    tri = v[f]
    limit = np.broadcast_to(np.asarray(threshold, dtype=np.float64), (len(points),))
    threshold = float(limit.max()) if len(limit) else 0.0
    lo, hi = tri.min(axis=1) - threshold, tri.max(axis=1) + threshold
    fn = mesh.face_normals
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    bnd = uniq[counts == 1]
    ea, eb = v[bnd[:, 0]], v[bnd[:, 1]]
    elo, ehi = np.minimum(ea, eb) - threshold, np.maximum(ea, eb) + threshold
    near = np.zeros(len(points), dtype=bool)
    for s in range(0, len(points), chunk):
        p = points[s : s + chunk]
        fi = face_idx[s : s + chunk]
        cand = np.all((p[:, None, :] >= lo[None]) & (p[:, None, :] <= hi[None]), axis=2)
        ip, jf = np.nonzero(cand)
        same_plane = (np.sum(fn[fi[ip]] * fn[jf], axis=1) > 1.0 - 1e-9) & (
            np.abs(np.sum((p[ip] - tri[jf, 0]) * fn[jf], axis=1)) < 1e-7
        )
        ip, jf = ip[~same_plane], jf[~same_plane]
        if len(ip):
            d = _point_triangle_dist(p[ip], tri[jf, 0], tri[jf, 1], tri[jf, 2])
            np.logical_or.at(near, s + ip[d < limit[s + ip]], True)
        if len(bnd):
            cand = np.all((p[:, None, :] >= elo[None]) & (p[:, None, :] <= ehi[None]), axis=2)
            ip, je = np.nonzero(cand)
            if len(ip):
                d = _point_segment_dist(p[ip], ea[je], eb[je])
                np.logical_or.at(near, s + ip[d < limit[s + ip]], True)
    return near


def _hidden(caster: RayCaster, face_normals: NDArray[np.float64], points: NDArray[np.float64],
            normals: NDArray[np.float64], rng: np.random.Generator, rays: int = 16) -> NDArray[np.bool_]:
    """True for points no light reaches: enclosed (under a box standing on the floor, behind a cabinet against a
    wall: a ray from just above the point first hits the *back* of a triangle) or pressed face to face against
    another surface with nothing on their side (a box's bottom on the floor: every ray of the point's hemisphere
    leaves the scene, which no visible point of a closed room does)."""
    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    d = rng.normal(size=(len(points), rays, 3))
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    d = np.where(np.sum(d * normals[:, None], axis=2, keepdims=True) < 0, -d, d)
    d[:, 0] = normals
    o = np.repeat((points + 1e-4 * normals)[:, None], rays, axis=1)
    hits = caster.intersect(o.reshape(-1, 3), d.reshape(-1, 3))
    hit = hits.hit.reshape(len(points), rays)
    back = hit & (np.sum(face_normals[np.where(hits.hit, hits.triangle_id, 0)].reshape(len(points), rays, 3) * d,
                         axis=2) > 0.0)
    return np.any(back, axis=1) | ~np.any(hit, axis=1)


def sample_surface_points(
    mesh: ReflectanceMesh,
    n: int,
    *,
    seed: int,
    exclude_near_edges_m: float = 0.05,
    near_edges_only_m: float = 0.0,
    edge_clearance: bool = False,
    max_rounds: int = 50,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``n`` points uniformly distributed by area on the mesh's visible surfaces, with their face normals.

    A candidate (a uniform point in a triangle chosen by area) is rejected when

    * it lies within ``exclude_near_edges_m`` of a triangle in another plane (a crease: room corners, where furniture
      meets the floor or a wall, the window reveals) or of a mesh boundary edge (openings; also creases between
      separately tessellated parts), so comparisons happen where the lighting is well defined; or
    * no light reaches it (:func:`_hidden`): enclosed (under a box standing on the floor, behind a shelf against a
      wall) or pressed face to face against another surface (a closed box's bottom on the floor).

    Args:
        mesh: the scene (front faces towards the air).
        n: number of points wanted.
        seed: seed of the NumPy random generator (the result is deterministic).
        exclude_near_edges_m: clearance from creases and boundary edges in metres (0 disables the test).
        near_edges_only_m: if positive, only points within this distance of a crease or boundary edge (and still
            ``exclude_near_edges_m`` from it): the neighbourhood of junctions, where the visibility rays of issue 21
            went wrong. Exactly on a crease the irradiance is not defined (a reference renderer's query point lies in
            the other surface's plane and sees through it), hence the inner limit.
        edge_clearance: also keep each point at least its triangle's longest edge from a crease, so that the
            triangle's nearest vertex (where :func:`~lightfast.eval.radiosity_validation.snap_to_vertices` moves it)
            is not on one either (coarse meshes: a user's room). No effect where triangles are no larger than
            ``exclude_near_edges_m``.
        max_rounds: candidate batches to draw before giving up.

    Returns:
        ``(points (n, 3), normals (n, 3))``, metres and unit face normals.

    Raises:
        ValidationRoomError: fewer than ``n`` acceptable points were found.
    """
    if n < 0:
        raise ValidationRoomError(f"n must be >= 0, got {n}")
    if 0 < near_edges_only_m <= exclude_near_edges_m:
        raise ValidationRoomError(f"near_edges_only_m={near_edges_only_m} leaves no band outside "
                                  f"exclude_near_edges_m={exclude_near_edges_m}")
    rng = np.random.default_rng(seed)
    areas = mesh.face_areas_m2
    prob = areas / areas.sum()
    caster = RayCaster(mesh.vertices_m, mesh.faces)
    tri = mesh.vertices_m[mesh.faces]
    fn = mesh.face_normals
    longest_edge = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)
    got_p: list[NDArray[np.float64]] = []
    got_n: list[NDArray[np.float64]] = []
    have = 0
    for _ in range(max_rounds):
        if have >= n:
            break
        m = max(2 * (n - have), 256)
        fi = rng.choice(len(areas), size=m, p=prob)
        r1, r2 = rng.random(m), rng.random(m)
        s = np.sqrt(r1)
        w0, w1, w2 = 1.0 - s, s * (1.0 - r2), s * r2
        p = w0[:, None] * tri[fi, 0] + w1[:, None] * tri[fi, 1] + w2[:, None] * tri[fi, 2]
        nrm = fn[fi]
        ok = np.ones(m, dtype=bool)
        if near_edges_only_m > 0:
            ok &= _near_creases(mesh, p, fi, near_edges_only_m)
        clearance = np.maximum(exclude_near_edges_m, longest_edge[fi]) if edge_clearance else exclude_near_edges_m
        if np.any(clearance > 0):
            ok &= ~_near_creases(mesh, p, fi, clearance)
        idx = np.flatnonzero(ok)
        ok[idx[_hidden(caster, fn, p[ok], nrm[ok], rng)]] = False
        got_p.append(p[ok])
        got_n.append(nrm[ok])
        have += int(ok.sum())
    if have < n:
        raise ValidationRoomError(f"found only {have} of {n} acceptable surface points after {max_rounds} rounds")
    return np.concatenate(got_p)[:n], np.concatenate(got_n)[:n]


def sample_crease_vertices(
    mesh: ReflectanceMesh,
    n: int,
    *,
    seed: int,
    within_m: float = 1e-3,
    inset_m: float = 2e-3,
    batch: int = 512,
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """``n`` mesh vertices on a crease (within ``within_m`` of a triangle in another plane or of an open mesh edge:
    where parts meet, issue 21, or where the mesh ends), each with a reference query point ``inset_m`` from it
    towards the centroid of one of its incident faces, in that face's plane, and the face's normal.

    The method's radiosity is defined at the vertex; a reference renderer cannot be asked exactly there (its query
    point would lie in the other surface's plane and see through it), so it is asked just inside the vertex's own
    face. Query points that no light reaches (:func:`_hidden`) or that are closer than ``inset_m / 8`` to a crease
    are skipped, as is a vertex with no such face.

    Returns:
        ``(vertex_ids (n,), query_points_m (n, 3), normals (n, 3))``.

    Raises:
        ValidationRoomError: the mesh has fewer than ``n`` such vertices.
    """
    if n < 0:
        raise ValidationRoomError(f"n must be >= 0, got {n}")
    if not 0 < inset_m / 8 < inset_m or within_m <= 0:
        raise ValidationRoomError("within_m and inset_m must be positive")
    rng = np.random.default_rng(seed)
    v, f, fn = mesh.vertices_m, mesh.faces, mesh.face_normals
    centroid = v[f].mean(axis=1)
    # incident faces per vertex, as a CSR list
    order = np.argsort(f.reshape(-1), kind="stable")
    face_of = order // 3
    start = np.searchsorted(f.reshape(-1)[order], np.arange(mesh.num_vertices + 1))
    caster = RayCaster(v, f)
    ids: list[int] = []
    qs: list[NDArray[np.float64]] = []
    ns: list[NDArray[np.float64]] = []
    perm = rng.permutation(mesh.num_vertices)
    for s in range(0, mesh.num_vertices, batch):
        if len(ids) >= n:
            break
        cand = perm[s : s + batch]
        has_face = start[cand + 1] > start[cand]
        cand = cand[has_face]
        first_face = face_of[start[cand]]
        cand = cand[_near_creases(mesh, v[cand], first_face, within_m)]
        counts = start[cand + 1] - start[cand]
        pair_v = np.repeat(cand, counts)  # every (vertex, incident face) pair of the batch
        pair_f = face_of[np.concatenate([np.arange(start[c], start[c + 1]) for c in cand])] if len(cand) else cand
        d = centroid[pair_f] - v[pair_v]
        q = v[pair_v] + inset_m * d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
        ok = ~_near_creases(mesh, q, pair_f, inset_m / 8)
        ok[ok] = ~_hidden(caster, fn, q[ok], fn[pair_f[ok]], rng)
        seen: set[int] = set()
        for k in np.flatnonzero(ok):  # the first usable face of each vertex, in the batch's random order
            if int(pair_v[k]) in seen:
                continue
            seen.add(int(pair_v[k]))
            ids.append(int(pair_v[k]))
            qs.append(q[k])
            ns.append(fn[pair_f[k]])
            if len(ids) >= n:
                break
    if len(ids) < n:
        raise ValidationRoomError(f"found only {len(ids)} of {n} crease vertices")
    return np.asarray(ids, dtype=np.int64), np.asarray(qs).reshape(-1, 3), np.asarray(ns).reshape(-1, 3)
