import pytest

from lightfast.io import atomic_directory, write_text_atomic


def test_write_text_atomic_replaces_and_leaves_no_temp(tmp_path) -> None:
    path = tmp_path / "sub" / "f.txt"
    write_text_atomic(path, "one")
    write_text_atomic(path, "two")
    assert path.read_text() == "two"
    assert sorted(p.name for p in path.parent.iterdir()) == ["f.txt"]


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
