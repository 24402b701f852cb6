"""Outdoor light for the ground-truth renderer: sun, a non-uniform sky and a ground glow, in physical units.

This is the *truth* side of the daylight simulation, deliberately richer than the method's model of uniform
directional light sets (Krawez et al., RA-L 2021, §III-A): the sky brightness varies over the dome and with the sun.
Radiance is in W m⁻² sr⁻¹, irradiance in W m⁻², per **linear RGB channel**; directions are unit vectors in the map
frame (z up). A broadband value (DNI, DHI, GHI in W m⁻²) is split into channels by a colour vector of unit Rec. 709
luminance ``0.2126 R + 0.7152 G + 0.0722 B``, so the luminance-weighted channel sum reproduces the broadband value.

Sky luminance distributions (ISO 15469 / CIE S 011:2003): relative luminance of a sky element at zenith angle ``Z``
whose angular distance from the sun is ``χ``, the sun at zenith angle ``Zs``::

    L(Z, χ) / Lz = f(χ) φ(Z) / (f(Zs) φ(0)),   φ(Z) = 1 + a exp(b / cos Z),
    f(χ) = 1 + c (exp(d χ) - exp(d π/2)) + e cos² χ.

:data:`CIE_CLEAR_SKY` is the CIE standard general sky type 12 ("CIE standard clear sky, low luminance turbidity":
a = -1, b = -0.32, c = 10, d = -3, e = 0.45; the same function as Radiance's ``gensky +s``); the overcast component
is the CIE standard overcast sky (Moon & Spencer), ``L(Z) ∝ (1 + 2 cos Z) / 3``; for tests, :data:`UNIFORM_SKY` has
``F ≡ 1`` (``L = DHI / π``). A distribution is normalized so that the sky's diffuse horizontal irradiance equals a
given DHI: ``L = DHI · F(ω) / ∫ F cos Z dω``, the integral over the upper hemisphere on a 180 × 360 midpoint grid.

Ground: no outdoor geometry; directions below the horizon see a uniform Lambertian ground of radiance
``L_grd = albedo · GHI / π`` per channel (:data:`GROUND_ALBEDO_RGB`, grass/pavement mix). Sun: a disk of angular
radius :data:`SUN_ANGULAR_RADIUS_RAD` with the direct normal irradiance DNI (the disk's integral on a plane facing
the sun). Clear-sky DNI and DHI come from pvlib's simplified Solis model (Ineichen 2008) for the apparent elevation;
GHI = ``DNI cos Zs + DHI`` so the parts add up. Colours (simple, documented choices, not spectral): the sun from
Rayleigh + Ångström aerosol transmittance at 610/550/465 nm along the relative air mass (Kasten & Young), normalized
to unit luminance (white-ish at noon, orange near the horizon); :data:`CLEAR_SKY_RGB` (bluish) and
:data:`OVERCAST_SKY_RGB` (neutral, a touch blue) for the skies.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import SupportsFloat, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "CIE_CLEAR_SKY",
    "CIE_OVERCAST_SKY",
    "CLEAR_SKY_RGB",
    "GROUND_ALBEDO_RGB",
    "LUMA",
    "OVERCAST_SKY_RGB",
    "SUN_ANGULAR_RADIUS_RAD",
    "UNIFORM_SKY",
    "ClearSkyIrradiance",
    "SkyDistribution",
    "SkyState",
    "clear_sky_irradiance",
    "float3",
    "luminance",
    "sun_rgb",
]

def float3(values: Iterable[SupportsFloat]) -> tuple[float, float, float]:
    """``tuple(float(x) for x in values)`` for ``values`` known to hold three numbers (not checked), typed as a
    3-tuple."""
    return cast(tuple[float, float, float], tuple(float(x) for x in values))


#: Rec. 709 / sRGB luminance weights of linear RGB.
LUMA = np.array([0.2126, 0.7152, 0.0722])
#: Mean angular radius of the solar disk (0.2666°, i.e. a 0.533° diameter).
SUN_ANGULAR_RADIUS_RAD = math.radians(0.2666)
#: Linear RGB colour of the clear sky (unit luminance).
CLEAR_SKY_RGB = np.array([0.72, 0.98, 1.55]) / float(LUMA @ [0.72, 0.98, 1.55])
#: Linear RGB colour of the overcast sky (unit luminance).
OVERCAST_SKY_RGB = np.array([0.95, 1.0, 1.1]) / float(LUMA @ [0.95, 1.0, 1.1])
#: Ground albedo per channel.
GROUND_ALBEDO_RGB = np.array([0.2, 0.21, 0.16])


def luminance(rgb: ArrayLike) -> NDArray[np.float64]:
    """Rec. 709 luminance of linear RGB ``(..., 3)``."""
    return np.asarray(rgb, dtype=np.float64) @ LUMA


@dataclass(frozen=True)
class SkyDistribution:
    """A relative sky luminance distribution: CIE general sky parameters, the Moon–Spencer overcast sky or uniform.

    ``kind`` is ``"cie"`` (parameters ``a b c d e``), ``"overcast"`` (``(1 + 2 cos Z) / 3``) or ``"uniform"``.
    """

    name: str
    kind: str = "cie"
    a: float = 0.0
    b: float = 0.0
    c: float = 0.0
    d: float = 0.0
    e: float = 0.0

    def relative(self, directions: ArrayLike, sun_direction: ArrayLike) -> NDArray[np.float64]:
        """Relative luminance ``F(ω)`` (zenith = 1 for CIE types) of unit ``directions (..., 3)`` (z up) with the
        sun at unit ``sun_direction``; 0 below the horizon."""
        w = np.asarray(directions, dtype=np.float64)
        cos_z = w[..., 2]
        up = cos_z > 0.0
        if self.kind == "uniform":
            return np.where(up, 1.0, 0.0)
        if self.kind == "overcast":
            return np.where(up, (1.0 + 2.0 * np.clip(cos_z, 0, 1)) / 3.0, 0.0)
        s = np.asarray(sun_direction, dtype=np.float64)
        s = s / np.linalg.norm(s)
        cos_chi = np.clip(w @ s, -1.0, 1.0)
        chi = np.arccos(cos_chi)
        zs = math.acos(min(1.0, max(-1.0, float(s[2]))))
        safe = np.where(up, cos_z, 1.0)
        phi = 1.0 + self.a * np.exp(self.b / safe)
        f = 1.0 + self.c * (np.exp(self.d * chi) - math.exp(self.d * math.pi / 2)) + self.e * cos_chi**2
        phi0 = 1.0 + self.a * math.exp(self.b)
        fzs = 1.0 + self.c * (math.exp(self.d * zs) - math.exp(self.d * math.pi / 2)) + self.e * math.cos(zs) ** 2
        return np.where(up, f * phi / (fzs * phi0), 0.0)

    def horizontal_integral(self, sun_direction: ArrayLike, *, n_zenith: int = 180) -> float:
        """``∫ F(ω) cos Z dω`` over the upper hemisphere (sr), by the midpoint rule on an ``n × 2n`` grid."""
        if self.kind == "uniform":
            return math.pi
        nz, na = n_zenith, 2 * n_zenith
        z = (np.arange(nz) + 0.5) * (0.5 * math.pi / nz)
        az = (np.arange(na) + 0.5) * (2 * math.pi / na)
        Z, A = np.meshgrid(z, az, indexing="ij")
        dirs = np.stack([np.sin(Z) * np.cos(A), np.sin(Z) * np.sin(A), np.cos(Z)], axis=-1)
        F = self.relative(dirs, sun_direction)
        dw = np.sin(Z) * (0.5 * math.pi / nz) * (2 * math.pi / na)
        return float(np.sum(F * np.cos(Z) * dw))


#: CIE standard general sky type 12: CIE standard clear sky, low luminance turbidity.
CIE_CLEAR_SKY = SkyDistribution("CIE type 12 clear", "cie", a=-1.0, b=-0.32, c=10.0, d=-3.0, e=0.45)
#: CIE standard overcast sky (Moon & Spencer 1942): L(Z) = Lz (1 + 2 cos Z) / 3.
CIE_OVERCAST_SKY = SkyDistribution("CIE overcast", "overcast")
#: A uniform sky (test hook: closed-form irradiance π L).
UNIFORM_SKY = SkyDistribution("uniform", "uniform")


@dataclass(frozen=True)
class ClearSkyIrradiance:
    """Broadband clear-sky irradiances in W m⁻² (zero with the sun below the horizon)."""

    dni_wm2: float
    dhi_wm2: float
    ghi_wm2: float


def clear_sky_irradiance(elevation_deg: float, *, altitude_m: float = 0.0, aod700: float = 0.1,
                         precipitable_water_cm: float = 1.0) -> ClearSkyIrradiance:
    """DNI and DHI of a clear sky (pvlib ``simplified_solis``) at the apparent sun ``elevation_deg``; GHI as
    ``DNI sin(elevation) + DHI``. Pressure from the altitude (ISO 2533 barometric formula)."""
    if elevation_deg <= 0.0:
        return ClearSkyIrradiance(0.0, 0.0, 0.0)
    import pvlib  # slow import, only when needed

    pressure = 101325.0 * (1.0 - 2.25577e-5 * altitude_m) ** 5.25588
    r = pvlib.clearsky.simplified_solis(float(elevation_deg), aod700=aod700,
                                        precipitable_water=precipitable_water_cm, pressure=pressure)
    dni, dhi = max(0.0, float(r["dni"])), max(0.0, float(r["dhi"]))
    return ClearSkyIrradiance(dni, dhi, dni * math.sin(math.radians(elevation_deg)) + dhi)


def _air_mass(elevation_deg: float) -> float:
    """Relative optical air mass, Kasten & Young (1989)."""
    z = 90.0 - max(elevation_deg, 0.0)
    return 1.0 / (math.cos(math.radians(z)) + 0.50572 * (96.07995 - z) ** -1.6364)


def sun_rgb(elevation_deg: float) -> NDArray[np.float64]:
    """Unit-luminance linear RGB colour of direct sunlight: the relative spectral transmittance of Rayleigh
    (τ_R = 0.0088 λ^-4.05, λ in µm) and aerosol (β = 0.06, α = 1.3) extinction along the air mass, at 610, 550 and
    465 nm, relative to the transmittance at zenith (so the sun is white at high elevation)."""
    lam = np.array([0.61, 0.55, 0.465])
    tau = 0.0088 * lam**-4.05 + 0.06 * lam**-1.3
    m = _air_mass(elevation_deg)
    t = np.exp(-tau * (m - 1.0))
    return t / float(LUMA @ t)


@dataclass(frozen=True)
class SkyState:
    """The outdoor light at one instant, in physical units (see the module docstring).

    Attributes:
        sun_direction: (3,) unit vector towards the sun (map frame, z up).
        sun_dni_rgb: (3,) direct normal irradiance of the (possibly cloud-attenuated) sun per channel, W m⁻².
        clear_dhi_rgb: (3,) diffuse horizontal irradiance of the CIE clear-sky component per channel, W m⁻².
        overcast_dhi_rgb: (3,) diffuse horizontal irradiance of the overcast component per channel, W m⁻².
        ground_albedo_rgb: (3,) ground albedo; the ground radiance is ``albedo · GHI / π``.
        clear_sky: distribution of the clear component (a test may use :data:`UNIFORM_SKY`).
        overcast_sky: distribution of the overcast component.
    """

    sun_direction: tuple[float, float, float]
    sun_dni_rgb: tuple[float, float, float]
    clear_dhi_rgb: tuple[float, float, float]
    overcast_dhi_rgb: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ground_albedo_rgb: tuple[float, float, float] = tuple(GROUND_ALBEDO_RGB)
    clear_sky: SkyDistribution = CIE_CLEAR_SKY
    overcast_sky: SkyDistribution = CIE_OVERCAST_SKY

    @property
    def sun_up(self) -> bool:
        return self.sun_direction[2] > 0.0

    @property
    def ghi_rgb(self) -> NDArray[np.float64]:
        """Global horizontal irradiance per channel (W m⁻²)."""
        cz = max(0.0, self.sun_direction[2])
        return np.asarray(self.sun_dni_rgb) * cz + np.asarray(self.clear_dhi_rgb) + np.asarray(self.overcast_dhi_rgb)

    @property
    def ground_radiance_rgb(self) -> NDArray[np.float64]:
        """Radiance of the ground glow per channel (W m⁻² sr⁻¹)."""
        return np.asarray(self.ground_albedo_rgb) * self.ghi_rgb / math.pi

    def clear_sky_normalized(self, directions: ArrayLike) -> NDArray[np.float64]:
        """Clear-sky radiance per unit DHI (sr⁻¹): ``F(ω) / ∫ F cos Z dω``; 0 below the horizon."""
        return self.clear_sky.relative(directions, self.sun_direction) / _integral(self.clear_sky,
                                                                                   self.sun_direction)

    def overcast_sky_normalized(self, directions: ArrayLike) -> NDArray[np.float64]:
        """Overcast-sky radiance per unit DHI (sr⁻¹); 0 below the horizon."""
        return self.overcast_sky.relative(directions, self.sun_direction) / _integral(self.overcast_sky,
                                                                                      self.sun_direction)

    def radiance(self, directions: ArrayLike) -> NDArray[np.float64]:
        """Total outdoor radiance ``(..., 3)`` (W m⁻² sr⁻¹) seen along unit ``directions`` (sky above the
        horizon, ground below; the sun disk is not included)."""
        w = np.asarray(directions, dtype=np.float64)
        out = (self.clear_sky_normalized(w)[..., None] * np.asarray(self.clear_dhi_rgb)
               + self.overcast_sky_normalized(w)[..., None] * np.asarray(self.overcast_dhi_rgb))
        return np.where((w[..., 2] <= 0.0)[..., None], self.ground_radiance_rgb, out)


_INTEGRALS: dict[tuple[SkyDistribution, tuple[float, ...]], float] = {}


def _integral(dist: SkyDistribution, sun_direction: ArrayLike) -> float:
    key = (dist, tuple(np.round(np.asarray(sun_direction, dtype=np.float64), 9)))
    if key not in _INTEGRALS:
        if len(_INTEGRALS) > 256:
            _INTEGRALS.clear()
        _INTEGRALS[key] = dist.horizontal_integral(sun_direction)
    return _INTEGRALS[key]
