"""Nodes started as `ros2 run` starts them, with bad arguments: one clear line, exit code 1, never a traceback."""
import sys
from pathlib import Path

import pytest

from test.helpers import child_env, run_bounded

SUN_NODE = [sys.executable, "-m", "sun_update_node.node"]


def run_node(args: list[str], domain_id: int) -> tuple[int, list[str]]:
    result = run_bounded([*SUN_NODE, "--ros-args", *args], timeout_s=60, env=child_env(domain_id))
    assert "Traceback" not in result.stderr + result.stdout, result.stderr
    return result.returncode, result.stderr.strip().splitlines()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "cannot read the parameter file"),
        ("/**:\n  ros__parameters: [\n", "is not valid YAML"),
        ("- just\n- a list\n", "must map node names"),
        # valid YAML that rcl refuses: a list of mixed types
        ("/**:\n  ros__parameters:\n    chunk_vertices: [1, 'x']\n", "Sequence should be of same type"),
    ],
    ids=["missing", "malformed", "not-a-mapping", "rcl-refuses"],
)
def test_a_bad_params_file_is_one_line(tmp_path: Path, domain_id: int, content: str | None, message: str) -> None:
    path = tmp_path / "params.yaml"
    if content is not None:
        path.write_text(content)
    code, lines = run_node(["--params-file", str(path)], domain_id)
    assert code == 1
    assert len(lines) == 1, lines
    assert lines[0].startswith("sun_update_node: error: ") and message in lines[0], lines
    assert "/project/src" not in lines[0]  # rcl's C source locations are not for users


def test_a_misspelt_parameter_is_named_with_the_closest_known_one(tmp_path: Path, domain_id: int) -> None:
    code, lines = run_node(["-p", f"lighting_mpa:={tmp_path}"], domain_id)
    assert code == 1
    assert any("unknown parameter 'lighting_mpa' ignored; did you mean 'lighting_map'?" in line for line in lines)
    assert lines[-1].startswith("sun_update_node: error: parameter lighting_map is required"), lines
