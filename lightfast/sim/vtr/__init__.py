"""The simulated outdoor route for colour-constant stereo visual teach & repeat (paper: Paton et al., "It's Not Easy
Seeing Green", ICRA 2015, §V–VI): ``lightfast sim vtr``. One module per concept:

* :mod:`~lightfast.sim.vtr.spectra` — wavelength grid, reflectance basis, measured camera sensitivities, the
  spectral camera integral;
* :mod:`~lightfast.sim.vtr.light` — clear-sky and overcast daylight spectra (SPCTRAL2-like);
* :mod:`~lightfast.sim.vtr.camera` — the rectified stereo rig, sensor noise, auto-exposure, 8-bit output;
* :mod:`~lightfast.sim.vtr.scene` — route parameters, the scene mesh and its file, the robot's pose on it;
* :mod:`~lightfast.sim.vtr.build` — procedural construction of the route (terrain, rocks, trees, sky visibility);
* :mod:`~lightfast.sim.vtr.shading` — procedural texture, materials and micro-relief (compiled kernel);
* :mod:`~lightfast.sim.vtr.renderer` — the spectral renderer (Embree rays, four illuminants);
* :mod:`~lightfast.sim.vtr.recordings` — driving the runs of the paper's Table I and writing bags and truth.

The design and its measurements are in docs/vtr.md ("The simulated route").
"""
