"""Modules cut along concepts (issue 20): no Python module of ``lightfast/`` or a node package over
``MAX_MODULE_LINES`` lines unless its docstring states why (a paragraph starting ``Kept in one module:``), every
``node.py`` at most ``MAX_NODE_LINES`` lines of wiring, and module docstrings short (paper section, equations,
inputs and outputs; measurements live in ``benchmarks/results/``)."""
from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MAX_MODULE_LINES = 600
MAX_NODE_LINES = 250
MAX_DOCSTRING_LINES = 30
REASON = "Kept in one module:"


def _modules() -> Iterator[Path]:
    yield from sorted((ROOT / "lightfast").rglob("*.py"))
    for package in sorted(p.parent for p in ROOT.glob("*_node/node.py")):
        yield from sorted(package.rglob("*.py"))


def _lines(path: Path) -> int:
    return len(path.read_text().splitlines())


def _docstring(path: Path) -> str:
    return ast.get_docstring(ast.parse(path.read_text(), filename=str(path)), clean=False) or ""


def test_modules_are_short_or_say_why() -> None:
    long = [f"{p.relative_to(ROOT)}: {_lines(p)} lines" for p in _modules()
            if _lines(p) > MAX_MODULE_LINES and REASON not in _docstring(p)]
    assert long == []


def test_nodes_only_wire() -> None:
    fat = [f"{p.relative_to(ROOT)}: {_lines(p)} lines" for p in sorted(ROOT.glob("*_node/node.py"))
           if _lines(p) > MAX_NODE_LINES]
    assert fat == []


def test_module_docstrings_are_short() -> None:
    wordy = [f"{p.relative_to(ROOT)}: {_docstring(p).count(chr(10)) + 1} lines" for p in _modules()
             if _docstring(p).count("\n") + 1 > MAX_DOCSTRING_LINES]
    assert wordy == []


def test_every_module_has_a_docstring() -> None:
    bare = [str(p.relative_to(ROOT)) for p in _modules() if p.name != "__init__.py" and not _docstring(p).strip()]
    assert bare == []
