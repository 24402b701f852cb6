import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lightfast.camera import PinholeCamera
from lightfast.errors import CameraModelError

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
