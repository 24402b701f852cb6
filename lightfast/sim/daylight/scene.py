"""The daylight test room's records: the room frame, the window aperture and a generated scene.

Implements the setup of Krawez et al. (RA-L 2021) §IV-A: a 4.5 × 4.8 × 2.9 m room (x ∈ [0, 4.5], y ∈ [0, 4.8],
z ∈ [0, 2.9] m; floor at z = 0, z up) with **one window** in the wall y = 0. The map frame is ENU when the site
heading is 0, so the window looks south (outward normal −y); a site with another ``heading_deg`` rotates the world
around the room. The walls are 0.3 m thick: the opening is a tunnel through the wall, and the glass (not in the
mesh; the renderer models it as a transmittance) lies inside the outer wall plane.

* :class:`WindowGeometry`: the aperture rectangle in the **outer** wall plane (map frame, metres), through which
  all outdoor light enters; :func:`window_opening` turns it into the :class:`~lightfast.daylight.openings.Opening`
  a user of the method would measure (2 cm tape-measure margin).
* :class:`DaylightScene`: the reflectance mesh (map frame, metres, linear RGB reflectance in
  [:data:`RHO_MIN`, :data:`RHO_MAX`]), its window, the room size, the default site and the furniture bounds
  (:class:`Box`, for camera trajectories). The scenes DS1 and DS2 are built by :mod:`lightfast.sim.daylight.rooms`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.daylight.openings import Opening
from lightfast.daylight.sun import FREIBURG, Site

__all__ = [
    "RHO_MAX",
    "RHO_MIN",
    "ROOM_SIZE_M",
    "Box",
    "DaylightScene",
    "WindowGeometry",
    "window_opening",
]

#: Room extent (x, y, z) in metres, like the paper's test room.
ROOM_SIZE_M = (4.5, 4.8, 2.9)
#: Reflectance bounds of every generated vertex.
RHO_MIN, RHO_MAX = 0.03, 0.9


# ----------------------------------------------------------------------------------------------------------------
# geometry records


@dataclass(frozen=True)
class WindowGeometry:
    """The window aperture: the opening rectangle in the **outer** wall plane, through which all outdoor light
    enters the room.

    ``center_m`` is the centre of the outer rectangle, ``normal`` its unit outward normal, ``axis_u`` (horizontal)
    and ``axis_v`` (up) its unit in-plane axes, ``half_u_m``/``half_v_m`` its half sizes. The opening runs through
    the wall over ``wall_thickness_m`` (the inner rectangle is ``center_m - wall_thickness_m * normal``). The glass
    pane (not in the mesh) lies in the plane ``glass_depth_m`` inside the outer plane.
    """

    center_m: tuple[float, float, float]
    normal: tuple[float, float, float]
    axis_u: tuple[float, float, float]
    axis_v: tuple[float, float, float]
    half_u_m: float
    half_v_m: float
    wall_thickness_m: float
    glass_depth_m: float

    @property
    def area_m2(self) -> float:
        return 4.0 * self.half_u_m * self.half_v_m

    def corners_m(self) -> NDArray[np.float64]:
        """The outer rectangle's corners (4, 3), counter-clockwise seen from outside."""
        c, u, v = np.array(self.center_m), np.array(self.axis_u), np.array(self.axis_v)
        return np.array([c + su * self.half_u_m * u + sv * self.half_v_m * v
                         for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))])

    def glass_signed_distance(self, points_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """Signed distance (m) of points to the glass plane, positive outside (towards ``normal``)."""
        c = np.array(self.center_m) - self.glass_depth_m * np.array(self.normal)
        return (np.asarray(points_m) - c) @ np.array(self.normal)


def window_opening(window: WindowGeometry, *, margin_m: float = 0.02) -> Opening:
    """The window as the user of the method declares it (:mod:`lightfast.daylight.openings`): its outer rectangle,
    ``margin_m`` larger on every side (a tape-measure tolerance; the reveals block the rays that cross the margin)."""
    c, u, v = np.array(window.center_m), np.array(window.axis_u), np.array(window.axis_v)
    hu, hv = window.half_u_m + margin_m, window.half_v_m + margin_m
    corner = c - hu * u - hv * v
    return Opening(tuple(float(x) for x in corner), tuple(float(x) for x in 2 * hu * u),  # type: ignore[arg-type]
                   tuple(float(x) for x in 2 * hv * v), name="window")  # type: ignore[arg-type]


@dataclass(frozen=True)
class Box:
    """An obstacle for trajectory planning: axis-aligned bounds (min, max) in metres (before the box's yaw)."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]


@dataclass(frozen=True, eq=False)
class DaylightScene:
    """A generated scene: the reflectance mesh, its window, the room size, the default site and the furniture
    bounds (for camera trajectories)."""

    name: str
    mesh: ReflectanceMesh
    window: WindowGeometry
    room_size_m: tuple[float, float, float]
    site: Site = FREIBURG
    obstacles: tuple[Box, ...] = field(default=())
    resolution_m: float = 0.02
