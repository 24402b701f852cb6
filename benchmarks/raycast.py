"""Benchmark :class:`lightfast.raycast.RayCaster` (Embree through embreex) against Open3D's ``RaycastingScene``.

Builds a finely tessellated terrain (a height field of ~``--triangles`` triangles made with NumPy), then in the same
run and on the same mesh and rays times, for both libraries:

* the BVH build (constructor plus first commit),
* ``intersect`` / ``cast_rays`` for one 640×480 pinhole camera looking over the terrain and for ``--rays`` random
  rays (random origins in the terrain's bounding box, random directions: a mix of hits and misses),
* ``occluded`` / ``test_occlusions`` for the same rays.

Every figure is the median (with min–max) of ``--repeats`` runs; lightfast runs first, then Open3D, so their
thread pools never overlap. Both libraries are timed from NumPy arrays to NumPy arrays (for Open3D: tensor
creation, the query and ``.numpy()`` of its results). The script checks that the two agree (hit / miss, triangle
ids, distances, barycentrics, occlusion), prints a markdown report and writes it atomically to
``--output`` (default ``benchmarks/results/raycast.md``). Exit code 1 if they disagree on more than 0.1 % of rays.

Usage: ``.venv/bin/python benchmarks/raycast.py [--rays N] [--triangles N] [--repeats K]``
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib.metadata import version
from pathlib import Path

import numpy as np
import open3d as o3d
from numpy.typing import NDArray

from lightfast.camera import PinholeCamera
from lightfast.eval.machine import cpu_model
from lightfast.geometry import make_transform
from lightfast.raycast import RayCaster, RayHits

DEFAULT_OUTPUT = Path(__file__).resolve().parent / "results" / "raycast.md"
MAX_DISAGREEMENT = 1e-3  # fraction of rays on which the libraries may disagree (grazing rays in float32)


def terrain_mesh(triangles: int, *, size_m: float = 100.0) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """A hilly height field over ``[-size/2, size/2]^2`` with about ``triangles`` triangles (two per grid cell)."""
    n = max(2, round(np.sqrt(triangles / 2.0)) + 1)  # vertices per side
    x = np.linspace(-size_m / 2, size_m / 2, n)
    X, Y = np.meshgrid(x, x, indexing="xy")
    Z = 3.0 * np.sin(X / 9.0) * np.cos(Y / 13.0) + 0.4 * np.sin(1.7 * X + 0.9 * Y) + 0.05 * np.cos(7.0 * X)
    vertices = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    b, c = a + 1, a + n
    d = c + 1
    faces = np.concatenate([np.stack([a, b, d], axis=-1), np.stack([a, d, c], axis=-1)])
    return vertices, faces


def camera_rays(width: int, height: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Origin ``(3,)`` and world directions ``(H, W, 3)`` of a Kinect-like camera looking down over the terrain."""
    cam = PinholeCamera(width=width, height=height, fx=525.0 * width / 640, fy=525.0 * height / 480,
                        cx=(width - 1) / 2, cy=(height - 1) / 2)
    eye = np.array([-35.0, -30.0, 18.0])
    forward = np.array([30.0, 25.0, -12.0])  # towards the terrain; the upper image rows see the far hills / sky
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    T_world_cam = make_transform(np.stack([right, down, forward], axis=-1), eye)  # optical frame: x right, y down
    directions = cam.ray_directions() @ T_world_cam[:3, :3].T
    return eye, directions


def random_rays(n: int, vertices: NDArray[np.float64], rng: np.random.Generator) -> tuple[NDArray, NDArray]:
    lo, hi = vertices.min(axis=0), vertices.max(axis=0) + np.array([0.0, 0.0, 10.0])
    return rng.uniform(lo, hi, (n, 3)), rng.normal(size=(n, 3))


@dataclass(frozen=True)
class Timing:
    """Wall times in seconds of repeated calls."""

    times: tuple[float, ...]

    @property
    def median(self) -> float:
        return statistics.median(self.times)

    def cell(self) -> str:
        """``median (min–max)`` in milliseconds."""
        ms = [t * 1e3 for t in self.times]
        return f"{self.median * 1e3:.0f} ({min(ms):.0f}–{max(ms):.0f})" if len(ms) > 1 else f"{ms[0]:.0f}"


def timed(fn: Callable[[], object], repeats: int) -> tuple[Timing, object]:
    """Wall times of ``repeats`` calls, and the last result."""
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return Timing(tuple(times)), result


@dataclass
class Row:
    query: str
    rays: int
    ours: Timing
    open3d: Timing

    def cells(self) -> list[str]:
        def rate(t: Timing) -> str:
            return f"{self.rays / t.median / 1e6:.2f}" if self.rays else "–"

        return [self.query, f"{self.rays:,}" if self.rays else "–", self.ours.cell(), rate(self.ours),
                self.open3d.cell(), rate(self.open3d), f"{self.ours.median / self.open3d.median:.2f}"]


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def o3d_scene(vertices: NDArray, faces: NDArray) -> o3d.t.geometry.RaycastingScene:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32)))
    scene.cast_rays(o3d.core.Tensor(np.array([[0, 0, 1e4, 0, 0, 1]], np.float32)))  # forces the BVH build
    return scene


def o3d_cast(scene: o3d.t.geometry.RaycastingScene, rays32: NDArray[np.float32]) -> dict[str, NDArray]:
    res = scene.cast_rays(o3d.core.Tensor(rays32))
    return {k: res[k].numpy() for k in ("t_hit", "primitive_ids", "primitive_uvs")}


def o3d_occluded(scene: o3d.t.geometry.RaycastingScene, rays32: NDArray[np.float32]) -> NDArray[np.bool_]:
    return scene.test_occlusions(o3d.core.Tensor(rays32)).numpy().astype(bool)


def compare(
    name: str, hits: RayHits, o3d_res: dict[str, NDArray], occ_ours: NDArray, occ_o3d: NDArray
) -> tuple[list[str], float]:
    """Agreement row and the worst disagreement fraction."""
    hit_ours = hits.hit.ravel()
    t_o3d = o3d_res["t_hit"].ravel()
    hit_o3d = np.isfinite(t_o3d)
    both = hit_ours & hit_o3d
    ids_o3d = o3d_res["primitive_ids"].ravel().astype(np.int64)
    same_id = hits.triangle_id.ravel()[both] == ids_o3d[both]
    dt = np.abs(hits.distance_m.ravel()[both].astype(np.float64) - t_o3d[both])
    duv = np.abs(hits.barycentric_uv.reshape(-1, 2)[both] - o3d_res["primitive_uvs"].reshape(-1, 2)[both])
    n = hit_ours.size
    hit_mismatch = int(np.sum(hit_ours != hit_o3d))
    id_mismatch = int(np.sum(~same_id))
    occ_mismatch = int(np.sum(occ_ours.ravel() != occ_o3d.ravel()))
    worst = max(hit_mismatch, id_mismatch, occ_mismatch) / n
    row = [name, f"{n:,}", f"{hit_ours.mean() * 100:.1f} %", f"{hit_mismatch}", f"{id_mismatch}",
           f"{dt.max(initial=0.0):.2e}", f"{duv[same_id].max(initial=0.0):.2e}", f"{occ_mismatch}"]
    return row, worst


def write_atomically(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rays", type=int, default=1_000_000, help="number of random rays (default 1,000,000)")
    parser.add_argument("--triangles", type=int, default=1_000_000, help="approximate mesh size (default 1,000,000)")
    parser.add_argument("--width", type=int, default=640, help="camera image width (default 640)")
    parser.add_argument("--height", type=int, default=480, help="camera image height (default 480)")
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats per figure, median reported")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT, help="markdown report path")
    args = parser.parse_args(argv)
    if args.rays < 1 or args.triangles < 2 or args.repeats < 1:
        parser.error("--rays and --repeats must be >= 1, --triangles >= 2")

    t_start = time.perf_counter()
    load_start = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    rng = np.random.default_rng(args.seed)
    vertices, faces = terrain_mesh(args.triangles)
    eye, cam_dirs = camera_rays(args.width, args.height)
    rnd_origins, rnd_dirs = random_rays(args.rays, vertices, rng)
    ray_sets = {
        f"camera {args.width}×{args.height}": (np.broadcast_to(eye, cam_dirs.shape), cam_dirs),
        f"random {args.rays:,}": (rnd_origins, rnd_dirs),
    }

    # One library after the other, so that neither one's idle worker threads compete with the other's queries.
    build_ours, caster = timed(lambda: RayCaster(vertices, faces), args.repeats)
    ours: dict[str, tuple[Timing, RayHits, Timing, NDArray[np.bool_]]] = {}
    for name, (origins, dirs) in ray_sets.items():
        t_hit, hits = timed(lambda o=origins, d=dirs: caster.intersect(o, d), args.repeats)
        t_occ, occ = timed(lambda o=origins, d=dirs: caster.occluded(o, d), args.repeats)
        ours[name] = (t_hit, hits, t_occ, occ)  # type: ignore[assignment]
    time.sleep(1.0)
    build_o3d, scene = timed(lambda: o3d_scene(vertices, faces), args.repeats)
    rows = [Row(f"BVH build ({len(faces):,} triangles)", 0, build_ours, build_o3d)]
    agreement: list[list[str]] = []
    worst = 0.0
    for name, (origins, dirs) in ray_sets.items():
        unit = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
        rays32 = np.concatenate([origins, unit], axis=-1).reshape(-1, 6).astype(np.float32)
        n = rays32.shape[0]
        t_hit, hits, t_occ, occ = ours[name]
        t_o3d, o3d_res = timed(lambda r=rays32: o3d_cast(scene, r), args.repeats)
        rows.append(Row(f"intersect, {name}", n, t_hit, t_o3d))
        t_o3d, occ_o3d = timed(lambda r=rays32: o3d_occluded(scene, r), args.repeats)
        rows.append(Row(f"occluded, {name}", n, t_occ, t_o3d))
        row, bad = compare(name, hits, o3d_res, occ, occ_o3d)
        agreement.append(row)
        worst = max(worst, bad)
    rows = [rows[0], *sorted(rows[1:], key=lambda r: r.query)]
    total_s = time.perf_counter() - t_start

    threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    command = " ".join(["benchmarks/raycast.py", *(sys.argv[1:] if argv is None else argv)])
    report = "\n".join([
        "# Ray casting: lightfast `RayCaster` (Embree via embreex) vs Open3D `RaycastingScene`",
        "",
        f"Generated by `{command}` on {datetime.now(UTC):%Y-%m-%d %H:%M} UTC in {total_s:.0f} s.",
        f"Machine: {cpu_model()}, {threads} CPU(s) available, load average {load_start:.2f} at start; "
        f"Python {platform.python_version()}, "
        f"numpy {np.__version__}, embreex {version('embreex')}, open3d {o3d.__version__}.",
        f"Mesh: terrain height field, {len(vertices):,} vertices, {len(faces):,} triangles. "
        f"Times: median (min–max) of {args.repeats} runs, NumPy ↔ library conversions included; both libraries use "
        "all CPUs; lightfast runs first, then Open3D.",
        "",
        markdown_table(["query", "rays", "lightfast ms", "lightfast Mrays/s", "Open3D ms", "Open3D Mrays/s",
                        "lightfast / Open3D (median time)"], [r.cells() for r in rows]),
        "",
        "Agreement (same mesh, same rays; `occluded` with t_far = inf):",
        "",
        markdown_table(["rays", "n", "hit rate", "hit/miss mismatches", "triangle id mismatches", "max abs Δt (m)",
                        "max abs Δuv", "occlusion mismatches"], agreement),
        "",
    ])
    print(report)
    write_atomically(args.output, report)
    if worst > MAX_DISAGREEMENT:
        print(f"error: the libraries disagree on {worst:.3%} of rays (> {MAX_DISAGREEMENT:.1%})", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
