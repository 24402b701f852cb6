"""Shared pytest fixtures. Three kinds of tests live apart:

- ``test/unit``: the ROS-free core; no rclpy.
- ``test/ros``: rclpy on a private :class:`~rclpy.context.Context` with a domain id no other process holds and
  discovery range OFF (in-process only), spun by a real SingleThreadedExecutor.
- ``test/replay``: bags written in ``tmp_path`` and replayed, some across processes (discovery LOCALHOST on a
  reserved domain id; subprocesses run under ``timeout -k`` in their own process group).
"""
from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from lightfast.data.shared import shared_root
from lightfast.ros.transport import use_local_transport

if TYPE_CHECKING:  # rclpy is imported lazily so that unit tests never load it
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

use_local_transport(force=True)  # every participant of the test run uses the loopback-only profile

ROOT = Path(__file__).resolve().parent.parent
SHARED = shared_root()  # $LIGHTFAST_SHARED, else ../shared beside the checkout


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` or ``$LIGHTFAST_SHARED/data`` (read in place, never copied)."""
    path = SHARED / "data"
    if not path.is_dir():
        pytest.fail(f"shared data not found at {path}; set LIGHTFAST_SHARED to the shared/ folder")
    return path


@pytest.fixture(scope="session")
def sevenscenes_dir(shared_data: Path) -> Path:
    return shared_data / "7scenes_redkitchen_300"


@pytest.fixture(scope="session")
def sevenscenes_bag(sevenscenes_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """All 300 real 7-Scenes frames as an MCAP bag, converted once per session."""
    from lightfast.data.sevenscenes import convert_7scenes

    return convert_7scenes(sevenscenes_dir, tmp_path_factory.mktemp("bags") / "7scenes_redkitchen_300")


@pytest.fixture(scope="session")
def tiny_lighting_map(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small lighting map (coarse window room at Freiburg), saved once per session."""
    from lightfast.daylight.lighting_map import LightingMapConfig, prepare_lighting_map
    from lightfast.daylight.sun import FREIBURG
    from lightfast.sim.validation_rooms import box_room_with_window

    mesh = box_room_with_window(tessellation_m=0.4)
    config = LightingMapConfig(patch_size_m=0.6, sky_directions=256, hemisphere_rays=32)
    return prepare_lighting_map(mesh, FREIBURG, config).save(tmp_path_factory.mktemp("map") / "lm")


@pytest.fixture
def domain_id() -> Iterator[int]:
    """A ROS domain id held exclusively by this test (other test runs on the machine get other ids).

    ``LIGHTFAST_TEST_DOMAIN_ID`` forces an id: only for the isolation test's control experiment."""
    from lightfast.ros.domain import reserve_domain_id

    if forced := os.environ.get("LIGHTFAST_TEST_DOMAIN_ID"):
        yield int(forced)
        return
    with reserve_domain_id() as lease:
        yield lease.domain_id


@pytest.fixture
def discovery_range() -> str:
    """Discovery range of the test's own participant: OFF (in-process only); replay tests override it
    (``LIGHTFAST_TEST_DISCOVERY`` too, for the isolation probe)."""
    return os.environ.get("LIGHTFAST_TEST_DISCOVERY", "OFF")


@pytest.fixture
def ros_context(domain_id: int, discovery_range: str, monkeypatch: pytest.MonkeyPatch) -> Iterator[Context]:
    """A private rclpy context on the test's domain id."""
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", discovery_range)
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


@pytest.fixture
def executor(ros_context: Context) -> Iterator[SingleThreadedExecutor]:
    from rclpy.executors import SingleThreadedExecutor

    ex = SingleThreadedExecutor(context=ros_context)
    try:
        yield ex
    finally:
        ex.shutdown(timeout_sec=1.0)


@pytest.fixture
def make_node(ros_context: Context, executor: SingleThreadedExecutor) -> Iterator[Callable[..., Node]]:
    """``make_node(name, *, spun=True, **kwargs)``: a node on the private context, added to ``executor`` unless
    ``spun`` is false (a node another thread creates and destroys entities on must not be in a waiting executor)."""
    from rclpy.node import Node

    nodes: list[Node] = []

    def factory(name: str, *, spun: bool = True, **kwargs: object) -> Node:
        node = Node(name, context=ros_context, **kwargs)
        if spun:
            executor.add_node(node)
        nodes.append(node)
        return node

    try:
        yield factory
    finally:
        for node in nodes:
            executor.remove_node(node)
            node.destroy_node()
