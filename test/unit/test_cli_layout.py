"""The command line lives in one place: argparse only in ``lightfast/cli/`` (and the benchmark and setup scripts),
one module per command group, every subcommand parses its own options, and ``lightfast --help`` loads no rclpy."""
from __future__ import annotations

import ast
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from lightfast import cli

ROOT = Path(__file__).resolve().parents[2]
#: Where argparse may be imported: the CLI package and the stand-alone scripts.
ARGPARSE_ALLOWED = (ROOT / "lightfast" / "cli", ROOT / "benchmarks", ROOT / "scripts")
REMAINDER = "..."  # argparse.REMAINDER (this test, too, does without argparse)


def _python_files() -> Iterator[Path]:
    """Every .py file of the repository outside hidden directories (.venv, .git) and the allowed places."""
    for top in sorted(ROOT.iterdir()):
        if top.name.startswith(".") or top in ARGPARSE_ALLOWED:
            continue
        if top.is_dir():
            yield from (p for p in top.rglob("*.py") if not any(p.is_relative_to(a) for a in ARGPARSE_ALLOWED))
        elif top.suffix == ".py":
            yield top


def _imports_argparse(path: Path) -> bool:
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "argparse" for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "argparse":
            return True
    return False


def _leaf_parsers(parser: Any) -> Iterator[Any]:
    """The subcommands of ``parser`` that have no subcommands (a subparsers action's choices map names to
    parsers)."""
    subs = [a for a in parser._actions if isinstance(a.choices, dict)]
    if not subs:
        yield parser
    for action in subs:
        for child in action.choices.values():
            yield from _leaf_parsers(child)


def test_argparse_only_in_the_cli_package() -> None:
    offenders = [str(p.relative_to(ROOT)) for p in _python_files() if _imports_argparse(p)]
    assert offenders == []


def test_every_cli_module_is_a_listed_command_group() -> None:
    modules = {p.stem for p in (ROOT / "lightfast" / "cli").glob("*.py")} - {"__init__", "common"}
    assert {g.__name__.rsplit(".", 1)[-1] for g in cli.GROUPS} == modules
    for group in cli.GROUPS:
        assert isinstance(group.NAME, str) and isinstance(group.HELP, str) and callable(group.add_parser)


def test_every_subcommand_parses_its_own_options() -> None:
    """No passthrough: each leaf subcommand has a command function and no REMAINDER argument."""
    leaves = list(_leaf_parsers(cli.build_parser()))
    assert {p.prog for p in leaves} >= {"lightfast sim daylight", "lightfast eval racr", "lightfast crf calibrate",
                                        "lightfast racr wait", "lightfast vtr summary", "lightfast wait-ready"}
    for p in leaves:
        assert callable(p.get_default("func")), p.prog
        assert all(a.nargs != REMAINDER for a in p._actions), p.prog


def test_help_lists_every_group_and_loads_no_rclpy() -> None:
    result = subprocess.run([sys.executable, "-m", "lightfast", "--help"], capture_output=True, text=True,
                            timeout=60, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    listed = {m.group(1) for m in re.finditer(r"^ {4}(\S+)", result.stdout, re.MULTILINE)}
    assert listed == {g.NAME for g in cli.GROUPS}
    code = ("import sys\nfrom lightfast import cli\n"
            "for argv in (['--help'], ['racr', '--help'], ['vtr', 'summary', '--help']):\n"
            "    try:\n        cli.main(argv)\n    except SystemExit:\n        pass\n"
            "cli.build_parser()\n"
            "assert not [m for m in sys.modules if m == 'rclpy' or m.startswith('rclpy.')]\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 0, result.stderr


def test_sim_daylight_help_shows_its_options(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main(["sim", "daylight", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: lightfast sim daylight")
    assert all(opt in out for opt in ("--sequences", "--frames", "--size", "--resolution", "--no-progress"))
