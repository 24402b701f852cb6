"""DDS transport defaults that keep lightfast on this machine and let images through.

Every lightfast entry point (CLI, node ``main``, scripts, tests) calls :func:`use_local_transport` before rclpy
creates its first participant. It points Fast DDS at the packaged profile (64 MB shared-memory segments, UDP on
loopback only) and limits automatic discovery to this host, unless the user has set those variables already:
a real multi-host deployment sets ``FASTRTPS_DEFAULT_PROFILES_FILE`` to its own profile and
``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``.
"""
from __future__ import annotations

import os
from pathlib import Path

PROFILE_PATH = Path(__file__).with_name("fastdds_local.xml")
PROFILE_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
RANGE_ENV = "ROS_AUTOMATIC_DISCOVERY_RANGE"
RMW_ENV = "RMW_IMPLEMENTATION"


def local_transport_env(*, discovery_range: str = "LOCALHOST", domain_id: int | None = None) -> dict[str, str]:
    """The environment variables of the local transport, e.g. to pass to a subprocess."""
    env = {PROFILE_ENV: str(PROFILE_PATH), RANGE_ENV: discovery_range, RMW_ENV: "rmw_fastrtps_cpp"}
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(int(domain_id))
    return env


def use_local_transport(*, force: bool = False) -> None:
    """Set the local transport variables in this process (``force`` overrides what the user set)."""
    for key, value in local_transport_env().items():
        if force or not os.environ.get(key):
            os.environ[key] = value

