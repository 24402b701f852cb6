"""What a benchmark or evaluation ran on: the CPU model, core count and Python version, for its results file
(timings are comparable only on the same CPU)."""
from __future__ import annotations

import os
import platform
from pathlib import Path


def cpu_model() -> str:
    """The CPU's model name from ``/proc/cpuinfo`` (else :func:`platform.processor`, else ``"unknown CPU"``)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine_info() -> dict[str, str | int | None]:
    """``cpu``, ``cpus`` (cores this process may use) and ``python``."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {"cpu": cpu_model(), "cpus": cpus, "python": platform.python_version()}


def describe_machine() -> str:
    """One line for a results file: ``"<CPU>, <n> cores, Python <version>"``."""
    m = machine_info()
    return f"{m['cpu']}, {m['cpus']} cores, Python {m['python']}"
