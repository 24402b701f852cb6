"""The daylight simulator: the test room DS1/DS2, a ground-truth renderer and the RGB-D recordings (Krawez et al.).

scene.py (room frame, window, scene records), textures.py (procedural reflectance), rooms.py (DS1, DS2 meshes),
direct_sun.py (glass, sun disk, direct sun), irradiance_cache.py (Monte-Carlo indirect light per vertex),
renderer.py (frames), sensors.py (camera response, depth sensor), sequences.py (the recording set and its light),
trajectory.py (hand-held camera poses), recordings.py (rendering and writing the recordings). The outdoor light
model is :mod:`lightfast.sim.sky_model`.
"""
