"""One error tree (see :mod:`lightfast.errors`): every exception class lightfast defines derives from
``LightfastError``; each subpackage keeps all of its error classes in its own ``errors.py`` under one root; the
top-level modules keep theirs in ``lightfast/errors.py``; no two error classes share a name; and each concrete
error says whose fault it is (``InputError`` or ``InternalError``)."""
from __future__ import annotations

import ast
import importlib
import pkgutil
from pathlib import Path

import pytest

import lightfast
from lightfast.errors import InputError, InternalError, LightfastError

REPO = Path(lightfast.__file__).resolve().parent.parent

#: The one root of each subpackage of lightfast, defined in ``lightfast/<subpackage>/errors.py``.
ROOTS = {
    "bag": "BagError",
    "data": "DataError",
    "daylight": "DaylightError",
    "eval": "EvalError",
    "racr": "RacrError",
    "ros": "RosError",
    "sim": "SimError",
    "tracking": "TrackingError",
    "vtr": "VtrError",
}
#: Exception classes defined in lightfast that need not derive from LightfastError (name -> reason).
NOT_LIGHTFAST: dict[str, str] = {}
#: Classes that are neither InputError nor InternalError besides the roots and the markers (name -> reason).
NEITHER: dict[str, str] = {}
MARKERS = (LightfastError, InputError, InternalError)


def _modules() -> list[str]:
    names = ["lightfast"]
    names += [m.name for m in pkgutil.walk_packages(lightfast.__path__, "lightfast.")
              if not m.name.endswith(".__main__")]
    return names


def _collect() -> list[type[BaseException]]:
    found: dict[str, type[BaseException]] = {}
    for name in _modules():
        module = importlib.import_module(name)
        for obj in vars(module).values():
            if isinstance(obj, type) and issubclass(obj, BaseException) and obj.__module__ == name:
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return list(found.values())


@pytest.fixture(scope="module")
def errors() -> list[type[BaseException]]:
    return _collect()


def _root(subpackage: str) -> type[LightfastError]:
    return getattr(importlib.import_module(f"lightfast.{subpackage}.errors"), ROOTS[subpackage])


def _subpackage(cls: type) -> str | None:
    """``"bag"`` for a class of ``lightfast.bag.*``, None for one of a top-level module (``lightfast.config``)."""
    parts = cls.__module__.split(".")
    return parts[1] if len(parts) > 2 else None


def test_the_walk_finds_the_tree(errors):
    names = {c.__name__ for c in errors}
    assert {"LightfastError", "InputError", "InternalError", "ConfigError", "CrfError", "MapCorruptError",
            "TrackingError", "ConversionError", "BagFormatError"} <= names
    assert len(errors) > 50


def test_every_error_derives_from_lightfast_error(errors):
    stray = [f"{c.__module__}.{c.__qualname__}" for c in errors
             if not issubclass(c, LightfastError) and c.__name__ not in NOT_LIGHTFAST]
    assert not stray, f"exception classes outside the LightfastError tree: {stray}"


def test_roots(errors):
    for sub in ROOTS:
        root = _root(sub)
        assert root.__module__ == f"lightfast.{sub}.errors"
        assert root.__bases__ == (LightfastError,), f"{root.__name__} must derive from LightfastError only"
        assert not issubclass(root, InputError | InternalError), f"the root {root.__name__} is neither kind"
    subpackages = {_subpackage(c) for c in errors} - {None}
    assert subpackages <= set(ROOTS), f"subpackages with errors but no root in ROOTS: {subpackages - set(ROOTS)}"


def test_each_error_lives_in_its_errors_module_under_its_root(errors):
    roots = {sub: _root(sub) for sub in ROOTS}
    problems = []
    for c in errors:
        if not issubclass(c, LightfastError):
            continue
        sub = _subpackage(c)
        home = f"lightfast.{sub}.errors" if sub else "lightfast.errors"
        if c.__module__ != home:
            problems.append(f"{c.__module__}.{c.__name__} is not defined in {home}")
        if sub is None:
            others = [r.__name__ for r in roots.values() if issubclass(c, r)]
            if others:
                problems.append(f"{c.__name__} of a top-level module derives from {others}")
            continue
        if not issubclass(c, roots[sub]):
            problems.append(f"{c.__name__} does not derive from {roots[sub].__name__}")
        others = [r.__name__ for s, r in roots.items() if s != sub and issubclass(c, r)]
        if others:
            problems.append(f"{c.__name__} of lightfast.{sub} also derives from {others}")
    assert not problems, "\n".join(problems)


def test_every_error_is_input_or_internal(errors):
    roots = {_root(sub) for sub in ROOTS}
    problems = []
    for c in errors:
        if not issubclass(c, LightfastError) or c in MARKERS or c in roots or c.__name__ in NEITHER:
            continue
        kinds = [k.__name__ for k in (InputError, InternalError) if issubclass(c, k)]
        if len(kinds) != 1:
            problems.append(f"{c.__module__}.{c.__name__}: {kinds or 'neither InputError nor InternalError'}")
    assert not problems, "\n".join(problems)


def test_no_duplicate_names(errors):
    seen: dict[str, str] = {}
    dups = []
    for c in errors:
        where = f"{c.__module__}.{c.__qualname__}"
        if c.__name__ in seen:
            dups.append(f"{c.__name__}: {seen[c.__name__]} and {where}")
        seen[c.__name__] = where
    assert not dups, dups


def _error_classes_in_source(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    return [n.name for n in ast.walk(tree)
            if isinstance(n, ast.ClassDef) and (n.name.endswith("Error") or n.name.endswith("Exception"))]


def test_node_packages_define_no_errors():
    """The node packages raise lightfast's errors; an error class of theirs belongs in ``lightfast/ros/errors.py``
    (or the core's ``errors.py``)."""
    defined = {}
    for pkg in sorted(p for p in REPO.glob("*_node") if (p / "__init__.py").exists()):
        for path in sorted(pkg.rglob("*.py")):
            for name in _error_classes_in_source(path):
                defined.setdefault(name, []).append(str(path.relative_to(REPO)))
    assert not defined, f"error classes in node packages: {defined}"
