"""Normalized radiosity (paper Eq. 1–2 with patches): closed forms, energy, furnace, chunked sun update."""
from __future__ import annotations

import numpy as np
import pytest

from lightfast.daylight.lighting_map import LightingMapConfig, prepare_lighting_map
from lightfast.daylight.lights import sky_and_ground, sun_disk
from lightfast.daylight.patches import build_patches
from lightfast.daylight.radiosity import PatchRadiositySolver, PatchTransport, direct_irradiance, vertex_radiosity
from lightfast.daylight.sun import FREIBURG
from lightfast.daylight.sun_update import SunUpdate, sun_radiosity
from lightfast.raycast import RayCaster
from lightfast.sim.validation_rooms import furnished_room
from test.unit.daylight_scenes import closed_box, open_floor

SMALL = LightingMapConfig(patch_size_m=0.3, sky_directions=1024, hemisphere_rays=64, vertex_chunk=4000)


def transport_of(mesh, patch_size_m=0.5, hemisphere_rays=256):
    caster = RayCaster(mesh.vertices_m, mesh.faces)
    patches = build_patches(mesh, patch_size_m=patch_size_m)
    return caster, patches, PatchTransport.compute(patches, caster, hemisphere_rays=hemisphere_rays)


def test_open_floor_closed_forms() -> None:
    """Nothing but a floor: sky irradiance π (uniform radiance 1), sun irradiance cos(zenith), no inter-reflection."""
    mesh = open_floor(rho=(0.2, 0.5, 0.8))
    caster, patches, transport = transport_of(mesh)
    assert np.all(transport.coverage == 0) and not transport.gather.any()
    sky, ground = sky_and_ground(2048)
    e_sky = direct_irradiance(mesh, caster, sky)
    np.testing.assert_allclose(e_sky, np.pi, rtol=1e-3)
    assert not direct_irradiance(mesh, caster, ground).any()
    sun_dir = np.array([0.0, -np.cos(np.radians(30)), np.sin(np.radians(30))])
    e_sun = direct_irradiance(mesh, caster, sun_disk(sun_dir, 8))
    np.testing.assert_allclose(e_sun, 0.5, rtol=1e-4)
    b = vertex_radiosity(mesh, patches, transport, e_sun)
    np.testing.assert_allclose(b, 0.5 * mesh.reflectance, rtol=1e-4)


def test_closed_box_form_factors_and_furnace() -> None:
    """In a closed box every patch sees only the scene: coverage 1; the raw disk-approximation row sums are 1 in the
    median (low only for corner patches, where the point-to-patch approximation is poor — hence the normalization);
    with uniform unit direct irradiance and reflectance ρ the irradiance is 1/(1−ρ) everywhere (furnace)."""
    mesh = closed_box(n=16, rho=0.6)
    _, patches, transport = transport_of(mesh, patch_size_m=0.25)
    np.testing.assert_allclose(transport.coverage, 1.0)
    raw = PatchTransport.from_visibility(patches, transport.visible, transport.coverage, normalize=False)
    sums = raw.gather.sum(axis=1)
    assert abs(np.median(sums) - 1) < 0.03 and 0.6 < sums.min() and sums.max() < 1.05, (sums.min(), sums.max())
    np.testing.assert_allclose(transport.gather.sum(axis=1), 1.0, rtol=1e-5)
    b = PatchRadiositySolver(transport, patches.reflectance, np.ones(patches.count)).solve()
    np.testing.assert_allclose(b / patches.reflectance, 1 / (1 - 0.6), rtol=1e-4)
    fixed = PatchRadiositySolver(transport, patches.reflectance, np.ones(patches.count), iterations=10).solve()
    np.testing.assert_allclose(fixed / patches.reflectance, sum(0.6**k for k in range(11)), rtol=1e-4)


@pytest.fixture(scope="module")
def room_map():
    return prepare_lighting_map(furnished_room(tessellation_m=0.15), FREIBURG, SMALL)


def test_energy_is_conserved(room_map) -> None:
    """No vertex reflects more than the light reaching it; the scene receives back no more indirect light than its
    surfaces emit (some escapes through the window)."""
    lmap = room_map
    d = np.array([0.3, -0.8, 0.5])
    d /= np.linalg.norm(d)
    b_sun = sun_radiosity(lmap, d)
    direct = direct_irradiance(lmap.mesh, lmap.caster, lmap.sun_lights(d))
    b_patch = PatchRadiositySolver(lmap.transport, lmap.patches.reflectance,
                                   lmap.patches.vertex_to_patch @ direct).solve()
    ceiling = lmap.mesh.reflectance * (direct[:, None] + b_patch.max(axis=0)[None, :])
    assert np.all(b_sun <= ceiling * (1 + 1e-5) + 1e-7)
    assert np.all(b_sun >= lmap.mesh.reflectance * direct[:, None] * (1 - 1e-5))
    area = lmap.patches.area_m2[:, None]
    emitted = np.sum(area * b_patch, axis=0)
    received = np.sum(area * (lmap.transport.gather.astype(np.float64) @ b_patch), axis=0)
    assert np.all(received <= emitted)
    assert np.all(received > 0.3 * emitted)  # a room keeps most of its light
    for b in (lmap.sky_radiosity, lmap.ground_radiosity):
        assert np.all(b >= 0) and np.all(b <= lmap.mesh.reflectance * 2 * np.pi + 1e-6)


@pytest.mark.parametrize("patches_per_step", [None, 7])
def test_chunked_sun_update_equals_one_shot(room_map, patches_per_step) -> None:
    lmap = room_map
    d = np.array([-0.2, -0.7, 0.6])
    d /= np.linalg.norm(d)
    one = sun_radiosity(lmap, d)
    update = SunUpdate(lmap, d, chunk_vertices=997, epoch_ns=123, patches_per_step=patches_per_step)
    chunks = list(update.run())
    ids = np.concatenate([c.vertex_ids for c in chunks])
    np.testing.assert_array_equal(ids, np.arange(lmap.num_vertices))  # every vertex exactly once
    assert all(c.epoch_ns == 123 for c in chunks)
    chunked = np.concatenate([c.radiosity for c in chunks])
    np.testing.assert_allclose(chunked, one, rtol=1e-5, atol=1e-5 * float(one.max()))
    assert update.steps_done > len(chunks)  # direct and transport steps came first
    assert one.max() > 0
    if patches_per_step:  # the Jacobi iterations were split into row blocks: many more, smaller steps
        assert update.steps_done > len(chunks) + lmap.patches.count // patches_per_step


def test_sun_below_horizon_gives_zero(room_map) -> None:
    b = sun_radiosity(room_map, np.array([0.0, -0.9, -0.1]) / np.linalg.norm([0.0, -0.9, -0.1]))
    assert not b.any()
