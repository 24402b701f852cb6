"""Options of the repeat phase of colour-constant VT&R (paper §IV-B, IV-C): :class:`RepeatConfig` and the
localization :data:`MODES`.

Read by :class:`~lightfast.vtr.repeat.RepeatPipeline` (the window, the failure distance, the prior gate),
:class:`~lightfast.vtr.localization.MapLocalizer` (matching, RANSAC and the success checks) and the whole-map search
(:mod:`lightfast.vtr.map_search`); the ``repeat`` section of ``vtr_localizer_node``'s parameters
(:mod:`lightfast.vtr.localizer_config`). Units: pixels of the rectified left image, metres, keyframe counts. The
modes: ``fused`` (the paper's method, Fig. 4: the matches of all image sources in one RANSAC), ``grey`` (the legacy
greyscale system [6]) and ``mcmanus`` (McManus et al. [10]: one image source at a time, greyscale favoured).
"""
from __future__ import annotations

from dataclasses import dataclass

from lightfast.config import Config, param

__all__ = ["MODES", "RepeatConfig"]

#: Localization modes: the paper's fused method, the legacy greyscale system [6], McManus et al. [10].
MODES = ("fused", "grey", "mcmanus")
_COLOR_SOURCES = ("fv", "fr", "peak")


@dataclass(frozen=True)
class RepeatConfig(Config):
    """Options of the repeat phase (paper §IV-B, IV-C)."""

    mode: str = param("fused", description="Localization: fused (paper), grey (legacy [6]) or mcmanus ([10]).",
                      choices=MODES)
    window_radius: int = param(
        2, description="Keyframes on each side of the expected nearest keyframe in the localization window.", min=0,
        max=50,
    )
    search_window_radius: int = param(
        2, description="Keyframes on each side of every candidate keyframe in the whole-map search (0: each keyframe "
        "alone; 2, as window_radius, doubled the candidate matches at the start of the evening repeat07).", min=0,
        max=50,
    )
    min_inliers: int = param(6, description="Fewest inliers for a successful localization (paper: 6).", min=4)
    max_distance_on_vo_m: float = param(
        20.0, description="Distance on VO alone after which a localization failure is declared (paper: 20 m), m.",
        min=0.0,
    )
    match_radius_px: float = param(
        40.0, description="Guided map matching: a keyframe landmark must project within this of the current "
        "keypoint under the VO prior, px (0: unguided).", min=0.0,
    )
    ratio: float = param(0.9, description="Lowe ratio test of keyframe-to-frame matches (0.9: more candidates under "
                         "changed lighting; the mutual check and RANSAC remove the extra wrong ones).", min=0.0,
                         max=1.0)
    mutual: bool = param(True, description="Keep only mutually nearest keyframe-to-frame matches.")
    orb_max_distance: float = param(
        80.0, description="ORB: largest Hamming distance of a keyframe-to-frame match (of 256 bits).", min=0.0
    )
    sift_max_distance: float = param(
        300.0, description="SIFT: largest Euclidean distance of a keyframe-to-frame match.", min=0.0
    )
    ransac_threshold_px: float = param(
        3.0, description="RANSAC inlier threshold on the stereo reprojection error (u, v, disparity), px (3: map "
        "landmarks and live keypoints come from different stereo pairs, so their disparity errors add).", min=0.1,
        max=100.0,
    )
    ransac_iterations: int = param(1000, description="Most RANSAC hypotheses.", min=10, max=100000)
    ransac_confidence: float = param(0.999, description="RANSAC confidence (adaptive stop).", min=0.5,
                                     max=0.999999)
    ransac_consistent_fraction: float = param(
        0.0, description="Share of RANSAC hypotheses drawn from distance-consistent triples of matches (the rest "
        "uniformly): finds a few inliers among many matches (0.5 localized the first frame of the sunset repeat10, "
        "but also found a wrong place 63 m off at the start of repeat07: off by default).", min=0.0, max=1.0,
    )
    ransac_ordered_fraction: float = param(
        0.5, description="Unguided localizations (whole-map search, start window): share of RANSAC hypotheses drawn "
        "by PROSAC's progressive sampling from the matches ordered by descriptor distance (the rest uniformly): the "
        "correct matches concentrate among the closest when most are wrong (sunset repeat10's first frame localized "
        "in 30 of 40 seeds, 9 of 40 uniformly). Not used with a prior: there it found more wrong poses (a second "
        "simulated route, repeat07: 14 localizations > 1 m off vs 4).", min=0.0, max=1.0,
    )
    ransac_min_iterations: int = param(
        0, description="Fewest RANSAC hypotheses before the adaptive stop (the VO's option; see ransac_refine_top).",
        min=0, max=100000,
    )
    ransac_refine_top: int = param(
        1, description="The best RANSAC hypotheses refined (inliers re-selected and refined); the one with the most "
        "inliers after refinement wins. 16 (with ransac_min_iterations 1000) localized more frames on development "
        "route 6273 (five repeats: strict autonomy 98.15 -> 98.73 %) but also finds larger wrong consensus sets "
        "among random greyscale matches under changed lighting (McManus mode then trusts them): off by default.",
        min=1, max=1000,
    )
    prior_consensus_sigmas: float = param(
        1.0, description="With a prior, the prior's own consensus (inliers at the VO prior, refined) is kept unless "
        "the RANSAC's best has more than this many sqrt(n) inliers more (n: its count) or lies within the gate's "
        "sigmas of the prior's position uncertainty: where the counts cannot tell poses apart (far points only: poses "
        "~1 m apart along their viewing direction differ by a few inliers), the prior decides. 0: the most inliers "
        "win.", min=0.0,
    )
    prior_consensus_min_inliers: int = param(
        30, description="Fewest inliers of the prior's own consensus for prior_consensus_sigmas to keep it (the "
        "strength confirm_beyond_gate_inliers asks for): with a dozen inliers under low sun the counts say little "
        "and a prior left off by a weak localization would hold itself.", min=0,
    )
    prior_consensus_exclusive_inliers: int = param(
        30, description="With a prior, its own consensus is also kept (whatever the counts) when it holds at least "
        "this many inliers the RANSAC's best does not explain: two coherent sets of matches, one at the prior, are "
        "a second structure in the view (a shadow moved since the teach, a repeated pattern), not evidence that "
        "the prior is off. 0: off.", min=0,
    )
    max_position_std_m: float = param(
        0.5, description="A localization also needs its camera position constrained to this standard deviation "
        "(nominal 1 px noise), m: rejects poses resting on far points only.", min=0.0,
    )
    prior_gate_m: float = param(
        0.5, description="A windowed localization farther than prior_gate_m + prior_gate_per_m * (distance on VO) "
        "from the VO prior is rejected, m (0: no gate).", min=0.0,
    )
    prior_gate_per_m: float = param(
        0.1, description="Growth of the prior gate per metre driven on VO alone (allowed VO drift), m/m.", min=0.0,
    )
    prior_gate_sigmas: float = param(
        3.0, description="The prior gate also admits a localization with confirm_beyond_gate_inliers inliers within "
        "this many standard deviations of the VO prior's own position uncertainty (Mahalanobis; a VO step resting on "
        "far points is uncertain along the optical axis, and the localization that mends it lies there). 0: the "
        "radius alone. Without the inlier minimum it admitted wrong greyscale localizations in the unit test's "
        "changed lighting (docs/vtr.md, 'Gates that follow the uncertainty').", min=0.0,
    )
    search_gate_sigmas: float = param(
        3.0, description="From a place of the whole-map search until a windowed localization with "
        "search_confirm_inliers inliers is accepted, the prior gate also admits a localization with "
        "search_min_inliers inliers within this many standard deviations of the prior's position uncertainty (the "
        "search's own covariance, propagated): a place found on far landmarks is uncertain along the optical axis, "
        "and prior_gate_m alone would protect its error. 0: off.", min=0.0,
    )
    prior_gate_innovation: bool = param(
        True, description="The Mahalanobis test of the prior gate reads the localization's own position covariance "
        "(x localization_cov_scale^2) added to the prior's: the innovation covariance of a Kalman filter's validation "
        "gate. A localization resting on far points is uncertain along the optical axis as well, and the prior's "
        "covariance alone, shrunk by the fusions, refused the localizations that would mend it (docs/vtr.md, 'A "
        "search place is confirmed by a strong localization'). False: the prior's alone.",
    )
    search_confirm_inliers: int = param(
        30, description="The gate of search_gate_sigmas stays open from a place of the whole-map search until a "
        "windowed localization with at least this many inliers is accepted: a weaker one admitted next to the place "
        "was admitted because it lay there, and confirms nothing. 0: until the next accepted localization.", min=0,
    )
    confirm_beyond_gate_inliers: int = param(
        30, description="Accept a windowed localization beyond the prior gate when it and the previous frame's, also "
        "beyond the gate, have at least this many inliers and agree within prior_gate_m after the VO motion between "
        "them: then the VO prior is the wrong one (in the cloudy evening repeat24 one VO step 1.8 m off made every "
        "following localization, 45-108 inliers, fail the gate until the 20 m failure; with no inlier minimum, "
        "consecutive wrong localizations of 13 inliers in the sand of repeat07 were accepted). 0: never.", min=0,
    )
    confirm_admitted: bool = param(
        True, description="The confirmation beyond the gate (confirm_beyond_gate_inliers) also counts localizations "
        "the gate's Mahalanobis widening admitted beyond prior_gate_m: two consecutive strong ones agreeing with each "
        "other far from the prior replace it instead of being fused with it (fused, they pulled a greyscale search "
        "place 2.5 m off back by centimetres per frame for 25 frames: the prior's covariance shrank with each "
        "fusion; docs/vtr.md). False: refused ones only.",
    )
    follow_path_on_vo_failure: bool = param(
        True, description="When the VO fails, move the prior along the taught path at the speed of the last frames' "
        "poses (the robot follows the path) instead of repeating the last VO motion (one wrong VO step before a dark "
        "stretch otherwise carries a wrong heading and speed into every frame of it).",
    )
    fuse_vo_prior: bool = param(
        True, description="Fuse an accepted windowed localization with the VO prior by their covariances (the "
        "paper's 'VO estimate is fed to the localizer as a prior'); False: the localization replaces the prior.",
    )
    localization_cov_scale: float = param(
        5.0, description="Standard deviations of a localization = this x those of its nominal covariance (1 px "
        "noise), for the fusion: the nominal one ignores landmark depth noise and the teach edges of the window "
        "(development route 7: errors over 1 m scored a median NEES of ~600 against it; 3-5 fused well, 10 trusted "
        "VO too much).", min=1e-3,
    )
    vo_cov_scale: float = param(
        2.0, description="Standard deviations of a VO step added to the prior's covariance = this x those of the "
        "step's nominal covariance (1 px noise; 0: the per-metre VO noise alone). At sunset on development route "
        "45863 VO steps resting on landmarks 50-60 m away were 0.3-1.4 m off; their nominal covariance tracks the "
        "error (correlation 0.65-0.69) but is too small (median NEES 5-10 for 3 position DOF). 2 vs 0, fused, "
        "strict manual distance: route 45863 repeats 06/07/10 77.2 vs 81.4 m, route 14489 11.4 vs 13.6 m.", min=0.0,
    )
    vo_position_noise_per_m: float = param(
        0.06, description="VO position noise (standard deviation) per metre driven, for the prior's covariance, m/m.",
        min=1e-6,
    )
    vo_rotation_noise_deg_per_m: float = param(
        0.2, description="VO rotation noise (standard deviation) per metre driven, deg/m.", min=1e-6,
    )
    keyframe_position_noise_m: float = param(
        0.1, description="Position noise added to the prior's covariance when it moves to another keyframe (a teach "
        "edge: the development route's edges are ~0.1 m off per 1.6 m), m.", min=0.0,
    )
    keyframe_rotation_noise_deg: float = param(
        0.15, description="Rotation noise added when the prior moves to another keyframe, deg.", min=0.0,
    )
    search_min_inliers: int = param(
        12, description="A place found by the whole-map search is accepted only with at least this many inliers: "
        "it is chosen among every keyframe window of the map, so a look-alike place reaches the 6 of a local "
        "localization far more often (twice min_inliers).", min=4,
    )
    search_margin: float = param(
        2.0, description="... and with at least this many times the inliers of the best place farther than "
        "search_distinct_m along the path (a ratio test between places: a repetitive route has look-alikes; the "
        "verification raises a look-alike's inliers too, docs/vtr.md).",
        min=1.0,
    )
    search_distinct_m: float = param(
        5.0, description="Localizations of the whole-map search that put the camera this far apart along the "
        "taught path count as different places for search_margin, m.", min=0.0,
    )
    search_verify_places: int = param(
        3, description="The whole-map search localizes this many of its best localizations, and the best one of a "
        "place search_distinct_m from the first, again by guided matching from their own pose before choosing "
        "among them (0: off; lightfast.vtr.map_search).", min=0,
    )
    search_accept_inliers: int = param(
        40, description="A place of the whole-map search with at least this many inliers (after verification, "
        "search_verify_places) is accepted at once; a weaker one (search_min_inliers up to this) only when a later "
        "search (search_hold_frames) finds it again, where the VO motion between the frames puts it (within "
        "search_agree_m): a look-alike seldom wins twice. On the development routes a wrong place had 31 (grey, low "
        "sun, 5.7 m off along the optical axis), the right ones at the repeats' starts 30-54 (docs/vtr.md).", min=0,
    )
    search_hold_frames: int = param(
        3, description="A weak place of the whole-map search (below search_accept_inliers) is held this many frames, "
        "moved by the VO motion, for a later search to find it again (1: the next frame only; at dusk every other "
        "frame's search may find too little).", min=1,
    )
    search_agree_m: float = param(
        1.0, description="A held place of the whole-map search, moved by the VO motion since, and this frame's place "
        "agree when their camera positions are this close, m.", min=0.0,
    )
    search_track_held: bool = param(
        False, description="A held place is also found again by a windowed localization from it (guided matching from "
        "the place moved by the VO motion) with search_min_inliers inliers within prior_gate_m of it. At dusk it finds "
        "the right place on frames where the unguided search misses it, but guided matching from a place off along "
        "the optical axis confirms it there (a low-sun greyscale repeat accepted a place 3.5 m off): off by default "
        "(docs/vtr.md, 'Tracking a held place').",
    )
    initial_keyframe: int = param(
        -1, description="Keyframe where the repeat starts (-1: search the whole map for the first localization).",
        min=-1,
    )
    workers: int = param(
        1, description="Threads of the stereo front end (one image source per thread; 1: sequential).", min=1,
        max=8,
    )
