"""Reference irradiance from Radiance (``rtrace -I``): the oracle the daylight radiosity is validated against.

Implements the light model of the daylight paper (Krawez et al., RA-L 2021, §III-A) in Radiance: the outside world
is a sphere at infinity split by the horizon plane (normal ``up``) into three components, each computed separately
with unit brightness (:data:`COMPONENTS`):

* ``"sky"``: every direction ``d`` with ``up·d > 0`` has radiance 1 W/m²/sr in each RGB channel (a Radiance
  ``glow`` material of radiance (1, 1, 1) on a 180° ``source`` pointing up); a horizontal surface open to the whole
  upper hemisphere therefore receives ``π`` W/m².
* ``"ground"``: the same for ``up·d < 0``; there is no ground plane geometry, the lower hemisphere itself glows.
* ``"sun"``: a disk of 0.533° angular diameter in the direction ``sun_direction`` (unit vector from the scene
  towards the sun), a Radiance ``light`` of radiance ``1/Ω`` (``Ω = 2π(1 − cos 0.2665°)``), i.e. *normal*
  irradiance 1 W/m²; shadows from the disk centre (sharp) by default, ``sun_disk_samples=k`` sub-suns for penumbrae.

Output: the RGB irradiance ``E`` (W/m², direct plus all inter-reflections up to ``ambient_bounces``) at points (map
frame, metres) facing given unit normals; a Lambertian surface of reflectance ``ρ`` there has radiosity ``ρ·E``
and radiance ``ρ·E/π``, the paper's *normalized* quantity: scale by ``s_x`` to get component ``x``.

Scene translation: every triangle becomes a Radiance ``polygon`` with a purely Lambertian ``plastic`` material of
the triangle's mean vertex reflectance (one material per distinct reflectance rounded to 1e-4; Radiance polygons
are two-sided, which makes no difference in closed rooms). Query points are moved 1e-4 m along their normals.
Ambient settings (:data:`FIXED_RTRACE_OPTIONS`): no irradiance cache (``-aa 0``), no super-sampling (``-as 0``),
Russian roulette: unbiased Monte Carlo estimates per point (up to the ``-ab`` bounce limit) without interpolation
artefacts, but noisy on dark points: use ``repeats`` or :func:`radiance_irradiance_with_error`. The sky and ground
are found only by ambient rays that leave the scene, exactly as the light model defines them. Radiance ships with
the PyPI package ``pyradiance`` (importing it sets ``RAYPATH`` and ``PATH``); ``oconv`` and ``rtrace`` are run as
plain subprocesses. Design notes (rejected window portals, noise): docs/daylight.md.
"""
from __future__ import annotations

import contextlib
import math
import os
import shutil
import signal
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.geometry import unit_vector
from lightfast.sim.errors import RadianceError

Component = Literal["sun", "sky", "ground"]
COMPONENTS: tuple[str, ...] = ("sun", "sky", "ground")

SUN_DIAMETER_DEG = 0.533
"""Angular diameter of the sun disk (degrees)."""
SUN_SOLID_ANGLE_SR = 2.0 * math.pi * (1.0 - math.cos(math.radians(SUN_DIAMETER_DEG / 2.0)))
"""Solid angle of the sun disk (sr), ≈ 6.8e-5."""
POINT_OFFSET_M = 1e-4
"""Query points are moved this far along their normals before tracing."""

DEFAULT_AMBIENT_BOUNCES = 8
DEFAULT_AMBIENT_DIVISIONS = 2048
LIMIT_WEIGHT = 1e-5
FIXED_RTRACE_OPTIONS: tuple[str, ...] = (
    "-h",  # no header: the output is exactly 3 numbers per input line
    "-I",  # irradiance at (origin, direction = surface normal)
    "-aa", "0",  # no irradiance cache: unbiased Monte Carlo per point, no interpolation
    "-as", "0",  # NO ambient super-sampling: it is variance-driven and biased (-as 512 gave 20-25 % too little
                 # on dark points in the box room, checked against an independent path tracer)
    "-lw", f"{LIMIT_WEIGHT:g}",  # Russian roulette below this ray weight (see -lr)
    "-lr", "-12",  # roulette (unbiased, survivors re-weighted) instead of a hard cut; hard limit 12 reflections
    "-av", "0", "0", "0",  # no ambient value: light not traced is 0, never guessed
    "-aw", "0",
    "-dj", "0",  # shadow rays to the centre of each sun (sub-)disk: deterministic
    "-dt", "0",  # direct threshold 0: test every source, never approximate
    "-dc", "1",  # direct certainty 1
    "-w-",  # no warnings on stderr (e.g. "no light sources" for sky/ground); errors are still reported
)
"""``rtrace`` options that never change. ``-ab``, ``-ad`` and ``-n`` come from the arguments.

Convergence study (``box_room_with_window()``, 4.5 × 4.8 × 2.9 m, 1.6 × 1.5 m south window, grey walls ρ≈0.6,
sky component; 16 repetitions per setting; reference: an independent brute-force path tracer with unlimited bounces,
±0.5 %). Four dark points (irradiance 0.02-0.06 W/m², 1-3 % of the sky's π):

======================  ===========================  ==============================
setting                 mean / reference             per-point noise (1 σ)
======================  ===========================  ==============================
-ab 4                   0.75 / 0.85 / 0.91 / 0.91    5-9 %
-ab 6                   0.93 / 0.95 / 0.97 / 0.98    5-8 %
-ab 8                   0.99 / 0.95 / 0.99 / 0.99    4-7 %   (≈ 0.17 s per point, 2 cores)
-ab 12                  0.98 / 0.98 / 0.99 / 0.99    5-7 %
-ab 8 -ad 1024          0.97 / 0.99 / 0.99 / 1.01    7-9 %
-ab 8 -ad 4096          0.96 / 1.00 / 0.99 / 0.99    4-5 %   (≈ 0.31 s per point)
-ab 8 -as 512           0.72 / 0.77 / 0.86 / 0.81    biased (super-sampling)
======================  ===========================  ==============================

``-ab 8`` is within ~2 % (the resolution of this study) of the unlimited-bounce value; the noise of a single dark
point is ~5 %, so average ``repeats`` independent traces (noise ∝ 1/√repeats) when per-point precision matters. Sun
component: ~2 % noise on shadowed points at ``-ab 8``. Points that see the sky or sun directly are much less noisy
(< 1 %).
"""


def radiance_bin_dir() -> Path | None:
    """The folder holding ``oconv`` and ``rtrace``: pyradiance's ``bin`` if importable, else ``PATH``; None if
    neither has them."""
    try:
        import pyradiance  # sets RAYPATH and PATH on import

        candidate = Path(pyradiance.BINPATH)
        if (candidate / "rtrace").is_file() and (candidate / "oconv").is_file():
            return candidate
    except ImportError:
        pass
    rtrace, oconv = shutil.which("rtrace"), shutil.which("oconv")
    if rtrace and oconv and Path(rtrace).parent == Path(oconv).parent:
        return Path(rtrace).parent
    return None


def radiance_available() -> bool:
    """True if the Radiance binaries can be found."""
    return radiance_bin_dir() is not None


def _radiance_env(bin_dir: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = str(bin_dir) + os.pathsep + env.get("PATH", "")
    lib = bin_dir.parent / "lib"
    raypath = [p for p in env.get("RAYPATH", "").split(os.pathsep) if p]
    for p in (str(lib), "."):
        if p not in raypath and (p == "." or lib.is_dir()):
            raypath.insert(0, p)
    env["RAYPATH"] = os.pathsep.join(raypath)
    return env


def _first_lines(text: str, n: int = 8) -> str:
    lines = [ln for ln in text.strip().splitlines() if ln.strip()]
    return "\n".join(lines[:n]) if lines else "(no output on stderr)"


def _run(cmd: Sequence[str], *, cwd: Path, env: dict[str, str], timeout_s: float, stdin: bytes | None = None,
         stdout_path: Path | None = None) -> bytes:
    """Run ``cmd`` in its own process group (rtrace ``-n`` forks); kill the group on timeout. Returns stdout (or
    writes it to ``stdout_path``)."""
    with contextlib.ExitStack() as stack:
        out_file = stack.enter_context(open(stdout_path, "wb")) if stdout_path is not None else None
        try:
            proc = subprocess.Popen(
                list(cmd), cwd=cwd, env=env, stdin=subprocess.PIPE if stdin is not None else subprocess.DEVNULL,
                stdout=out_file if out_file is not None else subprocess.PIPE, stderr=subprocess.PIPE,
                start_new_session=True,
            )
        except OSError as exc:
            raise RadianceError(f"cannot start {cmd[0]}: {exc}") from None
        try:
            out, err = proc.communicate(stdin, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            raise RadianceError(f"{Path(cmd[0]).name} did not finish within {timeout_s:g} s") from None
    if proc.returncode != 0:
        raise RadianceError(
            f"{Path(cmd[0]).name} failed (exit code {proc.returncode}):\n{_first_lines(err.decode(errors='replace'))}"
        )
    return out if out is not None else b""


def _fmt(x: NDArray[np.float64]) -> str:
    return " ".join(f"{v:.9g}" for v in x)


def _sun_disk(direction: NDArray[np.float64], samples: int) -> list[tuple[NDArray[np.float64], float]]:
    """``samples`` sub-suns tiling the sun disk: (unit direction, angular diameter in degrees) each, of equal solid
    angle ``Ω/samples``, centred on a sunflower (Vogel) pattern over the disk."""
    if samples == 1:
        return [(direction, SUN_DIAMETER_DEG)]
    alpha = math.radians(SUN_DIAMETER_DEG / 2.0)
    e1 = np.cross(direction, [1.0, 0.0, 0.0] if abs(direction[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(direction, e1)
    sub_omega = SUN_SOLID_ANGLE_SR / samples
    sub_diameter = 2.0 * math.degrees(math.acos(1.0 - sub_omega / (2.0 * math.pi)))
    golden = math.pi * (3.0 - math.sqrt(5.0))
    out = []
    for k in range(samples):
        r = math.tan(alpha) * math.sqrt((k + 0.5) / samples)
        d = direction + r * (math.cos(k * golden) * e1 + math.sin(k * golden) * e2)
        out.append((d / np.linalg.norm(d), sub_diameter))
    return out


def light_description(component: Component, *, sun_direction: ArrayLike | None = None, sun_disk_samples: int = 1,
                      up: ArrayLike = (0.0, 0.0, 1.0)) -> str:
    """The Radiance primitives of one unit-brightness light component (see the module docstring and
    :func:`radiance_irradiance`)."""
    if component == "sun":
        if sun_direction is None:
            raise RadianceError('component "sun" needs sun_direction (unit vector towards the sun)')
        if int(sun_disk_samples) < 1:
            raise RadianceError(f"sun_disk_samples must be >= 1, got {sun_disk_samples}")
        d = unit_vector(sun_direction, "sun_direction", error=RadianceError)
        radiance = 1.0 / SUN_SOLID_ANGLE_SR  # every sub-sun has the disk's radiance and 1/samples of its area
        parts = [f"void light sun_light\n0\n0\n3 {radiance:.9g} {radiance:.9g} {radiance:.9g}\n"]
        for k, (dk, diameter) in enumerate(_sun_disk(d, int(sun_disk_samples))):
            parts.append(f"sun_light source sun{k}\n0\n0\n4 {_fmt(dk)} {diameter:.9g}\n")
        return "\n".join(parts)
    if component in ("sky", "ground"):
        u = unit_vector(up, "up", error=RadianceError)
        if component == "ground":
            u = -u + 0.0  # + 0.0: no "-0" in the file
        return (
            f"void glow {component}_glow\n0\n0\n4 1 1 1 0\n\n"
            f"{component}_glow source {component}\n0\n0\n4 {_fmt(u)} 180\n"
        )
    raise RadianceError(f"component must be one of {COMPONENTS}, got {component!r}")


def scene_description(mesh: ReflectanceMesh) -> str:
    """The mesh as Radiance ``plastic`` materials (one per distinct reflectance, rounded to 1e-4) and ``polygon``
    triangles."""
    rho = np.round(mesh.face_reflectance, 4)
    keys, inverse = np.unique(rho, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    tri = mesh.vertices_m[mesh.faces].reshape(-1, 9)
    parts: list[str] = []
    for k, key in enumerate(keys):
        parts.append(f"void plastic mat{k}\n0\n0\n5 {key[0]:.4f} {key[1]:.4f} {key[2]:.4f} 0 0\n")
    for k in range(len(keys)):
        idx = np.flatnonzero(inverse == k)
        lines = [f"mat{k} polygon t{i}\n0\n0\n9 " + _fmt(tri[i]) for i in idx]
        parts.append("\n".join(lines) + "\n")
    return "\n".join(parts)


def rtrace_options(*, ambient_bounces: int = DEFAULT_AMBIENT_BOUNCES,
                   ambient_divisions: int = DEFAULT_AMBIENT_DIVISIONS, processes: int = 2) -> list[str]:
    """The ``rtrace`` command-line options (without the octree) used by :func:`radiance_irradiance`."""
    return ["-ab", str(int(ambient_bounces)), "-ad", str(int(ambient_divisions)), *FIXED_RTRACE_OPTIONS,
            "-n", str(int(processes))]


def _irradiance_samples(
    mesh: ReflectanceMesh, points_m: ArrayLike, normals: ArrayLike, *, component: Component,
    sun_direction: ArrayLike | None, sun_disk_samples: int, ambient_bounces: int, ambient_divisions: int,
    repeats: int, processes: int, up: ArrayLike, workdir: str | os.PathLike[str] | None, timeout_s: float,
) -> NDArray[np.float64]:
    """``(repeats, N, 3)`` independent ``rtrace -I`` estimates (one run; the rays are listed ``repeats`` times)."""
    if component not in COMPONENTS:
        raise RadianceError(f"component must be one of {COMPONENTS}, got {component!r}")
    if int(ambient_bounces) < 0 or int(ambient_divisions) < 1 or int(processes) < 1 or int(repeats) < 1:
        raise RadianceError("ambient_bounces must be >= 0; ambient_divisions, processes and repeats >= 1")
    p = np.asarray(points_m, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or n.shape != p.shape:
        raise RadianceError(f"points_m and normals must both have shape (N, 3), got {p.shape} and {n.shape}")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(n))):
        raise RadianceError("points_m and normals must be finite")
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    if np.any(norm < 1e-12):
        raise RadianceError("normals must be non-zero")
    n = n / norm
    lights = light_description(component, sun_direction=sun_direction, sun_disk_samples=sun_disk_samples, up=up)
    if len(p) == 0:
        return np.zeros((int(repeats), 0, 3))
    bin_dir = radiance_bin_dir()
    if bin_dir is None:
        raise RadianceError("Radiance binaries (oconv, rtrace) not found: install pyradiance or put them on PATH")
    env = _radiance_env(bin_dir)

    with tempfile.TemporaryDirectory(prefix="lightfast-radiance-") as tmp:
        wd = Path(workdir) if workdir is not None else Path(tmp)
        wd.mkdir(parents=True, exist_ok=True)
        (wd / "scene.rad").write_text(scene_description(mesh))
        (wd / "lights.rad").write_text(lights)
        _run([str(bin_dir / "oconv"), "-f", "lights.rad", "scene.rad"], cwd=wd, env=env, timeout_s=timeout_s,
             stdout_path=wd / "scene.oct")
        origins = p + POINT_OFFSET_M * n
        rays = "\n".join(_fmt(row) for row in np.concatenate([origins, n], axis=1)) + "\n"
        (wd / "rays.txt").write_text(rays)
        cmd = [str(bin_dir / "rtrace"),
               *rtrace_options(ambient_bounces=ambient_bounces, ambient_divisions=ambient_divisions,
                               processes=processes),
               "scene.oct"]
        out = _run(cmd, cwd=wd, env=env, timeout_s=timeout_s, stdin=(rays * int(repeats)).encode())
    try:
        values = np.array(out.split(), dtype=np.float64)
    except ValueError:
        raise RadianceError(f"rtrace printed something that is not numbers: {out[:200]!r}") from None
    expected = 3 * len(p) * int(repeats)
    if values.size != expected:
        raise RadianceError(f"rtrace returned {values.size} numbers for {len(p)} points x {repeats} (expected "
                            f"{expected})")
    return values.reshape(int(repeats), len(p), 3)


def radiance_irradiance(
    mesh: ReflectanceMesh,
    points_m: ArrayLike,
    normals: ArrayLike,
    *,
    component: Component,
    sun_direction: ArrayLike | None = None,
    sun_disk_samples: int = 1,
    ambient_bounces: int = DEFAULT_AMBIENT_BOUNCES,
    ambient_divisions: int = DEFAULT_AMBIENT_DIVISIONS,
    repeats: int = 1,
    processes: int = 2,
    up: ArrayLike = (0.0, 0.0, 1.0),
    workdir: str | os.PathLike[str] | None = None,
    timeout_s: float = 600.0,
) -> NDArray[np.float64]:
    """RGB irradiance (W/m², ``rtrace -I``) at ``points_m`` facing ``normals`` under one unit-brightness component.

    Args:
        mesh: the scene; every triangle is a Lambertian polygon of its face reflectance.
        points_m: ``(N, 3)`` query points in metres (mesh frame); moved 1e-4 m along ``normals`` before tracing.
        normals: ``(N, 3)`` directions the irradiance sensor faces (normalized here).
        component: ``"sun"``, ``"sky"`` or ``"ground"`` (see the module docstring).
        sun_direction: unit vector from the scene towards the sun; required for ``"sun"``.
        sun_disk_samples: 1: the sun is one Radiance source whose shadows are cast from the disk centre (sharp);
            ``k > 1``: the disk is tiled by ``k`` equal sub-suns, so penumbrae (0.0093 × distance to the occluder
            wide) come out as a ``k``-step ramp. The unshadowed irradiance is the same.
        ambient_bounces: ``-ab``, diffuse inter-reflections (8: within the noise of unlimited bounces for rooms of
            grey walls, see :data:`FIXED_RTRACE_OPTIONS`).
        ambient_divisions: ``-ad``, hemisphere samples at the query point.
        repeats: trace every point this many times (independent Monte Carlo estimates) and return the mean.
        processes: ``-n``, rtrace processes.
        up: the horizon plane's normal (sky above, ground below).
        workdir: where the scene, octree and rays are written (kept); a temporary folder (removed) by default.
        timeout_s: limit for each of ``oconv`` and ``rtrace``.

    Returns:
        ``(N, 3)`` float64 irradiance per RGB channel.

    Raises:
        RadianceError: binaries missing, bad arguments, a non-zero exit, or an unexpected amount of output.
    """
    samples = _irradiance_samples(
        mesh, points_m, normals, component=component, sun_direction=sun_direction, sun_disk_samples=sun_disk_samples,
        ambient_bounces=ambient_bounces, ambient_divisions=ambient_divisions, repeats=repeats, processes=processes,
        up=up, workdir=workdir, timeout_s=timeout_s,
    )
    return samples.mean(axis=0)


def radiance_irradiance_with_error(
    mesh: ReflectanceMesh,
    points_m: ArrayLike,
    normals: ArrayLike,
    *,
    component: Component,
    sun_direction: ArrayLike | None = None,
    sun_disk_samples: int = 1,
    ambient_bounces: int = DEFAULT_AMBIENT_BOUNCES,
    ambient_divisions: int = DEFAULT_AMBIENT_DIVISIONS,
    repeats: int = 4,
    processes: int = 2,
    up: ArrayLike = (0.0, 0.0, 1.0),
    workdir: str | os.PathLike[str] | None = None,
    timeout_s: float = 600.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Like :func:`radiance_irradiance`, also returning the Monte Carlo standard error of each mean.

    Returns:
        ``(mean, standard_error)``, both ``(N, 3)``; the standard error is the sample standard deviation of the
        ``repeats`` (>= 2) independent estimates divided by ``sqrt(repeats)``.
    """
    if int(repeats) < 2:
        raise RadianceError(f"repeats must be >= 2 to estimate an error, got {repeats}")
    samples = _irradiance_samples(
        mesh, points_m, normals, component=component, sun_direction=sun_direction, sun_disk_samples=sun_disk_samples,
        ambient_bounces=ambient_bounces, ambient_divisions=ambient_divisions, repeats=repeats, processes=processes,
        up=up, workdir=workdir, timeout_s=timeout_s,
    )
    return samples.mean(axis=0), samples.std(axis=0, ddof=1) / math.sqrt(int(repeats))
