"""package.xml declares what the installed packages import, and only that.

Every ``.py`` file of the packages that setup.py installs (``lightfast`` and the node packages in ``NODES``; not
``test/`` nor ``benchmarks/``) is read with ``ast``: every ``import``/``from … import`` at any depth (lazy imports
inside functions too, relative ones skipped) and every interface type string such as
``"builtin_interfaces/msg/Time"`` (message classes that ``importlib`` loads by name). Each third-party top-level
module goes through :data:`MODULE_DEPS` to its dependency: a ROS package name or rosdep key, which package.xml must
declare as ``exec_depend``/``depend``, or ``pip:<distribution>`` for a library with no usable rosdep key, which must
be in package.xml's pip-only comment and in the pip command of docs/install.md, pinned as in
requirements.lock. Declared entries that nothing imports fail too (test and buildtool entries aside, and
:data:`ALLOWED_UNUSED`).
"""
from __future__ import annotations

import ast
import functools
import re
import shlex
import sys
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE_XML = ROOT / "package.xml"
SETUP_PY = ROOT / "setup.py"
SNIPPET = ROOT / "docs" / "install.md"
LOCK = ROOT / "requirements.lock"

#: Top-level module -> what provides it: a ROS package name, a rosdep key (rosdistro rosdep/python.yaml or
#: base.yaml), or "pip:<distribution>" when no rosdep key installs what we need.
MODULE_DEPS: dict[str, str] = {
    # ROS packages, by their ROS name
    "ament_index_python": "ament_index_python",
    "builtin_interfaces": "builtin_interfaces",  # as "builtin_interfaces/msg/Time", loaded by name
    "diagnostic_msgs": "diagnostic_msgs",
    "geometry_msgs": "geometry_msgs",
    "nav_msgs": "nav_msgs",
    "rcl_interfaces": "rcl_interfaces",
    "rclpy": "rclpy",
    "rosgraph_msgs": "rosgraph_msgs",
    "sensor_msgs": "sensor_msgs",
    "std_msgs": "std_msgs",
    "std_srvs": "std_srvs",
    "tf2_msgs": "tf2_msgs",
    # Python libraries with a rosdep key (apt packages on Ubuntu)
    "cv2": "python3-opencv",
    "matplotlib": "python3-matplotlib",
    "numba": "python3-numba",
    "numpy": "python3-numpy",
    "pandas": "python3-pandas",
    "scipy": "python3-scipy",
    "tqdm": "python3-tqdm",
    "yaml": "python3-yaml",
    # pip-only. python3-rosbags-pip and python3-open3d-pip exist, but rosdep would pip-install them as root and
    # unpinned, and python3-open3d-pip is the distribution open3d, not open3d-cpu (python3-open3d has no noble entry)
    "colour": "pip:colour-science",
    "embreex": "pip:embreex",
    "lz4": "pip:lz4",
    "mcap": "pip:mcap",
    "open3d": "pip:open3d-cpu",
    "pvlib": "pip:pvlib",
    "pyradiance": "pip:pyradiance",
    "rosbags": "pip:rosbags",
    "zstandard": "pip:zstandard",
}

#: Declared run-time entries that no import needs (yet), with the reason.
ALLOWED_UNUSED: dict[str, str] = {
    "libusb-1.0": "system library (libusb-1.0.so.0) that the pip wheel open3d-cpu loads; rosdep installs it",
    "tf2_msgs": "TF publishing (lightfast.ros.tf); kept declared even where nothing imports it yet",
}

#: pip-only versions that differ from requirements.lock on a real Jazzy install, with the reason.
JAZZY_PINS: dict[str, tuple[str, str]] = {
    "colour-science": ("0.4.6", "0.4.7 needs NumPy 2; Jazzy's message modules, SciPy and OpenCV need NumPy 1.x"),
}

#: Requirements in the snippet's pip command that are not pip-only dependencies, with the reason.
PIP_COMMAND_EXTRAS: dict[str, str] = {
    "numpy<2": "keeps apt's NumPy 1.26, which Jazzy's compiled modules need",
}

#: package.xml tags whose entries are exempt from the "declared but not imported" check.
EXEMPT_TAGS = {"test_depend", "buildtool_depend", "buildtool_export_depend", "doc_depend"}
#: package.xml tags that make a dependency present when the nodes run.
RUN_TAGS = {"depend", "exec_depend"}

_INTERFACE_TYPE = re.compile(r"^([a-z][a-z0-9_]*)/(?:msg|srv|action)/[A-Z][A-Za-z0-9]*$")
_PINNED = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==(\S+)$")


def _norm(dist: str) -> str:
    return re.sub(r"[-_.]+", "-", dist).lower()


def installed_packages(setup_py: Path | None = None) -> list[str]:
    """``PACKAGE`` and ``NODES`` of setup.py: the top-level packages that ``find_packages`` installs."""
    tree = ast.parse((setup_py or SETUP_PY).read_text())
    values: dict[str, object] = {}
    for node in tree.body:
        if isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                if isinstance(target, ast.Name) and target.id in ("PACKAGE", "NODES") and node.value is not None:
                    values[target.id] = ast.literal_eval(node.value)
    assert set(values) == {"PACKAGE", "NODES"}, "setup.py no longer assigns PACKAGE and NODES as literals"
    return [str(values["PACKAGE"]), *map(str, values["NODES"])]  # type: ignore[arg-type]


def used_modules(packages: list[str] | None = None) -> dict[str, list[str]]:
    """Third-party top-level module -> the ``file:line`` places that import it (or name one of its interfaces)."""
    packages = packages or installed_packages()
    own = set(packages)
    uses: dict[str, list[str]] = defaultdict(list)
    for package in packages:
        files = sorted((ROOT / package).rglob("*.py"))
        assert files, f"installed package {package} has no .py files under {ROOT / package}"
        for path in files:
            rel = path.relative_to(ROOT).as_posix()
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), rel)):
                if isinstance(node, ast.Import):
                    names = [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom):
                    if node.level or not node.module:
                        continue  # relative import: the package itself
                    names = [node.module]
                elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                    match = _INTERFACE_TYPE.match(node.value)
                    names = [match.group(1)] if match else []
                else:
                    continue
                for name in names:
                    top = name.partition(".")[0]
                    if top not in own and top not in sys.stdlib_module_names:
                        uses[top].append(f"{rel}:{node.lineno}")
    return dict(uses)


@functools.cache
def _uses() -> dict[str, list[str]]:
    """:func:`used_modules` of the installed packages, read once per session."""
    return used_modules()


def parse_package_xml(path: Path | None = None) -> tuple[dict[str, list[str]], dict[str, str]]:
    """(dependency name -> tags declaring it, pip-only distribution -> pinned version from the pip-only comment)."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.parse(path or PACKAGE_XML, parser).getroot()
    declared: dict[str, list[str]] = defaultdict(list)
    pins: dict[str, str] = {}
    for element in root:
        if element.tag is ET.Comment:
            text = element.text or ""
            if text.strip().startswith("pip-only"):
                for line in text.splitlines():
                    words = line.split()
                    match = _PINNED.match(words[0]) if words else None
                    if match:
                        pins[_norm(match.group(1))] = match.group(2)
        elif isinstance(element.tag, str) and element.tag.endswith("depend"):
            declared[(element.text or "").strip()].append(element.tag)
    return dict(declared), pins


def snippet_pip_command(path: Path | None = None) -> list[str]:
    """The requirements of the snippet's one ``pip install`` command."""
    text = (path or SNIPPET).read_text().replace("\\\n", " ")
    commands = [line for line in text.splitlines() if re.search(r"\bpip install\b", line) and "==" in line]
    assert len(commands) == 1, f"{SNIPPET.relative_to(ROOT)} should have one pip install command, has {commands}"
    words = shlex.split(commands[0].split("pip install", 1)[1])
    return [w for w in words if not w.startswith("-")]


def lock_pins(path: Path | None = None) -> dict[str, str]:
    pins = {}
    for line in (path or LOCK).read_text().splitlines():
        match = _PINNED.match(line.split("#", 1)[0].strip().split(";", 1)[0].strip())
        if match:
            pins[_norm(match.group(1))] = match.group(2)
    return pins


def _pip_dists() -> dict[str, str]:
    """pip distribution (normalized) -> the module that needs it, for the modules in use."""
    uses = _uses()
    return {_norm(dep[4:]): module for module, dep in MODULE_DEPS.items() if dep.startswith("pip:") and module in uses}


def test_installed_packages_are_read():
    packages = installed_packages()
    assert packages[0] == "lightfast" and len(packages) > 1
    uses = used_modules(packages)
    assert "rclpy" in uses and "numpy" in uses, sorted(uses)


def test_every_imported_module_is_in_the_table():
    unknown = {m: places for m, places in _uses().items() if m not in MODULE_DEPS}
    assert not unknown, "\n".join(
        f"module {m!r} (imported in {', '.join(places[:3])}) is not in MODULE_DEPS of test/unit/test_package_xml.py: "
        f"add it there, mapped to its ROS package name, its rosdep key (rosdistro rosdep/python.yaml) or "
        f"'pip:<distribution>' when no rosdep key fits, and declare it in package.xml"
        for m, places in sorted(unknown.items()))


def test_every_imported_module_is_declared():
    declared, pip_pins = parse_package_xml()
    problems = []
    for module, places in sorted(_uses().items()):
        dep = MODULE_DEPS.get(module)
        if dep is None:
            continue  # test_every_imported_module_is_in_the_table reports it
        where = ", ".join(places[:3]) + (f" and {len(places) - 3} more" if len(places) > 3 else "")
        if dep.startswith("pip:"):
            if _norm(dep[4:]) not in pip_pins:
                problems.append(f"module {module!r} (imported in {where}) is pip-only ({dep[4:]}) but not in "
                                f"package.xml's pip-only comment: add '{dep[4:]}==<version>' there")
        elif not set(declared.get(dep, ())) & RUN_TAGS:
            problems.append(f"module {module!r} (imported in {where}) needs <exec_depend>{dep}</exec_depend> "
                            f"in package.xml")
    assert not problems, "\n".join(problems)


def test_nothing_is_declared_that_nothing_imports():
    declared, pip_pins = parse_package_xml()
    needed = {MODULE_DEPS[m] for m in _uses() if m in MODULE_DEPS}
    problems = [f"package.xml declares {name!r} ({', '.join(sorted(tags))}) but no module in MODULE_DEPS that the "
                f"installed packages import maps to it: remove it, or add it to ALLOWED_UNUSED with the reason"
                for name, tags in sorted(declared.items())
                if set(tags) - EXEMPT_TAGS and name not in needed and name not in ALLOWED_UNUSED]
    needed_pip = {_norm(d[4:]) for d in needed if d.startswith("pip:")}
    problems += [f"package.xml's pip-only comment lists {dist!r} but no module in MODULE_DEPS that the installed "
                 f"packages import maps to it: remove it"
                 for dist in sorted(set(pip_pins) - needed_pip)]
    problems += [f"ALLOWED_UNUSED names {name!r}, which package.xml does not declare: remove it from ALLOWED_UNUSED"
                 for name in sorted(set(ALLOWED_UNUSED) - set(declared))]
    problems += [f"package.xml declares {name!r} more than once ({', '.join(tags)}): keep one entry"
                 for name, tags in sorted(declared.items()) if len(tags) > 1]
    assert not problems, "\n".join(problems)


def test_table_has_no_stale_entries():
    stale = sorted(m for m in set(MODULE_DEPS) - set(_uses()) if MODULE_DEPS[m] not in ALLOWED_UNUSED)
    assert not stale, (f"MODULE_DEPS maps {stale}, which no installed package imports any more: remove them from "
                       f"the table (and their entries from package.xml)")


def test_pip_only_list_matches_the_snippet_and_the_lock():
    _, comment_pins = parse_package_xml()
    lock = lock_pins()
    needed = _pip_dists()
    problems = []
    command = snippet_pip_command()
    command_pins = {}
    for requirement in command:
        match = _PINNED.match(requirement)
        if match:
            command_pins[_norm(match.group(1))] = match.group(2)
        elif requirement not in PIP_COMMAND_EXTRAS:
            problems.append(f"the snippet's pip command has {requirement!r}: pin it as dist==version (or list it "
                            f"in PIP_COMMAND_EXTRAS with the reason)")
    for dist in sorted(set(needed) | set(comment_pins) | set(command_pins)):
        expected = JAZZY_PINS[dist][0] if dist in JAZZY_PINS else lock.get(dist)
        if expected is None:
            problems.append(f"{dist} is not pinned in requirements.lock")
        for source, pins in (("package.xml's pip-only comment", comment_pins),
                             (f"the pip command of {SNIPPET.relative_to(ROOT)}", command_pins)):
            if pins.get(dist) != expected:
                problems.append(f"{source} has {dist}=={pins.get(dist)}, expected {dist}=={expected} "
                                f"({'JAZZY_PINS' if dist in JAZZY_PINS else 'requirements.lock'})"
                                + ("" if dist in needed else "; nothing imports it"))
    assert not problems, "\n".join(problems)
