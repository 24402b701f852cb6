"""Unit tests of lightfast.geometry: closed forms against scipy (expm, Rotation), round trips, edge angles, errors."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from lightfast import geometry as g
from lightfast.errors import GeometryError, LightfastError

finite = st.floats(min_value=-10.0, max_value=10.0, allow_nan=False, allow_infinity=False)
vec3 = arrays(np.float64, 3, elements=finite)
unit_axis = vec3.filter(lambda a: np.linalg.norm(a) > 1e-3).map(lambda a: a / np.linalg.norm(a))
# angles concentrated on the hard cases: tiny, around the Taylor threshold, generic, and right below pi
angle = st.one_of(
    st.floats(min_value=0.0, max_value=1e-6),
    st.floats(min_value=5e-3, max_value=2e-2),
    st.floats(min_value=0.0, max_value=np.pi),
    st.floats(min_value=np.pi - 1e-6, max_value=np.pi),
)
rotvec = st.builds(lambda a, t: a * t, unit_axis, angle)
log_scale = st.one_of(st.floats(min_value=-1e-6, max_value=1e-6), st.floats(min_value=-3.0, max_value=3.0))


def generator_se3(xi: np.ndarray) -> np.ndarray:
    G = np.zeros((4, 4))
    G[:3, :3] = g.hat(xi[3:])
    G[:3, 3] = xi[:3]
    return G


def generator_sim3(v: np.ndarray) -> np.ndarray:
    G = np.zeros((4, 4))
    G[:3, :3] = g.hat(v[3:6]) + v[6] * np.eye(3)
    G[:3, 3] = v[:3]
    return G


def expm_reference(G: np.ndarray) -> np.ndarray:
    """Matrix exponential in extended precision (long double Taylor series with scaling and squaring).

    scipy's expm is only good to ~1e-13 relative for larger norms, too coarse to check the closed forms.
    """
    A = G.astype(np.longdouble)
    k = max(0, int(np.ceil(np.log2(float(np.abs(G).sum(axis=1).max()) + 1e-300))) + 4)
    A = A / np.longdouble(2.0) ** k
    E = np.eye(G.shape[0], dtype=np.longdouble)
    term = E.copy()
    for i in range(1, 40):
        term = term @ A / i
        E = E + term
    for _ in range(k):
        E = E @ E
    return E


# tolerance of comparisons against expm_reference: tight where long double is wider than double (x86-64)
REF_RTOL = 2e-15 if np.finfo(np.longdouble).eps < 1e-17 else 5e-13


def random_rotations(n: int, seed: int = 0) -> np.ndarray:
    return Rotation.random(n, random_state=seed).as_matrix()


# ---------------------------------------------------------------------------------------------------------------
# hat / vee / SO(3)


@given(vec3, vec3)
def test_hat_is_cross_product_and_vee_inverts_it(v: np.ndarray, w: np.ndarray) -> None:
    np.testing.assert_allclose(g.hat(v) @ w, np.cross(v, w), atol=1e-12)
    np.testing.assert_array_equal(g.vee(g.hat(v)), v)
    np.testing.assert_array_equal(g.hat(v), -g.hat(v).T)


def test_hat_batched_shape() -> None:
    v = np.arange(24.0).reshape(2, 4, 3)
    H = g.hat(v)
    assert H.shape == (2, 4, 3, 3)
    np.testing.assert_array_equal(H[1, 2], g.hat(v[1, 2]))


@given(rotvec)
def test_so3_exp_matches_scipy(phi: np.ndarray) -> None:
    np.testing.assert_allclose(g.so3_exp(phi), Rotation.from_rotvec(phi).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(g.so3_exp(phi), scipy.linalg.expm(g.hat(phi)), atol=1e-13)


@given(rotvec)
def test_so3_log_round_trip(phi: np.ndarray) -> None:
    R = g.so3_exp(phi)
    back = g.so3_log(R)
    np.testing.assert_allclose(g.so3_exp(back), R, atol=1e-14)
    theta = np.linalg.norm(phi)
    if theta < np.pi - 1e-6:  # below pi the vector is unique
        np.testing.assert_allclose(back, phi, rtol=1e-12, atol=1e-15)
    else:  # at pi, +phi and -phi are the same rotation
        assert min(np.abs(back - phi).max(), np.abs(back + phi).max()) < 1e-6
    assert np.linalg.norm(back) <= np.pi + 1e-15


@pytest.mark.parametrize("theta", [0.0, 1e-300, 1e-12, 1e-8, 1e-5, 1e-3, 2e-2 - 1e-12, 2e-2, 2e-2 + 1e-12, 0.3, 3.0])
def test_so3_log_tiny_and_threshold_angles_are_exact(theta: float) -> None:
    axis = np.array([2.0, -3.0, 6.0]) / 7.0
    phi = theta * axis
    back = g.so3_log(g.so3_exp(phi))
    np.testing.assert_allclose(back, phi, rtol=1e-15, atol=1e-300)


@pytest.mark.parametrize("eps", [0.0, 1e-12, 1e-9, 1e-6, 1e-4])
def test_so3_log_near_pi_keeps_angle(eps: float) -> None:
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    phi = (np.pi - eps) * axis
    back = g.so3_log(g.so3_exp(phi))
    assert abs(np.linalg.norm(back) - (np.pi - eps)) < 1e-12
    assert min(np.abs(back - phi).max(), np.abs(back + phi).max()) < 1e-9
    np.testing.assert_allclose(g.so3_exp(back), g.so3_exp(phi), atol=1e-14)


def test_so3_log_of_exact_half_turns() -> None:
    for axis in np.eye(3):
        R = 2.0 * np.outer(axis, axis) - np.eye(3)  # rotation by pi about axis
        phi = g.so3_log(R)
        assert np.linalg.norm(phi) == pytest.approx(np.pi, abs=1e-15)
        np.testing.assert_allclose(np.abs(phi), np.pi * axis, atol=1e-15)


# Extended-precision references of the closed-form coefficients. They detect a wrong Taylor term that the matrices
# hide (the K^2 coefficients only enter multiplied by t^2). Above the series threshold the closed forms lose up to
# ~eps/t^2 relative in the K^2 coefficients (cancellation), which again costs only ~eps absolute in the matrices.
LD = np.longdouble
EPS = np.finfo(np.float64).eps


def coeffs_reference(t: float, lam: float) -> tuple[LD, LD, LD, LD]:
    """``(integral cos(ts), a, b, c)`` of ``e^(lam s) (cos ts, 1, sin(ts)/t, 2 sin^2(ts/2)/t^2)`` over ``s in [0, 1]``.

    Composite Gauss-Legendre quadrature (32 panels x 8 nodes, whose float64 nodes are accurate) in long double;
    the integrands are written without cancellation (no 1 - cos).
    """
    x, w = np.polynomial.legendre.leggauss(8)
    panels = 32
    s = (np.arange(panels, dtype=LD)[:, None] + (1 + x.astype(LD)[None]) / 2).ravel() / panels
    w = np.tile(w.astype(LD) / (2 * panels), panels)
    t, lam = LD(t), LD(lam)
    e = np.exp(lam * s)
    half = t * s / 2
    sinc_half = np.where(half > 0, np.sin(half) / np.where(half > 0, half, 1), LD(1))
    return (
        np.sum(w * np.cos(t * s)),
        np.sum(w * e),
        np.sum(w * e * s * np.cos(half) * sinc_half),  # sin(ts)/t = s cos(ts/2) sinc(ts/2)
        np.sum(w * e * s**2 / 2 * sinc_half**2),  # 2 sin^2(ts/2)/t^2 = (s^2/2) sinc^2(ts/2)
    )


def se3_inv_coeff_reference(t: float) -> LD:
    """``D = 1/t^2 - cot(t/2)/(2t)``: its Bernoulli series for small t, the closed form in long double otherwise."""
    t = LD(t)
    if t < 0.05:
        t2 = t * t
        return LD(1) / 12 + t2 / 720 + t2**2 / 30240 + t2**3 / 1209600 + t2**4 / 47900160
    return 1 / t**2 - np.cos(t / 2) / (2 * t * np.sin(t / 2))


def relerr(value: object, ref: LD) -> float:
    return abs(float((LD(float(value)) - ref) / ref))


COEFF_ANGLES = [0.0, 1e-7, 1e-4, 1e-3, 5e-3, 9.9999e-3, 1.00001e-2, 2e-2, 0.1, 2.0, np.pi - 1e-4]


@pytest.mark.skipif(np.finfo(np.longdouble).eps > 1e-17, reason="needs an extended-precision long double")
@pytest.mark.parametrize("theta", COEFF_ANGLES)
def test_closed_form_coefficients_match_extended_precision(theta: float) -> None:
    series = theta < 1e-2  # the series branch must be accurate to a few ulp
    tol = 5e-15 if series else 5e-15 + 64 * EPS / theta**2
    A, B, C = g._so3_coeffs(np.array(theta))
    A_ref, _, B_ref, C_ref = coeffs_reference(theta, 0.0)
    assert relerr(A, A_ref) < 5e-15 and relerr(B, B_ref) < 5e-15 and relerr(C, C_ref) < tol
    D_ref = se3_inv_coeff_reference(theta)
    assert relerr(g._se3_inv_coeff(np.array(theta)), D_ref) < tol
    for lam in (0.0, 1e-9, -0.3, 1.5, -1.999, 2.001, -4.0, 6.0):
        a, b, c = g._sim3_coeffs(np.array(theta), np.array(lam))
        _, a_ref, b_ref, c_ref = coeffs_reference(theta, lam)
        assert relerr(a, a_ref) < 5e-15, lam
        assert relerr(b, b_ref) < (5e-15 if series else 5e-15 + 8 * EPS / theta), lam
        assert relerr(c, c_ref) < tol, lam


def test_so3_batched_exp_log() -> None:
    phis = Rotation.random(50, random_state=1).as_rotvec().reshape(5, 10, 3)
    R = g.so3_exp(phis)
    assert R.shape == (5, 10, 3, 3)
    np.testing.assert_allclose(R[3, 7], g.so3_exp(phis[3, 7]), atol=0)
    np.testing.assert_allclose(g.so3_log(R), phis, atol=1e-13)


# ---------------------------------------------------------------------------------------------------------------
# quaternions


@given(rotvec)
def test_matrix_to_quat_matches_scipy_canonical(phi: np.ndarray) -> None:
    R = Rotation.from_rotvec(phi)
    q = g.matrix_to_quat(R.as_matrix())
    assert q[3] >= 0.0
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
    expected = R.as_quat(canonical=True)
    # at exactly w == 0 both pick a sign by the first non-zero component; guard against float ties anyway
    assert min(np.abs(q - expected).max(), np.abs(q + expected).max() if abs(q[3]) < 1e-12 else 1.0) < 1e-14


@given(arrays(np.float64, 4, elements=finite).filter(lambda q: np.linalg.norm(q) > 1e-3))
def test_quat_round_trip(q_raw: np.ndarray) -> None:
    q = q_raw / np.linalg.norm(q_raw)
    R = g.quat_to_matrix(q)
    np.testing.assert_allclose(R, Rotation.from_quat(q).as_matrix(), atol=1e-14)
    assert g.is_rotation(R, atol=1e-14)
    back = g.matrix_to_quat(R)
    sign = 1.0 if q[3] > 0 else -1.0
    if abs(q[3]) > 1e-9:
        np.testing.assert_allclose(back, sign * q, atol=1e-14)
    np.testing.assert_allclose(g.quat_to_matrix(back), R, atol=1e-14)


@pytest.mark.parametrize("eps", [0.0, 1e-10, 1e-7, 1e-4])
def test_quat_round_trip_near_pi(eps: float) -> None:
    axes = Rotation.random(20, random_state=3).as_rotvec()
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    rotvecs = axes * (np.pi - eps)
    R = g.so3_exp(rotvecs)
    q = g.matrix_to_quat(R)
    assert np.all(q[:, 3] >= 0.0)
    np.testing.assert_allclose(q[:, 3], np.sin(eps / 2.0), atol=1e-15)
    np.testing.assert_allclose(g.quat_to_matrix(q), R, atol=1e-14)
    expected = Rotation.from_matrix(R).as_quat(canonical=True)
    if eps > 0:
        np.testing.assert_allclose(q, expected, atol=1e-13)


def test_quat_identity_and_known_rotation() -> None:
    np.testing.assert_array_equal(g.quat_to_matrix([0.0, 0.0, 0.0, 1.0]), np.eye(3))
    s = np.sqrt(0.5)
    Rz90 = g.quat_to_matrix([0.0, 0.0, s, s])  # +90 deg about z: x -> y
    np.testing.assert_allclose(Rz90 @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(g.matrix_to_quat(Rz90), [0.0, 0.0, s, s], atol=1e-15)
    # -q is the same rotation; matrix_to_quat returns the w >= 0 form
    np.testing.assert_allclose(g.matrix_to_quat(g.quat_to_matrix([0.0, 0.0, -s, -s])), [0.0, 0.0, s, s], atol=1e-15)


def test_quat_near_unit_is_normalized_far_raises() -> None:
    q = np.array([0.1, -0.2, 0.3, 0.9])
    q /= np.linalg.norm(q)
    np.testing.assert_allclose(g.quat_to_matrix(q * (1.0 + 9e-4)), g.quat_to_matrix(q), atol=1e-15)
    with pytest.raises(GeometryError, match="q_xyzw"):
        g.quat_to_matrix(q * 1.01)
    with pytest.raises(GeometryError, match="q_xyzw"):
        g.quat_to_matrix([0.0, 0.0, 0.0, 0.0])
    with pytest.raises(GeometryError, match="q_xyzw"):
        g.quat_to_matrix([0.0, 0.0, 1.0])


def test_quat_batched() -> None:
    q = Rotation.random(12, random_state=4).as_quat(canonical=True).reshape(3, 4, 4)
    R = g.quat_to_matrix(q)
    assert R.shape == (3, 4, 3, 3)
    np.testing.assert_allclose(g.matrix_to_quat(R), q, atol=1e-14)


# ---------------------------------------------------------------------------------------------------------------
# SE(3)


@given(vec3, rotvec)
def test_se3_exp_matches_expm_and_log_round_trips(rho: np.ndarray, phi: np.ndarray) -> None:
    xi = np.concatenate([rho, phi])
    T = g.se3_exp(xi)
    np.testing.assert_allclose(T, scipy.linalg.expm(generator_se3(xi)), rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(T[3], [0.0, 0.0, 0.0, 1.0])
    back = g.se3_log(T)
    np.testing.assert_allclose(g.se3_exp(back), T, atol=1e-11)
    if np.linalg.norm(phi) < np.pi - 1e-3:
        np.testing.assert_allclose(back, xi, rtol=1e-10, atol=1e-12)


def test_se3_exp_single_twist_path_equals_the_batched_one() -> None:
    rng = np.random.default_rng(3)
    xi = np.concatenate([rng.normal(size=(400, 6)) * s for s in (1e-5, 3e-3, 0.05, 1.0)])  # both coefficient branches
    batched = g.se3_exp(xi)
    single = np.stack([g.se3_exp(x) for x in xi])
    np.testing.assert_allclose(single, batched, rtol=0, atol=1e-14)
    with pytest.raises(g.GeometryError, match="non-finite"):
        g.se3_exp(np.array([0.0, 0.0, np.nan, 0.0, 0.0, 0.0]))


def test_se3_log_single_matrix_path_equals_the_batched_one() -> None:
    rng = np.random.default_rng(4)
    xi = np.concatenate([rng.normal(size=(400, 6)) * s for s in (1e-5, 3e-3, 0.05, 1.0)])  # both series branches
    xi = xi[np.linalg.norm(xi[:, 3:], axis=1) < 3.0]  # away from pi, where phi and -phi are the same rotation
    T = g.se3_exp(xi)
    batched = g.se3_log(T)
    single = np.stack([g.se3_log(t) for t in T])
    np.testing.assert_allclose(single, batched, rtol=0, atol=1e-13)
    bad = T[0].copy()
    bad[0, 0] += 1e-3
    with pytest.raises(g.GeometryError, match="not a rotation matrix"):
        g.se3_log(bad)


def test_se3_pure_translation_and_known_screw() -> None:
    T = g.se3_exp([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(T, g.make_transform(np.eye(3), [1.0, 2.0, 3.0]))
    # quarter turn about z with rho along x: the translation is V rho = (sin t / t, (1 - cos t) / t, 0) for t = pi/2
    T = g.se3_exp([1.0, 0.0, 0.0, 0.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(T[:3, 3], [2.0 / np.pi, 2.0 / np.pi, 0.0], atol=1e-15)


def test_se3_batched() -> None:
    rng = np.random.default_rng(5)
    xi = np.concatenate([rng.normal(size=(40, 3)), Rotation.random(40, random_state=5).as_rotvec()], axis=-1)
    T = g.se3_exp(xi)
    assert T.shape == (40, 4, 4)
    np.testing.assert_allclose(T[17], g.se3_exp(xi[17]), atol=0)
    np.testing.assert_allclose(g.se3_log(T), xi, atol=1e-12)


# ---------------------------------------------------------------------------------------------------------------
# Sim(3)


@settings(max_examples=300)
@given(vec3, rotvec, log_scale)
def test_sim3_exp_matches_expm_and_log_round_trips(rho: np.ndarray, phi: np.ndarray, lam: float) -> None:
    v = np.concatenate([rho, phi, [lam]])
    S = g.sim3_exp(v)
    expected = scipy.linalg.expm(generator_sim3(v))
    np.testing.assert_allclose(S, expected, rtol=1e-11, atol=1e-11 * max(1.0, np.abs(expected).max()))
    back = g.sim3_log(S)
    np.testing.assert_allclose(g.sim3_exp(back), S, rtol=1e-11, atol=1e-11 * max(1.0, np.abs(S).max()))
    assert back[6] == pytest.approx(lam, abs=1e-14)
    if np.linalg.norm(phi) < np.pi - 1e-3:
        np.testing.assert_allclose(back, v, rtol=1e-9, atol=1e-11)


@pytest.mark.parametrize("lam", [0.0, 1e-12, -1e-8, 1e-4, 0.5, -1.999, 2.0, 2.001, -6.0])
@pytest.mark.parametrize("theta", [0.0, 1e-10, 1e-4, 9.99e-3, 1.001e-2, 0.7, np.pi - 1e-5])
def test_sim3_left_jacobian_regimes(lam: float, theta: float) -> None:
    """Every branch (small/large angle x series/recursion scale moments) is accurate to a few ulp."""
    v = np.concatenate([[0.3, -1.2, 0.8], theta * np.array([0.6, 0.0, -0.8]), [lam]])
    S = g.sim3_exp(v)
    expected = expm_reference(generator_sim3(v))
    err = float(np.abs(S - expected).max())
    assert err <= REF_RTOL * max(1.0, float(np.abs(expected).max()))
    np.testing.assert_allclose(g.sim3_log(S), v, rtol=0, atol=1e-12)


def test_sim3_with_zero_scale_equals_se3() -> None:
    rng = np.random.default_rng(6)
    xi = np.concatenate([rng.normal(size=(20, 3)), Rotation.random(20, random_state=6).as_rotvec()], axis=-1)
    v = np.concatenate([xi, np.zeros((20, 1))], axis=-1)
    np.testing.assert_allclose(g.sim3_exp(v), g.se3_exp(xi), atol=1e-14)


def test_sim3_inverse_and_scale() -> None:
    v = np.array([0.5, -1.0, 2.0, 0.3, 0.2, -0.1, np.log(2.5)])
    S = g.sim3_exp(v)
    assert np.cbrt(np.linalg.det(S[:3, :3])) == pytest.approx(2.5, rel=1e-14)
    np.testing.assert_allclose(g.sim3_inverse(S) @ S, np.eye(4), atol=1e-14)
    np.testing.assert_allclose(g.sim3_inverse(S), np.linalg.inv(S), atol=1e-14)
    np.testing.assert_allclose(g.sim3_log(g.sim3_inverse(S)), g.sim3_log(np.linalg.inv(S)), atol=1e-13)
    p = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(g.transform_points(S, p), 2.5 * g.so3_exp(v[3:6]) @ p + S[:3, 3], atol=1e-14)


def test_sim3_batched() -> None:
    rng = np.random.default_rng(7)
    v = np.concatenate(
        [rng.normal(size=(30, 3)), Rotation.random(30, random_state=7).as_rotvec(), rng.uniform(-2, 2, (30, 1))],
        axis=-1,
    ).reshape(5, 6, 7)
    S = g.sim3_exp(v)
    assert S.shape == (5, 6, 4, 4)
    np.testing.assert_allclose(g.sim3_log(S), v, atol=1e-12)


# ---------------------------------------------------------------------------------------------------------------
# transforms


def test_make_transform_inverse_compose_and_points() -> None:
    R = random_rotations(3, seed=8)
    t = np.array([[1.0, 2.0, 3.0], [-4.0, 0.5, 0.0], [0.0, 0.0, 10.0]])
    T_a_b, T_b_c, T_c_d = (g.make_transform(R[i], t[i]) for i in range(3))
    np.testing.assert_allclose(g.inverse(T_a_b) @ T_a_b, np.eye(4), atol=1e-14)
    np.testing.assert_allclose(g.inverse(T_a_b), np.linalg.inv(T_a_b), atol=1e-14)
    T_a_d = g.compose(T_a_b, T_b_c, T_c_d)
    np.testing.assert_allclose(T_a_d, T_a_b @ T_b_c @ T_c_d, atol=1e-14)
    np.testing.assert_array_equal(g.compose(T_a_b), T_a_b)
    p_d = np.random.default_rng(8).normal(size=(7, 5, 3))
    chained = g.transform_points(T_a_b, g.transform_points(T_b_c, g.transform_points(T_c_d, p_d)))
    np.testing.assert_allclose(g.transform_points(T_a_d, p_d), chained, atol=1e-13)
    assert g.transform_points(T_a_d, p_d).shape == (7, 5, 3)
    # t_a_b is the origin of frame b in frame a
    np.testing.assert_allclose(g.transform_points(T_a_b, [0.0, 0.0, 0.0]), t[0], atol=0)


def test_batched_transforms_broadcast() -> None:
    R = random_rotations(4, seed=9)
    t = np.arange(12.0).reshape(4, 3)
    T = g.make_transform(R, t)
    assert T.shape == (4, 4, 4)
    np.testing.assert_allclose(g.inverse(T) @ T, np.broadcast_to(np.eye(4), (4, 4, 4)), atol=1e-13)
    p = np.ones((4, 3))
    np.testing.assert_allclose(g.transform_points(T, p), np.einsum("nij,nj->ni", R, p) + t, atol=1e-13)
    T_shared_rot = g.make_transform(R[0], t)  # one rotation, four translations
    np.testing.assert_array_equal(T_shared_rot[:, :3, :3], np.broadcast_to(R[0], (4, 3, 3)))


def test_is_rotation_and_project_to_so3() -> None:
    R = random_rotations(10, seed=10)
    assert np.all(g.is_rotation(R))
    assert g.is_rotation(np.eye(3)) and isinstance(g.is_rotation(np.eye(3)), np.bool_)
    assert not g.is_rotation(np.diag([1.0, 1.0, -1.0]))  # reflection
    assert not g.is_rotation(2.0 * np.eye(3))
    assert not g.is_rotation(np.full((3, 3), np.nan))
    assert not g.is_rotation(np.eye(3) + 1e-5) and g.is_rotation(np.eye(3) + 1e-5, atol=1e-4)
    noisy = R + np.random.default_rng(10).normal(scale=1e-3, size=R.shape)
    assert not np.any(g.is_rotation(noisy))
    fixed = g.project_to_so3(noisy)
    assert np.all(g.is_rotation(fixed, atol=1e-14))
    # nearest rotation in Frobenius norm = orthogonal polar factor (det > 0 here)
    for i in range(10):
        np.testing.assert_allclose(fixed[i], scipy.linalg.polar(noisy[i])[0], atol=1e-13)
    np.testing.assert_allclose(g.project_to_so3(R), R, atol=1e-14)
    assert g.is_rotation(g.project_to_so3(np.diag([1.0, 1.0, -1.0])))


def test_error_metrics() -> None:
    Rz30 = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    assert g.rotation_angle_deg(Rz30) == pytest.approx(30.0, abs=1e-12)
    assert g.rotation_angle_deg(np.eye(3)) == 0.0
    Rz50 = Rotation.from_euler("z", 50, degrees=True).as_matrix()
    assert g.rotation_angle_deg(Rz50, Rz30) == pytest.approx(20.0, abs=1e-12)
    assert g.rotation_angle_deg(g.make_transform(Rz50, [1, 2, 3]), g.make_transform(Rz30, [0, 0, 0])) == (
        pytest.approx(20.0, abs=1e-12)
    )
    assert g.rotation_angle_deg(g.so3_exp([0.0, np.pi - 1e-9, 0.0])) == pytest.approx(180.0 - np.degrees(1e-9))
    assert g.rotation_angle_deg(g.so3_exp([1e-9, 0.0, 0.0])) == pytest.approx(np.degrees(1e-9), rel=1e-12)
    batch = g.rotation_angle_deg(g.so3_exp(np.array([[0.1, 0, 0], [0, 0.2, 0], [0, 0, 3.0]])))
    np.testing.assert_allclose(batch, np.degrees([0.1, 0.2, 3.0]), rtol=1e-13)
    assert g.translation_distance([0.0, 0.0, 0.0], [3.0, 4.0, 0.0]) == pytest.approx(5.0)
    T = g.make_transform(np.eye(3), [3.0, 4.0, 12.0])
    assert g.translation_distance(T, np.eye(4)) == pytest.approx(13.0)
    assert g.translation_distance(T, [3.0, 4.0, 0.0]) == pytest.approx(12.0)


# ---------------------------------------------------------------------------------------------------------------
# validation


def test_geometry_error_types() -> None:
    assert issubclass(GeometryError, LightfastError) and issubclass(GeometryError, ValueError)


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda: g.so3_exp([1.0, 2.0]), "phi"),
        (lambda: g.so3_exp([np.nan, 0.0, 0.0]), "phi"),
        (lambda: g.so3_log(np.eye(4)), "R"),
        (lambda: g.so3_log(2.0 * np.eye(3)), "R"),
        (lambda: g.hat(np.zeros(4)), "v"),
        (lambda: g.se3_exp(np.zeros(7)), "xi"),
        (lambda: g.se3_exp([0, 0, 0, 0, np.inf, 0]), "xi"),
        (lambda: g.se3_log(np.zeros((3, 4))), "T"),
        (lambda: g.se3_log(np.ones((4, 4))), "T"),
        (lambda: g.sim3_exp(np.zeros(6)), "v"),
        (lambda: g.sim3_log(np.diag([-1.0, -1.0, -1.0, 1.0])), "S"),
        (lambda: g.sim3_inverse(np.zeros((4, 4)) + np.eye(4) * [1, 1, 0, 1]), "S"),
        (lambda: g.make_transform(np.eye(3), [1.0, 2.0]), "t"),
        (lambda: g.make_transform(np.diag([1.0, 1.0, -1.0]), [0, 0, 0]), "R"),
        (lambda: g.inverse(g.sim3_exp([0, 0, 0, 0, 0, 0, 0.5])), "T"),
        (lambda: g.compose(np.eye(4), np.eye(3)), "Ts\\[1\\]"),
        (lambda: g.compose(), "at least one"),
        (lambda: g.transform_points(np.eye(4), np.zeros((5, 2))), "p"),
        (lambda: g.transform_points(np.eye(4), [[np.nan, 0.0, 0.0]]), "p"),
        (lambda: g.matrix_to_quat(np.zeros((3, 3))), "R"),
        (lambda: g.is_rotation(np.eye(2)), "R"),
        (lambda: g.project_to_so3(np.full((3, 3), np.inf)), "R"),
        (lambda: g.rotation_angle_deg(np.eye(3), np.zeros((2, 2))), "R_ref"),
        (lambda: g.translation_distance(np.zeros(3), np.zeros(2)), "b"),
        (lambda: g.so3_exp("abc"), "phi"),
    ],
)
def test_invalid_inputs_raise_geometry_error_naming_argument(call: Callable[[], object], name: str) -> None:
    with pytest.raises(GeometryError, match=rf"\b{name}"):
        call()


def test_look_at_points_the_optical_axis_and_keeps_x_level() -> None:
    T = g.look_at([1.0, 2.0, 1.5], [3.0, 2.0, 1.5])  # looking east
    assert g.is_rotation(T[:3, :3])
    np.testing.assert_allclose(T[:3, 2], [1.0, 0.0, 0.0], atol=1e-12)  # z forward
    np.testing.assert_allclose(T[:3, 0], [0.0, -1.0, 0.0], atol=1e-12)  # x right (south), level
    np.testing.assert_allclose(T[:3, 1], [0.0, 0.0, -1.0], atol=1e-12)  # y down
    np.testing.assert_allclose(T[:3, 3], [1.0, 2.0, 1.5])
    rolled = g.look_at([1.0, 2.0, 1.5], [3.0, 2.0, 1.5], roll_rad=np.pi / 2)
    np.testing.assert_allclose(rolled[:3, 2], T[:3, 2], atol=1e-12)
    np.testing.assert_allclose(rolled[:3, 0], T[:3, 1], atol=1e-12)  # x turned into the old y
    down = g.look_at([0.0, 0.0, 2.0], [0.0, 0.0, 0.0])  # along up: still a rotation
    assert g.is_rotation(down[:3, :3]) and np.allclose(down[:3, 2], [0.0, 0.0, -1.0])
    with pytest.raises(GeometryError, match="apart"):
        g.look_at([1.0, 1.0, 1.0], [1.0, 1.0, 1.0])
