"""Localization of the current frame against a window of teach keyframes: paper §IV-B (Fig. 3–4), §IV-C (six inliers).

"A current local submap consisting of the keyframe the robot is closest to, with a window of adjacent keyframes that
are relaxed into a single coordinate frame": the window's landmarks are moved into the reference keyframe's frame by
the chained teach edges (:meth:`MapLocalizer.submap`). **Each image source is matched separately** — the window's
landmarks of that source, all keyframes together, against the current left keypoints of the same source, guided by
the prior within ``match_radius_px`` (:func:`~lightfast.vtr.landmark_matching.match_landmarks`; Lowe's ratio per
landmark over the current keypoints, mutual nearest neighbours, so a landmark seen by several keyframes matches a
keypoint once); then, by ``RepeatConfig.mode``:

* ``fused`` (the paper's method, Fig. 4): the matches of **all sources are placed together** and sent to ONE RANSAC
  and ONE nonlinear refinement (:func:`~lightfast.vtr.pose_estimation.estimate_pose_stereo`; without a prior half of
  the hypotheses by PROSAC from the matches ordered by descriptor distance, ``ransac_ordered_fraction``);
* ``grey`` (legacy system [6], Fig. 3): greyscale matches only;
* ``mcmanus`` ([10]: "matched features from one image source are chosen ..., favoring the greyscale matches"):
  greyscale alone; only if that fails, each colour-constant source alone (computed on demand), the one with the
  most inliers wins — no fusion.

Success needs ``min_inliers`` (§IV-C: six) inliers after outlier rejection and two checks added to the paper's rule
(six inliers alone accepted wrong poses on synthetic scenes, see ``docs/vtr.md``): a constrained camera position
(``max_position_std_m``, from the pose covariance at a nominal 1 px noise: rejects poses resting on far points
only) and, with a prior, a position the repeat's :class:`~lightfast.vtr.vo_prior.PriorGate` admits. Output:
:class:`Localization` — the camera pose ``T_ref_cam`` in keyframe ``ref_index``'s frame (4×4; metres, REP-103
optical axes), success, matches and inliers per source, RMS reprojection error (px), covariance. The whole-map
search over every keyframe is :mod:`lightfast.vtr.map_search`.
"""
from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from lightfast.vtr.descriptor_matching import NearestMatches
from lightfast.vtr.errors import VtrInputError
from lightfast.vtr.features import StereoFeatures
from lightfast.vtr.landmark_matching import match_landmarks, max_descriptor_distance
from lightfast.vtr.map_search import search_map
from lightfast.vtr.map_store import TeachMap
from lightfast.vtr.pose_estimation import PriorSupport, StereoCamera, estimate_pose_stereo
from lightfast.vtr.repeat_config import RepeatConfig
from lightfast.vtr.vo_prior import PriorGate

__all__ = ["FeatureSupplier", "Localization", "MapLocalizer"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Localization:
    """A localization attempt: the camera pose ``T_ref_cam`` in keyframe ``ref_index``'s frame (m), success,
    per image source the matches sent to RANSAC and the inliers kept, the inliers' RMS stereo reprojection error
    (px) and the covariance of the pose (see :class:`~lightfast.vtr.pose_estimation.PoseEstimate`)."""

    T_ref_cam: NDArray[np.float64]
    ref_index: int
    success: bool
    inliers_per_source: Mapping[str, int]
    matches_per_source: Mapping[str, int]
    rms_px: float = float("nan")
    covariance: NDArray[np.float64] = field(default_factory=lambda: np.full((6, 6), np.inf))
    gated: bool = False  # failed only by the prior gate; T_ref_cam is then the rejected pose
    #: whole-map search: the most inliers of a successful place farther than ``search_distinct_m`` along the path
    runner_up_inliers: int = 0

    @property
    def inliers(self) -> int:
        return int(sum(self.inliers_per_source.values()))


FeatureSupplier = Callable[[], Mapping[str, StereoFeatures]]


@dataclass(frozen=True)
class _Submap:
    """The landmarks of one source of a keyframe window, moved into the reference keyframe's frame."""

    points: NDArray[np.float64]
    descriptors: NDArray[np.generic]


class MapLocalizer:
    """Localization of the current frame against a teach map (module docstring)."""

    def __init__(self, teach_map: TeachMap, config: RepeatConfig | None = None) -> None:
        self.map = teach_map
        self.config = config or RepeatConfig()
        c = self.config
        if "grey" not in teach_map.sources:
            raise VtrInputError(f"the map has no greyscale landmarks (sources {list(teach_map.sources)})")
        if c.mode == "grey":
            self.sources: tuple[str, ...] = ("grey",)
        else:
            self.sources = ("grey", *[s for s in teach_map.sources if s != "grey"])
        self._max_d = max_descriptor_distance(teach_map.feature, c.orb_max_distance, c.sift_max_distance)
        self._submaps: dict[tuple[int, tuple[int, ...], str], _Submap] = {}
        # during a whole-map search: per (keyframe, source) its unguided matches with the features they were made of
        self._unguided: dict[tuple[int, str], tuple[StereoFeatures, NearestMatches]] | None = None

    @property
    def first_sources(self) -> tuple[str, ...]:
        """The sources needed before anything is known: all for ``fused``, greyscale for the others."""
        return self.sources if self.config.mode == "fused" else ("grey",)

    def submap(self, ref: int, window: Sequence[int], source: str) -> _Submap:
        """Landmarks of ``source`` of the keyframes in ``window``, in keyframe ``ref``'s frame (cached)."""
        key = (ref, tuple(window), source)
        sub = self._submaps.get(key)
        if sub is None:
            pts, descs = [], []
            for j in window:
                lm = self.map.keyframes[j].landmarks[source]
                T = self.map.T_a_b(ref, j)
                pts.append(lm.points @ T[:3, :3].T + T[:3, 3])
                descs.append(lm.descriptors)
            sub = _Submap(np.concatenate(pts), np.concatenate(descs))
            if len(self._submaps) >= 64:
                self._submaps.clear()
            self._submaps[key] = sub
        return sub

    def correspondences(
        self, features: StereoFeatures, source: str, camera: StereoCamera, ref: int, window: Sequence[int],
        T_ref_cam_prior: NDArray[np.float64] | None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float32], NDArray[np.float64], NDArray[np.float32]]:
        """Matches of one source between the window's landmarks (in ``ref``'s frame) and the current keypoints:
        keyframe points, current left pixels, current effective disparities and descriptor distances (at most one
        match per current keypoint and per window landmark)."""
        c = self.config
        sub = self.submap(ref, window, source)
        guided = T_ref_cam_prior is not None and c.match_radius_px > 0
        if not guided and self._unguided is not None and c.mutual:
            parts = [self._unguided_rows(j, source, features) for j in window]
            i_ref, i_cur = NearestMatches.mutual(parts)
            dist = np.concatenate([p.d1 for p in parts])[i_ref]
        else:
            i_ref, i_cur, dist = match_landmarks(
                sub.points, sub.descriptors, features.uv_left, features.descriptors, features.kind, K=camera.K,
                T_ref_cur=T_ref_cam_prior if guided else None, radius_px=c.match_radius_px if guided else 0.0,
                ratio=c.ratio, mutual=c.mutual, max_distance=self._max_d,
            )
        return sub.points[i_ref], features.uv_left[i_cur], camera.effective_disparity(features)[i_cur], dist

    def _unguided_rows(self, keyframe: int, source: str, features: StereoFeatures) -> NearestMatches:
        """The unguided matches of one keyframe's landmarks of ``source``, computed once per search frame."""
        assert self._unguided is not None
        cached = self._unguided.get((keyframe, source))
        if cached is None or cached[0] is not features:
            rows = NearestMatches.of(self.map.keyframes[keyframe].landmarks[source].descriptors, features.descriptors,
                                     features.kind, ratio=self.config.ratio, max_distance=self._max_d)
            cached = self._unguided[(keyframe, source)] = (features, rows)
        return cached[1]

    def localize_sources(
        self, features: Mapping[str, StereoFeatures], sources: Sequence[str], camera: StereoCamera, ref: int,
        window: Sequence[int], T_ref_cam_prior: NDArray[np.float64] | None, gate: PriorGate | None = None,
    ) -> Localization:
        """Match each of ``sources`` separately, fuse all matches into ONE RANSAC + ONE refinement; success with
        ``min_inliers`` inliers, a well-constrained position (``max_position_std_m``) and, with a prior, a position
        the ``gate`` admits."""
        c = self.config
        objs, imgs, disps, dists, labels, matches = [], [], [], [], [], {}
        for k, s in enumerate(sources):
            if s not in features:
                raise VtrInputError(f"features of source {s!r} are missing")
            if features[s].kind != self.map.feature:
                raise VtrInputError(f"{features[s].kind} features cannot match a map of {self.map.feature} features")
            obj, img, disp, dist = self.correspondences(features[s], s, camera, ref, window, T_ref_cam_prior)
            objs.append(obj)
            imgs.append(img)
            disps.append(disp)
            dists.append(dist)
            labels.append(np.full(len(obj), k, np.intp))
            matches[s] = len(obj)
        est = estimate_pose_stereo(
            np.concatenate(objs), np.concatenate(imgs), np.concatenate(disps), camera,
            threshold_px=c.ransac_threshold_px, iterations=c.ransac_iterations, confidence=c.ransac_confidence,
            min_inliers=c.min_inliers, consistent_fraction=c.ransac_consistent_fraction,
            quality=np.concatenate(dists),
            ordered_fraction=c.ransac_ordered_fraction if T_ref_cam_prior is None else 0.0,  # unguided only
            min_iterations=c.ransac_min_iterations, refine_top=c.ransac_refine_top,
            prior=None if T_ref_cam_prior is None or c.prior_consensus_sigmas <= 0 else PriorSupport(
                T_ref_cam_prior, c.prior_consensus_sigmas, gate.position_cov if gate is not None else None,
                gate.sigmas if gate is not None else 0.0, c.prior_consensus_min_inliers,
                c.prior_consensus_exclusive_inliers),
        )
        lab = np.concatenate(labels)
        counts = np.bincount(lab[est.inliers], minlength=len(sources))
        inliers = {s: int(counts[k]) for k, s in enumerate(sources)}
        success = est.success and est.position_std_m <= c.max_position_std_m
        if est.success and not success:
            log.debug("localization at keyframe %d rejected: %d inliers but position std %.2f m", ref,
                      est.num_inliers, est.position_std_m)
        gated = False
        if success and T_ref_cam_prior is not None and gate is not None:
            offset = est.T_ref_cur[:3, 3] - T_ref_cam_prior[:3, 3]
            R = est.T_ref_cur[:3, :3]
            if not gate.admits(offset, est.num_inliers, R @ est.covariance[:3, :3] @ R.T):
                success, gated = False, True
                log.debug("localization at keyframe %d rejected: %d inliers but %.2f m from the VO prior (gate "
                          "%.2f m)", ref, est.num_inliers, float(np.linalg.norm(offset)), gate.radius_m)
        return Localization(est.T_ref_cur if success or gated else np.eye(4), ref, success, inliers, matches,
                            est.rms_px, est.covariance if success or gated else np.full((6, 6), np.inf), gated)

    def localize(
        self, features: Mapping[str, StereoFeatures], camera: StereoCamera, ref: int, window: Sequence[int],
        T_ref_cam_prior: NDArray[np.float64] | None, more: FeatureSupplier | None = None,
        gate: PriorGate | None = None,
    ) -> Localization:
        """Localize by the configured mode (module docstring). ``more`` supplies the colour-constant
        sources on demand in ``mcmanus`` mode (default: they must be in ``features``)."""
        if self.config.mode != "mcmanus":
            return self._complete(self.localize_sources(features, self.sources, camera, ref, window,
                                                        T_ref_cam_prior, gate))
        grey = self.localize_sources(features, ("grey",), camera, ref, window, T_ref_cam_prior, gate)
        if grey.success or len(self.sources) == 1:
            return self._complete(grey)
        feats = dict(more()) if more is not None else dict(features)
        best: Localization | None = None
        gated = grey if grey.gated else None
        inliers, matches = dict(grey.inliers_per_source), dict(grey.matches_per_source)
        for s in self.sources[1:]:
            loc = self.localize_sources(feats, (s,), camera, ref, window, T_ref_cam_prior, gate)
            matches[s] = loc.matches_per_source[s]
            inliers[s] = loc.inliers_per_source[s]
            if loc.success and (best is None or loc.inliers > best.inliers):
                best = loc
            if loc.gated and gated is None:
                gated = loc
        if best is None:
            if gated is not None:  # the favoured source's pose beyond the gate (for a confirmation next frame)
                return self._complete(replace(gated, matches_per_source=matches))
            return self._complete(Localization(np.eye(4), ref, False, inliers, matches))
        return self._complete(replace(best, matches_per_source=matches))

    def _complete(self, loc: Localization) -> Localization:
        """Every mode source appears in the per-source counts (zeros for sources not used)."""
        ins = {s: int(loc.inliers_per_source.get(s, 0)) for s in self.sources}
        mat = {s: int(loc.matches_per_source.get(s, 0)) for s in self.sources}
        return replace(loc, inliers_per_source=ins, matches_per_source=mat)

    def search(self, features: Mapping[str, StereoFeatures], camera: StereoCamera,
               more: FeatureSupplier | None = None) -> Localization:
        """Whole-map search (§IV-C): :func:`~lightfast.vtr.map_search.search_map`."""
        return search_map(self, features, camera, more)

    @contextmanager
    def unguided_cache(self) -> Iterator[None]:
        """While open (a whole-map search), unguided matching (:meth:`correspondences`) matches the landmarks of
        every keyframe and source to the frame once (:class:`~lightfast.vtr.descriptor_matching.NearestMatches`)
        and combines them per window."""
        self._unguided = {}
        try:
            yield
        finally:
            self._unguided = None
