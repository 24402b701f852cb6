"""Simulated rACR scenes (paper §5.1): 20 textured scenes with 3-D micro-structure, their lighting, an Embree
renderer, the AFD metric and the scene files written by ``lightfast sim racr``.

Everything here is the *simulator and evaluation* side. rACR itself reads only a scene's ``reference/``
directory (:func:`lightfast.racr.reference.load_reference`) and, at run time, what the platform and the VSE
stand-in (:mod:`lightfast.sim.racr_platform`) publish: images, a scaled point cloud, VSE poses and reported hand
poses.

Modules: :mod:`~lightfast.sim.racr.materials` (solid noise, canvases, materials), :mod:`~lightfast.sim.racr.builder`
(procedural triangle meshes), :mod:`~lightfast.sim.racr.recipes` (the seven subjects and two sets;
:mod:`~lightfast.sim.racr.recipes_stone`, :mod:`~lightfast.sim.racr.recipes_machines`),
:mod:`~lightfast.sim.racr.lighting` (point light, sun and sky), :mod:`~lightfast.sim.racr.render` (Embree renderer,
sensor), :mod:`~lightfast.sim.racr.afd` (the metric), :mod:`~lightfast.sim.racr.scenes` (S01–S20, truth,
reference observation), :mod:`~lightfast.sim.racr.scene_files` (scene directories).
"""
from __future__ import annotations

from lightfast.sim.racr.afd import AFD_GRID, AFD_SUCCESS_PX, AfdResult, afd, afd_grid_points
from lightfast.sim.racr.builder import DEFAULT_RESOLUTION_M
from lightfast.sim.racr.lighting import Lighting, LightingSpec, resolve_lighting
from lightfast.sim.racr.render import RacrRenderer, RenderResult, SensorModel, camera_for_size, look_at
from lightfast.sim.racr.scene_files import FORMAT_VERSION, generate_racr_set, load_scene, scene_complete, write_scene
from lightfast.sim.racr.scenes import (
    RacrScene,
    RacrSceneSpec,
    SceneTruth,
    build_scene,
    make_reference,
    scene_specs,
)

__all__ = [
    "AFD_GRID",
    "AFD_SUCCESS_PX",
    "DEFAULT_RESOLUTION_M",
    "FORMAT_VERSION",
    "AfdResult",
    "Lighting",
    "LightingSpec",
    "RacrRenderer",
    "RacrScene",
    "RacrSceneSpec",
    "RenderResult",
    "SceneTruth",
    "SensorModel",
    "afd",
    "afd_grid_points",
    "build_scene",
    "camera_for_size",
    "generate_racr_set",
    "load_scene",
    "look_at",
    "make_reference",
    "resolve_lighting",
    "scene_complete",
    "scene_specs",
    "write_scene",
]
