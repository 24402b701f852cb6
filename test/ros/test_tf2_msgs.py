"""tf2_msgs in the lightfast venv. PyPI has no tf2_msgs wheel, so scripts/build_interfaces.sh (run by setup.sh)
builds it from interfaces/tf2_msgs; these tests check the result is the real ROS 2 Jazzy tf2_msgs/msg/TFMessage:

- its fields, recursively, and its type hash are those of the Jazzy definition that rosbags carries;
- it goes through a real publisher and subscription (Fast DDS typesupport) in-process;
- its CDR bytes decode with rosbags, and rosbags' bytes decode with rclpy, so /tf in bags is readable by
  rosbags, Foxglove and rosbag2 alike.
"""
from __future__ import annotations

import dataclasses
import importlib
from typing import Any

from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import Stores, get_typestore

from lightfast.ros.spin import spin_until

TFMESSAGE = "tf2_msgs/msg/TFMessage"
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
# rosidl's names of the basic types that rosbags spells differently
ROSIDL_TO_ROSBAGS = {"double": "float64", "float": "float32", "long double": "float128", "octet": "byte"}


def _tfmessage_class() -> type:
    from tf2_msgs.msg import TFMessage

    return TFMessage


def _rclpy_class(msgtype: str) -> type:
    """The rclpy message class of ``pkg/msg/Name``."""
    pkg, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def _slot_as_rosbags(slot: Any) -> tuple[str, Any]:
    """An rclpy SLOT_TYPES entry in the shape of a rosbags field definition (node type name, details)."""
    from rosidl_parser import definition as d

    if isinstance(slot, d.NamespacedType):
        return ("NAME", "/".join([*slot.namespaces, slot.name]))
    if isinstance(slot, d.UnboundedString):
        return ("BASE", ("string", 0))
    if isinstance(slot, d.BoundedString):
        return ("BASE", ("string", slot.maximum_size))
    if isinstance(slot, d.BasicType):
        return ("BASE", (ROSIDL_TO_ROSBAGS.get(slot.typename, slot.typename), 0))
    if isinstance(slot, d.UnboundedSequence):
        return ("SEQUENCE", (_slot_as_rosbags(slot.value_type), 0))
    if isinstance(slot, d.BoundedSequence):
        return ("SEQUENCE", (_slot_as_rosbags(slot.value_type), slot.maximum_size))
    if isinstance(slot, d.Array):
        return ("ARRAY", (_slot_as_rosbags(slot.value_type), slot.size))
    raise AssertionError(f"unexpected rosidl slot type {slot!r}")


def _rosbags_field(field: Any) -> tuple[str, Any]:
    """A rosbags field definition with node type names instead of enum members, nested alike."""
    nodetype, details = field
    if nodetype.name in ("SEQUENCE", "ARRAY"):
        inner, size = details
        return (nodetype.name, (_rosbags_field(inner), size))
    return (nodetype.name, details)


def _assert_same_definition(msgtype: str, seen: set[str]) -> None:
    """Field names and types of the rclpy class of ``msgtype`` equal rosbags' Jazzy definition, recursively."""
    if msgtype in seen:
        return
    seen.add(msgtype)
    cls = _rclpy_class(msgtype)
    ours = list(zip(cls.get_fields_and_field_types(), (_slot_as_rosbags(s) for s in cls.SLOT_TYPES), strict=True))
    _consts, fields = TYPESTORE.fielddefs[msgtype]
    theirs = [(name, _rosbags_field(field)) for name, field in fields]
    assert ours == theirs, msgtype
    for _name, (kind, details) in ours:
        while kind in ("SEQUENCE", "ARRAY"):
            kind, details = details[0]
        if kind == "NAME":
            _assert_same_definition(details, seen)


def _type_hash_string(type_hash: Any) -> str:
    return f"RIHS{type_hash.version:02d}_{bytes(type_hash.value).hex()}"


def _plain(msg: Any) -> Any:
    """An rclpy or rosbags message as nested dicts/lists of plain values, to compare the two."""
    if hasattr(msg, "get_fields_and_field_types"):
        return {name: _plain(getattr(msg, name)) for name in msg.get_fields_and_field_types()}
    if dataclasses.is_dataclass(msg):
        return {f.name: _plain(getattr(msg, f.name)) for f in dataclasses.fields(msg) if not f.name.startswith("__")}
    if isinstance(msg, (list, tuple)):
        return [_plain(item) for item in msg]
    return msg


def _two_transforms() -> Any:
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Quaternion, Transform, TransformStamped, Vector3
    from std_msgs.msg import Header

    tf_message = _tfmessage_class()
    return tf_message(transforms=[
        TransformStamped(header=Header(stamp=Time(sec=1_712_695_790, nanosec=531_351_240), frame_id="map"),
                         child_frame_id="odom",
                         transform=Transform(translation=Vector3(x=1.5, y=-2.25, z=0.125),
                                             rotation=Quaternion(x=0.0, y=0.0, z=0.38268343236, w=0.92387953251))),
        TransformStamped(header=Header(stamp=Time(sec=1_712_695_791, nanosec=7), frame_id="odom"),
                         child_frame_id="camera_rgb_optical_frame",
                         transform=Transform(translation=Vector3(x=-0.05, y=0.0, z=1e-9),
                                             rotation=Quaternion(x=-0.5, y=0.5, z=-0.5, w=0.5))),
    ])


def test_tfmessage_imports_and_matches_the_jazzy_definition() -> None:
    tf_message = _tfmessage_class()
    assert tf_message.get_fields_and_field_types() == {"transforms": "sequence<geometry_msgs/TransformStamped>"}
    assert TFMESSAGE in TYPESTORE.fielddefs
    _assert_same_definition(TFMESSAGE, set())


def test_tfmessage_published_and_received_in_process(make_node, executor) -> None:
    tf_message = _tfmessage_class()
    publisher_node = make_node("tf_publisher")
    subscriber_node = make_node("tf_subscriber")
    received: list[Any] = []
    subscriber_node.create_subscription(tf_message, "/tf", received.append, 10)
    publisher = publisher_node.create_publisher(tf_message, "/tf", 10)
    assert spin_until(executor, lambda: publisher.get_subscription_count() == 1, timeout_s=10.0)

    sent = _two_transforms()
    publisher.publish(sent)
    assert spin_until(executor, lambda: len(received) == 1, timeout_s=10.0)
    assert received[0] == sent
    assert [t.child_frame_id for t in received[0].transforms] == ["odom", "camera_rgb_optical_frame"]

    # The type hash Fast DDS announces for the topic is that of the upstream definition (what rosbag2 records).
    (info,) = publisher_node.get_publishers_info_by_topic("/tf")
    assert info.topic_type == TFMESSAGE
    assert _type_hash_string(info.topic_type_hash) == TYPESTORE.hash_rihs01(TFMESSAGE)


def test_cdr_bytes_are_those_rosbags_reads_and_writes() -> None:
    tf_message = _tfmessage_class()
    sent = _two_transforms()
    data = serialize_message(sent)
    decoded = TYPESTORE.deserialize_cdr(data, TFMESSAGE)
    assert _plain(decoded) == _plain(sent)
    assert decoded.transforms[1].transform.translation.z == 1e-9

    # ... and back: what rosbags writes into a bag, rclpy reads. (Messages are compared, not bytes: Fast CDR
    # need not zero the alignment padding.)
    written = bytes(TYPESTORE.serialize_cdr(decoded, TFMESSAGE))
    assert deserialize_message(written, tf_message) == sent
