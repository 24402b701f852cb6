"""``lightfast daylight radiosity`` end to end on a mesh made here (issue 21): a PLY with 8-bit per-vertex
reflectance and open edges (a floor and a slab hovering over half of it, no walls) goes through ``lightfast daylight
prepare`` and ``lightfast daylight radiosity``; the npz, the vertex-coloured PLY and the per-point values agree
with the sun at that time (a sunlit floor point against one in the slab's shadow, the sunlit irradiance equal to
the sine of the sun's elevation). Bad input gives one line and exit code 1."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from lightfast.daylight.errors import RadiosityFileError
from lightfast.daylight.radiosity_export import DEFAULT_SCALES, FORMAT_VERSION, load_points, load_radiosity, tone_map
from lightfast.daylight.sun import FREIBURG, sun_position
from test.helpers import LIGHTFAST, run_bounded

TIME = "2021-06-21T13:30:00+02:00"  # Freiburg, near solar noon: the sun ~65° up in the south (−y)
FLOOR_RHO, SLAB_RHO = (153, 128, 102), (200, 200, 200)


def grid(origin, u, v, n: int) -> tuple[np.ndarray, np.ndarray]:
    """An n × n quad grid ``origin + [0,1] u + [0,1] v`` facing ``u × v``: vertices, faces."""
    o, u, v = (np.asarray(x, dtype=float) for x in (origin, u, v))
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    pts = (o + (i[..., None] / n) * u + (j[..., None] / n) * v).reshape(-1, 3)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return pts, faces


def write_scene(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Floor [0, 2]² (z = 0) and a 5 cm slab over x ∈ [0, 1], 1 m up; ASCII PLY with uchar colours."""
    parts = [(grid((0, 0, 0), (2, 0, 0), (0, 2, 0), 20), FLOOR_RHO)]
    lo, hi = np.array([0.0, 0.0, 1.0]), np.array([1.0, 2.0, 1.05])
    for axis in range(3):
        i, j = (axis + 1) % 3, (axis + 2) % 3
        size = hi - lo
        ei, ej = np.eye(3)[i] * size[i], np.eye(3)[j] * size[j]
        top = lo.copy()
        top[axis] = hi[axis]
        parts += [(grid(top, ei, ej, 4), SLAB_RHO), (grid(lo, ej, ei, 4), SLAB_RHO)]  # outward faces
    verts, faces, colours, offset = [], [], [], 0
    for (v, f), rgb in parts:
        verts.append(v)
        faces.append(f + offset)
        colours.append(np.tile(rgb, (len(v), 1)))
        offset += len(v)
    v, f, c = np.concatenate(verts), np.concatenate(faces), np.concatenate(colours)
    lines = ["ply", "format ascii 1.0", "comment made by the test", f"element vertex {len(v)}", "property float x",
             "property float y", "property float z", "property uchar red", "property uchar green",
             "property uchar blue", f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
    lines += [f"{x:.6f} {y:.6f} {z:.6f} {r} {g} {b}" for (x, y, z), (r, g, b) in zip(v, c, strict=True)]
    lines += [f"3 {a} {b} {cc}" for a, b, cc in f]
    path.write_text("\n".join(lines) + "\n")
    return v, f


def read_ply_colours(path: Path) -> tuple[np.ndarray, np.ndarray]:
    raw = path.read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    header = raw[:end].decode()
    n = int(header.split("element vertex ")[1].split()[0])
    assert "property uchar red" in header and "format binary_little_endian" in header
    dtype = np.dtype([("xyz", "<f4", (3,)), ("n", "<f4", (3,)), ("rgb", "u1", (3,))])
    vert = np.frombuffer(raw, dtype=dtype, count=n, offset=end)
    return vert["xyz"].astype(np.float64), vert["rgb"]


@pytest.fixture(scope="module")
def prepared(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    d = tmp_path_factory.mktemp("radiosity_cli")
    v, _ = write_scene(d / "scene.ply")
    FREIBURG.to_yaml(d / "site.yaml")
    made = run_bounded([*LIGHTFAST, "daylight", "prepare", str(d / "scene.ply"), str(d / "site.yaml"),
                        str(d / "map"), "--patch-size", "0.5", "--sky-directions", "256"], timeout_s=300)
    assert made.returncode == 0, made.stderr
    return d, v


def nearest(points: np.ndarray, p: tuple[float, float, float]) -> int:
    return int(np.argmin(np.linalg.norm(points - np.asarray(p), axis=1)))


def test_radiosity_command_end_to_end(prepared: tuple[Path, np.ndarray]) -> None:
    d, verts = prepared
    (d / "points.txt").write_text("# x y z nx ny nz\n1.5 1.0 0 0 0 1\n0.5,1.5,0, 0,0,1\n2.0 0.55 0.0 0 0 1\n"
                                  "0.5 1.0 1.05 0 0 1   # the slab's top\n")
    out = d / "out" / "scene"
    ran = run_bounded([*LIGHTFAST, "daylight", "radiosity", str(d / "map"), "--time", TIME, "--points",
                       str(d / "points.txt"), "-o", str(out)], timeout_s=300)
    assert ran.returncode == 0, ran.stderr
    assert "wrote" in ran.stdout and "sun elevation" in ran.stdout

    arrays, meta = load_radiosity(out.with_suffix(".npz"))
    V = len(verts)
    assert meta["version"] == FORMAT_VERSION and meta["sun"]["above_horizon"] and meta["time"] == TIME
    assert all(arrays[c].shape == (V, 3) and arrays[c].dtype == np.float32 for c in ("sun", "sky", "ground"))
    np.testing.assert_allclose(arrays["vertices_m"], verts, atol=1e-6)  # the file's vertex order is kept
    sunlit, shaded = nearest(verts, (1.5, 1.0, 0.0)), nearest(verts, (0.5, 1.5, 0.0))
    rho = np.asarray(FLOOR_RHO) / 255
    elevation = float(sun_position(FREIBURG, np.datetime64("2021-06-21T11:30:00")).elevation_deg)
    assert 60 < elevation < 70
    np.testing.assert_allclose(arrays["sun"][sunlit], rho * math.sin(math.radians(elevation)), rtol=0.03)
    assert np.all(arrays["sun"][shaded] < 0.1 * arrays["sun"][sunlit])
    assert np.all(arrays["sky"][sunlit] > arrays["sky"][shaded])
    assert np.all(arrays["sky"] <= arrays["reflectance"] * math.pi * 1.001)  # no more than an open sky's π

    xyz, rgb = read_ply_colours(out.with_suffix(".ply"))
    np.testing.assert_allclose(xyz, verts, atol=1e-5)
    assert rgb[sunlit].astype(int).sum() > rgb[shaded].astype(int).sum() + 100

    e = arrays["points_irradiance"]  # (N, component, channel)
    assert e.shape == (4, 3, 3)
    np.testing.assert_allclose(e[0, 0], math.sin(math.radians(elevation)), rtol=0.03)  # unobstructed floor
    assert np.all(e[1, 0] < 0.1 * e[0, 0])  # in the slab's shadow
    assert np.all(e[2, 0] > 0.9 * e[0, 0])  # on the floor's open edge: fine
    np.testing.assert_allclose(e[3, 0], math.sin(math.radians(elevation)), rtol=0.03)  # the slab's top
    rows = (d / "out" / "scene.points.csv").read_text().splitlines()
    assert len(rows) == 5 and rows[0].startswith("x,y,z,nx,ny,nz,distance_m,E_sun_r")


def one_line_error(result) -> str:
    assert result.returncode == 1, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lightfast: error:"), result.stderr
    return lines[0]


def test_radiosity_command_errors(prepared: tuple[Path, np.ndarray], tmp_path: Path) -> None:
    d, _ = prepared
    cmd = [*LIGHTFAST, "daylight", "radiosity", str(d / "map"), "-o", str(tmp_path / "x")]
    assert "bad --time" in one_line_error(run_bounded([*cmd, "--time", "noon"], timeout_s=120))
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    assert "bad.txt:1: expected 'x y z nx ny nz'" in one_line_error(
        run_bounded([*cmd, "--points", str(tmp_path / "bad.txt")], timeout_s=120))
    (tmp_path / "off.txt").write_text("1.0 1.0 0.5 0 0 1\n")  # in mid air
    assert "farther than" in one_line_error(run_bounded([*cmd, "--time", TIME, "--points", str(tmp_path / "off.txt")],
                                                        timeout_s=120))
    old = tmp_path / "old_map"
    old.mkdir()
    for p in (d / "map").iterdir():
        (old / p.name).write_bytes(p.read_bytes())
    meta = json.loads((old / "metadata.json").read_text())
    meta["version"] = 1
    (old / "metadata.json").write_text(json.dumps(meta))
    line = one_line_error(run_bounded([*LIGHTFAST, "daylight", "radiosity", str(old), "-o", str(tmp_path / "y")],
                                      timeout_s=120))
    assert "format version 1 is not supported" in line and "prepare it again" in line
    assert not list(tmp_path.glob("x*")) and not list(tmp_path.glob("y*"))  # nothing written


def test_tone_map_points_file_and_format(tmp_path: Path) -> None:
    assert DEFAULT_SCALES == (800.0, 30.0, 30.0)
    rgb = tone_map(np.array([[0.0, 50.0, 100.0], [200.0, 1e-4, -1.0]]), white=100.0)
    np.testing.assert_array_equal(rgb, [[0, 188, 255], [255, 0, 0]])  # sRGB(0.5) = 0.735
    (tmp_path / "p.txt").write_text("\n# only a comment\n0 0 0 0 0 2\n")
    _, n = load_points(tmp_path / "p.txt")
    np.testing.assert_array_equal(n, [[0, 0, 1]])
    with pytest.raises(RadiosityFileError, match="no points"):
        load_points(tmp_path / "nothing.txt" if (tmp_path / "nothing.txt").write_text("# none\n") else None)
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(RadiosityFileError, match="not a lightfast radiosity file"):
        load_radiosity(tmp_path / "other.npz")
