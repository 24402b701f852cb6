"""rACR-S (paper §5.4): the alignment that estimates only T_p and keeps σ_p fixed (``estimate_scale=False`` in
:class:`FastAlignmentConfig` and :class:`FineAlignmentConfig`).

The fast alignment is checked on the real-surface set of ``test_fast_alignment.py`` (real 3DMatch geometry, exact
truth), the fine alignment on the ray-cast relief of ``test_fine_alignment.py``.
"""
from __future__ import annotations

import numpy as np
import pytest

from lightfast.racr import FastAlignmentConfig, FineAlignmentConfig, fast_align, fine_align
from test.unit.racr.test_fast_alignment import (  # noqa: F401  (fixtures)
    _as_current,
    _errors,
    _perturbed_start,
    _true_pose,
    pair,
    real_surface,
)
from test.unit.racr.test_fine_alignment import (  # noqa: F401  (fixtures)
    DRIFT,
    T_CUR_CAM,
    TRUE_SIGMA,
    TRUE_T,
    camera_error,
    current_observation,
    reference,
    scene,
)

FIXED = FastAlignmentConfig(estimate_scale=False)


def test_fast_alignment_with_the_true_scale_fixed_recovers_the_pose(real_surface) -> None:  # noqa: F811 (fixtures)
    """σ_p stays exactly at sigma_init; given the true σ, T_p is recovered as well as with the scale free."""
    ref_cloud, current_ref = real_surface
    sigma = 1.6
    T0, _ = _perturbed_start(_true_pose(), sigma, current_ref, np.random.default_rng(11))
    result = fast_align(_as_current(current_ref, sigma), ref_cloud, T_ref_cur_init=T0, sigma_init=sigma,
                        config=FIXED)
    rot_deg, t_m, _ = _errors(result, _true_pose(), sigma)
    assert result.sigma == sigma and result.converged
    assert rot_deg <= 0.3 and t_m <= 0.01


def test_fast_alignment_with_a_wrong_fixed_scale_is_worse_than_scale_aware(real_surface) -> None:  # noqa: F811 (fixtures)
    """With σ_p fixed 4 % off (what an imperfect Eq. 8 scale leaves), T_p absorbs the error as a pose error; the
    scale-aware alignment (the default) removes it. Measured: fixed 4 % → centimetres off, scale-aware ≤ 2 mm."""
    ref_cloud, current_ref = real_surface
    sigma = 0.8
    current = _as_current(current_ref, sigma)
    T0, _ = _perturbed_start(_true_pose(), sigma, current_ref, np.random.default_rng(12))
    s0 = 1.04 * sigma
    fixed = fast_align(current, ref_cloud, T_ref_cur_init=T0, sigma_init=s0, config=FIXED)
    free = fast_align(current, ref_cloud, T_ref_cur_init=T0, sigma_init=s0)
    assert fixed.sigma == s0
    # the error of mapping the current cloud into the reference frame (what moves the camera in Eq. 3)
    true_ref = current_ref
    err_fixed = float(np.median(np.linalg.norm(fixed.transform(current) - true_ref, axis=1)))
    err_free = float(np.median(np.linalg.norm(free.transform(current) - true_ref, axis=1)))
    assert abs(free.sigma / sigma - 1.0) < 0.002
    assert err_free < 0.004
    assert err_fixed > 3.0 * err_free and err_fixed > 0.01


def test_fine_alignment_with_scale_fixed_keeps_sigma_and_refines_the_pose(scene, reference) -> None:  # noqa: F811 (fixtures)
    """Eq. 17 alone: σ_p is untouched, the pose still improves on a perturbed start with the true σ. Measured:
    camera 15.6 mm → 6.0 mm (the scale-aware default: 7.4 mm; both at E_p's precision with 160×120 keyframes)."""
    obs = current_observation(scene, T_CUR_CAM, TRUE_T, TRUE_SIGMA, gradient_quantile=0.75,
                              depth_noise_rel=DRIFT["depth_noise_rel"])
    T0 = obs.T_ref_cur.copy()
    T0[:3, 3] += [0.012, -0.008, 0.006]  # 15.6 mm
    cfg = FineAlignmentConfig(estimate_scale=False, max_photometric_points=1500, max_keyframe_points=1000)

    class Start:
        T_ref_cur, sigma = T0, TRUE_SIGMA

    before_mm = camera_error(Start, obs)[1]
    fine = fine_align(obs.points_cur, reference, obs.keyframes, T_ref_cur_init=T0, sigma_init=TRUE_SIGMA,
                      intensities=obs.intensities, config=cfg)
    assert fine.sigma == TRUE_SIGMA
    assert camera_error(fine, obs)[1] < 0.5 * before_mm
    assert fine.cost_final < fine.cost_initial


@pytest.mark.parametrize("cls", [FastAlignmentConfig, FineAlignmentConfig])
def test_scale_estimation_is_on_by_default(cls) -> None:
    assert cls().estimate_scale is True and cls(estimate_scale=False).estimate_scale is False
