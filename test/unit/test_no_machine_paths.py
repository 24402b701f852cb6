"""No tracked file names one machine's absolute path (issue 21): data comes from ``$LIGHTFAST_SHARED`` or
``../shared`` (:mod:`lightfast.data.shared`) or a ``--data`` option, and committed reports show paths relative to
the repository or the home directory (:func:`lightfast.data.shared.shown_path`).

Scanned: every text file ``git ls-files`` lists. A path counts when it starts at a user's or a machine's own folder
(``work``, ``home/NAME``, ``root`` or ``Users/NAME`` at the file system's root, a Windows user folder), not inside a
URL or a longer path. System locations every installation shares (``/opt/ros/...``, ``/usr/...``, ``/tmp`` as a
default for scratch output that an option overrides) are not machine paths."""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: the folders that belong to one machine or user; built from pieces so that this file does not match itself
_PREFIXES = ("/" + "work/", "/" + "root/", "/" + r"home/[^/\s]+/", "/" + r"Users/[^/\s]+/")
MACHINE_PATH = re.compile(r"(?<![\w.:/~$-])(?:" + "|".join(_PREFIXES) + r")|\b[A-Za-z]:\\\\?Users\\")

#: tracked files allowed to hold such a path, each with the reason (none at present)
ALLOWED: dict[str, str] = {}


def _tracked_text_files() -> list[Path]:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: no list of tracked files")
    out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    return [ROOT / name for name in out.decode().split("\0") if name]


def machine_paths(text: str) -> list[str]:
    """The lines of ``text`` that name a machine path, as ``line number: line`` (shortened)."""
    return [f"{n}: {line.strip()[:160]}" for n, line in enumerate(text.splitlines(), 1) if MACHINE_PATH.search(line)]


def test_the_pattern_finds_machine_paths_and_spares_the_rest() -> None:
    bad = ["DATA = Path('/" + "work/shared/data/x')", "`/" + "root/.cache/lightfast/sim`", "/" + "home/alice/data",
           "C:\\" + "Users\\bob\\data", "/" + "Users/carol/x"]
    good = ["source /opt/ros/jazzy/setup.bash", "https://example.org/" + "work/x", "~/.cache/lightfast",
            "../shared/data", "/tmp/lightfast-heldout", "$LIGHTFAST_SHARED/data", "lightfast/work/x", "/" + "home"]
    assert [s for s in bad if not machine_paths(s)] == []
    assert [s for s in good if machine_paths(s)] == []


def test_no_tracked_file_names_a_machine_path() -> None:
    found = []
    for path in _tracked_text_files():
        rel = path.relative_to(ROOT).as_posix()
        if rel in ALLOWED or not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data[:8192]:
            continue  # binary
        found += [f"{rel}:{hit}" for hit in machine_paths(data.decode("utf-8", errors="replace"))]
    assert found == [], "absolute machine paths in tracked files:\n" + "\n".join(found)


def test_the_shared_folder_and_how_reports_show_paths(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from lightfast.data.shared import REPO_ROOT, SHARED_ENV, shared_data_dir, shared_root, shown_command, shown_path

    monkeypatch.delenv(SHARED_ENV, raising=False)
    assert shared_root() == REPO_ROOT.parent / "shared"
    assert shown_path(shared_data_dir("7scenes_redkitchen_300")) == "../shared/data/7scenes_redkitchen_300"
    assert shown_path(REPO_ROOT / "benchmarks" / "results") == "benchmarks/results"
    monkeypatch.setenv(SHARED_ENV, str(tmp_path / "elsewhere"))
    assert shared_data_dir("x") == tmp_path / "elsewhere" / "data" / "x"
    assert shown_path(shared_data_dir("x")) == "$LIGHTFAST_SHARED/data/x"
    monkeypatch.setenv("HOME", str(tmp_path))
    assert shown_path(tmp_path / ".cache" / "lightfast" / "sim") == "~/.cache/lightfast/sim"
    command = shown_command("benchmarks/b.py", [str(tmp_path / "sim"), "--jobs", "2"])
    assert command == "python benchmarks/b.py ~/sim --jobs 2"
