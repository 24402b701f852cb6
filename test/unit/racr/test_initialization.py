"""Hand–eye rotation (Eq. 4, OpenCV), real scale (Eq. 8) and t_X (Eq. 6) of rACR's initialization (paper §3.2).

Synthetic motions follow the module's convention: X = T_cam_hand, hand motions M_B = T_hand_hand' and camera
motions M_A = X M_B X⁻¹, whose translation the VSE reports divided by the real scale s (t_VSE = t_A / s).
"""
from __future__ import annotations

import numpy as np
import pytest

from lightfast.geometry import compose, inverse, make_transform, rotation_angle_deg, so3_exp
from lightfast.racr import (
    DegenerateMotionError,
    InitializationConfig,
    InitializationError,
    RacrError,
    hand_eye_rotation,
    hand_eye_translation,
    initialize,
    real_scale,
    relative_motions,
)
from lightfast.racr.initialization import HAND_EYE_METHODS

S_TRUE = 2.5  # metres per VSE unit


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _hand_eye(rng: np.random.Generator) -> np.ndarray:
    return make_transform(so3_exp(rng.normal(size=3)), rng.normal(size=3) * 0.1)


def _motions(
    X: np.ndarray,
    rng: np.random.Generator,
    n: int,
    *,
    angles_deg: tuple[float, float] = (20.0, 40.0),
    axes: np.ndarray | None = None,
    translation_m: float = 0.04,
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` screw motions of the hand and the camera motions the VSE would report (translation / S_TRUE)."""
    M_B = np.stack(
        [
            make_transform(
                so3_exp((_unit(rng) if axes is None else axes[k]) * np.radians(rng.uniform(*angles_deg))),
                rng.normal(size=3) * translation_m,
            )
            for k in range(n)
        ]
    )
    M_A = compose(X, M_B, inverse(X))
    M_A[:, :3, 3] /= S_TRUE
    return M_A, M_B


def _errors(result, X: np.ndarray) -> tuple[float, float, float]:
    return (
        float(rotation_angle_deg(result.T_cam_hand, X)),
        abs(result.scale_m_per_vse / S_TRUE - 1.0),
        float(np.linalg.norm(result.T_cam_hand[:3, 3] - X[:3, 3])),
    )


@pytest.mark.parametrize("method", HAND_EYE_METHODS)
@pytest.mark.parametrize("n", [2, 6])
def test_noise_free_motions_recover_x_and_s_exactly(method: str, n: int) -> None:
    rng = np.random.default_rng(n)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, n)
    result = initialize(M_A, M_B, config=InitializationConfig(method=method))
    rot_deg, scale_rel, trans_m = _errors(result, X)
    assert rot_deg < 1e-7
    assert scale_rel < 1e-10
    assert trans_m < 1e-10
    assert result.rotation_residual_deg < 1e-7 and result.translation_residual_m < 1e-10
    assert result.motions_used_for_scale == n
    np.testing.assert_allclose(result.motion_scales, S_TRUE, rtol=1e-9)


def test_the_steps_compose_to_initialize() -> None:
    rng = np.random.default_rng(3)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, 4)
    R_X = hand_eye_rotation(M_A, M_B)
    s, _ = real_scale(M_A, M_B, R_X)
    t_X = hand_eye_translation(M_A, M_B, R_X, s)
    np.testing.assert_allclose(R_X, X[:3, :3], atol=1e-10)
    assert s == pytest.approx(S_TRUE, rel=1e-12)
    np.testing.assert_allclose(t_X, X[:3, 3], atol=1e-12)


def test_eq8_scale_follows_eq6_not_its_printed_reciprocal() -> None:
    """t_A = s t_VSE (Eq. 6, §3.3): s is metres per VSE unit, so a VSE twice as large halves s."""
    rng = np.random.default_rng(4)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, 3)
    M_A2 = M_A.copy()
    M_A2[:, :3, 3] *= 2.0
    s, _ = real_scale(M_A, M_B, X[:3, :3])
    s2, _ = real_scale(M_A2, M_B, X[:3, :3])
    assert s == pytest.approx(S_TRUE, rel=1e-12)
    assert s2 == pytest.approx(S_TRUE / 2.0, rel=1e-12)


# Noise model and the tolerances it is held to. Measured over 200 seeds (all three of tsai, horaud, park): the
# worst errors were 0.33 deg (R_X), 2.5 % (s) and 7.3 mm (t_X); medians 0.13 deg, 0.6 %, 1.7 mm.
VSE_ROT_NOISE_DEG = 0.1  # per axis, on every camera rotation
VSE_T_NOISE_M = 1e-3  # per axis, on every camera translation (before division by s)
HAND_ROT_NOISE_DEG = 0.02
HAND_T_NOISE_M = 1e-4
TOL_ROT_DEG = 0.5
TOL_SCALE_REL = 0.03
TOL_T_M = 0.01


@pytest.mark.parametrize("seed", range(5))
def test_noisy_motions_stay_within_stated_tolerances(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, 10)
    M_A = M_A.copy()
    M_B = M_B.copy()
    for k in range(len(M_A)):
        M_A[k, :3, :3] = so3_exp(rng.normal(size=3) * np.radians(VSE_ROT_NOISE_DEG)) @ M_A[k, :3, :3]
        M_A[k, :3, 3] += rng.normal(size=3) * VSE_T_NOISE_M / S_TRUE
        M_B[k, :3, :3] = so3_exp(rng.normal(size=3) * np.radians(HAND_ROT_NOISE_DEG)) @ M_B[k, :3, :3]
        M_B[k, :3, 3] += rng.normal(size=3) * HAND_T_NOISE_M
    result = initialize(M_A, M_B)
    rot_deg, scale_rel, trans_m = _errors(result, X)
    assert rot_deg <= TOL_ROT_DEG
    assert scale_rel <= TOL_SCALE_REL
    assert trans_m <= TOL_T_M
    assert 0.0 < result.rotation_residual_deg < 1.0


def test_pure_translations_are_degenerate() -> None:
    rng = np.random.default_rng(5)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, 5, angles_deg=(0.0, 0.0))
    with pytest.raises(DegenerateMotionError, match="pure translations"):
        initialize(M_A, M_B)


def test_parallel_rotation_axes_are_degenerate() -> None:
    rng = np.random.default_rng(6)
    X = _hand_eye(rng)
    axis = _unit(rng)
    M_A, M_B = _motions(X, rng, 5, axes=np.tile(axis, (5, 1)))
    with pytest.raises(DegenerateMotionError, match="parallel"):
        initialize(M_A, M_B)
    with pytest.raises(DegenerateMotionError, match="t_X"):
        hand_eye_translation(M_A, M_B, X[:3, :3], S_TRUE)


def test_one_motion_is_not_enough() -> None:
    rng = np.random.default_rng(7)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, 1)
    with pytest.raises(DegenerateMotionError, match="at least 2"):
        initialize(M_A, M_B)


def test_motions_without_axial_translation_leave_the_scale_undetermined() -> None:
    """Pure rotations of the hand (t_B = 0): Eq. 8 is 0/0 for every motion."""
    rng = np.random.default_rng(8)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, 4, translation_m=0.0)
    with pytest.raises(DegenerateMotionError, match=r"Eq\. 8"):
        initialize(M_A, M_B)


def test_tsai_below_its_rotation_threshold_is_reported_not_returned() -> None:
    """OpenCV 4.x's Tsai drops motions under ~17 deg and returns the identity without raising."""
    rng = np.random.default_rng(9)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, 6, angles_deg=(5.0, 10.0))
    with pytest.raises(DegenerateMotionError, match="horaud"):
        initialize(M_A, M_B)
    result = initialize(M_A, M_B, config=InitializationConfig(method="horaud"))
    assert _errors(result, X)[0] < 1e-7


def test_motions_that_do_not_correspond_are_rejected() -> None:
    rng = np.random.default_rng(10)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, 4)
    with pytest.raises(InitializationError, match="do not correspond"):
        initialize(M_A[::-1], M_B)


def test_opposite_translation_conventions_give_a_clear_error() -> None:
    """Camera motions given as T_cam'_cam while the hand's are T_hand_hand': the scale comes out negative."""
    rng = np.random.default_rng(11)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, 4)
    M_A = M_A.copy()
    M_A[:, :3, 3] *= -1.0
    with pytest.raises(InitializationError, match="non-positive scale"):
        real_scale(M_A, M_B, X[:3, :3])


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda a, b: (a[:, :3, :3], b), "shape"),
        (lambda a, b: (a[:3], b), "pair up"),
        (lambda a, b: (np.where(np.arange(4)[:, None, None] == 1, np.nan, a), b), "non-finite"),
        (lambda a, b: (a * 1.1, b), "bottom row"),
        (lambda a, b: (a, b * np.diag([1.1, 1.0, 1.0, 1.0])), "not rotations"),
    ],
)
def test_invalid_input_raises(mutate, match: str) -> None:
    rng = np.random.default_rng(12)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, 4)
    a, b = mutate(M_A.copy(), M_B.copy())
    with pytest.raises(InitializationError, match=match):
        initialize(a, b)


def test_errors_share_the_racr_root() -> None:
    assert issubclass(DegenerateMotionError, InitializationError)
    assert issubclass(InitializationError, RacrError)
    with pytest.raises(RacrError):
        initialize(np.eye(4)[None], np.eye(4)[None])


def test_missing_calibrate_hand_eye_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    import cv2

    monkeypatch.delattr(cv2, "calibrateHandEye")
    rng = np.random.default_rng(13)
    X = _hand_eye(rng)
    M_A, M_B = _motions(X, rng, 3)
    with pytest.raises(InitializationError, match="calibrateHandEye"):
        initialize(M_A, M_B)


def test_relative_motions_of_a_trajectory_feed_initialize() -> None:
    """Consecutive motions of a hand trajectory and of the camera seen by a VSE (scaled world) pair up."""
    rng = np.random.default_rng(14)
    X = _hand_eye(rng)
    _, M_B = _motions(X, rng, 5)
    T_base_hand = [make_transform(so3_exp(rng.normal(size=3)), rng.normal(size=3))]
    for M in M_B:
        T_base_hand.append(T_base_hand[-1] @ M)
    T_base_hand_arr = np.stack(T_base_hand)
    T_world_cam = compose(T_base_hand_arr, inverse(X))  # camera = hand · T_hand_cam
    T_vse_cam = T_world_cam.copy()
    T_vse_cam[:, :3, 3] /= S_TRUE  # the VSE's world is the real one shrunk by s
    hand = relative_motions(T_base_hand_arr)
    np.testing.assert_allclose(hand, M_B, atol=1e-12)
    result = initialize(relative_motions(T_vse_cam), hand)
    rot_deg, scale_rel, trans_m = _errors(result, X)
    assert rot_deg < 1e-7 and scale_rel < 1e-10 and trans_m < 1e-10
    with pytest.raises(InitializationError, match="two poses"):
        relative_motions(T_base_hand_arr[:1])
