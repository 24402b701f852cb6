"""The light sets L_sun, L_sky and L_grd of the outdoor illumination model (Krawez et al., §III-A).

The outside world is a sphere of infinite radius; every point l on it is a directional light with direction n(l).
The sky and ground sets split a nearly uniform set of sphere directions by the horizon plane (the paper uses an
icosphere; :func:`fibonacci_sphere` gives the same uniformity for any count). The sun set spreads samples
uniformly over the solar disk around the computed sun direction, so that the sun shines "around" edges and casts
the soft shadow borders of Fig. 4 instead of the hard ones of a point sun.

All directions point from the scene *to* the light, in the map frame (z up unless told otherwise).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.daylight.errors import LightsError
from lightfast.geometry import unit_vector

__all__ = [
    "GOLDEN_ANGLE",
    "SUN_ANGULAR_DIAMETER_DEG",
    "LightSet",
    "fibonacci_sphere",
    "sky_and_ground",
    "sun_disk",
]

#: The golden angle pi (3 - sqrt 5) in radians, the azimuth step of Fibonacci and Vogel spirals.
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))
#: Mean angular diameter of the sun seen from Earth, degrees.
SUN_ANGULAR_DIAMETER_DEG = 0.533
_UNIT_TOL = 1e-6


@dataclass(frozen=True, eq=False)
class LightSet:
    """A set of M directional lights of one illumination component, all with the same brightness scale s_x.

    ``directions`` (M, 3) are unit vectors pointing *to* the lights in the map frame; ``weights`` (M,) say what
    each direction stands for: the solid angle in steradians for sky and ground (so the weights of a full sphere
    sum to 4π), or the fraction of the sun's normal irradiance for the sun (1/M each, summing to 1).

    With these weights the irradiance of an unoccluded surface with unit normal n under the set at unit brightness
    is ``Σ w · max(0, n · d)`` (:meth:`irradiance`). For the sky (uniform radiance 1) that approximates
    ``∫ L cosθ dω`` over the sky hemisphere, π for an open horizontal floor; for the sun it is the cosine of the
    incidence angle (normal irradiance 1). M may be 0 (e.g. the sun below the horizon). Arrays are read-only.
    """

    directions: NDArray[np.float64]
    weights: NDArray[np.float64]
    name: str

    def __post_init__(self) -> None:
        d = np.array(self.directions, dtype=np.float64)
        if d.size == 0:
            d = d.reshape(0, 3)
        w = np.array(self.weights, dtype=np.float64)
        if d.ndim != 2 or d.shape[1] != 3:
            raise LightsError(f"{self.name}: directions must have shape (M, 3), got {d.shape}")
        if w.shape != (len(d),):
            raise LightsError(f"{self.name}: weights must have shape ({len(d)},), got {w.shape}")
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(w))):
            raise LightsError(f"{self.name}: directions and weights must be finite")
        if np.any(w < 0.0):
            raise LightsError(f"{self.name}: weights must be non-negative")
        norms = np.linalg.norm(d, axis=1)
        if np.any(np.abs(norms - 1.0) > _UNIT_TOL):
            worst = float(np.max(np.abs(norms - 1.0)))
            raise LightsError(f"{self.name}: directions must be unit vectors (worst |norm - 1| = {worst:.3g})")
        d = d / norms[:, None]
        d.setflags(write=False)
        w.setflags(write=False)
        object.__setattr__(self, "directions", d)
        object.__setattr__(self, "weights", w)

    def __len__(self) -> int:
        return len(self.directions)

    @property
    def total_weight(self) -> float:
        """Σ w: the solid angle covered (sky, ground) or 1 (a non-empty sun)."""
        return float(self.weights.sum())

    def irradiance(self, normals: ArrayLike) -> NDArray[np.float64]:
        """``Σ w · max(0, n · d)`` for unit normals of shape (..., 3), ignoring occlusion; shape (...)."""
        n = np.asarray(normals, dtype=np.float64)
        if n.shape[-1:] != (3,):
            raise LightsError(f"normals must have shape (..., 3), got {n.shape}")
        return np.maximum(n @ self.directions.T, 0.0) @ self.weights


def fibonacci_sphere(n: int) -> NDArray[np.float64]:
    """``n`` nearly uniform unit directions (n, 3) on a Fibonacci spiral around +z (deterministic).

    Point i has ``z = 1 - (2i + 1)/n`` (equal-area bands) and azimuth ``i`` times the golden angle.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise LightsError(f"fibonacci_sphere needs an integer n >= 1, got {n!r}")
    i = np.arange(n, dtype=np.float64)
    z = 1.0 - (2.0 * i + 1.0) / n
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    phi = i * GOLDEN_ANGLE
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def _frame_around(axis: NDArray[np.float64], hint: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation (3, 3) whose third column is ``axis``; the first column is orthogonal to ``hint`` when possible."""
    ref = hint if np.linalg.norm(np.cross(axis, hint)) > 1e-6 else np.array([1.0, 0.0, 0.0])
    if np.linalg.norm(np.cross(axis, ref)) <= 1e-6:
        ref = np.array([0.0, 1.0, 0.0])
    u = np.cross(ref, axis)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    return np.stack([u, v, axis], axis=-1)


def _rotation_z_to(axis: NDArray[np.float64]) -> NDArray[np.float64]:
    """The smallest rotation (3, 3) taking +z to the unit vector ``axis`` (identity for +z)."""
    c = float(axis[2])
    if c < -1.0 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    K = np.array([[0.0, 0.0, axis[0]], [0.0, 0.0, axis[1]], [-axis[0], -axis[1], 0.0]])  # hat(z x axis)
    return np.eye(3) + K + K @ K / (1.0 + c)


def sky_and_ground(n_total: int, *, up: ArrayLike = (0.0, 0.0, 1.0)) -> tuple[LightSet, LightSet]:
    """L_sky and L_grd: ``n_total`` Fibonacci-sphere directions split by the horizon plane, each weighted 4π/n_total.

    The spiral's pole is aligned with ``up``, so the horizon falls between equal-area bands: directions with
    ``up · d > 0`` form the sky, the others (including one exactly on the horizon for odd ``n_total``) the ground.
    For even ``n_total`` the sky irradiance of a floor facing ``up`` is exactly π.
    """
    if isinstance(n_total, bool) or not isinstance(n_total, (int, np.integer)) or n_total < 2:
        raise LightsError(f"sky_and_ground needs an integer n_total >= 2, got {n_total!r}")
    up_u = unit_vector(up, "up", error=LightsError)
    local = fibonacci_sphere(int(n_total))
    dirs = local @ _rotation_z_to(up_u).T
    is_sky = local[:, 2] > 0.0  # up · d in exact arithmetic; immune to rounding for the horizon point
    weight = 4.0 * math.pi / n_total
    sky = LightSet(dirs[is_sky], np.full(int(is_sky.sum()), weight), "sky")
    ground = LightSet(dirs[~is_sky], np.full(int((~is_sky).sum()), weight), "ground")
    return sky, ground


def sun_disk(
    direction_to_sun: ArrayLike,
    n_samples: int,
    *,
    angular_diameter_deg: float = SUN_ANGULAR_DIAMETER_DEG,
    horizon_up: ArrayLike | None = None,
) -> LightSet:
    """L_sun: ``n_samples`` directions spread uniformly over the solar disk around ``direction_to_sun``.

    Samples sit on a point-symmetric Vogel spiral in the disk: for odd counts one sample is the centre, the rest
    come in pairs ``±p`` at stratified equal-area radii ``r_j = R sqrt((o + 2j + 1)/n)`` (``o`` = 1 for odd n,
    else 0) and golden-angle azimuths. Offsets are angular (exponential map around the centre), so every sample
    lies within ``R = angular_diameter_deg / 2`` of the centre and their mean direction is the centre.
    ``n_samples = 1`` gives the point sun. Weights are ``1/n`` each.

    With ``horizon_up`` given, a sun whose centre is on or below the horizon (``horizon_up · d <= 0``) yields an
    empty set. The spiral's orientation is fixed relative to ``horizon_up`` (or +z), so it does not spin as the
    sun moves.
    """
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise LightsError(f"sun_disk needs an integer n_samples >= 1, got {n_samples!r}")
    if not (math.isfinite(angular_diameter_deg) and 0.0 <= angular_diameter_deg < 180.0):
        raise LightsError(f"angular_diameter_deg must lie in [0, 180), got {angular_diameter_deg!r}")
    centre = unit_vector(direction_to_sun, "direction_to_sun", error=LightsError)
    hint = np.array([0.0, 0.0, 1.0])
    if horizon_up is not None:
        hint = unit_vector(horizon_up, "horizon_up", error=LightsError)
        if float(hint @ centre) <= 0.0:
            return LightSet(np.empty((0, 3)), np.empty(0), "sun")
    n = int(n_samples)
    odd = n % 2
    pairs = n // 2
    j = np.arange(pairs, dtype=np.float64)
    radius = math.radians(angular_diameter_deg) / 2.0
    rho = radius * np.sqrt((odd + 2.0 * j + 1.0) / n)
    phi = j * GOLDEN_ANGLE
    rho = np.concatenate([np.zeros(odd), rho, rho])
    phi = np.concatenate([np.zeros(odd), phi, phi + math.pi])
    R = _frame_around(centre, hint)
    local = np.stack([np.sin(rho) * np.cos(phi), np.sin(rho) * np.sin(phi), np.cos(rho)], axis=-1)
    return LightSet(local @ R.T, np.full(n, 1.0 / n), "sun")
