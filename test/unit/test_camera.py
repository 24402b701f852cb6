import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lightfast.camera import PinholeCamera, Undistorter
from lightfast.errors import CameraModelError
from test.helpers import distorted

CAM = PinholeCamera(640, 480, 585.0, 585.0, 320.0, 240.0)


@given(
    u=st.floats(-0.49, 639.49), v=st.floats(-0.49, 479.49), z=st.floats(0.1, 50.0),
)
def test_backproject_then_project_is_identity(u: float, v: float, z: float) -> None:
    p = CAM.backproject(np.array([u, v]), z)
    uv, in_front = CAM.project(p)
    assert in_front
    np.testing.assert_allclose(uv, [u, v], atol=1e-9)
    assert CAM.in_image(uv)


def test_points_behind_are_flagged() -> None:
    uv, in_front = CAM.project(np.array([[0.0, 0.0, -1.0], [0.1, 0.2, 2.0]]))
    assert in_front.tolist() == [False, True]
    assert np.isnan(uv[0]).all()
    np.testing.assert_allclose(uv[1], [320 + 585 * 0.05, 240 + 585 * 0.1])


def test_depth_image_backprojection_and_rays() -> None:
    depth = np.full(CAM.shape, 2.0)
    depth[0, 0] = 0.0
    pts = CAM.backproject_depth(depth)
    assert pts.shape == (480, 640, 3)
    assert np.isnan(pts[0, 0]).all()
    np.testing.assert_allclose(pts[240, 320], [0, 0, 2.0])
    rays = CAM.ray_directions()
    np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0)


def test_scaled_keeps_pixel_centres() -> None:
    half = CAM.scaled(0.5)
    assert (half.width, half.height) == (320, 240)
    p = np.array([0.3, -0.2, 1.7])
    uv_full, _ = CAM.project(p)
    uv_half, _ = half.project(p)
    np.testing.assert_allclose((uv_full + 0.5) * 0.5 - 0.5, uv_half)


@pytest.mark.parametrize("kwargs", [dict(width=0), dict(fx=0.0), dict(fy=float("nan")), dict(cx=float("inf"))])
def test_invalid_intrinsics(kwargs: dict) -> None:
    base = dict(width=640, height=480, fx=500.0, fy=500.0, cx=320.0, cy=240.0) | kwargs
    with pytest.raises(CameraModelError):
        PinholeCamera(**base)


def test_from_matrix() -> None:
    assert PinholeCamera.from_matrix(CAM.K, 640, 480) == CAM
    with pytest.raises(CameraModelError, match="K must be"):
        PinholeCamera.from_matrix([[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], 10, 10)


# Lenses of real cameras' camera_info (magnitudes as calibrated: a RealSense D455's colour, an Azure Kinect's, a
# fisheye); the tests recover the pinhole image a scene would give from what the lens records of it.
CAM_LENS = PinholeCamera(320, 240, 260.0, 262.0, 161.0, 118.5)
LENSES = {"plumb_bob": [-0.25, 0.09, 0.001, -0.002, -0.015],
          "rational_polynomial": [0.45, -2.6, 0.0005, -0.0003, 1.5, 0.33, -2.4, 1.4],
          "equidistant": [0.05, -0.01, 0.004, -0.001]}


def _scene(camera: PinholeCamera) -> np.ndarray:
    """A smooth grey pattern (float32) whose pinhole image is known at every pixel."""
    uv = camera.pixel_grid()
    return (0.5 + 0.25 * np.sin(uv[..., 0] / 9.0) + 0.25 * np.cos(uv[..., 1] / 7.0)).astype(np.float32)


@pytest.mark.parametrize("model", sorted(LENSES))
def test_undistortion_recovers_the_pinhole_image(model: str) -> None:
    pinhole = _scene(CAM_LENS)
    recorded = distorted(pinhole, CAM_LENS, model, LENSES[model])
    u = Undistorter(CAM_LENS, model, LENSES[model])
    back = u.colour(recorded)
    assert back.dtype == np.float32 and back.shape == pinhole.shape
    inner = (slice(20, -20), slice(20, -20))  # the lens's own resampling blurs a pixel's width at most
    err = np.percentile(np.abs(back - pinhole)[inner], 99)
    lens = np.percentile(np.abs(recorded - pinhole)[inner], 99)  # what the lens did: 0.12-0.6 of the range 0-1
    assert err < 0.02 and err < 0.1 * lens, (err, lens)


def test_undistorted_depth_keeps_measured_values_and_puts_them_where_the_pinhole_would() -> None:
    model, d = "plumb_bob", LENSES["plumb_bob"]
    depth = np.full(CAM_LENS.shape, 2.0, np.float32)
    p = np.array([[0.9, -0.65, 2.0]])  # a point near the corner, where the lens moves it most (~9 px)
    (uv,), _ = CAM_LENS.project(p)
    u0, v0 = round(float(uv[0])), round(float(uv[1]))
    depth[v0 - 2:v0 + 3, u0 - 2:u0 + 3] = 1.25  # a small box in front of a wall
    recorded = distorted(depth, CAM_LENS, model, d, nearest=True)
    assert not np.any(recorded[v0 - 2:v0 + 3, u0 - 2:u0 + 3] == 1.25)  # the lens moved it elsewhere
    back = Undistorter(CAM_LENS, model, d).depth(recorded)
    assert set(np.unique(back[np.isfinite(back)])) <= {np.float32(1.25), np.float32(2.0)}  # no mixed depth
    assert np.all(back[v0 - 1:v0 + 2, u0 - 1:u0 + 2] == np.float32(1.25))
    recorded[recorded == 2.0] = 0.0  # invalid stays invalid
    assert np.isnan(Undistorter(CAM_LENS, model, d).depth(recorded)[0, 0])


def test_undistorted_depth_of_a_slanted_wall_is_interpolated_not_shifted() -> None:
    """On a smooth surface the depth is interpolated at the lookup: the nearest pixel alone would move it by up to
    half a pixel, a warp of the surface an aligner takes for motion."""
    model, d = "plumb_bob", LENSES["plumb_bob"]
    rays = CAM_LENS.backproject(CAM_LENS.pixel_grid(), np.ones(CAM_LENS.shape))
    normal, offset = np.array([0.5, 0.0, -1.0]) / np.hypot(0.5, 1.0), -1.5  # n·p = offset, a wall seen at 27°
    pinhole = (offset / (rays @ normal)).astype(np.float32)  # z of the wall along each pinhole ray
    recorded = distorted(pinhole, CAM_LENS, model, d)  # smooth: sampled bilinearly is the lens's own recording
    inner = (slice(20, -20), slice(20, -20))
    err = np.abs(Undistorter(CAM_LENS, model, d).depth(recorded) - pinhole)[inner]
    slope = np.abs(np.diff(pinhole, axis=1)).max()  # m per pixel: what half a pixel's shift would cost
    assert err.max() < 0.1 * slope, (err.max(), slope)


def test_pixels_the_lens_did_not_see_are_invalid_depth_and_make_no_colour_edge() -> None:
    pincushion = [0.3, 0.2, 0.0, 0.0, 0.0]  # the pinhole corners fall outside the recorded image
    u = Undistorter(CAM_LENS, "plumb_bob", pincushion)
    assert np.isnan(u.depth(np.ones(CAM_LENS.shape, np.float32))[0, 0])
    assert np.all(u.colour(np.full((*CAM_LENS.shape, 3), 200, np.uint8)) == 200)  # not black: no fixed edge


@pytest.mark.parametrize(("model", "d", "match"), [
    ("fisheye", [0.1] * 4, "not one of"), ("plumb_bob", [0.1] * 3, "takes 4 or 5"),
    ("rational_polynomial", [0.1] * 5, "takes 8"), ("plumb_bob", [0.1, np.nan, 0, 0, 0], "finite"),
])
def test_lenses_it_cannot_invert_are_refused(model: str, d: list[float], match: str) -> None:
    with pytest.raises(CameraModelError, match=match):
        Undistorter(CAM_LENS, model, d)


def test_an_image_of_another_size_is_refused() -> None:
    u = Undistorter(CAM_LENS, "plumb_bob", LENSES["plumb_bob"])
    with pytest.raises(CameraModelError, match="does not match"):
        u.colour(np.zeros((120, 160, 3), np.uint8))
    with pytest.raises(CameraModelError, match="does not match"):
        u.depth(np.zeros((120, 160), np.float32))
