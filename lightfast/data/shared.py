"""Where the shared real data lives, and how a path is written into a committed report.

The data sets (7-Scenes, 3DMatch, webcam time-lapses; each folder's PROVENANCE.md gives source and licence) are
read in place, never copied into the repository: from ``$LIGHTFAST_SHARED`` if set, else from the ``shared``
folder beside the checkout (``<repo>/../shared``). Tests (the ``shared_data`` fixture), benchmarks and scripts all
ask :func:`shared_root` / :func:`shared_data_dir`; a benchmark's ``--data`` option overrides it.

:func:`shown_path` is how reports name a file: relative to the repository (``../shared/data/...`` for the data
beside it), ``$LIGHTFAST_SHARED/...``, ``~/...`` under the home directory, else as given, so that no committed
result holds one machine's absolute path (``test/unit/test_no_machine_paths.py`` checks the tracked files).
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["REPO_ROOT", "SHARED_ENV", "shared_data_dir", "shared_root", "shown_command", "shown_path"]

#: The checkout this package runs from (``lightfast/`` is at its top level).
REPO_ROOT = Path(__file__).resolve().parents[2]
#: Environment variable naming the shared folder (the one holding ``data/``).
SHARED_ENV = "LIGHTFAST_SHARED"


def shared_root() -> Path:
    """``$LIGHTFAST_SHARED`` if set (and not empty), else ``<repo>/../shared``; not checked for existence."""
    env = os.environ.get(SHARED_ENV)
    return Path(env).expanduser() if env else REPO_ROOT.parent / "shared"


def shared_data_dir(name: str = "") -> Path:
    """``<shared>/data/<name>`` (``<shared>/data`` without a name)."""
    data = shared_root() / "data"
    return data / name if name else data


def _relative(path: Path, base: Path) -> str | None:
    try:
        return path.relative_to(base).as_posix()
    except ValueError:
        return None


def shown_path(path: str | os.PathLike[str]) -> str:
    """``path`` as a report shows it, without one machine's absolute prefix (see the module docstring)."""
    p = Path(path).expanduser().resolve()
    if (rel := _relative(p, REPO_ROOT)) is not None:
        return rel or "."
    if (rel := _relative(p, REPO_ROOT.parent)) is not None:
        return f"../{rel}"
    if os.environ.get(SHARED_ENV) and (rel := _relative(p, shared_root().resolve())) is not None:
        return f"${SHARED_ENV}/{rel}".rstrip("/")
    if (rel := _relative(p, Path.home().resolve())) is not None:
        return f"~/{rel}".rstrip("/")
    return str(path)


def shown_command(script: str, argv: list[str]) -> str:
    """``python <script> <argv>`` as a report shows the command that made it: absolute paths among the arguments
    through :func:`shown_path`."""
    return " ".join(["python", script, *(shown_path(a) if a.startswith("/") else a for a in argv)])
