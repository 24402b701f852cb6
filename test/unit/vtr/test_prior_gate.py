"""The prior gate of a windowed localization (:class:`lightfast.vtr.vo_prior.PriorGate`): a radius, widened along
the directions in which the VO prior itself is uncertain."""
from __future__ import annotations

import numpy as np

from lightfast.vtr.vo_prior import PriorGate


def test_the_radius_alone_without_a_covariance() -> None:
    gate = PriorGate(0.5)
    assert gate.admits(np.array([0.3, 0.0, 0.3]))
    assert not gate.admits(np.array([0.0, 0.0, 0.6]))
    assert not PriorGate(0.5, np.diag([1.0, 1.0, 1.0]), sigmas=0.0).admits(np.array([0.0, 0.0, 0.6]))


def test_the_gate_widens_along_the_priors_uncertain_axis_only() -> None:
    """The prior is 0.5 m uncertain along z (a VO step on far points), 5 cm across: a localization 1.2 m along z
    (2.4 sigma) is admitted at 3 sigma, one 1.2 m sideways (24 sigma) is not; at 2 sigma neither; an infinite or
    singular covariance falls back to the radius."""
    cov = np.diag([0.05**2, 0.05**2, 0.5**2])
    along, across = np.array([0.0, 0.0, 1.2]), np.array([1.2, 0.0, 0.0])
    gate = PriorGate(0.5, cov, sigmas=3.0)
    assert gate.admits(along) and not gate.admits(across)
    assert not PriorGate(0.5, cov, sigmas=2.0).admits(along)
    assert not PriorGate(0.5, np.full((3, 3), np.inf), sigmas=3.0).admits(along)
    assert not PriorGate(0.5, np.zeros((3, 3)), sigmas=3.0).admits(along)


def test_the_widened_gate_can_ask_for_more_inliers() -> None:
    """After a search the widening admits only localizations with ``min_inliers_beyond_radius`` inliers; within the
    radius any count passes."""
    gate = PriorGate(0.5, np.diag([0.05**2, 0.05**2, 0.5**2]), sigmas=3.0, min_inliers_beyond_radius=12)
    along = np.array([0.0, 0.0, 1.2])
    assert gate.admits(along, 12) and not gate.admits(along, 11)
    assert gate.admits(np.array([0.0, 0.0, 0.4]), 6)


def test_the_innovation_gate_adds_the_localizations_own_uncertainty() -> None:
    """With ``measurement_cov_scale`` the Mahalanobis test reads the prior's and the localization's covariances
    together (a Kalman filter's validation gate): a prior that claims 0.3 m along z refuses a localization 1.5 m
    along z (5 sigma) on its own, but admits it when the localization itself is 0.4 m uncertain there (scaled ×1:
    1.5 / 0.5 = 3 sigma); a localization that claims 5 cm is still refused, and sideways nothing changes."""
    prior = np.diag([0.05**2, 0.05**2, 0.3**2])
    loose, tight = np.diag([0.02**2, 0.02**2, 0.4**2]), np.diag([0.02**2, 0.02**2, 0.05**2])
    along, across = np.array([0.0, 0.0, 1.49]), np.array([1.49, 0.0, 0.0])
    assert not PriorGate(0.5, prior, sigmas=3.0).admits(along, 50, loose)
    gate = PriorGate(0.5, prior, sigmas=3.0, measurement_cov_scale=1.0)
    assert gate.admits(along, 50, loose) and not gate.admits(along, 50, tight)
    assert not gate.admits(across, 50, loose)
    assert not gate.admits(along, 50) and not gate.admits(along, 50, np.full((3, 3), np.inf))
    assert not PriorGate(0.5, prior, sigmas=3.0, min_inliers_beyond_radius=30,
                         measurement_cov_scale=1.0).admits(along, 29, loose)
