"""Lighting map files and bad input: each gives one clear error."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lightfast.daylight.errors import LightingMapError, LightingMapVersionError, MeshError, SiteError
from lightfast.daylight.lighting_map import FORMAT_VERSION, LightingMap, LightingMapConfig, prepare_lighting_map
from lightfast.daylight.mesh import ReflectanceMesh, as_mesh, load_ply, save_ply
from lightfast.daylight.sun import FREIBURG, Site
from lightfast.sim.validation_rooms import box_room_with_window
from test.helpers import LIGHTFAST, run_bounded
from test.unit.daylight_scenes import closed_box

CONFIG = LightingMapConfig(patch_size_m=0.5, sky_directions=128, hemisphere_rays=16)


def test_save_load_round_trip(tiny_lighting_map: Path) -> None:
    lmap = LightingMap.load(tiny_lighting_map)
    again = LightingMap.load(tiny_lighting_map, mesh=load_ply(tiny_lighting_map / "mesh.ply"))
    np.testing.assert_array_equal(lmap.sky_radiosity, again.sky_radiosity)
    np.testing.assert_array_equal(lmap.transport.gather, again.transport.gather)
    assert lmap.site == FREIBURG
    assert lmap.sky_radiosity.shape == (lmap.num_vertices, 3) and lmap.sky_radiosity.max() > 0
    meta = json.loads((tiny_lighting_map / "metadata.json").read_text())
    assert meta["mesh_sha256"] == lmap.mesh.content_hash and meta["version"] == FORMAT_VERSION == 2


def test_fresh_prepare_equals_loaded(tmp_path: Path) -> None:
    lmap = prepare_lighting_map(closed_box(n=4), FREIBURG, CONFIG)
    loaded = LightingMap.load(lmap.save(tmp_path / "m"))
    np.testing.assert_allclose(loaded.transport.gather, lmap.transport.gather, rtol=1e-6)
    np.testing.assert_allclose(loaded.ground_radiosity, lmap.ground_radiosity)


def test_maps_keep_their_normals(tmp_path: Path) -> None:
    """Smoothed input normals (tilted 20° off the faces) survive saving: the loaded map's sun radiosity, computed
    after loading, uses the same normals as the sky and ground radiosity computed while preparing."""
    from lightfast.daylight.sun_update import sun_radiosity

    box = closed_box(n=4)
    tilt = np.array([np.sin(np.radians(20)), 0.0, 0.0])
    smooth = box.vertex_normals + tilt
    mesh = ReflectanceMesh(box.vertices_m, box.faces, box.reflectance, smooth)
    lmap = prepare_lighting_map(mesh, FREIBURG, CONFIG)
    loaded = LightingMap.load(lmap.save(tmp_path / "m"))
    np.testing.assert_array_equal(loaded.mesh.vertex_normals, lmap.mesh.vertex_normals)
    assert not np.allclose(loaded.mesh.vertex_normals, box.vertex_normals, atol=0.1)  # not recomputed from faces
    np.testing.assert_array_equal(loaded.ray_origins.offset_m, lmap.ray_origins.offset_m)
    np.testing.assert_array_equal(loaded.ray_origins.covered, lmap.ray_origins.covered)
    sun = np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])
    np.testing.assert_array_equal(sun_radiosity(loaded, sun), sun_radiosity(lmap, sun))


def test_a_map_of_an_older_format_is_refused_with_one_line(tiny_lighting_map: Path, tmp_path: Path) -> None:
    old = copy_map(tiny_lighting_map, tmp_path / "v1")
    meta = json.loads((old / "metadata.json").read_text())
    meta["version"] = 1
    (old / "metadata.json").write_text(json.dumps(meta))
    with pytest.raises(LightingMapVersionError) as info:
        LightingMap.load(old)
    message = str(info.value)
    assert "\n" not in message and "format version 1 is not supported" in message
    assert f"reads version {FORMAT_VERSION}" in message and "lightfast daylight prepare" in message
    assert isinstance(info.value, LightingMapError)


def copy_map(src: Path, dst: Path) -> Path:
    dst.mkdir()
    for p in src.iterdir():
        (dst / p.name).write_bytes(p.read_bytes())
    return dst


def test_damaged_maps_are_refused(tiny_lighting_map: Path, tmp_path: Path) -> None:
    truncated = copy_map(tiny_lighting_map, tmp_path / "truncated")
    npz = truncated / "lighting_map.npz"
    npz.write_bytes(npz.read_bytes()[: npz.stat().st_size // 2])
    with pytest.raises(LightingMapError, match="damaged or truncated"):
        LightingMap.load(truncated)
    old = copy_map(tiny_lighting_map, tmp_path / "old")
    meta = json.loads((old / "metadata.json").read_text())
    meta["version"] = 0
    (old / "metadata.json").write_text(json.dumps(meta))
    with pytest.raises(LightingMapError, match="format version 0 is not supported"):
        LightingMap.load(old)
    with pytest.raises(LightingMapError, match="made for another mesh"):
        LightingMap.load(tiny_lighting_map, mesh=closed_box(n=3))
    with pytest.raises(LightingMapError, match="no lighting map"):
        LightingMap.load(tmp_path / "nothing")
    # metadata of the wrong shape (each raised AttributeError / TypeError through the node before)
    good = json.loads((tiny_lighting_map / "metadata.json").read_text())
    for i, (bad, message) in enumerate([
        ([1, 2], "must be a JSON object"),
        ({**good, "config": [1, 2]}, "bad metadata"),
        ({**good, "site": "Freiburg"}, "bad metadata"),
        ({**good, "counts": {"patches": "many", "vertices": None}}, "inconsistent"),
        ({**good, "counts": None}, "inconsistent"),
        ('{"format": "lightfast-lighting-map", "vers', "unreadable"),
    ]):
        damaged = copy_map(tiny_lighting_map, tmp_path / f"meta{i}")
        (damaged / "metadata.json").write_text(bad if isinstance(bad, str) else json.dumps(bad))
        with pytest.raises(LightingMapError, match=message):
            LightingMap.load(damaged)
    with pytest.raises(LightingMapError, match="exists"):
        LightingMap.load(tiny_lighting_map).save(tiny_lighting_map)


def write_ascii_ply(path: Path, vertices, faces, colors=None, color_type: str = "float") -> Path:
    lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}", "property float x", "property float y",
             "property float z"]
    if colors is not None:
        lines += [f"property {color_type} {c}" for c in ("red", "green", "blue")]
    lines += [f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    for i, v in enumerate(vertices):
        lines.append(" ".join(map(str, [*v, *(colors[i] if colors is not None else [])])))
    lines += [f"3 {a} {b} {c}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


TRI = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]


def written(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def test_ply_io(tmp_path: Path) -> None:
    mesh = load_ply(write_ascii_ply(tmp_path / "a.ply", TRI, [[0, 1, 2], [1, 3, 2]], [[0.5, 0.25, 0.125]] * 4))
    np.testing.assert_allclose(mesh.reflectance, [[0.5, 0.25, 0.125]] * 4)
    uchar = load_ply(write_ascii_ply(tmp_path / "u.ply", TRI, [[0, 1, 2]], [[255, 0, 51]] * 4, color_type="uchar"))
    np.testing.assert_allclose(uchar.reflectance[0], [1.0, 0.0, 0.2])
    save_ply(mesh, tmp_path / "b.ply")
    back = load_ply(tmp_path / "b.ply")
    assert back.content_hash == mesh.content_hash
    np.testing.assert_array_equal(back.faces, mesh.faces)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: write_ascii_ply(p, TRI, [[0, 1, 2]]), "carry no reflectance"),
        (lambda p: write_ascii_ply(p, TRI, [[0, 1, 2]], [[1.2, 0.5, 0.5]] * 4), r"reflectance must lie in \[0, 1\]"),
        (lambda p: write_ascii_ply(p, TRI, [[0, 1, 7]], [[0.5] * 3] * 4), r"face indices must lie in"),
        (lambda p: written(p, b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                              b"property float y\nproperty float z\nelement face 1\n"
                              b"property list uchar int vertex_indices\nend_header\n\x00\x00"), "truncated"),
        (lambda p: written(p, b"solid not a ply\n"), "not a PLY file"),
        (lambda p: p, "cannot read mesh"),
    ],
    ids=["no-reflectance", "reflectance-range", "bad-index", "truncated", "not-ply", "missing"],
)
def test_bad_meshes(tmp_path: Path, make, message: str) -> None:
    with pytest.raises(MeshError, match=message):
        load_ply(make(tmp_path / "m.ply"))


def test_bad_topology_is_refused_by_prepare() -> None:
    degenerate = as_mesh(TRI + [[2, 0, 0]], [[0, 1, 2], [0, 1, 4]], 0.5)  # vertices 0, 1, 4 are collinear
    with pytest.raises(LightingMapError, match="degenerate triangles"):
        prepare_lighting_map(degenerate, FREIBURG, CONFIG)
    fin = as_mesh(TRI + [[0.5, 0, 1], [0.5, 0, -1]], [[0, 1, 2], [0, 4, 1], [0, 1, 5]], 0.5)  # an edge of 3 faces
    with pytest.raises(LightingMapError, match="non-manifold edges"):
        prepare_lighting_map(fin, FREIBURG, CONFIG)
    with pytest.raises(MeshError, match="reflectance must lie"):
        ReflectanceMesh(np.zeros((3, 3)), np.array([[0, 1, 2]]), np.full((3, 3), -0.1))


def test_site_validation(tmp_path: Path) -> None:
    with pytest.raises(SiteError, match="latitude_deg"):
        Site(latitude_deg=95.0, longitude_deg=0.0)
    bad = tmp_path / "site.yaml"
    bad.write_text("latitude_deg: -91\nlongitude_deg: 7.8\n")
    with pytest.raises(SiteError, match=r"site\.yaml"):
        Site.from_yaml(bad)


def test_prepare_cli(tmp_path: Path) -> None:
    mesh = tmp_path / "room.ply"
    save_ply(box_room_with_window(tessellation_m=0.5), mesh)
    site = tmp_path / "site.yaml"
    FREIBURG.to_yaml(site)
    out = tmp_path / "map"
    ok = run_bounded([*LIGHTFAST, "daylight", "prepare", str(mesh), str(site), str(out), "--patch-size", "0.6",
                      "--sky-directions", "128"], timeout_s=300)
    assert ok.returncode == 0, ok.stderr
    assert "patches" in ok.stdout and LightingMap.load(out).num_vertices > 0
    again = run_bounded([*LIGHTFAST, "daylight", "prepare", str(mesh), str(site), str(out)], timeout_s=300)
    assert again.returncode == 1 and again.stderr.startswith("lightfast: error:") and "exists" in again.stderr
    bad = run_bounded([*LIGHTFAST, "daylight", "prepare", str(tmp_path / "nope.ply"), str(site), str(out)],
                      timeout_s=60)
    assert bad.returncode == 1 and len(bad.stderr.strip().splitlines()) == 1 and "cannot read mesh" in bad.stderr
    sun = run_bounded([*LIGHTFAST, "daylight", "sun", str(site), "--time", "2021-03-20T11:36:00+00:00"],
                      timeout_s=60)
    assert sun.returncode == 0 and "azimuth 179.99" in sun.stdout and "elevation 42.04" in sun.stdout


def test_the_evaluation_prepares_an_outdated_map_again(tmp_path: Path) -> None:
    """`lightfast eval daylight` keeps its maps in maps_dir/<scene>: one made by an older lightfast (format
    version) is prepared again instead of stopping the evaluation."""
    from lightfast.eval.daylight import scene_lighting_map

    scenes = tmp_path / "sim" / "scenes"
    scenes.mkdir(parents=True)
    save_ply(closed_box(n=3), scenes / "S.map.ply")
    FREIBURG.to_yaml(scenes / "S.site.yaml")
    maps = tmp_path / "maps"
    first = scene_lighting_map("S", tmp_path / "sim", maps, False, CONFIG)
    meta = json.loads((maps / "S" / "metadata.json").read_text())
    meta["version"] = 1
    (maps / "S" / "metadata.json").write_text(json.dumps(meta))
    again = scene_lighting_map("S", tmp_path / "sim", maps, False, CONFIG)
    assert json.loads((maps / "S" / "metadata.json").read_text())["version"] == FORMAT_VERSION
    np.testing.assert_allclose(again.sky_radiosity, first.sky_radiosity)
