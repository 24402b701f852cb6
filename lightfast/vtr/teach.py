"""Teach phase of colour-constant stereo VT&R: paper §IV-B ("During the teaching phase, the robot is driven ...
while a pose graph of visual features linked by relative transformations is built"; "Keyframes in the new map
contain independent sets of SURF features from all three image sources, linked by relative transformations
computed by VO").

Per stereo frame (:meth:`TeachPipeline.step`, the call a node makes per synchronized pair):

1. the stereo front end (:class:`SourceFrontEnd`, wrapping :class:`~lightfast.vtr.stereo_front_end.StereoFrontEnd`)
   extracts, left–right matches and triangulates the landmarks of every image source (greyscale, F_v, F_r);
2. frame-to-frame VO on greyscale (:class:`~lightfast.vtr.visual_odometry.VisualOdometry`) gives ``T_prev_cur``,
   chained into ``T_kf_cam``, the pose of the camera in the last keyframe;
3. when the camera has moved ``keyframe_distance_m`` or turned ``keyframe_angle_deg`` from the last keyframe, the
   current frame becomes a keyframe: its landmarks of all sources (3-D points in its own left camera frame), and
   the edge ``T_parent_child`` = the chained VO estimate, are written to the map at once (atomically, see
   :mod:`lightfast.vtr.map_store`). The first frame is keyframe 0.

:meth:`TeachPipeline.finish` adds the last frame as a keyframe (if it moved at least a fifth of the keyframe
spacing), writes the manifest and moves the map into place; until then a previous map at the path is untouched,
and an interrupted teach (crash, :meth:`TeachPipeline.abort`) leaves it so.

When VO fails during the teach, the constant-velocity prediction is chained (and counted in
:attr:`TeachPipeline.vo_failures`); the paper does not say what its teach does then.
"""
from __future__ import annotations

import functools
import logging
import math
import os
import time
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.config import Config, ConfigError, param
from lightfast.vtr.color_constant import SOURCES, ColorConstantConfig, image_sources
from lightfast.vtr.errors import MapExistsError, VtrInputError, VtrStateError
from lightfast.vtr.features import FeatureExtractor, StereoFeatures
from lightfast.vtr.map_store import Landmarks, MapStore, MapWriter, TeachMap
from lightfast.vtr.pose_estimation import StereoCamera
from lightfast.vtr.stereo_config import StereoConfig
from lightfast.vtr.stereo_front_end import StereoFrontEnd, check_stereo_pair
from lightfast.vtr.visual_odometry import VisualOdometry, VisualOdometryConfig

__all__ = [
    "PendingFeatures",
    "SourceFrontEnd",
    "TeachConfig",
    "TeachPipeline",
    "TeachResult",
    "rotation_deg",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TeachConfig(Config):
    """Options of the teach phase (paper §IV-B)."""

    keyframe_distance_m: float = param(
        1.0, description="A new keyframe when the camera has moved this far from the last keyframe, m.", min=0.01
    )
    keyframe_angle_deg: float = param(
        10.0, description="A new keyframe when the camera has turned this much from the last keyframe, deg.",
        min=0.1, max=180.0,
    )
    sources: tuple[str, ...] = param(
        ("grey", "fv", "fr"), description="Image sources stored per keyframe (grey is needed for VO).",
        choices=SOURCES,
    )
    workers: int = param(
        1, description="Threads of the stereo front end (one image source per thread; 1: sequential).", min=1,
        max=8,
    )

    def check(self) -> None:
        if "grey" not in self.sources or len(set(self.sources)) != len(self.sources):
            raise ConfigError(f"TeachConfig.sources must be distinct and include grey, got {list(self.sources)}")


def rotation_deg(T: NDArray[np.float64]) -> float:
    """Rotation angle of a 4×4 transform, degrees."""
    c = (float(np.trace(T[:3, :3])) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


class SourceFrontEnd:
    """The per-source stereo front end of Fig. 4 for both pipelines: one
    :class:`~lightfast.vtr.stereo_front_end.StereoFrontEnd` per image source, computed on demand (:meth:`process` with a
    subset of the sources).

    With ``workers > 1`` a thread pool runs the six feature detections of a three-source stereo frame (OpenCV's
    detection releases the GIL; each (source, side) has its own detector object) and the image sources of the left
    and right image, while the calling thread matches, refines and triangulates every source as soon as its two
    detections are done. :meth:`submit` returns at once with a :class:`PendingFeatures` mapping that finishes a
    source when it is first read, so a caller can start work on the greyscale landmarks (VO) while the colour-
    constant ones are still being detected."""

    def __init__(self, sources: tuple[str, ...], stereo: StereoConfig | None = None,
                 color: ColorConstantConfig | None = None, workers: int = 1) -> None:
        self.sources = tuple(sources)
        self.stereo = stereo or StereoConfig()
        self.color = color or ColorConstantConfig()
        self._fronts = {s: StereoFrontEnd(self.stereo, self.color, sources=(s,)) for s in self.sources}
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="vtr-front") if workers > 1 else None
        # a second detector per source, so that the left and right detections can run concurrently
        self._right = ({s: FeatureExtractor(self.stereo) for s in self.sources}
                       if self._pool is not None and self.stereo.detects_right else {})

    @property
    def kind(self) -> str:
        return self.stereo.feature

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def _wanted(self, sources: tuple[str, ...] | None) -> tuple[str, ...]:
        wanted = self.sources if sources is None else tuple(sources)
        unknown = [s for s in wanted if s not in self._fronts]
        if unknown:
            raise VtrInputError(f"image source(s) {unknown} not configured (have {list(self.sources)})")
        return wanted

    def process(self, left_rgb: NDArray[np.generic], right_rgb: NDArray[np.generic], P_left: ArrayLike,
                P_right: ArrayLike, sources: tuple[str, ...] | None = None) -> dict[str, StereoFeatures]:
        """Landmarks of ``sources`` (default: all configured) for one rectified rgb stereo pair."""
        return dict(self.submit(left_rgb, right_rgb, P_left, P_right, sources))

    def submit(self, left_rgb: NDArray[np.generic], right_rgb: NDArray[np.generic], P_left: ArrayLike,
               P_right: ArrayLike, sources: tuple[str, ...] | None = None) -> PendingFeatures:
        """Start the front end of ``sources`` (default: all) on one rectified rgb stereo pair; the landmarks of a
        source are finished in the calling thread when first read from the returned mapping. Without a thread pool
        everything is computed here."""
        wanted = self._wanted(sources)
        left, right = np.asarray(left_rgb), np.asarray(right_rgb)
        if left.shape != right.shape:
            raise VtrInputError(f"left image {left.shape} and right image {right.shape} differ in size")
        Pl, Pr = check_stereo_pair(P_left, P_right)
        pool = self._pool
        if pool is None or not wanted:
            ls, rs = image_sources(left, self.color, wanted), image_sources(right, self.color, wanted)
            return PendingFeatures({s: self._fronts[s].source_features(ls[s], rs[s], Pl, Pr) for s in wanted})
        images = [pool.submit(image_sources, im, self.color, wanted) for im in (left, right)]
        ls, rs = images[0].result(), images[1].result()
        if not self.stereo.detects_right:  # no right-image detection: each source's whole front end is one job
            jobs = {s: pool.submit(self._fronts[s].source_features, ls[s], rs[s], Pl, Pr) for s in wanted}
            return PendingFeatures({}, {s: jobs[s].result for s in wanted})
        detections = {s: (pool.submit(self._fronts[s].extractor.detect, ls[s].image, ls[s].valid),
                          pool.submit(self._right[s].detect, rs[s].image, rs[s].valid)) for s in wanted}

        def finish(s: str) -> StereoFeatures:
            fl, fr = (f.result() for f in detections[s])
            return self._fronts[s].landmarks(ls[s], rs[s], fl, fr, Pl, Pr)

        return PendingFeatures({}, {s: functools.partial(finish, s) for s in wanted})


class PendingFeatures(Mapping[str, StereoFeatures]):
    """Landmarks per image source, each finished (by a callable) when first read; ``seconds`` is the time spent
    finishing them (waiting for detections, matching, triangulation). Not thread-safe."""

    def __init__(self, done: Mapping[str, StereoFeatures],
                 pending: Mapping[str, Callable[[], StereoFeatures]] | None = None) -> None:
        self._done = dict(done)
        self._pending = dict(pending or {})
        self.seconds = 0.0

    def __getitem__(self, source: str) -> StereoFeatures:
        if source not in self._done:
            finish = self._pending.pop(source)  # KeyError for an unknown source, as a dict
            t0 = time.perf_counter()
            self._done[source] = finish()
            self.seconds += time.perf_counter() - t0
        return self._done[source]

    def __contains__(self, source: object) -> bool:
        return source in self._done or source in self._pending

    def __iter__(self) -> Iterator[str]:
        return iter([*self._done, *self._pending])

    def __len__(self) -> int:
        return len(self._done) + len(self._pending)

    def update(self, other: PendingFeatures) -> None:
        """Add the (pending) sources of another submission."""
        for s in other._done:
            self._done[s] = other._done[s]
        self._pending.update(other._pending)
        self.seconds += other.seconds


@dataclass(frozen=True)
class TeachResult:
    """One teach step: the pose of the camera in the last keyframe (``T_kf_cam``, m), the index of that keyframe,
    whether this frame became a keyframe, the VO outcome and the path distance taught so far (m)."""

    stamp_ns: int
    keyframe_index: int
    new_keyframe: bool
    T_kf_cam: NDArray[np.float64]
    vo_success: bool
    vo_inliers: int
    distance_m: float
    landmarks: Mapping[str, int]


class TeachPipeline:
    """The teach phase (module docstring): ``step`` per stereo frame, then ``finish`` (or ``abort``).

    ``path`` is the map directory; with ``overwrite`` a previous map there is replaced when the teach finishes
    (and only then). Not thread-safe.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        config: TeachConfig | None = None,
        *,
        stereo: StereoConfig | None = None,
        color: ColorConstantConfig | None = None,
        vo: VisualOdometryConfig | None = None,
        overwrite: bool = False,
    ) -> None:
        self.path = Path(path)
        self.config = config or TeachConfig()
        self.front = SourceFrontEnd(self.config.sources, stereo, color, self.config.workers)
        self.vo = VisualOdometry(vo)
        self.overwrite = overwrite
        if MapStore.exists(self.path) and not overwrite:
            raise MapExistsError(f"a map exists at {self.path} (allow overwriting to replace it)")
        self._writer: MapWriter | None = None
        self._camera: tuple[NDArray[np.float64], NDArray[np.float64], tuple[int, int]] | None = None
        self._T_kf_cam = np.eye(4)
        self._kf_index = -1
        self._distance_m = 0.0  # path distance of the last keyframe
        self._last: tuple[int, dict[str, StereoFeatures]] | None = None  # last frame, if not a keyframe
        self._closed = False
        self.frames = 0
        self.vo_failures = 0

    @property
    def num_keyframes(self) -> int:
        return self._kf_index + 1

    def step(self, stamp_ns: int, left_rgb: NDArray[np.generic], right_rgb: NDArray[np.generic],
             P_left: ArrayLike, P_right: ArrayLike) -> TeachResult:
        """Process one rectified rgb8 stereo pair with its ``camera_info`` projection matrices."""
        left = np.asarray(left_rgb)
        features = self.front.process(left, right_rgb, P_left, P_right)
        return self.step_features(stamp_ns, features, P_left, P_right, (left.shape[1], left.shape[0]))

    def step_features(self, stamp_ns: int, features: Mapping[str, StereoFeatures], P_left: ArrayLike,
                      P_right: ArrayLike, image_size: tuple[int, int]) -> TeachResult:
        """:meth:`step` with the front end's output computed elsewhere (all configured sources)."""
        if self._closed:
            raise VtrStateError("the teach has finished or was aborted")
        missing = [s for s in self.config.sources if s not in features]
        if missing:
            raise VtrInputError(f"features of {missing} are missing")
        Pl, Pr = check_stereo_pair(P_left, P_right)
        size = (int(image_size[0]), int(image_size[1]))
        if self._camera is None:
            self._camera = (Pl, Pr, size)
        elif not (np.allclose(self._camera[0], Pl) and np.allclose(self._camera[1], Pr) and self._camera[2] == size):
            raise VtrInputError("the camera (projection matrices or image size) changed during the teach")
        self.frames += 1
        vo = self.vo.process(features["grey"], StereoCamera.from_projections(Pl, Pr))
        if not vo.first and not vo.success:
            self.vo_failures += 1
        self._T_kf_cam = self._T_kf_cam @ vo.T_prev_cur
        new_kf = vo.first or (
            float(np.linalg.norm(self._T_kf_cam[:3, 3])) >= self.config.keyframe_distance_m
            or rotation_deg(self._T_kf_cam) >= self.config.keyframe_angle_deg
        )
        if new_kf:
            self._add_keyframe(int(stamp_ns), features, None if vo.first else self._T_kf_cam)
            self._last = None
        else:
            self._last = (int(stamp_ns), dict(features))
        return TeachResult(int(stamp_ns), self._kf_index, new_kf, self._T_kf_cam.copy(), vo.success or vo.first,
                           vo.num_inliers, self._distance_m + float(np.linalg.norm(self._T_kf_cam[:3, 3])),
                           {s: len(f) for s, f in features.items()})

    def _add_keyframe(self, stamp_ns: int, features: Mapping[str, StereoFeatures],
                      T_parent_child: NDArray[np.float64] | None) -> None:
        if self._writer is None:
            assert self._camera is not None
            Pl, Pr, size = self._camera
            grey = features["grey"]
            self._writer = MapWriter(
                self.path, sources=self.config.sources, feature=grey.kind, descriptor_dim=grey.descriptors.shape[1],
                P_left=Pl, P_right=Pr, image_size=size, overwrite=self.overwrite,
                metadata={"teach": self.config.to_dict(), "stereo": self.front.stereo.to_dict(),
                          "color": self.front.color.to_dict(), "vo": self.vo.config.to_dict()},
            )
        landmarks = {s: Landmarks.from_stereo(features[s]) for s in self.config.sources}
        self._kf_index = self._writer.add_keyframe(stamp_ns, landmarks, T_parent_child)
        if T_parent_child is not None:
            self._distance_m += float(np.linalg.norm(T_parent_child[:3, 3]))
        log.debug("keyframe %d at %.2f m: %s", self._kf_index, self._distance_m,
                  {s: len(lm) for s, lm in landmarks.items()})
        self._T_kf_cam = np.eye(4)

    def finish(self) -> TeachMap:
        """Close the teach: add the last frame as a keyframe if it moved ≥ 1/5 of the keyframe spacing, write the
        manifest, move the map into place and return it (loaded back from disk, i.e. validated)."""
        if self._closed:
            raise VtrStateError("the teach has finished or was aborted")
        try:
            if self._writer is None:
                raise VtrInputError(f"no frames were taught: nothing to save at {self.path}")
            if self._last is not None:
                moved = float(np.linalg.norm(self._T_kf_cam[:3, 3])) >= 0.2 * self.config.keyframe_distance_m
                turned = rotation_deg(self._T_kf_cam) >= 0.2 * self.config.keyframe_angle_deg
                if moved or turned:
                    self._add_keyframe(self._last[0], self._last[1], self._T_kf_cam)
            self._writer.commit()
        except BaseException:
            self.abort()
            raise
        finally:
            self._closed = True
            self.front.close()
        log.info("teach finished: %d frames, %d keyframes, %.1f m, %d VO failures", self.frames,
                 self.num_keyframes, self._distance_m, self.vo_failures)
        return MapStore.load(self.path)

    def abort(self) -> None:
        """Discard this teach; a previous map at the path stays as it was."""
        self._closed = True
        if self._writer is not None:
            self._writer.abort()
        self.front.close()
