"""Errors of :mod:`lightfast.ros` and the node packages' helpers: every one is a :class:`RosError`, and an
:class:`~lightfast.errors.InputError` (a message, file, host or interface that cannot be used) or an
:class:`~lightfast.errors.InternalError` (a step that failed: nodes not up in time, no free domain id).

Importing this module does not import rclpy.
"""
from __future__ import annotations

from lightfast.errors import InputError, InternalError, LightfastError

__all__ = [
    "CameraInfoError",
    "ConversionError",
    "DomainExhaustedError",
    "ImageConversionError",
    "NotReadyError",
    "PointCloudConversionError",
    "PoseConversionError",
    "RosError",
    "ToolError",
    "TransportError",
]


class RosError(LightfastError):
    """Root of the errors of :mod:`lightfast.ros`."""


# --- message conversions (lightfast.ros.convert) --------------------------------------------------------------

class ConversionError(RosError, InputError, ValueError):
    """A message cannot be converted (malformed or unsupported); the message names the offending field."""


class ImageConversionError(ConversionError):
    """A malformed or unsupported ``sensor_msgs/Image`` or image array."""


class PointCloudConversionError(ConversionError):
    """A malformed or unsupported ``sensor_msgs/PointCloud2`` or point array."""


class PoseConversionError(ConversionError):
    """A non-unit quaternion, a matrix that is not a rigid transform, or a badly shaped pose array."""


class CameraInfoError(ConversionError):
    """A ``sensor_msgs/CameraInfo`` that :class:`~lightfast.camera.PinholeCamera` cannot represent."""


# --- DDS transport (lightfast.ros.transport) -------------------------------------------------------------------

class TransportError(RosError, InputError):
    """A host, interface or address given for the network transport cannot be used (not IPv4, not unicast,
    malformed, too many peers)."""


# --- test isolation and readiness (lightfast.ros.domain, lightfast.ros.ready) ----------------------------------

class DomainExhaustedError(RosError, InternalError):
    """Every domain id in the range is held by another process (:func:`lightfast.ros.domain.reserve_domain_id`)."""


class NotReadyError(RosError, InternalError):
    """Nodes did not announce themselves in time, or a watched process ended first
    (:func:`lightfast.ros.ready.wait_ready`)."""


# --- script helpers (lightfast.ros.racr_tools, lightfast.ros.vtr_tools) ----------------------------------------

class ToolError(RosError, InternalError):
    """A script helper (``lightfast racr …``, ``lightfast vtr …``) could not do its job: a run that did not
    converge or become idle in time, a node that stopped or exited, a failed service call, a recording that
    cannot be scored."""
