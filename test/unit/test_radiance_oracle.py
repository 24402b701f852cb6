"""Unit tests of lightfast.sim.radiance_oracle (Radiance as the reference) and lightfast.sim.validation_rooms.

Closed-form checks: an open horizontal floor under the uniform sky receives π, under the sun sin(elevation); a
room with a window has a sun patch, shadows, and sky light that fades away from the window. The room builders are
checked for closure and normal orientation with Embree rays.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from lightfast.daylight.mesh import as_mesh, merge_meshes
from lightfast.errors import LightfastError
from lightfast.raycast import RayCaster
from lightfast.sim.errors import RadianceError, ValidationRoomError
from lightfast.sim.radiance_oracle import (
    SUN_SOLID_ANGLE_SR,
    light_description,
    radiance_available,
    radiance_irradiance,
    radiance_irradiance_with_error,
    scene_description,
)
from lightfast.sim.validation_rooms import (
    box_room_with_window,
    furnished_room,
    random_room,
    sample_crease_vertices,
    sample_surface_points,
)

pytestmark = pytest.mark.skipif(
    not radiance_available(), reason="Radiance binaries (oconv, rtrace from pyradiance) not found"
)

SIZE = (4.5, 4.8, 2.9)
WINDOW = (1.6, 1.5, 0.8, "south")  # x in [1.45, 3.05], z in [0.8, 2.3] on the wall y = 0, 0.2 m thick


def sun_vector(elevation_deg: float, towards: tuple[float, float]) -> np.ndarray:
    """Unit vector towards a sun at ``elevation_deg`` above the horizon in the horizontal direction ``towards``."""
    h = np.array([*towards, 0.0]) / np.hypot(*towards)
    e = math.radians(elevation_deg)
    return math.cos(e) * h + np.array([0.0, 0.0, math.sin(e)])


@pytest.fixture(scope="module")
def open_floor():
    """A 20 × 20 m horizontal quad at z = 0 (reflectance 0.5), nothing else."""
    return as_mesh([[-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0]], [[0, 1, 2], [0, 2, 3]], (0.5, 0.5, 0.5))


@pytest.fixture(scope="module")
def room():
    return box_room_with_window(size_m=SIZE, window=WINDOW, tessellation_m=0.2)


# ---------------------------------------------------------------------------------------------------------------
# closed-form scenes


def test_open_floor_under_uniform_sky_receives_pi(open_floor) -> None:
    p = [[0.0, 0.0, 0.0], [2.0, -3.0, 0.0]]
    n = [[0.0, 0.0, 1.0]] * 2
    sky = radiance_irradiance(open_floor, p, n, component="sky")
    assert sky.shape == (2, 3)
    np.testing.assert_allclose(sky, math.pi, rtol=0.02)
    ground = radiance_irradiance(open_floor, p, n, component="ground", ambient_bounces=2)
    np.testing.assert_allclose(ground, 0.0, atol=1e-6)  # the floor hides the glowing lower hemisphere


def test_open_floor_under_sun_receives_sin_elevation(open_floor) -> None:
    s = sun_vector(30.0, (1.0, 0.3))
    p = [[0.0, 0.0, 0.0]]
    E = radiance_irradiance(open_floor, p, [[0.0, 0.0, 1.0]], component="sun", sun_direction=s)
    np.testing.assert_allclose(E, 0.5, rtol=0.02)
    # a disk of sub-suns gives the same unshadowed irradiance
    E61 = radiance_irradiance(open_floor, p, [[0.0, 0.0, 1.0]], component="sun", sun_direction=s,
                              sun_disk_samples=61)
    np.testing.assert_allclose(E61, 0.5, rtol=0.005)
    # a sensor facing the sun receives the normal irradiance 1 plus a little light from the floor below
    Ef = radiance_irradiance(open_floor, [[0.0, 0.0, 1.0]], [s], component="sun", sun_direction=s)
    assert 1.0 < Ef[0, 0] < 1.1


def test_vertical_sensor_sees_half_the_sky_and_ground() -> None:
    """A vertical sensor in empty space: π/2 from the sky, π/2 from the ground, and the sun's cosine."""
    far = as_mesh([[100, 100, -50], [101, 100, -50], [100, 101, -50]], [[0, 1, 2]], (0.0, 0.0, 0.0))
    p, n = [[0.0, 0.0, 0.0]], [[1.0, 0.0, 0.0]]
    for component in ("sky", "ground"):
        E = radiance_irradiance(far, p, n, component=component, ambient_bounces=1)
        np.testing.assert_allclose(E, math.pi / 2, rtol=0.02)
    s = sun_vector(20.0, (1.0, 0.0))
    E = radiance_irradiance(far, p, n, component="sun", sun_direction=s, ambient_bounces=0)
    np.testing.assert_allclose(E, math.cos(math.radians(20.0)), rtol=1e-3)


def test_penumbra_with_sun_disk_samples() -> None:
    """Behind a straight edge the visible fraction of the sun disk ramps from 0 to 1 over 0.0093 × distance."""
    floor = as_mesh([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], [[0, 1, 2], [0, 2, 3]], (0.0, 0.0, 0.0))
    plate = as_mesh([[-5, -5, 3], [0, -5, 3], [0, 5, 3], [-5, 5, 3]], [[0, 2, 1], [0, 3, 2]], (0.0, 0.0, 0.0))
    scene = merge_meshes([floor, plate])
    r = 3.0 * math.tan(math.radians(0.2665))  # penumbra half-width on the floor
    u = np.array([-1.5, -0.5, 0.0, 0.5, 1.5])
    pts = np.stack([u * r, np.zeros(5), np.zeros(5)], axis=1)
    n = np.tile([0.0, 0.0, 1.0], (5, 1))
    c = np.clip(u, -1.0, 1.0)
    exact = 1.0 - (np.arccos(c) - c * np.sqrt(1.0 - c * c)) / math.pi
    E = radiance_irradiance(scene, pts, n, component="sun", sun_direction=[0, 0, 1], sun_disk_samples=61,
                            ambient_bounces=0)[:, 0]
    np.testing.assert_allclose(E, exact, atol=0.05)
    sharp = radiance_irradiance(scene, pts, n, component="sun", sun_direction=[0, 0, 1], ambient_bounces=0)[:, 0]
    np.testing.assert_array_equal(sharp, [0.0, 0.0, 0.0, 1.0, 1.0])


# ---------------------------------------------------------------------------------------------------------------
# the room with a window


def test_room_sun_patch_and_shadow(room) -> None:
    """Sun from the south at 30°: the floor 1.39-3.78 m from the window wall is lit (the rays pass the 0.8-2.3 m
    opening through the 0.2 m reveal), nearer floor is in the wall's shadow."""
    s = sun_vector(30.0, (0.0, -1.0))
    p = np.array([[2.25, 2.5, 0.0], [2.25, 1.0, 0.0], [2.25, 4.5, 0.0]])
    n = np.tile([0.0, 0.0, 1.0], (3, 1))
    E, err = radiance_irradiance_with_error(room, p, n, component="sun", sun_direction=s, repeats=4)
    lit, shade, back = E[:, 1]
    assert np.all(err[:, 1] < 0.1 * E[:, 1] + 1e-3)
    indirect = lit - 0.5  # cos(incidence) = sin 30°
    assert 0.005 < indirect < 0.1, E
    assert 0.0 < shade < 0.1 * lit
    assert 0.0 < back < 0.1 * lit
    assert np.all(E > 0.0)


def test_room_sky_is_positive_and_largest_near_window(room) -> None:
    p, n = sample_surface_points(room, 24, seed=7, exclude_near_edges_m=0.05)
    probes = np.array([[2.25, 0.6, 0.0], [2.25, 4.4, 0.0]])
    pts = np.concatenate([p, probes])
    nrm = np.concatenate([n, np.tile([0.0, 0.0, 1.0], (2, 1))])
    # 8 independent estimates: one estimate of the dim far probe scatters by ±15 % between runs (rtrace's two
    # processes draw other samples), which put the near/far ratio (3.6 with 32 estimates) at 2.9 once in CI
    E = radiance_irradiance(room, pts, nrm, component="sky", ambient_divisions=1024, repeats=8)
    assert np.all(E > 0.0)
    near_probe, far_probe = E[-2:, 1]
    assert near_probe > 3.0 * far_probe
    lo, hi = np.array([1.45, -0.2, 0.8]), np.array([3.05, 0.0, 2.3])  # the opening
    dist = np.linalg.norm(np.maximum(0.0, np.maximum(lo - pts, pts - hi)), axis=1)
    order = np.argsort(dist)
    third = len(pts) // 3
    assert E[order[:third], 1].mean() > 2.0 * E[order[-third:], 1].mean()
    assert dist[np.argmax(E[:, 1])] < 0.5
    # the slightly coloured surfaces give coloured light: the floor is reddish, so red > blue on the ceiling
    ceiling = np.flatnonzero(nrm[:, 2] < -0.99)
    if len(ceiling):
        assert np.all(E[ceiling, 0] > E[ceiling, 2])


# ---------------------------------------------------------------------------------------------------------------
# scene translation and errors


def test_scene_description_groups_materials_and_sun_radiance() -> None:
    m = merge_meshes([
        as_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], (0.2, 0.3, 0.4)),
        as_mesh([[0, 0, 1], [1, 0, 1], [0, 1, 1]], [[0, 2, 1]], (0.2, 0.3, 0.4)),
        as_mesh([[0, 0, 2], [1, 0, 2], [0, 1, 2]], [[0, 1, 2]], (0.5, 0.5, 0.5)),
    ])
    text = scene_description(m)
    assert text.count(" plastic ") == 2
    assert text.count(" polygon ") == 3
    sun = light_description("sun", sun_direction=[0, 0, 2])
    radiance = float(sun.split("light sun_light")[1].split()[3])
    assert radiance * SUN_SOLID_ANGLE_SR == pytest.approx(1.0, rel=1e-8)
    assert "0 0 1 0.533" in sun
    assert light_description("ground").split("source")[1].split()[4:8] == ["0", "0", "-1", "180"]


def test_errors() -> None:
    m = as_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], (0.5, 0.5, 0.5))
    with pytest.raises(RadianceError, match="sun_direction"):
        radiance_irradiance(m, [[0, 0, 0]], [[0, 0, 1]], component="sun")
    with pytest.raises(RadianceError, match="component"):
        radiance_irradiance(m, [[0, 0, 0]], [[0, 0, 1]], component="moon")  # type: ignore[arg-type]
    with pytest.raises(RadianceError, match="shape"):
        radiance_irradiance(m, [[0, 0, 0]], [[0, 0, 1], [0, 0, 1]], component="sky")
    with pytest.raises(RadianceError, match="non-zero"):
        radiance_irradiance(m, [[0, 0, 0]], [[0, 0, 0]], component="sky")
    with pytest.raises(RadianceError, match="repeats"):
        radiance_irradiance_with_error(m, [[0, 0, 0]], [[0, 0, 1]], component="sky", repeats=1)
    assert issubclass(RadianceError, LightfastError)
    assert radiance_irradiance(m, np.zeros((0, 3)), np.zeros((0, 3)), component="sky").shape == (0, 3)


def test_failing_rtrace_reports_stderr(tmp_path, monkeypatch) -> None:
    import lightfast.sim.radiance_oracle as ro

    monkeypatch.setattr(ro, "FIXED_RTRACE_OPTIONS", (*ro.FIXED_RTRACE_OPTIONS, "-bogus_option"))
    m = as_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], (0.5, 0.5, 0.5))
    with pytest.raises(RadianceError, match="rtrace failed"):
        radiance_irradiance(m, [[0.1, 0.1, 0]], [[0, 0, 1]], component="sky", workdir=tmp_path)
    assert (tmp_path / "scene.oct").is_file()  # the workdir is kept


# ---------------------------------------------------------------------------------------------------------------
# room builders and sampling (Embree only)


def _rays_from(point: np.ndarray, count: int, seed: int) -> np.ndarray:
    d = np.random.default_rng(seed).normal(size=(count, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize("wall", ["south", "east", "+y", "-x"])
def test_box_room_is_closed_except_window_and_faces_inwards(wall: str) -> None:
    m = box_room_with_window(size_m=SIZE, window=(1.2, 1.0, 0.9, wall), tessellation_m=0.3)
    m.validate_topology()
    e = m.vertices_m[m.faces]
    assert np.linalg.norm(e - np.roll(e, 1, axis=1), axis=2).max() <= 0.3 + 1e-9
    assert m.vertices_m[:, 2].min() == 0.0 and m.vertices_m[:, 2].max() == pytest.approx(2.9)
    caster = RayCaster(m.vertices_m, m.faces)
    origin = np.array([2.0, 2.6, 1.3])
    d = _rays_from(origin, 20000, seed=1)
    hits = caster.intersect(np.broadcast_to(origin, d.shape), d)
    n_hit = m.face_normals[hits.triangle_id[hits.hit]]
    assert np.all(np.sum(n_hit * d[hits.hit], axis=1) < 0.0)  # only front faces are seen from inside
    escaped = d[~hits.hit]
    assert 0 < len(escaped) < 0.05 * len(d)
    # escaping rays leave through the opening: where they cross the window wall's plane, they are inside it
    axis = {"south": 1, "north": 1, "+y": 1, "east": 0, "-x": 0}[wall]
    plane = {"south": 0.0, "+y": 4.8, "east": 4.5, "-x": 0.0}[wall]
    t = (plane - origin[axis]) / escaped[:, axis]
    cross = origin + t[:, None] * escaped
    along = cross[:, 1 - axis]
    centre = (SIZE[1 - axis]) / 2.0
    assert np.all(t > 0)
    assert np.all(np.abs(along - centre) <= 0.6 + 1e-6)
    assert np.all((cross[:, 2] >= 0.9 - 1e-6) & (cross[:, 2] <= 1.9 + 1e-6))


def test_furnished_room_faces_the_air_and_has_furniture() -> None:
    box = box_room_with_window(size_m=SIZE, window=WINDOW, tessellation_m=0.2)
    m = furnished_room(size_m=SIZE, window=WINDOW, tessellation_m=0.2)
    assert m.num_faces > box.num_faces
    m.validate_topology()
    e = m.vertices_m[m.faces]
    assert np.linalg.norm(e - np.roll(e, 1, axis=1), axis=2).max() <= 0.2 + 1e-9
    caster = RayCaster(m.vertices_m, m.faces)
    for origin in ([1.0, 3.0, 2.0], [3.5, 1.0, 1.0], [2.25, 1.6, 0.3]):  # in the air, one under the table
        d = _rays_from(np.array(origin), 5000, seed=2)
        hits = caster.intersect(np.broadcast_to(origin, d.shape), d)
        n_hit = m.face_normals[hits.triangle_id[hits.hit]]
        assert np.all(np.sum(n_hit * d[hits.hit], axis=1) < 0.0)
    # the window cross blocks the view straight out through the centre of the opening
    out = caster.intersect([[2.25, 1.0, 1.55]], [[0.0, -1.0, 0.0]])
    assert out.hit[0] and -0.2 < out.points()[0, 1] < 0.0
    between = caster.intersect([[1.8, 1.0, 1.2]], [[0.0, -1.0, 0.0]])  # through a pane: nothing
    assert not between.hit[0]


def test_sample_surface_points() -> None:
    m = box_room_with_window(size_m=SIZE, window=WINDOW, tessellation_m=0.2)
    p, n = sample_surface_points(m, 300, seed=3, exclude_near_edges_m=0.05)
    p2, _ = sample_surface_points(m, 300, seed=3, exclude_near_edges_m=0.05)
    np.testing.assert_array_equal(p, p2)
    assert p.shape == n.shape == (300, 3)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
    X, Y, Z = SIZE
    inside = p[:, 1] >= 0.0
    q = p[inside]
    # every interior point is on one of the six planes and >= 5 cm from the other ones
    gaps = np.stack([q[:, 0], X - q[:, 0], q[:, 1], Y - q[:, 1], q[:, 2], Z - q[:, 2]], axis=1)
    on_plane = gaps < 1e-9
    assert np.all(on_plane.sum(axis=1) == 1)
    assert np.all(np.where(on_plane, np.inf, gaps).min(axis=1) >= 0.05 - 1e-9)
    # reveal points stay away from the inner wall plane and the outer edge
    r = p[~inside]
    assert np.all((r[:, 1] <= -0.05 + 1e-9) & (r[:, 1] >= -0.15 - 1e-9))
    # roughly uniform by area: the floor holds about 21.6 / 96 of the points
    floor_share = np.mean(n[:, 2] > 0.99)
    assert 0.12 < floor_share < 0.32

    f = furnished_room(size_m=SIZE, window=WINDOW, tessellation_m=0.2)
    pf, nf = sample_surface_points(f, 400, seed=4)
    # nothing under the cube (x 3.45-3.95, y 2.6-3.1) or behind/under the shelf block (y > 4.4, x 0.5-1.7)
    under_cube = (pf[:, 0] > 3.45) & (pf[:, 0] < 3.95) & (pf[:, 1] > 2.6) & (pf[:, 1] < 3.1) & (pf[:, 2] < 1e-9)
    behind_shelf = (pf[:, 0] > 0.5) & (pf[:, 0] < 1.7) & (pf[:, 1] > 4.4) & (pf[:, 2] < 1.7)
    assert not np.any(under_cube)
    assert not np.any(behind_shelf & (np.abs(nf[:, 1]) > 0.99) & (pf[:, 1] > 4.79))
    assert not np.any(behind_shelf & (nf[:, 2] > 0.99))
    quad = as_mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]], (0.5, 0.5, 0.5))
    with pytest.raises(ValidationRoomError, match="found only 0 of 10"):
        sample_surface_points(quad, 10, seed=0, exclude_near_edges_m=0.6, max_rounds=2)  # all near the border


@pytest.mark.parametrize(("seed", "wall"), [(1, "south"), (2, "west"), (3, "north")])
def test_random_room_is_closed_furnished_and_sampled_where_light_reaches(seed: int, wall: str) -> None:
    m = random_room(seed, window_wall=wall, tessellation_m=0.2)
    m.validate_topology()
    again = random_room(seed, window_wall=wall, tessellation_m=0.2)
    np.testing.assert_array_equal(m.vertices_m, again.vertices_m)
    assert m.num_vertices != random_room(seed + 100, window_wall=wall, tessellation_m=0.2).num_vertices
    floor = m.vertices_m[m.faces[m.face_normals[:, 2] > 0.99]].reshape(-1, 3)
    X, Y = (float(v) for v in floor[floor[:, 2] < 1e-9].max(axis=0)[:2])  # the room, not the window reveals
    Z = float(m.vertices_m[:, 2].max())
    caster = RayCaster(m.vertices_m, m.faces)
    origin = np.array([0.5 * X, 0.5 * Y, Z - 0.15])  # above every piece of furniture
    d = _rays_from(origin, 20000, seed=seed)
    hits = caster.intersect(np.broadcast_to(origin, d.shape), d)
    n_hit = m.face_normals[hits.triangle_id[hits.hit]]
    assert np.all(np.sum(n_hit * d[hits.hit], axis=1) < 0.0)  # only front faces are seen from inside
    assert 0 < np.sum(~hits.hit) < 0.1 * len(d)  # light leaves only through the window
    # closed furniture boxes stand on the floor: faces at z = 0 that face down
    down = (m.face_normals[:, 2] < -0.99) & (m.vertices_m[m.faces][:, :, 2].max(axis=1) < 1e-9)
    assert down.sum() > 0
    p, n = sample_surface_points(m, 200, seed=5)
    pj, nj = sample_surface_points(m, 100, seed=6, near_edges_only_m=0.02, exclude_near_edges_m=0.002)
    for pts, nrm in ((p, n), (pj, nj)):
        assert not np.any((pts[:, 2] < 1e-9) & (nrm[:, 2] < 0))  # no box bottom pressed on the floor
        outward = (((np.abs(pts[:, 0]) < 1e-9) & (nrm[:, 0] < -0.99))
                   | ((np.abs(pts[:, 0] - X) < 1e-9) & (nrm[:, 0] > 0.99))
                   | ((np.abs(pts[:, 1]) < 1e-9) & (nrm[:, 1] < -0.99))
                   | ((np.abs(pts[:, 1] - Y) < 1e-9) & (nrm[:, 1] > 0.99)))
        assert not np.any(outward)  # no cabinet back pressed against a wall


def test_crease_vertices_lie_on_a_crease_and_their_query_points_inside_their_own_face() -> None:
    m = furnished_room(tessellation_m=0.25)
    ids, q, n = sample_crease_vertices(m, 40, seed=3)
    ids2, q2, _ = sample_crease_vertices(m, 40, seed=3)
    assert np.array_equal(ids, ids2) and np.array_equal(q, q2)  # deterministic
    assert len(set(ids.tolist())) == 40
    v = m.vertices_m[ids]
    np.testing.assert_allclose(np.linalg.norm(q - v, axis=1), 2e-3, atol=1e-9)
    np.testing.assert_allclose(np.sum((q - v) * n, axis=1), 0.0, atol=1e-12)  # in the vertex's own face's plane
    tri = m.vertices_m[m.faces]
    edges = np.sort(np.concatenate([m.faces[:, [0, 1]], m.faces[:, [1, 2]], m.faces[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    assert np.all(np.isin(ids, uniq[count == 1]))  # parts are not welded: each on its part's border
    lo, hi = tri.min(axis=1) - 1e-3, tri.max(axis=1) + 1e-3
    other_plane_within_1mm = [np.any((np.abs(m.face_normals @ nrm) < 0.999) & np.all((p >= lo) & (p <= hi), axis=1))
                              for p, nrm in zip(v, n, strict=True)]  # brute force (box test)
    assert np.mean(other_plane_within_1mm) > 0.8  # nearly all where parts meet; the rest where the mesh ends
    with pytest.raises(ValidationRoomError, match="crease vertices"):
        sample_crease_vertices(box_room_with_window(tessellation_m=1.0), 10_000, seed=0)


def test_room_parameter_errors() -> None:
    with pytest.raises(ValidationRoomError, match="wall"):
        box_room_with_window(window=(1.0, 1.0, 1.0, "up"))
    with pytest.raises(ValidationRoomError, match="fit"):
        box_room_with_window(window=(5.0, 1.0, 1.0, "south"))
    with pytest.raises(ValidationRoomError, match="fit"):
        box_room_with_window(window=(1.0, 2.5, 1.0, "south"))
    with pytest.raises(ValidationRoomError):
        furnished_room(size_m=(3.0, 3.0, 2.5))
    assert issubclass(ValidationRoomError, LightfastError)
