"""benchmarks/radiance_heldout.py on a user's own room (``--mesh PLY --site --time``): the table and JSON are
written, with Radiance's values beside ours per component (a few points only: the benchmark's protocol is checked,
not its accuracy, which test_radiance_validation.py and the committed results cover)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from lightfast.daylight.mesh import save_ply
from lightfast.sim.radiance_oracle import radiance_available
from lightfast.sim.validation_rooms import furnished_room

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.skipif(not radiance_available(), reason="Radiance binaries (pyradiance) not found")


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / "radiance_heldout.py"), *args],
                          capture_output=True, text=True, timeout=600, check=False)


def test_own_room_gets_its_table(tmp_path: Path) -> None:
    ply = tmp_path / "my_room.ply"
    save_ply(furnished_room(tessellation_m=0.3), ply)
    out = tmp_path / "result"
    done = _run("--mesh", str(ply), "--site", "52.52,13.405,34", "--time", "2026-12-21T11:00Z", "--points", "6",
                "--junction-points", "3", "--repeats", "2", "--out", str(out))
    assert done.returncode == 0, done.stderr[-2000:]
    doc = json.loads(out.with_suffix(".json").read_text())
    room = doc["rooms"]["my_room"]
    assert room["site"] == "52.52,13.405,34" and 13 < room["sun_elevation_deg"] < 15  # Berlin, midwinter noon
    for component in ("sky", "ground", "sun"):
        s = room["components"][component]
        assert {"median_rel_err", "pearson_r", "scale", "pass", "junctions"} <= set(s)
        # same units as Radiance; points snapped onto a crease of the coarse mesh (before edge_clearance) gave 3.2
        assert 0.8 < s["scale"] < 1.25, (component, s["scale"])
    assert "| my_room |" in out.with_suffix(".md").read_text()


def test_bad_arguments_exit_non_zero_with_one_line(tmp_path: Path) -> None:
    ply = tmp_path / "room.ply"
    ply.write_text("not a ply\n")
    assert _run("--mesh", str(ply), "--site", "52.5,13.4").returncode == 2  # no --time
    bad = _run("--mesh", str(ply), "--site", "52.5,13.4", "--time", "2026-12-21T11:00Z")
    assert bad.returncode != 0 and "Traceback" not in bad.stderr
