"""Start and stop rclpy for lightfast's commands and nodes: private context, local transport, clean shutdown."""
from __future__ import annotations

import importlib
import itertools
import os
import re
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import rclpy
import rclpy.logging
import yaml
from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from lightfast.bag.errors import UnknownMessageTypeError
from lightfast.config import ConfigError
from lightfast.errors import LightfastError
from lightfast.ros.transport import describe_transport, use_local_transport

#: Longest teardown of a node or session (destroying a node has been seen to hang); then the process exits.
SHUTDOWN_GRACE_S = 5.0


@contextmanager
def _exit_if_stuck(grace_s: float) -> Iterator[None]:
    """A teardown: the work is done, so if the block hangs (destroying a node has been seen to) longer than
    ``grace_s``, the process exits (code 3) rather than live on."""
    watchdog = threading.Timer(grace_s, os._exit, args=(3,))
    watchdog.daemon = True
    watchdog.start()
    try:
        yield
    finally:
        watchdog.cancel()


@contextmanager
def ros_session(
    node_name: str,
    *,
    domain_id: int | None = None,
    install_signal_handlers: bool = True,
    args: list[str] | None = None,
    use_sim_time: bool = False,
    shutdown_grace_s: float = SHUTDOWN_GRACE_S,
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
        with _exit_if_stuck(shutdown_grace_s):
            try:
                executor.shutdown(timeout_sec=1.0)
                if node is not None:
                    node.destroy_node()
            finally:
                rclpy.try_shutdown(context=context)


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


def _check_params_files(args: list[str]) -> None:
    """Every ``--params-file`` in ``args`` exists and is YAML with a mapping at the top: checked here, before rcl
    reads it, so that a bad file is one clear line rather than rcl's parser trace."""
    for flag, path in itertools.pairwise(args):
        if flag != "--params-file":
            continue
        try:
            data = yaml.safe_load(Path(path).read_text())
        except OSError as exc:
            raise ConfigError(f"cannot read the parameter file {path}: {exc.strerror or exc}") from None
        except (UnicodeDecodeError, yaml.YAMLError) as exc:
            raise ConfigError(f"the parameter file {path} is not valid YAML: {' '.join(str(exc).split())}") from None
        if not isinstance(data, dict):
            raise ConfigError(f"the parameter file {path} must map node names (or '/**') to 'ros__parameters'")


def _rcl_message(exc: Exception) -> str:
    """rcl's error text without the C source locations (``, at /project/src/parse.c:309``)."""
    return " ".join(re.sub(r",? at /\S+:\d+", "", str(exc)).split())


def _init_quietly(args: list[str] | None) -> None:
    """``rclpy.init`` without rcl's own "[ERROR] [rcl]: Failed to parse global arguments" line when it refuses the
    arguments: the caller prints one line of its own."""
    rclpy.logging.set_logger_level("rcl", rclpy.logging.LoggingSeverity.FATAL)
    try:
        rclpy.init(args=args)
    finally:
        if rclpy.logging.get_logger_effective_level("rcl") == rclpy.logging.LoggingSeverity.FATAL:
            rclpy.logging.set_logger_level("rcl", rclpy.logging.LoggingSeverity.UNSET)


def spin(executor: Executor, node: Node) -> None:
    """Spin until the context shuts down. An exception escaping a callback (rclpy's own, e.g. a negative /clock
    message raises in its time source) is logged, throttled, and the node carries on: one bad message must not end
    it. A :class:`LightfastError` still ends it (run_node turns it into one line and exit 1)."""
    context = executor.context
    while context.ok():
        try:
            executor.spin_once(timeout_sec=0.5)
        except (LightfastError, KeyboardInterrupt, ExternalShutdownException, _rclpy.RCLError):
            raise
        except Exception as exc:  # the safety net of the docstring
            node.get_logger().error(f"a callback failed, carrying on: {type(exc).__name__}: {exc}",
                                    throttle_duration_sec=5.0)


def run_node(make_node: Callable[[], Node], name: str, args: list[str] | None = None, *,
             num_threads: int = 1) -> int:
    """The ``main`` of a node executable: lightfast's DDS profile, init, spin until Ctrl-C / SIGTERM, clean up.
    ``num_threads`` > 1 spins a multi-threaded executor (for nodes whose callback groups may run in parallel).

    A :class:`LightfastError` while constructing or spinning (bad parameters, a missing map), a parameter file that
    cannot be read, or arguments rcl refuses end it with one line ``<name>: error: …`` on stderr and exit code 1.
    (Parameters the node does not know are reported by :class:`~lightfast.ros.params.ConfigParameters`.)"""
    use_local_transport()
    argv = list(sys.argv[1:] if args is None else args)
    try:
        _check_params_files(argv)
        _init_quietly(argv if args is not None else None)
    except LightfastError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 1
    except _rclpy.RCLError as exc:
        print(f"{name}: error: {_rcl_message(exc)}", file=sys.stderr)
        return 1
    node = None
    executor: Executor | None = None
    try:
        node = make_node()
        node.get_logger().info(describe_transport())  # which DDS profile and discovery range: this host only?
        executor = MultiThreadedExecutor(num_threads=num_threads) if num_threads > 1 else SingleThreadedExecutor()
        executor.add_node(node)
        spin(executor, node)
    except LightfastError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):  # Ctrl-C, or SIGTERM through rclpy's handler
        pass
    except _rclpy.RCLError:
        if rclpy.ok():  # a real error; after a signal the wait set may fail on the shut-down context instead
            raise
    finally:
        with _exit_if_stuck(SHUTDOWN_GRACE_S):
            if executor is not None:
                executor.shutdown(timeout_sec=1.0)
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
    return 0
