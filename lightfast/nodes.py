"""The registry of lightfast's nodes and their configuration dataclasses.

Each node package adds one entry when it is built: ``node name -> "module:ConfigClass"``. ``lightfast config
write`` generates ``config/<node>.yaml`` from it, and a test checks the committed files are current.
"""
from __future__ import annotations

import importlib
from pathlib import Path

from lightfast.config import Config, config_markdown, config_yaml
from lightfast.io import write_text_atomic

NODE_CONFIGS: dict[str, str] = {
    "sun_update_node": "lightfast.daylight.sun_update:SunUpdateConfig",
    "daylight_relight_node": "lightfast.daylight.relight:RelightConfig",
    "rgbd_tracker_node": "lightfast.tracking.pipeline:TrackerConfig",
    "vtr_localizer_node": "lightfast.vtr.localizer_config:VtrLocalizerConfig",
    "racr_node": "lightfast.racr.node_config:RacrNodeConfig",
    "racr_platform_sim_node": "lightfast.sim.racr_live:RacrPlatformSimConfig",
    "racr_vse_node": "lightfast.sim.racr_live:RacrVseSimConfig",
}


def node_config_class(node_name: str) -> type[Config]:
    module, _, cls = NODE_CONFIGS[node_name].partition(":")
    return getattr(importlib.import_module(module), cls)


def parameters_markdown() -> str:
    """``docs/parameters.md``: every node's parameters, generated from the configuration dataclasses."""
    parts = ["# Node parameters", "",
             "Generated from the nodes' configuration dataclasses by `lightfast config write` (like `config/*.yaml`);",
             "edit the dataclasses, not this file. A section's fields are dotted parameters (`-p repeat.mode:=grey`).",
             ""]
    for node in sorted(NODE_CONFIGS):
        cls = node_config_class(node)
        parts += [f"## `{node}`", "", f"From `{cls.__module__}.{cls.__qualname__}`.", "", config_markdown(cls)]
    return "\n".join(parts)


def write_node_configs(directory: Path, *, docs_path: Path | None = None, check: bool = False) -> list[Path]:
    """Write (or with ``check`` only compare) every node's YAML in ``directory`` and, with ``docs_path``, the
    parameter reference; returns the files that were out of date."""
    files = {directory / f"{node}.yaml": config_yaml(node_config_class(node), node_name=node)
             for node in sorted(NODE_CONFIGS)}
    if docs_path is not None:
        files[docs_path] = parameters_markdown()
    stale = []
    for path, text in files.items():
        if not path.exists() or path.read_text() != text:
            stale.append(path)
            if not check:
                write_text_atomic(path, text)
    return stale
