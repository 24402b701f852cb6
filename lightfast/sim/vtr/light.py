"""Daylight spectra of the simulated VT&R route: clear sky and overcast (paper: Paton et al., §III assumes
Planckian illuminants, Eq. 2–5; these are not black bodies, their spectra change with sun elevation and weather,
and skylight is much bluer than sunlight).

:func:`solar_spectra`: spectral direct-normal and diffuse-horizontal irradiance (W m⁻² nm⁻¹ on
:data:`~lightfast.sim.vtr.spectra.WAVELENGTHS_NM`) for an apparent sun elevation (degrees), from a simplified
Bird–Riordan (SPCTRAL2) clear-sky model (:class:`Atmosphere`): extraterrestrial sun = 5778 K black body scaled to
1361 W/m²; Rayleigh optical depth 0.008735 λ^-4.08 (λ in µm, scaled by pressure), Ångström aerosol β λ^-α (β 0.04,
α 1.3, single-scattering albedo 0.945, 75 % forward scattering), ozone Chappuis band
(0.12 exp(-((λ - 600 nm) / 70 nm)²) per atm-cm, 0.33 atm-cm), Kasten–Young air mass. Below 0.5° the sky keeps its
0.5° spectrum and dims by exp((el - 0.5°) / 1.5°) (twilight); the sun is gone below 0°.

:func:`daylight_illumination` → :class:`Illumination`, the light of one frame: the sun direction as a unit vector
in the z-up map frame (ENU), e.g. from :func:`lightfast.daylight.sun.sun_position`, and the spectra. Sunny: that
clear sky. Cloudy (overcast): the clear-sky global spectrum transmitted by a neutral cloud layer
(``cloud_transmittance``, ≈ 0.35) and made bluer by scattering under it (factor (λ / 560 nm)^-1), plus an
attenuated direct sun (``direct_transmittance``, ≈ 0.02: faint shadows). The colour temperatures these give are
in docs/vtr.md ("The simulated route").
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.sim.vtr.spectra import WAVELENGTHS_NM, planck

__all__ = [
    "WEATHERS",
    "Atmosphere",
    "Illumination",
    "daylight_illumination",
    "solar_spectra",
]

_F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Atmosphere:
    """Clear-sky parameters of :func:`solar_spectra` (a simplified Bird–Riordan SPCTRAL2 model)."""

    pressure_hpa: float = 1013.25
    aerosol_beta: float = 0.04  # Ångström turbidity at 1 µm
    aerosol_alpha: float = 1.3
    aerosol_albedo: float = 0.945  # single-scattering albedo
    aerosol_forward: float = 0.75  # fraction of aerosol scattering going down
    ozone_atm_cm: float = 0.33
    sun_temperature_k: float = 5778.0
    solar_constant_wm2: float = 1361.0


def solar_spectra(elevation_deg: float, atmosphere: Atmosphere = Atmosphere()) -> tuple[_F64, _F64]:
    """Clear-sky ``(direct_normal, diffuse_horizontal)`` spectral irradiance (W m⁻² nm⁻¹) on
    :data:`WAVELENGTHS_NM` for the apparent sun ``elevation_deg`` (see the module docstring)."""
    a = atmosphere
    lam = WAVELENGTHS_NM
    l_um = lam / 1000.0
    sigma = 5.670374419e-8
    h0 = a.solar_constant_wm2 * math.pi * planck(lam, a.sun_temperature_k) / (sigma * a.sun_temperature_k**4)
    el = float(elevation_deg)
    el_c = max(el, 0.5)
    zen = 90.0 - el_c
    m = 1.0 / (math.cos(math.radians(zen)) + 0.50572 * (96.07995 - zen) ** -1.6364)
    tau_r = 0.008735 * l_um**-4.08 * (a.pressure_hpa / 1013.25)
    tau_a = a.aerosol_beta * l_um**-a.aerosol_alpha
    tau_o = 0.12 * np.exp(-(((lam - 600.0) / 70.0) ** 2)) * a.ozone_atm_cm
    t_r, t_a, t_o = np.exp(-m * tau_r), np.exp(-m * tau_a), np.exp(-m * tau_o)
    t_aa = np.exp(-(1.0 - a.aerosol_albedo) * tau_a * m)
    t_as = np.exp(-a.aerosol_albedo * tau_a * m)
    direct = h0 * t_r * t_a * t_o if el > 0.0 else np.zeros_like(lam)
    cz = math.sin(math.radians(el_c))
    rayleigh = h0 * cz * t_o * t_aa * (1.0 - t_r**0.95) * 0.5
    aerosol = h0 * cz * t_o * t_aa * t_r**1.5 * (1.0 - t_as) * a.aerosol_forward
    diffuse = rayleigh + aerosol
    if el < 0.5:
        diffuse = diffuse * math.exp((el - 0.5) / 1.5)
    return direct, diffuse


@dataclass(frozen=True, eq=False)
class Illumination:
    """The light of one frame: spectra on :data:`WAVELENGTHS_NM` (W m⁻² nm⁻¹) and the sun's direction.

    ``direct_normal`` is the sun's irradiance on a surface facing it (already attenuated by clouds);
    ``sky_horizontal`` the diffuse irradiance of the unobstructed sky on a horizontal surface.
    """

    sun_direction_map: _F64  # (3,) unit vector towards the sun
    sun_elevation_deg: float
    weather: str  # "sunny" | "cloudy"
    direct_normal: _F64
    sky_horizontal: _F64
    cloud_transmittance: float = 1.0
    direct_transmittance: float = 1.0

    @property
    def global_horizontal(self) -> _F64:
        """Global horizontal irradiance spectrum (direct on the horizontal plus sky)."""
        s = max(float(self.sun_direction_map[2]), 0.0)
        return self.direct_normal * s + self.sky_horizontal


WEATHERS = ("sunny", "cloudy")


def daylight_illumination(sun_direction_map: ArrayLike, elevation_deg: float, weather: str, *,
                          cloud_transmittance: float = 0.35, direct_transmittance: float = 0.02,
                          atmosphere: Atmosphere = Atmosphere()) -> Illumination:
    """Sunny (clear sky) or cloudy (overcast: neutral cloud layer, attenuated direct sun) daylight for a sun
    position (see the module docstring). ``cloud_transmittance`` and ``direct_transmittance`` apply when cloudy."""
    if weather not in WEATHERS:
        raise ValueError(f"weather must be one of {WEATHERS}, got {weather!r}")
    d = np.asarray(sun_direction_map, dtype=np.float64).reshape(3)
    d = d / np.linalg.norm(d)
    direct, diffuse = solar_spectra(elevation_deg, atmosphere)
    if weather == "sunny":
        return Illumination(d, float(elevation_deg), weather, direct, diffuse)
    glob = direct * max(float(d[2]), 0.0) + diffuse
    sky = cloud_transmittance * glob * (WAVELENGTHS_NM / 560.0) ** -1.0
    return Illumination(d, float(elevation_deg), weather, direct * direct_transmittance, sky,
                        cloud_transmittance=float(cloud_transmittance),
                        direct_transmittance=float(direct_transmittance))
