"""Window openings: light enters a lighting map only through them, not through holes of a reconstructed mesh."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lightfast.daylight.errors import OpeningsError
from lightfast.daylight.lighting_map import LightingMap, LightingMapConfig, prepare_lighting_map
from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.daylight.openings import Opening, load_openings, openings_array, save_openings, through_openings
from lightfast.daylight.sun import FREIBURG
from lightfast.sim.validation_rooms import box_room_with_window

# the default validation room's south window (1.6 × 1.5 m, sill 0.8 m, centred in x ∈ [0, 4.5]) in the outer plane
# of its 0.2-m wall, 2 cm larger on every side
WINDOW = Opening((1.43, -0.2, 0.78), (1.64, 0.0, 0.0), (0.0, 0.0, 1.54), name="south")
CONFIG = LightingMapConfig(patch_size_m=0.4, sky_directions=512, hemisphere_rays=16)


def test_rays_through_a_parallelogram() -> None:
    square = openings_array([Opening((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))])
    origins = np.array([[0.5, 0.5, 1.0], [0.5, 0.5, 1.0], [1.5, 0.5, 1.0], [0.5, 0.5, -1.0], [0.5, 0.5, 1.0],
                        [0.0, 0.0, 1.0]])
    directions = np.array([[0, 0, -1], [0.2, 0.2, -1], [0, 0, -1], [0, 0, -1], [1, 0, 0], [0.5, 0.5, -1.0]])
    # straight through; slanted through; beside it; pointing away (the plane is behind); parallel; onto the corner
    np.testing.assert_array_equal(through_openings(origins, directions, square),
                                  [True, True, False, False, False, True])
    assert not through_openings(origins, directions, openings_array(None)).any()


def _room_with_hole() -> tuple[ReflectanceMesh, ReflectanceMesh]:
    """The validation room, and the same room with a 1 × 0.6 m hole at the foot of its east wall (x = 4.5), as a
    scan leaves behind a cabinet."""
    room = box_room_with_window(tessellation_m=0.2)
    c = room.vertices_m[room.faces].mean(axis=1)
    hole = (np.abs(c[:, 0] - 4.5) < 1e-6) & (c[:, 1] > 3.0) & (c[:, 1] < 4.0) & (c[:, 2] < 0.6)
    assert hole.sum() > 10
    return room, ReflectanceMesh(room.vertices_m, room.faces[~hole], room.reflectance)


def _near_hole(mesh: ReflectanceMesh) -> np.ndarray:
    """Vertices of the north wall (y = 4.8) near the hole's corner."""
    v = mesh.vertices_m
    return (np.abs(v[:, 1] - 4.8) < 1e-6) & (v[:, 0] > 3.4) & (v[:, 2] < 0.6)


def test_openings_keep_light_from_leaking_through_holes() -> None:
    room, holed = _room_with_hole()
    near = _near_hole(room)
    plain = prepare_lighting_map(room, FREIBURG, CONFIG)
    closed = prepare_lighting_map(room, FREIBURG, CONFIG, openings=[WINDOW])
    leaky = prepare_lighting_map(holed, FREIBURG, CONFIG)
    sealed = prepare_lighting_map(holed, FREIBURG, CONFIG, openings=[WINDOW])
    sky = {name: m.sky_radiosity[near].mean() for name, m in (("closed", closed), ("leaky", leaky),
                                                               ("sealed", sealed))}
    assert sky["leaky"] > 1.5 * sky["closed"], sky  # the hole lets the sky in
    assert abs(sky["sealed"] / sky["closed"] - 1.0) < 0.05, sky  # only the window does
    # in the intact room the openings only take away light that came in elsewhere than through the window: rays
    # along the room's edges slip through the seams of its parts (a few % of the light, all of it indirect away
    # from the edges)
    v = room.vertices_m
    inner = np.all((v[:, :2] > 0.3) & (v[:, :2] < [4.2, 4.5]), axis=1)
    for a, b in ((closed.sky_radiosity, plain.sky_radiosity), (closed.ground_radiosity, plain.ground_radiosity)):
        assert np.all(a <= b * (1 + 1e-5) + 1e-9)
        ratio = (a[inner] / b[inner]).mean(axis=1)
        assert ratio.min() > 0.8 and np.median(ratio) > 0.95, (ratio.min(), np.median(ratio))


def test_openings_are_saved_with_the_map(tmp_path: Path) -> None:
    room, _ = _room_with_hole()
    lmap = prepare_lighting_map(room, FREIBURG, CONFIG, openings=[WINDOW])
    loaded = LightingMap.load(lmap.save(tmp_path / "m"))
    np.testing.assert_array_equal(loaded.openings, openings_array([WINDOW]))
    plain = LightingMap.load(prepare_lighting_map(room, FREIBURG, CONFIG).save(tmp_path / "plain"))
    assert plain.openings.shape == (0, 3, 3)


def test_openings_file_round_trip_and_bad_files(tmp_path: Path) -> None:
    path = save_openings(tmp_path / "o.yaml", [WINDOW])
    assert load_openings(path) == (WINDOW,)
    with pytest.raises(OpeningsError, match="cannot read"):
        load_openings(tmp_path / "missing.yaml")
    (tmp_path / "other.yaml").write_text("format: something-else\n")
    with pytest.raises(OpeningsError, match="not an openings file"):
        load_openings(tmp_path / "other.yaml")
    (tmp_path / "empty.yaml").write_text("format: lightfast-openings\nversion: 1\nopenings: []\n")
    with pytest.raises(OpeningsError, match="non-empty list"):
        load_openings(tmp_path / "empty.yaml")
    (tmp_path / "short.yaml").write_text("format: lightfast-openings\nversion: 1\nopenings:\n- corner_m: [0, 0, 0]\n")
    with pytest.raises(OpeningsError, match="needs corner_m, edge_u_m, edge_v_m"):
        load_openings(tmp_path / "short.yaml")
    with pytest.raises(OpeningsError, match="parallel or zero"):
        Opening((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (2.0, 0.0, 0.0))
    with pytest.raises(OpeningsError, match="finite 3-vectors"):
        Opening((0.0, 0.0, float("nan")), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
