"""Outdoor light reaching the daylight room's surfaces through its window: glass, sun disk and direct sun.

Part of the ground-truth renderer (:mod:`lightfast.sim.daylight.renderer`), the *truth* the daylight method
(Krawez et al., RA-L 2021, §III-A: uniform directional light sets) is tested against; it shares neither its model
nor its code. :class:`RoomTracer` holds the scene: a :class:`~lightfast.daylight.mesh.ReflectanceMesh` (map frame,
metres, Lambertian, per-vertex linear RGB reflectance ρ interpolated barycentrically) with its Embree BVH, lit
through one :class:`~lightfast.sim.daylight.scene.WindowGeometry` (or ``None``: an open scene without walls) by the
outdoor light of :class:`~lightfast.sim.sky_model.SkyState`:

* the **sun**: a limb-darkened disk of radius 0.2666° (``I(μ) ∝ 1 - 0.6 (1 - μ)``, :data:`LIMB_DARKENING`) with
  direct normal irradiance DNI, sampled in stratified equal-area annuli (the subpixels of a pixel split them);
* the **glass pane** (:class:`GlassModel`): two-pane Fresnel transmittance (n = 1.52, multiple reflections, each
  polarization) times 0.96 absorption per pane along the refracted path (≈ 0.78 at normal incidence, falling off
  at grazing angles), for light reaching points inside the glass plane;
* the **direct sun** (:meth:`RoomTracer.direct_sun`): irradiance per unit DNI at points with given front normals,
  from stratified disk directions with shadow rays through the window's outer rectangle.

Units: radiance L in W m⁻² sr⁻¹, irradiance E in W m⁻², linear RGB; a Lambertian surface with irradiance E has
radiosity B = ρ E and radiance L = ρ E / π. Points and unit directions are in the map frame; the sun direction
points from the scene towards the sun.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.raycast import RayCaster
from lightfast.sim.daylight.scene import WindowGeometry
from lightfast.sim.sky_model import SUN_ANGULAR_RADIUS_RAD

__all__ = [
    "EPS_M",
    "LIMB_DARKENING",
    "GlassModel",
    "RoomTracer",
    "frames",
]

#: Limb-darkening coefficient of the solar disk (visible light).
LIMB_DARKENING = 0.6
EPS_M = 1e-4  # ray origin offset along the normal (m)

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class GlassModel:
    """Window glazing: ``panes`` clear panes of refractive index ``n`` (Fresnel reflection with inter-reflections
    per pane and between panes, each polarization separately) and ``absorption`` transmittance per pane at normal
    incidence (scaled to the refracted path length)."""

    panes: int = 2
    n: float = 1.52
    absorption: float = 0.96

    def transmittance(self, cos_theta: ArrayLike) -> F64:
        """Transmittance for light crossing the window at ``cos_theta`` from its normal (0 at grazing)."""
        c = np.clip(np.abs(np.asarray(cos_theta, dtype=np.float64)), 1e-6, 1.0)
        s = np.sqrt(1.0 - c**2)
        st = s / self.n
        ct = np.sqrt(1.0 - st**2)
        rs = ((c - self.n * ct) / (c + self.n * ct)) ** 2
        rp = ((ct - self.n * c) / (ct + self.n * c)) ** 2
        total = np.zeros_like(c)
        for r in (rs, rp):
            t1 = (1.0 - r) / (1.0 + r)  # one lossless pane with inter-reflections
            total += 0.5 * t1 / (self.panes - (self.panes - 1) * t1)
        return total * self.absorption ** (self.panes / ct)


# ----------------------------------------------------------------------------------------------------------------
# sampling helpers


def frames(n: F64) -> tuple[F64, F64]:
    """Two unit tangents completing unit normals ``n`` (..., 3) to right-handed frames (Duff et al. 2017)."""
    sign = np.where(n[..., 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    t1 = np.stack([1.0 + sign * n[..., 0] ** 2 * a, sign * b, -sign * n[..., 0]], axis=-1)
    t2 = np.stack([b, sign + n[..., 1] ** 2 * a, -n[..., 1]], axis=-1)
    return t1, t2


def _sun_disk_directions(sun: F64, annuli: NDArray[np.int64], n_annuli: int, theta0: F64,
                         rng: np.random.Generator) -> tuple[F64, F64]:
    """Stratified directions inside the solar disk, ``annuli.shape + (3,)``, and their limb-darkening weights
    (normalized to mean 1 over the disk). The disk is cut into ``n_annuli`` equal-area annuli; a sample of annulus
    ``a`` lies uniformly in it (random radius within the annulus) at the angle ``theta0 + a × golden angle``.
    With a uniformly random ``theta0`` every sample is uniform over its annulus, so any set of distinct annuli is an
    unbiased, stratified sample of the disk (the subpixels of a pixel share ``theta0`` and split the annuli)."""
    e1, e2 = frames(sun[None, :])
    e1, e2 = e1[0], e2[0]
    r = np.sqrt((annuli + rng.random(annuli.shape)) / n_annuli)
    theta = 2 * math.pi * ((theta0 + annuli * 0.6180339887) % 1.0)
    tan_a = math.tan(SUN_ANGULAR_RADIUS_RAD)
    off = (r * np.cos(theta))[..., None] * e1 + (r * np.sin(theta))[..., None] * e2
    d = sun + tan_a * off
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    mu = np.sqrt(np.clip(1.0 - r**2, 0.0, 1.0))
    w = (1.0 - LIMB_DARKENING * (1.0 - mu)) / (1.0 - LIMB_DARKENING / 3.0)
    return d, w


# ----------------------------------------------------------------------------------------------------------------
# the scene with its window


class RoomTracer:
    """The scene a ground-truth renderer traces: a reflectance mesh (with its BVH) lit through ``window``
    (``None``: open scene, light reaches every surface directly from the sky), and the window's glass."""

    def __init__(self, mesh: ReflectanceMesh, window: WindowGeometry | None, *, glass: GlassModel | None = None,
                 num_threads: int | None = None) -> None:
        self.mesh = mesh
        self.window = window
        self.glass = glass if glass is not None else GlassModel()
        self.caster = RayCaster(mesh.vertices_m, mesh.faces, num_threads=num_threads)
        self._faces = mesh.faces
        self._face_normals = mesh.face_normals
        self._rho = mesh.reflectance.astype(np.float32)
        if window is not None:
            self._wc = np.array(window.center_m, dtype=np.float64)
            self._wn = np.array(window.normal, dtype=np.float64)
            self._wu = np.array(window.axis_u, dtype=np.float64)
            self._wv = np.array(window.axis_v, dtype=np.float64)
            self._inside = window.glass_signed_distance(mesh.vertices_m) < 0.0
        else:
            self._inside = np.zeros(mesh.num_vertices, dtype=bool)

    # --- window geometry ---------------------------------------------------------------------------------------

    def _crossing(self, points: F64, dirs: F64, margin_m: float = 0.0) -> tuple[NDArray[np.bool_], F64, F64]:
        """Whether rays ``points + t dirs`` (unit dirs, broadcastable) cross the window's outer rectangle at
        ``t >= 0``: (mask, t, cos to the window normal)."""
        assert self.window is not None
        basis = np.stack([self._wn, self._wu, self._wv], axis=1)  # (3, 3): columns n, u, v
        pr = (points - self._wc) @ basis  # point in window coordinates
        dr = dirs @ basis
        cw = dr[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -pr[..., 0] / cw
            ok = (cw > 1e-9) & (t >= -1e-6)
            ok &= np.abs(pr[..., 1] + t * dr[..., 1]) <= self.window.half_u_m + margin_m
            ok &= np.abs(pr[..., 2] + t * dr[..., 2]) <= self.window.half_v_m + margin_m
        return ok, np.where(ok, t, 0.0), cw

    def _glass(self, inside: NDArray[np.bool_], dirs: F64) -> F64:
        """Glass transmittance for rays leaving from points (inside flags) along unit ``dirs``."""
        if self.window is None:
            return np.ones(dirs.shape[:-1])
        return np.where(inside, self.glass.transmittance(dirs @ self._wn), 1.0)

    def _sun_enters(self, sun: F64) -> bool:
        return bool(sun[2] > 0.0 and (self.window is None or sun @ self._wn > 1e-6))

    # --- direct sun --------------------------------------------------------------------------------------------

    def direct_sun(self, points: F64, normals: F64, inside: NDArray[np.bool_], sun: ArrayLike, n_samples: int,
                   rng: np.random.Generator, *, group: NDArray[np.int64] | None = None, n_groups: int = 1,
                   theta0: F64 | None = None) -> F64:
        """Direct sun irradiance per unit DNI (N,) at ``points`` with front ``normals``: stratified limb-darkened
        disk samples with shadow rays, glass transmittance for points inside the glass.

        Without ``group`` every point takes ``n_samples`` samples over the whole disk. With ``group`` (N,) in
        ``[0, n_groups)``, ``n_samples`` is the budget of a *set* of ``n_groups`` points (the subpixels of one
        pixel, sharing ``theta0``): point ``g`` takes the annuli ``g, g + n_groups, ...`` of ``n_samples``, so each
        point is unbiased and the set together is stratified over the disk.
        """
        s = np.asarray(sun, dtype=np.float64)
        n = len(points)
        out = np.zeros(n)
        if n == 0 or not self._sun_enters(s):
            return out
        # cheap pre-test with the disk's central direction: facing the sun within the disk radius, window
        cos0 = normals @ s
        cand = cos0 > -0.005
        if self.window is not None:
            cand &= self._crossing(points, s[None, :], margin_m=0.05)[0]  # disk spread < 5 cm over 10 m
        idx = np.flatnonzero(cand)
        if len(idx) == 0:
            return out
        if group is None:
            annuli = np.broadcast_to(np.arange(n_samples), (len(idx), n_samples))
            t0 = rng.random((len(idx), 1))
        else:
            per = max(1, n_samples // n_groups)
            annuli = group[idx, None] + n_groups * np.arange(per)
            n_samples = per * n_groups
            t0 = (theta0[idx] if theta0 is not None else rng.random(len(idx)))[:, None]
        d, w = _sun_disk_directions(s, annuli, n_samples, t0, rng)
        p, nrm = points[idx], normals[idx]
        cos = np.einsum("nkj,nj->nk", d, nrm)
        live = cos > 0.0
        if self.window is not None:
            live &= self._crossing(p[:, None, :], d, margin_m=1e-3)[0]
        li = np.nonzero(live)
        org = p[li[0]] + EPS_M * nrm[li[0]]
        visible = ~self.caster.occluded(org, d[li])
        contrib = np.zeros_like(cos)
        contrib[li] = visible * cos[li] * w[li]
        if self.window is not None:
            contrib *= np.where(inside[idx, None], self.glass.transmittance(d @ self._wn), 1.0)
        out[idx] = contrib.mean(axis=1)
        return out
