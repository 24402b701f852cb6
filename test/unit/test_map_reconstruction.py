"""The method's map of a simulated scene: a reconstruction close to, but not equal to, the true mesh."""
from __future__ import annotations

import numpy as np

from lightfast.sim.daylight_scene import make_ds2
from lightfast.sim.map_reconstruction import ReconstructionSettings, reconstruct_map, scan_poses


def _closest(mesh, points):  # noqa: ANN001, ANN202
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices_m.astype(np.float32)),
                        o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    ans = scene.compute_closest_points(o3d.core.Tensor(points.astype(np.float32)))
    return ans["points"].numpy(), ans["primitive_ids"].numpy().astype(np.int64)


def _face_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def test_reconstructed_map_is_near_the_true_surface_but_not_it() -> None:
    scene = make_ds2(resolution_m=0.1)
    cfg = ReconstructionSettings(voxel_m=0.05, width=80, height=60, yaw_step_deg=45.0, grid=2)
    assert len(scan_poses(scene, cfg)) > 20
    recon = reconstruct_map(scene, cfg)
    assert recon.num_vertices > 1000
    q, tri = _closest(scene.mesh, recon.vertices_m)
    dist = np.linalg.norm(q - recon.vertices_m, axis=1)
    assert np.median(dist) < 0.5 * cfg.voxel_m  # a reconstruction, accurate to a fraction of a voxel ...
    assert np.median(dist) > 1e-3  # ... but not the true surface
    # faces wound like the true mesh's (counter-clockwise seen from the room)
    centres = recon.vertices_m[recon.faces].mean(axis=1)
    _, tri_f = _closest(scene.mesh, centres)
    n_rec = _face_normals(recon.vertices_m, recon.faces)
    n_true = _face_normals(scene.mesh.vertices_m, scene.mesh.faces[tri_f])
    assert np.mean(np.einsum("ij,ij->i", n_rec, n_true) > 0) > 0.9
    # reflectance recovered with a few per cent of error
    rho_true = scene.mesh.reflectance[scene.mesh.faces[tri]].mean(axis=1)
    rel = np.abs(recon.reflectance - rho_true) / np.maximum(rho_true, 0.05)
    assert 0.01 < np.median(rel) < 0.15


def test_scene_files_reconstruct_once(tmp_path) -> None:  # noqa: ANN001
    from lightfast.sim.daylight_recordings import _scene_files

    scene = make_ds2(resolution_m=0.3)
    first = _scene_files(tmp_path, scene)
    stamp = first["map"].stat().st_mtime_ns
    again = _scene_files(tmp_path, scene)
    assert again == first and again["map"].stat().st_mtime_ns == stamp  # cached: no second scan
