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

if TYPE_CHECKING:  # localization calls search_map: annotations only, no import cycle at run time
    from lightfast.vtr.localization import FeatureSupplier, Localization, MapLocalizer

__all__ = ["search_map"]


def search_map(localizer: MapLocalizer, features: Mapping[str, StereoFeatures], camera: StereoCamera,
               more: FeatureSupplier | None = None) -> Localization:
    """Whole-map search (§IV-C): every keyframe (with ``search_window_radius`` neighbours on each side),
    unguided; the most inliers win (first on ties); ``runner_up_inliers``: the best distinct place's."""
    best: Localization | None = None
    found: list[Localization] = []
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
    if best.success:
        along = localizer.map.along_path_m
        at = along(best.ref_index, best.T_ref_cam)
        far = [f.inliers for f in found
               if abs(along(f.ref_index, f.T_ref_cam) - at) > localizer.config.search_distinct_m]
        best = replace(best, runner_up_inliers=max(far, default=0))
    return best
