"""The ACR baseline (Tian et al. 2019 as the rACR paper describes it) on the ray-cast relief of
``test_fine_alignment.py``, with high-contrast carvings in its texture so that SIFT finds features.

The images are rendered from known poses, so the relative pose the 5-point algorithm recovers can be compared with
the truth, and the ACR loop (hand–eye taken as identity, translation step by bisection) can be run on a platform
whose true hand–eye is not the identity.
"""
from __future__ import annotations

import numpy as np
import pytest

from lightfast.camera import PinholeCamera
from lightfast.config import ConfigError
from lightfast.geometry import make_transform, rotation_angle_deg, so3_exp
from lightfast.racr import AcrBaseline, AcrConfig, AcrError, RacrError, relative_pose, sift_matches
from test.unit.racr.test_fine_alignment import T_REF_CAM, afd_px, shared_scene

CAMERA_VGA = PinholeCamera(640, 480, 560.0, 560.0, 319.5, 239.5)
CAMERA_QVGA = PinholeCamera(320, 240, 280.0, 280.0, 159.5, 119.5)
T_CUR = make_transform(so3_exp(np.radians(4.0) * np.array([0.3, 0.9, 0.3])) @ T_REF_CAM[:3, :3],
                       T_REF_CAM[:3, 3] + 0.06 * np.array([0.8, -0.3, 0.5]))
X_TRUE = make_transform(so3_exp(np.radians(10.0) * np.array([0.0, 0.6, 0.8])), [0.05, 0.0, -0.03])


@pytest.fixture(scope="module")
def scene():
    return shared_scene(0, marks=300)


def render(scene, T: np.ndarray, camera: PinholeCamera) -> np.ndarray:
    return scene.render(T, camera, supersample=1)[0]


def test_the_5_point_pose_matches_the_rendered_truth(scene) -> None:
    """Measured: ~300 inliers, 0.15° rotation and 2° direction error (6 cm baseline at 0.8 m, 640×480)."""
    image_ref, image_cur = render(scene, T_REF_CAM, CAMERA_VGA), render(scene, T_CUR, CAMERA_VGA)
    pc, pr = sift_matches(image_cur, image_ref)
    pose = relative_pose(pc, pr, CAMERA_VGA)
    T_cur_ref = np.linalg.inv(T_CUR) @ T_REF_CAM
    true_dir = T_cur_ref[:3, 3] / np.linalg.norm(T_cur_ref[:3, 3])
    assert pose.inliers >= 100 and pose.matches >= pose.inliers
    assert rotation_angle_deg(pose.R_cur_ref, T_cur_ref[:3, :3]) < 0.5
    assert np.degrees(np.arccos(np.clip(pose.direction_cur @ true_dir, -1.0, 1.0))) < 5.0
    assert abs(np.linalg.norm(pose.direction_cur) - 1.0) < 1e-12
    assert pose.afd_px > 5.0  # the two images differ
    # the matches (and the 8-bit conversion of float images) are the same for uint8 input
    pc8, _ = sift_matches((image_cur * 255).round().astype(np.uint8), (image_ref * 255).round().astype(np.uint8))
    assert len(pc8) == len(pc)


@pytest.mark.parametrize("rule", ["direction", "feature_displacement"])
def test_the_acr_loop_converges_with_bisection(scene, rule: str) -> None:
    """ACR executes its camera motion as the hand motion (X taken as identity) on a platform whose true X is 10°
    and 6 cm off, halving the step as §5.2.3 describes. Measured: direction rule 9 iterations, displacement rule
    ~25; true AFD well below 3 px at the end."""
    acr = AcrBaseline(render(scene, T_REF_CAM, CAMERA_QVGA), CAMERA_QVGA, AcrConfig(bisection=rule))
    T = T_CUR.copy()
    for _ in range(40):
        step = acr.step(render(scene, T, CAMERA_QVGA))
        if step.converged:
            break
        T = T @ X_TRUE @ step.M_hand @ np.linalg.inv(X_TRUE)  # the platform moves the hand; the camera follows
    assert step.converged and step.afd_px <= acr.config.stop_afd_px
    np.testing.assert_array_equal(step.M_hand, np.eye(4))
    assert acr.halvings >= 1 and step.step_m < acr.config.initial_step_m
    assert afd_px(scene, T_REF_CAM, T, CAMERA_QVGA, step_px=20) < 3.0


def test_first_step_moves_along_the_estimated_direction_by_the_initial_step(scene) -> None:
    acr = AcrBaseline(render(scene, T_REF_CAM, CAMERA_QVGA), CAMERA_QVGA, AcrConfig(initial_step_m=0.02))
    step = acr.step(render(scene, T_CUR, CAMERA_QVGA))
    assert not step.converged and step.iteration == 1
    assert np.linalg.norm(step.M_hand[:3, 3]) == pytest.approx(0.02)
    np.testing.assert_allclose(step.M_hand[:3, 3] / 0.02, step.pose.direction_cur)
    np.testing.assert_allclose(step.M_hand[:3, :3], step.pose.R_cur_ref)


def test_images_that_do_not_match_raise(scene) -> None:
    acr = AcrBaseline(render(scene, T_REF_CAM, CAMERA_QVGA), CAMERA_QVGA)
    with pytest.raises(AcrError, match="matches"):
        acr.step(np.full(CAMERA_QVGA.shape, 0.5))  # a blank image: no features
    rng = np.random.default_rng(0)
    with pytest.raises(AcrError):
        acr.step(rng.random(CAMERA_QVGA.shape))  # noise: few, wrong matches
    assert acr.iterations == 0  # no motion came out of them
    with pytest.raises(AcrError, match="image"):
        acr.step(np.zeros((8, 8)))
    with pytest.raises(AcrError, match="non-finite"):
        acr.step(np.full(CAMERA_QVGA.shape, np.nan))
    with pytest.raises(AcrError, match="SIFT features"):
        AcrBaseline(np.full(CAMERA_QVGA.shape, 0.5), CAMERA_QVGA)
    with pytest.raises(AcrError, match="differ in length"):
        relative_pose(np.zeros((20, 2)), np.zeros((19, 2)), CAMERA_QVGA)
    assert issubclass(AcrError, RacrError)
    with pytest.raises(ConfigError):
        AcrConfig(bisection="golden")
    with pytest.raises(ConfigError):
        AcrConfig(min_inliers=4)
