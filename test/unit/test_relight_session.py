"""The relight node's policy without ROS (§III-C/D references per paired frame, §III-E complete B̂_sun epochs):
image/pose pairing and the bounded queue, sun epochs swapped in only when complete and refused when stamped ahead
of the clock or older, stamps and clocks going back, and why a frame gets no reference. A stand-in relighter
records what the session asks of it."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from lightfast.camera import PinholeCamera
from lightfast.daylight.errors import BrightnessError
from lightfast.daylight.relight import Reference, RelightConfig
from lightfast.daylight.relight_session import MAX_QUEUED, RelightSession, Skip

CAMERA = PinholeCamera(8, 6, 10.0, 10.0, 3.5, 2.5)
V = 10  # vertices of the stand-in lighting map
S = 1_000_000_000  # ns per s
T0 = 1_700_000_000 * S


class FakeRelighter:
    """What the session uses of :class:`~lightfast.daylight.relight.DaylightRelighter`, recording the calls."""

    names = ("sun", "sky", "ground")

    def __init__(self) -> None:
        self.lmap = SimpleNamespace(num_vertices=V)
        self.sun_epoch_ns: int | None = None
        self.sun: np.ndarray | None = None
        self.restarts = 0
        self.configs: list[RelightConfig] = []
        self.steps: list[int] = []
        self.fail: Exception | None = None

    @property
    def ready(self) -> bool:
        return self.sun_epoch_ns is not None

    def set_sun_radiosity(self, sun: np.ndarray, epoch_ns: int) -> None:
        self.sun, self.sun_epoch_ns = sun, epoch_ns

    def restart_average(self) -> None:
        self.restarts += 1

    def reconfigure(self, config: RelightConfig) -> None:
        self.configs.append(config)

    def step(self, stamp_ns: int, rgb: np.ndarray, T: np.ndarray, camera: PinholeCamera) -> Reference:
        if self.fail is not None:
            raise self.fail
        self.steps.append(stamp_ns)
        return Reference(stamp_ns, T, np.zeros((*camera.shape, 3), np.uint8), np.zeros(camera.shape, np.float32),
                         self.names, np.ones((3, 3)), None, 7)


class Clock:
    def __init__(self, now_ns: int = T0) -> None:
        self.now_ns = now_ns

    def __call__(self) -> int:
        return self.now_ns


def make(**options: object) -> tuple[RelightSession, FakeRelighter, Clock]:
    relighter, clock = FakeRelighter(), Clock()
    session = RelightSession(relighter, RelightConfig(**options), clock, max_unpaired=3)  # type: ignore[arg-type]
    return session, relighter, clock


def rgb(shape: tuple[int, int] = CAMERA.shape) -> np.ndarray:
    return np.full((*shape, 3), 100, np.uint8)


def pose(x: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[0, 3] = x
    return T


def frame(session: RelightSession, stamp: int, x: float = 0.0) -> bool:
    session.add_image(stamp, rgb(), "cam")
    return session.add_pose(stamp, pose(x), "map")


def send_epoch(session: RelightSession, epoch: int, value: float = 1.0, parts: slice = slice(None)) -> list:
    chunks = [(np.arange(i, min(i + 4, V)), np.full((min(4, V - i), 3), value)) for i in range(0, V, 4)][parts]
    return [session.add_chunk(epoch, ids, rad) for ids, rad in chunks]


def ready(session: RelightSession, epoch: int = T0 - S) -> None:
    send_epoch(session, epoch)
    session.set_camera(CAMERA)
    assert session.take_work().sun_epoch_ns == epoch


def test_image_and_pose_pair_by_stamp_in_either_order() -> None:
    session, _, clock = make()
    clock.now_ns = T0 + 20_000_000  # the image comes 20 ms of clock after its stamp
    assert not session.add_image(T0, rgb(), "cam")  # image first
    assert session.queued == 0
    assert session.add_pose(T0, pose(1.0), "map")
    assert not session.add_pose(T0 + 1, pose(2.0), "")  # pose first; "" counts as the map frame
    assert session.add_image(T0 + 1, rgb(), "cam")
    assert session.queued == 2 and session.stats["frames_in"] == 2 and session.stats["poses_in"] == 2
    work = session.take_work()
    assert work.frame is not None and work.more
    f = work.frame
    assert (f.stamp_ns, f.frame_id, f.T_map_cam[0, 3]) == (T0, "cam", 1.0)
    assert f.arrival[1] == 20_000_000  # the first of image and pose
    assert f.pose_latency_ms >= 20.0 and f.latency_ms() >= f.pose_latency_ms
    assert session.take_work().frame.stamp_ns == T0 + 1  # type: ignore[union-attr]


def test_a_pose_in_another_frame_is_refused_and_not_counted() -> None:
    session, _, _ = make()
    with pytest.raises(BrightnessError, match="'odom' is not 'map'"):
        session.add_pose(T0, pose(), "odom")
    assert session.stats["poses_in"] == 0


def test_the_oldest_frames_are_dropped_when_the_worker_falls_behind() -> None:
    session, _, _ = make()
    for i in range(MAX_QUEUED + 2):
        frame(session, T0 + i)
    assert session.queued == MAX_QUEUED and session.stats["dropped_behind"] == 2
    assert session.take_work().frame.stamp_ns == T0 + 2  # type: ignore[union-attr]
    for i in range(5):  # images without poses: beyond max_unpaired the oldest go
        session.add_image(T0 + 100 + i, rgb(), "cam")
    assert session.stats["dropped_unpaired"] == 2


def test_a_sun_epoch_is_swapped_in_only_when_complete() -> None:
    session, relighter, _ = make()
    session.set_camera(CAMERA)
    assert not any(r.complete for r in send_epoch(session, T0, parts=slice(0, 2)))
    assert session.status_values() == {"sun_epoch_ns": None, "pending_epoch_ns": T0, "chunk_progress": 0.8}
    assert session.epoch_progress() == f" (epoch {T0} at 80%)"
    frame(session, T0)
    r = session.relight(session.take_work().frame)  # type: ignore[arg-type]
    assert r.skip is Skip.WAITING and session.stats["waiting_for_sun"] == 1 and relighter.sun is None
    assert send_epoch(session, T0, 2.0, parts=slice(2, None))[-1].complete
    work = session.take_work()
    assert (work.sun_epoch_ns, work.first_sun) == (T0, True)
    assert relighter.sun_epoch_ns == T0 and relighter.sun is not None and relighter.sun.shape == (V, 3)
    assert session.stats["chunks"] == 3
    send_epoch(session, T0 + S)
    assert (session.take_work().sun_epoch_ns, relighter.sun_epoch_ns) == (T0 + S, T0 + S)


def test_epochs_ahead_of_the_clock_or_older_are_refused_once_each() -> None:
    session, relighter, clock = make(max_sun_epoch_ahead_s=10.0)
    ready(session, T0)
    bogus = T0 + 365 * 86_400 * S
    results = send_epoch(session, bogus)
    assert results[0].dropped is not None and "ahead of this node's clock" in results[0].dropped
    assert all(r.dropped is None and not r.complete for r in results[1:])  # one log line per epoch
    old = send_epoch(session, T0 - S)
    assert old[0].dropped == f"older than the epoch in use ({T0})"
    assert session.stats["dropped_epochs"] == 2 and session.stats["chunks"] == 3
    send_epoch(session, T0 + 5 * S)  # a real later epoch still comes in
    assert session.take_work().sun_epoch_ns == T0 + 5 * S
    clock.now_ns = 0  # sim time before the first /clock: no check against the clock
    send_epoch(session, bogus)
    assert relighter.sun_epoch_ns == T0 + 5 * S and session.take_work().sun_epoch_ns == bogus


def test_chunks_of_another_map_raise() -> None:
    session, _, _ = make()
    with pytest.raises(BrightnessError, match="another lighting map"):
        session.add_chunk(T0, np.arange(V + 5), np.ones((V + 5, 3)))


def test_a_changed_epoch_limit_applies_at_once_and_the_relighter_takes_options_between_frames() -> None:
    session, relighter, _ = make()
    session.set_config(RelightConfig(max_sun_epoch_ahead_s=1.0, window=5))
    assert send_epoch(session, T0 + 2 * S)[0].dropped is not None
    assert relighter.configs == []
    session.take_work()
    assert [c.window for c in relighter.configs] == [5]


def test_a_reference_and_why_there_is_none() -> None:
    session, relighter, _ = make()
    send_epoch(session, T0 - S)
    session.take_work()
    frame(session, T0)
    assert session.relight(session.take_work().frame).skip is Skip.NO_CAMERA  # type: ignore[arg-type]
    session.set_camera(CAMERA.scaled(0.5))
    frame(session, T0 + 1)
    r = session.relight(session.take_work().frame)  # type: ignore[arg-type]
    assert (r.skip, r.reason) == (Skip.SIZE, "colour image is 8x6, camera_info says 4x3")
    session.set_camera(CAMERA)
    frame(session, T0 + 2)
    relighter.fail = BrightnessError("bad pose")
    r = session.relight(session.take_work().frame)  # type: ignore[arg-type]
    assert (r.skip, r.reason, r.reference) == (Skip.FAILED, "bad pose", None)
    relighter.fail = None
    frame(session, T0 + 3, x=0.5)
    r = session.relight(session.take_work().frame)  # type: ignore[arg-type]
    assert r.skip is None and r.time_jump is None and r.started > 0
    assert r.reference is not None and r.reference.stamp_ns == T0 + 3 and r.reference.T_map_cam[0, 3] == 0.5


def test_frames_ahead_of_the_clock_are_refused_and_out_of_order_ones_relit() -> None:
    session, relighter, _ = make(max_stamp_ahead_s=1.0, time_jump_back_s=1.0)
    ready(session)
    frame(session, T0 + 5 * S)
    r = session.relight(session.take_work().frame)  # type: ignore[arg-type]
    assert r.skip is Skip.AHEAD and "ahead of this node's clock" in r.reason
    for stamp in (T0, T0 - S // 2):  # the second: slightly out of order
        frame(session, stamp)
        assert session.relight(session.take_work().frame).reference is not None  # type: ignore[arg-type]
    assert relighter.steps == [T0, T0 - S // 2] and session.stats["time_jumps"] == 0


def test_stamps_going_back_restart_the_average_and_let_an_older_epoch_in() -> None:
    session, relighter, _ = make(time_jump_back_s=1.0)
    ready(session, T0)
    frame(session, T0)
    session.relight(session.take_work().frame)  # type: ignore[arg-type]
    assert send_epoch(session, T0 - 10 * S)[0].dropped is not None  # older than the epoch in use
    frame(session, T0 - 30 * S)  # a bag played again
    r = session.relight(session.take_work().frame)  # type: ignore[arg-type]
    assert r.time_jump == "frame stamps went back 30.000 s" and r.reference is not None
    assert relighter.restarts == 1 and session.stats["time_jumps"] == 1
    results = send_epoch(session, T0 - 10 * S)  # now taken, though older
    assert results[0].dropped is None and results[-1].complete
    assert session.take_work().sun_epoch_ns == T0 - 10 * S


def test_the_clock_going_back_restarts_only_when_the_frames_are_beyond_it() -> None:
    session, relighter, _ = make(time_jump_back_s=1.0)
    ready(session, T0)
    frame(session, T0)
    session.relight(session.take_work().frame)  # type: ignore[arg-type]
    assert session.take_work(clock_jump_ns=T0 - S // 2).time_jump is None  # within time_jump_back_s
    work = session.take_work(clock_jump_ns=T0 - 20 * S)
    assert work.time_jump == f"ROS time jumped back to {(T0 - 20 * S) * 1e-9:.3f} s"
    assert relighter.restarts == 1 and session.stats["time_jumps"] == 1
    assert session.take_work(clock_jump_ns=T0 - 40 * S).time_jump is None  # the frames have not come back yet
