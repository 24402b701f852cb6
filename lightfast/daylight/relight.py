"""The relit reference of frame-to-model tracking: brightness scales per live frame and the adapted map rendered at
the coarse pose (paper §III-C, Eq. 3–6, and §III-D, the reference images I_C^ref, I_D^ref of Eq. 7).

:class:`DaylightRelighter` is the pipeline ``daylight_relight_node`` runs, one :meth:`~DaylightRelighter.step` per
live frame at its coarse pose ``T≈`` (from frame-to-frame tracking):

1. *rendering*: one Embree ray per pixel of the live camera's pixel subset Ω (the ``stride_px`` grid) gives the
   normalized radiosity images I_B̂x and the reflectance there (:class:`~lightfast.daylight.brightness.
   RadiosityImages`); one ray per pixel of the reference camera (the live camera scaled by ``reference_scale``,
   one batch) gives the hit triangles and barycentric weights of the reference images and the depth image;
2. *estimation*: the scales ``s_x`` by E_crf (Eq. 4) or E_lin (Eq. 6), averaged over ``window`` frames
   (:class:`~lightfast.daylight.brightness.BrightnessEstimator`);
3. *shading*: the reference colour ``f(Δt · Σ_x s_x I_B̂x)`` of every pixel (Eq. 3 through the camera response).

With ``reference = "reflectance"`` step 3 renders the reflectance map instead, scaled so that its mean grey value
over the valid pixels matches the live image's — the ``refl-f2m`` baseline of §IV-C.

B̂_sun comes from the chunk stream of ``sun_update_node`` (:class:`~lightfast.daylight.sun_update.SunEpochAssembler`
swaps it in only when an epoch is complete); B̂_sky and B̂_grd from the lighting map.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import cv2
import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.config import param
from lightfast.daylight.brightness import (
    COMPONENTS,
    MIN_REFLECTANCE,
    BrightnessEstimator,
    RadiosityImages,
    _grid_rays,
    _pose,
)
from lightfast.daylight.brightness import warm_up as warm_up_brightness
from lightfast.daylight.crf import CameraResponse
from lightfast.daylight.errors import BrightnessError
from lightfast.daylight.lighting_map import LightingMap
from lightfast.node_options import CameraInputOptions, SensorInputOptions, StampOptions

__all__ = ["REFERENCE_KINDS", "DaylightRelighter", "Reference", "RelightConfig"]

log = logging.getLogger(__name__)

#: What the reference colour is rendered from: the relit map (proposed) or the reflectance map (refl-f2m).
REFERENCE_KINDS = ("relit", "reflectance")
_GREY = np.array([0.299, 0.587, 0.114])


@dataclass(frozen=True)
class RelightConfig(SensorInputOptions, CameraInputOptions, StampOptions):
    """Brightness estimation and reference rendering (paper §III-C, §III-D), and the node's frames, sensor QoS and
    stamp checks (``daylight_relight_node``)."""

    lighting_map: str = param("", description="Lighting map directory made by `lightfast daylight prepare`.",
                              read_only=True)
    crf_file: str = param("", description="Camera response + exposure YAML (`lightfast crf calibrate`, or a "
                          "simulator's camera.yaml).", read_only=True)
    reference: str = param("relit", description="Reference colour: the relit map (proposed) or the reflectance "
                           "map scaled to the live mean brightness (refl-f2m baseline).", choices=REFERENCE_KINDS)
    method: str = param("crf", description="Brightness error: E_crf (Eq. 4) or E_lin (Eq. 6).", choices=("crf", "lin"))
    solver: str = param("bounded-lm", description="E_crf solver: Levenberg-Marquardt with s >= 0 or unbounded.",
                        choices=("bounded-lm", "lm"))
    reference_scale: float = param(
        0.5, description="Reference images at this fraction of the live resolution (0.5: a quarter of the rays; "
        "frame-to-model tracking projects the live points into it).", choices=(1.0, 0.5))
    stride_px: int = param(15, description="Grid spacing of the pixel subset Omega, pixels.", min=1, max=200)
    window: int = param(30, description="Frames in the moving average of the scales.", min=1, max=10_000)
    min_reflectance: float = param(MIN_REFLECTANCE, description="Omega drops pixels with a smaller model "
                                   "reflectance in any channel.", min=0.0, max=1.0)
    min_pixels: int = param(10, description="Frames with fewer valid pixels in Omega do not update the scales.",
                            min=1)
    map_frame: str = param("map", description="Frame of the lighting map; coarse poses must be in it.",
                           read_only=True)
    max_sun_epoch_ahead_s: float = param(
        600.0, min=0.0, max=86_400.0,
        description="A sun update epoch stamped more than this ahead of the node's clock is refused (epochs are the "
        "time an update finishes, ahead of the clock by the update's duration); 0 turns the check off.",
    )


@dataclass(frozen=True, eq=False)
class Reference:
    """The reference images of one live frame, rendered at ``T_map_cam`` (the coarse pose ``T≈``).

    ``color`` (H, W, 3) uint8 (0 where nothing was hit), ``depth_m`` (H, W) float32 z-depth (0 = no geometry),
    ``scales`` (K, 3) the averaged brightness scales used (rows :attr:`names`), ``frame_scales`` the single-frame
    estimate (None when the frame was not used), ``seconds`` the stage timings (render, estimate, shade).
    """

    stamp_ns: int
    T_map_cam: NDArray[np.float64]
    color: NDArray[np.uint8]
    depth_m: NDArray[np.float32]
    names: tuple[str, ...]
    scales: NDArray[np.float64]
    frame_scales: NDArray[np.float64] | None
    num_pixels: int
    seconds: dict[str, float] = field(default_factory=dict)

    def scale(self, name: str) -> NDArray[np.float64]:
        return self.scales[self.names.index(name)]


@numba.njit(cache=True, nogil=True)
def _shade(triangle_id: NDArray[np.int64], uv: NDArray[np.float32], faces: NDArray[np.int64],
           values: NDArray[np.float32], mix: NDArray[np.float32]) -> NDArray[np.float32]:
    """Per ray: the per-vertex ``values`` (V, C) interpolated barycentrically at the hit, times ``mix`` (C, D);
    0 where the ray missed (``triangle_id < 0``)."""
    n, c_in, c_out = len(triangle_id), values.shape[1], mix.shape[1]
    out = np.zeros((n, c_out), dtype=np.float32)
    acc = np.empty(c_in, dtype=np.float32)
    for i in range(n):
        f = triangle_id[i]
        if f < 0:
            continue
        b1, b2 = uv[i, 0], uv[i, 1]
        b0 = 1.0 - b1 - b2
        v0, v1, v2 = faces[f, 0], faces[f, 1], faces[f, 2]
        for j in range(c_in):
            acc[j] = b0 * values[v0, j] + b1 * values[v1, j] + b2 * values[v2, j]
        for k in range(c_out):
            total = 0.0
            for j in range(c_in):
                total += acc[j] * mix[j, k]
            out[i, k] = total
    return out


#: Bins of the table that starts the lookup of f(x) in :func:`_apply_response`.
_RESPONSE_BINS = 8192


def _response_table(
    inverse: NDArray[np.float64], bins: int = _RESPONSE_BINS
) -> tuple[NDArray[np.float64], NDArray[np.int16], NDArray[np.float64], NDArray[np.float64]]:
    """The rounded 8-bit camera response ``round(f(x))`` per channel as thresholds, for :func:`_apply_response`.

    ``f(x)`` rounds to at least k where ``x >= threshold[k]``, the exposure where the linear interpolation of the
    inverse table ``f⁻¹`` (256, 3) reaches k − ½ (as :meth:`CameraResponse.apply`); ``threshold[0] = -inf``,
    ``threshold[256] = inf``. ``start`` (bins, 3) holds the level at the lower edge of each bin of a uniform table
    over ``[f⁻¹(0), f⁻¹(255)]``, so a lookup is one read and, outside the steepest part of the curve, at most one
    comparison (a binary search over the 256 entries mispredicted a branch per step: 2 ms per 160×120 reference).
    Returns ``(threshold, start, x0, bins per unit x)``."""
    inv = np.asarray(inverse, dtype=np.float64)
    levels = inv.shape[0]
    threshold = np.empty((levels + 1, 3))
    threshold[0], threshold[levels] = -np.inf, np.inf
    threshold[1:levels] = 0.5 * (inv[:-1] + inv[1:])
    x0, span = inv[0], inv[-1] - inv[0]
    edges = x0 + span * (np.arange(bins)[:, None] / bins)
    start = np.stack([np.searchsorted(threshold[1:levels, c], edges[:, c], side="right") for c in range(3)], axis=1)
    return threshold, start.astype(np.int16), x0, bins / span


@numba.njit(cache=True, nogil=True)
def _apply_response(x: NDArray[np.float32], threshold: NDArray[np.float64], start: NDArray[np.int16],
                    x0: NDArray[np.float64], bin_per_x: NDArray[np.float64]) -> NDArray[np.uint8]:
    """Rounded 8-bit ``f(x)`` (N, 3) through :func:`_response_table`'s arrays (0 for NaN)."""
    n, bins, top = x.shape[0], start.shape[0], threshold.shape[0] - 2
    out = np.empty((n, 3), dtype=np.uint8)
    for i in range(n):
        for c in range(3):
            v = x[i, c]
            b = (v - x0[c]) * bin_per_x[c] if v > x0[c] else 0.0  # NaN: 0
            k = np.int64(start[int(min(b, bins - 1.0)), c])
            while k < top and threshold[k + 1, c] <= v:
                k += 1
            out[i, c] = k
    return out


class DaylightRelighter:
    """Brightness estimation and reference rendering for one camera and lighting map; see the module docstring.

    ``crf`` is the camera response with the exposure of the live camera. B̂_sun is ``None`` until
    :meth:`set_sun_radiosity` is called; :meth:`step` raises :class:`BrightnessError` until then.
    """

    def __init__(self, lmap: LightingMap, crf: CameraResponse, *, config: RelightConfig | None = None) -> None:
        self.lmap = lmap
        self.crf = crf
        self._response = _response_table(crf.inverse)
        self.config = RelightConfig() if config is None else config
        self.names = COMPONENTS
        V = lmap.num_vertices
        # (V, K*3) per-vertex B̂ of all components, sun first; the sun columns are filled by set_sun_radiosity
        self._stack = np.zeros((V, len(self.names) * 3), dtype=np.float32)
        self._stack[:, 3:6] = lmap.sky_radiosity
        self._stack[:, 6:9] = lmap.ground_radiosity
        self._faces = np.ascontiguousarray(np.asarray(lmap.mesh.faces), dtype=np.int64)
        self._reflectance = np.asarray(lmap.mesh.reflectance, dtype=np.float32)
        self.sun_epoch_ns: int | None = None
        self.estimator = self._make_estimator()
        self._warm_up()

    def _warm_up(self) -> None:
        """Run the jitted kernels once with the argument types of :meth:`step` (numba compiles, or loads its cache,
        here rather than on the first live frame)."""
        miss = np.full(1, -1, dtype=np.int64)
        uv = np.zeros((1, 2), dtype=np.float32)
        x = _shade(miss, uv, self._faces, self._stack, np.eye(self._stack.shape[1], 3, dtype=np.float32))
        _shade(miss, uv, self._faces, self._reflectance, np.eye(3, dtype=np.float32))
        _apply_response(x, *self._response)
        warm_up_brightness(self.crf)

    def _make_estimator(self) -> BrightnessEstimator:
        cfg = self.config
        return BrightnessEstimator(self.crf, names=self.names, window=cfg.window, method=cfg.method,  # type: ignore[arg-type]
                                   solver=cfg.solver, min_pixels=cfg.min_pixels)  # type: ignore[arg-type]

    def restart_average(self) -> None:
        """Forget the scales averaged so far (time went back: the frames of the window are from another time)."""
        self.estimator = self._make_estimator()

    def reconfigure(self, config: RelightConfig) -> None:
        """Apply new options; the scale average restarts if the estimation options changed."""
        old, self.config = self.config, config
        if (old.method, old.solver, old.window, old.min_pixels) != (config.method, config.solver, config.window,
                                                                     config.min_pixels):
            self.estimator = self._make_estimator()

    @property
    def ready(self) -> bool:
        """B̂_sun has been set: references can be rendered."""
        return self.sun_epoch_ns is not None

    def set_sun_radiosity(self, sun_radiosity: ArrayLike, epoch_ns: int) -> None:
        """Swap in a complete B̂_sun (V, 3) for the sun time ``epoch_ns``."""
        b = np.asarray(sun_radiosity, dtype=np.float32)
        if b.shape != (self.lmap.num_vertices, 3) or not np.all(np.isfinite(b)):
            raise BrightnessError(f"B̂_sun must be finite with shape ({self.lmap.num_vertices}, 3), got {b.shape}")
        self._stack[:, 0:3] = b
        self.sun_epoch_ns = int(epoch_ns)

    def step(self, stamp_ns: int, rgb: ArrayLike, T_map_cam: ArrayLike, camera: PinholeCamera) -> Reference:
        """Estimate the scales from the live colour image ``rgb`` (H, W, 3 uint8) at the coarse pose and render the
        reference colour and depth there."""
        if not self.ready:
            raise BrightnessError("no complete B̂_sun yet (waiting for the first sun update epoch)")
        img = np.asarray(rgb)
        if img.shape != (camera.height, camera.width, 3):
            raise BrightnessError(f"live image shape {img.shape} does not match the camera "
                                  f"({camera.height}, {camera.width}, 3)")
        if img.dtype != np.uint8:
            raise BrightnessError(f"live image must be uint8 RGB, got {img.dtype}")
        R, t = _pose(T_map_cam)
        cfg = self.config
        t0 = time.perf_counter()
        # Ω: the stride_px grid of the live camera, its own (small) cast
        uv_g, d_g = _grid_rays(camera, cfg.stride_px)
        hits_g = self.lmap.caster.intersect(t, d_g @ R.T)
        comp = _shade(hits_g.triangle_id, hits_g.barycentric_uv, self._faces, self._stack,
                      np.eye(self._stack.shape[1], dtype=np.float32))
        rho = _shade(hits_g.triangle_id, hits_g.barycentric_uv, self._faces, self._reflectance,
                     np.eye(3, dtype=np.float32))
        valid = hits_g.hit & np.all(rho >= cfg.min_reflectance, axis=1)
        depth_g = np.where(hits_g.hit, hits_g.distance_m * d_g[:, 2].astype(np.float32), 0.0).astype(np.float32)
        images = RadiosityImages(uv_g, {n: comp[:, 3 * k: 3 * k + 3] for k, n in enumerate(self.names)}, rho, valid,
                                 depth_g)
        # the reference camera: one ray per pixel of the live camera scaled by reference_scale
        ref_cam = camera if cfg.reference_scale == 1.0 else camera.scaled(cfg.reference_scale)
        _, d_cam = _grid_rays(ref_cam, 1)
        hits = self.lmap.caster.intersect(t, d_cam @ R.T)
        hit, tri_id, uv = hits.hit, hits.triangle_id, hits.barycentric_uv
        depth = np.where(hit, hits.distance_m * d_cam[:, 2].astype(np.float32), 0.0).astype(np.float32)
        t1 = time.perf_counter()
        scales = self.estimator.update(img, images)
        fit = self.estimator.last_fit
        frame_scales = fit.scales.copy() if fit is not None and fit.num_pixels >= cfg.min_pixels else None
        t2 = time.perf_counter()
        h, wd = ref_cam.height, ref_cam.width
        if cfg.reference == "relit":
            # B = Σ_x s_x B̂_x per pixel (the (K·3, 3) matrix holds the scales), then f(Δt · B) through the table
            mix = np.zeros((self._stack.shape[1], 3), dtype=np.float32)
            for k in range(len(self.names)):
                mix[3 * k: 3 * k + 3] = np.diag(scales[k] * self.crf.exposure_factor)
            color8 = _apply_response(_shade(tri_id, uv, self._faces, self._stack, mix), *self._response)
        else:
            refl = _shade(tri_id, uv, self._faces, self._reflectance, np.eye(3, dtype=np.float32))
            m_ref = float(np.mean(refl[hit] @ _GREY)) if hit.any() else 0.0
            live = img if ref_cam is camera else cv2.resize(img, (wd, h), interpolation=cv2.INTER_AREA)
            m_live = float(np.mean(live.reshape(-1, 3)[hit] @ _GREY)) if hit.any() else 0.0
            color8 = np.clip(np.rint(refl * (m_live / m_ref if m_ref > 0 else 0.0)), 0, 255).astype(np.uint8)
        color8 = color8.reshape(h, wd, 3)
        t3 = time.perf_counter()
        return Reference(
            stamp_ns=int(stamp_ns), T_map_cam=np.asarray(T_map_cam, dtype=np.float64).copy(), color=color8,
            depth_m=depth.reshape(h, wd), names=self.names, scales=scales, frame_scales=frame_scales,
            num_pixels=int(np.count_nonzero(valid)),
            seconds={"render": t1 - t0 + (t3 - t2), "estimate": t2 - t1, "cast": t1 - t0, "shade": t3 - t2},
        )
