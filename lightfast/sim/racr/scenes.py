"""The 20 simulated rACR scenes (paper §5.1: S01–S10 indoor, S11–S20 outdoor, S14–S15 day–night): their
specification, the built scene and its reference observation.

:func:`scene_specs` draws the deterministic :class:`RacrSceneSpec` of S01–S20 from a seed: recipe
(:mod:`lightfast.sim.racr.recipes`), the three lighting variants (:mod:`lightfast.sim.racr.lighting`; outdoor a
site and local times), the reference view (azimuth, elevation, distance scale), the initial offset (5–12 cm,
4–10°), the hand–eye transform's size (15–40°, 4–12 cm) and the VSE's monocular scale (0.3–3 m per VSE unit).
:func:`build_scene` builds from it a :class:`RacrScene`: mesh, camera, resolved and auto-exposed lightings, and
:class:`SceneTruth`, all in the ``world`` frame (metres, z up):

* ``T_world_camref``: the reference camera, looking at the subject's target point from the front (−y side);
* ``T_camref_cam0``: the initial camera relative to the reference one (the relocalization's start);
* ``T_cam_hand`` = X (hand–eye), ``T_world_base`` (the platform's base), ``vse_scale_m_per_vse``;
* ``T_world_ref``: the frame of the reference cloud (arbitrary, as a SLAM map's), and the AFD grid
  (:mod:`lightfast.sim.racr.afd`).

:func:`make_reference` makes the :class:`~lightfast.racr.reference.ReferenceObservation` (what rACR reads): a
metric, drift-free VSE cloud in frame ``reference`` and the reference image, at ``T_world_camref`` under the
``reference`` lighting. :class:`RacrScene` also renders views, and makes the platform simulator and VSE stand-in
(:mod:`lightfast.sim.racr_platform`) with the scene's truth, and scores a final pose by AFD.
"""
from __future__ import annotations

import dataclasses
import datetime as dt
import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.daylight.sun import Site, sun_position
from lightfast.geometry import inverse, make_transform, so3_exp
from lightfast.racr.reference import ReferenceObservation
from lightfast.sim.errors import RacrSimError
from lightfast.sim.racr.afd import AfdResult, afd, afd_grid_points
from lightfast.sim.racr.builder import DEFAULT_RESOLUTION_M, Builder, unit
from lightfast.sim.racr.lighting import Lighting, LightingSpec, clock_position, resolve_lighting
from lightfast.sim.racr.recipes import INDOOR, OUTDOOR, RECIPES, indoor_set, outdoor_set
from lightfast.sim.racr.render import RacrRenderer, RenderResult, SensorModel, camera_for_size, look_at
from lightfast.sim.racr_platform import PlatformConfig, PlatformSimulator, VseConfig, VseStandIn
from lightfast.sim.sky_model import float3

__all__ = ["RacrScene", "RacrSceneSpec", "SceneTruth", "build_scene", "make_reference", "scene_specs"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class RacrSceneSpec:
    """Everything that defines a scene before it is built (scene.yaml's ``scene`` section)."""

    name: str
    kind: str
    recipe: str
    seed: int
    lighting: tuple[LightingSpec, ...]
    site: dict[str, Any] | None = None
    camera_azimuth_deg: float = 0.0
    camera_elevation_deg: float = 15.0
    camera_distance_scale: float = 1.0
    initial_translation_m: float = 0.08
    initial_rotation_deg: float = 6.0
    handeye_rotation_deg: float = 25.0
    handeye_translation_m: float = 0.08
    vse_scale_m_per_vse: float = 1.0
    description: str = ""

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "lighting"}
        d["lighting"] = [lt.to_dict() for lt in self.lighting]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RacrSceneSpec:
        d = dict(d)
        d["lighting"] = tuple(LightingSpec.from_dict(x) for x in d.get("lighting", ()))
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise RacrSimError(f"unknown scene key(s): {sorted(unknown)}")
        return cls(**d)

    def site_obj(self) -> Site | None:
        return Site(**self.site) if self.site else None


_SITES = {
    "beijing": dict(latitude_deg=39.99, longitude_deg=116.27, altitude_m=50.0, timezone="Asia/Shanghai"),
    "freiburg": dict(latitude_deg=48.0, longitude_deg=7.85, altitude_m=278.0, timezone="Europe/Berlin"),
    "tianjin": dict(latitude_deg=39.1, longitude_deg=117.17, altitude_m=5.0, timezone="Asia/Shanghai"),
}


def scene_specs(seed: int = 0) -> tuple[RacrSceneSpec, ...]:
    """The 20 scenes S01–S20 (S01–S10 indoor, S11–S20 outdoor), deterministic for ``seed``."""
    specs = []
    for i in range(20):
        rng = np.random.default_rng([seed, i, 7])
        name = f"S{i + 1:02d}"
        outdoor = i >= 10
        recipe = (OUTDOOR if outdoor else INDOOR)[i % 10]
        common: dict[str, Any] = dict(
            camera_azimuth_deg=round(float(rng.uniform(-20, 20)), 2),
            camera_elevation_deg=round(float(rng.uniform(8, 25)), 2),
            camera_distance_scale=round(float(rng.uniform(0.95, 1.1)), 3),
            initial_translation_m=round(float(rng.uniform(0.05, 0.12)), 4),
            initial_rotation_deg=round(float(rng.uniform(4.0, 10.0)), 2),
            handeye_rotation_deg=round(float(rng.uniform(15.0, 40.0)), 2),
            handeye_translation_m=round(float(rng.uniform(0.04, 0.12)), 4),
            vse_scale_m_per_vse=round(float(np.exp(rng.uniform(math.log(0.3), math.log(3.0)))), 4),
        )
        if not outdoor:
            dist = round(float(rng.uniform(0.9, 1.3)), 3)
            inten = 1.0
            ref_tilt = round(float(rng.uniform(30, 40)), 1)
            sim_clock = float(rng.choice([11.0, 1.0]))
            var_clock = float(rng.choice([2.0, 3.0, 9.0, 10.0]))  # lower clock positions: under the table
            lights = (
                LightingSpec("reference", "point", "front light (12 o'clock)", 12.0, ref_tilt, dist,
                             intensity_w_sr=inten),
                LightingSpec("similar", "point", f"front light ({sim_clock:g} o'clock)", sim_clock,
                             round(ref_tilt + float(rng.uniform(-3, 5)), 1), dist, intensity_w_sr=inten),
                LightingSpec("varied", "point", f"side light ({var_clock:g} o'clock, grazing)", var_clock,
                             round(float(rng.uniform(65, 78)), 1), dist, intensity_w_sr=inten),
            )
            specs.append(RacrSceneSpec(name, "indoor", recipe, int(rng.integers(1 << 30)), lights,
                                       description="", **common))
            continue
        site_name = str(rng.choice(list(_SITES)))
        site = dict(_SITES[site_name], heading_deg=round(float(rng.uniform(-25, 25)), 2))
        month = int(rng.integers(4, 10))
        day = int(rng.integers(1, 20))
        morning = bool(rng.random() < 0.5)
        h_ref = float(rng.uniform(9.0, 10.5)) if morning else float(rng.uniform(14.0, 15.5))
        h_var = float(rng.uniform(14.5, 16.0)) if morning else float(rng.uniform(8.5, 10.0))

        def iso(day_: int, hour: float, month: int = month) -> str:
            hh, mm = int(hour), round((hour - int(hour)) * 60) % 60
            return f"2021-{month:02d}-{day_:02d}T{hh:02d}:{mm:02d}:00"

        ref = LightingSpec("reference", "daylight", "clear sky", time_local=iso(day, h_ref),
                           sun_transmittance=1.0)
        sim = LightingSpec("similar", "daylight", "same time of day, days later, light haze",
                           time_local=iso(day + int(rng.integers(2, 8)), h_ref + float(rng.uniform(-0.25, 0.25))),
                           sun_transmittance=round(float(rng.uniform(0.8, 0.95)), 3))
        if name in ("S14", "S15"):
            var = LightingSpec("varied", "point", "night, floodlight from the side",
                               clock_h=float(rng.choice([3.0, 9.0])), tilt_deg=round(float(rng.uniform(55, 70)), 1),
                               distance_m=2.5, intensity_w_sr=1.0, color_rgb=(1.0, 0.85, 0.65), ambient_frac=0.01)
        else:
            var = LightingSpec("varied", "daylight", "other time of day (sun on the other side)",
                               time_local=iso(day + int(rng.integers(3, 10)), h_var),
                               sun_transmittance=round(float(rng.uniform(0.85, 1.0)), 3))
        specs.append(RacrSceneSpec(name, "outdoor", recipe, int(rng.integers(1 << 30)), (ref, sim, var),
                                   site=site, description="", **common))
    return tuple(specs)


@dataclass(frozen=True, eq=False)
class SceneTruth:
    """Truth of a scene (truth.yaml): poses in the world frame, X, the VSE scale and the AFD grid."""

    T_world_camref: F64
    T_camref_cam0: F64
    T_cam_hand: F64
    T_world_base: F64
    T_world_ref: F64
    vse_scale_m_per_vse: float
    afd_points_world: F64
    afd_pixels_ref: F64
    target_m: F64 = field(default_factory=lambda: np.zeros(3))

    @property
    def T_world_cam0(self) -> F64:
        return self.T_world_camref @ self.T_camref_cam0


@dataclass(eq=False)
class RacrScene:
    """A built (or loaded) scene: spec, mesh, camera, resolved lighting variants, truth, reference."""

    spec: RacrSceneSpec
    mesh: ReflectanceMesh
    camera: PinholeCamera
    lightings: dict[str, LightingSpec]
    truth: SceneTruth
    platform_config: PlatformConfig = field(default_factory=PlatformConfig)
    vse_config: VseConfig = field(default_factory=VseConfig)
    reference: ReferenceObservation | None = None
    description: str = ""
    resolution_m: float = DEFAULT_RESOLUTION_M

    @cached_property
    def renderer(self) -> RacrRenderer:
        return RacrRenderer(self.mesh)

    @property
    def site(self) -> Site | None:
        return self.spec.site_obj()

    def lighting(self, name: str) -> Lighting:
        """The resolved lighting variant ``name`` (reference, similar, varied)."""
        if name not in self.lightings:
            raise RacrSimError(f"scene {self.spec.name}: no lighting {name!r} (have {sorted(self.lightings)})")
        cache = self.__dict__.setdefault("_resolved", {})
        spec = self.lightings[name]
        if cache.get(name, (None,))[0] != spec:
            cache[name] = (spec, resolve_lighting(spec, self.site))
        return cache[name][1]

    def sensor(self, name: str) -> SensorModel:
        exp = self.lightings[name].exposure
        return SensorModel(exposure=1.0 if exp is None else float(exp))

    def render(self, T_world_cam: ArrayLike, lighting: str, *, camera: PinholeCamera | None = None,
               seed: int = 0) -> RenderResult:
        return self.renderer.render(T_world_cam, camera or self.camera, self.lighting(lighting),
                                    sensor=self.sensor(lighting), rng=np.random.default_rng(seed))

    def make_platform(self, config: PlatformConfig | None = None, *, seed: int = 0) -> PlatformSimulator:
        """The platform at the scene's initial pose (camera at ``T_world_cam0``) with the true X."""
        X = self.truth.T_cam_hand
        return PlatformSimulator(self.truth.T_world_cam0 @ X, X, config=config or self.platform_config,
                                 T_world_base=self.truth.T_world_base, seed=seed)

    def make_vse(self, lighting: str = "varied", *, config: VseConfig | None = None, seed: int = 0,
                 scale_m_per_vse: float | None = None) -> VseStandIn:
        """A VSE stand-in for a session under ``lighting`` with the scene's monocular scale."""
        return VseStandIn(self.renderer, self.camera, self.lighting(lighting), sensor=self.sensor(lighting),
                          scale_m_per_vse=scale_m_per_vse or self.truth.vse_scale_m_per_vse,
                          config=config or self.vse_config, seed=seed)

    def add_clock_lighting(self, clock_h: float, *, tilt_deg: float | None = None, name: str | None = None) -> str:
        """Add a point-light variant at ``clock_h`` o'clock around the reference view (paper Fig. 7: the reference
        under 12 o'clock, relocalization under 1–12 o'clock), tilted like the ``varied`` light unless
        ``tilt_deg``; auto-exposed at the initial pose. Indoor scenes only. Returns the variant's name."""
        ref = self.lightings["reference"]
        if ref.kind != "point":
            raise RacrSimError(f"scene {self.spec.name}: clock lighting needs a point-light (indoor) scene")
        var = self.lightings.get("varied", ref)
        tilt = float(tilt_deg if tilt_deg is not None else (var.tilt_deg or 70.0))
        dist = float(ref.distance_m or 1.0)
        pos = clock_position(self.truth.target_m, self.truth.T_world_camref, clock_h, tilt, dist)
        name = name or f"clock{clock_h:g}"
        spec = replace(ref, name=name, description=f"point light at {clock_h:g} o'clock", clock_h=float(clock_h),
                       tilt_deg=tilt, position_m=float3(np.round(pos, 6)), exposure=None)
        exp = self.renderer.auto_exposure(self.truth.T_world_cam0, self.camera, resolve_lighting(spec, None))
        self.lightings[name] = replace(spec, exposure=float(f"{exp:.6g}"))
        return name

    def afd(self, T_world_cam: ArrayLike) -> AfdResult:
        """AFD of a final camera pose against the reference pose (truth)."""
        return afd(self.truth.afd_points_world, self.truth.T_world_camref, T_world_cam, self.camera,
                   caster=self.renderer.caster)


def _random_rotation(rng: np.random.Generator, angle_deg: float) -> F64:
    axis = unit(rng.normal(size=3))
    return so3_exp(axis * math.radians(angle_deg))


def _handeye(rng: np.random.Generator, angle_deg: float, trans_m: float) -> F64:
    """X = T_cam_hand: the hand flange a few cm behind/above the camera, rotated by ``angle_deg``."""
    R = _random_rotation(rng, angle_deg)
    t = trans_m * unit(rng.normal(size=3) + np.array([0.0, -0.5, -1.0]))
    return make_transform(R, t)


def build_scene(spec: RacrSceneSpec, *, width: int = 640, height: int = 480,
                resolution_m: float = DEFAULT_RESOLUTION_M, reference: bool = True,
                vse_config: VseConfig | None = None, platform_config: PlatformConfig | None = None) -> RacrScene:
    """Build the mesh, camera, lighting, truth and (unless ``reference`` is False) the reference observation of
    ``spec``. Deterministic."""
    if spec.recipe not in RECIPES:
        raise RacrSimError(f"unknown scene recipe {spec.recipe!r} (have {sorted(RECIPES)})")
    rng = np.random.default_rng([spec.seed, 1])
    b = Builder(resolution_m, spec.seed % 100000)
    outdoor = spec.kind == "outdoor"
    (outdoor_set if outdoor else indoor_set)(b, rng, spec.seed % 100000)
    target, dist, desc = RECIPES[spec.recipe](b, rng, spec.seed % 100000 + 11, outdoor)
    mesh = b.finish()
    camera = camera_for_size(width, height)
    # reference camera: in front of the subject (-y), azimuth and elevation from the spec
    d = dist * spec.camera_distance_scale
    az, el = math.radians(spec.camera_azimuth_deg), math.radians(spec.camera_elevation_deg)
    pos = target + d * np.array([math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el)])
    T_world_camref = look_at(pos, target)
    prng = np.random.default_rng([spec.seed, 2])
    tdir = unit(prng.normal(size=3))
    T_camref_cam0 = make_transform(_random_rotation(prng, spec.initial_rotation_deg),
                                   spec.initial_translation_m * tdir)
    X = _handeye(prng, spec.handeye_rotation_deg, spec.handeye_translation_m)
    T_world_base = make_transform(so3_exp([0.0, 0.0, prng.uniform(-math.pi, math.pi)]),
                                  target + np.array([prng.uniform(-0.3, 0.3), -d - 0.5, -0.1]))
    T_world_ref = make_transform(_random_rotation(prng, prng.uniform(20, 170)), prng.normal(size=3))
    renderer = RacrRenderer(mesh)
    site = spec.site_obj()
    lightings: dict[str, LightingSpec] = {}
    for lt in spec.lighting:
        if lt.kind == "point" and lt.position_m is None:
            pos_l = clock_position(target, T_world_camref, lt.clock_h or 12.0, lt.tilt_deg or 35.0,
                                    lt.distance_m or 1.0)
            lt = replace(lt, position_m=float3(np.round(pos_l, 6)))
        if lt.kind == "daylight":
            if site is None or lt.time_local is None:
                raise RacrSimError(f"lighting {lt.name!r}: daylight needs a site and a local time")
            sp = sun_position(site, dt.datetime.fromisoformat(lt.time_local).replace(tzinfo=site.zone))
            lt = replace(lt, sun_azimuth_deg=round(float(sp.azimuth_deg), 3),
                         sun_elevation_deg=round(float(sp.elevation_deg), 3))
        if lt.exposure is None:
            at = T_world_camref if lt.name == "reference" else T_world_camref @ T_camref_cam0
            exp = renderer.auto_exposure(at, camera, resolve_lighting(lt, site))
            lt = replace(lt, exposure=float(f"{exp:.6g}"))
        lightings[lt.name] = lt
    pts, pix = afd_grid_points(renderer.caster, camera, T_world_camref)
    truth = SceneTruth(T_world_camref, T_camref_cam0, X, T_world_base, T_world_ref, spec.vse_scale_m_per_vse,
                       pts, pix, np.asarray(target, float))
    scene = RacrScene(spec, mesh, camera, lightings, truth, platform_config or PlatformConfig(),
                      vse_config or VseConfig(), None, desc, resolution_m)
    scene.__dict__["renderer"] = renderer
    if reference:
        scene.reference = make_reference(scene, seed=spec.seed % 1000)
    return scene


def make_reference(scene: RacrScene, *, seed: int = 0, lighting: str = "reference") -> ReferenceObservation:
    """The reference observation: a metric VSE cloud in frame ``reference`` around the reference pose, and the
    reference image at exactly that pose."""
    tr = scene.truth
    vse = VseStandIn(scene.renderer, scene.camera, scene.lighting(lighting), sensor=scene.sensor(lighting),
                     scale_m_per_vse=1.0, config=replace(scene.vse_config, drift_rotation_deg_per_m=0.0,
                                                         drift_translation_per_m=0.0, drift_scale_per_m=0.0,
                                                         pose_noise_deg=0.0, pose_noise_m=0.0),
                     T_world_vse=tr.T_world_ref, seed=seed)
    obs = vse.observe(tr.T_world_camref)
    img = scene.render(tr.T_world_camref, lighting, seed=seed + 1).image
    assert img is not None
    return ReferenceObservation(scene.spec.name, lighting, scene.camera, inverse(tr.T_world_ref) @ tr.T_world_camref,
                                obs.points_vse, obs.intensity, img)
