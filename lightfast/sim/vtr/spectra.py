"""Spectra of the simulated VT&R route (paper: Paton et al., "It's Not Easy Seeing Green", ICRA 2015, §III, §V):
the reflectance basis, measured camera sensitivities, black bodies and the spectral camera integral.

The simulator deliberately does **not** use the narrow-band Planckian model that the method assumes (§III,
Eq. 2–5): light is integrated over wavelength against broad, overlapping measured camera sensitivities,

    R_c = Σ_λ ρ(λ) E(λ) S_c(λ) Δλ / π                                   (:func:`camera_response`)

with ρ a Lambertian reflectance (0–1), E an irradiance (W m⁻² nm⁻¹) and S_c the peak-normalized sensitivity of
channel c (R, G, B), all on :data:`WAVELENGTHS_NM` (380–780 nm in 10 nm steps, 41 samples).

* :func:`camera_sensitivities` ``(41, 3)``: colour-science's measured **Nikon D5100** (NPL) curves (the paper's
  Bumblebee XB3 / Sony ICX445 curves are not published in machine-readable form; both have broad, overlapping
  channels, which is what matters here);
* :func:`material_spectra` ``(15, 41)`` in [0.01, 0.95], rows :data:`BASIS`: ``grass_green`` is the measured
  ColorChecker "foliage" patch (colour-science, N. Ohta) with the vegetation red edge; the others are analytic
  curves (logistic rises ``L(λ; c, w) = 1 / (1 + exp(-(λ - c) / w))`` and Gaussian bumps) shaped after typical
  field spectra: quartz sand, iron-oxide red sand (ferric absorption edge near 570 nm), granite-grey and weathered
  red rock, straw, soil, leaf litter, moss and leaves (chlorophyll absorption in blue and red, green peak at
  550 nm, red edge at 705–715 nm), grey and brown bark;
* :func:`planck`: black-body spectral radiance (W m⁻² sr⁻¹ nm⁻¹); :func:`spectrum_cct`: correlated colour
  temperature (K; Hernández-Andrés 1999, CIE 1931 2° observer).

The whole simulator is described in docs/vtr.md ("The simulated route").
"""
from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "BASIS",
    "CAMERA_SENSITIVITY",
    "DLAMBDA_NM",
    "WAVELENGTHS_NM",
    "camera_response",
    "camera_sensitivities",
    "material_spectra",
    "planck",
    "spectrum_cct",
]

#: Wavelength samples (nm) of every spectrum here: 380–780 nm in 10 nm steps (41 samples).
WAVELENGTHS_NM: NDArray[np.float64] = np.arange(380.0, 781.0, 10.0)
DLAMBDA_NM = 10.0
#: The colour-science camera whose measured spectral sensitivities the simulated camera has.
CAMERA_SENSITIVITY = "Nikon 5100 (NPL)"
#: Names of the reflectance basis spectra (rows of :func:`material_spectra`).
BASIS = ("sand_light", "sand_red", "gravel_dark", "rock_grey", "rock_red", "rock_dark", "grass_green",
         "grass_dry", "soil_brown", "leaf_litter", "moss", "bark_grey", "bark_brown", "leaf_green", "leaf_yellow")

_F64 = NDArray[np.float64]


def _logistic(lam: _F64, centre: float, width: float) -> _F64:
    return 1.0 / (1.0 + np.exp(-(lam - centre) / width))


def _bump(lam: _F64, centre: float, width: float) -> _F64:
    return np.exp(-(((lam - centre) / width) ** 2))


@functools.cache
def material_spectra() -> _F64:
    """The reflectance basis ``(len(BASIS), len(WAVELENGTHS_NM))`` in [0.01, 0.95] (see the module docstring)."""
    import colour

    lam = WAVELENGTHS_NM
    ramp = (lam - 380.0) / 400.0
    foliage = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]["foliage"]
    grass = np.interp(lam, foliage.wavelengths, foliage.values)
    spectra = {
        "sand_light": 0.18 + 0.30 * _logistic(lam, 520.0, 45.0),
        "sand_red": 0.07 + 0.38 * _logistic(lam, 570.0, 25.0),
        "gravel_dark": 0.06 + 0.08 * _logistic(lam, 550.0, 80.0),
        "rock_grey": 0.22 + 0.06 * ramp,
        "rock_red": 0.08 + 0.17 * _logistic(lam, 590.0, 35.0),
        "rock_dark": 0.05 + 0.04 * ramp,
        "grass_green": grass,
        "grass_dry": 0.10 + 0.32 * _logistic(lam, 540.0, 45.0),
        "soil_brown": 0.05 + 0.20 * _logistic(lam, 600.0, 70.0),
        "leaf_litter": 0.05 + 0.16 * _logistic(lam, 610.0, 50.0),
        "moss": 0.03 + 0.07 * _bump(lam, 555.0, 35.0) + 0.35 * _logistic(lam, 705.0, 12.0),
        "bark_grey": 0.10 + 0.08 * ramp,
        "bark_brown": 0.05 + 0.15 * _logistic(lam, 600.0, 60.0),
        "leaf_green": 0.04 + 0.09 * _bump(lam, 550.0, 32.0) + 0.46 * _logistic(lam, 712.0, 10.0),
        "leaf_yellow": 0.05 + 0.22 * _logistic(lam, 510.0, 18.0) * (1.0 - 0.7 * _logistic(lam, 655.0, 12.0))
        + 0.40 * _logistic(lam, 712.0, 10.0),
    }
    out = np.stack([spectra[name] for name in BASIS])
    return np.clip(out, 0.01, 0.95)


@functools.cache
def camera_sensitivities(name: str = CAMERA_SENSITIVITY) -> _F64:
    """Measured camera spectral sensitivities ``(len(WAVELENGTHS_NM), 3)`` (columns R, G, B; peak 1) from
    colour-science's ``MSDS_CAMERA_SENSITIVITIES[name]``, linearly interpolated (0 outside the measured range)."""
    import colour

    msds = colour.MSDS_CAMERA_SENSITIVITIES[name]
    labels = [str(x).lower() for x in msds.labels]
    cols = [labels.index(c) for c in ("red", "green", "blue")]
    out = np.stack([np.interp(WAVELENGTHS_NM, msds.wavelengths, msds.values[:, c], left=0.0, right=0.0)
                    for c in cols], axis=1)
    return out / out.max()


def planck(lam_nm: ArrayLike, temperature_k: float) -> _F64:
    """Black-body spectral radiance (W m⁻² sr⁻¹ nm⁻¹) at wavelengths ``lam_nm`` (Planck's law)."""
    h, c, k = 6.62607015e-34, 2.99792458e8, 1.380649e-23
    lam = np.asarray(lam_nm, dtype=np.float64) * 1e-9
    return 2.0 * h * c**2 / lam**5 / np.expm1(h * c / (lam * k * temperature_k)) * 1e-9


def camera_response(reflectance: ArrayLike, illuminant: ArrayLike,
                    sensitivities: ArrayLike | None = None) -> _F64:
    """Raw camera response ``Σ_λ ρ(λ) E(λ) S_c(λ) Δλ / π`` (..., 3) of Lambertian reflectance ``(..., Λ)`` under
    irradiance ``(..., Λ)`` (broadcast), on :data:`WAVELENGTHS_NM`; sensitivities default to the camera's."""
    S = camera_sensitivities() if sensitivities is None else np.asarray(sensitivities, dtype=np.float64)
    L = np.asarray(reflectance, dtype=np.float64) * np.asarray(illuminant, dtype=np.float64)
    return L @ S * (DLAMBDA_NM / math.pi)


def spectrum_cct(spectrum: ArrayLike) -> float:
    """Correlated colour temperature (K, Hernández-Andrés 1999) of a spectrum on :data:`WAVELENGTHS_NM` (CIE 1931
    2° observer)."""
    import colour

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    cmf = np.stack([np.interp(WAVELENGTHS_NM, cmfs.wavelengths, cmfs.values[:, j]) for j in range(3)], axis=1)
    xyz = np.asarray(spectrum, dtype=np.float64) @ cmf
    if not np.all(np.isfinite(xyz)) or xyz[1] <= 0:
        return float("nan")
    return float(colour.xy_to_CCT(xyz[:2] / xyz.sum(), method="Hernandez 1999"))
