"""Where outdoor light enters the room: the window openings of a scene (paper §III-A, §IV-A).

The outdoor model of §III-A puts the sky, ground and sun on a sphere around the scene and lets a directional light
``l`` reach a vertex when "the ray with direction n(l), starting at v_i, does not intersect any scene geometry"
(G(l, v) in Eq. 1). On a *reconstructed* mesh that test also lets light in through every hole the scan left — the
wall behind a cabinet, the underside of a table, a corner no standpoint saw — and such a leak puts a bright,
smooth spot into the relit reference where the live image has none (a plain wall beside a 5-cm gap behind a box,
simulated DS2: 3–4× the wall's sky irradiance), which the photometric term of f2m then follows.

A room's windows are known to whoever maps it, so a lighting map can be told where they are: a list of
parallelograms (``corner_m``, ``edge_u_m``, ``edge_v_m`` in the map frame; any plane across the opening will do,
e.g. the window's outer rectangle). With openings given, a ray that leaves the mesh counts as outdoor light only if
it crosses one of them; any other escaping ray is taken to hit unreconstructed geometry (no light). Without
openings every escaping ray counts, as in the paper.

File format (YAML, ``yaml.safe_load``)::

    format: lightfast-openings
    version: 1
    openings:
      - name: south window            # optional
        corner_m: [1.35, -0.3, 0.8]
        edge_u_m: [1.8, 0.0, 0.0]
        edge_v_m: [0.0, 0.0, 1.6]
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from lightfast.daylight.errors import OpeningsError
from lightfast.io import read_versioned_yaml, write_text_atomic

__all__ = ["Opening", "load_openings", "openings_array", "save_openings", "through_openings"]

FORMAT_NAME = "lightfast-openings"
FORMAT_VERSION = 1
_PLANE_TOLERANCE_M = 1e-3  # a ray starting this close to an opening's plane (e.g. on its sill) starts in it


@dataclass(frozen=True)
class Opening:
    """A parallelogram ``corner_m + a·edge_u_m + b·edge_v_m``, ``a, b ∈ [0, 1]``, in the map frame (metres)."""

    corner_m: tuple[float, float, float]
    edge_u_m: tuple[float, float, float]
    edge_v_m: tuple[float, float, float]
    name: str = ""

    def __post_init__(self) -> None:
        arr = np.array([self.corner_m, self.edge_u_m, self.edge_v_m], dtype=np.float64)
        if arr.shape != (3, 3) or not np.all(np.isfinite(arr)):
            raise OpeningsError(f"opening {self.name!r}: corner_m, edge_u_m, edge_v_m must be finite 3-vectors")
        if np.linalg.norm(np.cross(arr[1], arr[2])) < 1e-6:
            raise OpeningsError(f"opening {self.name!r}: its edges are parallel or zero (area < 1e-6 m²)")

    @property
    def array(self) -> NDArray[np.float64]:
        """(3, 3): corner, edge u, edge v."""
        return np.array([self.corner_m, self.edge_u_m, self.edge_v_m], dtype=np.float64)


def openings_array(openings: Sequence[Opening] | ArrayLike | None) -> NDArray[np.float64]:
    """(N, 3, 3) corner / edge u / edge v of each opening; (0, 3, 3) for none."""
    if openings is None:
        return np.zeros((0, 3, 3))
    if isinstance(openings, Sequence) and all(isinstance(o, Opening) for o in openings):
        ops = cast(Sequence[Opening], openings)  # every item checked above
        return np.stack([o.array for o in ops]) if len(ops) else np.zeros((0, 3, 3))
    arr = np.asarray(openings, dtype=np.float64).reshape(-1, 3, 3)
    for row in arr:
        Opening(tuple(row[0]), tuple(row[1]), tuple(row[2]))  # validates
    return arr


def through_openings(origins_m: NDArray[np.floating], directions: NDArray[np.floating],
                     openings: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Whether each ray ``origin + t·direction`` (unit ``directions``, t > -1 mm) crosses any of ``openings``
    (N, 3, 3); (M,) bool."""
    o = np.asarray(origins_m, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    out = np.zeros(len(d), dtype=bool)
    for corner, eu, ev in openings:
        n = np.cross(eu, ev)
        denom = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):  # rays parallel to the plane: t = ±inf / nan
            t = ((corner - o) @ n) / denom
            p = o + t[:, None] * d - corner
            # coordinates in the (eu, ev) basis of the plane
            g = np.array([[eu @ eu, eu @ ev], [eu @ ev, ev @ ev]])
            ab = np.linalg.solve(g, np.stack([p @ eu, p @ ev]))
        inside = (ab[0] >= 0) & (ab[0] <= 1) & (ab[1] >= 0) & (ab[1] <= 1)
        out |= (np.abs(denom) > 1e-12) & (t > -_PLANE_TOLERANCE_M) & inside
    return out


def save_openings(path: str | os.PathLike[str], openings: Sequence[Opening]) -> Path:
    """Write an openings file atomically."""
    doc = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "openings": [
        {**({"name": o.name} if o.name else {}), "corner_m": [float(x) for x in o.corner_m],
         "edge_u_m": [float(x) for x in o.edge_u_m], "edge_v_m": [float(x) for x in o.edge_v_m]}
        for o in openings]}
    path = Path(path)
    write_text_atomic(path, yaml.safe_dump(doc, sort_keys=False))
    return path


def load_openings(path: str | os.PathLike[str]) -> tuple[Opening, ...]:
    """Read an openings file (see the module docstring)."""
    path = Path(path)
    doc = read_versioned_yaml(path, format_name=FORMAT_NAME, version=FORMAT_VERSION, error=OpeningsError,
                              what="an openings file")
    items = doc.get("openings")
    if not isinstance(items, list) or not items:
        raise OpeningsError(f"{path}: 'openings' must be a non-empty list")
    out = []
    for i, item in enumerate(items):
        try:
            out.append(Opening(tuple(item["corner_m"]), tuple(item["edge_u_m"]), tuple(item["edge_v_m"]),
                               str(item.get("name", ""))))
        except (KeyError, TypeError) as exc:
            raise OpeningsError(f"{path}: opening {i}: needs corner_m, edge_u_m, edge_v_m ({exc})") from None
    return tuple(out)
