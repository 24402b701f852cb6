"""What ``daylight_relight_node`` decides, without ROS: which live frame is relit at which coarse pose T≈, when a
new B̂_sun is swapped in, and what time going back restarts (Krawez et al., RA-L 2021: §III-C brightness scales,
Eq. 3–6, averaged over a window of frames, and §III-D reference images I_C^ref, I_D^ref rendered at T≈, by
:class:`~lightfast.daylight.relight.DaylightRelighter`; the B̂_sun epochs of the chunked sun update, §III-E).

Inputs, from any thread: live colour images (H, W, 3) uint8 with their stamp (ns) and optical frame id; coarse
poses ``T_map_cam`` (4×4, metres, in ``map_frame``) stamped with their image; the live camera
(:class:`~lightfast.camera.PinholeCamera`); B̂_sun chunks (vertex ids, (n, 3) normalized radiosity) stamped with
their epoch (ns). ``clock()`` is the node's clock (ns; <= 0: not known yet). Image and pose pair by exact stamp,
either first (``MAX_UNPAIRED`` wait per side); at most ``MAX_QUEUED`` paired frames wait, the oldest dropped: its
reference would miss the tracker's deadline. A chunk's epoch stamped more than ``max_sun_epoch_ahead_s`` ahead of
the clock, or older than the epoch in use or being received, is refused (reported once per epoch); an epoch is
swapped in only when complete (:class:`~lightfast.daylight.sun_update.SunEpochAssembler`).

One worker thread drives the rest: :meth:`RelightSession.take_work` applies parameter changes and a complete
B̂_sun, :meth:`RelightSession.relight` checks the frame's stamp against the clock and renders its
:class:`~lightfast.daylight.relight.Reference` (colour rgb8, depth float32 metres, scales per component). Time
going back (the clock, or frame stamps by more than ``time_jump_back_s``) restarts the brightness average and lets
the next complete epoch in, whatever its time. Results say what happened (:class:`Work`, :class:`Relit`,
:class:`ChunkResult`) for the node to log: the session never logs. It counts into ``stats`` (the node's status
counters). Invalid input raises :class:`~lightfast.daylight.errors.BrightnessError`.
"""
from __future__ import annotations

import enum
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lightfast.camera import PinholeCamera
from lightfast.daylight.errors import BrightnessError
from lightfast.daylight.relight import DaylightRelighter, Reference, RelightConfig
from lightfast.daylight.sun_update import SunEpochAssembler
from lightfast.errors import LightfastError
from lightfast.stamps import StampGuard, StampVerdict
from lightfast.sync import ExactTimePairs

__all__ = ["MAX_QUEUED", "MAX_UNPAIRED", "ChunkResult", "RelightFrame", "RelightSession", "Relit", "Skip", "Work"]

#: Images and coarse poses waiting for their partner (per side): about a second of frames at 30 Hz.
MAX_UNPAIRED = 30
#: Paired frames waiting for the relighter; when it falls behind the oldest are dropped: their references would come
#: after the tracker's deadline, so rendering them would only delay the references of the newer frames.
MAX_QUEUED = 2
#: The counters :class:`RelightSession` adds to its ``stats``.
COUNTERS = ("frames_in", "poses_in", "dropped_behind", "dropped_unpaired", "waiting_for_sun", "chunks",
            "dropped_epochs", "time_jumps")

#: When a message of a frame came: time.monotonic() then, and the node clock minus the frame's stamp (>= 0, ns).
Arrival = tuple[float, int]
_Image = tuple[NDArray[np.uint8], str, Arrival]
_Pose = tuple[NDArray[np.float64], Arrival]


@dataclass
class RelightFrame:
    """A live image paired with its coarse pose."""

    stamp_ns: int
    rgb: NDArray[np.uint8]
    frame_id: str
    T_map_cam: NDArray[np.float64]
    arrival: Arrival  # the first of image and pose
    pose_latency_ms: float  # image stamp -> coarse pose here

    def latency_ms(self) -> float:
        """Image stamp -> now: the node clock's lag when the first of image and pose came, plus the wall time since
        (on sim time the node clock only moves with /clock messages, about one per frame)."""
        return 1e-6 * self.arrival[1] + 1e3 * (time.monotonic() - self.arrival[0])


@dataclass(frozen=True)
class ChunkResult:
    """What a B̂_sun chunk did: ``complete``: it completed its epoch (wake the worker); ``dropped``: why its epoch
    was refused, only for the first refused chunk of an epoch (one log line each)."""

    complete: bool = False
    dropped: str | None = None


@dataclass(frozen=True)
class Work:
    """What :meth:`RelightSession.take_work` took and did: ``time_jump`` why the time-dependent state restarted
    (the clock went back), ``sun_epoch_ns`` the epoch swapped in (``first_sun``: the first one), ``frame`` the
    frame to :meth:`~RelightSession.relight` next, ``more`` whether more frames wait."""

    frame: RelightFrame | None = None
    more: bool = False
    time_jump: str | None = None
    sun_epoch_ns: int | None = None
    first_sun: bool = False


class Skip(enum.Enum):
    """Why a frame got no reference; the values are the node's problem keys."""

    AHEAD = "stamp"  # stamped too far ahead of the clock
    NO_CAMERA = "no_camera_info"
    SIZE = "size"  # image and camera disagree
    WAITING = "waiting"  # no complete sun epoch yet
    FAILED = "step"  # the relighter raised


@dataclass(frozen=True)
class Relit:
    """What :meth:`RelightSession.relight` did with a frame: ``time_jump`` why the time-dependent state restarted
    first (its stamp went back), then either ``skip`` with ``reason`` or the ``reference``, whose relighting started
    at ``started`` (time.perf_counter())."""

    time_jump: str | None = None
    skip: Skip | None = None
    reason: str = ""
    reference: Reference | None = None
    started: float = 0.0


class RelightSession:
    """The relight node's state between its input callbacks and its worker thread; see the module docstring.

    Thread-safe as used: the ``add_*`` / ``set_*`` calls from any thread, :meth:`take_work` and :meth:`relight`
    from one worker thread (the only one that touches ``relighter``).
    """

    def __init__(self, relighter: DaylightRelighter, config: RelightConfig, clock: Callable[[], int], *,
                 stats: dict[str, int] | None = None, max_unpaired: int = MAX_UNPAIRED,
                 max_queued: int = MAX_QUEUED) -> None:
        self.relighter = relighter
        self.assembler = SunEpochAssembler(relighter.lmap.num_vertices)
        self.config = config  # the options in use for the inputs; the relighter takes a change in take_work
        self._clock = clock
        self.max_queued = max_queued
        self.stats = {} if stats is None else stats
        for key in COUNTERS:
            self.stats.setdefault(key, 0)
        self._lock = threading.Lock()  # guards everything the inputs share with the worker
        self._pairs: ExactTimePairs[_Image, _Pose] = ExactTimePairs(max_unpaired)
        self._queue: deque[RelightFrame] = deque()
        self._camera: PinholeCamera | None = None
        self._new_sun: tuple[NDArray[np.float32], int] | None = None
        self._new_config: RelightConfig | None = None
        self._guard = StampGuard(config)  # stamps of the paired frames (worker only), with the start-up options
        self._dropped_epochs: set[int] = set()  # sun epochs already reported as dropped

    # ---------------------------------------------------------------------------------------------- state

    @property
    def queued(self) -> int:
        return len(self._queue)

    @property
    def camera(self) -> PinholeCamera | None:
        return self._camera

    def epoch_progress(self) -> str:
        """`` (epoch E at P%)`` while an epoch is being received, else ``""``."""
        a = self.assembler
        return f" (epoch {a.pending_epoch_ns} at {100 * a.progress:.0f}%)" if a.pending_epoch_ns else ""

    def status_values(self) -> dict[str, Any]:
        """The sun epoch in use and the one being received."""
        a = self.assembler
        return {"sun_epoch_ns": self.relighter.sun_epoch_ns, "pending_epoch_ns": a.pending_epoch_ns,
                "chunk_progress": a.progress if a.pending_epoch_ns is not None else None}

    # ---------------------------------------------------------------------------------------------- inputs

    def _arrival(self, stamp: int) -> Arrival:
        return time.monotonic(), max(0, self._clock() - stamp)

    def add_image(self, stamp_ns: int, rgb: NDArray[np.uint8], frame_id: str) -> bool:
        """A live colour image; returns whether a paired frame was queued (wake the worker)."""
        arrival = self._arrival(stamp_ns)
        with self._lock:
            self.stats["frames_in"] += 1
            return self._enqueue(stamp_ns, self._pairs.add_first(stamp_ns, (rgb, frame_id, arrival)))

    def add_pose(self, stamp_ns: int, T_map_cam: NDArray[np.float64], frame_id: str) -> bool:
        """A coarse pose; returns whether a paired frame was queued. Raises :class:`BrightnessError` for a pose in
        another frame than ``map_frame`` (``""`` counts as ``map_frame``)."""
        if frame_id not in ("", self.config.map_frame):
            raise BrightnessError(f"frame_id {frame_id!r} is not {self.config.map_frame!r}")
        arrival = self._arrival(stamp_ns)
        with self._lock:
            self.stats["poses_in"] += 1
            return self._enqueue(stamp_ns, self._pairs.add_second(stamp_ns, (T_map_cam, arrival)))

    def _enqueue(self, stamp: int, pair: tuple[_Image, _Pose] | None) -> bool:
        self.stats["dropped_unpaired"] = self._pairs.dropped
        if pair is None:
            return False
        (rgb, frame_id, image_arrival), (T, pose_arrival) = pair
        first = min(image_arrival, pose_arrival)
        pose_latency_ms = 1e-6 * first[1] + 1e3 * (pose_arrival[0] - first[0])
        self._queue.append(RelightFrame(stamp, rgb, frame_id, T, first, pose_latency_ms))
        while len(self._queue) > self.max_queued:
            self._queue.popleft()
            self.stats["dropped_behind"] += 1
        return True

    def set_camera(self, camera: PinholeCamera) -> None:
        with self._lock:
            self._camera = camera

    def set_config(self, config: RelightConfig) -> None:
        """New options: the inputs use them at once, the relighter at the next :meth:`take_work`."""
        with self._lock:
            self.config = config
            self._new_config = config

    def add_chunk(self, epoch_ns: int, vertex_ids: NDArray[Any], radiosity: NDArray[Any]) -> ChunkResult:
        """A B̂_sun chunk of the epoch ``epoch_ns``. Raises :class:`BrightnessError` for a chunk that does not fit
        the lighting map (a stream for another map)."""
        with self._lock:  # the worker restarts the assembler when time jumps back
            why = self._epoch_refused(epoch_ns)
            if why is not None:
                first = epoch_ns not in self._dropped_epochs
                if first:
                    self._dropped_epochs.add(epoch_ns)
                    self.stats["dropped_epochs"] += 1
                return ChunkResult(dropped=why if first else None)
            try:
                complete = self.assembler.add(epoch_ns, vertex_ids, radiosity)
            except ValueError as exc:
                raise BrightnessError(str(exc)) from exc
            self.stats["chunks"] += 1
            if complete is not None:
                self._new_sun = (complete, epoch_ns)
        return ChunkResult(complete=complete is not None)

    def _epoch_refused(self, epoch: int) -> str | None:
        """(Under the lock.) Why a sun epoch is refused: stamped implausibly far ahead of the clock, or older than
        the one in use or being received; ``None``: it is taken."""
        now = self._clock()
        ahead_s = self.config.max_sun_epoch_ahead_s
        ahead_ns = round(ahead_s * 1e9)
        if ahead_ns > 0 and now > 0 and epoch - now > ahead_ns:
            return (f"stamped {(epoch - now) * 1e-9:.1f} s ahead of this node's clock (max_sun_epoch_ahead_s "
                    f"{ahead_s:g})")
        return self.assembler.drop_reason(epoch)

    # ---------------------------------------------------------------------------------------------- worker

    def _time_jumped(self) -> None:
        """(Under the lock.) Time went back: the scale average restarts and the next complete sun epoch is taken
        whatever its time (the B̂_sun in use stays until then)."""
        self.stats["time_jumps"] += 1
        self._guard.reset()
        self.relighter.restart_average()
        self.assembler.restart()
        self._dropped_epochs.clear()

    def take_work(self, clock_jump_ns: int | None = None) -> Work:
        """Take the next frame; restart the time-dependent state if the clock jumped back to ``clock_jump_ns``
        past the frames' stamps; apply new options and a complete B̂_sun."""
        with self._lock:
            new_sun, self._new_sun = self._new_sun, None
            new_config, self._new_config = self._new_config, None
            frame = self._queue.popleft() if self._queue else None
            more = bool(self._queue)
            time_jump = None
            if clock_jump_ns is not None and self._guard.clock_jumped_back(clock_jump_ns):
                self._time_jumped()
                time_jump = f"ROS time jumped back to {clock_jump_ns * 1e-9:.3f} s"
        if new_config is not None:
            self.relighter.reconfigure(new_config)
        if new_sun is None:
            return Work(frame, more, time_jump)
        first = not self.relighter.ready
        self.relighter.set_sun_radiosity(*new_sun)
        return Work(frame, more, time_jump, new_sun[1], first)

    def relight(self, frame: RelightFrame) -> Relit:
        """Check the frame's stamp (refused ahead of the clock; a jump back restarts the time-dependent state; one
        slightly out of order is relit as it is), the camera and the sun, and render the frame's reference."""
        stamp = frame.stamp_ns
        now = self._clock()
        verdict = self._guard.check(stamp, now)
        if verdict is StampVerdict.AHEAD:
            return Relit(skip=Skip.AHEAD, reason=self._guard.describe(verdict, stamp, now))
        time_jump = None
        if verdict is StampVerdict.JUMPED_BACK:
            assert self._guard.last_ns is not None  # JUMPED_BACK: there is a previous stamp
            time_jump = f"frame stamps went back {(self._guard.last_ns - stamp) * 1e-9:.3f} s"
            with self._lock:
                self._time_jumped()
        if verdict is not StampVerdict.OUT_OF_ORDER:
            self._guard.accept(stamp)
        with self._lock:
            camera = self._camera
        if camera is None:
            return Relit(time_jump, Skip.NO_CAMERA, "no camera_info yet")
        if frame.rgb.shape[:2] != camera.shape:
            return Relit(time_jump, Skip.SIZE, f"colour image is {frame.rgb.shape[1]}x{frame.rgb.shape[0]}, "
                         f"camera_info says {camera.width}x{camera.height}")
        if not self.relighter.ready:
            self.stats["waiting_for_sun"] += 1
            return Relit(time_jump, Skip.WAITING, "waiting for the first complete sun epoch")
        started = time.perf_counter()
        try:
            ref = self.relighter.step(stamp, frame.rgb, frame.T_map_cam, camera)
        except LightfastError as exc:
            return Relit(time_jump, Skip.FAILED, str(exc))
        return Relit(time_jump, reference=ref, started=started)
