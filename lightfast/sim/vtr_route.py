"""Spectral outdoor route for colour-constant stereo VT&R recordings (paper: Paton et al., "It's Not Easy Seeing
Green", §V–VI): the scene, the route through it, the stereo rig and an independent spectral renderer.

The renderer deliberately does **not** use the narrow-band Planckian model of the paper's §III (Eq. 2–5) that the
method assumes: light is integrated over wavelength against broad, overlapping measured camera sensitivities, and
the illuminants are not black bodies (sunlight and skylight come from a spectral clear-sky model; their spectra
change with sun elevation and weather, and skylight is much bluer than sunlight). ``test/unit/test_vtr_sim.py``
shows the difference: the log-chromaticity of a surface under changing illuminants leaves the straight line the
narrow-band model predicts, and its shift depends on the surface.

Scene (:func:`build_route_scene`, :class:`RouteConfig`)
-------------------------------------------------------
A smooth centreline of ``length_m`` in a z-up map frame (ENU, x east, y north, metres; the route starts at the
origin in a random direction) that snakes (curvature noise, 40–160 m periods) while curling round by
``total_turn_deg`` (default 270°, like the paper's route that loops back to its start; curvature ≤
``max_curvature_per_m``), so the sun falls from every side along it; divided into stretches of sand-and-rock, grass
and woods (default 40 / 30 / 30 %, blended over 6 m). The terrain is a height field (random plane waves, 8–80 m
wavelengths, ``terrain_rms_m``), triangulated at ``grid_m`` within ``corridor_half_width_m`` of the centreline and
at ``outer_grid_m`` out to ``outer_margin_m`` (the horizon backdrop). On it: rocks and boulders (displaced,
flattened, half-buried icospheres, radius 0.15–1.6 m, power-law sizes; dense on sand-and-rock), and trees (tapered
8-sided trunks, crowns of 15–60 leaf clusters so that their shadows are dappled; dense in the woods, sparse on
grass). Nothing but small texture lies within ``path_clearance_m`` (rocks) / ``tree_clearance_m`` (trunks) of the
centreline, so a robot with small lateral offsets can drive it; canopies overhang the path above 3 m.

Materials: every surface is a per-pixel mixture of the :data:`BASIS` reflectance spectra (380–780 nm, 10 nm),
chosen by surface kind (ground, rock, trunk, foliage), stretch, distance to the path (a dirt track on grass and
in the woods) and a world-fixed procedural texture (FFT-synthesized tileable fractal noise, 4 channels, 2048² texels
with a mip-map chain, sampled at two scales, 1.5 cm and 12.4 cm texels (periods 31 m and 254 m, the coarse one
rotated), bilinearly in the mip level nearest to the pixel footprint) that varies brightness *and* chromaticity
(sand vs. iron-red sand vs. dark grains, green vs. dry grass vs. bare soil, litter vs. moss, grey vs. red rock,
bark, two leaf spectra), so features exist in greyscale and in colour-constant images alike.

Reflectance spectra (:func:`material_spectra`): ``grass_green`` is the measured ColorChecker "foliage" patch
(colour-science, N. Ohta), with the vegetation red edge (0.10 → 0.36 from 680 to 740 nm). The others are
documented analytic curves (logistic rises ``L(λ; c, w) = 1 / (1 + exp(-(λ - c) / w))`` and Gaussian bumps)
shaped after typical field spectra: quartz sand rising 0.18 → 0.48; iron-oxide red sand with its ferric absorption
edge near 570 nm; granite-grey and weathered red rock; straw, soil, leaf litter; moss and leaves with chlorophyll
absorption in blue and red, the green peak at 550 nm and the red edge at 705–715 nm; grey and brown bark.

Light (:func:`solar_spectra`, :func:`daylight_illumination`, :class:`Atmosphere`)
--------------------------------------------------------------------------------
Spectral direct-normal and diffuse-horizontal irradiance from a simplified Bird–Riordan (SPCTRAL2) clear-sky
model: extraterrestrial sun = 5778 K black body scaled to 1361 W/m²; Rayleigh optical depth 0.008735 λ^-4.08 (λ in
µm, scaled by pressure), Ångström aerosol β λ^-α (β 0.04, α 1.3, single-scattering albedo 0.945, 75 % forward
scattering), ozone Chappuis band (0.12 exp(-((λ - 600 nm) / 70 nm)²) per atm-cm, 0.33 atm-cm), Kasten–Young air
mass. Direct sun: CCT ≈ 5150 K at 60° elevation, 3750 K at 10°, 1900 K at 2°; skylight: ≈ 11800 K at 60°, 9200 K
at 10° (visible-band direct normal / diffuse horizontal: 499 / 65 W/m² at 60°). Below 0.5° the sky keeps its 0.5°
spectrum and dims by exp((el - 0.5°) / 1.5°) (twilight); the sun is gone below 0°. Sunny: that clear sky. Cloudy
(overcast): the clear-sky global spectrum transmitted by a neutral cloud layer (``cloud_transmittance``, ≈ 0.35)
and made bluer by scattering under it (factor (λ / 560 nm)^-1, CCT ≈ 6700–6950 K), plus an attenuated direct sun
(``direct_transmittance``, ≈ 0.02: faint shadows). The sun's position comes from pvlib's SPA
(:func:`lightfast.daylight.sun.sun_position`).

Renderer (:class:`SpectralRenderer`)
------------------------------------
Per pixel (both stereo views in one batch): an Embree primary ray; Lambertian shading with four illuminants,

* sun: ``E_dn(λ) · max(n·s, 0) · V_sun``, ``V_sun`` from one Embree shadow ray per pixel towards a point of the
  0.53° sun disk (soft edges);
* sky: ``E_sky(λ) · v_sky``, with ``v_sky`` the cosine-weighted fraction of the hemisphere above the surface that
  sees the sky (per vertex, ``sky_samples`` Embree rays at scene build, interpolated);
* light bounced by occluders: ``v_foliage · ρ_leaf(λ) E_glob(λ)`` under canopies (green: leaf reflectance plus
  transmittance ≈ 2 ρ_leaf, half the crown lit) and ``v_other · 0.5 ρ_env(λ) E_glob(λ)`` from terrain, rocks and
  trunks, with ``E_glob`` the global horizontal irradiance and ``ρ_env`` the mean of the sand, grass, soil, rock
  and litter spectra;

so shadows are lit by bluish skylight (plus some green under trees). Ground, rocks and trunks carry a micro-relief
below the mesh resolution (sand ripples and grains, rock roughness, bark ridges): the shading normal is tilted by
facet slopes up to :data:`BUMP_SLOPE` (0.5 ground, 0.6 rock, 0.5 bark; from the texture's "mid" noise channel at
two unrelated points, mip-averaged like the albedo so that the relief smooths out with distance), so that sunlit
surfaces show a shading texture that changes with the sun's direction while sky-lit shadow keeps the albedo
texture only. Sky pixels see ``E_sky / π`` times a
gradient (clear: brighter towards the horizon; overcast: CIE overcast ``(1 + 2 sin el)``). The spectral
integral is exact on the 10 nm grid and vectorized as matrix products over wavelength: with per-pixel basis
weights ``W`` (pixels × basis) and ``A_k = (ρ_basis ⊙ E_k(λ)) · S(λ) Δλ / π`` (basis × channels, a product
over the 41 wavelength samples), the raw response is ``Σ_k w_k ⊙ (W · A_k)`` — identical to forming each pixel's
spectrum and integrating it against the sensitivities, without the pixels × wavelengths array. The per-pixel
geometry and material step (hit point, normals, interpolated vertex data, texture lookups, basis weights ``W``) is
one compiled Numba kernel (one chunk per CPU; it releases the GIL); ray casting is Embree
(:class:`lightfast.raycast.RayCaster`). No inter-reflection beyond the bounce term, no atmospheric perspective,
no Bayer mosaic, no motion blur.

Speed (this machine, 2 cores shared with other jobs, load 6–7): about 0.65 s of CPU per 640 × 480 stereo pair
on the 300 m route (Embree ≈ 0.3 s, kernel ≈ 0.1 s, NumPy glue ≈ 0.25 s), 1.1–1.6 s wall under that load.

Camera (:class:`StereoRig`, :class:`SensorModel`, :class:`AutoExposure`)
-----------------------------------------------------------------------
Spectral sensitivities: colour-science's measured **Nikon D5100** (NPL) curves (the XB3's Sony ICX445 curves are
not published in machine-readable form; both have broad, overlapping channels, which is what matters here).
Geometry like a Point Grey Bumblebee XB3 (3.8 mm lens, 3.75 µm pixels at 1280 × 960): an ideal rectified pair,
``fx = fy = 1013.33 · width / 1280`` px (506.67 px at 640 × 480, 64.5° horizontal field of view), principal point
at the image centre, 24 cm baseline, mounted 1.25 m above the ground, 0.3 m ahead of the robot's centre, pitched
down 12°. Left ``P = [K | 0]``, right ``P = [K | (-fx·b, 0, 0)ᵀ]``.

Exposure and noise: normalized sensor signal ``x = k · R`` with ``R`` the raw response and
``k = quantum_scale · exposure_s · gain``; auto-exposure like a real camera: per frame, ``k`` that brings the mean
of ``min(k·Y, 1)`` (Y: white-balanced luma) to ``target_mean``, approached geometrically from the previous
frame's ``k`` (``adaptation``), split into exposure time (≤ ``max_exposure_s``) and analog gain (≤ ``max_gain``).
Then shot noise (Gaussian approximation of Poisson on ``x · full_well_e / gain`` electrons), read noise
(``read_noise_e``), sensor saturation at ``x = 1``, a fixed white balance (a white surface under CIE D65 gives
equal channels, like a manually white-balanced machine-vision camera), clipping, a pure power-law gamma
``x^(1/gamma)`` (default 2.2, so shadows keep detail; ``gamma=1`` is a linear camera; a power law scales every
log-channel by ``1/gamma``, so colour-constant images stay invariant up to that scale), 8-bit quantization →
``rgb8``.
"""
from __future__ import annotations

import functools
import json
import math
import os
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from lightfast.camera import PinholeCamera
from lightfast.io import write_bytes_atomic
from lightfast.progress import track
from lightfast.raycast import RayCaster

__all__ = [
    "BASIS",
    "CAMERA_SENSITIVITY",
    "KIND_FOLIAGE",
    "KIND_GROUND",
    "KIND_ROCK",
    "KIND_TRUNK",
    "STRETCHES",
    "WAVELENGTHS_NM",
    "Atmosphere",
    "AutoExposure",
    "Illumination",
    "RenderOutput",
    "RouteConfig",
    "RouteScene",
    "SensorModel",
    "SpectralRenderer",
    "StereoRig",
    "base_pose",
    "build_route_scene",
    "camera_response",
    "camera_sensitivities",
    "daylight_illumination",
    "flat_test_scene",
    "material_spectra",
    "planck",
    "solar_spectra",
    "spectrum_cct",
]

#: Wavelength samples (nm) of every spectrum here: 380–780 nm in 10 nm steps (41 samples).
WAVELENGTHS_NM: NDArray[np.float64] = np.arange(380.0, 781.0, 10.0)
DLAMBDA_NM = 10.0
#: The colour-science camera whose measured spectral sensitivities the simulated camera has.
CAMERA_SENSITIVITY = "Nikon 5100 (NPL)"

#: Surface kinds (per triangle).
KIND_GROUND, KIND_ROCK, KIND_TRUNK, KIND_FOLIAGE = 0, 1, 2, 3
#: Stretch (region) names of a route, in the order of the per-vertex region weights.
STRETCHES = ("sand_rock", "grass", "wood")
#: Names of the reflectance basis spectra (rows of :func:`material_spectra`).
BASIS = ("sand_light", "sand_red", "gravel_dark", "rock_grey", "rock_red", "rock_dark", "grass_green",
         "grass_dry", "soil_brown", "leaf_litter", "moss", "bark_grey", "bark_brown", "leaf_green", "leaf_yellow")
_B = {name: i for i, name in enumerate(BASIS)}

#: Bump when the scene or the rendering of the same parameters changes.
SCENE_FORMAT_VERSION = 1
#: Largest micro-relief facet slope (tan of the tilt) per surface kind: ground, rock, trunk, foliage (see the
#: module docstring, "Renderer").
BUMP_SLOPE = (0.5, 0.6, 0.5, 0.0)

_F32 = NDArray[np.float32]
_F64 = NDArray[np.float64]


# ================================================================================================================
# spectra


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


# ================================================================================================================
# light


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


# ================================================================================================================
# camera


@dataclass(frozen=True)
class StereoRig:
    """A rectified stereo pair like a Bumblebee XB3 on the robot (see the module docstring).

    Robot base frame: x forward, y left, z up, at the ground under the robot's centre. The left camera is at
    ``(forward_m, baseline_m / 2, height_m)``, the right one ``baseline_m`` to the right along the left optical x
    axis; both look forward, pitched down by ``pitch_down_deg``."""

    width: int = 640
    height: int = 480
    focal_px_at_1280: float = 1013.33  # 3.8 mm lens / 3.75 µm pixels
    baseline_m: float = 0.24
    height_m: float = 1.25
    forward_m: float = 0.3
    pitch_down_deg: float = 12.0

    @property
    def fx(self) -> float:
        return self.focal_px_at_1280 * self.width / 1280.0

    @property
    def camera(self) -> PinholeCamera:
        """The (identical) intrinsics of both rectified images."""
        return PinholeCamera(self.width, self.height, self.fx, self.fx, (self.width - 1) / 2.0,
                             (self.height - 1) / 2.0)

    @property
    def P_left(self) -> _F64:
        return np.hstack([self.camera.K, np.zeros((3, 1))])

    @property
    def P_right(self) -> _F64:
        P = self.P_left.copy()
        P[0, 3] = -self.fx * self.baseline_m
        return P

    @property
    def T_base_left(self) -> _F64:
        """Pose of the left optical frame (x right, y down, z forward) in the robot base frame."""
        r0 = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        p = math.radians(self.pitch_down_deg)
        ry = np.array([[math.cos(p), 0.0, math.sin(p)], [0.0, 1.0, 0.0], [-math.sin(p), 0.0, math.cos(p)]])
        T = np.eye(4)
        T[:3, :3] = ry @ r0
        T[:3, 3] = (self.forward_m, self.baseline_m / 2.0, self.height_m)
        return T

    @property
    def T_left_right(self) -> _F64:
        """Pose of the right optical frame in the left one: a pure translation by the baseline along x."""
        T = np.eye(4)
        T[0, 3] = self.baseline_m
        return T

    def camera_poses(self, T_map_base: ArrayLike) -> tuple[_F64, _F64]:
        """``(T_map_left, T_map_right)`` for a robot base pose."""
        T_ml = np.asarray(T_map_base, dtype=np.float64) @ self.T_base_left
        return T_ml, T_ml @ self.T_left_right


@dataclass(frozen=True)
class SensorModel:
    """Exposure, noise and output of the simulated camera (see the module docstring)."""

    sensitivity: str = CAMERA_SENSITIVITY
    quantum_scale: float = 15.0  # normalized signal per (raw response unit · second) at gain 1
    full_well_e: float = 10000.0
    read_noise_e: float = 12.0
    min_exposure_s: float = 2e-5
    max_exposure_s: float = 0.05
    max_gain: float = 15.85  # 24 dB
    target_mean: float = 0.22
    adaptation: float = 0.6
    gamma: float = 2.2
    white_point: str = "D65"

    @functools.cached_property
    def wb_gains(self) -> _F64:
        """Fixed white-balance gains (R, G, B): a perfect white under :attr:`white_point` gives equal channels,
        green gain 1."""
        import colour

        sd = colour.SDS_ILLUMINANTS[self.white_point]
        e = np.interp(WAVELENGTHS_NM, sd.wavelengths, sd.values)
        r = e @ camera_sensitivities(self.sensitivity)
        return r[1] / r

    def split_exposure(self, k: float) -> tuple[float, float, float]:
        """Exposure time and analog gain for the wanted normalized exposure ``k``: ``(exposure_s, gain, k_eff)``."""
        t = min(max(k / self.quantum_scale, self.min_exposure_s), self.max_exposure_s)
        gain = min(max(k / (self.quantum_scale * t), 1.0), self.max_gain)
        return t, gain, self.quantum_scale * t * gain

    def capture(self, raw: ArrayLike, exposure_s: float, gain: float, rng: np.random.Generator
                ) -> NDArray[np.uint8]:
        """The 8-bit rgb8 image of a raw response image ``(H, W, 3)`` (see the module docstring)."""
        raw = np.asarray(raw, dtype=np.float32)
        k = np.float32(self.quantum_scale * exposure_s * gain)
        x = raw * k
        shot = rng.standard_normal(x.shape, dtype=np.float32)
        shot *= np.sqrt(np.maximum(x, 0.0) * np.float32(gain / self.full_well_e))
        x += shot
        x += rng.standard_normal(x.shape, dtype=np.float32) * np.float32(gain * self.read_noise_e / self.full_well_e)
        np.clip(x, 0.0, 1.0, out=x)  # full well / ADC range
        x *= self.wb_gains.astype(np.float32)
        np.clip(x, 0.0, 1.0, out=x)
        if self.gamma != 1.0:
            np.power(x, np.float32(1.0 / self.gamma), out=x)
        return np.rint(x * 255.0).astype(np.uint8)


class AutoExposure:
    """Per-frame auto-exposure (see the module docstring); :meth:`update` returns ``(exposure_s, gain)``."""

    def __init__(self, sensor: SensorModel) -> None:
        self.sensor = sensor
        self.k: float | None = None
        self._luma = np.array([0.25, 0.5, 0.25]) * sensor.wb_gains

    def target(self, raw: ArrayLike) -> float:
        """The normalized exposure that brings the mean clipped luma of ``raw`` (H, W, 3) to the target."""
        y = (np.asarray(raw, dtype=np.float32)[::3, ::3] @ self._luma.astype(np.float32)).ravel()
        mean = float(np.mean(y))
        if not mean > 0.0:
            return self.sensor.quantum_scale * self.sensor.max_exposure_s * self.sensor.max_gain
        k = self.sensor.target_mean / mean
        for _ in range(4):  # saturated pixels pull the mean down: iterate on the clipped mean
            m = float(np.mean(np.minimum(k * y, 1.0)))
            k *= self.sensor.target_mean / max(m, 1e-9)
        return k

    def update(self, raw: ArrayLike) -> tuple[float, float]:
        k_t = self.target(raw)
        k = k_t if self.k is None else self.k ** (1.0 - self.sensor.adaptation) * k_t ** self.sensor.adaptation
        exposure, gain, self.k = self.sensor.split_exposure(k)
        return exposure, gain


# ================================================================================================================
# procedural texture


class _MipTexture:
    """A tileable 4-channel fractal-noise texture (values roughly uniform in [0, 1]) with a mip-map chain, sampled
    by pixel footprint."""

    BETAS = (2.2, 1.2, 1.8, 0.8)  # power-spectrum exponents: blotches, grain, mid, speckle

    def __init__(self, size: int, seed: int) -> None:
        if size < 16 or size & (size - 1):
            raise ValueError(f"texture size must be a power of two >= 16, got {size}")
        rng = np.random.default_rng([seed, 77])
        fy = np.fft.fftfreq(size)[:, None]
        fx = np.fft.rfftfreq(size)[None, :]
        f = np.hypot(fx, fy)
        f[0, 0] = 1.0
        chans = []
        for beta in self.BETAS:
            spec = np.fft.rfft2(rng.standard_normal((size, size))) * f ** (-beta / 2.0)
            spec[0, 0] = 0.0
            img = np.fft.irfft2(spec, s=(size, size)).ravel()
            ranks = np.empty(img.size)
            ranks[np.argsort(img, kind="stable")] = (np.arange(img.size) + 0.5) / img.size
            chans.append(ranks.reshape(size, size))
        level = np.stack(chans, axis=-1).astype(np.float32)
        levels = [level]
        while levels[-1].shape[0] > 1:
            a = levels[-1]
            levels.append(0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2]))
        self.size = size
        self.n_levels = len(levels)
        self.offsets = np.cumsum([0] + [lv.shape[0] ** 2 for lv in levels[:-1]]).astype(np.int64)
        self.flat = np.ascontiguousarray(np.concatenate([lv.reshape(-1, 4) for lv in levels]), dtype=np.float32)


# Column indices of the basis spectra, as compile-time constants of the shading kernel.
_SAND_LIGHT, _SAND_RED, _GRAVEL_DARK, _ROCK_GREY, _ROCK_RED, _ROCK_DARK = 0, 1, 2, 3, 4, 5
_GRASS_GREEN, _GRASS_DRY, _SOIL_BROWN, _LEAF_LITTER, _MOSS = 6, 7, 8, 9, 10
_BARK_GREY, _BARK_BROWN, _LEAF_GREEN, _LEAF_YELLOW = 11, 12, 13, 14
assert BASIS.index("leaf_yellow") == _LEAF_YELLOW and BASIS.index("moss") == _MOSS


@numba.njit(cache=True, nogil=True, inline="always")
def _smoothstep(e0: float, e1: float, x: float) -> float:
    t = min(max((x - e0) / (e1 - e0), 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


@numba.njit(cache=True, nogil=True)
def _tex_sample(tex: _F32, offsets: NDArray[np.int64], size: int, n_levels: int, u: float, v: float,
                footprint: float) -> tuple[float, float, float, float]:
    """Bilinear sample (4 channels) of the mip level nearest to ``log2(footprint)`` (texel units of level 0)."""
    lev = round(math.log2(max(footprint, 1e-6)))
    lev = min(max(lev, 0), n_levels - 1)
    n = size >> lev
    mask = n - 1
    scale = 1.0 / (1 << lev)
    x = u * scale - 0.5
    y = v * scale - 0.5
    x0 = math.floor(x)
    y0 = math.floor(y)
    fx = x - x0
    fy = y - y0
    ix0 = np.int64(x0) & mask
    iy0 = np.int64(y0) & mask
    ix1 = (ix0 + 1) & mask
    iy1 = (iy0 + 1) & mask
    base = offsets[lev]
    a00, a01 = base + iy0 * n + ix0, base + iy0 * n + ix1
    a10, a11 = base + iy1 * n + ix0, base + iy1 * n + ix1
    w00, w01, w10, w11 = (1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy
    return (w00 * tex[a00, 0] + w01 * tex[a01, 0] + w10 * tex[a10, 0] + w11 * tex[a11, 0],
            w00 * tex[a00, 1] + w01 * tex[a01, 1] + w10 * tex[a10, 1] + w11 * tex[a11, 1],
            w00 * tex[a00, 2] + w01 * tex[a01, 2] + w10 * tex[a10, 2] + w11 * tex[a11, 2],
            w00 * tex[a00, 3] + w01 * tex[a01, 3] + w10 * tex[a10, 3] + w11 * tex[a11, 3])


@numba.njit(cache=True, nogil=True)
def _shade_kernel(origins: _F64, view: NDArray[np.int64], t: _F32, d: _F32, tri: NDArray[np.int64], uv: _F32,
                  faces: NDArray[np.int64], face_normals: _F32, face_kind: NDArray[np.int8], vdata: _F32,
                  smooth: NDArray[np.bool_], tex: _F32, tex_offsets: NDArray[np.int64], tex_size: int,
                  tex_levels: int, textured: bool, k_fine: float, k_coarse: float, fx_px: float,
                  bump: NDArray[np.float64], p_out: _F64, ng_out: _F32, n_out: _F32, vis_out: _F32,
                  W: _F32) -> None:
    """Per hit pixel: position, facing geometric and shading normals (with the micro-relief of ``bump``, the
    largest facet slope per surface kind), interpolated hemisphere fractions and basis weights (mixture ×
    brightness; see :class:`SpectralRenderer`). ``W`` must be zero on entry."""
    ca, sa = math.cos(0.6) * k_coarse, math.sin(0.6) * k_coarse
    for i in range(len(t)):
        o = origins[view[i]]
        ti = t[i]
        p0 = o[0] + ti * d[i, 0]
        p1 = o[1] + ti * d[i, 1]
        p2 = o[2] + ti * d[i, 2]
        p_out[i, 0], p_out[i, 1], p_out[i, 2] = p0, p1, p2
        f = tri[i]
        kind = face_kind[f]
        g0, g1, g2 = face_normals[f, 0], face_normals[f, 1], face_normals[f, 2]
        cosv = g0 * d[i, 0] + g1 * d[i, 1] + g2 * d[i, 2]
        if cosv > 0:
            g0, g1, g2 = -g0, -g1, -g2
        cosv = abs(cosv)
        ng_out[i, 0], ng_out[i, 1], ng_out[i, 2] = g0, g1, g2
        b1, b2 = uv[i, 0], uv[i, 1]
        b0 = 1.0 - b1 - b2
        va, vb, vc = faces[f, 0], faces[f, 1], faces[f, 2]
        for c in range(3):
            vis_out[i, c] = b0 * vdata[va, 7 + c] + b1 * vdata[vb, 7 + c] + b2 * vdata[vc, 7 + c]
        if smooth[kind]:
            n0 = b0 * vdata[va, 0] + b1 * vdata[vb, 0] + b2 * vdata[vc, 0]
            n1 = b0 * vdata[va, 1] + b1 * vdata[vb, 1] + b2 * vdata[vc, 1]
            n2 = b0 * vdata[va, 2] + b1 * vdata[vb, 2] + b2 * vdata[vc, 2]
            ln = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2) + 1e-12
            n0, n1, n2 = n0 / ln, n1 / ln, n2 / ln
            if n0 * g0 + n1 * g1 + n2 * g2 < 0:
                n0, n1, n2 = -n0, -n1, -n2
        else:
            n0, n1, n2 = g0, g1, g2
        n_out[i, 0], n_out[i, 1], n_out[i, 2] = n0, n1, n2
        r0 = b0 * vdata[va, 3] + b1 * vdata[vb, 3] + b2 * vdata[vc, 3]  # sand_rock weight / object tint
        r1 = b0 * vdata[va, 4] + b1 * vdata[vb, 4] + b2 * vdata[vc, 4]  # grass weight / texture offset
        r2 = b0 * vdata[va, 5] + b1 * vdata[vb, 5] + b2 * vdata[vc, 5]  # wood weight
        track = b0 * vdata[va, 6] + b1 * vdata[vb, 6] + b2 * vdata[vc, 6]
        tint = r0
        f0 = f1 = f3 = c0 = c1 = c2 = 0.5
        if textured:
            foot = ti / fx_px / math.sqrt(max(cosv, 0.05))
            a0, a1, a2 = abs(n0), abs(n1), abs(n2)
            z = p2 * 0.25 if kind == KIND_TRUNK else p2
            u = p1 if (a0 >= a1 and a0 >= a2) else p0
            v = p1 if (a2 > a0 and a2 > a1) else z
            off = 0.0 if kind == KIND_GROUND else kind * 1234.5 + r1 * 5000.0
            f0, f1, f2, f3 = _tex_sample(tex, tex_offsets, tex_size, tex_levels, u * k_fine + off,
                                         v * k_fine + 0.37 * off, foot * k_fine)
            slope = bump[kind]
            if slope > 0.0:
                # micro-relief below the mesh resolution: facet slopes along the texture's (u, v) axes from the
                # "mid" noise channel at this point and at an unrelated one (mip-averaged like the albedo, so
                # the relief smooths out with distance), applied to the shading normal
                h2 = _tex_sample(tex, tex_offsets, tex_size, tex_levels, u * k_fine + off + 517.0,
                                 v * k_fine + 0.37 * off + 211.0, foot * k_fine)[2]
                su = slope * (2.0 * f2 - 1.0)
                sv = slope * (2.0 * h2 - 1.0)
                if a0 >= a1 and a0 >= a2:  # u = y, v = z
                    m0, m1, m2 = n0, n1 - su, n2 - sv
                elif a2 > a0 and a2 > a1:  # u = x, v = y
                    m0, m1, m2 = n0 - su, n1 - sv, n2
                else:  # u = x, v = z
                    m0, m1, m2 = n0 - su, n1, n2 - sv
                lm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2) + 1e-12
                m0, m1, m2 = m0 / lm, m1 / lm, m2 / lm
                if m0 * g0 + m1 * g1 + m2 * g2 > 0.05:  # facets stay on the visible side
                    n0, n1, n2 = m0, m1, m2
                    n_out[i, 0], n_out[i, 1], n_out[i, 2] = n0, n1, n2
            if kind <= KIND_ROCK:
                c0, c1, c2, _ = _tex_sample(tex, tex_offsets, tex_size, tex_levels, ca * u - sa * v + off + 333.0,
                                            sa * u + ca * v + 777.0, foot * k_coarse)
        flat = not textured
        if kind == KIND_GROUND:
            keep = 1.0 - track
            w = r0 * keep
            if w > 1e-4:  # sand and rock
                red = 0.0 if flat else _smoothstep(0.45, 0.75, 0.6 * c0 + 0.4 * f0)
                grav = 0.0 if flat else _smoothstep(0.82, 0.92, f3)
                wb = w * (1.0 if flat else 0.75 + 0.5 * (0.6 * f1 + 0.4 * c1))
                W[i, _SAND_LIGHT] += wb * (1 - red) * (1 - grav)
                W[i, _SAND_RED] += wb * red * (1 - grav)
                W[i, _GRAVEL_DARK] += wb * grav
            w = r1 * keep
            if w > 1e-4:  # grass
                dry = 0.0 if flat else _smoothstep(0.45, 0.75, 0.7 * c0 + 0.3 * f0)
                bare = 0.0 if flat else _smoothstep(0.85, 0.95, f3)
                wb = w * (1.0 if flat else 0.55 + 0.9 * (0.7 * f1 + 0.3 * c1))
                W[i, _GRASS_GREEN] += wb * (1 - dry) * (1 - bare)
                W[i, _GRASS_DRY] += wb * dry * (1 - bare)
                W[i, _SOIL_BROWN] += wb * bare
            w = r2 * keep
            if w > 1e-4:  # woods
                moss = 0.0 if flat else _smoothstep(0.5, 0.8, c0)
                soil = 0.0 if flat else _smoothstep(0.6, 0.8, f0)
                wb = w * (1.0 if flat else 0.6 + 0.8 * (0.7 * f1 + 0.3 * c2))
                W[i, _MOSS] += wb * moss
                W[i, _SOIL_BROWN] += wb * (1 - moss) * soil
                W[i, _LEAF_LITTER] += wb * (1 - moss) * (1 - soil)
            if track > 1e-4:  # dirt track
                gq = 0.0 if flat else _smoothstep(0.6, 0.9, f3)
                wb = track * (1.0 if flat else 0.8 + 0.4 * f1)
                W[i, _SOIL_BROWN] += wb * (1 - gq)
                W[i, _GRAVEL_DARK] += wb * gq
        elif kind == KIND_ROCK:
            red = min(max(tint + (0.0 if flat else 0.3 * (c0 - 0.5)), 0.0), 1.0)
            dark = 0.0 if flat else _smoothstep(0.8, 0.95, f3)
            wb = 1.0 if flat else 0.7 + 0.6 * (0.5 * f1 + 0.5 * f0)
            W[i, _ROCK_GREY] = wb * (1 - red) * (1 - dark)
            W[i, _ROCK_RED] = wb * red * (1 - dark)
            W[i, _ROCK_DARK] = wb * dark
        elif kind == KIND_TRUNK:
            brown = min(max(tint + (0.0 if flat else 0.6 * (f0 - 0.5)), 0.0), 1.0)
            wb = 1.0 if flat else 0.6 + 0.8 * f1
            W[i, _BARK_BROWN] = wb * brown
            W[i, _BARK_GREY] = wb * (1 - brown)
        else:
            yel = 0.0 if flat else _smoothstep(0.5, 0.9, 0.5 * tint + 0.5 * f0)
            wb = 1.0 if flat else 0.5 + 1.0 * f1
            W[i, _LEAF_GREEN] = wb * (1 - yel)
            W[i, _LEAF_YELLOW] = wb * yel


# ================================================================================================================
# scene


@dataclass(frozen=True)
class RouteConfig:
    """Parameters of :func:`build_route_scene` (see the module docstring). Densities are per m² and per stretch
    (sand_rock, grass, wood)."""

    length_m: float = 300.0
    seed: int = 2014
    stretches: tuple[tuple[str, float], ...] = (("sand_rock", 0.4), ("grass", 0.3), ("wood", 0.3))
    corridor_half_width_m: float = 20.0
    grid_m: float = 0.25
    outer_margin_m: float = 100.0
    outer_grid_m: float = 2.0
    extension_m: float = 25.0  # straight continuation of the corridor beyond both route ends
    max_curvature_per_m: float = 1.0 / 25.0
    total_turn_deg: float = 270.0  # the route curls round (mean curvature; capped at half the maximum)
    terrain_rms_m: float = 0.3
    path_clearance_m: float = 1.2
    tree_clearance_m: float = 2.2
    rock_density: tuple[float, float, float] = (0.12, 0.006, 0.015)
    tree_density: tuple[float, float, float] = (0.0, 0.003, 0.03)
    tree_band_m: float = 12.0  # trees also this far beyond the corridor
    sky_samples: int = 24
    texture_size: int = 2048

    def __post_init__(self) -> None:
        if not self.length_m > 0.0:
            raise ValueError(f"length_m must be > 0, got {self.length_m}")
        if not self.stretches or any(name not in STRETCHES or not frac > 0 for name, frac in self.stretches):
            raise ValueError(f"stretches must be (name, fraction > 0) pairs with names in {STRETCHES}, "
                             f"got {self.stretches}")
        if not 0.0 < self.grid_m <= self.outer_grid_m:
            raise ValueError("need 0 < grid_m <= outer_grid_m")
        if self.sky_samples < 1:
            raise ValueError("sky_samples must be >= 1")

    def to_dict(self) -> dict:
        d = asdict(self)
        d["stretches"] = [list(s) for s in self.stretches]
        d["rock_density"] = list(self.rock_density)
        d["tree_density"] = list(self.tree_density)
        return d

    @classmethod
    def for_tests(cls, length_m: float = 30.0, seed: int = 7, **kw: object) -> RouteConfig:
        """A small, quick scene: a short route, a narrow coarse corridor, a small texture."""
        base: dict[str, Any] = dict(length_m=length_m, seed=seed, corridor_half_width_m=10.0, grid_m=0.5,
                                    outer_margin_m=40.0, outer_grid_m=4.0, extension_m=10.0, sky_samples=12,
                                    texture_size=256)
        base.update(kw)
        return cls(**base)


@dataclass(frozen=True, eq=False)
class Heightfield:
    """``h(x, y) = Σ a_i sin(k_i · (x, y) + φ_i)`` (metres)."""

    k: _F64  # (n, 2) wave vectors, rad/m
    amplitude: _F64  # (n,)
    phase: _F64  # (n,)

    @classmethod
    def random(cls, rng: np.random.Generator, rms_m: float, n: int = 24) -> Heightfield:
        lam = np.exp(rng.uniform(math.log(8.0), math.log(80.0), n))
        ang = rng.uniform(0.0, 2.0 * math.pi, n)
        k = (2.0 * math.pi / lam)[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        amp = lam**0.8
        amp *= rms_m / math.sqrt(0.5 * float(np.sum(amp**2))) if rms_m > 0 else 0.0
        return cls(k, amp, rng.uniform(0.0, 2.0 * math.pi, n))

    def __call__(self, xy: ArrayLike) -> _F64:
        p = np.asarray(xy, dtype=np.float64)
        return np.sin(p @ self.k.T + self.phase) @ self.amplitude

    def gradient(self, xy: ArrayLike) -> _F64:
        p = np.asarray(xy, dtype=np.float64)
        return (np.cos(p @ self.k.T + self.phase) * self.amplitude) @ self.k


@dataclass(eq=False)
class RouteScene:
    """A triangle mesh with per-triangle kinds and per-vertex data, plus the route (see the module docstring).

    ``vertex_attr`` (V, 4): ground: region weights (sand_rock, grass, wood) and the dirt-track weight; objects:
    ``(tint, texture offset, 0, 0)``. ``vertex_vis`` (V, 3): cosine-weighted hemisphere fractions (sky, foliage,
    other occluders). ``stations`` (n, 4): centreline ``s, x, y, heading_rad`` every 0.25 m (the route is
    ``0 <= s <= length_m``; the table extends beyond both ends); ``station_regions`` (n, 3)."""

    config: RouteConfig
    vertices: _F64
    faces: NDArray[np.int64]
    face_kind: NDArray[np.int8]
    vertex_attr: _F32
    vertex_normals: _F32
    vertex_vis: _F32
    stations: _F64
    station_regions: _F32
    heightfield: Heightfield
    stats: dict = field(default_factory=dict)

    @property
    def length_m(self) -> float:
        return float(self.config.length_m)

    def height(self, xy: ArrayLike) -> _F64:
        return self.heightfield(xy)

    def centreline(self, s: ArrayLike) -> tuple[_F64, _F64]:
        """Centreline ``(xy (..., 2), heading_rad (...))`` at arc lengths ``s`` (linear interpolation)."""
        s = np.asarray(s, dtype=np.float64)
        st = self.stations
        x = np.interp(s, st[:, 0], st[:, 1])
        y = np.interp(s, st[:, 0], st[:, 2])
        return np.stack([x, y], axis=-1), np.interp(s, st[:, 0], st[:, 3])

    def stretch_at(self, s: ArrayLike) -> NDArray[np.int64]:
        """Index into :data:`STRETCHES` of the dominant stretch at arc lengths ``s``."""
        s = np.asarray(s, dtype=np.float64)
        idx = np.clip(np.searchsorted(self.stations[:, 0], s), 0, len(self.stations) - 1)
        return np.argmax(self.station_regions[idx], axis=-1)

    @property
    def content_hash(self) -> str:
        import hashlib

        h = hashlib.sha256()
        for a in (self.vertices, self.faces, self.face_kind, self.vertex_attr):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()[:16]

    # ------------------------------------------------------------------------------------------------ files

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the scene as a NumPy ``.npz`` (no pickles), atomically."""
        import io

        buf = io.BytesIO()
        np.savez(buf, format_version=np.array(SCENE_FORMAT_VERSION), config=np.array(json.dumps(
            self.config.to_dict())), vertices=self.vertices, faces=self.faces, face_kind=self.face_kind,
            vertex_attr=self.vertex_attr, vertex_normals=self.vertex_normals, vertex_vis=self.vertex_vis,
            stations=self.stations, station_regions=self.station_regions, height_k=self.heightfield.k,
            height_amplitude=self.heightfield.amplitude, height_phase=self.heightfield.phase,
            stats=np.array(json.dumps(self.stats)))
        write_bytes_atomic(path, buf.getvalue())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> RouteScene:
        with np.load(path, allow_pickle=False) as z:
            if int(z["format_version"]) != SCENE_FORMAT_VERSION:
                raise ValueError(f"{path}: scene format {int(z['format_version'])}, expected {SCENE_FORMAT_VERSION}")
            cfg = json.loads(str(z["config"]))
            cfg["stretches"] = tuple((str(n), float(f)) for n, f in cfg["stretches"])
            cfg["rock_density"] = tuple(cfg["rock_density"])
            cfg["tree_density"] = tuple(cfg["tree_density"])
            return cls(RouteConfig(**cfg), z["vertices"], z["faces"], z["face_kind"], z["vertex_attr"],
                       z["vertex_normals"], z["vertex_vis"], z["stations"], z["station_regions"],
                       Heightfield(z["height_k"], z["height_amplitude"], z["height_phase"]),
                       json.loads(str(z["stats"])))


# ---------------------------------------------------------------------------------------------------- geometry


@functools.cache
def _icosphere(subdiv: int) -> tuple[_F64, NDArray[np.int64]]:
    t = (1.0 + 5.0**0.5) / 2.0
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
             (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
             (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    v = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in verts]
    for _ in range(subdiv):
        cache: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int, cache: dict[tuple[int, int], int] = cache) -> int:
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = v[a] + v[b]
                v.append(m / np.linalg.norm(m))
                cache[key] = len(v) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    V = np.array(v)
    F = np.array(faces, dtype=np.int64)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    inward = np.sum(n * V[F].mean(axis=1), axis=1) < 0
    F[inward] = F[inward][:, ::-1]
    return V, F


def _grid(x0: float, y0: float, nx: int, ny: int, step: float, keep: NDArray[np.bool_]
          ) -> tuple[_F64, NDArray[np.int64]]:
    """Vertices (V, 2) and CCW (from above) faces of the kept cells ``keep (ny, nx)`` of a regular grid."""
    jj, ii = np.nonzero(keep)
    if not len(ii):
        return np.zeros((0, 2)), np.zeros((0, 3), np.int64)
    w = nx + 1
    i00 = jj * w + ii
    corners = np.stack([i00, i00 + 1, i00 + w + 1, i00 + w], axis=1)
    used, inv = np.unique(corners.ravel(), return_inverse=True)
    c = inv.reshape(-1, 4)
    faces = np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]])
    xy = np.stack([x0 + (used % w) * step, y0 + (used // w) * step], axis=1)
    return xy, faces


class _Parts:
    """Accumulates mesh parts (vertices, faces, kind, per-vertex attributes)."""

    def __init__(self) -> None:
        self.v: list[_F64] = []
        self.f: list[NDArray[np.int64]] = []
        self.k: list[NDArray[np.int8]] = []
        self.a: list[_F32] = []
        self.n = 0

    def add(self, vertices: _F64, faces: NDArray[np.int64], kind: int, attr: ArrayLike) -> None:
        attr = np.broadcast_to(np.asarray(attr, dtype=np.float32), (len(vertices), 4))
        self.v.append(vertices)
        self.f.append(faces + self.n)
        self.k.append(np.full(len(faces), kind, np.int8))
        self.a.append(np.array(attr))
        self.n += len(vertices)

    def arrays(self) -> tuple[_F64, NDArray[np.int64], NDArray[np.int8], _F32]:
        return np.concatenate(self.v), np.concatenate(self.f), np.concatenate(self.k), np.concatenate(self.a)


def _vertex_normals(v: _F64, f: NDArray[np.int64]) -> _F32:
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # area-weighted
    vn = np.zeros_like(v)
    for j in range(3):
        np.add.at(vn, f[:, j], fn)
    length = np.linalg.norm(vn, axis=1, keepdims=True)
    vn = np.divide(vn, length, out=np.tile([0.0, 0.0, 1.0], (len(v), 1)), where=length > 0)
    return vn.astype(np.float32)


def _hemisphere_visibility(caster: RayCaster, v: _F64, n: _F32, face_kind: NDArray[np.int8], samples: int,
                           rng: np.random.Generator, progress: bool, chunk: int = 40000) -> _F32:
    """Per vertex: cosine-weighted fractions of the hemisphere around its normal that see the sky, foliage, or
    other geometry (directions below the horizon count as other)."""
    i = np.arange(samples) + 0.5
    r = np.sqrt(i / samples)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - r * r)], axis=1)  # (K, 3)
    out = np.zeros((len(v), 3), np.float32)
    starts = range(0, len(v), chunk)
    for s0 in track(starts, desc="sky visibility", total=len(starts), enabled=progress, unit="chunk"):
        sl = slice(s0, min(s0 + chunk, len(v)))
        nn = n[sl].astype(np.float64)
        a = np.where(np.abs(nn[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = np.cross(nn, a)
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        t2 = np.cross(nn, t1)
        rot = rng.uniform(0.0, 2.0 * math.pi, len(nn))
        c, s = np.cos(rot)[:, None], np.sin(rot)[:, None]
        lx = c * local[None, :, 0] - s * local[None, :, 1]
        ly = s * local[None, :, 0] + c * local[None, :, 1]
        d = lx[..., None] * t1[:, None] + ly[..., None] * t2[:, None] + local[None, :, 2, None] * nn[:, None]
        o = v[sl][:, None, :] + 0.02 * nn[:, None, :]
        hits = caster.intersect(np.broadcast_to(o, d.shape), d, t_near_m=1e-3)
        up = d[..., 2] > 0.0
        sky = ~hits.hit & up
        fol = hits.hit & (face_kind[np.where(hits.hit, hits.triangle_id, 0)] == KIND_FOLIAGE)
        out[sl, 0] = sky.mean(axis=1)
        out[sl, 1] = fol.mean(axis=1)
        out[sl, 2] = 1.0 - out[sl, 0] - out[sl, 1]
    return out


def _smooth_noise(x: _F64, rng: np.random.Generator, periods: tuple[float, float], n: int = 4) -> _F64:
    """Sum of ``n`` random sinusoids of ``x`` with periods in ``periods``, normalized to [-1, 1]."""
    p = np.exp(rng.uniform(math.log(periods[0]), math.log(periods[1]), n))
    a = rng.uniform(0.5, 1.0, n)
    ph = rng.uniform(0.0, 2.0 * math.pi, n)
    return np.sin(2.0 * math.pi * np.asarray(x)[..., None] / p + ph) @ a / a.sum()


def _centreline(cfg: RouteConfig, rng: np.random.Generator) -> tuple[_F64, _F32]:
    ds = 0.25
    ext = cfg.extension_m
    s = np.arange(-ext, cfg.length_m + ext + ds / 2, ds)
    bias = min(math.radians(cfg.total_turn_deg) / cfg.length_m, 0.5 * cfg.max_curvature_per_m)
    kappa = bias + 0.5 * cfg.max_curvature_per_m * np.clip(1.5 * _smooth_noise(s, rng, (40.0, 160.0)), -1.0, 1.0)
    kappa[(s < 0) | (s > cfg.length_m)] = 0.0
    cum = np.cumsum(kappa) * ds
    heading = rng.uniform(0.0, 2.0 * math.pi) + cum - np.interp(0.0, s, cum)  # random heading at s = 0
    dx = np.cos(heading) * ds
    dy = np.sin(heading) * ds
    x = np.cumsum(dx)
    y = np.cumsum(dy)
    x -= np.interp(0.0, s, x)
    y -= np.interp(0.0, s, y)
    # stretches: one-hot by arc length, blended over 6 m
    fr = np.array([f for _, f in cfg.stretches], dtype=np.float64)
    bounds = np.concatenate([[0.0], np.cumsum(fr) / fr.sum() * cfg.length_m])
    idx = np.clip(np.searchsorted(bounds, s, side="right") - 1, 0, len(fr) - 1)
    onehot = np.zeros((len(s), len(STRETCHES)))
    onehot[np.arange(len(s)), [STRETCHES.index(cfg.stretches[i][0]) for i in idx]] = 1.0
    k = round(3.0 / ds)
    kern = np.hanning(2 * k + 1)
    kern /= kern.sum()
    reg = np.stack([np.convolve(np.pad(onehot[:, j], k, mode="edge"), kern, mode="valid")
                    for j in range(len(STRETCHES))], axis=1)
    return np.stack([s, x, y, heading], axis=1), reg.astype(np.float32)


def _rock_mesh(rng: np.random.Generator, radius: float) -> _F64:
    V, _ = _icosphere(2 if radius > 0.4 else 1)
    axes = rng.normal(size=(4, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    freq = rng.uniform(1.5, 4.0, 4)
    amp = rng.uniform(0.05, 0.15, 4)
    ph = rng.uniform(0.0, 2.0 * math.pi, 4)
    disp = 1.0 + np.cos((V @ axes.T) * freq + ph) @ amp
    scale = np.array([rng.uniform(0.8, 1.25), rng.uniform(0.8, 1.25), rng.uniform(0.45, 0.8)]) * radius
    yaw = rng.uniform(0.0, 2.0 * math.pi)
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return (V * disp[:, None] * scale) @ R.T


def _tree_parts(rng: np.random.Generator, base: _F64, parts: _Parts, tint: float, tex: float) -> None:
    H = rng.uniform(5.0, 12.0)
    r0 = rng.uniform(0.12, 0.35)
    crown_base = max(3.2, rng.uniform(0.35, 0.5) * H)
    sides = 8
    ang = np.arange(sides) * 2.0 * math.pi / sides
    ring_z = np.array([-0.3, crown_base, 0.85 * H])
    ring_r = np.array([r0 * 1.1, r0 * 0.8, r0 * 0.35])
    V = np.concatenate([np.stack([base[0] + r * np.cos(ang), base[1] + r * np.sin(ang),
                                  np.full(sides, base[2] + z)], axis=1) for z, r in zip(ring_z, ring_r, strict=True)])
    F = []
    for ring in range(len(ring_z) - 1):
        for j in range(sides):
            a0, a1 = ring * sides + j, ring * sides + (j + 1) % sides
            b0, b1 = a0 + sides, a1 + sides
            F += [(a0, a1, b1), (a0, b1, b0)]
    parts.add(V, np.array(F, dtype=np.int64), KIND_TRUNK, (tint, tex, 0.0, 0.0))
    # crown: leaf clusters in an ellipsoid
    Rc = rng.uniform(1.5, 3.5)
    hz = (H - crown_base) / 2.0
    centre = base + np.array([0.0, 0.0, crown_base + hz])
    cl_r = rng.uniform(0.5, 0.9)
    n = int(np.clip(0.35 * (Rc * Rc * hz) / cl_r**3, 15, 60))
    ico_v, ico_f = _icosphere(0)
    vs, fs = [], []
    for i in range(n):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        p = centre + u * rng.uniform(0.45, 1.0) ** 0.5 * np.array([Rc, Rc, hz])
        sc = cl_r * rng.uniform(0.7, 1.2, 3) * np.array([1.0, 1.0, 0.75])
        vs.append(ico_v * sc + p)
        fs.append(ico_f + 12 * i)
    parts.add(np.concatenate(vs), np.concatenate(fs), KIND_FOLIAGE, (tint, tex + 0.5, 0.0, 0.0))


def _place(rng: np.random.Generator, kd: cKDTree, reg: _F32, lo: _F64, hi: _F64, densities: tuple,
           d_min: float, d_max: float) -> tuple[_F64, NDArray[np.int64]]:
    """Random positions with per-stretch density whose distance to the centreline is in ``[d_min, d_max]``."""
    dens = np.asarray(densities, dtype=np.float64)
    if dens.max() <= 0.0:
        return np.zeros((0, 2)), np.zeros(0, np.int64)
    area = float(np.prod(hi - lo))
    n = rng.poisson(dens.max() * area)
    p = lo + rng.random((n, 2)) * (hi - lo)
    d, j = kd.query(p)
    keep = rng.random(n) < (reg[j] @ dens) / dens.max()
    keep &= (d >= d_min) & (d <= d_max)
    return p[keep], j[keep]


def build_route_scene(config: RouteConfig = RouteConfig(), *, progress: bool = False) -> RouteScene:
    """Build the route scene of ``config`` (deterministic in ``config.seed``; see the module docstring)."""
    t0 = time.perf_counter()
    cfg = config
    rng = np.random.default_rng([cfg.seed, 1])
    stations, reg = _centreline(cfg, rng)
    hf = Heightfield.random(np.random.default_rng([cfg.seed, 2]), cfg.terrain_rms_m)
    kd = cKDTree(stations[:, 1:3])
    D = cfg.corridor_half_width_m
    lo = stations[:, 1:3].min(axis=0) - D - 2.0
    hi = stations[:, 1:3].max(axis=0) + D + 2.0
    parts = _Parts()

    def ground_attr(xy: _F64) -> _F32:
        d, j = kd.query(xy)
        track = np.exp(-((d / 0.9) ** 2)) * (1.0 - reg[j, 0])
        return np.concatenate([reg[j], track[:, None]], axis=1).astype(np.float32)

    # fine corridor grid, then the coarse backdrop (slightly lower, beyond the corridor)
    g = cfg.grid_m
    nx, ny = math.ceil((hi[0] - lo[0]) / g), math.ceil((hi[1] - lo[1]) / g)
    cx = lo[0] + (np.arange(nx) + 0.5) * g
    cy = lo[1] + (np.arange(ny) + 0.5) * g
    dist = kd.query(np.stack(np.meshgrid(cx, cy), axis=-1).reshape(-1, 2))[0].reshape(ny, nx)
    xy, f = _grid(lo[0], lo[1], nx, ny, g, dist < D + 0.75 * cfg.outer_grid_m)
    parts.add(np.column_stack([xy, hf(xy)]), f, KIND_GROUND, ground_attr(xy))
    n_fine = len(xy)
    G = cfg.outer_grid_m
    olo, ohi = lo - cfg.outer_margin_m, hi + cfg.outer_margin_m
    nx, ny = math.ceil((ohi[0] - olo[0]) / G), math.ceil((ohi[1] - olo[1]) / G)
    cx = olo[0] + (np.arange(nx) + 0.5) * G
    cy = olo[1] + (np.arange(ny) + 0.5) * G
    dist = kd.query(np.stack(np.meshgrid(cx, cy), axis=-1).reshape(-1, 2))[0].reshape(ny, nx)
    xy, f = _grid(olo[0], olo[1], nx, ny, G, dist > D)
    parts.add(np.column_stack([xy, hf(xy) - 0.03]), f, KIND_GROUND, ground_attr(xy))
    # rocks
    rng_r = np.random.default_rng([cfg.seed, 3])
    pos, j = _place(rng_r, kd, reg, lo, hi, cfg.rock_density, 0.0, D - 0.5)
    r_min, r_max, a = 0.15, 1.6, 1.2
    radii = r_min * (1.0 - rng_r.random(len(pos)) * (1.0 - (r_max / r_min) ** -a)) ** (-1.0 / a)
    d = kd.query(pos)[0] if len(pos) else np.zeros(0)
    ok = d >= cfg.path_clearance_m + radii * 1.25
    n_rocks = 0
    for p, r, jj in zip(pos[ok], radii[ok], j[ok], strict=True):
        V = _rock_mesh(rng_r, float(r))
        z = hf(p[None])[0] - 0.3 * V[:, 2].max()
        V = V + np.array([p[0], p[1], z])
        red = float(np.clip(reg[jj, 0] * rng_r.uniform(0.2, 1.0) + rng_r.uniform(-0.2, 0.2), 0.0, 1.0))
        parts.add(V, _icosphere(2 if r > 0.4 else 1)[1], KIND_ROCK, (red, rng_r.random(), 0.0, 0.0))
        n_rocks += 1
    # trees
    rng_t = np.random.default_rng([cfg.seed, 4])
    pos, j = _place(rng_t, kd, reg, lo - cfg.tree_band_m, hi + cfg.tree_band_m, cfg.tree_density,
                    cfg.tree_clearance_m + 0.4, D + cfg.tree_band_m)
    trunks: list[_F64] = []
    for p in pos:
        if trunks and np.min(np.linalg.norm(np.array(trunks) - p, axis=1)) < 2.0:
            continue
        trunks.append(p)
        _tree_parts(rng_t, np.array([p[0], p[1], hf(p[None])[0]]), parts, rng_t.random(), rng_t.random())
    vertices, faces, kinds, attr = parts.arrays()
    t_geom = time.perf_counter() - t0
    normals = _vertex_normals(vertices, faces)
    # the fine grid's normals from the height field (exact, no seam artefacts)
    gr = hf.gradient(vertices[:n_fine, :2])
    nz = np.column_stack([-gr, np.ones(n_fine)])
    normals[:n_fine] = nz / np.linalg.norm(nz, axis=1, keepdims=True)
    caster = RayCaster(vertices, faces)
    vis = _hemisphere_visibility(caster, vertices, normals, kinds, cfg.sky_samples,
                                 np.random.default_rng([cfg.seed, 5]), progress)
    stats = {"vertices": len(vertices), "triangles": len(faces), "rocks": n_rocks,
             "trees": len(trunks), "seconds_geometry": round(t_geom, 3),
             "seconds_total": round(time.perf_counter() - t0, 3)}
    scene = RouteScene(cfg, vertices, faces, kinds, attr, normals, vis, stations, reg, hf, stats)
    scene._caster = caster  # type: ignore[attr-defined]
    return scene


def flat_test_scene(*, material: str = "sand_rock", wall: bool = True, size_m: float = 40.0,
                    grid_m: float = 1.0) -> RouteScene:
    """A flat square of ground of one stretch (``material``) with an optional 3 m high, 8 m long wall along the
    x axis at y = 4 m (north of the origin), for tests: its shadow falls on the ground when the sun is south."""
    cfg = RouteConfig.for_tests(length_m=size_m / 2.0, stretches=((material, 1.0),), terrain_rms_m=0.0)
    parts = _Parts()
    n = round(size_m / grid_m)
    half = size_m / 2.0
    xy, f = _grid(-half, -half, n, n, grid_m, np.ones((n, n), bool))
    reg = np.zeros(4, np.float32)
    reg[STRETCHES.index(material)] = 1.0
    parts.add(np.column_stack([xy, np.zeros(len(xy))]), f, KIND_GROUND, reg)
    if wall:
        x0, x1, y0, y1, h = -4.0, 4.0, 4.0, 4.3, 3.0
        V = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0],
                      [x0, y0, h], [x1, y0, h], [x1, y1, h], [x0, y1, h]], dtype=np.float64)
        F = np.array([[0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7],
                      [4, 5, 6], [4, 6, 7]], dtype=np.int64)
        parts.add(V, F, KIND_ROCK, (0.0, 0.0, 0.0, 0.0))
    vertices, faces, kinds, attr = parts.arrays()
    normals = _vertex_normals(vertices, faces)
    caster = RayCaster(vertices, faces)
    vis = _hemisphere_visibility(caster, vertices, normals, kinds, 64, np.random.default_rng(0), False)
    s = np.arange(-half, half + 0.125, 0.25)
    stations = np.column_stack([s, s, np.zeros_like(s), np.zeros_like(s)])
    sreg = np.tile(reg[:3], (len(s), 1))
    scene = RouteScene(cfg, vertices, faces, kinds, attr, normals, vis, stations, sreg,
                       Heightfield(np.zeros((0, 2)), np.zeros(0), np.zeros(0)))
    scene._caster = caster  # type: ignore[attr-defined]
    return scene


def base_pose(scene: RouteScene, s: float, lateral_m: float = 0.0, yaw_offset_rad: float = 0.0) -> _F64:
    """Robot base pose ``T_map_base`` (4×4) at arc length ``s`` with a lateral offset (left positive), on the
    terrain and aligned with its slope; heading along the offset path plus ``yaw_offset_rad``."""
    xy, _ = scene.centreline(s)
    ds = 0.2
    (xa, _), (xb, _) = scene.centreline(s - ds), scene.centreline(s + ds)
    ha = math.atan2(xb[1] - xa[1], xb[0] - xa[0])
    nrm = np.array([-math.sin(ha), math.cos(ha)])
    p = xy + lateral_m * nrm
    psi = ha + yaw_offset_rad
    g = scene.heightfield.gradient(p[None])[0]
    fwd2 = np.array([math.cos(psi), math.sin(psi)])
    left2 = np.array([-math.sin(psi), math.cos(psi)])
    x = np.array([fwd2[0], fwd2[1], g @ fwd2])
    y = np.array([left2[0], left2[1], g @ left2])
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = (p[0], p[1], float(scene.height(p[None])[0]))
    return T


# ================================================================================================================
# renderer


@functools.cache
def _openblas_thread_controls() -> list[tuple[object, object]]:
    """``(get, set)`` thread-count functions of every OpenBLAS loaded in this process (Linux; else none)."""
    import ctypes

    try:
        with open("/proc/self/maps") as fh:
            libs = sorted({line.split()[-1] for line in fh if "openblas" in line.lower() and "/" in line})
    except OSError:
        return []
    names = [("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
             ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
             ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
             ("openblas_get_num_threads", "openblas_set_num_threads")]
    out = []
    for path in libs:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for get, set_ in names:
            if hasattr(lib, get) and hasattr(lib, set_):
                out.append((getattr(lib, get), getattr(lib, set_)))
                break
    return out


class _SingleThreadedBlas:
    """Run OpenBLAS single-threaded inside the block (restored afterwards). The renderer's matrix products are
    tall and thin (pixels × ≤ 15 by ≤ 15 × 12); on a loaded 2-core machine OpenBLAS's worker threads make them
    10–25× slower than one thread (measured: 0.18 s vs 0.02 s for 565k × 15 × 12)."""

    def __enter__(self) -> None:
        self._saved = []
        for get, set_ in _openblas_thread_controls():
            n = int(get())  # type: ignore[operator]
            self._saved.append((set_, n))
            if n != 1:
                set_(1)  # type: ignore[operator]

    def __exit__(self, *exc: object) -> None:
        for set_, n in self._saved:
            if n != 1:
                set_(n)  # type: ignore[operator]


@dataclass(frozen=True, eq=False)
class RenderOutput:
    """One rendered view. ``raw`` (H, W, 3) float32: linear camera response (R, G, B; before exposure, white
    balance and noise); ``depth_m`` (H, W): z in the optical frame (inf on sky); ``kind`` (H, W) int8 (-1 sky);
    ``sun`` (H, W): ``max(n·s, 0) · V_sun`` (0 in shadow); ``points`` (H, W, 3) float32 map-frame hit points (NaN
    on sky); ``sky_vis`` (H, W): interpolated ``v_sky``."""

    raw: _F32
    depth_m: _F32
    kind: NDArray[np.int8]
    sun: _F32
    points: _F32
    sky_vis: _F32


class SpectralRenderer:
    """Spectral renderer of a :class:`RouteScene` (see the module docstring). ``texture=False`` renders every
    surface with the base spectrum of its stretch / kind (no variation), for tests."""

    SUN_RADIUS_RAD = math.radians(0.2666)

    def __init__(self, scene: RouteScene, *, texture: bool = True, sensitivity: str = CAMERA_SENSITIVITY,
                 fine_texel_m: float = 0.015, coarse_texel_m: float = 0.124,
                 bump_slope: tuple[float, float, float, float] = BUMP_SLOPE) -> None:
        self.scene = scene
        caster = getattr(scene, "_caster", None)
        self.caster: RayCaster = caster if caster is not None else RayCaster(scene.vertices, scene.faces)
        self.textured = texture
        self.basis = material_spectra()  # (M, Λ)
        self.sens = camera_sensitivities(sensitivity)  # (Λ, 3)
        self.texture = _MipTexture(scene.config.texture_size, scene.config.seed) if texture else None
        self.fine_texel_m = fine_texel_m
        self.bump_slope = np.asarray(bump_slope, dtype=np.float64) if texture else np.zeros(4)
        if self.bump_slope.shape != (4,) or np.any(self.bump_slope < 0):
            raise ValueError(f"bump_slope must be 4 slopes >= 0 (ground, rock, trunk, foliage), got {bump_slope}")
        self.coarse_texel_m = coarse_texel_m
        fn = self.caster.face_normals
        self._face_normals = fn.astype(np.float32)
        self._faces = np.ascontiguousarray(scene.faces, dtype=np.int64)
        self._smooth_kind = np.array([True, False, True, False])
        self._vdata = np.ascontiguousarray(np.concatenate(
            [scene.vertex_normals, scene.vertex_attr, scene.vertex_vis], axis=1), dtype=np.float32)
        env = [_B[n] for n in ("sand_light", "grass_green", "soil_brown", "rock_grey", "leaf_litter")]
        self.rho_env = self.basis[env].mean(axis=0)
        self.rho_leaf = self.basis[_B["leaf_green"]]
        self._dirs: dict[tuple, _F32] = {}
        self._no_tex = np.full((1, 4), 0.5, np.float32)
        self._no_off = np.zeros(1, np.int64)
        cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        self._threads = max(1, cpus)

    # -------------------------------------------------------------------------------------------- spectra

    def illuminant_spectra(self, light: Illumination) -> _F64:
        """The four illuminant spectra ``(4, Λ)``: sun (normal), sky (horizontal), foliage and other bounce."""
        glob = light.global_horizontal
        return np.stack([light.direct_normal, light.sky_horizontal, 1.0 * self.rho_leaf * glob,
                         0.5 * self.rho_env * glob])

    def response_matrix(self, light: Illumination) -> _F32:
        """``A`` (M, 4·3): raw response of each basis reflectance under each illuminant, ``(ρ ⊙ E_k) S Δλ / π``."""
        E = self.illuminant_spectra(light)  # (4, Λ)
        A = np.einsum("ml,kl,lc->mkc", self.basis, E, self.sens) * (DLAMBDA_NM / math.pi)
        return A.reshape(len(self.basis), 12).astype(np.float32)

    # -------------------------------------------------------------------------------------------- rendering

    def _camera_dirs(self, camera: PinholeCamera) -> _F32:
        key = (camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy)
        if key not in self._dirs:
            self._dirs[key] = camera.ray_directions().reshape(-1, 3).astype(np.float32)
        return self._dirs[key]

    def render(self, poses: Sequence[ArrayLike], camera: PinholeCamera, light: Illumination,
               rng: np.random.Generator) -> list[RenderOutput]:
        """Render views ``T_map_camera`` (optical frames) of ``camera`` under ``light`` in one batch."""
        with _SingleThreadedBlas():
            return self._render(poses, camera, light, rng)

    def _render(self, poses: Sequence[ArrayLike], camera: PinholeCamera, light: Illumination,
                rng: np.random.Generator) -> list[RenderOutput]:
        dc = self._camera_dirs(camera)
        hw = dc.shape[0]
        nv = len(poses)
        Ts = [np.asarray(T, dtype=np.float64) for T in poses]
        D = np.concatenate([dc @ T[:3, :3].T.astype(np.float32) for T in Ts])
        centres = np.array([T[:3, 3] for T in Ts])
        orig = np.repeat(centres, hw, axis=0)
        hits = self.caster.intersect(orig, D, t_near_m=0.05)
        N = nv * hw
        raw = np.zeros((N, 3), np.float32)
        kind_img = np.full(N, -1, np.int8)
        sun_img = np.zeros(N, np.float32)
        sky_img = np.zeros(N, np.float32)
        pts_img = np.full((N, 3), np.nan, np.float32)
        depth = np.full(N, np.inf, np.float32)
        hit = hits.hit.reshape(-1)
        hi = np.flatnonzero(hit)
        # sky
        si = np.flatnonzero(~hit)
        if len(si):
            sky_rgb = (light.sky_horizontal @ self.sens * (DLAMBDA_NM / math.pi)).astype(np.float32)
            el = np.arcsin(np.clip(D[si, 2], 0.0, 1.0))
            if light.weather == "cloudy":
                grad = 3.0 * (1.0 + 2.0 * np.sin(el)) / 7.0
            else:
                grad = (1.0 + 1.2 * np.exp(-el / 0.15)) / 1.2
            raw[si] = grad[:, None] * sky_rgb
        if len(hi):
            t = np.ascontiguousarray(hits.distance_m.reshape(-1)[hi])
            d = np.ascontiguousarray(D[hi])
            tri = hits.triangle_id.reshape(-1)[hi]
            uv = np.ascontiguousarray(hits.barycentric_uv.reshape(-1, 2)[hi])
            kind = self.scene.face_kind[tri]
            depth[hi] = t * np.tile(dc[:, 2], nv)[hi]
            nh = len(hi)
            p = np.empty((nh, 3))
            ng = np.empty((nh, 3), np.float32)
            n = np.empty((nh, 3), np.float32)
            vv = np.empty((nh, 3), np.float32)
            W = np.zeros((nh, len(self.basis)), np.float32)
            tex = self.texture
            view = (hi // hw).astype(np.int64)

            def shade(sl: slice) -> None:  # the compiled kernel releases the GIL: one chunk per thread
                _shade_kernel(centres, view[sl], t[sl], d[sl], tri[sl], uv[sl], self._faces, self._face_normals,
                              self.scene.face_kind, self._vdata, self._smooth_kind,
                              tex.flat if tex else self._no_tex, tex.offsets if tex else self._no_off,
                              tex.size if tex else 1, tex.n_levels if tex else 1, self.textured,
                              1.0 / self.fine_texel_m, 1.0 / self.coarse_texel_m, float(camera.fx),
                              self.bump_slope, p[sl], ng[sl], n[sl], vv[sl], W[sl])

            step = -(-nh // self._threads)
            slices = [slice(k, min(k + step, nh)) for k in range(0, nh, step)]
            if len(slices) > 1 and nh > 20000:
                with ThreadPoolExecutor(len(slices)) as pool:
                    list(pool.map(shade, slices))
            else:
                shade(slice(0, nh))
            # sun: cosine and one shadow ray per pixel to a point of the sun disk
            s = light.sun_direction_map
            s32 = s.astype(np.float32)
            sunw = np.zeros(nh, np.float32)
            if light.direct_normal.max() > 0.0 and s[2] > -0.01:
                cos = n @ s32
                cand = np.flatnonzero((cos > 0) & (ng @ s32 > 0))
                if len(cand):
                    a = np.array([1.0, 0.0, 0.0]) if abs(s[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
                    e1 = np.cross(s, a)
                    e1 /= np.linalg.norm(e1)
                    e2 = np.cross(s, e1)
                    rr = self.SUN_RADIUS_RAD * np.sqrt(rng.random(len(cand)))
                    ph = rng.uniform(0.0, 2.0 * math.pi, len(cand))
                    sd = s + (rr * np.cos(ph))[:, None] * e1 + (rr * np.sin(ph))[:, None] * e2
                    occ = self.caster.occluded(p[cand] + 0.02 * ng[cand], sd, t_near_m=1e-3)
                    sunw[cand] = np.where(occ, np.float32(0.0), cos[cand])
            # spectral integration: (pixels × basis) · (basis × [illuminant, channel]); A integrates over λ
            R = (W @ self.response_matrix(light)).reshape(-1, 4, 3)
            out = R[:, 0] * sunw[:, None]
            out += R[:, 1] * vv[:, 0:1]
            out += R[:, 2] * vv[:, 1:2]
            out += R[:, 3] * vv[:, 2:3]
            raw[hi] = out
            kind_img[hi] = kind
            sun_img[hi] = sunw
            sky_img[hi] = vv[:, 0]
            pts_img[hi] = p
        H, Wd = camera.height, camera.width
        outs = []
        for k in range(nv):
            sl = slice(k * hw, (k + 1) * hw)
            outs.append(RenderOutput(raw[sl].reshape(H, Wd, 3), depth[sl].reshape(H, Wd),
                                     kind_img[sl].reshape(H, Wd), sun_img[sl].reshape(H, Wd),
                                     pts_img[sl].reshape(H, Wd, 3), sky_img[sl].reshape(H, Wd)))
        return outs
