"""The subjects and sets of the simulated rACR scenes (paper §5.1: 20 scenes, indoor and outdoor, cultural heritage
and equipment): which recipe each scene uses.

S01–S10 (:data:`INDOOR`) stand on a wooden table in front of a plaster wall (:func:`indoor_set`), S11–S20
(:data:`OUTDOOR`) on paving (:func:`outdoor_set`). A recipe (:data:`~lightfast.sim.racr.builder.Recipe`) builds
its subject from procedural triangle meshes into a :class:`~lightfast.sim.racr.builder.Builder` (world frame,
metres, z up, the front facing −y) and returns ``(target point (3,) m, base camera distance m, description)``:

========  ============================================================================================
recipe    geometry
========  ============================================================================================
panel     carved relief panel: raised frame with a carved meander or rope groove, raised rosette or
          scrolls with carved veins, a carved inscription line; sandstone, marble, wood or plaster
tablet    inscription tablet / stele: carved border, 4–6 lines of V-cut letters (Hershey fonts), pits
cabinet   equipment cabinet: door seam, vent slots, raised name plate, labels, hex bolts, a pipe with
          flanges and bolt circles, a gauge
motor     electric motor / pump: finned body (lathe with displaced fins), end shields with bolt circles,
          shaft and coupling, feet, terminal box with bolts and labels
stupa     stupa: plinth with carved niches, drum with a carved band, bell dome with a lotus-petal band,
          harmika, ringed spire, finial
facade    stone facade: staggered blocks with recessed joints and bevels, a carved emblem block with an
          inscription, a cornice with dentils
bogie     train bogie side: frame plate with lightening holes, ribs and stamped text, wheels with carved
          rings, axle boxes with bolts and labels, coil springs, rails on ballast
========  ============================================================================================

Stone subjects are in :mod:`~lightfast.sim.racr.recipes_stone`, machines in
:mod:`~lightfast.sim.racr.recipes_machines`.
"""
from __future__ import annotations

import numpy as np

from lightfast.sim.racr.builder import Builder, Recipe
from lightfast.sim.racr.materials import paving, plaster, wood
from lightfast.sim.racr.recipes_machines import MACHINE_RECIPES
from lightfast.sim.racr.recipes_stone import STONE_RECIPES

__all__ = ["INDOOR", "OUTDOOR", "RECIPES", "indoor_set", "outdoor_set"]


def indoor_set(b: Builder, rng: np.random.Generator, seed: int) -> None:
    """Wooden table top (z = 0) and a plaster wall behind (y = 0.35)."""
    tone = rng.uniform(0.8, 1.1)
    b.surface((-0.75, -0.7, 0.0), (1, 0, 0), (0, 1, 0), 1.5, 1.05, wood(np.array([0.45, 0.28, 0.15]) * tone, seed + 1),
              step=b.coarse, taper_m=0.0)
    b.surface((-0.85, 0.35, 0.0), (1, 0, 0), (0, 0, 1), 1.7, 1.1,
              plaster(np.array([0.72, 0.70, 0.64]) * rng.uniform(0.85, 1.05), seed + 2), step=b.coarse,
              taper_m=0.0)


def outdoor_set(b: Builder, rng: np.random.Generator, seed: int, size: float = 3.2) -> None:
    b.surface((-size / 2, -size / 2 - 0.4, 0.0), (1, 0, 0), (0, 1, 0), size, size, paving(seed + 1),
              step=b.coarse, taper_m=0.0)


#: All recipes by name.
RECIPES: dict[str, Recipe] = {**STONE_RECIPES, **MACHINE_RECIPES}
INDOOR = ("panel", "tablet", "cabinet", "motor", "panel", "stupa", "tablet", "cabinet", "motor", "panel")
OUTDOOR = ("stupa", "tablet", "facade", "bogie", "cabinet", "facade", "stupa", "tablet", "motor", "bogie")
