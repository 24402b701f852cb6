"""Whole-map search of colour-constant VT&R: paper §IV-C ("the map is searched until the live stereo feed
localizes") — the relocalization after a localization failure (20 m on VO alone) and before the first localization.

:func:`search_map` tries every keyframe of the teach map as the reference, with ``search_window_radius`` neighbours
on each side, by :meth:`~lightfast.vtr.localization.MapLocalizer.localize` without a prior (unguided matching, the
mode's image sources, PROSAC-ordered RANSAC hypotheses, no prior gate); the localization with the most inliers wins
(first on ties), and its ``runner_up_inliers`` are those of the best successful localization that puts the camera
farther than ``search_distinct_m`` along the taught path, so the caller can refuse a place that a look-alike nearly
matches. (Windows overlap: a window centred a few keyframes away often localizes the camera at the same place with
its shared keyframes; that is the same place, not a look-alike.)
Every keyframe lies in up to 2r + 1 windows: during the search each keyframe's landmarks are matched
to the frame once per source and the matches are combined per window
(:meth:`~lightfast.vtr.localization.MapLocalizer.unguided_cache`) — exactly the matches of matching each window at
once. In ``mcmanus`` mode the colour-constant features are computed once, at the first keyframe where greyscale
fails, and reused for the later keyframes.

**Verification by guided matching** (``search_verify_places`` > 0; not in the paper — ORB-SLAM's relocalization,
Mur-Artal et al. 2015 §V-E, "search by projection" before accepting): unguided matching keeps only landmarks whose
descriptor is the frame's nearest, so under a changed sun a right place gathers few inliers. The
``search_verify_places`` localizations with the most inliers, and the best one of a place distinct from the first,
are localized again against the window of ``window_radius`` around them, matched by projection from their own pose
(as a windowed localization with a VO prior): a right place gains the matches its pose predicts, a look-alike's
pose predicts few. Winner and runner-up are chosen among the verified localizations and the unverified rest (a
verification that fails or finds fewer inliers keeps the unguided localization).

Inputs: the current frame's :class:`~lightfast.vtr.features.StereoFeatures` per image source and the
:class:`~lightfast.vtr.pose_estimation.StereoCamera`. Output: the best
:class:`~lightfast.vtr.localization.Localization` (``T_ref_cam``: the camera in keyframe ``ref_index``'s frame,
4×4, metres; ``success`` False when no keyframe localizes).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING

from lightfast.vtr.features import StereoFeatures
from lightfast.vtr.pose_estimation import StereoCamera
from lightfast.vtr.vo_prior import PriorGate

if TYPE_CHECKING:  # localization calls search_map: annotations only, no import cycle at run time
    from lightfast.vtr.localization import FeatureSupplier, Localization, MapLocalizer

__all__ = ["search_map"]


def search_map(localizer: MapLocalizer, features: Mapping[str, StereoFeatures], camera: StereoCamera,
               more: FeatureSupplier | None = None) -> Localization:
    """Whole-map search (§IV-C): every keyframe (with ``search_window_radius`` neighbours on each side),
    unguided; the most inliers win (first on ties); ``runner_up_inliers``: the best distinct place's."""
    best: Localization | None = None
    found: list[Localization] = []  # every successful window
    r, n = localizer.config.search_window_radius, len(localizer.map)
    # every keyframe is in up to 2r + 1 windows: match its landmarks once (NearestMatches), combine per window
    with localizer.unguided_cache():
        for k in range(n):
            loc = localizer.localize(features, camera, k, tuple(range(max(0, k - r), min(n, k + r + 1))), None, more)
            if more is not None and localizer.config.mode == "mcmanus" and not loc.success:
                features, more = more(), None  # computed once; later keyframes reuse them
            if loc.success:
                found.append(loc)
            if best is None or (loc.success and (not best.success or loc.inliers > best.inliers)):
                best = loc
    assert best is not None
    if not best.success:
        return best
    found.sort(key=lambda f: -f.inliers)  # stable: first on ties as above
    path_m = localizer.map.along_path_m
    distinct_m = localizer.config.search_distinct_m
    along = [path_m(f.ref_index, f.T_ref_cam) for f in found]
    k = min(localizer.config.search_verify_places, len(found))
    # the k best, and the best place distinct from the first, so the margin compares verified with verified
    chosen = list(range(k)) + [i for i in range(k, len(found)) if k and abs(along[i] - along[0]) > distinct_m][:1]
    verified = [_verified(localizer, features, camera, found[i], more) for i in chosen]
    best = max(verified, key=lambda f: f.inliers) if verified else best
    at = path_m(best.ref_index, best.T_ref_cam)
    rivals = [f.inliers for f in verified if abs(path_m(f.ref_index, f.T_ref_cam) - at) > distinct_m]
    rivals += [f.inliers for i, f in enumerate(found) if i not in chosen and abs(along[i] - at) > distinct_m]
    return replace(best, runner_up_inliers=max(rivals, default=0))


def _verified(localizer: MapLocalizer, features: Mapping[str, StereoFeatures], camera: StereoCamera,
              place: Localization, more: FeatureSupplier | None) -> Localization:
    """``place`` localized again by guided matching from its own pose (module docstring); ``place`` itself if
    that fails or finds fewer inliers."""
    k = place.ref_index
    loc = localizer.localize(features, camera, k, localizer.map.window(k, localizer.config.window_radius),
                             place.T_ref_cam, more, PriorGate(localizer.config.search_distinct_m))
    return loc if loc.success and loc.inliers >= place.inliers else place
