"""Unit tests of lightfast.raycast: closed-form scenes, Embree conventions, brute-force check, chunking, errors."""
from __future__ import annotations

import numpy as np
import pytest

from lightfast.camera import PinholeCamera
from lightfast.errors import LightfastError, RaycastError
from lightfast.raycast import RayCaster, RayHits

# ---------------------------------------------------------------------------------------------------------------
# meshes


Vec3 = tuple[float, float, float]


def box_mesh(lo: Vec3, hi: Vec3, *, inward: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box, 12 triangles, normals outward (right-hand rule) unless ``inward``.

    Triangles 2k and 2k+1 form face k in the order -x, +x, -y, +y, -z, +z.
    """
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    V = np.array(
        [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0], [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]
    )
    quads = [  # each counter-clockwise seen from outside
        (0, 4, 7, 3),  # -x
        (1, 2, 6, 5),  # +x
        (0, 1, 5, 4),  # -y
        (3, 7, 6, 2),  # +y
        (0, 3, 2, 1),  # -z
        (4, 5, 6, 7),  # +z
    ]
    F = np.array([tri for a, b, c, d in quads for tri in ((a, b, c), (a, c, d))], dtype=np.int64)
    if inward:
        F = F[:, ::-1].copy()
    return V, F


def quad_mesh(size: float = 1.0, z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Square [0, size]^2 at height z, two triangles split along the diagonal x == y, normals +z.

    Triangle 0 = (0, 1, 2) covers x > y, triangle 1 = (0, 2, 3) covers y > x.
    """
    V = np.array([[0.0, 0.0, z], [size, 0.0, z], [size, size, z], [0.0, size, z]])
    F = np.array([[0, 1, 2], [0, 2, 3]])
    return V, F


def moller_trumbore(V: np.ndarray, F: np.ndarray, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Brute-force nearest hit (distance along unit d, triangle id) of every ray against every triangle."""
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    v0, v1, v2 = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    e1, e2 = v1 - v0, v2 - v0  # (F, 3)
    p = np.cross(d[:, None, :], e2[None])  # (N, F, 3)
    det = np.einsum("fi,nfi->nf", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o[:, None, :] - v0[None]
        u = np.einsum("nfi,nfi->nf", s, p) * inv
        q = np.cross(s, e1[None])
        v = np.einsum("ni,nfi->nf", d, q) * inv
        t = np.einsum("fi,nfi->nf", e2, q) * inv
    ok = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    t = np.where(ok, t, np.inf)
    tri = np.argmin(t, axis=1)
    dist = t[np.arange(len(o)), tri]
    return dist, np.where(np.isfinite(dist), tri, -1)


# ---------------------------------------------------------------------------------------------------------------
# closed-form scenes


def test_two_triangles_distances_ids_and_barycentrics() -> None:
    V, F = quad_mesh(z=0.0)
    caster = RayCaster(V, F)
    o = np.array([[0.7, 0.2, 2.0], [0.2, 0.7, 3.0], [1.5, 0.5, 1.0], [0.5, 0.25, -1.0]])
    d = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]])
    hits = caster.intersect(o, d)
    assert isinstance(hits, RayHits)
    np.testing.assert_array_equal(hits.hit, [True, True, False, True])
    np.testing.assert_array_equal(hits.triangle_id, [0, 1, -1, 0])
    np.testing.assert_allclose(hits.distance_m, [2.0, 3.0, np.inf, 1.0], rtol=1e-6)
    assert hits.distance_m.dtype == np.float32 and hits.triangle_id.dtype == np.int64
    assert hits.barycentric_uv.dtype == np.float32 and hits.barycentric_uv.shape == (4, 2)
    assert np.all(np.isnan(hits.barycentric_uv[2]))
    # Embree's convention: p = (1 - u - v) v0 + u v1 + v v2, checked here by hand (not through points()).
    # Ray 0 hits (0.7, 0.2) in triangle (0, 1, 2) = ((0,0), (1,0), (1,1)): p = u (1,0) + v (1,1) -> v = 0.2, u = 0.5
    np.testing.assert_allclose(hits.barycentric_uv[0], [0.5, 0.2], atol=1e-6)
    # Ray 1 hits (0.2, 0.7) in triangle (0, 2, 3) = ((0,0), (1,1), (0,1)): u = 0.2, v = 0.5
    np.testing.assert_allclose(hits.barycentric_uv[1], [0.2, 0.5], atol=1e-6)
    for i in (0, 1, 3):
        u, v = hits.barycentric_uv[i].astype(np.float64)
        tri = V[F[hits.triangle_id[i]]]
        p = (1 - u - v) * tri[0] + u * tri[1] + v * tri[2]
        np.testing.assert_allclose(p, o[i] + hits.distance_m[i] * d[i], atol=1e-6)
    expected_points = [[0.7, 0.2, 0.0], [0.2, 0.7, 0.0], [0.5, 0.25, 0.0]]
    np.testing.assert_allclose(hits.points()[[0, 1, 3]], expected_points, atol=1e-6)
    assert np.all(np.isnan(hits.points()[2]))
    # geometric normal by the right-hand rule is +z whichever side the ray comes from ...
    np.testing.assert_allclose(hits.normals()[[0, 1, 3]], np.tile([0.0, 0.0, 1.0], (3, 1)), atol=0)
    assert np.all(np.isnan(hits.normals()[2]))
    # ... unless it is asked to face the ray
    np.testing.assert_allclose(hits.normals(facing=d)[3], [0.0, 0.0, -1.0], atol=0)


def test_unit_cube_hits_every_face_with_outward_normals() -> None:
    V, F = box_mesh((0, 0, 0), (1, 1, 1))
    caster = RayCaster(V, F)
    assert caster.num_triangles == 12 and caster.num_vertices == 8
    c = np.array([0.5, 0.4, 0.3])
    axes = np.concatenate([-np.eye(3), np.eye(3)])[[0, 3, 1, 4, 2, 5]]  # -x, +x, -y, +y, -z, +z
    origins = c + 3.0 * axes  # outside, looking back at the cube
    hits = caster.intersect(origins, -axes)
    assert np.all(hits.hit)
    expected = 3.0 - np.array([c[0], 1 - c[0], c[1], 1 - c[1], c[2], 1 - c[2]])
    np.testing.assert_allclose(hits.distance_m, expected, rtol=1e-6)
    np.testing.assert_array_equal(hits.triangle_id // 2, np.arange(6))  # face k = triangles 2k, 2k+1
    np.testing.assert_allclose(hits.normals(), axes, atol=1e-7)
    np.testing.assert_allclose(caster.face_normals[::2], axes, atol=1e-15)
    np.testing.assert_allclose(hits.points(), origins - axes * expected[:, None], atol=1e-6)


def test_box_room_from_inside() -> None:
    V, F = box_mesh((-2.0, -3.0, 0.0), (2.0, 3.0, 2.5), inward=True)
    caster = RayCaster(V, F)
    o = np.array([0.5, 1.0, 1.2])
    d = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1], [1, 1, 0]], dtype=float)
    hits = caster.intersect(o, d)  # one origin broadcast against 7 directions
    assert hits.shape == (7,)
    np.testing.assert_allclose(hits.distance_m, [1.5, 2.5, 2.0, 4.0, 1.3, 1.2, 1.5 * np.sqrt(2)], rtol=1e-6)
    # inward normals point back at the viewer
    np.testing.assert_allclose(hits.normals()[:6], -d[:6], atol=1e-7)
    assert np.all(caster.occluded(o, d))
    # nothing within 1 m in any axis direction, the floor within 1.25 m
    np.testing.assert_array_equal(caster.occluded(o, d[:6], t_far_m=1.0), [False] * 6)
    np.testing.assert_array_equal(caster.occluded(o, d[:6], t_far_m=1.25), [False] * 5 + [True])


def test_non_unit_directions_are_normalized() -> None:
    V, F = quad_mesh()
    caster = RayCaster(V, F)
    hits = caster.intersect([[0.3, 0.6, 4.0], [0.3, 0.6, 4.0]], [[0.0, 0.0, -1.0], [0.0, 0.0, -25.0]])
    np.testing.assert_allclose(hits.distance_m, [4.0, 4.0], rtol=1e-6)
    # oblique non-unit direction: distance is Euclidean metres from the origin
    d = np.array([0.3, 0.4, -1.2]) * 7.0
    h = caster.intersect([0.1, 0.1, 1.2], d)
    np.testing.assert_allclose(h.distance_m, np.linalg.norm([0.3, 0.4, 1.2]), rtol=1e-6)
    np.testing.assert_allclose(h.points(), [0.4, 0.5, 0.0], atol=1e-6)
    assert h.shape == ()
    # extreme (but finite, non-zero) lengths
    h = caster.intersect([[0.3, 0.6, 4.0]] * 2, [[0.0, 0.0, -1e-200], [0.0, 1e-300, -1e300]])
    np.testing.assert_allclose(h.distance_m, [4.0, 4.0], rtol=1e-6)


def test_occlusion_with_t_far_below_and_above_the_hit() -> None:
    V, F = quad_mesh()
    caster = RayCaster(V, F)
    o = np.array([0.4, 0.5, 2.0])
    down = np.array([0.0, 0.0, -1.0])
    assert not caster.occluded(o, down, t_far_m=1.99)
    assert caster.occluded(o, down, t_far_m=2.01)
    assert caster.occluded(o, down)
    assert not caster.occluded(o, -down)
    assert not caster.intersect(o, down, t_far_m=1.99).hit
    assert caster.intersect(o, down, t_far_m=2.01).hit
    # per-ray t_far
    t_far = np.array([0.5, 1.9, 2.1, np.inf])
    np.testing.assert_array_equal(caster.occluded(o, down, t_far_m=t_far), [False, False, True, True])
    hits = caster.intersect(np.tile(o, (4, 1)), down, t_far_m=t_far)
    np.testing.assert_array_equal(hits.hit, [False, False, True, True])
    np.testing.assert_allclose(hits.distance_m, [np.inf, np.inf, 2.0, 2.0], rtol=1e-6)


def test_t_near_skips_the_first_surface() -> None:
    V, F = box_mesh((0, 0, 0), (1, 1, 1))
    caster = RayCaster(V, F)
    o = np.array([-2.0, 0.5, 0.3])
    d = np.array([1.0, 0.0, 0.0])
    first = caster.intersect(o, d)
    assert first.distance_m == pytest.approx(2.0, rel=1e-6) and first.triangle_id // 2 == 0
    second = caster.intersect(o, d, t_near_m=2.5)
    assert second.distance_m == pytest.approx(3.0, rel=1e-6) and second.triangle_id // 2 == 1  # the +x face
    np.testing.assert_allclose(second.points(), [1.0, 0.5, 0.3], atol=1e-6)
    assert not caster.intersect(o, d, t_near_m=3.5).hit
    # occlusion of the segment between the two faces only
    assert not caster.occluded(o, d, t_near_m=2.1, t_far_m=2.9)
    assert caster.occluded(o, d, t_near_m=2.1, t_far_m=3.1)
    # per-ray t_near, and an empty interval (t_far <= t_near) never hits
    hits = caster.intersect(o, d, t_near_m=np.array([0.0, 2.5, 2.5]), t_far_m=np.array([10.0, 10.0, 2.0]))
    np.testing.assert_allclose(hits.distance_m, [2.0, 3.0, np.inf], rtol=1e-6)
    np.testing.assert_array_equal(caster.occluded(o, d, t_near_m=[0.0, 2.5], t_far_m=[0.0, 2.5]), [False, False])
    # ... even when the (empty) interval sits exactly on a surface, which Embree alone would report at t = 0
    on_surface = np.array([0.0, 0.5, 0.3])
    assert not caster.intersect(on_surface, d, t_far_m=0.0).hit
    assert not caster.occluded(on_surface, d, t_far_m=0.0)
    assert not caster.intersect(o, d, t_near_m=2.0, t_far_m=2.0).hit
    assert not caster.occluded(o, d, t_near_m=2.0, t_far_m=1.0)


def test_misses() -> None:
    V, F = quad_mesh()
    caster = RayCaster(V, F)
    hits = caster.intersect([[0.5, 0.5, 1.0], [2.0, 2.0, 1.0], [0.5, 0.5, 1.0]], [[0, 0, 1], [0, 0, -1], [1, 0, 0]])
    assert not hits.hit.any()
    assert np.all(np.isinf(hits.distance_m)) and np.all(hits.triangle_id == -1)
    assert np.all(np.isnan(hits.points())) and np.all(np.isnan(hits.normals()))
    assert not caster.occluded([[2.0, 2.0, 1.0]], [[0, 0, -1]]).any()


def test_image_shaped_batches() -> None:
    cam = PinholeCamera(width=64, height=48, fx=50.0, fy=50.0, cx=31.5, cy=23.5)
    d = cam.ray_directions()  # (H, W, 3), optical frame: z forward
    V, F = quad_mesh(size=100.0, z=2.0)
    V[:, :2] -= 50.0  # a 100 m wide wall 2 m in front of the camera
    caster = RayCaster(V, F)
    hits = caster.intersect(np.zeros(3), d)
    assert hits.shape == (48, 64) and hits.barycentric_uv.shape == (48, 64, 2)
    assert hits.points().shape == (48, 64, 3) and hits.normals().shape == (48, 64, 3)
    assert hits.hit.all()
    np.testing.assert_allclose(hits.distance_m, 2.0 / d[..., 2], rtol=1e-6)
    np.testing.assert_allclose(hits.points()[..., 2], 2.0, atol=1e-5)
    # z-depth of the hits back-projects to the same points
    np.testing.assert_allclose(cam.backproject(cam.pixel_grid(), hits.points()[..., 2]), hits.points(), atol=1e-5)
    depth_range = 2.0 / d[..., 2]  # per-pixel t_far just beyond / short of the wall
    occ = caster.occluded(np.zeros(3), d, t_far_m=1.001 * depth_range)
    assert occ.shape == (48, 64) and occ.all()
    assert not caster.occluded(np.zeros(3), d, t_far_m=0.999 * depth_range).any()
    # the corner rays are longer than 2.5 m, the centre ones shorter
    occ = caster.occluded(np.zeros(3), d, t_far_m=2.5)
    np.testing.assert_array_equal(occ, depth_range < 2.5)


def test_matches_brute_force_on_random_mesh() -> None:
    rng = np.random.default_rng(11)
    centers = rng.uniform(-3, 3, (60, 1, 3))
    tris = centers + rng.normal(scale=0.8, size=(60, 3, 3))
    V = tris.reshape(-1, 3)
    F = np.arange(180).reshape(60, 3)
    caster = RayCaster(V, F)
    o = rng.uniform(-6, 6, (3000, 3))
    d = rng.normal(size=(3000, 3)) + 0.0
    d -= 0.8 * o / np.linalg.norm(o, axis=-1, keepdims=True)  # bias towards the cloud of triangles
    dist, tri = moller_trumbore(V, F, o, d)
    hits = caster.intersect(o, d)
    assert 300 < hits.hit.sum() < 2900  # a meaningful mix of hits and misses
    # rays grazing an edge may legitimately disagree in float32; they must be rare
    agree = (hits.triangle_id == tri) | np.isclose(hits.distance_m, dist, rtol=0.0, atol=1e-4)
    assert agree.mean() > 0.998
    both = hits.hit & np.isfinite(dist)
    np.testing.assert_allclose(hits.distance_m[both], dist[both], rtol=2e-5, atol=2e-5)
    unit = d / np.linalg.norm(d, axis=-1, keepdims=True)
    np.testing.assert_allclose(hits.points()[both], o[both] + dist[both, None] * unit[both], atol=2e-4)
    # occluded agrees with intersect, away from the t_far boundary
    t_far = rng.uniform(0, 12, 3000)
    occ = caster.occluded(o, d, t_far_m=t_far)
    clear = np.abs(np.where(np.isfinite(dist), dist, 1e9) - t_far) > 1e-3
    np.testing.assert_array_equal(occ[clear & agree], ((dist <= t_far) & np.isfinite(dist))[clear & agree])


def test_more_than_one_chunk_of_rays() -> None:
    V, F = quad_mesh(size=1.0, z=0.0)
    caster = RayCaster(V, F)
    n = (1 << 20) + 12_345  # default chunk is 1 Mi rays: two chunks, the second partial
    rng = np.random.default_rng(12)
    o = np.empty((n, 3), np.float32)
    o[:, :2] = rng.uniform(-0.25, 1.25, (n, 2))
    o[:, 2] = rng.uniform(0.5, 5.0, n)
    hits = caster.intersect(o, np.array([0.0, 0.0, -1.0]))
    inside = (o[:, 0] >= 0) & (o[:, 0] <= 1) & (o[:, 1] >= 0) & (o[:, 1] <= 1)
    edge = np.minimum.reduce([np.abs(o[:, 0]), np.abs(o[:, 0] - 1), np.abs(o[:, 1]), np.abs(o[:, 1] - 1)]) < 1e-6
    diag = np.abs(o[:, 0] - o[:, 1]) < 1e-6
    np.testing.assert_array_equal(hits.hit[~edge], inside[~edge])
    np.testing.assert_allclose(hits.distance_m[inside], o[inside, 2], rtol=1e-6)
    sel = inside & ~diag
    np.testing.assert_array_equal(hits.triangle_id[sel], np.where(o[sel, 0] > o[sel, 1], 0, 1))
    # the tail of the last chunk is filled in too
    assert hits.hit[-12_345:].sum() == inside[-12_345:].sum()
    occ = caster.occluded(o, np.array([0.0, 0.0, -1.0]), t_far_m=o[:, 2].astype(np.float64) - 0.01)
    assert not occ.any()


def test_chunk_size_does_not_change_results() -> None:
    V, F = box_mesh((-1, -1, -1), (1, 1, 1))
    rng = np.random.default_rng(13)
    o = rng.uniform(-3, 3, (5000, 3))
    d = rng.normal(size=(5000, 3))
    t_far = rng.uniform(0, 6, 5000)
    a = RayCaster(V, F).intersect(o, d, t_far_m=t_far)
    b = RayCaster(V, F, chunk_rays=777).intersect(o, d, t_far_m=t_far)
    for name in ("distance_m", "triangle_id", "barycentric_uv", "hit"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    np.testing.assert_array_equal(
        RayCaster(V, F).occluded(o, d, t_far_m=t_far), RayCaster(V, F, chunk_rays=777).occluded(o, d, t_far_m=t_far)
    )


def test_far_from_origin_mesh_keeps_precision() -> None:
    """A georeferenced mesh (UTM-sized coordinates): float32 alone would quantize to ~0.5 m."""
    V, F = quad_mesh(size=100.0, z=250.0)
    offset = np.array([512_345.678, 4_123_456.789, 0.0])
    caster = RayCaster(V + offset, F)
    o = offset + np.array([[40.123, 60.456, 251.234], [70.5, 10.25, 262.0]])
    hits = caster.intersect(o, [0.0, 0.0, -1.0])
    np.testing.assert_allclose(hits.distance_m, [1.234, 12.0], atol=2e-5)
    np.testing.assert_allclose(hits.points() - offset, [[40.123, 60.456, 250.0], [70.5, 10.25, 250.0]], atol=1e-4)
    np.testing.assert_allclose(caster.vertices_m, V + offset, atol=1e-4)


def test_empty_batch() -> None:
    V, F = quad_mesh()
    caster = RayCaster(V, F)
    hits = caster.intersect(np.zeros((0, 3)), np.zeros((0, 3)))
    assert hits.shape == (0,) and hits.points().shape == (0, 3)
    assert caster.occluded(np.zeros((0, 3)), np.zeros((0, 3))).shape == (0,)


# ---------------------------------------------------------------------------------------------------------------
# validation


def test_raycast_error_types() -> None:
    assert issubclass(RaycastError, LightfastError) and issubclass(RaycastError, ValueError)


@pytest.mark.parametrize(
    ("vertices", "faces", "name"),
    [
        (np.zeros((4, 2)), [[0, 1, 2]], "vertices_m"),
        (np.zeros((0, 3)), np.zeros((0, 3), int), "vertices_m"),
        ([[0, 0, 0], [1, 0, np.nan], [0, 1, 0]], [[0, 1, 2]], "vertices_m"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0.0, 1.0, 2.0]], "faces"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]], "faces"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, -1, 2]], "faces"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.zeros((0, 3), int), "faces"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2, 0]], "faces"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[True, False, True]], "faces"),
    ],
)
def test_invalid_mesh_raises(vertices: object, faces: object, name: str) -> None:
    with pytest.raises(RaycastError, match=name):
        RayCaster(vertices, faces)  # type: ignore[arg-type]


def test_invalid_chunk_size_raises() -> None:
    with pytest.raises(RaycastError, match="chunk_rays"):
        RayCaster(*quad_mesh(), chunk_rays=0)


@pytest.mark.parametrize("method", ["intersect", "occluded"])
@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"origins_m": np.zeros((5, 2))}, "origins_m"),
        ({"origins_m": [[np.nan, 0.0, 0.0]]}, "origins_m"),
        ({"directions": np.zeros((5, 4))}, "directions"),
        ({"directions": [[0.0, 0.0, 0.0]]}, "directions"),
        ({"directions": [[np.inf, 0.0, 0.0]]}, "directions"),
        ({"origins_m": np.zeros((4, 3)), "directions": np.ones((5, 3))}, "broadcast"),
        ({"t_near_m": -1.0}, "t_near_m"),
        ({"t_near_m": np.inf}, "t_near_m"),
        ({"t_far_m": np.nan}, "t_far_m"),
        ({"t_far_m": -0.5}, "t_far_m"),
        ({"t_far_m": np.ones(3)}, "t_far_m"),
    ],
)
def test_invalid_rays_raise(method: str, kwargs: dict, name: str) -> None:
    caster = RayCaster(*quad_mesh())
    args = {"origins_m": np.zeros((5, 3)), "directions": np.ones((5, 3))} | kwargs
    o, d = args.pop("origins_m"), args.pop("directions")
    with pytest.raises(RaycastError, match=name):
        getattr(caster, method)(o, d, **args)
