"""``lightfast daylight …``: sun position, lighting maps and their radiosity at a time."""
from __future__ import annotations

import argparse
import datetime as dt
import sys
import time
from pathlib import Path

from lightfast.errors import LightfastError

NAME = "daylight"
HELP = "daylight illumination: sun position, lighting maps, radiosity"


def _cmd_daylight_prepare(args: argparse.Namespace) -> int:
    from lightfast.config import config_from_mapping
    from lightfast.daylight.lighting_map import LightingMapConfig, prepare_lighting_map
    from lightfast.daylight.mesh import load_ply
    from lightfast.daylight.openings import load_openings
    from lightfast.daylight.sun import Site

    overrides = {k: v for k, v in (("patch_size_m", args.patch_size), ("normal_merge_deg", args.normal_merge),
                                   ("sky_directions", args.sky_directions),
                                   ("sun_samples", args.sun_samples), ("iterations", args.iterations))
                 if v is not None}
    config = config_from_mapping(LightingMapConfig, overrides)
    mesh = load_ply(args.mesh)
    site = Site.from_yaml(args.site)
    openings = load_openings(args.openings) if args.openings else None
    start = time.monotonic()
    lmap = prepare_lighting_map(mesh, site, config, openings=openings, progress=sys.stderr.isatty())
    path = lmap.save(args.out, overwrite=args.overwrite)
    size_mb = sum(p.stat().st_size for p in Path(path).iterdir()) / 1e6
    print(f"wrote {path}: {mesh.num_vertices} vertices, {lmap.patches.count} patches, {size_mb:.1f} MB, "
          f"{time.monotonic() - start:.1f} s")
    return 0


def _time(text: str | None, zone: dt.tzinfo) -> dt.datetime:
    """``--time``: ISO 8601 (without an offset: in ``zone``, the site's time zone); default now."""
    try:
        when = dt.datetime.fromisoformat(text) if text else dt.datetime.now(dt.UTC)
    except ValueError as exc:
        raise LightfastError(f"bad --time {text!r}: {exc} (use ISO 8601 with an offset)") from None
    return when.replace(tzinfo=zone) if when.tzinfo is None else when


def _cmd_daylight_sun(args: argparse.Namespace) -> int:
    from lightfast.daylight.sun import Site, sun_position

    site = Site.from_yaml(args.site)
    when = _time(args.time, site.zone)
    sun = sun_position(site, when)
    d = sun.direction_map
    print(f"{when.isoformat()}: azimuth {float(sun.azimuth_deg):.4f}°, elevation {float(sun.elevation_deg):.4f}°, "
          f"direction in map ({d[0]:.5f}, {d[1]:.5f}, {d[2]:.5f})" + ("" if sun.above_horizon else ", below horizon"))
    return 0


def _cmd_daylight_radiosity(args: argparse.Namespace) -> int:
    from lightfast.daylight.lighting_map import LightingMap
    from lightfast.daylight.radiosity_export import (
        DEFAULT_SCALES,
        at_points,
        load_points,
        locate_points,
        radiosity_at,
        write_radiosity,
    )

    if args.white is not None and not args.white > 0:
        raise LightfastError(f"--white must be > 0, got {args.white}")
    sun_s, sky_s, ground_s = args.scales if args.scales else DEFAULT_SCALES
    scales = (float(sun_s), float(sky_s), float(ground_s))
    if any(not s >= 0 for s in scales):
        raise LightfastError(f"--scales must be >= 0, got {scales}")
    points = load_points(args.points) if args.points else None  # a bad file fails before the work
    lmap = LightingMap.load(args.map)
    when = _time(args.time, lmap.site.zone)
    surface = locate_points(lmap.mesh, *points) if points is not None else None
    start = time.monotonic()
    result = radiosity_at(lmap, when, progress=sys.stderr.isatty())
    values = at_points(lmap.mesh, result, *points, surface) if points is not None else None
    paths = write_radiosity(args.out, lmap, result, scales=scales, white=args.white, points=values,
                            map_path=str(args.map))
    sun = result.sun
    where = (f"sun elevation {float(sun.elevation_deg):.2f}°, azimuth {float(sun.azimuth_deg):.2f}°"
             if sun.above_horizon else f"sun below the horizon ({float(sun.elevation_deg):.2f}°): B̂_sun = 0")
    print(f"wrote {', '.join(str(p) for p in paths.values())}: {lmap.num_vertices} vertices"
          + (f", {len(values.points_m)} points" if values is not None else "")
          + f" at {when.isoformat()} ({where}), {time.monotonic() - start:.1f} s")
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """``lightfast daylight`` and its subcommands."""
    daylight = subparsers.add_parser(NAME, help=HELP)
    daylight_sub = daylight.add_subparsers(dest="daylight_command", required=True, metavar="DAYLIGHT_COMMAND")
    p = daylight_sub.add_parser("prepare", help="build a lighting map (patches, transport, sky and ground radiosity)")
    p.add_argument("mesh", help="PLY mesh with per-vertex reflectance (red green blue in [0,1])")
    p.add_argument("site", help="site YAML (latitude_deg, longitude_deg, altitude_m, heading_deg, timezone)")
    p.add_argument("out", help="lighting map directory to create")
    p.add_argument("--patch-size", type=float, help="patch edge length in metres (default 0.1)")
    p.add_argument("--normal-merge", type=float, help="face-normal bins within this many degrees form one patch "
                   "inside a cell (default 30; 0 keeps every 10° bin apart)")
    p.add_argument("--sky-directions", type=int, help="directional lights over the sphere (default 2048)")
    p.add_argument("--sun-samples", type=int, help="directions inside the solar disk (default 8)")
    p.add_argument("--iterations", type=int, help="Jacobi iterations of Eq. 2 (default: until converged)")
    p.add_argument("--openings", help="YAML of the room's window openings: outdoor light then enters only through "
                   "them, not through holes of a reconstructed mesh (format: lightfast.daylight.openings)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing map")
    p.set_defaults(func=_cmd_daylight_prepare)
    p = daylight_sub.add_parser("sun", help="sun position at a site and time")
    p.add_argument("site", help="site YAML")
    p.add_argument("--time", help="ISO 8601 time (default now); without an offset the site's time zone is used")
    p.set_defaults(func=_cmd_daylight_sun)
    p = daylight_sub.add_parser(
        "radiosity", help="normalized radiosity of sun, sky and ground at a time: OUT.npz and a vertex-coloured "
        "OUT.ply (lightfast.daylight.radiosity_export)")
    p.add_argument("map", help="lighting map directory (lightfast daylight prepare)")
    p.add_argument("-o", "--out", required=True, help="output path without suffix: writes OUT.npz, OUT.ply "
                   "(and OUT.points.csv with --points)")
    p.add_argument("--time", help="ISO 8601 time (default now); without an offset the map site's time zone is used")
    p.add_argument("--points", help="text file, one surface point per line: 'x y z nx ny nz' (metres, map frame; "
                   "the normal of the side the point is on): radiosity and irradiance there")
    p.add_argument("--scales", type=float, nargs=3, metavar=("SUN", "SKY", "GROUND"),
                   help="brightness of the PLY colours: solar normal irradiance W/m², sky and ground radiance "
                   "W/(m² sr) (default 800 30 30, a clear day)")
    p.add_argument("--white", type=float, help="radiosity in W/m² shown as white in the PLY (default: the 99th "
                   "percentile of the vertices' brightest channel)")
    p.set_defaults(func=_cmd_daylight_radiosity)
