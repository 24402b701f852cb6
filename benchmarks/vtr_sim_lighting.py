"""Diagnostic for the VT&R evaluation (paper §VI; issue 6): how each image source of the simulated route holds up
across the day, without any viewpoint change.

At positions spread along the route of ``lightfast sim vtr`` (the scene of a simulation directory), the left camera
of the rig is rendered at the *same* pose under the light of the teach run (2014-05-12 10:50, sunny) and under the
light at the start of every repeat of the default schedule (sun position from the site and time; cloudy days with
the simulator's overcast transmittances). Per image source (greyscale, F_v, F_r, the constrained peak image)
ORB features (the front end's defaults) of the teach image are matched to those of the repeat image with the map
matching rules of :class:`lightfast.vtr.RepeatConfig` (Lowe ratio 0.8, mutual, Hamming ≤ 80); a match is correct
when both keypoints lie within 3 px (same pose: a correct match is at the same pixel). "fused" counts the correct
matches of grey, F_v and F_r together (what the fused localization can use).

For the correct greyscale matches the renderer's sun visibility at the keypoint tells whether the lighting there
changed between the two times: sunlit at both, in shadow at both, or changed (sunlit ↔ shadow) — ORB compares
pixel intensities within a patch, so a surface texture survives a change of the light as long as the whole patch is
lit alike.

Usage: ``nice -n 10 .venv/bin/python benchmarks/vtr_sim_lighting.py [SIM_DIR] [--size 320x240] [--positions 8]``
(default SIM_DIR: the simulation of the committed evaluation; its scene is rebuilt if missing); writes
``benchmarks/results/vtr_sim_lighting.md`` and ``.json``.
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from lightfast.data.shared import shown_path  # noqa: E402
from lightfast.daylight.sun import sun_position  # noqa: E402
from lightfast.io import write_text_atomic  # noqa: E402
from lightfast.sim.vtr.build import build_route_scene  # noqa: E402
from lightfast.sim.vtr.camera import AutoExposure, SensorModel, StereoRig  # noqa: E402
from lightfast.sim.vtr.light import daylight_illumination  # noqa: E402
from lightfast.sim.vtr.recordings import DEFAULT_RUNS, MET_SITE, TABLE_I  # noqa: E402
from lightfast.sim.vtr.renderer import SpectralRenderer  # noqa: E402
from lightfast.sim.vtr.scene import RouteConfig, RouteScene, base_pose  # noqa: E402
from lightfast.vtr import FeatureExtractor, RepeatConfig, StereoConfig, image_sources, match_descriptors  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
DEFAULT_SIM = Path.home() / ".cache" / "lightfast" / "vtr-sim-L300-320x240-r1-f2"
SOURCES = ("grey", "fv", "fr", "peak")
CORRECT_PX = 3.0
RUNS = {r.name: r for r in TABLE_I}


def light_at(run: str):
    spec = RUNS[run]
    start = spec.start_local(MET_SITE)
    sp = sun_position(MET_SITE, int(start.timestamp()) * 1_000_000_000)
    kw = dict(cloud_transmittance=0.35, direct_transmittance=0.02) if spec.weather == "cloudy" else {}
    el = float(np.ravel(sp.elevation_deg)[0])
    return daylight_illumination(np.asarray(sp.direction_map).reshape(-1, 3)[0], el, spec.weather, **kw), el


def capture(renderer: SpectralRenderer, rig: StereoRig, T, light):
    out = renderer.render([T], rig.camera, light, np.random.default_rng(0))[0]
    sensor = SensorModel()
    ae = AutoExposure(sensor)
    for _ in range(8):  # converged auto-exposure, as after a few frames of driving
        e, g = ae.update(out.raw)
    return sensor.capture(out.raw, e, g, np.random.default_rng(1)), out.sun


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sim_dir", type=Path, nargs="?", default=DEFAULT_SIM)
    ap.add_argument("--size", default="320x240", help="image size WxH (default 320x240, the evaluation's)")
    ap.add_argument("--positions", type=int, default=8, help="positions along the route (default 8)")
    ap.add_argument("--output", type=Path, default=RESULTS / "vtr_sim_lighting.md")
    args = ap.parse_args()
    t_start = time.perf_counter()
    load_before = os.getloadavg()[0]
    w, h = (int(x) for x in args.size.split("x"))
    scene_file = args.sim_dir / "scene" / "scene.npz"
    scene = RouteScene.load(scene_file) if scene_file.is_file() else build_route_scene(RouteConfig())
    renderer = SpectralRenderer(scene)
    rig = StereoRig(width=w, height=h)
    ex = FeatureExtractor(StereoConfig())
    rc = RepeatConfig()
    repeats = [r for r in DEFAULT_RUNS if r != "teach"]
    lights = {r: light_at(r) for r in ("teach", *repeats)}
    positions = np.linspace(10.0, scene.length_m - 10.0, args.positions)
    counts = {r: {s: [] for s in (*SOURCES, "fused")} for r in repeats}
    where = {r: {"lit at both": 0, "shadow at both": 0, "changed": 0} for r in repeats}
    for k, s_m in enumerate(positions):
        print(f"position {k + 1}/{len(positions)} (s = {s_m:.0f} m)", flush=True)
        T, _ = rig.camera_poses(base_pose(scene, float(s_m), 0.0))
        img0, sun0 = capture(renderer, rig, T, lights["teach"][0])
        src0 = image_sources(img0, sources=SOURCES)
        f0 = {s: ex.detect(src0[s].image, src0[s].valid) for s in SOURCES}
        for r in repeats:
            img, sun = capture(renderer, rig, T, lights[r][0])
            src = image_sources(img, sources=SOURCES)
            fused = 0
            for s in SOURCES:
                f = ex.detect(src[s].image, src[s].valid)
                i, j, _ = match_descriptors(f0[s].descriptors, f.descriptors, "orb", ratio=rc.ratio, mutual=rc.mutual,
                                            max_distance=rc.orb_max_distance)
                good = np.linalg.norm(f0[s].uv[i] - f.uv[j], axis=1) <= CORRECT_PX
                counts[r][s].append(int(good.sum()))
                if s != "peak":
                    fused += int(good.sum())
                if s == "grey" and good.any():
                    uv = np.rint(f0[s].uv[i[good]]).astype(int)
                    a = sun0[uv[:, 1], uv[:, 0]] > 0
                    b = sun[uv[:, 1], uv[:, 0]] > 0
                    where[r]["lit at both"] += int(np.sum(a & b))
                    where[r]["shadow at both"] += int(np.sum(~a & ~b))
                    where[r]["changed"] += int(np.sum(a != b))
            counts[r]["fused"].append(fused)
    rows = []
    for r in repeats:
        spec = RUNS[r]
        total = max(sum(where[r].values()), 1)
        rows.append({"run": r, "date": spec.date, "start": spec.start, "weather": spec.weather,
                     "sun_elevation_deg": lights[r][1],
                     "correct_matches_mean": {s: float(np.mean(v)) for s, v in counts[r].items()},
                     "grey_correct_where": {k: v / total for k, v in where[r].items()}})
    lines = [
        "# Simulated route: matches across the day at the same pose, per image source",
        "",
        f"Scene of `{shown_path(args.sim_dir)}` ({scene.length_m:.0f} m route), left camera at {w}×{h}, "
        f"{len(positions)} positions "
        f"every {positions[1] - positions[0]:.0f} m on the centreline; teach light 2014-05-12 10:50 (sun elevation "
        f"{lights['teach'][1]:.0f}°) against the light at the start of each repeat of the default schedule. Mean "
        f"number of correct matches (same pixel ± {CORRECT_PX:.0f} px) per position, of 1000 ORB features per image, "
        "matched with the map matching rules (ratio 0.8, mutual, Hamming ≤ 80); fused = grey + F_v + F_r. Right: "
        "where the correct greyscale matches lie (renderer's sun visibility at the two times).",
        "",
        "| repeat | start | weather | sun elevation | grey | F_v | F_r | peak | fused | grey matches: lit at both / "
        "shadow at both / lighting changed |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for row in rows:
        c, g = row["correct_matches_mean"], row["grey_correct_where"]
        lines.append(f"| {row['run']} | {row['date']} {row['start']} | {row['weather']} | "
                     f"{row['sun_elevation_deg']:.0f}° | {c['grey']:.0f} | {c['fv']:.0f} | {c['fr']:.0f} | "
                     f"{c['peak']:.0f} | {c['fused']:.0f} | {100 * g['lit at both']:.0f} / "
                     f"{100 * g['shadow at both']:.0f} / {100 * g['changed']:.0f} % |")
    lines += [
        "",
        f"Generated {dt.datetime.now(dt.UTC).isoformat(timespec='seconds')} by `benchmarks/vtr_sim_lighting.py` in "
        f"{time.perf_counter() - t_start:.0f} s (load average {load_before:.1f}).",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    write_text_atomic(args.output, text)
    write_text_atomic(args.output.with_suffix(".json"), json.dumps(
        {"sim_dir": shown_path(args.sim_dir), "size": [w, h], "positions_m": positions.tolist(), "rows": rows,
         "teach_sun_elevation_deg": lights["teach"][1]}, indent=1) + "\n")


if __name__ == "__main__":
    main()
