"""Benchmark rACR's fine alignment (paper §3.4.3, Eq. 10–11 and 16–18) at 50 k points: time and accuracy.

The paper's fine alignment takes about 5 s (C++, i7 laptop, §3.6); the goal here is ≤ 2 s on 2 shared CPU cores.

Fine alignment needs images, so the data are synthetic with exact truth: the ray-cast textured relief of
``test/unit/racr/test_fine_alignment.py`` (1.2 m × 1.2 m, Gaussian bumps and two blocks, Lambertian shading,
supersampled pixels), seen at 0.6–1.1 m by 320×240 cameras (f = 280 px):

* **reference**: the back-projected depth of the reference camera (1 mm noise), ``--points`` of its points;
* **current**: five keyframes (image noise 0.005) on a 12 cm circle around the current camera, a semi-dense cloud
  from their highest-gradient pixels (~``--points`` points) with each point's intensity, in a VSE frame related
  to the reference by a known similarity (σ = 1.35, 0.37 rad, 37 cm).

Scenarios (each with ``--trials`` seeds): **drift** — 1 % depth noise and a per-keyframe depth bias of +2, −1,
+1.5, −2, 0 % (a monocular VSE whose keyframes disagree in scale); **kf-pose** — a good cloud (0.5 % depth
noise) but keyframe poses off by 0.2° and 2 mm; **good** — 0.4 % depth noise, nothing else. Each run: the fast
alignment from the truth perturbed by ~2°, 2.4 cm and +5 % scale, then the fine alignment from its result, in
variants: the default (joint Eq. 17–18 solve), the paper's alternation, SciPy ``trf`` instead of ``lm``, geometry
only (α = 1) and without Eq. 16 (rACR-P). Errors are those of the current camera's pose in the reference frame as
rACR computes it (``T_p ⟨R_A, σ_p t_A⟩``, Eq. 3's T̃_A), which is what the adjustment acts on, and of σ_p.
Times: wall clock and CPU time of this process per fine alignment, reference preparation (normals + KD-tree,
once per rACR run) excluded and reported apart.

Usage: ``.venv/bin/python benchmarks/racr_fine_alignment.py [--points 50000] [--trials 3]``.
Writes ``benchmarks/results/racr_fine_alignment.md`` and ``.json`` (atomically).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from lightfast.camera import PinholeCamera  # noqa: E402
from lightfast.geometry import rotation_angle_deg, so3_exp  # noqa: E402
from lightfast.io import write_text_atomic  # noqa: E402
from lightfast.racr import (  # noqa: E402
    FineAlignmentConfig,
    ReferenceCloud,
    camera_pose_in_reference,
    fast_align,
    fine_align,
)
from test.unit.racr.test_fine_alignment import (  # noqa: E402
    T_CUR_CAM,
    TRUE_SIGMA,
    TRUE_T,
    ReliefScene,
    current_observation,
    reference_cloud,
)

CAMERA = PinholeCamera(320, 240, 280.0, 280.0, 159.5, 119.5)
SCENARIOS = {
    "drift": {"depth_noise_rel": 0.01, "depth_bias_rel": (0.02, -0.01, 0.015, -0.02, 0.0)},
    "kf-pose": {"depth_noise_rel": 0.005, "keyframe_pose_noise": (0.2, 0.002)},
    "good": {"depth_noise_rel": 0.004},
}
VARIANTS = {
    "default (joint Eq. 17-18)": {},
    "paper's alternation": {"scale_update": "alternate"},
    "SciPy trf": {"method": "trf"},
    "geometry only (alpha = 1)": {"alpha": 1.0},
    "without Eq. 16 (rACR-P)": {"refine_keyframes": False},
}


def camera_error(T_ref_cur: np.ndarray, sigma: float, obs) -> tuple[float, float, float]:
    T = camera_pose_in_reference(obs.to_current(T_CUR_CAM), T_ref_cur, sigma)
    return (float(rotation_angle_deg(T[:3, :3], T_CUR_CAM[:3, :3])),
            1e3 * float(np.linalg.norm(T[:3, 3] - T_CUR_CAM[:3, 3])), 100 * abs(sigma / obs.sigma - 1.0))


def quantile_for(scene: ReliefScene, n_points: int) -> float:
    """The gradient quantile that gives about ``n_points`` current points from five keyframes."""
    obs = current_observation(scene, T_CUR_CAM, TRUE_T, TRUE_SIGMA, camera=CAMERA, n_keyframes=5,
                              gradient_quantile=0.5)
    return float(np.clip(1.0 - n_points / (2.0 * len(obs.points_cur)), 0.0, 0.99))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=50_000)
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "racr_fine_alignment")
    args = parser.parse_args()
    load_before = os.getloadavg()
    scene = ReliefScene(0)
    ref = reference_cloud(scene, camera=CAMERA, views=1)
    if len(ref) < args.points:
        raise SystemExit(f"the reference view has only {len(ref)} points; lower --points")
    ref = ref[np.random.default_rng(0).choice(len(ref), args.points, replace=False)]
    t0 = time.perf_counter()
    reference = ReferenceCloud(ref)
    prep_s = time.perf_counter() - t0
    q = quantile_for(scene, args.points)

    rows: list[dict] = []
    for scenario, kw in SCENARIOS.items():
        for trial in range(args.trials):
            obs = current_observation(scene, T_CUR_CAM, TRUE_T, TRUE_SIGMA, camera=CAMERA, n_keyframes=5,
                                      gradient_quantile=q, seed=10 * trial + 2, **kw)
            rng = np.random.default_rng(trial)
            axis = rng.normal(size=3)
            T0 = obs.T_ref_cur.copy()
            T0[:3, :3] = so3_exp(np.radians(2.0) * axis / np.linalg.norm(axis)) @ T0[:3, :3]
            T0[:3, 3] += [0.02, -0.01, 0.01]
            fast = fast_align(obs.points_cur, reference, T_ref_cur_init=T0, sigma_init=obs.sigma * 1.05)
            fast_err = camera_error(fast.T_ref_cur, fast.sigma, obs)
            for variant, overrides in VARIANTS.items():
                cpu = time.process_time()
                r = fine_align(obs.points_cur, reference, obs.keyframes, T_ref_cur_init=fast.T_ref_cur,
                               sigma_init=fast.sigma, intensities=obs.intensities,
                               config=FineAlignmentConfig(**overrides))
                cpu = time.process_time() - cpu
                err = camera_error(r.T_ref_cur, r.sigma, obs)
                rows.append({
                    "scenario": scenario, "variant": variant, "trial": trial, "points_cur": len(obs.points_cur),
                    "seconds": r.seconds, "cpu_seconds": cpu, "iterations": r.iterations, "converged": r.converged,
                    "photometric_residuals": r.photometric_residuals, "keyframe_residuals": r.keyframe_residuals,
                    "fast_rot_deg": fast_err[0], "fast_mm": fast_err[1], "fast_scale_pct": fast_err[2],
                    "rot_deg": err[0], "mm": err[1], "scale_pct": err[2],
                })
                print(f"{scenario:8s} {trial} {variant:28s} {r.seconds:5.2f} s (CPU {cpu:5.2f} s)  it {r.iterations}  "
                      f"fast {fast_err[0]:.3f} deg {fast_err[1]:6.2f} mm {fast_err[2]:.2f} %  ->  "
                      f"{err[0]:.3f} deg {err[1]:6.2f} mm {err[2]:.2f} %", flush=True)
    load_after = os.getloadavg()

    def med(scenario: str, variant: str, key: str) -> float:
        return float(np.median([r[key] for r in rows if r["scenario"] == scenario and r["variant"] == variant]))

    def worst(scenario: str, variant: str, key: str) -> float:
        return float(np.max([r[key] for r in rows if r["scenario"] == scenario and r["variant"] == variant]))

    table = []
    summary = []
    for scenario in SCENARIOS:
        first = next(iter(VARIANTS))
        table.append(
            f"| {scenario} | fast alignment (start) | – | – | – | {med(scenario, first, 'fast_rot_deg'):.3f} | "
            f"{med(scenario, first, 'fast_mm'):.2f} | {med(scenario, first, 'fast_scale_pct'):.2f} |"
        )
        for variant in VARIANTS:
            entry = {k: med(scenario, variant, k) for k in ("seconds", "cpu_seconds", "iterations", "rot_deg", "mm",
                                                             "scale_pct", "fast_rot_deg", "fast_mm",
                                                             "fast_scale_pct")}
            entry.update({"scenario": scenario, "variant": variant, "max_seconds": worst(scenario, variant, "seconds"),
                          "max_mm": worst(scenario, variant, "mm")})
            summary.append(entry)
            bold = "**" if variant == first else ""
            table.append(
                f"| {scenario} | {variant} | {bold}{entry['seconds']:.2f}{bold} | {entry['cpu_seconds']:.2f} | "
                f"{entry['iterations']:.0f} | {entry['rot_deg']:.3f} | {entry['mm']:.2f} | {entry['scale_pct']:.2f} |"
            )
    n_cur = int(np.median([r["points_cur"] for r in rows]))
    default = next(iter(VARIANTS))
    all_default = [r for r in rows if r["variant"] == default]
    wall_med = float(np.median([r["seconds"] for r in all_default]))
    cpu_med = float(np.median([r["cpu_seconds"] for r in all_default]))
    lines = [
        "# rACR fine alignment (paper §3.4.3, Eq. 10–11, 16–18) at 50 k points",
        "",
        f"Reference cloud of {len(reference):,} points, current clouds of ~{n_cur:,} points from 5 keyframes of "
        "320×240 px (synthetic ray-cast relief with exact truth, see the script's docstring), "
        f"{args.trials} seeds per scenario. Each fine alignment starts from the fast alignment's result "
        "(itself started ~2°, 2.4 cm, +5 % off). Errors: the current camera's pose in the reference frame as rACR "
        "computes it (T_p ⟨R_A, σ_p t_A⟩), and σ_p; medians over the seeds. Time per fine alignment (Eq. 16 "
        f"included); reference preparation (normals + KD-tree, once per run) took {prep_s:.2f} s. Single process "
        f"on a shared 2-core machine (load average {load_before[0]:.1f} before, {load_after[0]:.1f} after).",
        "",
        "| scenario | variant | wall s (median) | CPU s (median) | outer iterations | rot [deg] | camera [mm] "
        "| scale [%] |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
        *table,
        "",
        "Scenarios: *drift* — the VSE's keyframes disagree in depth by −2…+2 % (1 % noise): the geometric fast "
        "alignment follows the biased cloud, the photometric term (keyframe images and poses only) pulls the pose "
        "back, geometry alone (α = 1) cannot. *kf-pose* — keyframe poses 0.2° / 2 mm off: Eq. 16 refines them "
        "(rACR-P shows what happens without). *good* — an accurate cloud: here the fast alignment is already better "
        "than the photometric term's own precision at 320×240 px, so the fine alignment costs accuracy.",
        "",
        f"Paper: ~5 s per fine alignment (C++, i7). Goal here: ≤ 2 s. Default configuration over all runs: "
        f"{wall_med:.2f} s wall clock, {cpu_med:.2f} s CPU time (the wall clock includes waiting for the other "
        "jobs sharing the 2 cores; CPU time is what an idle core would take).",
        "",
        f"Generated {datetime.now(UTC).isoformat(timespec='seconds')} by `benchmarks/racr_fine_alignment.py` "
        f"(Python {platform.python_version()}, NumPy {np.__version__}, {platform.machine()}, {os.cpu_count()} cores).",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    result = {
        "points_ref": len(reference), "points_cur_median": n_cur, "trials": args.trials,
        "reference_prep_s": prep_s, "default_median_s": wall_med, "default_median_cpu_s": cpu_med,
        "summary": summary, "runs": rows, "config": FineAlignmentConfig().to_dict(),
        "load_average": [load_before[0], load_after[0]], "machine": f"{platform.machine()}, {os.cpu_count()} cores",
    }
    write_text_atomic(args.out.with_suffix(".md"), text)
    write_text_atomic(args.out.with_suffix(".json"), json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
