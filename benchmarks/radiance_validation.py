"""Validation of the normalized radiosity against Radiance (issue "Daylight I", item 6).

Two rooms like the paper's (4.5×4.8×2.9 m, one window): (a) empty, (b) furnished with a window cross casting sharp
shadows. For each, the lighting map's normalized sky-only, ground-only and sun-only irradiance (B̂/ρ interpolated at
the points) is compared with ``rtrace -I`` (uniform-luminance sky, ground glow, a 0.533° solar source, 8 ambient
bounces, no ambient cache) at ``--points`` surface points, after one best-fit global scale per component.
Targets: median relative error <= 10 % and Pearson r >= 0.98.

    .venv/bin/python benchmarks/radiance_validation.py [--points 150] [--repeats 2]

Writes ``benchmarks/results/radiance_validation.md`` and ``.json`` (atomically) and a scatter plot PNG.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from lightfast.daylight.lighting_map import LightingMapConfig  # noqa: E402
from lightfast.eval.radiosity_validation import TARGET_MEDIAN, TARGET_R, compare_with_radiance  # noqa: E402
from lightfast.io import write_text_atomic  # noqa: E402
from lightfast.sim.validation_rooms import box_room_with_window, furnished_room  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=150)
    parser.add_argument("--repeats", type=int, default=2, help="rtrace samples averaged per point")
    parser.add_argument("--tessellation", type=float, default=0.05)
    parser.add_argument("--inside-triangles", action="store_true",
                        help="compare at the sampled points themselves (our values interpolated inside triangles, "
                        "blurring sun shadow edges over a triangle) instead of at the nearest mesh vertex")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "radiance_validation")
    args = parser.parse_args()
    config = LightingMapConfig()
    rooms = {"(a) empty room, one window": box_room_with_window(tessellation_m=args.tessellation),
             "(b) furnished, window cross": furnished_room(tessellation_m=args.tessellation)}
    rows, results, plots = [], {}, {}
    for name, mesh in rooms.items():
        t0 = time.perf_counter()
        res = compare_with_radiance(mesh, points=args.points, seed=1, repeats=args.repeats, config=config,
                                    at_vertices=not args.inside_triangles)
        elapsed = time.perf_counter() - t0
        for comp, a in res.items():
            ok = a.median_relative_error <= TARGET_MEDIAN and a.pearson_r >= TARGET_R
            rows.append(f"| {name} | {comp} | {mesh.num_vertices:,} | {a.median_relative_error * 100:.1f} % | "
                        f"{a.pearson_r:.4f} | {a.scale:.3f} | {'pass' if ok else 'FAIL'} |")
            results[f"{name}/{comp}"] = {"median_relative_error": a.median_relative_error, "pearson_r": a.pearson_r,
                                         "scale": a.scale, "points": args.points, "pass": ok}
            plots[(name, comp)] = a
        print(f"{name}: {elapsed:.0f} s", flush=True)
    all_ok = all(r["pass"] for r in results.values())
    text = "\n".join([
        "# Normalized radiosity vs Radiance",
        "",
        f"{args.points} surface points per room (uniform by area, away from creases, "
        f"{'interpolated inside triangles' if args.inside_triangles else 'snapped to the nearest mesh vertex'}), "
        "mesh tessellation "
        f"{args.tessellation * 100:.0f} cm, lighting map defaults (10 cm patches, {config.sky_directions} sky+ground "
        f"directions, {config.sun_samples} sun samples); Radiance `rtrace -I -ab 8 -aa 0 -ad 2048 -as 0`, "
        f"{args.repeats} samples per point, sun as 19 sub-disks of the 0.533° disk. "
        "Irradiance after one best-fit scale per component. `python benchmarks/radiance_validation.py`.",
        "",
        "| room | component | vertices | median rel. error | Pearson r | best-fit scale | target (<=10 %, r >= 0.98) |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
        f"All targets met: {'yes' if all_ok else 'NO'}.",
        "",
    ])
    print(text)
    write_text_atomic(args.out.with_suffix(".md"), text)
    write_text_atomic(args.out.with_suffix(".json"), json.dumps(results, indent=2) + "\n")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(len(rooms), 3, figsize=(12, 4 * len(rooms)), squeeze=False)
        for i, name in enumerate(rooms):
            for j, comp in enumerate(("sky", "ground", "sun")):
                a = plots[(name, comp)]
                ax = axes[i, j]
                ax.loglog(a.reference.reshape(-1), a.scale * a.ours.reshape(-1), ".", ms=3)
                lim = [a.reference.min() * 0.8, a.reference.max() * 1.2]
                ax.plot(lim, lim, "k-", lw=0.5)
                ax.set(title=f"{name.split(',')[0]} {comp}: med {a.median_relative_error * 100:.1f} %, "
                       f"r {a.pearson_r:.3f}", xlabel="Radiance irradiance", ylabel="lightfast (scaled)")
        fig.tight_layout()
        png = args.out.with_suffix(".png")
        tmp = png.with_name(f".{png.name}.tmp.png")
        fig.savefig(tmp, dpi=80)
        tmp.replace(png)
    except ImportError:
        pass
    return 0 if all_ok else 1


if __name__ == "__main__":
    sys.exit(main())
