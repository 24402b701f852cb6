"""Atomic file output: readers never see a half-written file, a crash leaves the previous version intact. And the
readers' side: damaged or foreign files give the loader's own error with the reason, never a traceback."""
from __future__ import annotations

import io
import json
import os
import shutil
import tempfile
import zipfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import yaml

#: What numpy and zipfile raise on a truncated, garbled or foreign .npz file.
NPZ_ERRORS = (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error)


def _umask() -> int:
    """The process umask, read without changing it (``os.umask`` sets it, racing other threads)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    return 0o022


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` atomically (temporary file in the same directory, fsync, rename)."""
    write_bytes_atomic(path, text.encode())


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file in the same directory, fsync, rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            os.fchmod(fh.fileno(), 0o666 & ~_umask())  # as open() would (mkstemp makes it private)
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def atomic_directory(path: str | os.PathLike[str], *, overwrite: bool = False) -> Iterator[Path]:
    """Build a directory under a temporary name beside ``path`` and move it into place when the block succeeds.

    Yields the temporary directory. On an exception it is removed and ``path`` is untouched. With ``overwrite``
    an existing ``path`` is replaced (it is moved aside first, then deleted); otherwise it is an error.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists (pass overwrite to replace it)")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent))
    tmp.chmod(0o777 & ~_umask())  # as mkdir() would (mkdtemp makes it private)
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if path.exists():
        old = path.with_name(f".{path.name}.old-{os.getpid()}")
        os.replace(path, old)
    os.replace(tmp, path)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def read_versioned_yaml(path: str | os.PathLike[str], *, format_name: str, version: int, error: type[Exception],
                        what: str, version_key: str = "version") -> dict[str, Any]:
    """Read a YAML mapping (``yaml.safe_load``) that names its ``format`` and version, for the loaders of lightfast's
    versioned files. Raises ``error`` with the reason when the file cannot be read, is not a mapping of format
    ``format_name`` (described as ``what``), or has another version."""
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise error(f"{path}: cannot read {what} ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != format_name:
        raise error(f"{path} is not {what} (expected format: {format_name})")
    if doc.get(version_key) != version:
        raise error(f"{path}: {what} {version_key} {doc.get(version_key)} is not supported (reads {version})")
    return doc


def load_npz(path: str | os.PathLike[str], *, error: type[Exception], what: str,
             data: bytes | None = None) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file (``allow_pickle=False``), read at once; ``data`` reads those bytes instead of
    the file. Raises ``error`` naming ``what`` and the file when it is missing, truncated or not an npz file."""
    try:
        source = io.BytesIO(data) if data is not None else Path(path)
        with np.load(source, allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except NPZ_ERRORS as exc:
        reason = f"{type(exc).__name__}: {exc}"
        raise error(f"{path}: {what} is damaged or truncated, or not an npz file ({reason})") from None


def read_json_mapping(path: str | os.PathLike[str], *, error: type[Exception], what: str) -> dict[str, Any]:
    """A JSON file holding an object (a ``dict``); ``error`` naming ``what`` when it cannot be read or parsed, or
    holds anything else."""
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise error(f"{path}: {what} is unreadable ({exc})") from None
    if not isinstance(doc, dict):
        raise error(f"{path}: {what} must be a JSON object, got {type(doc).__name__}")
    return doc


def json_finite(x: Any) -> Any:
    """``x`` (nested dicts, lists, tuples, numbers) with NumPy scalars as Python ones and every non-finite float
    (NaN: a rate over no runs; inf) as ``None``, so that ``json.dumps`` writes standard JSON (``null``)."""
    if isinstance(x, dict):
        return {k: json_finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_finite(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x
