"""The method's map of a simulated daylight scene: reconstructed from a simulated depth scan, not the true mesh.

The paper (Krawez et al., §IV-A) built its maps like this: the room was scanned after sunset (ceiling lamps on,
no sunlight to blind the depth sensor) with the Asus Xtion, fused with hashed-voxel TSDF fusion [23] at 0.5 cm
(DS1) / 0.7 cm (DS2), the mesh extracted, large planes fitted, and the reflectance recovered as in [4]. A method that
tracked against the simulator's exact mesh would enjoy a geometric accuracy no real map has, so the simulated
recordings come with a map made the same way:

1. **Scan**: depth images from standpoints spread over the free floor (two heights, yaw every 30°, three pitches),
   each measured by the recordings' :class:`~lightfast.sim.daylight.sensors.DepthSensor` (correlated disparity noise,
   systematic distortion, projector shadows, registration error; no sun), at poses with the small independent error
   of a tracked scan (``pose_noise_m``, ``pose_noise_deg``).
2. **Fusion**: Open3D's TSDF volume (``voxel_m``, truncation 4 voxels), marching-cubes mesh, fragments
   smaller than ``min_component_triangles`` removed.
3. **Plane augmentation** (the paper: "we augmented the scene geometry by fitting large flat surfaces, such as
   walls, ceiling, and floor, to planes"): planes are found one after another by RANSAC (Open3D's
   ``segment_plane``, inliers within ``plane_distance_m``) among the vertices not yet taken; the inliers whose
   normal agrees with the plane (within ``plane_normal_deg``) are projected onto it, as long as they cover at least
   ``plane_min_area_m2``. Without it, the marching-cubes normals of a flat wall scatter by ~10°, and so do the
   wall's direct sky and sun irradiance in the lighting map: a plain wall's relit reference gets a mottled
   texture the live image lacks, which the photometric term of f2m then locks onto.
4. **Reflectance**: per reconstructed vertex, the true reflectance at the closest point of the true surface (the
   ideal outcome of [4]), times a smooth multiplicative error (sum of random 3-D sinusoids, wavelengths 0.3–1.5 m,
   ``reflectance_error`` rms per channel: shading left in the recovered albedo) and a per-vertex error
   (``reflectance_noise`` rms), clipped to [0, 1].

The result is an ordinary :class:`~lightfast.daylight.mesh.ReflectanceMesh`; nothing of it is used by the
ground-truth renderer, which keeps rendering the true scene.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lightfast.daylight.mesh import ReflectanceMesh
from lightfast.progress import track
from lightfast.raycast import RayCaster
from lightfast.sim.daylight.scene import DaylightScene
from lightfast.sim.daylight.sensors import DepthSensor

__all__ = ["ReconstructionSettings", "fit_planes", "reconstruct_map", "scan_poses"]

F64 = NDArray[np.float64]
_MIN_AREA_M2 = 1e-10  # 0.0001 mm²: safely above zero after float32 rounding


@dataclass(frozen=True)
class ReconstructionSettings:
    """Parameters of the simulated scan, fusion and reflectance recovery (see the module docstring)."""

    voxel_m: float = 0.02
    width: int = 320
    height: int = 240
    heights_m: tuple[float, ...] = (1.0, 1.6)
    yaw_step_deg: float = 30.0
    pitches_deg: tuple[float, ...] = (-40.0, -10.0, 20.0)
    grid: int = 3
    wall_margin_m: float = 0.8
    pose_noise_m: float = 0.003
    pose_noise_deg: float = 0.2
    min_component_triangles: int = 200
    max_planes: int = 16
    plane_distance_m: float = 0.02
    plane_normal_deg: float = 45.0
    plane_min_area_m2: float = 0.5
    reflectance_error: float = 0.06
    reflectance_noise: float = 0.02
    seed: int = 0


def _look(position: F64, yaw: float, pitch: float) -> F64:
    """T_map_camera (optical frame: x right, y down, z forward) looking along yaw (from +x, about +z) and pitch."""
    f = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw), math.sin(pitch)])
    x = np.cross(f, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, np.cross(f, x), f], axis=1)
    T[:3, 3] = position
    return T


def scan_poses(scene: DaylightScene, settings: ReconstructionSettings) -> F64:
    """The scan's true camera poses ``(N, 4, 4)``: a grid of standpoints clear of the furniture."""
    W, D, _ = scene.room_size_m
    m = settings.wall_margin_m
    xs, ys = np.linspace(m, W - m, settings.grid), np.linspace(m, D - m, settings.grid)
    poses = []
    for x in xs:
        for y in ys:
            for z in settings.heights_m:
                p = np.array([x, y, z])
                if any(np.all(p[:2] > np.array(b.lo[:2]) - 0.2) and np.all(p[:2] < np.array(b.hi[:2]) + 0.2)
                       and z < b.hi[2] + 0.2 for b in scene.obstacles):
                    continue
                for yaw in np.arange(0.0, 360.0, settings.yaw_step_deg):
                    for pitch in settings.pitches_deg:
                        poses.append(_look(p, math.radians(yaw), math.radians(pitch)))
    return np.array(poses)


def _perturbed(T: F64, rng: np.random.Generator, settings: ReconstructionSettings) -> F64:
    from lightfast.geometry import so3_exp

    E = np.eye(4)
    E[:3, :3] = so3_exp(rng.normal(0.0, math.radians(settings.pose_noise_deg), 3))
    E[:3, 3] = rng.normal(0.0, settings.pose_noise_m, 3)
    return T @ E


def fit_planes(vertices: F64, faces: NDArray[np.int64], settings: ReconstructionSettings) -> F64:
    """Step 3 of the module docstring: ``vertices`` with those of large flat surfaces projected onto their planes."""
    import open3d as o3d

    cfg = settings
    out = vertices.copy()
    fn = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    vn = np.zeros_like(vertices)
    for k in range(3):  # area-weighted vertex normals
        np.add.at(vn, faces[:, k], fn)
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
    min_vertices = int(cfg.plane_min_area_m2 / cfg.voxel_m**2)  # marching cubes: about one vertex per voxel face
    min_cos = math.cos(math.radians(cfg.plane_normal_deg))
    o3d.utility.random.seed(cfg.seed)
    left = np.arange(len(vertices))
    planes = 0
    for _ in range(2 * cfg.max_planes):  # attempts: a plane's leftovers (its edge vertices) may come back once
        if planes >= cfg.max_planes or len(left) < max(min_vertices, 3):
            break
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(vertices[left]))
        plane, inliers = cloud.segment_plane(distance_threshold=cfg.plane_distance_m, ransac_n=3,
                                             num_iterations=1000)
        n = np.asarray(plane[:3], dtype=np.float64)
        n /= np.linalg.norm(n)
        inliers = left[np.asarray(inliers, dtype=np.int64)]
        members = inliers[np.abs(vn[inliers] @ n) >= min_cos]  # not the edges of other surfaces crossing it
        if len(members) < min_vertices:  # the largest plane left is small: only leftovers remain there
            left = np.setdiff1d(left, inliers, assume_unique=True)
            continue
        # least-squares plane of the members (RANSAC's is through three of them)
        centre = vertices[members].mean(axis=0)
        n = np.linalg.svd(vertices[members] - centre, full_matrices=False)[2][2]
        out[members] -= ((out[members] - centre) @ n)[:, None] * n
        left = np.setdiff1d(left, members, assume_unique=True)
        planes += 1
    return out


def _smooth_field(points: F64, rng: np.random.Generator, n_waves: int = 12) -> F64:
    """A smooth random field with unit rms over ``points`` (N, 3): sum of random 3-D sinusoids."""
    k = rng.normal(size=(n_waves, 3))
    k /= np.linalg.norm(k, axis=1, keepdims=True)
    k *= (2 * math.pi / rng.uniform(0.3, 1.5, n_waves))[:, None]
    phase = rng.uniform(0, 2 * math.pi, n_waves)
    return np.sqrt(2.0 / n_waves) * np.cos(points @ k.T + phase).sum(axis=1)


def _closest_reflectance(mesh: ReflectanceMesh, points: F64) -> F64:
    """The true mesh's reflectance at the surface point closest to each of ``points`` (barycentric)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices_m.astype(np.float32)),
                        o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    ans = scene.compute_closest_points(o3d.core.Tensor(points.astype(np.float32)))
    q = ans["points"].numpy().astype(np.float64)
    tri = mesh.faces[ans["primitive_ids"].numpy().astype(np.int64)]
    a, b, c = (mesh.vertices_m[tri[:, i]] for i in range(3))
    v0, v1, v2 = b - a, c - a, q - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    den = np.maximum(d00 * d11 - d01 * d01, 1e-20)
    wv, ww = (d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den
    w = np.clip(np.stack([1 - wv - ww, wv, ww], 1), 0.0, 1.0)
    w /= w.sum(1, keepdims=True)
    return np.einsum("ni,nic->nc", w, mesh.reflectance[tri])


def reconstruct_map(scene: DaylightScene, settings: ReconstructionSettings | None = None, *,
                    sensor: DepthSensor | None = None, progress: bool = False) -> ReflectanceMesh:
    """The method's map of ``scene``: TSDF fusion of a simulated night-time depth scan with recovered reflectance."""
    import open3d as o3d

    from lightfast.sim.daylight.sequences import camera_for_size

    cfg = settings or ReconstructionSettings()
    sensor = sensor or DepthSensor()
    rng = np.random.default_rng([cfg.seed, 7])
    camera = camera_for_size(cfg.width, cfg.height)
    caster = RayCaster(scene.mesh.vertices_m, scene.mesh.faces)
    intrinsic = o3d.camera.PinholeCameraIntrinsic(camera.width, camera.height, camera.fx, camera.fy,
                                                  camera.cx, camera.cy)
    # a uniform grid over the room (Open3D 0.20's hashed ScalableTSDFVolume returns empty meshes here)
    lo = scene.mesh.vertices_m.min(axis=0) - 4 * cfg.voxel_m
    length = float((scene.mesh.vertices_m.max(axis=0) + 4 * cfg.voxel_m - lo).max())
    volume = o3d.pipelines.integration.UniformTSDFVolume(
        length=length, resolution=math.ceil(length / cfg.voxel_m), sdf_trunc=4 * cfg.voxel_m,
        color_type=o3d.pipelines.integration.TSDFVolumeColorType.NoColor, origin=lo.reshape(3, 1))
    grey = o3d.geometry.Image(np.zeros((camera.height, camera.width, 3), np.uint8))
    T_reg = sensor.registration()
    no_sun = np.zeros((camera.height, camera.width))
    poses = scan_poses(scene, cfg)
    for T_true in track(poses, desc=f"{scene.name} scan", total=len(poses), enabled=progress, unit="view"):
        depth = sensor.measure(sensor.true_depth(caster, T_true @ T_reg, camera), no_sun, rng)
        T_tracked = _perturbed(T_true, rng, cfg)  # the scan's own pose estimate
        rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
            grey, o3d.geometry.Image(depth.astype(np.float32)), depth_scale=1.0,
            depth_trunc=sensor.max_depth_m, convert_rgb_to_intensity=False)
        volume.integrate(rgbd, intrinsic, np.linalg.inv(T_tracked))
    mesh = volume.extract_triangle_mesh()
    clusters, counts, _ = mesh.cluster_connected_triangles()
    clusters, counts = np.asarray(clusters), np.asarray(counts)
    mesh.remove_triangles_by_mask(counts[clusters] < cfg.min_component_triangles)
    mesh.remove_degenerate_triangles()
    mesh.remove_non_manifold_edges()
    f = np.asarray(mesh.triangles, dtype=np.int64)  # counter-clockwise seen from the free side, as ours
    v = fit_planes(np.asarray(mesh.vertices, dtype=np.float64), f, cfg)
    v = v.astype(np.float32).astype(np.float64)  # as a PLY file holds them
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    f = f[area > _MIN_AREA_M2]  # marching cubes makes slivers of zero area where the surface grazes a voxel corner
    used = np.unique(f)
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    vertices, faces = v[used], remap[f]
    rho = _closest_reflectance(scene.mesh, vertices)
    rng_rho = np.random.default_rng([cfg.seed, 8])
    gain = 1.0 + cfg.reflectance_error * np.stack([_smooth_field(vertices, rng_rho) for _ in range(3)], 1)
    gain *= 1.0 + cfg.reflectance_noise * rng_rho.normal(size=gain.shape)
    out = ReflectanceMesh(vertices, faces, np.clip(rho * gain, 0.0, 1.0))
    out.validate_topology(min_area_m2=_MIN_AREA_M2)  # what `lightfast daylight prepare` requires
    return out
