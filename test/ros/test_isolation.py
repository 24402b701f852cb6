"""Test isolation: concurrent test runs do not see each other's topics, and no subprocess outlives its timeout."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lightfast.ros.domain import reserve_domain_id
from lightfast.ros.errors import DomainExhaustedError
from test.helpers import bounded_process, run_bounded

PROBE = Path(__file__).with_name("isolation_probe.py")
ROOT = Path(__file__).resolve().parents[2]


def start_probe(tag: str, **env: str) -> subprocess.Popen[str]:
    full_env = dict(os.environ, PROBE_TAG=tag, **env)
    cmd = ["timeout", "-k", "5", "120", sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
           str(PROBE), "-o", "testpaths=", "--rootdir", str(ROOT)]
    # the probe runs with discovery on this host (LOCALHOST), the hardest case for isolation
    full_env["LIGHTFAST_TEST_DISCOVERY"] = "LOCALHOST"
    return subprocess.Popen(cmd, cwd=ROOT, env=full_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True)


def test_two_concurrent_runs_do_not_see_each_other() -> None:
    probes = [start_probe("alpha"), start_probe("beta")]
    outputs = [p.communicate(timeout=150)[0] for p in probes]
    for p, out in zip(probes, outputs, strict=True):
        assert p.returncode == 0, out


def test_the_probe_can_fail_when_domains_collide() -> None:
    """Control: force both runs onto one domain id and the probes do hear each other (so the check above bites)."""
    with reserve_domain_id() as lease:
        forced = {"LIGHTFAST_TEST_DOMAIN_ID": str(lease.domain_id)}
        probes = [start_probe("gamma", **forced), start_probe("delta", **forced)]
        outputs = [p.communicate(timeout=150)[0] for p in probes]
    assert all(p.returncode != 0 for p in probes), outputs
    assert any("heard ['delta', 'gamma']" in out for out in outputs), outputs


def test_domain_ids_are_exclusive(tmp_path: Path) -> None:
    with reserve_domain_id(first=5, last=6, lock_dir=tmp_path) as a, reserve_domain_id(
        first=5, last=6, lock_dir=tmp_path
    ) as b:
        assert {a.domain_id, b.domain_id} == {5, 6}
        with pytest.raises(DomainExhaustedError):
            reserve_domain_id(first=5, last=6, lock_dir=tmp_path)
        # another process cannot take them either
        code = (
            "import sys; from pathlib import Path; from lightfast.ros.domain import reserve_domain_id\n"
            f"try:\n    reserve_domain_id(first=5, last=6, lock_dir=Path({str(tmp_path)!r}))\n"
            "except Exception as e:\n    print(type(e).__name__); sys.exit(0)\nsys.exit(1)\n"
        )
        result = run_bounded([sys.executable, "-c", code], timeout_s=60)
        assert result.returncode == 0 and "DomainExhaustedError" in result.stdout
    with reserve_domain_id(first=5, last=5, lock_dir=tmp_path) as c:  # released on exit
        assert c.domain_id == 5


def test_a_process_ignoring_sigterm_cannot_outlive_its_timeout() -> None:
    stubborn = "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); print('up', flush=True); " \
               "time.sleep(600)"
    start = time.monotonic()
    with bounded_process([sys.executable, "-c", stubborn], timeout_s=1.0, kill_after_s=1.0) as proc:
        proc.wait(timeout=30)
    assert time.monotonic() - start < 10
    assert proc.returncode in (124, 137, -9)


def test_a_hung_destroy_node_cannot_hang_a_command() -> None:
    """ros_session's watchdog ends the process when node teardown hangs (seen in practice)."""
    code = (
        "import time\n"
        "from rclpy.node import Node\n"
        "from lightfast.ros.runtime import ros_session\n"
        "Node.destroy_node = lambda self: time.sleep(600)\n"
        "with ros_session('hang_test', shutdown_grace_s=1.0, install_signal_handlers=False):\n"
        "    print('work done', flush=True)\n"
    )
    start = time.monotonic()
    result = run_bounded([sys.executable, "-c", code], timeout_s=60,
                         env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="OFF"))
    assert "work done" in result.stdout
    assert result.returncode == 3
    assert time.monotonic() - start < 30
