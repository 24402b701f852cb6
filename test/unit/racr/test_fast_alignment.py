"""Fast scale-aware alignment of rACR (paper §3.4.2, Eq. 12–15) on real 3DMatch geometry.

Two real data sets, both read in place from ``../shared/data/3dmatch_redkitchen_pair``:

* **Real surface, exact truth.** The reference fragment (``ref.npy``, real Kinect geometry of a kitchen) split
  along its principal axis into a reference part and an overlapping current part (about 55 % of each is shared),
  the current part re-sampled at different points (mid-points between neighbours) with 2 mm noise, then moved by
  a known similarity. The truth is exact, so thresholds can be tight.
* **The real pair** ``src.npy`` → ``ref.npy`` (two fragments fused from different frames, ~45 % overlap). Its
  ``gt.npy`` is not the pair's geometric optimum (see :func:`test_gt_npy_is_not_the_pairs_optimum`), so the pair
  is scored against its own optimum: the minimum of the objective of Open3D's scaled point-to-point ICP, reached
  from ``gt.npy`` (:func:`test_open3d_stops_short_of_its_own_minimum`), from 20 seeded
  starts whose seeds were fixed before they were first run (:data:`HELD_OUT_SEEDS`; the method was developed on
  other seeds, ``docs/racr.md``). The peer (Open3D's scaled ICP from the same starts) is in
  ``benchmarks/results/racr_alignment.md``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lightfast.config import ConfigError
from lightfast.geometry import project_to_so3, rotation_angle_deg, so3_exp
from lightfast.racr import (
    AlignmentError,
    FastAlignmentConfig,
    FineAlignmentConfig,
    RacrError,
    ReferenceCloud,
    fast_align,
)
from lightfast.racr.alignment_job import AlignmentJob, _Observation

SIGMAS = (0.5, 0.8, 1.6, 2.0)
R_TRUE = so3_exp(np.array([0.3, -0.5, 0.2]))  # the known similarity of the real-surface set
T_TRUE_M = np.array([0.4, -0.2, 1.0])
#: the pair's held-out starts (round 2, benchmarks/results/HELDOUT.md), drawn and written down before they were
#: first run; development used seeds 1000-1129, round 1's seeds 0-19 were seen before the method last changed
HELD_OUT_SEEDS = (4252, 7284, 7859, 11135, 17375, 23312, 33065, 33109, 35100, 37486, 38220, 42614, 51353, 55035,
                  63026, 67417, 68242, 72266, 80136, 91694)
OPTIMUM_DISTANCE_M = 0.02  # Open3D's correspondence distance for the pair's optimum (= kernel_final_m)


@pytest.fixture(scope="module")
def pair(shared_data: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d = shared_data / "3dmatch_redkitchen_pair"
    gt = np.load(d / "gt.npy")
    T_ref_src = np.eye(4)
    T_ref_src[:3, :3] = project_to_so3(gt[:3, :3])  # stored with ~7e-5 orthonormality error
    T_ref_src[:3, 3] = gt[:3, 3]
    return np.load(d / "src.npy"), np.load(d / "ref.npy"), T_ref_src


@pytest.fixture(scope="module")
def pair_reference(pair) -> ReferenceCloud:
    return ReferenceCloud(pair[1])


@pytest.fixture(scope="module")
def real_surface(pair) -> tuple[ReferenceCloud, np.ndarray]:
    """(reference part, current part in the reference frame) of the split reference fragment."""
    ref = pair[1]
    rng = np.random.default_rng(5)
    centre = ref.mean(axis=0)
    axis = np.linalg.svd(ref - centre, full_matrices=False)[2][0]
    lo, hi = np.quantile((ref - centre) @ axis, [0.35, 0.65])
    reference = ReferenceCloud(ref[(ref - centre) @ axis < hi])
    _, nn = cKDTree(ref).query(ref, k=4)
    resampled = np.concatenate([(ref + ref[nn[:, j]]) / 2.0 for j in (1, 2, 3)])
    current = resampled[(resampled - centre) @ axis > lo]
    current = current[rng.choice(len(current), 12000, replace=False)] + rng.normal(scale=0.002, size=(12000, 3))
    return reference, current


def _perturbed_start(
    T_ref_cur: np.ndarray, sigma: float, points_ref: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, float]:
    """The true similarity perturbed about the cloud's centroid: 5° about a random axis, 5 cm, ±3 % scale."""
    axis = rng.normal(size=3)
    dR = so3_exp(np.radians(5.0) * axis / np.linalg.norm(axis))
    dt = rng.normal(size=3)
    dt *= 0.05 / np.linalg.norm(dt)
    ds = 1.0 + rng.choice([-0.03, 0.03])
    c = points_ref.mean(axis=0)
    T = np.eye(4)
    T[:3, :3] = dR @ T_ref_cur[:3, :3]
    T[:3, 3] = ds * dR @ (T_ref_cur[:3, 3] - c) + c + dt
    return T, sigma * ds


def _errors(result, T_ref_cur: np.ndarray, sigma: float) -> tuple[float, float, float]:
    return (
        float(rotation_angle_deg(result.T_ref_cur[:3, :3], T_ref_cur[:3, :3])),
        float(np.linalg.norm(result.T_ref_cur[:3, 3] - T_ref_cur[:3, 3])),
        abs(result.sigma / sigma - 1.0),
    )


def _true_pose() -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R_TRUE
    T[:3, 3] = T_TRUE_M
    return T


def _as_current(points_ref: np.ndarray, sigma: float) -> np.ndarray:
    """Current-cloud coordinates p with p_ref = R (σ p) + t."""
    return (points_ref - T_TRUE_M) @ R_TRUE / sigma


@pytest.mark.parametrize("sigma", SIGMAS)
def test_recovers_the_exact_similarity_on_a_real_surface(real_surface, sigma: float) -> None:
    """Measured: ≤ 0.06°, ≤ 1.7 mm, ≤ 0.06 % (≤ 0.13°, 3 mm, 0.08 % over sample sizes 2000–5000); asserted with
    margin, 3–5× below the issue's 1° / 5 cm / 1 %."""
    reference, current_ref = real_surface
    T0, s0 = _perturbed_start(_true_pose(), sigma, current_ref, np.random.default_rng(int(100 * sigma)))
    result = fast_align(_as_current(current_ref, sigma), reference, T_ref_cur_init=T0, sigma_init=s0)
    rot_deg, t_m, s_rel = _errors(result, _true_pose(), sigma)
    assert result.converged and result.iterations < 60
    assert rot_deg <= 0.3
    assert t_m <= 0.01
    assert s_rel <= 0.002
    assert result.fitness > 0.3 and result.rmse_m < 0.01
    np.testing.assert_allclose(
        result.transform(_as_current(current_ref[:5], sigma)), current_ref[:5], atol=0.01
    )


@pytest.mark.parametrize(
    "overrides",
    [
        {"rigid_solver": "open3d"},  # Open3D registration_icp as step 1
        {"scale_residual": "point_to_point"},  # Eq. 15 verbatim (point-to-point)
    ],
)
def test_solver_variants_agree_on_a_real_surface(real_surface, overrides: dict) -> None:
    reference, current_ref = real_surface
    sigma = 1.6
    T0, s0 = _perturbed_start(_true_pose(), sigma, current_ref, np.random.default_rng(7))
    result = fast_align(
        _as_current(current_ref, sigma), reference, T_ref_cur_init=T0, sigma_init=s0,
        config=FastAlignmentConfig(**overrides),
    )
    rot_deg, t_m, s_rel = _errors(result, _true_pose(), sigma)
    assert result.converged
    assert rot_deg <= 0.3 and t_m <= 0.01 and s_rel <= 0.005


def test_warm_start_converges_in_a_few_iterations(real_surface) -> None:
    """The alignment thread re-runs from its last estimate with the final kernel width."""
    reference, current_ref = real_surface
    sigma = 0.8
    current = _as_current(current_ref, sigma)
    T0, s0 = _perturbed_start(_true_pose(), sigma, current_ref, np.random.default_rng(8))
    # the cold start this test was measured with (a 0.1 m first kernel: the 5 cm / 5 deg start needs no more)
    cold = fast_align(current, reference, T_ref_cur_init=T0, sigma_init=s0,
                      config=FastAlignmentConfig(kernel_initial_m=0.1))
    warm_config = FastAlignmentConfig(kernel_initial_m=FastAlignmentConfig().kernel_final_m, seed=1)
    warm = fast_align(current, reference, T_ref_cur_init=cold.T_ref_cur, sigma_init=cold.sigma, config=warm_config)
    assert warm.converged and warm.iterations <= 8 and warm.iterations < cold.iterations
    rot_deg, t_m, s_rel = _errors(warm, _true_pose(), sigma)
    assert rot_deg <= 0.3 and t_m <= 0.01 and s_rel <= 0.002


@pytest.mark.parametrize("sigma", SIGMAS)
def test_injected_scale_is_handled_consistently_on_the_real_pair(pair, pair_reference, sigma: float) -> None:
    """Scaling the current cloud by 1/σ (and the start's scale by σ) must give the σ = 1 answer with σ_p × σ:
    kernel widths, tolerances and residuals live in the reference frame. Not bit-identical: rounding flips a few
    nearest-neighbour ties, and the pair's flat scale valley lets that shift where τ_T / τ_σ stop the iteration
    (seen: ≤ 0.006°, ≤ 0.2 mm, ≤ 3e-5 in σ_p)."""
    src, _, T_gt = pair
    T0, s0 = _perturbed_start(T_gt, 1.0, src @ T_gt[:3, :3].T + T_gt[:3, 3], np.random.default_rng(3))
    base = fast_align(src, pair_reference, T_ref_cur_init=T0, sigma_init=s0)
    scaled = fast_align(src / sigma, pair_reference, T_ref_cur_init=T0, sigma_init=s0 * sigma)
    assert base.converged and scaled.converged
    assert rotation_angle_deg(scaled.T_ref_cur[:3, :3], base.T_ref_cur[:3, :3]) < 0.02
    assert np.linalg.norm(scaled.T_ref_cur[:3, 3] - base.T_ref_cur[:3, 3]) < 1e-3
    assert scaled.sigma / sigma == pytest.approx(base.sigma, rel=2e-4)
    assert base.rmse_m < 0.01 and base.fitness > 0.3


def _open3d_scaled_icp(points_cur: np.ndarray, points_ref: np.ndarray, T0: np.ndarray, sigma0: float,
                       distance_m: float) -> tuple[np.ndarray, float]:
    """Open3D's scaled point-to-point ICP (Umeyama with scaling) from ``(T0, sigma0)``, run until it stands still:
    ``(T_ref_cur, σ)``."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    cloud = o3d.geometry.PointCloud
    S0 = T0.copy()
    S0[:3, :3] *= sigma0
    source, target = (cloud(o3d.utility.Vector3dVector(np.array(p, dtype=float))) for p in (points_cur, points_ref))
    res = reg.registration_icp(
        source, target, distance_m, S0, reg.TransformationEstimationPointToPoint(with_scaling=True),
        reg.ICPConvergenceCriteria(relative_fitness=1e-12, relative_rmse=1e-12, max_iteration=2000),
    )
    S = np.asarray(res.transformation)
    sigma = float(np.cbrt(np.linalg.det(S[:3, :3])))
    T = np.eye(4)
    T[:3, :3] = project_to_so3(S[:3, :3] / sigma)
    T[:3, 3] = S[:3, 3]
    return T, sigma


def truncated_cost(points_cur: np.ndarray, tree: cKDTree, T: np.ndarray, sigma: float,
                   distance_m: float = OPTIMUM_DISTANCE_M) -> float:
    """The objective Open3D's ICP descends with correspondence distance ``distance_m``: the mean over every current
    point of min(d, distance_m)², d its distance to the nearest reference point after ``(T, σ)`` (m²)."""
    d, _ = tree.query(sigma * points_cur @ T[:3, :3].T + T[:3, 3], distance_upper_bound=distance_m)
    return float(np.mean(np.minimum(d, distance_m) ** 2))


def descend_truncated_cost(points_cur: np.ndarray, points_ref: np.ndarray, T0: np.ndarray, sigma0: float,
                           distance_m: float = OPTIMUM_DISTANCE_M) -> tuple[np.ndarray, float]:
    """:func:`truncated_cost` minimized from ``(T0, σ0)`` by Powell's derivative-free descent (the cost is piecewise
    smooth: nearest neighbours switch; ICP stops where its correspondences stand still, not necessarily at the
    minimum): ``(T_ref_cur, σ)``. Parameters: rotation vector and shift about the moved cloud's centroid, log scale."""
    from scipy.optimize import minimize

    tree = cKDTree(points_ref)
    c = (sigma0 * points_cur @ T0[:3, :3].T + T0[:3, 3]).mean(axis=0)

    def pose(x: np.ndarray) -> tuple[np.ndarray, float]:
        dR, k = so3_exp(x[:3]), float(np.exp(x[6]))
        T = np.eye(4)
        T[:3, :3] = dR @ T0[:3, :3]
        T[:3, 3] = k * dR @ (T0[:3, 3] - c) + c + x[3:6]
        return T, sigma0 * k

    res = minimize(lambda x: 1e6 * truncated_cost(points_cur, tree, *pose(x), distance_m), np.zeros(7),
                   method="Powell", options={"xtol": 1e-7, "ftol": 1e-12, "maxfev": 30000})
    T, sigma = pose(res.x)
    T[:3, :3] = project_to_so3(T[:3, :3])
    return T, sigma


@pytest.fixture(scope="module")
def open3d_stop(pair) -> tuple[np.ndarray, float]:
    """Where Open3D's scaled ICP (2 cm) stops when started at ``gt.npy``: ``(T_ref_src, σ)``."""
    src, ref, T_gt = pair
    return _open3d_scaled_icp(src, ref, T_gt, 1.0, OPTIMUM_DISTANCE_M)


@pytest.fixture(scope="module")
def pair_optimum(pair, open3d_stop) -> tuple[np.ndarray, float]:
    """The pair's own optimum ``(T_ref_src, σ)``: the minimum of the objective of Open3D's scaled point-to-point ICP
    (:func:`truncated_cost`, 2 cm), reached from ``gt.npy`` by that ICP and then :func:`descend_truncated_cost`
    (:func:`test_open3d_stops_short_of_its_own_minimum`)."""
    src, ref, _ = pair
    return descend_truncated_cost(src, ref, *open3d_stop)


def _seeded_start(T_opt: np.ndarray, sigma_opt: float, centre: np.ndarray, seed: int) -> tuple[np.ndarray, float,
                                                                                                 float]:
    """``(T0, sigma_init, σ)``: the current cloud is ``src / σ`` (σ log-uniform in [0.5, 2]); the start is the
    optimum moved about the cloud's centre ``centre`` (reference frame) by 5–15° about a random axis, 5–20 cm in a
    random direction and a scale factor in [0.95, 1.05]."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    dR = so3_exp(np.radians(rng.uniform(5.0, 15.0)) * axis / np.linalg.norm(axis))
    shift = rng.normal(size=3)
    shift *= rng.uniform(0.05, 0.20) / np.linalg.norm(shift)
    sigma = float(np.exp(rng.uniform(np.log(0.5), np.log(2.0))))
    ds = rng.uniform(0.95, 1.05)
    T = np.eye(4)
    T[:3, :3] = dR @ T_opt[:3, :3]
    T[:3, 3] = ds * dR @ (T_opt[:3, 3] - centre) + centre + shift
    return T, sigma * sigma_opt * ds, sigma


@pytest.fixture(scope="module")
def held_out_runs(pair, pair_reference, pair_optimum) -> list[tuple[int, float, float, float, bool]]:
    """``(seed, rotation error [deg], translation error [m], relative scale error, converged)`` of the default fast
    alignment from each held-out start, errors against the pair's optimum (a raised AlignmentError: inf, False)."""
    src, _, _ = pair
    T_opt, s_opt = pair_optimum
    centre = (s_opt * src @ T_opt[:3, :3].T + T_opt[:3, 3]).mean(axis=0)
    runs = []
    for seed in HELD_OUT_SEEDS:
        T0, s0, sigma = _seeded_start(T_opt, s_opt, centre, seed)
        try:
            result = fast_align(src / sigma, pair_reference, T_ref_cur_init=T0, sigma_init=s0)
        except AlignmentError:
            runs.append((seed, np.inf, np.inf, np.inf, False))
            continue
        runs.append((seed, *_errors(result, T_opt, sigma * s_opt), result.converged))
    return runs


def test_gt_npy_is_not_the_pairs_optimum(pair, pair_optimum) -> None:
    """Why the pair is not scored against ``gt.npy``: 3DMatch's ``gt.log`` (which ``gt.npy`` copies) is built from
    the trajectory poses of the frames each fragment was fused from, not from registering the two fragments, and
    their geometry does not agree with it at the level of 1°, 5 cm, 1 %. Started at ``gt.npy``, Open3D's scaled
    ICP settles 0.5–3.3°, 5.6–25 cm, 2.2–7 % from it (correspondence distance 1–10 cm), fast_align 0.8–1.1°,
    9.5–10.6 cm, 1.7–2.2 % (over sample seeds, or all points); and the pair fixes scale only to about ±1 % (the
    optimum's σ moves from 0.978 to 0.967 as the distance goes from 1 to 4 cm). The optimum used here (2 cm) lies
    0.88°, 10.0 cm, 2.0 % from ``gt.npy``, and :func:`truncated_cost` is higher at ``gt.npy``."""
    src, ref, T_gt = pair
    T_opt, s_opt = pair_optimum
    rot_deg = rotation_angle_deg(T_opt[:3, :3], T_gt[:3, :3])
    t_m = np.linalg.norm(T_opt[:3, 3] - T_gt[:3, 3])
    assert rot_deg > 0.5 and t_m > 0.05 and abs(s_opt - 1.0) > 0.01
    tree = cKDTree(ref)
    assert truncated_cost(src, tree, T_opt, s_opt) < truncated_cost(src, tree, T_gt, 1.0)


def test_open3d_stops_short_of_its_own_minimum(pair, open3d_stop, pair_optimum) -> None:
    """Why the optimum is not simply where Open3D's scaled ICP stops when started at ``gt.npy``: that point stands
    still under the ICP (its correspondences no longer change) but is not the minimum of the ICP's own objective
    (:func:`truncated_cost`): Powell's descent from it goes on to a point 0.04°, 1.1 cm, 0.47 % away with a lower
    cost (312.27 against 312.55 mm² ×1e-3), where Open3D's ICP stands still too, and the same descent started at
    ``gt.npy`` itself ends there (within 0.03°, 2 mm, 0.02 %). Scored against the stopping point, the held-out starts
    looked 1 cm off through σ alone (0.47 % of scale at the frame origin ~2.3 m away is 1.1 cm)."""
    src, ref, _ = pair
    T_opt, s_opt = pair_optimum
    tree = cKDTree(ref)
    T_icp, s_icp = open3d_stop
    T_again, s_again = _open3d_scaled_icp(src, ref, T_icp, s_icp, OPTIMUM_DISTANCE_M)
    assert rotation_angle_deg(T_again[:3, :3], T_icp[:3, :3]) < 1e-6  # it stands still there ...
    assert np.linalg.norm(T_again[:3, 3] - T_icp[:3, 3]) < 1e-8 and abs(s_again / s_icp - 1.0) < 1e-9
    assert truncated_cost(src, tree, T_opt, s_opt) < truncated_cost(src, tree, T_icp, s_icp) - 1e-7  # ... above it
    T_at, s_at = _open3d_scaled_icp(src, ref, T_opt, s_opt, OPTIMUM_DISTANCE_M)  # the minimum: the ICP stays
    assert rotation_angle_deg(T_at[:3, :3], T_opt[:3, :3]) < 1e-3
    assert np.linalg.norm(T_at[:3, 3] - T_opt[:3, 3]) < 1e-5 and abs(s_at / s_opt - 1.0) < 1e-6


def test_held_out_starts_reach_the_pairs_optimum(held_out_runs) -> None:
    """The issue's acceptance on the pair: from 20 seeded starts (5–15°, 5–20 cm, start scale within ±5 %, injected
    scale σ ∈ [0.5, 2]), at least 19 end within 0.5°, 1 cm (translation of T_ref_cur) and 0.5 % (σ_p) of the
    pair's optimum. Why not ``gt.npy``: it copies 3DMatch's ``gt.log``, built from the trajectory poses of the
    frames each fragment was fused from, not from the fragments' geometry, and every registration of the pair
    started at it leaves it for a point ≥ 0.5°, ≥ 5.6 cm, ≥ 1.7 % away; no geometric method can end at it
    (:func:`test_gt_npy_is_not_the_pairs_optimum`). Measured on round 2's starts (fresh, HELDOUT.md): 20/20, all
    converged 0.31–0.36°, 0.29–0.64 cm, 0.02–0.15 % from the optimum. Round 1's starts (0–19) before the change of
    ``scale_kernel_m`` / ``kernel_decay``: 18/20."""
    hits = [seed for seed, rot, t, s, _ in held_out_runs if rot <= 0.5 and t <= 0.01 and s <= 0.005]
    assert len(hits) >= 19, held_out_runs


def test_no_held_out_start_is_reported_converged_far_from_the_optimum(held_out_runs) -> None:
    """What holds on the held-out starts: no result reported converged more than 2° or 5 cm from the optimum.
    Without ``min_fitness`` one was (round 1's seed 14, before ``scale_kernel_m``: stopped 13.7°, 49 cm, 17 % away on
    a fit of 0.13 of the points)."""
    far = [run for run in held_out_runs if run[4] and (run[1] > 2.0 or run[2] > 0.05)]
    assert far == []
    assert sum(run[4] for run in held_out_runs) >= 15  # not vacuous: most starts are reported converged


@pytest.fixture(scope="module")
def planted_wrong_start(pair) -> np.ndarray:
    """``gt.npy`` shifted 40 cm along the reference's −x: the alignment slides into a wrong local minimum there (from
    30 cm it was still sliding at the iteration cap)."""
    T0 = pair[2].copy()
    T0[:3, 3] += [-0.4, 0.0, 0.0]
    return T0


def test_a_wrong_local_minimum_is_not_reported_converged(pair, pair_reference, planted_wrong_start) -> None:
    """A wrong local minimum is a fixed point of the iteration like the right one: the step test alone
    (``min_fitness=0``) called this stop, 50 cm and 2.6 % from gt.npy on a fit of 0.22 of the points, converged.
    The fit criterion rejects it, and it does not reject the right minimum (0.35 of the points)."""
    src, _, T_gt = pair
    wrong_off = fast_align(src, pair_reference, T_ref_cur_init=planted_wrong_start,
                           config=FastAlignmentConfig(min_fitness=0.0))
    wrong = fast_align(src, pair_reference, T_ref_cur_init=planted_wrong_start)
    config = FastAlignmentConfig()
    assert wrong.pose_change <= config.pose_tolerance and wrong.scale_change <= config.scale_tolerance
    assert wrong.iterations < config.max_iterations  # it stopped: not the iteration cap
    assert np.linalg.norm(wrong.T_ref_cur[:3, 3] - T_gt[:3, 3]) > 0.2
    assert wrong_off.converged  # the same stop: only the verdict differs
    assert np.array_equal(wrong_off.T_ref_cur, wrong.T_ref_cur) and wrong_off.sigma == wrong.sigma
    assert wrong_off.iterations == wrong.iterations and wrong_off.fitness == wrong.fitness
    assert wrong.fitness < config.min_fitness and not wrong.converged
    right = fast_align(src, pair_reference, T_ref_cur_init=T_gt)
    assert right.converged and right.fitness > config.min_fitness


def test_the_alignment_thread_does_not_publish_a_rejected_fit(pair, pair_reference, planted_wrong_start) -> None:
    """The rACR scheme counts a fast result as converged once a re-run on the same cloud ends where it ended; so
    the alignment job turns a fit below ``min_fitness`` into an error (the scheme keeps its previous estimate)."""
    src, _, T_gt = pair
    jobs = []
    for T0 in (planted_wrong_start, T_gt):
        obs = _Observation(seq=0, stamp=0.0, points=src, intensities=None, T_cur_cam=np.eye(4), keyframes=())
        jobs.append(AlignmentJob("fast", obs, pair_reference, T0, 1.0, FastAlignmentConfig(),
                                 FineAlignmentConfig()).run())
    wrong, right = jobs
    assert wrong.result is None and isinstance(wrong.error, AlignmentError) and "min_fitness" in str(wrong.error)
    assert right.error is None and right.result is not None and right.result.converged


def test_not_converging_within_the_cap_is_reported_not_raised(real_surface) -> None:
    reference, current_ref = real_surface
    result = fast_align(
        _as_current(current_ref, 1.0), reference, T_ref_cur_init=_true_pose(),
        config=FastAlignmentConfig(max_iterations=1),
    )
    assert not result.converged and result.iterations == 1
    assert np.isfinite(result.sigma) and np.all(np.isfinite(result.T_ref_cur))


def test_every_point_can_be_used(real_surface) -> None:
    reference, current_ref = real_surface
    current = _as_current(current_ref[::4], 1.0)
    result = fast_align(current, reference, T_ref_cur_init=_true_pose(), config=FastAlignmentConfig(max_points=0))
    assert result.points_used == len(current) and result.converged


@pytest.mark.parametrize(
    ("points", "match"),
    [
        (np.zeros((0, 3)), "at least"),
        (np.zeros((100, 2)), "shape"),
        (np.array([[0.0, 0.0, np.nan]] * 100), "non-finite"),
    ],
)
def test_invalid_current_clouds_raise(real_surface, points: np.ndarray, match: str) -> None:
    with pytest.raises(AlignmentError, match=match):
        fast_align(points, real_surface[0])


def test_clouds_that_do_not_overlap_raise(real_surface) -> None:
    reference, current_ref = real_surface
    with pytest.raises(AlignmentError, match="overlap"):
        fast_align(current_ref + 10.0, reference)


def test_a_single_plane_is_degenerate() -> None:
    rng = np.random.default_rng(0)
    plane = np.c_[rng.uniform(-1, 1, (3000, 2)), np.zeros(3000)]
    with pytest.raises(AlignmentError, match="constrain"):
        fast_align(plane[:1500] + [0.0, 0.0, 0.005], plane)


def test_match_gate_removes_the_bias_of_a_surface_the_reference_lacks() -> None:
    """A raised 12 cm × 12 cm block (1 cm high) on a corrugated surface that the current cloud sees but the
    reference lacks (as two semi-dense clouds under different lighting sit on different parts of a relief): its
    points match the reference's base around it, whose tangent planes pass a centimetre off, and inside the 2 cm
    Tukey width those residuals pull the whole estimate. Weighting the matches by their nearest-neighbour distance
    (``match_gate``, the rACR scheme's warm starts) removes that. Measured from the true similarity: without
    0.38 mm mean error of the base points / 0.17°, with 0.05 mm / 0.016°."""
    rng = np.random.default_rng(0)

    def surface(n: int) -> tuple[np.ndarray, np.ndarray]:
        xy = rng.uniform(-0.2, 0.2, (n, 2))
        z = 0.01 * np.sin(2 * np.pi * xy[:, 0] / 0.1) * np.sin(2 * np.pi * xy[:, 1] / 0.1)
        block = (np.abs(xy[:, 0] - 0.1) < 0.06) & (np.abs(xy[:, 1] - 0.05) < 0.06)
        return np.column_stack([xy, z]), block

    ref_pts, ref_block = surface(60000)
    reference = ReferenceCloud(ref_pts[~ref_block])
    cur_true, block = surface(6000)
    cur_true[block, 2] += 0.01
    cur_true += rng.normal(scale=0.0005, size=cur_true.shape)
    T = np.eye(4)
    T[:3, :3], T[:3, 3], sigma = so3_exp([0.2, -0.1, 0.3]), [0.3, -0.2, 0.1], 1.35
    current = (cur_true - T[:3, 3]) @ T[:3, :3] / sigma
    errors = []
    for gate in (0.0, 2.0):
        result = fast_align(current, reference, T_ref_cur_init=T, sigma_init=sigma,
                            config=FastAlignmentConfig(kernel_initial_m=0.02, match_gate=gate))
        assert result.converged
        mm = 1e3 * np.linalg.norm(result.transform(current[~block]) - cur_true[~block], axis=1).mean()
        errors.append((mm, rotation_angle_deg(result.T_ref_cur[:3, :3], T[:3, :3])))
    (mm_plain, deg_plain), (mm_gated, deg_gated) = errors
    assert mm_plain > 0.2 and deg_plain > 0.1  # the scenario biases the plain robust ICP
    assert mm_gated < 0.1 and deg_gated < 0.04


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"sigma_init": 0.0}, "sigma_init"),
        ({"sigma_init": float("nan")}, "sigma_init"),
        ({"T_ref_cur_init": np.diag([2.0, 2.0, 2.0, 1.0])}, "rigid"),
        ({"T_ref_cur_init": np.eye(3)}, "4x4"),
        ({"config": object()}, "FastAlignmentConfig"),
    ],
)
def test_invalid_initial_guesses_raise(real_surface, kwargs: dict, match: str) -> None:
    reference, current_ref = real_surface
    with pytest.raises(RacrError, match=match):
        fast_align(current_ref, reference, **kwargs)


def test_config_is_validated() -> None:
    with pytest.raises(ConfigError, match="kernel_final_m"):
        FastAlignmentConfig(kernel_initial_m=0.01, kernel_final_m=0.02)
    with pytest.raises(ConfigError):
        FastAlignmentConfig(scale_residual="sparse")
    with pytest.raises(ConfigError):
        FastAlignmentConfig(query_workers=0)
    with pytest.raises(ConfigError, match="never be estimated"):
        FastAlignmentConfig(scale_kernel_m=0.01)
    FastAlignmentConfig(scale_kernel_m=0.0)  # 0: from the first iteration


def test_reference_without_normals_raises() -> None:
    sparse = np.arange(30, dtype=float).reshape(10, 3) * 10.0
    with pytest.raises(AlignmentError, match="normals"):
        ReferenceCloud(sparse)
