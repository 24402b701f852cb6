"""Configuration: one frozen dataclass per component is the single source of truth.

A component declares its options with :func:`param` (default, description, bounds or choices), derives from
:class:`Config`, and gets validation on construction. The same dataclass generates the node's ROS parameters
(:mod:`lightfast.ros.params`) and its ``config/<node>.yaml`` (:func:`config_yaml`), and loads YAML files
(:func:`load_config_yaml`, ``yaml.safe_load`` only).

Supported field types: ``bool``, ``int``, ``float``, ``str`` and tuples of one of them (``tuple[float, ...]``),
the types a ROS parameter can hold; and another :class:`Config` (a *section*): a node's configuration composes the
configurations of the core components it runs instead of copying their fields. A section's fields become dotted
ROS parameters (``stereo.max_features``) and a nested mapping in YAML; its default is the instance given to
:func:`param` (which may differ from the section class's own defaults).

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
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple, TypeVar

import yaml

from lightfast.errors import ConfigError as ConfigError  # re-exported: lightfast.config.ConfigError

C = TypeVar("C", bound="Config")
SCALAR_TYPES = (bool, int, float, str)


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

    @property
    def is_section(self) -> bool:
        """The field holds another configuration (a section of dotted parameters)."""
        return isinstance(self.scalar_type, type) and issubclass(self.scalar_type, Config)

    @property
    def choices_text(self) -> str:
        """The allowed values, e.g. ``"a, b"`` (empty: any)."""
        return "" if self.choices is None else ", ".join(map(str, self.choices))

    @property
    def range_text(self) -> str:
        """The inclusive bounds, e.g. ``"[1, inf]"`` (empty: none)."""
        if self.min is None and self.max is None:
            return ""
        return f"[{'-inf' if self.min is None else f'{self.min:g}'}, {'inf' if self.max is None else f'{self.max:g}'}]"

    def describe(self) -> str:
        """The description with the valid values appended, e.g. ``"Chunk size. Range [1, 100000]."``."""
        text = self.description
        if self.choices_text:
            text += f" One of: {self.choices_text}."
        if self.range_text:
            text += f" Range {self.range_text}."
        return text


def _resolve(annotation: Any, owner: type, name: str) -> tuple[type, bool]:
    if annotation in SCALAR_TYPES or (isinstance(annotation, type) and issubclass(annotation, Config)):
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
    """Check and convert one value for ``spec`` (ints become floats for float fields, lists become tuples, a
    mapping becomes a section laid over the field's default)."""
    where = f"{owner}.{spec.name}" if owner else spec.name
    if spec.is_section:
        if isinstance(value, spec.scalar_type):
            return value
        if isinstance(value, Mapping):
            return replace_config(spec.default, value)
        raise ConfigError(f"{where} must be a {spec.scalar_type.__name__} or a mapping of its fields, got {value!r}")
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

    if TYPE_CHECKING:  # every concrete subclass is a dataclass; tells the type checker so (no runtime attribute)
        __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]

    def __post_init__(self) -> None:
        name = type(self).__name__
        for spec in field_specs(self):
            object.__setattr__(self, spec.name, coerce_field(spec, getattr(self, spec.name), owner=name))
        self.check()

    def check(self) -> None:
        """Cross-field validation hook."""

    def to_dict(self) -> dict[str, Any]:
        """Plain values (tuples as lists, sections as nested dicts), ready for YAML or ROS parameters."""
        def plain(spec: FieldSpec, v: Any) -> Any:
            return v.to_dict() if spec.is_section else list(v) if spec.is_tuple else v
        return {s.name: plain(s, getattr(self, s.name)) for s in field_specs(self)}


class Leaf(NamedTuple):
    """A non-section field of a configuration: dotted name, spec, value, and whether it (or a section holding it)
    is read-only at run time."""

    name: str
    spec: FieldSpec
    value: Any
    read_only: bool


def leaves(config: Config) -> list[Leaf]:
    """Every non-section field of ``config``, sections flattened, in declaration order."""
    out: list[Leaf] = []

    def walk(c: Config, prefix: str, read_only: bool) -> None:
        for spec in field_specs(c):
            value = getattr(c, spec.name)
            if spec.is_section:
                walk(value, f"{prefix}{spec.name}.", read_only or spec.read_only)
            else:
                out.append(Leaf(prefix + spec.name, spec, value, read_only or spec.read_only))

    walk(config, "", False)
    return out


def leaf_specs(cls: type[Config]) -> list[tuple[str, FieldSpec]]:
    """``(dotted name, spec)`` of every non-section field of ``cls``."""
    return [(leaf.name, leaf.spec) for leaf in leaves(cls())]


def leaf_values(config: Config) -> dict[str, Any]:
    """``{dotted name: value}`` of every non-section field of ``config``."""
    return {leaf.name: leaf.value for leaf in leaves(config)}


def _split(cls: type[Config], values: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, dict[str, Any]],
                                                                 list[str]]:
    """``values`` (plain keys, dotted keys ``section.field`` or nested mappings) as the values of ``cls``'s own
    fields, the mappings per section, and the keys ``cls`` does not know."""
    if not isinstance(values, Mapping):
        raise ConfigError(f"{cls.__name__} needs a mapping of its fields, got {type(values).__name__} {values!r}")
    specs = {s.name: s for s in field_specs(cls)}
    own: dict[str, Any] = {}
    sections: dict[str, dict[str, Any]] = {}
    unknown: list[str] = []
    for key, value in values.items():
        head, dot, rest = str(key).partition(".")
        spec = specs.get(head)
        if spec is None or (dot and not spec.is_section):
            unknown.append(str(key))
        elif dot:
            sections.setdefault(head, {})[rest] = value
        elif spec.is_section and isinstance(value, Mapping):
            sections.setdefault(head, {}).update(value)
        else:
            own[head] = value
    return own, sections, unknown


def _check_known(cls: type[Config], values: Mapping[str, Any]) -> None:
    """Raise naming every key of ``values`` (dotted, at any depth) that ``cls`` does not have."""
    def unknown_keys(config_cls: type[Config], mapping: Mapping[str, Any], prefix: str) -> list[str]:
        _, sections, unknown = _split(config_cls, mapping)
        specs = {s.name: s for s in field_specs(config_cls)}
        out = [prefix + key for key in unknown]
        for head, sub in sections.items():
            out += unknown_keys(specs[head].scalar_type, sub, f"{prefix}{head}.")
        return out

    unknown = unknown_keys(cls, values, "")
    if unknown:
        known = ", ".join(name for name, _ in leaf_specs(cls))
        raise ConfigError(f"unknown {cls.__name__} parameter(s): {', '.join(sorted(unknown))} (known: {known})")


def replace_config(config: C, values: Mapping[str, Any], *, allow_unknown: bool = False) -> C:
    """``config`` with the fields in ``values`` changed (plain, dotted or nested keys; a section's fields are laid
    over its current value); validated like a new instance."""
    if not allow_unknown:
        _check_known(type(config), values)
    own, sections, _ = _split(type(config), values)
    for head, mapping in sections.items():
        own[head] = replace_config(own.get(head, getattr(config, head)), mapping, allow_unknown=True)
    return dataclasses.replace(config, **own) if own else config


def config_from_mapping(cls: type[C], values: Mapping[str, Any], *, allow_unknown: bool = False) -> C:
    """Build ``cls`` from a mapping (plain, dotted or nested keys; a section's fields are laid over the section's
    default); unknown keys are an error unless ``allow_unknown``."""
    if not allow_unknown:
        _check_known(cls, values)
    own, sections, _ = _split(cls, values)
    defaults = {s.name: s.default for s in field_specs(cls)}
    for head, mapping in sections.items():
        start = own.get(head, defaults[head])
        if not isinstance(start, Config):
            raise ConfigError(f"{cls.__name__}.{head} must be a mapping of its fields, got {start!r}")
        own[head] = replace_config(start, mapping, allow_unknown=True)
    return cls(**own)


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
    lines += _yaml_fields(instance, indent="    ")
    return "\n".join(lines) + "\n"


def _yaml_fields(config: Config, *, indent: str) -> list[str]:
    lines = []
    for spec in field_specs(config):
        lines.append(f"{indent}# {spec.describe()}" + (" (read-only at run time)" if spec.read_only else ""))
        value = getattr(config, spec.name)
        if spec.is_section:
            lines.append(f"{indent}{spec.name}:")
            lines += _yaml_fields(value, indent=indent + "  ")
        else:
            lines.append(f"{indent}{spec.name}: {_yaml_scalar(list(value) if spec.is_tuple else value)}")
    return lines


def config_markdown(cls: type[Config]) -> str:
    """A markdown table of every parameter of ``cls`` (sections as dotted names): name, type, default, valid
    values, whether it can change at run time, description."""
    rows = ["| parameter | type | default | valid values | at run time | description |", "|---|---|---|---|---|---|"]
    for leaf in leaves(cls()):
        spec = leaf.spec
        kind = f"{spec.scalar_type.__name__}[]" if spec.is_tuple else spec.scalar_type.__name__
        valid = "; ".join(filter(None, (spec.choices_text, spec.range_text)))
        default = _yaml_scalar(list(leaf.value) if spec.is_tuple else leaf.value)
        text = spec.description.replace("|", "\\|")
        rows.append(f"| `{leaf.name}` | {kind} | `{default}` | {valid} | {'read-only' if leaf.read_only else 'yes'} "
                    f"| {text} |")
    return "\n".join(rows) + "\n"


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

