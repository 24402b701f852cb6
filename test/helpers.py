"""Helpers shared by tests: bounded subprocesses and in-process ROS sessions."""
from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType

import cv2
import numpy as np

from lightfast.camera import PinholeCamera
from lightfast.ros.transport import local_transport_env

LIGHTFAST = [sys.executable, "-m", "lightfast"]


def child_env(domain_id: int, **extra: str) -> dict[str, str]:
    """Environment for a child process on ``domain_id`` with the local transport (discovery LOCALHOST)."""
    env = dict(os.environ)
    env.update(local_transport_env(discovery_range="LOCALHOST", domain_id=domain_id))
    env.update(extra)
    return env


@contextmanager
def bounded_process(
    cmd: Sequence[str], *, timeout_s: float, env: dict[str, str] | None = None, cwd: Path | None = None,
    stdout: int | None = subprocess.PIPE, stderr: int | None = subprocess.PIPE, kill_after_s: float = 20.0,
) -> Iterator[subprocess.Popen[str]]:
    """Start ``cmd`` under ``timeout -k`` in its own process group; whatever happens, it cannot outlive
    ``timeout_s + kill_after_s``, and leaving the block kills the whole group.

    ``kill_after_s`` is also the grace period of a signal sent to the process (``proc.send_signal`` or
    ``os.killpg``): timeout(1) forwards SIGINT/SIGTERM and SIGKILLs the group ``kill_after_s`` later, so a clean
    shutdown (a map saved, a bag closed, a demo's clean-up) must fit in it on a loaded machine too."""
    wrapped = ["timeout", "-k", f"{kill_after_s:g}", f"{timeout_s:g}", *cmd]
    proc = subprocess.Popen(wrapped, env=env, cwd=cwd, stdout=stdout, stderr=stderr, text=True,
                            start_new_session=True)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        proc.wait(timeout=kill_after_s + 5)


def run_bounded(cmd: Sequence[str], *, timeout_s: float, env: dict[str, str] | None = None,
                input_text: str | None = None) -> subprocess.CompletedProcess[str]:
    """Run ``cmd`` to completion under ``timeout -k``; returns its result (stdout/stderr as text)."""
    with bounded_process(cmd, timeout_s=timeout_s, env=env) as proc:
        out, err = proc.communicate(input=input_text, timeout=timeout_s + 30)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def load_benchmark(name: str) -> ModuleType:
    """``benchmarks/<name>.py`` imported as module ``name`` (registered in sys.modules: dataclasses look their
    module up)."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def distorted(image: np.ndarray, camera: PinholeCamera, model: str, coefficients: Sequence[float], *,
              nearest: bool = False, source: PinholeCamera | None = None) -> np.ndarray:
    """What a camera with lens ``model`` / ``coefficients`` (ROS ``CameraInfo.d``) and intrinsics ``camera`` records
    of a scene whose ideal pinhole image is ``image``: every recorded pixel samples the pinhole image where its ray
    goes (OpenCV's iterative point undistortion, run to convergence; bilinear, or ``nearest`` for depth), black /
    NaN where that is outside ``image``. ``source``: the pinhole camera of ``image`` if not ``camera`` -- a finer
    rendering (less resampling than a real lens's recording has) with a margin (a barrel lens sees beyond the
    pinhole image's edges)."""
    d = np.asarray(coefficients, dtype=np.float64)
    uv = camera.pixel_grid().reshape(-1, 1, 2)
    if model == "equidistant":
        xy = cv2.fisheye.undistortPoints(uv, camera.K, d, criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
                                                                      100, 1e-12))
    else:
        xy = cv2.undistortPointsIter(uv, camera.K, d, None, None, (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
                                                                    100, 1e-12))
    xy = xy.reshape(camera.height, camera.width, 2)
    fine = camera if source is None else source
    map_x = (fine.fx * xy[..., 0] + fine.cx).astype(np.float32)
    map_y = (fine.fy * xy[..., 1] + fine.cy).astype(np.float32)
    border = float("nan") if nearest else 0
    return cv2.remap(np.ascontiguousarray(image), map_x, map_y, cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=border)
