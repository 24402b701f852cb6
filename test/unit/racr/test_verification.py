"""The convergence self-check (lightfast.racr.verification) on a simulated scene: a right estimate is verified by
the reference image, a wrong one (a slide along the relief) is failed, an image that matches nothing is
ambiguous."""
from __future__ import annotations

import numpy as np
import pytest

from lightfast.geometry import make_transform
from lightfast.racr.verification import ReferenceView, VerificationConfig, verify
from lightfast.sim.racr import build_scene, scene_specs

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def scene():
    return build_scene(scene_specs()[0], width=320, height=240, resolution_m=0.005)


def _keyframe(scene, offset_m, lighting="similar"):
    """A keyframe image at ``offset_m`` (reference camera frame) from the reference camera, and its true pose in
    the reference cloud's frame."""
    T_camref_kf = make_transform(np.eye(3), offset_m)
    image = scene.render(scene.truth.T_world_camref @ T_camref_kf, lighting, seed=3).image
    grey = np.asarray(image, np.float64).mean(axis=2) / 255.0 if image.ndim == 3 else image / 255.0
    return grey, scene.reference.T_ref_camref @ T_camref_kf


def test_a_right_estimate_is_verified_and_a_slid_one_failed(scene) -> None:
    ref = scene.reference
    view = ReferenceView(ref.points_m, ref.T_ref_camref, ref.image, ref.camera)
    assert np.isfinite(view.depth_m).mean() > 0.2  # the semi-dense cloud gives many reference pixels a depth
    kfs = [_keyframe(scene, o) for o in ([0.02, 0.0, 0.0], [-0.02, 0.01, 0.0])]
    right = verify(view, [(img, T, scene.camera) for img, T in kfs])
    assert right.verdict == "verified" and right.agreeing >= 12, right  # more than the 6 needed
    # the same images, the estimate slid 3 cm along the wall (what a repetitive relief does to the alignment)
    slide = make_transform(np.eye(3), [0.03, 0.0, 0.0])
    wrong = verify(view, [(img, T @ slide, scene.camera) for img, T in kfs])
    assert wrong.verdict == "failed" and wrong.disagreement_px > 5.0 and wrong.agreeing < 6, wrong
    assert "disagrees" in wrong.describe()


def test_too_little_evidence_is_ambiguous(scene) -> None:
    ref = scene.reference
    view = ReferenceView(ref.points_m, ref.T_ref_camref, ref.image, ref.camera, VerificationConfig())
    img, T = _keyframe(scene, [0.02, 0.0, 0.0])
    flat = np.full_like(img, 0.5)
    result = verify(view, [(flat, T, scene.camera)])
    assert result.verdict == "ambiguous" and result.agreeing < 6 and "unverified" in result.describe()
