"""The VO prior of a localization (:mod:`lightfast.vtr.vo_prior`): covariance propagation and fusion, against
sampling and closed forms."""
from __future__ import annotations

import numpy as np

from lightfast.geometry import inverse, make_transform, se3_exp, se3_log, so3_exp
from lightfast.vtr.vo_prior import add_keyframe_noise, adjoint, fuse, propagate_covariance


def test_adjoint_moves_a_perturbation_across_a_transform() -> None:
    rng = np.random.default_rng(0)
    T = make_transform(so3_exp(rng.normal(size=3)), rng.normal(size=3))
    xi = 0.1 * rng.normal(size=6)
    np.testing.assert_allclose(T @ se3_exp(xi) @ inverse(T), se3_exp(adjoint(T) @ xi), atol=1e-12)


def test_propagated_covariance_matches_sampled_poses() -> None:
    """A yaw uncertainty of the previous pose becomes a sideways position uncertainty after driving 2 m forward (the
    lever arm), plus the VO noise of 2 m; checked against 20,000 sampled poses."""
    rng = np.random.default_rng(1)
    P = np.diag([0.01**2] * 3 + [np.radians(1.0) ** 2] * 3)
    motion = make_transform(np.eye(3), [0.0, 0.0, 2.0])  # camera z forward
    Q_pos, Q_rot_deg = 0.05, 0.1
    expected = propagate_covariance(P, motion, 2.0, Q_pos, Q_rot_deg)
    xi_prev = rng.multivariate_normal(np.zeros(6), P, size=20000)
    noise = rng.multivariate_normal(np.zeros(6), np.diag([(Q_pos * 2) ** 2] * 3 + [np.radians(Q_rot_deg * 2) ** 2] * 3),
                                    size=20000)
    xi_cur = np.array([se3_log(inverse(motion) @ se3_exp(a) @ motion @ se3_exp(b)) for a, b in zip(xi_prev, noise,
                                                                                                    strict=True)])
    sampled = np.cov(xi_cur.T)
    np.testing.assert_allclose(np.sqrt(np.diag(sampled)), np.sqrt(np.diag(expected)), rtol=0.03)
    assert np.sqrt(expected[0, 0]) > 0.03  # 1 deg of yaw at 2 m: 3.5 cm sideways, beyond the VO noise


def test_fusion_keeps_the_prior_along_the_axis_the_localization_cannot_see() -> None:
    """A localization 1 m off along the optical axis, resting on far points (5 m standard deviation along z, 2 cm
    across), fused with a prior 10 cm uncertain: z comes from the prior, x and y from the localization."""
    T_true = make_transform(so3_exp([0.0, 0.02, 0.0]), [0.3, -0.1, 4.0])
    T_loc = T_true @ se3_exp([0.05, 0.0, 1.0, 0.0, 0.0, 0.0])
    T_prior = T_true @ se3_exp([0.0, 0.0, 0.05, 0.0, 0.0, 0.0])
    C_loc = np.diag([0.02**2, 0.02**2, 5.0**2, 1e-4, 1e-4, 1e-4])
    P = np.diag([0.1**2] * 3 + [1e-3] * 3)
    T, C = fuse(T_loc, C_loc, T_prior, P)
    err = se3_log(inverse(T_true) @ T)
    assert abs(err[2] - 0.05) < 0.01  # the prior's z
    assert abs(err[0] - 0.05 * 0.1**2 / (0.02**2 + 0.1**2)) < 0.002  # x mostly the localization's (0.05)
    assert np.all(np.linalg.eigvalsh(C) > 0) and C[2, 2] < P[2, 2] and C[0, 0] < C_loc[0, 0]


def test_equal_covariances_fuse_to_the_midpoint() -> None:
    T_a = make_transform(np.eye(3), [0.0, 0.0, 0.0])
    T_b = make_transform(np.eye(3), [0.2, -0.4, 0.6])
    C = np.diag([0.1**2] * 3 + [1e-3] * 3)
    T, F = fuse(T_a, C, T_b, C)
    np.testing.assert_allclose(T[:3, 3], [0.1, -0.2, 0.3], atol=1e-12)
    np.testing.assert_allclose(F, C / 2, atol=1e-15)


def test_a_localization_without_a_covariance_is_kept_as_it_is() -> None:
    T_loc = make_transform(np.eye(3), [1.0, 2.0, 3.0])
    C_inf = np.full((6, 6), np.inf)
    T, C = fuse(T_loc, C_inf, np.eye(4), np.eye(6))
    assert T is T_loc and C is C_inf
    T, C = fuse(T_loc, np.eye(6), np.eye(4), np.zeros((6, 6)))  # a singular prior
    assert T is T_loc


def test_keyframe_noise_adds_on_the_diagonal() -> None:
    P = add_keyframe_noise(np.zeros((6, 6)), 0.1, 0.15)
    np.testing.assert_allclose(np.diag(P), [0.01] * 3 + [np.radians(0.15) ** 2] * 3)


def test_the_vo_steps_own_covariance_is_added_where_it_is_uncertain() -> None:
    """A VO step resting on far points: its nominal covariance is 0.5 m along the optical axis, 2 cm across. The
    prior's covariance gains it on top of the per-metre noise, in the current frame; a step without an estimate
    (infinite covariance) adds the per-metre noise only."""
    motion = make_transform(np.eye(3), [0.0, 0.0, 0.8])
    step = np.diag([0.02**2, 0.02**2, 0.5**2, 1e-6, 1e-6, 1e-6])
    base = propagate_covariance(np.zeros((6, 6)), motion, 0.8, 0.06, 0.2)
    with_step = propagate_covariance(np.zeros((6, 6)), motion, 0.8, 0.06, 0.2, step)
    np.testing.assert_allclose(with_step - base, step, atol=1e-15)
    assert np.sqrt(with_step[2, 2]) > 0.5 > 10 * np.sqrt(base[2, 2])
    np.testing.assert_array_equal(propagate_covariance(np.zeros((6, 6)), motion, 0.8, 0.06, 0.2,
                                                       np.full((6, 6), np.inf)), base)
