"""One VSE observation from its parts (paper §3.1, §3.4): the semi-dense cloud, the camera pose of the same stamp
and the keyframes stamped like it — how ``racr_node`` assembles what arrives on separate topics.

A cloud (``(n, 3)`` in VSE units, per-point intensities or None) waits up to ``input_wait_s`` for the VSE pose
``T_vse_cam`` of exactly its stamp, ``keyframes_per_cloud`` keyframes (image, ``T_vse_cam`` of the keyframe, keyed
by stamp and keyframe frame) and the keyframe camera; then it is used with what came, or dropped without its pose.
A newer cloud replaces a waiting one; a cloud repeating the last stamp is ignored. Stamps are ns, times s.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from lightfast.camera import PinholeCamera
from lightfast.racr.errors import RacrError
from lightfast.racr.session import RacrSession
from lightfast.status import Level, Log, Problem

__all__ = ["Observation", "VseInputs"]

Array = NDArray[np.float64]
#: Buffered VSE poses (by stamp) and keyframe halves (by stamp and frame) waiting for their clouds.
MAX_POSES = 64
MAX_KEYFRAME_PARTS = 256


@dataclass(frozen=True, eq=False)
class Observation:
    """A complete observation for :meth:`lightfast.racr.session.RacrSession.add_vse_observation`."""

    stamp_ns: int
    points: NDArray[np.floating]
    intensity: NDArray[np.floating] | None
    T_vse_cam: Array
    keyframes: list[tuple[NDArray[np.floating], Array, PinholeCamera]]


@dataclass
class _Cloud:
    stamp_ns: int
    points: NDArray[np.floating]
    intensity: NDArray[np.floating] | None
    received_s: float
    expired: bool = False  # the wait was over at a tick: the next tick uses it as it is


@dataclass
class VseInputs:
    """Buffers of the VSE's outputs until a cloud is complete; see the module docstring."""

    keyframes_per_cloud: int
    input_wait_s: float
    pose_source: str = "VSE pose"  # where the poses and the camera come from, for the problem texts
    camera_source: str = "VSE camera_info"
    camera: PinholeCamera | None = None
    poses: OrderedDict[int, Array] = field(default_factory=OrderedDict)
    stats: dict[str, int] = field(default_factory=dict)  # counters (added to a node's when given)
    _images: OrderedDict[tuple[int, str], NDArray[np.floating]] = field(default_factory=OrderedDict)
    _keyframe_poses: OrderedDict[tuple[int, str], Array] = field(default_factory=OrderedDict)
    _pending: _Cloud | None = None
    _last_used_ns: int | None = None

    def __post_init__(self) -> None:
        for key in ("clouds_used", "clouds_dropped", "clouds_superseded"):
            self.stats.setdefault(key, 0)

    def add_cloud(self, now_s: float, stamp_ns: int, points: NDArray[np.floating],
                  intensity: NDArray[np.floating] | None) -> bool:
        """A new cloud, received at ``now_s``; False when it repeats one already here."""
        if stamp_ns == self._last_used_ns or (self._pending is not None and self._pending.stamp_ns == stamp_ns):
            return False
        if self._pending is not None:
            self.stats["clouds_superseded"] += 1
        self._pending = _Cloud(stamp_ns, points, intensity, now_s)
        return True

    def add_pose(self, stamp_ns: int, T_vse_cam: Array) -> bool:
        """The VSE camera pose at ``stamp_ns``; False when it repeats one already here."""
        if stamp_ns in self.poses:
            return False
        self.poses[stamp_ns] = T_vse_cam
        _trim(self.poses, MAX_POSES)
        return True

    def add_keyframe_image(self, stamp_ns: int, frame: str, image: NDArray[np.floating]) -> None:
        self._images[(stamp_ns, frame)] = image
        _trim(self._images, MAX_KEYFRAME_PARTS)

    def add_keyframe_pose(self, stamp_ns: int, frame: str, T_vse_cam: Array) -> None:
        self._keyframe_poses[(stamp_ns, frame)] = T_vse_cam
        _trim(self._keyframe_poses, MAX_KEYFRAME_PARTS)

    def clear(self) -> None:
        """Forget everything (time went back)."""
        self.poses.clear()
        self._images.clear()
        self._keyframe_poses.clear()
        self._pending = self._last_used_ns = None

    def take(self, now_s: float, *, at_tick: bool = False) -> tuple[Observation | None, list[Problem | Log]]:
        """The waiting cloud once its pose, keyframes and camera are here, or when its wait was over at two ticks
        in a row (``at_tick``: input callbacks get their turn between two ticks, so messages that queued up while
        the executor was busy are not missed). Returns the observation (or None) and what to report."""
        c = self._pending
        if c is None:
            return None, []
        pose = self.poses.get(c.stamp_ns)
        keys = [k for k in self._images if k[0] == c.stamp_ns and k in self._keyframe_poses]
        complete = pose is not None and len(keys) >= self.keyframes_per_cloud and (
            self.camera is not None or self.keyframes_per_cloud == 0)
        if not complete:
            if not at_tick or now_s - c.received_s < self.input_wait_s:
                return None, []
            if not c.expired:
                c.expired = True
                return None, []
        self._pending = None
        if pose is None:
            self.stats["clouds_dropped"] += 1
            return None, [Problem("cloud_pose", f"VSE cloud {c.stamp_ns} dropped: no {self.pose_source} with its "
                                  f"stamp within {self.input_wait_s:g} s")]
        reports: list[Problem | Log] = []
        keyframes = []
        cam = self.camera
        if keys and cam is None:
            reports.append(Problem("camera_info", f"VSE cloud {c.stamp_ns}: keyframes unused, no {self.camera_source} "
                                   "yet"))
        elif cam is not None:
            for k in keys:
                image = self._images[k]
                if image.shape != cam.shape:
                    reports.append(Problem("keyframe", f"keyframe {k[1]} of cloud {c.stamp_ns} unused: image "
                                           f"{image.shape[1]}x{image.shape[0]} but camera_info "
                                           f"{cam.width}x{cam.height}"))
                    continue
                keyframes.append((image, self._keyframe_poses[k], cam))
        if len(keyframes) < self.keyframes_per_cloud:
            reports.append(Log(f"VSE cloud {c.stamp_ns} used with {len(keyframes)} of {self.keyframes_per_cloud} "
                               "keyframes", Level.WARN, key="few_keyframes"))
        return Observation(c.stamp_ns, c.points, c.intensity, pose, keyframes), reports

    def feed(self, session: RacrSession, now_s: float, *, at_tick: bool = False) -> list[Problem | Log]:
        """Hand the waiting cloud to ``session`` once it is complete (:meth:`take`); what to report."""
        obs, reports = self.take(now_s, at_tick=at_tick)
        if obs is None:
            return reports
        try:
            session.add_vse_observation(obs.points, obs.intensity, obs.T_vse_cam, obs.keyframes,
                                        stamp=obs.stamp_ns * 1e-9)
        except RacrError as exc:
            self.stats["clouds_dropped"] += 1
            return [*reports, Problem("cloud", f"VSE cloud {obs.stamp_ns} skipped: {exc}")]
        self._last_used_ns = obs.stamp_ns
        self.stats["clouds_used"] += 1
        return reports


def _trim(buffer: OrderedDict, size: int) -> None:
    while len(buffer) > size:
        buffer.popitem(last=False)
