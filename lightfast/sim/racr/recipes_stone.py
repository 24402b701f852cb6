"""Stone subjects of the simulated rACR scenes (paper §5.1: cultural heritage, e.g. the stupa and the stone
inscription of the paper's Fig. 15): relief panel, inscription tablet / stele, stupa and facade.

Each recipe ``(builder, rng, seed, outdoor) → (target point (3,) m, base camera distance m, description)`` builds
its subject into a :class:`~lightfast.sim.racr.builder.Builder` in the world frame (metres, z up, front facing −y,
standing on z = 0 or on a plinth outdoors), carving relief canvases (heights in metres, 1 mm pixels) with
inscriptions, borders and ornaments; see :mod:`lightfast.sim.racr.recipes` for the geometry of each.
"""
from __future__ import annotations

import math
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from lightfast.sim.racr.builder import Builder, Recipe
from lightfast.sim.racr.materials import (
    FONTS,
    Canvas,
    add_relief,
    blur,
    hash3,
    mask,
    metal,
    profile,
    stone,
    text_lines,
    wood,
    words,
)

__all__ = ["STONE_RECIPES"]

F64 = NDArray[np.float64]


def _stone_color(rng: np.random.Generator) -> tuple[F64, str]:
    name = str(rng.choice(["sandstone", "marble", "granite", "limestone", "slate", "red sandstone"]))
    base = {"sandstone": (0.62, 0.52, 0.38), "marble": (0.78, 0.77, 0.73), "granite": (0.52, 0.50, 0.49),
            "limestone": (0.70, 0.66, 0.56), "slate": (0.28, 0.29, 0.31), "red sandstone": (0.55, 0.33, 0.25)}[name]
    return np.asarray(base) * rng.uniform(0.9, 1.08), name


def _panel(b: Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    W, H, T = rng.uniform(0.46, 0.6), rng.uniform(0.32, 0.42), 0.045
    z0 = 0.0 if not outdoor else 0.35
    base, mname = _stone_color(rng)
    if not outdoor and rng.random() < 0.3:
        mat, mname = wood(np.array([0.55, 0.36, 0.2]), seed + 5, axis=0), "wood"
    else:
        mat = stone(base, seed + 5, lichen=0.25 if outdoor else 0.0)
    cv = Canvas.blank(W, H, 0.001)
    frame = mask(cv)
    bw = rng.uniform(0.025, 0.035)
    cv2.rectangle(frame, cv.px(0.004, H - 0.004), cv.px(W - 0.004, 0.004), 255, -1)
    cv2.rectangle(frame, cv.px(bw, H - bw), cv.px(W - bw, bw), 0, -1)
    add_relief(cv, frame, 0.004, 0.003)
    groove = mask(cv)
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
    add_relief(cv, groove, -0.003, 0.0015)
    motif = mask(cv)
    veins = mask(cv)
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
    add_relief(cv, motif, 0.0035, 0.0025)
    add_relief(cv, veins, -0.0018, 0.001)
    text = mask(cv)
    text_lines(cv, text, [words(rng, 3)], (bw + 0.015, bw + 0.006, W - bw - 0.015, bw + 0.04),
                FONTS[int(rng.integers(0, 3))], 0.0018)
    add_relief(cv, text, -0.002, 0.001)
    cv.data = blur(cv.data, 0.6)
    if outdoor:
        b.box((-W / 2 - 0.05, -T / 2 - 0.05, 0.0), (W + 0.1, T + 0.1, z0), stone(base * 0.85, seed + 9),
              step=b.coarse, front={"rough_m": 0.002})
    b.box((-W / 2, -T / 2, z0), (W, T, H), mat, step=3 * b.res, front={"relief": cv, "rough_m": 0.0006,
                                                                        "step": b.res})
    return np.array([0.0, -T / 2, z0 + H / 2]), 1.12 * W, f"carved {mname} relief panel ({kind}, {style} border)"


def _tablet(b: Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    if outdoor:
        W, H, T, z0 = rng.uniform(0.5, 0.62), rng.uniform(0.6, 0.75), 0.12, 0.12
        b.scale_detail(1.3)
    else:
        W, H, T, z0 = rng.uniform(0.42, 0.52), rng.uniform(0.3, 0.38), 0.05, 0.0
    base, mname = _stone_color(rng)
    mat = stone(base, seed + 5, lichen=0.3 if outdoor else 0.0, contrast=0.18)
    cv = Canvas.blank(W, H, 0.001)
    border = mask(cv)
    inset = 0.022
    cv2.rectangle(border, cv.px(inset, H - inset), cv.px(W - inset, inset), 255, 4, cv2.LINE_AA)
    add_relief(cv, border, -0.003, 0.002)
    text = mask(cv)
    n = int(rng.integers(4, 7))
    font = FONTS[int(rng.integers(0, 4))]
    top = H - inset - 0.015
    title_h = (top - inset - 0.01) / (n + 1) * 1.6
    text_lines(cv, text, [words(rng, 2)], (inset + 0.03, top - title_h, W - inset - 0.03, top), font, 0.003)
    text_lines(cv, text, [words(rng, int(rng.integers(2, 4))) for _ in range(n)],
                (inset + 0.02, inset + 0.012, W - inset - 0.02, top - title_h - 0.004), font, 0.0019)
    add_relief(cv, text, -0.0028, 0.0012)
    pits = mask(cv)
    for _ in range(int(rng.integers(40, 120))):
        cv2.circle(pits, cv.px(rng.uniform(0, W), rng.uniform(0, H)), int(rng.integers(1, 4)), 255, -1)
    add_relief(cv, pits, -0.0012, 0.001)
    cv.data = blur(cv.data, 0.6)
    if outdoor:
        b.box((-W / 2 - 0.06, -T / 2 - 0.06, 0.0), (W + 0.12, T + 0.12, z0), stone(base * 0.8, seed + 9),
              step=b.coarse, front={"rough_m": 0.002})
    b.box((-W / 2, -T / 2, z0), (W, T, H), mat, step=3 * b.res, front={"relief": cv, "rough_m": 0.0008,
                                                                        "step": b.res})
    return (np.array([0.0, -T / 2, z0 + H / 2]), 1.1 * max(W, H * 1.2),
            f"{mname} {'stele' if outdoor else 'tablet'} with a carved inscription")

def _stupa(b: Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    k = rng.uniform(1.0, 1.25) if outdoor else rng.uniform(0.55, 0.7)
    b.scale_detail(1.25 * k)
    base, mname = _stone_color(rng)
    mat = stone(base, seed + 5, lichen=0.3 if outdoor else 0.0)
    # plinth with carved niches on the front
    P, Ph = 0.5 * k, 0.1 * k
    cv = Canvas.blank(P, Ph, 0.001)
    nm = mask(cv)
    nn = int(rng.integers(5, 9))
    for i in range(nn):
        u = (i + 0.5) * P / nn
        cv2.rectangle(nm, cv.px(u - 0.35 * P / nn, Ph * 0.8), cv.px(u + 0.35 * P / nn, Ph * 0.2), 255, -1)
        cv2.circle(nm, cv.px(u, Ph * 0.8), int(0.35 * P / nn / 0.001), 255, -1)
    add_relief(cv, nm, -0.006 * k, 0.003)
    fig = mask(cv)
    for i in range(nn):
        u = (i + 0.5) * P / nn
        cv2.ellipse(fig, cv.px(u, Ph * 0.45), (int(0.12 * P / nn / 0.001), int(0.2 * Ph / 0.001)), 0, 0, 360, 255,
                    -1, cv2.LINE_AA)
        cv2.circle(fig, cv.px(u, Ph * 0.72), int(0.07 * P / nn / 0.001), 255, -1, cv2.LINE_AA)
    add_relief(cv, fig, 0.004 * k, 0.002)
    cv.data = blur(cv.data, 0.6)
    b.box((-P / 2, -P / 2, 0.0), (P, P, Ph), mat, step=3 * b.res, front={"relief": cv, "rough_m": 0.001,
                                                                           "step": b.res})
    z = Ph
    Rd, hd = 0.19 * k, 0.06 * k
    band = Canvas.blank(2 * math.pi * Rd, hd, 0.001, wrap_u=True)
    bm = mask(band)
    pts = [band.px(u, hd * (0.25 if i % 2 else 0.75)) for i, u in enumerate(np.arange(0, 2 * math.pi * Rd, 0.015))]
    cv2.polylines(bm, [np.array(pts, np.int32)], False, 255, 3, cv2.LINE_AA)
    for u in np.arange(0.0075, 2 * math.pi * Rd, 0.015):
        cv2.circle(bm, band.px(u, hd * (0.75 if round(u / 0.015) % 2 else 0.25)), 3, 255, -1)
    add_relief(band, bm, -0.003, 0.0015)
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
    pm = mask(petals)
    npt = int(rng.integers(16, 28))
    pw = 2 * math.pi * Rb * 1.06 / npt
    for i in range(npt):
        u = (i + 0.5) * pw
        cv2.ellipse(pm, petals.px(u, 0.05 * k), (int(0.42 * pw / 0.001), int(0.04 * k / 0.001)), 0, 180, 360, 255,
                    2, cv2.LINE_AA)
        cv2.line(pm, petals.px(u, 0.012 * k), petals.px(u, 0.045 * k), 255, 1, cv2.LINE_AA)
    cv2.line(pm, petals.px(0, 0.1 * k), petals.px(2 * math.pi * Rb * 1.06, 0.1 * k), 255, 3, cv2.LINE_AA)
    add_relief(petals, pm, -0.0028, 0.0012)
    b.lathe((0, 0, z), (0, 0, 1), (1, 0, 0), prof, mat, relief=petals, rough_m=0.0008)
    z += 0.22 * k
    hw = 0.08 * k
    b.box((-hw / 2, -hw / 2, z - 0.01 * k), (hw, hw, 0.05 * k), mat, step=b.res * 1.5, front={"rough_m": 0.0008})
    z += 0.04 * k
    # ringed spire
    Ls = 0.2 * k
    rings = Canvas.blank(2 * math.pi * 0.035 * k, Ls, 0.001, wrap_u=True)
    rm = mask(rings)
    for i in range(7):
        v = (i + 0.5) * Ls / 7
        cv2.rectangle(rm, rings.px(0, v + 0.006 * k), rings.px(2 * math.pi * 0.035 * k, v - 0.006 * k), 255, -1)
    add_relief(rings, rm, 0.006 * k, 0.002)
    b.lathe((0, 0, z), (0, 0, 1), (1, 0, 0), [(0.035 * k, 0.0), (0.02 * k, Ls), (0.0, Ls)], mat, relief=rings,
            taper_m=0.01)
    b.lathe((0, 0, z + Ls), (0, 0, 1), (1, 0, 0),
            [(1e-4, 0.0)] + [(0.02 * k * math.sin(math.pi * q), 0.04 * k * (1 - math.cos(math.pi * q)) / 2)
                             for q in np.linspace(0.05, 1, 10)], metal((0.55, 0.45, 0.2), seed + 7))
    return np.array([0.0, -0.1 * k, 0.3 * k]), 1.5 * 0.5 * k + 0.15, f"{mname} stupa (scale {k:.2f})"


def _facade(b: Builder, rng: np.random.Generator, seed: int, outdoor: bool) -> tuple[F64, float, str]:
    W, H, D = rng.uniform(0.9, 1.1), rng.uniform(0.75, 0.9), 0.25
    b.scale_detail(1.8)
    base, mname = _stone_color(rng)
    mat = stone(base, seed + 5, lichen=0.3, contrast=0.12)
    cv = Canvas.blank(W, H, 0.001)
    tone = Canvas.blank(W, H, 0.001, channels=4)
    joints = mask(cv)
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
    offs = hash3(np.arange(bid + 1), np.zeros(bid + 1, np.int64), np.zeros(bid + 1, np.int64), seed)
    cv.data += (profile(solid, 0.001, 0.008) * 0.008 + profile(solid, 0.001, 0.008) * (offs[blocks] - 0.5) * 0.004)
    tone.data[..., 3] = 0.0
    # emblem block: carved rosette and inscription
    eu, ev = W / 2, H * 0.55
    em = mask(cv)
    cv2.circle(em, cv.px(eu, ev), int(0.06 / 0.001), 255, 3, cv2.LINE_AA)
    for k in range(12):
        a = 2 * math.pi * k / 12
        cv2.line(em, cv.px(eu + 0.015 * math.cos(a), ev + 0.015 * math.sin(a)),
                 cv.px(eu + 0.052 * math.cos(a), ev + 0.052 * math.sin(a)), 255, 3, cv2.LINE_AA)
    text_lines(cv, em, [words(rng, 2)], (eu - 0.2, ev - 0.11, eu + 0.2, ev - 0.07), FONTS[0], 0.002)
    add_relief(cv, em, -0.003, 0.0012)
    cv.data = blur(cv.data, 0.6)
    # per-block tone as a translucent decal
    tone_rgb = 0.8 + 0.4 * hash3(np.arange(bid + 1), np.ones(bid + 1, np.int64), np.zeros(bid + 1, np.int64), seed)
    tone.data[..., :3] = (base[None, None, :] * tone_rgb[blocks][..., None]).astype(np.float32)
    tone.data[..., 3] = np.where(blocks > 0, 0.45, 0.0)
    b.box((-W / 2, -D / 2, 0.0), (W, D, H), mat, step=3 * b.res,
          front={"relief": cv, "decal": tone, "rough_m": 0.0015, "step": b.res})
    # cornice with dentils
    cw, ch = W + 0.06, 0.06
    cc = Canvas.blank(cw, ch, 0.001)
    dm = mask(cc)
    for u in np.arange(0.01, cw, 0.03):
        cv2.rectangle(dm, cc.px(u, ch * 0.45), cc.px(u + 0.015, 0.003), 255, -1)
    add_relief(cc, dm, 0.006, 0.001)
    b.box((-cw / 2, -D / 2 - 0.04, H), (cw, D + 0.04, ch), mat, step=3 * b.res,
          front={"relief": cc, "rough_m": 0.001, "step": b.res})
    return np.array([0.0, -D / 2, H * 0.5]), 0.95 * W, f"{mname} facade with carved emblem and cornice"


#: The stone recipes by name.
STONE_RECIPES: dict[str, Recipe] = {"panel": _panel, "tablet": _tablet, "stupa": _stupa, "facade": _facade}
