"""ROS parameters generated from a configuration dataclass (see :mod:`lightfast.config`).

:func:`declare_config` declares one parameter per field with its description, bounds and read-only flag (a
section's fields as dotted parameters, ``stereo.max_features``, read-only when the section is), reads
the values (defaults, ``--ros-args -p``, or a ``--params-file`` made by ``lightfast config write``) and returns the
validated dataclass. :class:`ConfigParameters` also validates run-time changes: a ``ros2 param set`` that the
dataclass rejects is refused with the validation message, an accepted one updates :attr:`ConfigParameters.config`.
"""
from __future__ import annotations

import difflib
from collections.abc import Callable
from typing import Any, Generic, TypeVar

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from lightfast.config import Config, ConfigError, FieldSpec, config_from_mapping, leaf_specs, leaves, replace_config

C = TypeVar("C", bound=Config)

_ARRAY_TYPES = {
    bool: Parameter.Type.BOOL_ARRAY,
    int: Parameter.Type.INTEGER_ARRAY,
    float: Parameter.Type.DOUBLE_ARRAY,
    str: Parameter.Type.STRING_ARRAY,
}
_SCALAR_TYPES = {
    bool: Parameter.Type.BOOL,
    int: Parameter.Type.INTEGER,
    float: Parameter.Type.DOUBLE,
    str: Parameter.Type.STRING,
}


def _descriptor(spec: FieldSpec, read_only: bool = False) -> ParameterDescriptor:
    desc = ParameterDescriptor(description=spec.describe(), read_only=spec.read_only or read_only)
    if spec.choices is not None:
        desc.additional_constraints = "one of: " + ", ".join(map(str, spec.choices))
    lo, hi = spec.min, spec.max
    if lo is not None and hi is not None and spec.scalar_type is float and not spec.is_tuple:
        desc.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi))]
    elif lo is not None and hi is not None and spec.scalar_type is int and not spec.is_tuple:
        desc.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
    elif lo is not None or hi is not None:
        desc.additional_constraints = (desc.additional_constraints + "; " if desc.additional_constraints else "") + (
            f"range [{spec.min}, {spec.max}]"
        )
    return desc


def _from_ros(spec: FieldSpec, value: Any) -> Any:
    if spec.is_tuple:
        return () if value is None else tuple(value)
    return value


def declare_config(node: Node, cls: type[C]) -> C:
    """Declare the parameters of ``cls`` on ``node`` and return the validated configuration.

    Raises :class:`~lightfast.config.ConfigError` naming the parameter when a value is invalid.
    """
    values = {}
    for name, spec, value, read_only in leaves(cls()):
        default = list(value) if spec.is_tuple else value
        descriptor = _descriptor(spec, read_only)
        try:
            if spec.is_tuple and not default:
                # an empty list carries no type: declare the type explicitly
                param = node.declare_parameter(name, _ARRAY_TYPES[spec.scalar_type], descriptor)
            else:
                param = node.declare_parameter(name, default, descriptor)
        except InvalidParameterTypeException as exc:  # e.g. `-p period_s:=60` for a double: rclpy's traceback
            raise ConfigError(_type_message(node, name, spec, exc)) from None
        except InvalidParameterValueException as exc:  # outside the descriptor's range
            raise ConfigError(f"node {node.get_name()}: invalid parameter {name}: {exc}") from None
        values[name] = _from_ros(spec, param.value)
    try:
        return config_from_mapping(cls, values)
    except ConfigError as exc:
        raise ConfigError(f"node {node.get_name()}: invalid parameter: {exc}") from None


def _type_message(node: Node, name: str, spec: FieldSpec, exc: InvalidParameterTypeException) -> str:
    expected = _ARRAY_TYPES[spec.scalar_type] if spec.is_tuple else _SCALAR_TYPES[spec.scalar_type]
    message = f"node {node.get_name()}: parameter {name} must be of type {expected.name.lower()} ({exc.args[0]})"
    if expected in (Parameter.Type.DOUBLE, Parameter.Type.DOUBLE_ARRAY) and "INTEGER" in str(exc.args[0]):
        message += "; write a double with a decimal point, e.g. 60.0 instead of 60"
    return message


class ConfigParameters(Generic[C]):
    """A node's configuration kept in sync with its parameters; invalid changes are refused.

    ``on_change(new_config)`` (settable later too) runs after an accepted change.
    """

    def __init__(self, node: Node, cls: type[C], *, on_change: Callable[[C], None] | None = None) -> None:
        self.node = node
        self.cls = cls
        try:
            self.config: C = declare_config(node, cls)
        except ConfigError as exc:  # a misspelt name is the likeliest cause of a missing or wrong value: say so
            unknown = "; ".join(_unknown_text(n, c) for n, c in unknown_parameters(node).items())
            raise ConfigError(f"{exc}" + (f" ({unknown})" if unknown else "")) from None
        report_unknown_parameters(node)
        self._specs = dict(leaf_specs(cls))
        self.on_change = on_change
        node.add_on_set_parameters_callback(self._validate)
        node.add_post_set_parameters_callback(self._apply)

    def _candidate(self, params: list[Parameter]) -> C:
        changes = {p.name: _from_ros(self._specs[p.name], p.value) for p in params if p.name in self._specs}
        return replace_config(self.config, changes)

    def _validate(self, params: list[Parameter]) -> SetParametersResult:
        try:
            self._candidate(params)
        except (ConfigError, TypeError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply(self, params: list[Parameter]) -> None:
        self.config = self._candidate(params)
        if self.on_change is not None:
            self.on_change(self.config)


#: Parameters rclpy or ROS tooling may set on any node without the node declaring them.
_FOREIGN_PREFIXES = ("qos_overrides.", "start_type_description_service")


def unknown_parameters(node: Node) -> dict[str, str | None]:
    """Parameters given to ``node`` (``-p``, ``--params-file``) that it did not declare, each with the closest
    declared name (or ``None``). Reads rclpy's override table: rclpy has no public call for it."""
    overrides = getattr(node, "_parameter_overrides", {})
    declared = sorted(node._parameters) if hasattr(node, "_parameters") else []
    return {
        name: next(iter(difflib.get_close_matches(name, declared, n=1, cutoff=0.6)), None)
        for name in sorted(overrides)
        if name not in declared and not name.startswith(_FOREIGN_PREFIXES)
    }


def _unknown_text(name: str, closest: str | None) -> str:
    return f"unknown parameter '{name}' ignored" + (f"; did you mean '{closest}'?" if closest else "")


def report_unknown_parameters(node: Node) -> None:
    """Log one warning per parameter the node does not know, naming the closest known one. (A warning, not an
    error: a ``/**`` section of a parameter file shared by several nodes holds the others' parameters too.)"""
    for name, closest in unknown_parameters(node).items():
        node.get_logger().warning(f"{_unknown_text(name, closest)} (all of this node's parameters: "
                                  f"config/{node.get_name()}.yaml)")
