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
