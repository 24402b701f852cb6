"""The daylight regime diagnostic (lightfast/eval/daylight_regime.py) on constructed scenes with known answers."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from lightfast.camera import PinholeCamera
from lightfast.daylight.crf import CameraResponse
from lightfast.daylight.mesh import ReflectanceMesh, as_mesh, merge_meshes
from lightfast.eval.daylight_regime import (
    PHOTO_STRONG_RATIO,
    FrameRegime,
    RegimeScene,
    analyze_frame,
    analyze_recording,
    conditioning,
    motion_errors,
    regime_check,
    summarize,
    table_markdown,
    weak_direction_information,
)
from lightfast.eval.errors import DaylightEvalError
from lightfast.geometry import look_at, so3_exp

CAMERA = PinholeCamera(320, 240, 262.5, 262.5, 159.5, 119.5)
F64 = NDArray[np.float64]
Texture = Callable[[F64], F64]


def _plain(p: F64) -> F64:
    return np.full(p.shape[:-1], 0.5)


def _textured(p: F64) -> F64:
    """Reflectance grey with structure in every direction of a surface (wavelengths 12-40 cm)."""
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    return 0.45 + 0.2 * np.sin(17 * x + 3 * y + 11 * z) * np.cos(13 * y - 7 * z + 5 * x) + 0.1 * np.sin(29 * x
                                                                                                          - 23 * z)


def _quad(corner: tuple[float, ...], eu: tuple[float, ...], ev: tuple[float, ...], texture: Texture = _plain,
          n: int = 60) -> ReflectanceMesh:
    """A rectangle corner + [0, 1] eu + [0, 1] ev as an n × n grid of vertex pairs of triangles."""
    s, t = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    v = np.asarray(corner) + s[..., None] * np.asarray(eu) + t[..., None] * np.asarray(ev)
    v = v.reshape(-1, 3)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    i = i.ravel()
    faces = np.concatenate([np.stack([i, i + n + 1, i + 1], 1), np.stack([i + 1, i + n + 1, i + n + 2], 1)])
    rho = np.clip(texture(v), 0.0, 1.0)
    return as_mesh(v, faces, np.repeat(rho[:, None], 3, axis=1))


def _render(scene: RegimeScene, T: F64, texture: Texture, light: Callable[[F64], F64] | None = None
            ) -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
    """Grey-as-RGB image 255 · ρ(p) · light(p) (clipped) and the true z-depth seen at ``T``."""
    d_cam = CAMERA.ray_directions()
    hits = scene.caster.intersect(T[:3, 3], d_cam @ T[:3, :3].T)
    p = np.nan_to_num(hits.points())
    value = texture(p) * (1.0 if light is None else light(p))
    grey = np.where(hits.hit, np.clip(np.rint(255 * value), 0, 255), 0).astype(np.uint8)
    depth = np.where(hits.hit, hits.distance_m * d_cam[..., 2], 0.0).astype(np.float32)
    return np.repeat(grey[..., None], 3, axis=2), depth


SUN_UP = np.array([0.0, 0.0, 1.0])
LINEAR = CameraResponse(np.repeat(np.linspace(1e-3, 1.0, 256)[:, None], 3, axis=1))


def _frame(scene: RegimeScene, T: F64, texture: Texture = _plain, **kw: object) -> FrameRegime:
    rgb, depth = _render(scene, T, texture)
    return analyze_frame(rgb, depth, CAMERA, T, scene, SUN_UP, **kw)  # type: ignore[arg-type]


def test_a_plane_leaves_three_weak_directions_a_box_corner_none() -> None:
    wall = RegimeScene(_quad((-3, 0, -1), (6, 0, 0), (0, 0, 4)))
    plane = _frame(wall, look_at((0.4, 2.0, 1.2), (0, 0, 1)))
    assert plane.geo_weak == 3
    assert plane.geo_ratio < 1e-6
    corner = RegimeScene(merge_meshes([_quad((0, 0, 0), (3, 0, 0), (0, 3, 0)), _quad((0, 0, 0), (0, 3, 0), (0, 0, 3)),
                                       _quad((0, 0, 0), (3, 0, 0), (0, 0, 3))]))
    box = _frame(corner, look_at((2.2, 1.9, 1.7), (0, 0, 0.3)))
    assert box.geo_weak == 0
    assert box.geo_ratio > 1e-2  # 0.019: even a room corner is only 7x above the weak threshold in std
    assert box.pixels > 0.9 * 160 * 120


def test_texture_fills_the_weak_directions_a_plane_leaves() -> None:
    T = look_at((0.4, 2.0, 1.2), (0, 0, 1))
    plain = _frame(RegimeScene(_quad((-3, 0, -1), (6, 0, 0), (0, 0, 4))), T)
    assert plain.photo_ratio == 0.0  # a constant image has no photometric information
    assert plain.photo_weak_ratio == 0.0
    assert plain.eq7_ratio < 1e-6
    textured = _frame(RegimeScene(_quad((-3, 0, -1), (6, 0, 0), (0, 0, 4), _textured, n=150)), T, _textured)
    assert textured.geo_weak == 3
    # colour constrains what the plane leaves free (in-plane translation, rotation about the normal) ...
    assert textured.photo_weak_ratio >= 2 * PHOTO_STRONG_RATIO
    assert textured.eq7_ratio > 1e-2
    # ... but alone, even a textured plane mixes up a sideways shift and a rotation: 0.0027 at 63 deg field of view
    assert 1e-3 < textured.photo_ratio < PHOTO_STRONG_RATIO
    s = summarize([plain, textured])
    assert s["weak_geometry"] == 1.0
    assert s["colour_matters"] == 0.0
    assert s["colour_fills_weak"] == 0.5


def test_weak_direction_information_reads_only_the_weak_subspace() -> None:
    H_geo = np.diag([1.0, 1.0, 1.0, 1.0, 1.0, 0.0])  # rotation about z free
    assert weak_direction_information(np.diag([1.0, 1, 1, 1, 1, 0.5]), H_geo, 1.0) == pytest.approx(0.5)
    assert weak_direction_information(np.diag([1.0, 1, 1, 1, 1, 0.0]), H_geo, 1.0) == 0.0
    assert np.isnan(weak_direction_information(np.eye(6), np.eye(6), 1.0))


def test_conditioning_measures_rotation_as_displacement_at_the_median_depth() -> None:
    H = np.diag([1.0, 1.0, 1.0, 4.0, 4.0, 4.0])  # rotation information 4 /rad²: at 2 m, 1 /m² of displacement
    assert conditioning(H, 2.0) == pytest.approx((1.0, 0))
    assert conditioning(np.diag([1.0, 1.0, 1.0, 1e-3, 4.0, 4.0]), 2.0) == pytest.approx((2.5e-4, 1))


def test_sunlit_share_and_missing_depth_match_the_occluders_shadow() -> None:
    # floor seen from 1.5 m straight down; the sun from the zenith; a 0.62 m square occluder above the camera
    # (its shadow's edges fall between pixel centres)
    scene = RegimeScene(merge_meshes([_quad((-3, -3, 0), (6, 0, 0), (0, 6, 0)),
                                      _quad((-0.31, -0.31, 3.0), (0.62, 0, 0), (0, 0.62, 0), n=2)]))
    T = look_at((0, 0, 1.5), (0, 0, 0), up=(0, 1, 0))
    rgb, depth = _render(scene, T, _plain)
    p = CAMERA.backproject_depth(depth) @ T[:3, :3].T + T[:3, 3]
    shadow = (np.abs(p[..., 0]) < 0.31) & (np.abs(p[..., 1]) < 0.31)
    assert 0.1 < shadow.mean() < 0.25
    depth[~shadow] = 0.0  # the depth camera loses every sunlit pixel
    f = analyze_frame(rgb, depth, CAMERA, T, scene, SUN_UP)
    assert f.sunlit == pytest.approx(1.0 - shadow.mean(), abs=1e-9)
    assert f.depth_valid == pytest.approx(shadow.mean(), abs=1e-9)
    assert f.sunlit_no_depth == 1.0
    assert f.sunlit_no_depth_image == pytest.approx(f.sunlit)
    assert summarize([f])["large_sunlit_depth_loss"] == 1.0
    # the sun from below the horizon lights nothing
    assert analyze_frame(rgb, depth, CAMERA, T, scene, -SUN_UP).sunlit == 0.0


def test_illumination_share_sees_the_sun_patch_not_the_texture() -> None:
    scene = RegimeScene(_quad((-3, -3, 0), (6, 0, 0), (0, 6, 0), _textured, n=150))
    T = look_at((0.3, -1.2, 1.5), (0, 0, 0))
    rgb, depth = _render(scene, T, lambda p: 0.5 * _textured(p))
    uniform = analyze_frame(rgb, depth, CAMERA, T, scene, SUN_UP, crf=LINEAR)
    rgb, depth = _render(scene, T, lambda p: 0.5 * _textured(p), lambda p: np.where(p[..., 0] > 0.2, 1.8, 0.6))
    patch = analyze_frame(rgb, depth, CAMERA, T, scene, SUN_UP, crf=LINEAR)
    assert uniform.illum_share < 0.02  # 8-bit rounding only
    assert patch.illum_share > 0.15  # one sharp 3x step in light against strong texture everywhere


def test_noise_share_is_one_on_a_noisy_plain_wall_and_small_on_a_clean_texture() -> None:
    scene = RegimeScene(_quad((-3, 0, -1), (6, 0, 0), (0, 0, 4), _textured, n=150))
    T = look_at((0.4, 2.0, 1.2), (0, 0, 1))
    e_per_x = 2000.0  # Poisson noise only: σ_x² = x / 2000, 4 LSB at x = 0.5
    rgb, depth = _render(scene, T, _plain)
    rng = np.random.default_rng(1)
    x = rng.poisson(0.5 * e_per_x, rgb.shape) / e_per_x
    noisy = np.clip(np.rint(255 * x), 0, 255).astype(np.uint8)
    f = analyze_frame(noisy, depth, CAMERA, T, scene, SUN_UP, crf=LINEAR, noise=(e_per_x, 0.0))
    assert f.photo_noise_share == pytest.approx(1.0, abs=0.1)
    # noise alone seems to constrain the plane's free directions (0.08); its expected information removed, nothing
    assert f.photo_weak_ratio > 3 * PHOTO_STRONG_RATIO
    assert f.photo_weak_signal_ratio < 0.1 * PHOTO_STRONG_RATIO
    assert summarize([f])["colour_fills_weak"] == 0.0
    rgb, depth = _render(scene, T, _textured)
    f = analyze_frame(rgb, depth, CAMERA, T, scene, SUN_UP, crf=LINEAR, noise=(e_per_x, 0.0))
    assert f.photo_noise_share < 0.1
    assert f.photo_weak_signal_ratio == pytest.approx(f.photo_weak_ratio, rel=0.05)


def test_motion_numbers_of_a_known_trajectory() -> None:
    def step(cm: float, deg: float) -> F64:
        V = np.eye(4)
        V[:3, :3] = so3_exp(np.radians([0.0, 0.0, deg]))
        V[:3, 3] = (0.01 * cm, 0.0, 0.0)
        return V

    T0 = np.eye(4)
    T0[:3, :3] = so3_exp([0.3, -0.2, 0.5])
    T0[:3, 3] = (1.0, 2.0, 1.5)
    poses = [T0, T0 @ step(1, 1), T0 @ step(1, 1) @ step(1, 1), T0 @ step(1, 1) @ step(1, 1) @ step(3, 0)]
    m = motion_errors(np.stack(poses))
    assert np.all(np.isnan(m[0])) and np.all(np.isnan(m[1, 2:]))
    assert m[1, :2] == pytest.approx([1.0, 1.0])
    assert m[2] == pytest.approx([1.0, 1.0, 0.0, 0.0], abs=1e-6)  # constant velocity: predicted exactly
    assert m[3] == pytest.approx([3.0, 0.0, 2.0, 1.0], abs=1e-6)  # predicted 1 cm and 1 deg, moved 3 cm and 0 deg


def test_bad_input_raises(tmp_path: Path) -> None:
    with pytest.raises(DaylightEvalError):
        analyze_recording(tmp_path)
    scene = RegimeScene(_quad((-3, 0, -1), (6, 0, 0), (0, 0, 4)))
    rgb, depth = _render(scene, look_at((0, 2, 1), (0, 0, 1)), _plain)
    with pytest.raises(DaylightEvalError):
        analyze_frame(rgb[:, :-1], depth, CAMERA, np.eye(4), scene, SUN_UP)
    with pytest.raises(DaylightEvalError):
        analyze_frame(rgb, depth, CAMERA, np.full((4, 4), np.nan), scene, SUN_UP)
    with pytest.raises(DaylightEvalError):
        summarize([])
    with pytest.raises(DaylightEvalError):
        regime_check([])


def test_regime_needs_weak_shadow_dominated_frames_and_sunlit_depth_loss() -> None:
    def frames(n_regime: int, n_loss: int, n: int = 10) -> list[FrameRegime]:
        return [FrameRegime(i, i, geo_weak=1.0 if i < n_regime else 0.0, sun_edge_share=0.6,
                            sunlit_no_depth_image=0.2 if i < n_loss else 0.0) for i in range(n)]

    assert regime_check(frames(2, 2)) == {"regime_frames": 0.2, "large_sunlit_depth_loss": 0.2, "frames": 10,
                                          "in_regime": True}
    assert not regime_check(frames(1, 10))["in_regime"]  # depth loss alone is not the regime
    assert not regime_check(frames(10, 1))["in_regime"]
    weak_no_shadow = [FrameRegime(i, i, geo_weak=3.0, sun_edge_share=0.4, sunlit_no_depth_image=0.5)
                      for i in range(10)]
    assert regime_check(weak_no_shadow)["regime_frames"] == 0.0  # texture or geometry edges dominate
    assert regime_check([FrameRegime(0, 0)])["regime_frames"] == 0.0  # undefined (NaN) measures count as no


def test_table_lists_every_recording() -> None:
    scene = RegimeScene(_quad((-3, 0, -1), (6, 0, 0), (0, 0, 4)))
    f = _frame(scene, look_at((0.4, 2.0, 1.2), (0, 0, 1)))
    text = table_markdown({"A": summarize([f]), "B": summarize([f, f])})
    assert text.splitlines()[0].endswith("| A | B |")
    assert "| frames | 1 | 2 |" in text
