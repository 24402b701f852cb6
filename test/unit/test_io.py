import json
import math
import os
import stat

import numpy as np
import pytest

from lightfast.io import atomic_directory, json_finite, read_versioned_yaml, write_text_atomic


def test_write_text_atomic_replaces_and_leaves_no_temp(tmp_path) -> None:
    path = tmp_path / "sub" / "f.txt"
    write_text_atomic(path, "one")
    write_text_atomic(path, "two")
    assert path.read_text() == "two"
    assert sorted(p.name for p in path.parent.iterdir()) == ["f.txt"]


def test_atomic_outputs_get_the_usual_permissions(tmp_path) -> None:
    """Not mkstemp's / mkdtemp's private 0600 / 0700: what open() and mkdir() make under the umask."""
    old = os.umask(0o022)
    try:
        write_text_atomic(tmp_path / "f.txt", "x")
        with atomic_directory(tmp_path / "d"):
            pass
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "f.txt").stat().st_mode) == 0o644
    assert stat.S_IMODE((tmp_path / "d").stat().st_mode) == 0o755


def test_atomic_directory_failure_keeps_old(tmp_path) -> None:
    target = tmp_path / "map"
    with atomic_directory(target) as d:
        (d / "a").write_text("1")
    with pytest.raises(RuntimeError), atomic_directory(target, overwrite=True) as d:
        (d / "a").write_text("2")
        raise RuntimeError("crash mid-write")
    assert (target / "a").read_text() == "1"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map"]
    with pytest.raises(FileExistsError):
        with atomic_directory(target):
            pass


class _ThingError(Exception):
    pass


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("format: thing\nversion: 1\nx: 2\n", None),
        ("format: other\nversion: 1\n", "is not a thing file"),
        ("- a list\n", "is not a thing file"),
        ("format: thing\nversion: 2\n", "version 2 is not supported"),
        ("format: thing\nversion: [1\n", "cannot read a thing file"),
    ],
)
def test_read_versioned_yaml_checks_format_and_version(tmp_path, text: str, match: str | None) -> None:
    path = tmp_path / "doc.yaml"
    path.write_text(text)
    read = lambda: read_versioned_yaml(path, format_name="thing", version=1, error=_ThingError, what="a thing file")  # noqa: E731
    if match is None:
        assert read()["x"] == 2
    else:
        with pytest.raises(_ThingError, match=match):
            read()


def test_read_versioned_yaml_missing_file_raises_the_given_error(tmp_path) -> None:
    with pytest.raises(_ThingError, match="cannot read"):
        read_versioned_yaml(tmp_path / "nope.yaml", format_name="thing", version=1, error=_ThingError,
                            what="a thing file")



def test_json_finite_writes_non_finite_as_null() -> None:
    doc = {"rate": float("nan"), "runs": [1.0, np.float64("nan"), (np.int64(2), np.float32(3.5))], "x": -math.inf}
    assert json.loads(json.dumps(json_finite(doc), allow_nan=False)) == {
        "rate": None, "runs": [1.0, None, [2, 3.5]], "x": None}
