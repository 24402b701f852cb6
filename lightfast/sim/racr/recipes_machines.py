"""Machine subjects of the simulated rACR scenes (paper §5.1: vital equipment, e.g. the train of the paper's
Fig. 15): equipment cabinet with a flanged pipe, finned motor and train bogie side frame.

Each recipe ``(builder, rng, seed, outdoor) → (target point (3,) m, base camera distance m, description)`` builds
its subject into a :class:`~lightfast.sim.racr.builder.Builder` in the world frame (metres, z up, front facing −y):
painted and bare metal with seams, vents, fins and stamped text as relief canvases (heights in metres), hex bolts
and bolt circles, and printed labels as RGBA decal canvases (0.5 mm pixels); see :mod:`lightfast.sim.racr.recipes`
for the geometry of each.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from lightfast.sim.racr.builder import Builder, Recipe
from lightfast.sim.racr.materials import (
    Canvas,
    add_relief,
    blur,
    mask,
    metal,
    paint,
    stone,
    text_lines,
    wood,
    words,
)

__all__ = ["MACHINE_RECIPES"]

F64 = NDArray[np.float64]


def _decal_label(size_u: float, size_v: float, lines: Sequence[str], bg: Sequence[float], fg: Sequence[float],
                 px: float = 0.0005, font: int = cv2.FONT_HERSHEY_SIMPLEX) -> Canvas:
    """An RGBA label canvas: background ``bg`` with text ``fg`` (alpha 1 inside)."""
    c = Canvas.blank(size_u, size_v, px, channels=4)
    c.data[..., :3] = np.asarray(bg, np.float32)
    c.data[..., 3] = 1.0
    m = mask(c)
    text_lines(c, m, lines, (0.1 * size_u, 0.1 * size_v, 0.9 * size_u, 0.9 * size_v), font, 0.4 * 0.001)
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


def _cabinet(b: Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    W, H, D = rng.uniform(0.38, 0.48), rng.uniform(0.45, 0.56), 0.22
    z0 = 0.1 if outdoor else 0.0
    colors = {"grey": (0.45, 0.47, 0.48), "orange": (0.75, 0.33, 0.08), "green": (0.2, 0.38, 0.25),
              "blue": (0.15, 0.25, 0.45), "beige": (0.7, 0.66, 0.55)}
    cname = str(rng.choice(list(colors)))
    mat = paint(colors[cname], seed + 5, rust=0.25 if outdoor else 0.05, scratches=0.8)
    steel = metal((0.45, 0.45, 0.47), seed + 6)
    cv = Canvas.blank(W, H, 0.001)
    seam = mask(cv)
    ins = 0.02
    cv2.rectangle(seam, cv.px(ins, H - ins), cv.px(W - ins, ins), 255, 2, cv2.LINE_AA)
    add_relief(cv, seam, -0.004, 0.0008)
    vents = mask(cv)
    n_slots = int(rng.integers(6, 11))
    for k in range(n_slots):
        v = H - ins - 0.03 - k * 0.014
        cv2.rectangle(vents, cv.px(ins + 0.04, v), cv.px(W * 0.55, v - 0.006), 255, -1)
    add_relief(cv, vents, -0.005, 0.0015)
    plate = mask(cv)
    pu0, pv0, pw, ph = W * 0.18, H * 0.32, W * 0.5, 0.08
    cv2.rectangle(plate, cv.px(pu0, pv0 + ph), cv.px(pu0 + pw, pv0), 255, -1)
    add_relief(cv, plate, 0.0015, 0.0008)
    ptext = mask(cv)
    text_lines(cv, ptext, [f"TYPE {int(rng.integers(100, 999))}-{words(rng, 1)[:3]}",
                            f"{int(rng.integers(200, 690))} V  {int(rng.integers(5, 60))} A"],
                (pu0 + 0.01, pv0 + 0.01, pu0 + pw - 0.01, pv0 + ph - 0.01), cv2.FONT_HERSHEY_SIMPLEX, 0.0012)
    add_relief(cv, ptext, -0.001, 0.0006)
    key = mask(cv)
    cv2.circle(key, cv.px(W - ins - 0.035, H * 0.5), 6, 255, -1, cv2.LINE_AA)
    add_relief(cv, key, -0.004, 0.001)
    cv.data = blur(cv.data, 0.5)
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
    ticks = mask(gl)
    for k in range(40):
        uu = 2 * math.pi * 0.03 * (k / 40)
        cv2.line(ticks, gl.px(uu, 0.001), gl.px(uu, 0.006 if k % 5 else 0.01), 255, 1)
    add_relief(gl, ticks, -0.0006, 0.0003)
    b.lathe((-W / 2 + gx, y_front - 0.015, gz), (0, -1, 0), (1, 0, 0), [(0.03, 0.0), (0.0, 0.0)],
            metal((0.85, 0.85, 0.82), seed + 12), relief=gl, taper_m=0.0)
    return np.array([0.0, y_front, z0 + H * 0.5]), 1.6 * W, f"{cname} equipment cabinet with a flanged pipe"


def _motor(b: Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    R, L = rng.uniform(0.09, 0.12), rng.uniform(0.3, 0.38)
    zc = R + 0.05
    colors = {"blue": (0.12, 0.22, 0.42), "green": (0.18, 0.33, 0.22), "grey": (0.42, 0.44, 0.45),
              "red": (0.5, 0.1, 0.08)}
    cname = str(rng.choice(list(colors)))
    mat = paint(colors[cname], seed + 5, rust=0.3 if outdoor else 0.05)
    steel = metal((0.5, 0.5, 0.52), seed + 6)
    fins = Canvas.blank(2 * math.pi * R, L, 0.001, wrap_u=True)
    fm = mask(fins)
    pitch = rng.uniform(0.011, 0.015)
    for u in np.arange(0, 2 * math.pi * R, pitch):
        cv2.rectangle(fm, fins.px(u, L - 0.03), fins.px(u + 0.4 * pitch, 0.03), 255, -1)
    add_relief(fins, fm, 0.008, 0.0025)
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


def _bogie(b: Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    Lf, Hf, Tf = rng.uniform(0.9, 1.05), rng.uniform(0.22, 0.28), 0.04
    Rw = rng.uniform(0.2, 0.24)
    b.scale_detail(1.8)
    zf = Rw + 0.08
    yf = -0.12
    body = paint((0.12, 0.12, 0.13) if rng.random() < 0.6 else (0.3, 0.16, 0.1), seed + 5, rust=0.35)
    steel = metal((0.5, 0.5, 0.5), seed + 6)
    cv = Canvas.blank(Lf, Hf, 0.001)
    holes = mask(cv)
    for u in np.linspace(0.18, Lf - 0.18, 3):
        cv2.ellipse(holes, cv.px(u, Hf / 2), (int(0.07 / 0.001), int(0.45 * Hf / 0.001)), 0, 0, 360, 255, -1,
                    cv2.LINE_AA)
    add_relief(cv, holes, -0.01, 0.006)
    ribs = mask(cv)
    cv2.line(ribs, cv.px(0.02, Hf - 0.015), cv.px(Lf - 0.02, Hf - 0.015), 255, 6)
    cv2.line(ribs, cv.px(0.02, 0.015), cv.px(Lf - 0.02, 0.015), 255, 6)
    add_relief(cv, ribs, 0.004, 0.002)
    txt = mask(cv)
    text_lines(cv, txt, [f"{int(rng.integers(10, 99))}-{int(rng.integers(1000, 9999))} {words(rng, 1)}"],
                (Lf * 0.35, Hf * 0.05, Lf * 0.65, Hf * 0.22), cv2.FONT_HERSHEY_SIMPLEX, 0.002)
    add_relief(cv, txt, 0.0015, 0.0008)
    cv.data = blur(cv.data, 0.6)
    b.box((-Lf / 2, yf, zf), (Lf, Tf, Hf), body, step=3 * b.res, front={"relief": cv, "rough_m": 0.0004,
                                                                         "step": b.res})
    for u in np.linspace(0.04, Lf - 0.04, 14):
        for v in (0.035, Hf - 0.035):
            b.bolt((-Lf / 2 + u, yf, zf + v), (0, -1, 0), 0.006, steel)
    # wheels (axis towards the camera, -y) behind the frame
    wx = Lf / 2 - 0.2
    for xw in (-wx, wx):
        wc = Canvas.blank(2 * math.pi * Rw, Rw, 0.001, wrap_u=True)
        wm = mask(wc)
        for v in (0.03, 0.06, Rw - 0.08):
            cv2.line(wm, wc.px(0, v), wc.px(2 * math.pi * Rw, v), 255, 3)
        add_relief(wc, wm, -0.003, 0.0015)
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


#: The machine recipes by name.
MACHINE_RECIPES: dict[str, Recipe] = {"cabinet": _cabinet, "motor": _motor, "bogie": _bogie}
