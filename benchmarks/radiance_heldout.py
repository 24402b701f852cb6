"""Normalized radiosity against Radiance on rooms no development saw, or on any mesh + site (issue 21, point 4).

* ``--rooms dev|heldout``: furnished rooms drawn by :func:`lightfast.sim.validation_rooms.random_room` from seeds
  written down in ``benchmarks/results/HELDOUT.md`` before any held-out run, each at its own site and time (the
  held-out set includes low winter sun); the window is put on the wall that faces the sun's azimuth.
* ``--mesh ROOM.ply --site LAT,LON[,ALT] --time ISO8601``: your own room (PLY with per-vertex reflectance, z up,
  map frame x east / y north, or set ``--heading``).

For each room a lighting map is prepared with the defaults of ``lightfast daylight prepare``; its sky, ground and sun
irradiance (B̂/ρ at mesh vertices) is compared with ``rtrace -I`` (no ambient cache, no ``-as`` super-sampling, see
:mod:`lightfast.sim.radiance_oracle`) at ``--points`` surface points away from creases (snapped to mesh vertices)
plus ``--junction-points`` mesh vertices on a crease (where parts meet; Radiance asked 2 mm into the vertex's own
face, since exactly on the crease its query point would see through the other surface), after one best-fit scale
per component. Goal: median relative
error <= 10 %, Pearson r >= 0.98, best-fit scale within 5 % of 1, every component. Reported over all points, and
for the junction points alone.

    .venv/bin/python benchmarks/radiance_heldout.py --rooms heldout
    .venv/bin/python benchmarks/radiance_heldout.py --mesh room.ply --site 52.52,13.40,34 --time 2026-12-21T11:00Z

Writes ``benchmarks/results/radiance_<rooms>.json`` and ``.md`` (or ``--out``), atomically.
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from lightfast.data.shared import shown_command  # noqa: E402
from lightfast.daylight.lighting_map import LightingMapConfig, prepare_lighting_map  # noqa: E402
from lightfast.daylight.mesh import ReflectanceMesh, load_ply  # noqa: E402
from lightfast.daylight.sun import Site, sun_position  # noqa: E402
from lightfast.eval.radiosity_validation import TARGET_MEDIAN, TARGET_R, Agreement, compare_with_radiance  # noqa: E402
from lightfast.io import json_finite, write_text_atomic  # noqa: E402

TARGET_SCALE = 0.05


@dataclass(frozen=True)
class Room:
    name: str
    seed: int | None  # random_room seed; None: a user's mesh
    site: Site
    site_name: str
    when: dt.datetime


def _site(name: str, lat: float, lon: float, alt: float) -> tuple[str, Site]:
    return name, Site(latitude_deg=lat, longitude_deg=lon, altitude_m=alt)


_SITES = dict([_site("Freiburg", 48.0, 7.85, 278.0), _site("Oslo", 59.91, 10.75, 23.0),
               _site("Berlin", 52.52, 13.405, 34.0), _site("Sydney", -33.87, 151.21, 10.0),
               _site("Denver", 39.74, -104.99, 1609.0), _site("Helsinki", 60.17, 24.94, 15.0)])
#: (seed, site, UTC time). Development rooms: any tuning. Held-out rooms: written in HELDOUT.md before any run.
ROOM_SETS: dict[str, tuple[tuple[int, str, str], ...]] = {
    "dev": ((11, "Freiburg", "2026-06-21T10:00:00+00:00"), (12, "Oslo", "2026-01-20T11:00:00+00:00")),
    "heldout": ((90211, "Berlin", "2026-12-21T11:00:00+00:00"), (90212, "Sydney", "2026-06-21T02:00:00+00:00"),
                (90213, "Denver", "2026-09-30T21:30:00+00:00"), (90214, "Helsinki", "2027-02-10T10:30:00+00:00")),
}
_WALL_AZIMUTH = {"north": 0.0, "east": 90.0, "south": 180.0, "west": 270.0}  # outward normal, clockwise from north


def window_wall(azimuth_deg: float) -> str:
    """The wall whose outward normal is closest to the sun's azimuth."""
    return min(_WALL_AZIMUTH, key=lambda w: abs((azimuth_deg - _WALL_AZIMUTH[w] + 180.0) % 360.0 - 180.0))


def _parse_time(text: str) -> dt.datetime:
    when = dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    if when.tzinfo is None:
        raise SystemExit(f"--time {text!r} has no time zone (add Z or +HH:MM)")
    return when


def _summary(a: Agreement) -> dict[str, float]:
    return {"median_rel_err": a.median_relative_error, "pearson_r": a.pearson_r, "scale": a.scale,
            "radiance_noise": a.reference_noise}


def _passes(s: dict[str, float]) -> bool:
    return (s["median_rel_err"] <= TARGET_MEDIAN and s["pearson_r"] >= TARGET_R
            and abs(s["scale"] - 1.0) <= TARGET_SCALE)


def evaluate_room(name: str, mesh: ReflectanceMesh, site: Site, site_name: str, when: dt.datetime,
                  args: argparse.Namespace) -> dict[str, Any]:
    sun = sun_position(site, when)
    if not sun.above_horizon:
        raise SystemExit(f"{name}: the sun is below the horizon at {when.isoformat()} ({sun.elevation_deg:.1f}°)")
    config = LightingMapConfig()
    t0 = time.perf_counter()
    lmap = prepare_lighting_map(mesh, site, config, progress=sys.stderr.isatty())
    t_map = time.perf_counter() - t0
    res = compare_with_radiance(mesh, points=args.points, junction_points=args.junction_points, seed=args.seed,
                                repeats=args.repeats, config=config, sun_direction=sun.direction_map, lmap=lmap)
    junction = slice(args.points, None)
    if args.save_points is not None:  # per point, for a look at the outliers
        np.savez_compressed(args.save_points / f"{name.split()[1] if args.rooms else name}.npz",
                            **{f"{c}_ours": a.scale * a.ours for c, a in res.items()},
                            **{f"{c}_ref": a.reference for c, a in res.items()},
                            points=res["sky"].points_m, normals=res["sky"].normals, junction_from=args.points)
    out: dict[str, Any] = {
        "site": site_name, "latitude_deg": site.latitude_deg, "longitude_deg": site.longitude_deg,
        "time_utc": when.astimezone(dt.UTC).isoformat(), "sun_elevation_deg": float(sun.elevation_deg),
        "sun_azimuth_deg": float(sun.azimuth_deg), "vertices": mesh.num_vertices,
        "points": args.points, "junction_points": args.junction_points, "map_seconds": round(t_map, 1),
        "seconds": round(time.perf_counter() - t0, 1), "components": {},
    }
    for comp, a in res.items():
        s = _summary(a)
        s["pass"] = _passes(s)
        if args.junction_points:
            s["junctions"] = _summary(Agreement.of(a.ours[junction], a.reference[junction]))
            ours, ref = a.scale * a.ours[junction].mean(axis=1), a.reference[junction].mean(axis=1)
            # a junction point wrongly dark or lit: one says direct light, the other under a tenth of it
            s["junctions"]["dark_or_lit"] = int(np.sum((np.minimum(ours, ref) < 0.1 * np.maximum(ours, ref))
                                                       & (np.maximum(ours, ref) > 0.05)))
        out["components"][comp] = s
    return out


def _table(results: dict[str, dict[str, Any]], args: argparse.Namespace) -> str:
    rows = []
    for name, r in results.items():
        for comp, s in r["components"].items():
            j = s.get("junctions")
            jtext = (f"{j['median_rel_err'] * 100:.1f} % / {j['pearson_r']:.4f} / {j['dark_or_lit']}"
                     if j else "–")
            rows.append(f"| {name} | {r['site']} {r['time_utc'][:16]} (sun {r['sun_elevation_deg']:.1f}°) | {comp} | "
                        f"{s['median_rel_err'] * 100:.1f} % | {s['pearson_r']:.4f} | {s['scale']:.3f} | "
                        f"{s['radiance_noise'] * 100:.1f} % | {jtext} | {'pass' if s['pass'] else 'FAIL'} |")
    all_ok = all(s["pass"] for r in results.values() for s in r["components"].values())
    return "\n".join([
        f"# Normalized radiosity vs Radiance: {args.label}",
        "",
        f"Per room: {args.points} surface points away from creases, snapped to mesh vertices, + "
        f"{args.junction_points} mesh vertices on a crease (junctions; Radiance asked 2 mm into the vertex's own "
        "face), lighting map defaults; "
        "Radiance `rtrace -I -ab 8 -ad 2048 -aa 0 -as 0`, "
        f"{args.repeats} samples per point, the sun as 19 sub-disks of its 0.533° disk. Irradiance after one best-fit "
        "scale per component. Goal: median relative error <= 10 %, Pearson r >= 0.98, scale within 5 % of 1. "
        "Radiance's noise: the median standard error of its mean over the repeats, relative (part of the error).",
        f"`{args.command}`",
        "",
        "| room | site, time (UTC) | component | median rel. error | Pearson r | best-fit scale | Radiance's noise | "
        "junctions: median / r / dark-or-lit | goal |",
        "|---|---|---|---:|---:|---:|---:|---|---|",
        *rows,
        "",
        f"Every component of every room meets the goal: {'yes' if all_ok else 'NO'}.",
        "",
    ])


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rooms", choices=sorted(ROOM_SETS), help="a room set (seeds in benchmarks/results/HELDOUT.md)")
    p.add_argument("--mesh", type=Path, help="your own room: PLY with per-vertex reflectance")
    p.add_argument("--site", help="LAT,LON[,ALT] of --mesh")
    p.add_argument("--time", help="ISO 8601 time with zone for --mesh, e.g. 2026-12-21T11:00Z")
    p.add_argument("--heading", type=float, default=0.0, help="compass bearing of the mesh's +y axis, degrees")
    p.add_argument("--points", type=int, default=150)
    p.add_argument("--junction-points", type=int, default=50)
    p.add_argument("--repeats", type=int, default=4, help="rtrace samples averaged per point (>= 2: its noise too)")
    p.add_argument("--seed", type=int, default=1, help="seed of the point sampling")
    p.add_argument("--room", type=int, action="append", help="only this room seed of --rooms (repeatable)")
    p.add_argument("--tessellation", type=float, default=0.05, help="edge length of generated rooms, m")
    p.add_argument("--work", type=Path, help="keep each finished room here; a later call skips it (resumable)")
    p.add_argument("--save-points", type=Path, help="folder for one npz per room: points, ours, Radiance's")
    p.add_argument("--out", type=Path, help="output stem (default benchmarks/results/radiance_<rooms or mesh name>)")
    args = p.parse_args()
    args.command = shown_command("benchmarks/radiance_heldout.py", sys.argv[1:])
    if (args.rooms is None) == (args.mesh is None):
        p.error("give either --rooms or --mesh")
    results: dict[str, dict[str, Any]] = {}
    if args.mesh is not None:
        if not args.site or not args.time:
            p.error("--mesh needs --site and --time")
        try:
            lat, lon, *rest = (float(x) for x in args.site.split(","))
            site = Site(latitude_deg=lat, longitude_deg=lon, altitude_m=rest[0] if rest else 0.0,
                        heading_deg=args.heading)
        except ValueError as exc:
            p.error(f"--site {args.site!r}: {exc}")
        args.label = args.mesh.stem
        results[args.mesh.stem] = evaluate_room(args.mesh.stem, load_ply(args.mesh), site, args.site,
                                                _parse_time(args.time), args)
    else:
        from lightfast.sim.validation_rooms import random_room

        args.label = f"{args.rooms} rooms"
        for seed, site_name, time_text in ROOM_SETS[args.rooms]:
            if args.room and seed not in args.room:
                continue
            site, when = _SITES[site_name], _parse_time(time_text)
            wall = window_wall(float(sun_position(site, when).azimuth_deg))
            mesh = random_room(seed, window_wall=wall, tessellation_m=args.tessellation)
            name = f"room {seed} ({wall} window)"
            done = args.work / f"room_{seed}.json" if args.work else None
            key = {"seed": seed, "site": site_name, "time": time_text, "points": args.points,
                   "junction_points": args.junction_points, "repeats": args.repeats, "sampling_seed": args.seed,
                   "tessellation": args.tessellation}
            if done is not None and done.is_file() and json.loads(done.read_text()).get("key") == key:
                results[name] = r = json.loads(done.read_text())["result"]  # finished by an earlier call
            else:
                results[name] = r = evaluate_room(name, mesh, site, site_name, when, args)
                r["seed"] = seed
                if done is not None:
                    write_text_atomic(done, json.dumps({"key": key, "result": r}, default=_json_default) + "\n")
            print(f"{name}: {r['seconds']:.0f} s; " + ", ".join(
                f"{c} {s['median_rel_err'] * 100:.1f} %/{s['pearson_r']:.3f}/{s['scale']:.3f}"
                for c, s in r["components"].items()), flush=True)
    stem = args.out or ROOT / "benchmarks" / "results" / f"radiance_{args.rooms or args.mesh.stem}"
    text = _table(results, args)
    print(text)
    write_text_atomic(stem.with_suffix(".md"), text)
    payload = {"command": args.command, "goal": {"median_rel_err": TARGET_MEDIAN, "pearson_r": TARGET_R,
                                                 "scale_within": TARGET_SCALE}, "rooms": results}
    write_text_atomic(stem.with_suffix(".json"),
                      json.dumps(json_finite(payload), indent=2, default=_json_default) + "\n")
    return 0


def _json_default(x: Any) -> Any:
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(type(x))


if __name__ == "__main__":
    from lightfast.errors import LightfastError

    try:
        sys.exit(main())
    except (LightfastError, OSError, ValueError) as exc:  # a bad mesh, site or time; Radiance failing
        print(f"radiance_heldout: {' '.join(str(exc).split())}", file=sys.stderr)
        sys.exit(1)
