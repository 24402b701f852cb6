#!/usr/bin/env python3
"""A picture of `lightfast daylight radiosity`'s vertex-coloured PLY (docs/images/radiosity.png).

Without --ply it makes the furnished daylight test room (lightfast.sim.validation_rooms.furnished_room, Freiburg)
in --work, runs

    lightfast daylight prepare room.ply site.yaml map
    lightfast daylight radiosity map --time TIME --white WHITE -o radiosity

there and renders radiosity.ply. With --ply it renders any PLY with vertex colours. The renderer (NumPy z-buffer,
perspective, colours interpolated across the triangles) draws only the faces that face the camera, so the walls
and the ceiling between the camera and the room drop out.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def read_colored_ply(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (V, 3), faces (F, 3) and 8-bit colours (V, 3) of a binary PLY as `daylight radiosity` writes it."""
    raw = path.read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    header = raw[:end].decode("ascii").splitlines()
    types = {"float": "<f4", "uchar": "u1", "int": "<i4", "uint": "<u4", "double": "<f8"}
    props, counts, element = [], {}, ""
    for line in header:
        parts = line.split()
        if parts[:1] == ["element"]:
            element, counts[parts[1]] = parts[1], int(parts[2])
        elif parts[:1] == ["property"] and element == "vertex":
            props.append((parts[2], types[parts[1]]))
    vdtype = np.dtype(props)
    vert = np.frombuffer(raw, dtype=vdtype, count=counts["vertex"], offset=end)
    fdtype = np.dtype([("n", "u1"), ("idx", "<i4", (3,))])
    faces = np.frombuffer(raw, dtype=fdtype, count=counts["face"], offset=end + vdtype.itemsize * counts["vertex"])
    xyz = np.stack([vert[k] for k in "xyz"], axis=1).astype(np.float64)
    rgb = np.stack([vert[k] for k in ("red", "green", "blue")], axis=1)
    return xyz, faces["idx"].astype(np.int64), rgb


def render(ply: Path, png: Path, eye: np.ndarray, target: np.ndarray, size: tuple[int, int], fov_deg: float,
           supersample: int = 2) -> None:
    """Perspective z-buffer rasterization of the faces that face the camera, colours interpolated across each
    triangle (Gouraud), rendered at ``supersample`` times the size and averaged down."""
    import matplotlib.image

    v, f, rgb = read_colored_ply(ply)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rel = v - eye
    cam = np.stack([rel @ right, rel @ up, rel @ forward], axis=1)
    tri = v[f]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    facing = np.einsum("ij,ij->i", normal, eye - tri.mean(axis=1)) > 0
    keep = np.flatnonzero(facing & np.all(cam[f][:, :, 2] > 0.05, axis=1))
    w, h = size[0] * supersample, size[1] * supersample
    focal = 0.5 * w / np.tan(np.radians(fov_deg) / 2)
    px = np.stack([0.5 * w + focal * cam[:, 0] / cam[:, 2], 0.5 * h - focal * cam[:, 1] / cam[:, 2]], axis=1)
    inv_z = 1.0 / cam[:, 2]
    colour = rgb.astype(np.float64) / 255.0
    image = np.ones((h, w, 3))
    zbuf = np.zeros((h, w))  # 1/z: larger is nearer
    for t in keep:
        (x0, y0), (x1, y1), (x2, y2) = px[f[t]]
        lo_x, hi_x = max(int(np.floor(min(x0, x1, x2))), 0), min(int(np.ceil(max(x0, x1, x2))), w - 1)
        lo_y, hi_y = max(int(np.floor(min(y0, y1, y2))), 0), min(int(np.ceil(max(y0, y1, y2))), h - 1)
        if lo_x > hi_x or lo_y > hi_y:
            continue
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < 1e-12:
            continue
        gx, gy = np.meshgrid(np.arange(lo_x, hi_x + 1) + 0.5, np.arange(lo_y, hi_y + 1) + 0.5)
        b1 = ((gx - x0) * (y2 - y0) - (x2 - x0) * (gy - y0)) / area
        b2 = ((x1 - x0) * (gy - y0) - (gx - x0) * (y1 - y0)) / area
        b0 = 1.0 - b1 - b2
        inside = (b0 >= 0) & (b1 >= 0) & (b2 >= 0)
        if not inside.any():
            continue
        iz = b0 * inv_z[f[t, 0]] + b1 * inv_z[f[t, 1]] + b2 * inv_z[f[t, 2]]
        win = zbuf[lo_y : hi_y + 1, lo_x : hi_x + 1]
        draw = inside & (iz > win)
        if not draw.any():
            continue
        # perspective-correct interpolation of the vertex colours
        w0, w1, w2 = b0 * inv_z[f[t, 0]] / iz, b1 * inv_z[f[t, 1]] / iz, b2 * inv_z[f[t, 2]] / iz
        c = w0[..., None] * colour[f[t, 0]] + w1[..., None] * colour[f[t, 1]] + w2[..., None] * colour[f[t, 2]]
        win[draw] = iz[draw]
        image[lo_y : hi_y + 1, lo_x : hi_x + 1][draw] = c[draw]
    image = image.reshape(size[1], supersample, size[0], supersample, 3).mean(axis=(1, 3))
    png.parent.mkdir(parents=True, exist_ok=True)
    matplotlib.image.imsave(png, np.clip(image, 0.0, 1.0))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("png", type=Path, nargs="?", default=ROOT / "docs" / "images" / "radiosity.png")
    parser.add_argument("--ply", type=Path, help="render this vertex-coloured PLY instead of making the test room")
    parser.add_argument("--work", type=Path, default=Path("radiosity-picture"), help="working directory")
    parser.add_argument("--time", default="2021-03-20T14:00:00+01:00", help="ISO 8601 time of the radiosity")
    parser.add_argument("--tessellation", type=float, default=0.05, help="test room triangle size, metres")
    parser.add_argument("--white", type=float, default=120.0, help="radiosity shown as white, W/m² (the "
                        "command's --white)")
    parser.add_argument("--eye", type=float, nargs=3, default=(8.8, 1.0, 5.6), help="camera position, map frame")
    parser.add_argument("--target", type=float, nargs=3, default=(1.6, 2.7, 0.4), help="point the camera looks at")
    parser.add_argument("--size", type=int, nargs=2, default=(960, 640), metavar=("W", "H"))
    parser.add_argument("--fov", type=float, default=50.0, help="horizontal field of view, degrees")
    args = parser.parse_args()
    ply = args.ply
    if ply is None:
        from lightfast.daylight.mesh import save_ply
        from lightfast.daylight.sun import FREIBURG
        from lightfast.sim.validation_rooms import furnished_room

        work = args.work
        work.mkdir(parents=True, exist_ok=True)
        save_ply(furnished_room(tessellation_m=args.tessellation), work / "room.ply")
        FREIBURG.to_yaml(work / "site.yaml")
        lf = [sys.executable, "-m", "lightfast"]
        if not (work / "map" / "metadata.json").exists():
            subprocess.run([*lf, "daylight", "prepare", "room.ply", "site.yaml", "map"], cwd=work, check=True)
        subprocess.run([*lf, "daylight", "radiosity", "map", "--time", args.time, "--white", str(args.white), "-o",
                        "radiosity"], cwd=work, check=True)
        ply = work / "radiosity.ply"
    render(ply, args.png, np.asarray(args.eye, float), np.asarray(args.target, float), tuple(args.size), args.fov)
    print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
