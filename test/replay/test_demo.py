"""The main job, ``scripts/demo.sh``, end to end on a tiny recording: three node processes, bag play with /clock,
recording, scoring; and Ctrl-C stops every process it started."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

from test.helpers import bounded_process, child_env

ROOT = Path(__file__).resolve().parents[2]
TINY = {"FRAMES": "20", "SIZE": "160x120", "RESOLUTION": "0.1", "PATCH_SIZE": "0.5", "PREROLL": "4"}


def _leftovers(marker: str) -> list[str]:
    out = subprocess.run(["pgrep", "-af", marker], capture_output=True, text=True).stdout
    return [line for line in out.splitlines() if "pgrep" not in line]


@pytest.mark.timeout(600)
def test_demo_runs_the_pipeline_on_a_tiny_recording(tmp_path: Path, domain_id: int) -> None:
    env = child_env(domain_id, LIGHTFAST_OUT=str(tmp_path), **TINY)
    with bounded_process(["bash", str(ROOT / "scripts/demo.sh")], timeout_s=540, env=env) as proc:
        out, err = proc.communicate(timeout=560)
    assert proc.returncode == 0, out[-3000:] + err[-3000:]
    m = re.search(r"frames (\d+), poses (\d+) .*f2m (\d+)", out)
    assert m, out[-2000:]
    frames, poses, f2m = map(int, m.groups())
    assert frames == 20 and poses >= 18, out[-2000:]
    assert f2m >= 1, "some frames must be refined against the relit reference"
    assert re.search(r"RMSE [\d.]+ cm, tracking loss [\d.]+ %", out)
    assert re.search(r"latency image stamp -> /tracker/pose: median [\d.]+ ms, p95 [\d.]+ ms", out)
    for stage in ("f2f", "rendering", "estimation", "f2m"):
        assert re.search(rf"\| {stage} \| [\d.]+ \| [\d.]+ \| \d+ \|", out), stage
    assert not _leftovers(str(tmp_path))


@pytest.mark.timeout(600)
def test_ctrl_c_stops_every_process_the_demo_started(tmp_path: Path, domain_id: int) -> None:
    env = child_env(domain_id, LIGHTFAST_OUT=str(tmp_path), **{**TINY, "PREROLL": "60"})
    with bounded_process(["bash", str(ROOT / "scripts/demo.sh")], timeout_s=540, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT) as proc:
        assert proc.stdout is not None
        lines = []
        deadline = time.monotonic() + 500
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if line.startswith("== playing"):
                break
        assert lines and lines[-1].startswith("== playing"), "".join(lines)[-2000:]
        # the sun and relight nodes, the recorder and the player carry tmp_path on their command line (the tracker
        # does not); the player starts just after its line is printed
        started = time.monotonic() + 30
        while len(_leftovers(str(tmp_path))) < 4 and time.monotonic() < started:
            time.sleep(0.2)
        assert len(_leftovers(str(tmp_path))) >= 4
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole foreground group
        rest, _ = proc.communicate(timeout=60)
    assert proc.returncode != 0
    assert not _leftovers(str(tmp_path)), rest[-2000:]
