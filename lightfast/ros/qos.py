"""QoS profiles: lightfast's defaults per kind of topic, and conversions between bag QoS records and rclpy.

Sensor subscriptions (images, camera_info, clouds from drivers) are best effort by default, like
``rclpy.qos.qos_profile_sensor_data``: a best-effort subscription matches both best-effort publishers (the default
or an option of most camera drivers) and reliable ones, where a reliable one would receive nothing from a
best-effort driver. Each node's ``sensor_reliability`` parameter can ask for reliable delivery instead (lossless
replays, tests). Outputs, and the topics between lightfast's own nodes, stay reliable.

Bags store the QoS their publishers offered as rosbags :class:`~rosbags.interfaces.Qos` records; the enum values
are the rmw ones, so conversion is by value.
"""
from __future__ import annotations

from collections.abc import Sequence

from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rosbags.interfaces import Qos, QosDurability, QosReliability

from lightfast.bag.writer import make_qos
from lightfast.node_options import SENSOR_RELIABILITIES, SensorInputOptions

#: What lightfast publishes (poses, references, status) and subscribes between its own nodes: reliable, volatile.
OUTPUT_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
#: Latched state (maps, static transforms): late subscribers get the last message.
LATCHED_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: /clock, as rosbag2 and gazebo publish it.
CLOCK_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def sensor_qos(options: SensorInputOptions) -> QoSProfile:
    """The QoS of a sensor subscription, volatile: best effort with KEEP_LAST ``sensor_queue_depth`` (takes
    best-effort and reliable publishers; a node that falls behind loses the oldest), or reliable with KEEP_ALL
    (lossless: a reliable publisher waits while the node is busy; deaf to best-effort publishers)."""
    assert options.sensor_reliability in SENSOR_RELIABILITIES  # validated by the options
    if options.sensor_reliability == "best_effort":
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=options.sensor_queue_depth,
                          reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)
    return QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def playback_qos(offered: Sequence[Qos], *, depth: int = 0, reliability: str | None = None) -> QoSProfile:
    """The QoS a player should publish a bag topic with, given what its publishers offered when recorded.

    Reliable unless some recorded publisher was best-effort (or as ``reliability``, ``reliable`` or
    ``best_effort``, says); transient-local only if every one was; history KEEP_ALL by default (a reliable
    subscriber then loses nothing however fast the bag plays) or KEEP_LAST ``depth`` if ``depth > 0``.
    """
    if reliability is None:
        best_effort = any(q.reliability == QosReliability.BEST_EFFORT for q in offered)
    elif reliability in SENSOR_RELIABILITIES:
        best_effort = reliability == "best_effort"
    else:
        raise ValueError(f"reliability must be one of {SENSOR_RELIABILITIES}, got {reliability!r}")
    latched = bool(offered) and all(q.durability == QosDurability.TRANSIENT_LOCAL for q in offered)
    history = dict(history=HistoryPolicy.KEEP_LAST, depth=depth) if depth > 0 else dict(history=HistoryPolicy.KEEP_ALL)
    return QoSProfile(
        **history,
        reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def recording_qos(offered: Sequence[QoSProfile]) -> QoSProfile:
    """The QoS a recorder should subscribe with, adapted to the live publishers (like rosbag2 does).

    Reliable KEEP_ALL when every publisher is reliable (nothing is lost), else best effort; transient-local when
    every publisher is, so latched messages published before the recorder started are still recorded.
    """
    reliable = bool(offered) and all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    latched = bool(offered) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if reliable else HistoryPolicy.KEEP_LAST,
        depth=1000,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def qos_to_bag(profile: QoSProfile) -> Qos:
    """A live publisher's QoS as a bag QoS record."""
    return make_qos(
        reliable=profile.reliability == ReliabilityPolicy.RELIABLE,
        transient_local=profile.durability == DurabilityPolicy.TRANSIENT_LOCAL,
        keep_all=profile.history == HistoryPolicy.KEEP_ALL,
        depth=int(profile.depth),
    )


def bag_to_qos(q: Qos) -> QoSProfile:
    """A bag QoS record as an rclpy profile (unknown or system-default values map to rclpy's defaults)."""
    def ns(t: object) -> Duration:
        return Duration(seconds=int(getattr(t, "sec", 0)), nanoseconds=int(getattr(t, "nsec", 0)))

    def enum(policy: type, value: int, default: object) -> object:
        try:
            return policy(value)
        except ValueError:
            return default

    return QoSProfile(
        history=enum(HistoryPolicy, q.history.value, HistoryPolicy.KEEP_LAST),
        depth=max(1, q.depth),
        reliability=enum(ReliabilityPolicy, q.reliability.value, ReliabilityPolicy.RELIABLE),
        durability=enum(DurabilityPolicy, q.durability.value, DurabilityPolicy.VOLATILE),
        liveliness=enum(LivelinessPolicy, q.liveliness.value, LivelinessPolicy.AUTOMATIC),
        deadline=ns(q.deadline),
        lifespan=ns(q.lifespan),
        liveliness_lease_duration=ns(q.liveliness_lease_duration),
    )
