"""The documentation keeps up with the code: a short README, every topic and every node parameter documented in
docs/, and no link to a file that does not exist."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

import lightfast.topics as topics
from lightfast.config import leaf_specs
from lightfast.nodes import NODE_CONFIGS, node_config_class

ROOT = Path(__file__).resolve().parents[2]
DOCS = sorted((ROOT / "docs").glob("*.md"))


def docs_text() -> str:
    return "\n".join(p.read_text() for p in DOCS)


def test_the_readme_is_short() -> None:
    assert (ROOT / "README.md").stat().st_size <= 10_240


def test_every_topic_and_frame_name_is_documented() -> None:
    text = docs_text()
    names = {k: v for k, v in vars(topics).items() if k.isupper() and isinstance(v, str)}
    assert names, "lightfast.topics defines no names"
    missing = sorted(f"{k} = {v!r}" for k, v in names.items() if v not in text)
    assert not missing, f"not in docs/*.md: {missing}"


@pytest.mark.parametrize("node", sorted(NODE_CONFIGS))
def test_every_node_parameter_is_documented(node: str) -> None:
    text = docs_text()
    missing = [name for name, _ in leaf_specs(node_config_class(node)) if f"`{name}`" not in text]
    assert not missing, f"{node}: parameters not in docs/*.md: {missing}"


@pytest.mark.parametrize("page", [ROOT / "README.md", *DOCS], ids=lambda p: p.name)
def test_relative_links_point_to_files_that_exist(page: Path) -> None:
    broken = []
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
        if "://" in target or target.startswith("mailto:"):
            continue
        if not (page.parent / target).exists():
            broken.append(target)
    assert not broken, f"{page.name}: links to missing files: {broken}"
