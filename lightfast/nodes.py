"""The registry of lightfast's nodes and their configuration dataclasses.

Each node package adds one entry when it is built: ``node name -> "module:ConfigClass"``. ``lightfast config
write`` generates ``config/<node>.yaml`` from it, and a test checks the committed files are current.
"""
from __future__ import annotations

import importlib
from pathlib import Path

from lightfast.config import Config, config_yaml
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


def write_node_configs(directory: Path, *, check: bool = False) -> list[Path]:
    """Write (or with ``check`` only compare) every node's YAML; returns the files that were out of date."""
    stale = []
    for node in sorted(NODE_CONFIGS):
        path = directory / f"{node}.yaml"
        text = config_yaml(node_config_class(node), node_name=node)
        if not path.exists() or path.read_text() != text:
            stale.append(path)
            if not check:
                write_text_atomic(path, text)
    return stale
