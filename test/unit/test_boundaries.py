"""The core library stays ROS-free: no rclpy import outside lightfast/ros, and importing it loads no rclpy."""
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
IMPORT_RCLPY = re.compile(r"^\s*(import rclpy|from rclpy)", re.MULTILINE)


def test_no_rclpy_import_statement_outside_ros_package() -> None:
    offenders = [
        str(p.relative_to(ROOT))
        for p in (ROOT / "lightfast").rglob("*.py")
        if "ros" not in p.relative_to(ROOT / "lightfast").parts[:1] and IMPORT_RCLPY.search(p.read_text())
    ]
    assert offenders == []


def test_importing_the_core_loads_no_rclpy() -> None:
    modules = [
        p.relative_to(ROOT).with_suffix("").as_posix().replace("/", ".")
        for p in (ROOT / "lightfast").rglob("*.py")
        if p.name != "__main__.py" and "ros" not in p.relative_to(ROOT / "lightfast").parts[:1]
    ]
    code = "import sys\n" + "".join(f"import {m}\n" for m in modules) + (
        "bad = sorted(m for m in sys.modules if m == 'rclpy' or m.startswith('rclpy.'))\n"
        "assert not bad, bad\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 0, result.stderr


IMPORT_LIGHTFAST = re.compile(r"^\s*(?:from|import)\s+(lightfast(?:\.\w+)*)", re.MULTILINE)
#: Node packages that are simulators themselves (they may read the simulator).
SIMULATOR_NODES = {"racr_platform_sim_node", "racr_vse_node"}
#: Core modules allowed above the core, each with its reason.
ALLOWED = {
    "lightfast/__main__.py": "`python -m lightfast` is the command line",
    "lightfast/ros/racr_tools.py": "scores a simulated rACR run against the simulator's truth for `lightfast racr "
                                   "wait` (a tool of the simulated demo; no node imports it)",
}


def _imports(path: Path) -> set[str]:
    return set(IMPORT_LIGHTFAST.findall(path.read_text()))


def _above_core(module: str) -> bool:
    return module.startswith(("lightfast.sim", "lightfast.eval", "lightfast.cli"))


def test_nodes_and_core_do_not_import_the_simulators_or_the_evaluations() -> None:
    """nodes → core → nothing above: no node (but the simulator nodes) and no core module reads lightfast.sim,
    lightfast.eval or lightfast.cli; the simulators do not read the evaluations."""
    offenders = []
    for package in sorted(p.parent for p in ROOT.glob("*_node/node.py")):
        if package.name in SIMULATOR_NODES:
            continue
        for path in package.rglob("*.py"):
            offenders += [f"{path.relative_to(ROOT)}: {m}" for m in _imports(path) if _above_core(m)]
    for path in (ROOT / "lightfast").rglob("*.py"):
        rel = path.relative_to(ROOT).as_posix()
        top = path.relative_to(ROOT / "lightfast").parts[0] if len(path.relative_to(ROOT / "lightfast").parts) > 1 \
            else ""
        if top in ("sim", "eval", "cli") or rel in ALLOWED:
            if top == "sim":
                above = ("lightfast.eval", "lightfast.cli")
                offenders += [f"{rel}: {m}" for m in _imports(path) if m.startswith(above)]
            continue
        offenders += [f"{rel}: {m}" for m in _imports(path) if _above_core(m)]
    assert offenders == []
