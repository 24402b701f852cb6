"""Keys of finished evaluation runs: what decides a run, never a name alone.

An evaluation keeps each finished run and skips it when started again. A run is the same only when everything
that decides it is: the content of its input (:func:`content_digest`: every file of a scene or recording
directory, so another seed, another size or another simulator version is another input), the method's
configuration, the protocol, and the code that computes it (:func:`code_version`: the source of the packages the
run executes). :func:`run_key` hashes these parts; evaluations store the key in each record and reuse a record only
for its exact key.
"""
from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable, Mapping
from functools import lru_cache
from pathlib import Path
from typing import Any

__all__ = ["code_version", "content_digest", "file_digest", "run_key"]

_LIGHTFAST = Path(__file__).resolve().parents[1]
_CHUNK = 1 << 20


def file_digest(path: Path) -> str:
    """SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(_CHUNK):
            h.update(block)
    return h.hexdigest()


@lru_cache(maxsize=4096)
def _cached_file_digest(path: str, size: int, mtime_ns: int) -> str:
    del size, mtime_ns  # part of the cache key: a rewritten file is hashed again
    return file_digest(Path(path))


def content_digest(path: str | os.PathLike[str], *, skip: Iterable[str] = ()) -> str:
    """SHA-256 over the relative paths and contents of every file below ``path`` (or of the file itself), in
    sorted order; files or directories named in ``skip`` (first path component, e.g. previews) do not count."""
    root = Path(path)
    if root.is_file():
        files = [root]
    else:
        left_out = set(skip)
        files = sorted(p for p in root.rglob("*") if p.is_file() and p.relative_to(root).parts[0] not in left_out)
    h = hashlib.sha256()
    for p in files:
        st = p.stat()
        rel = p.name if p == root else p.relative_to(root).as_posix()
        h.update(f"{rel}\0{_cached_file_digest(str(p), st.st_size, st.st_mtime_ns)}\n".encode())
    return h.hexdigest()[:16]


def code_version(*parts: str) -> str:
    """SHA-256 of the Python sources of ``parts`` of the lightfast package (``"racr"``, ``"eval/racr"``,
    ``"camera.py"`` …): a change to the code a run executes gives its runs new keys."""
    h = hashlib.sha256()
    for part in sorted(parts):
        target = _LIGHTFAST / part
        files = [target] if target.is_file() else sorted(target.rglob("*.py"))
        for p in files:
            h.update(f"{p.relative_to(_LIGHTFAST).as_posix()}\0".encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:12]


def run_key(parts: Mapping[str, Any]) -> str:
    """The key of a run from what decides it (JSON-serializable values; dataclass configs as dicts)."""
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:16]
