"""Options every node shares, as configuration mixins: how sensor topics are subscribed, how stamps are checked
against the node's clock, and which frames the node publishes in (REP 105).

A node's configuration dataclass derives from the mixins it needs (``class TrackerConfig(SensorInputOptions,
...)``), so the options become ROS parameters and ``config/*.yaml`` keys like every other field. Plain data: the
QoS profile itself is made in :mod:`lightfast.ros.qos`, the checks in :mod:`lightfast.stamps`.
"""
from __future__ import annotations

from dataclasses import dataclass

from lightfast.config import Config, param

__all__ = ["SENSOR_RELIABILITIES", "TIME_JUMP_BACK_S", "CameraInputOptions", "SensorInputOptions", "StampOptions"]

#: Time going back by more than this (s) counts as a jump (a bag played again): the default of ``time_jump_back_s``,
#: and the threshold of the nodes without input stamps to check (the sun update, rACR).
TIME_JUMP_BACK_S = 1.0
#: Values of ``sensor_reliability``.
SENSOR_RELIABILITIES = ("best_effort", "reliable")


@dataclass(frozen=True)
class SensorInputOptions(Config):
    """QoS of the sensor subscriptions (images, camera_info, point clouds)."""

    sensor_reliability: str = param(
        "best_effort", choices=SENSOR_RELIABILITIES, read_only=True,
        description="QoS reliability of the sensor subscriptions (images, camera_info, clouds). best_effort (like "
        "qos_profile_sensor_data) receives from best-effort and reliable publishers alike; reliable (with KEEP_ALL "
        "history) asks for lossless delivery (replays, tests) but receives nothing from a best-effort driver.",
    )
    sensor_queue_depth: int = param(
        10, min=1, max=1000, read_only=True,
        description="History depth of the best-effort sensor subscriptions, messages per topic (10: 0.33 s at "
        "30 Hz); the oldest are lost when the node falls further behind.",
    )


@dataclass(frozen=True)
class CameraInputOptions(Config):
    """What a node does with the images of a lens-distorted camera (``camera_info`` with non-zero ``D``)."""

    undistort: bool = param(
        True, read_only=True,
        description="Images whose camera_info has non-zero distortion coefficients (plumb_bob, rational_polynomial, "
        "equidistant) are resampled into the pinhole image of K before use (lightfast.camera.Undistorter: colour "
        "bilinear; registered depth bilinear on smooth surfaces, nearest across edges); false: such camera_info is "
        "refused with a log line (rectify upstream, e.g. image_proc).",
    )


@dataclass(frozen=True)
class StampOptions(Config):
    """How input stamps are checked against the node's clock, and when time counts as having jumped back."""

    max_stamp_ahead_s: float = param(
        1.0, min=0.0, max=86_400.0,
        description="Input stamped more than this ahead of the node's clock is refused with a log line (clocks of "
        "two hosts out of sync, a bogus stamp); 0 turns the check off.",
    )
    time_jump_back_s: float = param(
        TIME_JUMP_BACK_S, min=0.0, max=86_400.0,
        description="ROS time, or the stamps of the input, going back by more than this (a bag replayed again or "
        "looped, a restarted simulation) resets the node's time-dependent state with a log line; input stamped "
        "less far before the previous one is dropped as out of order.",
    )
