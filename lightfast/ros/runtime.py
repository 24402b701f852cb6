"""Start and stop rclpy for lightfast's commands and nodes: private context, local transport, clean shutdown."""
from __future__ import annotations

import importlib
import os
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from lightfast.bag.errors import UnknownMessageTypeError
from lightfast.errors import LightfastError
from lightfast.ros.transport import use_local_transport


@contextmanager
def ros_session(
    node_name: str,
    *,
    domain_id: int | None = None,
    install_signal_handlers: bool = True,
    args: list[str] | None = None,
    use_sim_time: bool = False,
    shutdown_grace_s: float = 5.0,
) -> Iterator[tuple[Node, SingleThreadedExecutor]]:
    """A node on its own context and executor, with lightfast's local DDS transport.

    On exit the node is destroyed and the context shut down. Destroying a node has been seen to hang; if the
    teardown takes longer than ``shutdown_grace_s`` the process exits (its work is already done by then).
    """
    use_local_transport()
    context = Context()
    rclpy.init(
        args=args,
        context=context,
        domain_id=domain_id,
        signal_handler_options=SignalHandlerOptions.ALL if install_signal_handlers else SignalHandlerOptions.NO,
    )
    executor = SingleThreadedExecutor(context=context)
    node = None
    try:
        overrides = [Parameter("use_sim_time", value=True)] if use_sim_time else []
        node = Node(node_name, context=context, parameter_overrides=overrides)
        executor.add_node(node)
        yield node, executor
    finally:
        watchdog = threading.Timer(shutdown_grace_s, os._exit, args=(3,))
        watchdog.daemon = True
        watchdog.start()
        try:
            executor.shutdown(timeout_sec=1.0)
            if node is not None:
                node.destroy_node()
        finally:
            rclpy.try_shutdown(context=context)
            watchdog.cancel()


def message_class(msgtype: str) -> type:
    """The rclpy message class for a type name like ``sensor_msgs/msg/Image``."""
    parts = msgtype.split("/")
    if len(parts) != 3 or not all(parts):
        raise UnknownMessageTypeError(f"malformed message type {msgtype!r} (expected package/msg/Name)")
    pkg, kind, name = parts
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError):
        raise UnknownMessageTypeError(
            f"message type {msgtype} is not installed here (no Python module {pkg}.{kind} with {name})"
        ) from None


def run_node(make_node: Callable[[], Node], name: str, args: list[str] | None = None, *,
             num_threads: int = 1) -> int:
    """The ``main`` of a node executable: lightfast's DDS profile, init, spin until Ctrl-C / SIGTERM, clean up.
    ``num_threads`` > 1 spins a multi-threaded executor (for nodes whose callback groups may run in parallel).

    A :class:`LightfastError` while constructing or spinning (bad parameters, a missing map) ends it with one line
    ``<name>: error: …`` on stderr and exit code 1."""
    use_local_transport()
    rclpy.init(args=args)
    node = None
    executor: MultiThreadedExecutor | None = None
    try:
        node = make_node()
        if num_threads > 1:
            executor = MultiThreadedExecutor(num_threads=num_threads)
            executor.add_node(node)
            executor.spin()
        else:
            rclpy.spin(node)
    except LightfastError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):  # Ctrl-C, or SIGTERM through rclpy's handler
        pass
    except _rclpy.RCLError:
        if rclpy.ok():  # a real error; after a signal the wait set may fail on the shut-down context instead
            raise
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
