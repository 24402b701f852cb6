"""Configuration: one frozen dataclass per component is the single source of truth.

A component declares its options with :func:`param` (default, description, bounds or choices), derives from
:class:`Config`, and gets validation on construction. The same dataclass generates the node's ROS parameters
(:mod:`lightfast.ros.params`) and its ``config/<node>.yaml`` (:func:`config_yaml`), and loads YAML files
(:func:`load_config_yaml`, ``yaml.safe_load`` only).

Supported field types: ``bool``, ``int``, ``float``, ``str`` and tuples of one of them (``tuple[float, ...]``),
the types a ROS parameter can hold.

Example::

    @dataclass(frozen=True)
    class ChunkConfig(Config):
        chunk_size: int = param(20000, description="Vertices per chunk.", min=1)
        mode: str = param("fast", description="Solver.", choices=("fast", "exact"))
"""
from __future__ import annotations

import dataclasses
import math
import os
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

import yaml

from lightfast.errors import LightfastError

C = TypeVar("C", bound="Config")
SCALAR_TYPES = (bool, int, float, str)


class ConfigError(LightfastError, ValueError):
    """A configuration value is missing, of the wrong type, out of range, or unknown."""


def param(
    default: Any,
    *,
    description: str,
    min: float | None = None,
    max: float | None = None,
    choices: tuple[Any, ...] | None = None,
    read_only: bool = False,
) -> Any:
    """Declare a configuration field: its default, a one-line description and its valid values.

    ``min``/``max`` are inclusive bounds for numbers (and for each element of a numeric tuple); ``choices`` lists
    the allowed values; ``read_only`` marks parameters that cannot change while a node runs.
    """
    if not description:
        raise ConfigError("every configuration field needs a description")
    meta = {"description": description, "min": min, "max": max, "choices": choices, "read_only": read_only}
    return dataclasses.field(default=default, metadata=meta)


@dataclasses.dataclass(frozen=True)
class FieldSpec:
    """What a configuration field accepts, resolved from its dataclass annotation and :func:`param` metadata."""

    name: str
    scalar_type: type
    is_tuple: bool
    default: Any
    description: str
    min: float | None
    max: float | None
    choices: tuple[Any, ...] | None
    read_only: bool

    def describe(self) -> str:
        """The description with the valid values appended, e.g. ``"Chunk size. [1, 100000]"``."""
        text = self.description
        if self.choices is not None:
            text += " One of: " + ", ".join(map(str, self.choices)) + "."
        if self.min is not None or self.max is not None:
            lo = "-inf" if self.min is None else f"{self.min:g}"
            hi = "inf" if self.max is None else f"{self.max:g}"
            text += f" Range [{lo}, {hi}]."
        return text


def _resolve(annotation: Any, owner: type, name: str) -> tuple[type, bool]:
    if annotation in SCALAR_TYPES:
        return annotation, False
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis and args[0] in SCALAR_TYPES:
        return args[0], True
    raise ConfigError(f"{owner.__name__}.{name}: unsupported configuration type {annotation!r}")


def field_specs(cls_or_instance: type[Config] | Config) -> tuple[FieldSpec, ...]:
    """The :class:`FieldSpec` of every field of a configuration dataclass, in declaration order."""
    cls = cls_or_instance if isinstance(cls_or_instance, type) else type(cls_or_instance)
    hints = typing.get_type_hints(cls)
    specs = []
    for f in dataclasses.fields(cls):
        scalar_type, is_tuple = _resolve(hints[f.name], cls, f.name)
        meta = f.metadata
        if "description" not in meta:
            raise ConfigError(f"{cls.__name__}.{f.name}: declare configuration fields with lightfast.config.param")
        specs.append(
            FieldSpec(
                name=f.name,
                scalar_type=scalar_type,
                is_tuple=is_tuple,
                default=f.default,
                description=meta["description"],
                min=meta["min"],
                max=meta["max"],
                choices=meta["choices"],
                read_only=meta["read_only"],
            )
        )
    return tuple(specs)


def _coerce_scalar(spec: FieldSpec, value: Any, where: str) -> Any:
    t = spec.scalar_type
    if t is bool:
        if isinstance(value, bool):
            return value
    elif t is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif t is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = float(value)
            if math.isnan(value):
                raise ConfigError(f"{where} must be a number, got NaN")
            return value
    elif t is str:
        if isinstance(value, str):
            return value
    raise ConfigError(f"{where} must be {t.__name__}, got {type(value).__name__} {value!r}")


def _check_value(spec: FieldSpec, value: Any, where: str) -> Any:
    value = _coerce_scalar(spec, value, where)
    if spec.choices is not None and value not in spec.choices:
        raise ConfigError(f"{where}={value!r} is not one of {list(spec.choices)}")
    if spec.min is not None and value < spec.min:
        raise ConfigError(f"{where}={value!r} is below its minimum {spec.min}")
    if spec.max is not None and value > spec.max:
        raise ConfigError(f"{where}={value!r} is above its maximum {spec.max}")
    return value


def coerce_field(spec: FieldSpec, value: Any, *, owner: str = "") -> Any:
    """Check and convert one value for ``spec`` (ints become floats for float fields, lists become tuples)."""
    where = f"{owner}.{spec.name}" if owner else spec.name
    if spec.is_tuple:
        if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where} must be a list of {spec.scalar_type.__name__}, got {value!r}")
        return tuple(_check_value(spec, v, f"{where}[{i}]") for i, v in enumerate(value))
    return _check_value(spec, value, where)


class Config:
    """Base of configuration dataclasses: validates every field on construction.

    Subclasses are ``@dataclass(frozen=True)`` with fields declared by :func:`param`; they may override
    :meth:`check` for rules that involve several fields (raise :class:`ConfigError`).
    """

    def __post_init__(self) -> None:
        name = type(self).__name__
        for spec in field_specs(self):
            object.__setattr__(self, spec.name, coerce_field(spec, getattr(self, spec.name), owner=name))
        self.check()

    def check(self) -> None:
        """Cross-field validation hook."""

    def to_dict(self) -> dict[str, Any]:
        """Plain values (tuples as lists), ready for YAML or ROS parameters."""
        return {s.name: list(v) if s.is_tuple else v for s in field_specs(self) for v in [getattr(self, s.name)]}


def config_from_mapping(cls: type[C], values: Mapping[str, Any], *, allow_unknown: bool = False) -> C:
    """Build ``cls`` from a mapping; unknown keys are an error unless ``allow_unknown``."""
    known = {s.name for s in field_specs(cls)}
    unknown = sorted(set(values) - known)
    if unknown and not allow_unknown:
        raise ConfigError(
            f"unknown {cls.__name__} parameter(s): {', '.join(unknown)} (known: {', '.join(sorted(known))})"
        )
    return cls(**{k: v for k, v in values.items() if k in known})


def _yaml_scalar(value: Any) -> str:
    """A value as YAML that rcl's parameter parser reads back with the same type: strings are always quoted (rcl
    reads a plain ``y``, ``n``, ``on`` or ``off`` as a bool, ``1`` as an integer)."""
    if isinstance(value, str):
        return "'" + value.replace("'", "''") + "'"
    if isinstance(value, list):
        return "[" + ", ".join(_yaml_scalar(v) for v in value) + "]"
    return yaml.safe_dump(value, default_flow_style=True, width=10_000).strip().removesuffix("...").strip()


def config_yaml(cls_or_instance: type[Config] | Config, *, node_name: str) -> str:
    """The ``config/<node>.yaml`` text for a configuration: ``/**: ros__parameters:`` with one commented key per
    field, its description and valid values. Values are the instance's, or the defaults for a class.
    """
    cls = cls_or_instance if isinstance(cls_or_instance, type) else type(cls_or_instance)
    instance = cls_or_instance if not isinstance(cls_or_instance, type) else cls()
    lines = [
        f"# Parameters of {node_name}.",
        f"# Generated from {cls.__module__}.{cls.__qualname__} by `lightfast config write`; edit the dataclass,",
        "# not this file. Use with: ros2 run lightfast " + node_name + " --ros-args --params-file <this file>",
        "/**:",
        "  ros__parameters:",
    ]
    for spec in field_specs(cls):
        lines.append(f"    # {spec.describe()}" + (" (read-only at run time)" if spec.read_only else ""))
        value = getattr(instance, spec.name)
        lines.append(f"    {spec.name}: {_yaml_scalar(list(value) if spec.is_tuple else value)}")
    return "\n".join(lines) + "\n"


def load_config_yaml(cls: type[C], path: str | os.PathLike[str], *, node_name: str | None = None) -> C:
    """Load a ROS parameter file (``/**`` or ``<node_name>`` section, ``ros__parameters``) into ``cls``."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"no parameter file at {path}") from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ConfigError(f"{path} is not valid YAML: {' '.join(str(exc).split())}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping with a '/**' or node section")
    section = None
    for key in ([node_name, f"/{node_name}"] if node_name else []) + ["/**"]:
        if key in data:
            section = data[key]
            break
    if not isinstance(section, dict) or not isinstance(section.get("ros__parameters"), dict):
        raise ConfigError(f"{path}: no 'ros__parameters' under '/**'" + (f" or '{node_name}'" if node_name else ""))
    try:
        return config_from_mapping(cls, section["ros__parameters"])
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None

