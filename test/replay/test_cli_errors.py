"""Bad input to the bag commands: one clear error line, exit code 1, never a traceback."""
from pathlib import Path

import pytest

from lightfast.bag import BagWriter
from test.helpers import LIGHTFAST, child_env, run_bounded


def make_unknown_type_bag(path: Path) -> Path:
    with BagWriter(path) as bag:
        bag.add_topic("/secret", "foo_msgs/msg/Bar", msgdef="int32 value\n")
        bag.write_message("/secret", 1, bag.typestore.types["foo_msgs/msg/Bar"](value=1))
    return path


def make_truncated_bag(path: Path) -> Path:
    with BagWriter(path) as bag:
        bag.add_topic("/text", "std_msgs/msg/String")
        for i in range(100):
            bag.write_message("/text", i, bag.typestore.types["std_msgs/msg/String"](data="x" * 100))
    mcap = path / f"{path.name}.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) * 2 // 3])
    return path


@pytest.mark.parametrize(
    ("make", "command", "message"),
    [
        (make_unknown_type_bag, "play", "message type foo_msgs/msg/Bar is not installed here"),
        (make_truncated_bag, "play", "cannot read bag"),
        (make_truncated_bag, "info", "cannot read bag"),
        (lambda p: p / "missing", "play", "no bag at"),
        (lambda p: p / "missing", "info", "no bag at"),
    ],
    ids=["unknown-type-play", "truncated-play", "truncated-info", "missing-play", "missing-info"],
)
def test_bad_bags_give_one_line(tmp_path: Path, domain_id: int, make, command: str, message: str) -> None:
    bag = make(tmp_path / "bag")
    result = run_bounded([*LIGHTFAST, "bag", command, str(bag)], timeout_s=60, env=child_env(domain_id))
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("lightfast: error: ") and message in lines[0]
    assert "Traceback" not in result.stderr + result.stdout


def test_compare_exit_code_and_usage(tmp_path: Path) -> None:
    a = make_unknown_type_bag(tmp_path / "a")
    same = run_bounded([*LIGHTFAST, "bag", "compare", str(a), str(a)], timeout_s=60)
    assert same.returncode == 0 and "1/1 messages on 1 topics, 0 dropped, payloads identical" in same.stdout
    result = run_bounded([*LIGHTFAST, "bag", "compare", str(a), str(tmp_path / "nope")], timeout_s=60)
    assert result.returncode == 1 and "no bag at" in result.stderr
    assert run_bounded([*LIGHTFAST, "bag", "frobnicate"], timeout_s=60).returncode == 2


def test_wait_ready_times_out_or_fails_on_a_dead_process_with_one_line(domain_id: int) -> None:
    """`lightfast wait-ready` (launch-free scripts): nobody announces -> exit 1 naming the missing node after the
    timeout; a --pid process that is gone -> exit 1 at once."""
    result = run_bounded([*LIGHTFAST, "wait-ready", "no_such_node", "--timeout", "1"], timeout_s=60,
                         env=child_env(domain_id))
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert result.stderr.strip().splitlines() == ["lightfast: error: not ready after 1 s: no_such_node (ready: none)"]
    beyond_pid_max = "999999999"  # no such process
    dead = run_bounded([*LIGHTFAST, "wait-ready", "no_such_node", "--timeout", "30", "--pid", beyond_pid_max],
                       timeout_s=60, env=child_env(domain_id))
    assert dead.returncode == 1 and "watched process ended" in dead.stderr
