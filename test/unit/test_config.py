from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from lightfast.config import (
    Config,
    ConfigError,
    config_from_mapping,
    config_yaml,
    field_specs,
    leaf_specs,
    leaf_values,
    load_config_yaml,
    param,
    replace_config,
)
from lightfast.io import write_text_atomic
from lightfast.nodes import NODE_CONFIGS, node_config_class


@dataclass(frozen=True)
class SampleConfig(Config):
    chunk_size: int = param(2000, description="Vertices per chunk.", min=1, max=10**6)
    period_s: float = param(1.0, description="Update period in seconds.", min=0.0)
    mode: str = param("fast", description="Solver.", choices=("fast", "exact"))
    enabled: bool = param(True, description="Run at all.")
    weights: tuple[float, ...] = param((1.0, 2.0), description="Per-channel weights.", min=0.0)
    names: tuple[str, ...] = param((), description="Topic names.", read_only=True)

    def check(self) -> None:
        if self.mode == "exact" and self.chunk_size > 1000:
            raise ConfigError("mode=exact needs chunk_size <= 1000")


def test_defaults_and_coercion() -> None:
    cfg = SampleConfig(period_s=2, weights=[3, 4])  # type: ignore[arg-type]
    assert cfg.period_s == 2.0 and isinstance(cfg.period_s, float)
    assert cfg.weights == (3.0, 4.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"chunk_size": 0}, "chunk_size=0 is below its minimum 1"),
        ({"chunk_size": 1.5}, "chunk_size must be int"),
        ({"enabled": 1}, "enabled must be bool"),
        ({"mode": "slow"}, "mode='slow' is not one of"),
        ({"period_s": float("nan")}, "period_s must be a number"),
        ({"weights": (1.0, -1.0)}, r"weights\[1\]=-1.0 is below"),
        ({"weights": "1,2"}, "weights must be a list of float"),
        ({"mode": "exact"}, "mode=exact needs chunk_size <= 1000"),
    ],
)
def test_invalid_values_name_the_field(kwargs: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        SampleConfig(**kwargs)


def test_unknown_keys_are_refused() -> None:
    with pytest.raises(ConfigError, match="unknown SampleConfig parameter"):
        config_from_mapping(SampleConfig, {"chunksize": 3})


def test_yaml_round_trip(tmp_path) -> None:
    cfg = SampleConfig(chunk_size=500, mode="exact", weights=(0.5,), names=("/a", "/b"))
    text = config_yaml(cfg, node_name="sample_node")
    data = yaml.safe_load(text)
    assert data["/**"]["ros__parameters"]["chunk_size"] == 500
    assert "# Vertices per chunk. Range [1, 1e+06]." in text
    assert "(read-only at run time)" in text
    path = tmp_path / "sample_node.yaml"
    write_text_atomic(path, text)
    assert load_config_yaml(SampleConfig, path) == cfg
    assert config_yaml(SampleConfig, node_name="x") == config_yaml(SampleConfig(), node_name="x")


def test_load_reports_bad_files(tmp_path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text("/**:\n  ros__parameters:\n    chunk_size: -3\n")
    with pytest.raises(ConfigError, match=r"bad.yaml: .*chunk_size=-3 is below"):
        load_config_yaml(SampleConfig, path)
    path.write_text("a: [\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config_yaml(SampleConfig, path)
    with pytest.raises(ConfigError, match="no parameter file"):
        load_config_yaml(SampleConfig, tmp_path / "missing.yaml")


def test_fields_need_param() -> None:
    @dataclass(frozen=True)
    class Bad(Config):
        x: int = 3

    with pytest.raises(ConfigError, match=r"declare configuration fields with lightfast\.config\.param"):
        Bad()
    assert [s.name for s in field_specs(SampleConfig)][:2] == ["chunk_size", "period_s"]


def test_committed_node_parameter_files_are_current() -> None:
    """config/<node>.yaml and docs/parameters.md are generated from the config dataclasses (`lightfast config
    write`)."""
    from pathlib import Path

    from lightfast.nodes import NODE_CONFIGS, write_node_configs

    root = Path(__file__).resolve().parents[2]
    config_dir = root / "config"
    assert write_node_configs(config_dir, docs_path=root / "docs" / "parameters.md", check=True) == []
    assert sorted(p.stem for p in config_dir.glob("*.yaml")) == sorted(NODE_CONFIGS)


# --- sections: configurations inside configurations ---------------------------------------------------------------

@dataclass(frozen=True)
class InnerConfig(Config):
    size: int = param(10, description="Size.", min=1)
    names: tuple[str, ...] = param(("a",), description="Names.")


_INNER = InnerConfig(size=20)


@dataclass(frozen=True)
class OuterConfig(Config):
    gain: float = param(0.5, description="Gain.")
    inner: InnerConfig = param(_INNER, description="The inner component.")


def test_a_section_defaults_to_the_given_instance_and_takes_dotted_or_nested_keys() -> None:
    assert OuterConfig().inner == InnerConfig(size=20)  # the node's default, not InnerConfig()'s
    dotted = config_from_mapping(OuterConfig, {"inner.names": ["x", "y"]})
    assert dotted.inner == InnerConfig(size=20, names=("x", "y"))  # laid over the section's default
    nested = config_from_mapping(OuterConfig, {"gain": 1.0, "inner": {"size": 3}})
    assert nested == OuterConfig(gain=1.0, inner=InnerConfig(size=3))
    assert replace_config(nested, {"inner.size": 4}).inner == InnerConfig(size=4)
    assert nested.to_dict() == {"gain": 1.0, "inner": {"size": 3, "names": ["a"]}}
    assert leaf_values(nested) == {"gain": 1.0, "inner.size": 3, "inner.names": ("a",)}
    assert [name for name, _ in leaf_specs(OuterConfig)] == ["gain", "inner.size", "inner.names"]
    with pytest.raises(ConfigError, match=r"InnerConfig\.size=0 is below its minimum"):
        config_from_mapping(OuterConfig, {"inner.size": 0})
    with pytest.raises(ConfigError, match=r"unknown OuterConfig parameter\(s\): inner\.sise .*inner\.size"):
        config_from_mapping(OuterConfig, {"inner.sise": 3})
    with pytest.raises(ConfigError, match="unknown"):
        config_from_mapping(OuterConfig, {"gain.x": 3})
    with pytest.raises(ConfigError, match="must be a InnerConfig or a mapping"):
        OuterConfig(inner=3)  # type: ignore[arg-type]


def test_a_section_is_a_nested_mapping_in_the_yaml(tmp_path: Path) -> None:
    text = config_yaml(OuterConfig, node_name="demo_node")
    assert "    inner:\n      # Size. Range [1, inf].\n      size: 20\n" in text
    path = tmp_path / "demo.yaml"
    path.write_text(text.replace("size: 20", "size: 7"))
    assert load_config_yaml(OuterConfig, path) == OuterConfig(inner=InnerConfig(size=7))


@pytest.mark.parametrize("node", sorted(NODE_CONFIGS))
def test_a_node_configuration_keeps_the_core_defaults(node: str) -> None:
    """A node's sections default to their component's own defaults: a node runs the core as the core is tested
    (the copies of fields this replaced had their defaults repeated as literals, and nothing pinned them)."""
    cls = node_config_class(node)
    for spec in field_specs(cls):
        if spec.is_section:
            assert spec.default == spec.scalar_type(), f"{node}: section {spec.name} does not keep the defaults"
