"""Brightness scale estimation (paper §III-C, Eq. 3–6) and rendering of the adapted map (§III-D reference image).

Inputs: a lighting map (mesh in the z-up map frame with per-vertex normalized radiosities B̂_x, x ∈ sun, sky,
ground), the coarse pose ``T≈ = T_map_cam`` (4×4, metres; camera in the REP-103 optical frame), the live colour
image I_C (pixel values 0..255) and the camera response ``f`` with its Δt (:mod:`lightfast.daylight.crf`). Per frame:

1. :func:`radiosity_images` renders the normalized radiosity images ``I_B̂x`` on the pixel subset Ω — a uniform grid
   every ``stride_px`` pixels (15 in the paper) — by casting one ray per grid pixel and interpolating the per-vertex
   B̂_x barycentrically. Ω is filtered: pixels whose ray misses the mesh or whose model reflectance is below 0.03 in
   any channel are invalid.
2. :func:`fit_scales` finds the brightness scales ``s_x`` (per colour channel; physical when the camera's
   ``sensitivity`` is, docs/daylight.md) minimizing ``E_crf = Σ_u (I_C(u) − f(Δt · Σ_x s_x I_B̂x(u)))²`` (Eq. 3–5)
   or ``E_lin = Σ_u (f⁻¹(I_C(u))/Δt − Σ_x s_x I_B̂x(u))²`` (Eq. 6, non-negative linear least squares). Over-exposed
   pixels only bound the radiosity from below; E_crf models that (a pixel predicted saturated that is saturated has
   zero residual, one predicted darker pulls the scales up), E_lin clips them and under-estimates the brightness
   (paper Fig. 5).
3. :class:`BrightnessEstimator` averages the per-frame estimates over a window of 30 frames.
4. :func:`relit_image` renders the colour ``f(Δt · Σ_x s_x I_B̂x)`` (pixel values in [0, 255]) and the z-depth (m) of
   every pixel, the reference images of frame-to-model tracking.

Solver for E_crf: Levenberg–Marquardt as in the paper, written out for the K ≤ 3 unknowns of a channel. By default
(``solver="bounded-lm"``) each trial step is projected onto ``s ≥ 0``: brightness scales are physically
non-negative, and a component that barely reaches the valid pixels (the sun on a cloudy day, or out of view) would
otherwise drift negative to absorb noise. ``solver="lm"`` (unbounded LM) is available; its result is clipped at 0.
Both start from the better (by E_crf) of the E_lin solution on unsaturated pixels and the caller's ``initial`` (e.g.
the previous average): a start at which all pixels are predicted saturated has no gradient. Components whose images
are zero on all valid pixels are *unobserved*: they keep their initial value (0 without one) and are flagged in
:attr:`ScaleFit.observed`. Δt in Eq. 4 is :attr:`CameraResponse.exposure_factor` (sensitivity · exposure_s · gain).
"""
from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING, Any, Literal

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import nnls

from lightfast.camera import PinholeCamera
from lightfast.daylight.crf import CameraResponse
from lightfast.daylight.errors import BrightnessError

if TYPE_CHECKING:
    from lightfast.daylight.lighting_map import LightingMap

__all__ = [
    "COMPONENTS",
    "MIN_REFLECTANCE",
    "BrightnessEstimator",
    "RadiosityImages",
    "RelitImage",
    "ScaleFit",
    "fit_scales",
    "radiosity_images",
    "relit_image",
    "warm_up",
]

#: The illumination components of §III-A, in the order of :attr:`ScaleFit.scales` rows.
COMPONENTS = ("sun", "sky", "ground")
#: Reflectance below which a pixel of Ω is dropped (§III-C).
MIN_REFLECTANCE = 0.03
#: Pixel values outside [LOW, HIGH] are not used to initialize the E_crf fit (clipped or in the noise).
_INIT_LOW, _INIT_HIGH = 2.0, 250.0

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]


# ----------------------------------------------------------------------------------------------------------------
# ray casting and interpolation


def _pose(T_map_cam: ArrayLike) -> tuple[F64, F64]:
    T = np.asarray(T_map_cam, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise BrightnessError(f"T_map_cam must be a finite 4x4 matrix, got shape {T.shape}")
    return T[:3, :3], T[:3, 3]


@lru_cache(maxsize=32)
def _grid_rays(camera: PinholeCamera, stride_px: int) -> tuple[NDArray[np.int64], F64]:
    """Pixels of Ω ``(N, 2)`` as integer ``(u, v)`` and their unit ray directions ``(N, 3)`` in the optical frame.

    ``stride_px = 1`` is every pixel (row-major). Otherwise the grid points are the centres of ``stride × stride``
    cells: ``u = stride // 2 + k · stride``. Cached per camera (arrays are read-only)."""
    off = stride_px // 2 if stride_px > 1 else 0
    us = np.arange(off, camera.width, stride_px)
    vs = np.arange(off, camera.height, stride_px)
    vv, uu = np.meshgrid(vs, us, indexing="ij")
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.int64)
    d = camera.backproject(uv.astype(np.float64), np.ones(len(uv)))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    uv.setflags(write=False)
    d.setflags(write=False)
    return uv, d


def _component_names(components: Mapping[str, ArrayLike], num_vertices: int) -> tuple[str, ...]:
    if not components:
        raise BrightnessError("need at least one radiosity component")
    for name, a in components.items():
        shape = np.shape(a)
        if shape != (num_vertices, 3):
            raise BrightnessError(f"component {name!r} must have shape ({num_vertices}, 3), got {shape}")
    return tuple(components)


def _component_stack(components: Mapping[str, ArrayLike], rows: int, *, what: str = "component",
                     like: str = "", dtype: type = np.float32) -> tuple[tuple[str, ...], np.ndarray]:
    """Named (rows, 3) arrays stacked to (rows, K, 3), each checked for its shape."""
    if not components:
        raise BrightnessError(f"need at least one radiosity {what}")
    names = tuple(components)
    arrays = []
    for name in names:
        a: NDArray[Any] = np.asarray(components[name], dtype=dtype)
        if a.shape != (rows, 3):
            raise BrightnessError(f"{what} {name!r} must have shape ({rows}, 3){like}, got {a.shape}")
        arrays.append(a)
    return names, np.stack(arrays, axis=1)


def _cast(lmap: LightingMap, camera: PinholeCamera, T_map_cam: ArrayLike, stride_px: int
          ) -> tuple[NDArray[np.int64], NDArray[np.bool_], tuple[NDArray[np.int64], ...], F32, F32]:
    """Cast the rays of Ω; returns (uv (N, 2), hit (N,), the 3 corner vertex ids (N,) each, barycentric weights
    (N, 3), z depth (N,)). Misses get vertex 0 with weight 0 (no compress/scatter of the hits needed)."""
    R, t = _pose(T_map_cam)
    uv, d_cam = _grid_rays(camera, stride_px)
    hits = lmap.caster.intersect(t, d_cam @ R.T)
    hit = hits.hit
    faces = np.asarray(lmap.mesh.faces)
    tri = np.take(faces, np.maximum(hits.triangle_id, 0), axis=0)
    corners = tuple(np.ascontiguousarray(tri[:, i]) for i in range(3))
    bu = np.nan_to_num(hits.barycentric_uv, nan=0.0)
    w = np.empty((len(uv), 3), dtype=np.float32)
    w[:, 1] = bu[:, 0]
    w[:, 2] = bu[:, 1]
    w[:, 0] = np.where(hit, 1.0 - bu[:, 0] - bu[:, 1], 0.0)
    depth = np.where(hit, hits.distance_m * d_cam[:, 2].astype(np.float32), 0.0).astype(np.float32)
    return uv, hit, corners, w, depth


def _interpolate(values: NDArray[np.floating], corners: tuple[NDArray[np.int64], ...], w: F32) -> F32:
    """Barycentric interpolation of per-vertex ``values`` (V, C) at the rays with corner ids and weights (N, 3)."""
    out = np.take(values, corners[0], axis=0) * w[:, 0:1]
    out += np.take(values, corners[1], axis=0) * w[:, 1:2]
    out += np.take(values, corners[2], axis=0) * w[:, 2:3]
    return out.astype(np.float32, copy=False)


@dataclass(frozen=True, eq=False)
class RadiosityImages:
    """The normalized radiosity images ``I_B̂x`` on the pixel subset Ω (§III-C); N grid pixels.

    Attributes:
        uv_px: (N, 2) int64 pixel coordinates ``(u, v)`` of Ω (all grid pixels, valid or not).
        images: component name → (N, 3) float32 ``I_B̂x`` (0 where the ray missed).
        reflectance: (N, 3) float32 interpolated model reflectance (0 where missed).
        valid: (N,) bool: the ray hit the mesh and the reflectance is ≥ 0.03 in every channel.
        depth_m: (N,) float32 z-depth of the hit in metres (0 where missed).
    """

    uv_px: NDArray[np.int64]
    images: dict[str, F32]
    reflectance: F32
    valid: NDArray[np.bool_]
    depth_m: F32

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.images)

    def __len__(self) -> int:
        return len(self.uv_px)

    def sample(self, image: ArrayLike) -> F64:
        """The values of a full image ``(H, W, 3)`` (e.g. the live colour image I_C) at Ω → (N, 3) float64."""
        img = np.asarray(image)
        if img.ndim != 3 or img.shape[2] != 3:
            raise BrightnessError(f"image must have shape (H, W, 3), got {img.shape}")
        u, v = self.uv_px[:, 0], self.uv_px[:, 1]
        if len(u) and (u.max() >= img.shape[1] or v.max() >= img.shape[0]):
            raise BrightnessError(f"image of shape {img.shape} is smaller than the camera of these radiosity images")
        return img[v, u].astype(np.float64)


def radiosity_images(
    lmap: LightingMap,
    components: Mapping[str, ArrayLike],
    T_map_cam: ArrayLike,
    camera: PinholeCamera,
    *,
    stride_px: int = 15,
    min_reflectance: float = MIN_REFLECTANCE,
) -> RadiosityImages:
    """Render ``I_B̂x`` for each component on the grid Ω (every ``stride_px`` pixels) at pose ``T_map_cam``.

    ``components`` maps names (e.g. ``"sun"``, ``"sky"``, ``"ground"``) to per-vertex normalized radiosity (V, 3),
    e.g. ``{"sun": sun_radiosity(lmap, s), "sky": lmap.sky_radiosity, "ground": lmap.ground_radiosity}``. Only
    ``lmap.mesh`` and ``lmap.caster`` are used.
    """
    if int(stride_px) < 1:
        raise BrightnessError(f"stride_px must be >= 1, got {stride_px}")
    names = _component_names(components, lmap.mesh.num_vertices)
    uv, hit, corners, w, depth = _cast(lmap, camera, T_map_cam, int(stride_px))
    images = {name: _interpolate(np.asarray(components[name]), corners, w) for name in names}
    rho = _interpolate(np.asarray(lmap.mesh.reflectance), corners, w)
    valid = hit & np.all(rho >= min_reflectance, axis=1)
    return RadiosityImages(uv, images, rho, valid, depth)


# ----------------------------------------------------------------------------------------------------------------
# scale fitting


@dataclass(frozen=True, eq=False)
class ScaleFit:
    """Brightness scales of one frame.

    Attributes:
        names: component names, the rows of ``scales``.
        scales: (K, 3) ``s_x`` per component and colour channel (R, G, B).
        observed: (K, 3) bool: the component reached valid pixels in that channel (else its scale is the initial).
        rms_px: (3,) RMS pixel residual of Eq. 4 at the solution, per channel (comparable across methods).
        num_pixels: valid pixels used.
        method: ``"crf"`` (Eq. 4) or ``"lin"`` (Eq. 6).
    """

    names: tuple[str, ...]
    scales: F64
    observed: NDArray[np.bool_]
    rms_px: F64
    num_pixels: int
    method: str

    def __getitem__(self, name: str) -> F64:
        return self.scales[self.names.index(name)]

    def as_dict(self) -> dict[str, F64]:
        return {n: self.scales[i].copy() for i, n in enumerate(self.names)}


def _as_scales(scales: ArrayLike | Mapping[str, ArrayLike] | ScaleFit, names: Sequence[str]) -> F64:
    if isinstance(scales, ScaleFit):
        scales = scales.as_dict()
    if isinstance(scales, Mapping):
        missing = [n for n in names if n not in scales]
        if missing:
            raise BrightnessError(f"no scale for component(s) {missing}")
        arr = np.stack([np.broadcast_to(np.asarray(scales[n], dtype=np.float64), (3,)) for n in names])
    else:
        arr = np.asarray(scales, dtype=np.float64)
        if arr.shape == (len(names),):
            arr = np.repeat(arr[:, None], 3, axis=1)
    if arr.shape != (len(names), 3) or not np.all(np.isfinite(arr)):
        raise BrightnessError(f"scales must be finite with shape ({len(names)}, 3), got {arr.shape}")
    return arr


@numba.njit(cache=True, nogil=True)
def _crf_residuals(A: F64, y: F64, table: F64, slopes: F64, s: F64) -> tuple[F64, F64]:
    """Residuals ``f_c(A s) − y`` of one channel and their derivatives ``f_c′(A s)``: the inverse table ``table``
    (256,) of the channel is linear between its entries (``slopes`` (255,) their reciprocal spacing); ``f`` is 0
    below ``table[0]`` and 255 from ``table[255]`` on, with slope 0 there (as :meth:`CameraResponse.
    channel_and_derivative`)."""
    n, top = len(y), len(table) - 1
    x = A @ s
    r = np.empty(n)
    d = np.zeros(n)
    for i in range(n):
        k = np.searchsorted(table, x[i], side="right") - 1  # segment; -1 below, top at/after the end
        if k < 0:
            r[i] = -y[i]
        elif k >= top:
            r[i] = top - y[i]
        else:
            d[i] = slopes[k]
            r[i] = k + (x[i] - table[k]) * d[i] - y[i]
    return r, d


@numba.njit(cache=True, nogil=True)
def _fit_channel_crf(A: F64, y: F64, table: F64, slopes: F64, x0: F64, bounded: bool, max_iterations: int,
                     tolerance: float) -> F64:
    """Minimize Eq. 4 for one channel over the columns of ``A`` (already multiplied by Δt) by Levenberg–Marquardt.

    A hand-written LM (Marquardt's diagonal damping; the system has only K ≤ 3 unknowns, so one step costs one
    evaluation of f and f′ and a K×K solve — far cheaper than a general solver's bookkeeping). ``bounded`` keeps
    ``s ≥ 0`` by projecting every trial step onto the bound (a step is accepted only if it lowers the cost);
    unbounded, the result is clipped at 0. ``table``, ``slopes``: the channel's response as in
    :func:`_crf_residuals`.
    """
    k = len(x0)
    s = np.maximum(x0, 0.0) if bounded else x0.copy()
    r, d = _crf_residuals(A, y, table, slopes, s)
    J = d[:, None] * A
    cost = r @ r
    lam = 1e-3
    for _ in range(max_iterations):
        g = J.T @ r
        H = J.T @ J
        # bounded: components held at s = 0 by a gradient pointing below it stay fixed (active set)
        free = np.ones(k, dtype=np.bool_)
        if bounded:
            free = ~((s <= 0.0) & (g > 0.0))
        idx = np.flatnonzero(free)
        m = len(idx)
        if m == 0:
            break
        Hf = np.empty((m, m))
        gf = np.empty(m)
        for a in range(m):
            gf[a] = g[idx[a]]
            for b in range(m):
                Hf[a, b] = H[idx[a], idx[b]]
        diag = np.maximum(np.diag(Hf).copy(), 1e-12 * max(np.max(np.diag(H)), 1e-300))
        improved = False
        rel = moved = 0.0
        while lam < 1e8:
            M = Hf + lam * np.diag(diag)
            if abs(np.linalg.det(M)) == 0.0:  # singular: more damping
                lam *= 10.0
                continue
            step_f = np.linalg.solve(M, -gf)
            trial = s.copy()
            trial[idx] += step_f
            if bounded:
                trial = np.maximum(trial, 0.0)
            r_t, d_t = _crf_residuals(A, y, table, slopes, trial)
            cost_t = r_t @ r_t
            if cost_t < cost:
                moved = np.sqrt(np.sum((trial - s) ** 2))
                # cost is r @ r of 1-D arrays: a scalar (typed as an array; numba-compiled, so no cast)
                rel = (cost - cost_t) / max(cost, 1e-300)  # type: ignore[operator]
                s, r, J, cost = trial, r_t, d_t[:, None] * A, cost_t
                lam = max(lam / 10.0, 1e-12)
                improved = True
                break
            lam *= 10.0
        if not improved or rel < tolerance or moved <= 1e-5 * (1.0 + np.sqrt(np.sum(s ** 2))):
            break
    return np.maximum(s, 0.0)


def warm_up(crf: CameraResponse) -> None:
    """Compile (or load from numba's cache) the jitted E_crf fit now: on a fresh checkout compiling it took ~30 s
    of the first live frame."""
    table, slopes = crf.channel_table(0)
    _fit_channel_crf(np.ones((3, 3)), np.full(3, 100.0), table, slopes, np.ones(3), True, 2, 1e-7)
    _crf_residuals(np.ones((3, 3)), np.full(3, 100.0), table, slopes, np.ones(3))


def fit_scales(
    I_C: ArrayLike,
    images: Mapping[str, ArrayLike] | RadiosityImages,
    crf: CameraResponse,
    *,
    valid: ArrayLike | None = None,
    method: Literal["crf", "lin"] = "crf",
    initial: ArrayLike | Mapping[str, ArrayLike] | ScaleFit | None = None,
    solver: Literal["bounded-lm", "lm"] = "bounded-lm",
) -> ScaleFit:
    """Estimate the brightness scales ``s_x`` per colour channel from the live image (§III-C).

    Args:
        I_C: (N, 3) live pixel values at Ω (float or uint8, 0..255); with ``images`` a :class:`RadiosityImages`
            also the full live image (H, W, 3), sampled at Ω.
        images: component name → (N, 3) ``I_B̂x``, or :class:`RadiosityImages` (its ``valid`` is the default mask).
        crf: the camera response ``f`` with the frame's exposure (Δt = ``crf.exposure_factor``).
        valid: (N,) bool mask of pixels to use (default: all, or ``images.valid``).
        method: ``"crf"`` minimizes E_crf (Eq. 4), ``"lin"`` E_lin (Eq. 6) by non-negative least squares.
        initial: (K, 3) / (K,) / mapping / :class:`ScaleFit` starting scales (e.g. the previous average); used for
            E_crf and kept for unobserved components.
        solver: ``"bounded-lm"`` (s ≥ 0) or ``"lm"`` (unbounded, clipped at 0); see the module docs.
    """
    if method not in ("crf", "lin"):
        raise BrightnessError(f"unknown method {method!r} (use 'crf' or 'lin')")
    if solver not in ("bounded-lm", "lm"):
        raise BrightnessError(f"unknown solver {solver!r} (use 'bounded-lm' or 'lm')")
    if isinstance(images, RadiosityImages):
        if valid is None:
            valid = images.valid
        if np.ndim(I_C) == 3:
            I_C = images.sample(I_C)
        images = images.images
    y_all = np.asarray(I_C, dtype=np.float64)
    if y_all.ndim != 2 or y_all.shape[1] != 3:
        raise BrightnessError(f"I_C must have shape (N, 3), got {y_all.shape}")
    n = len(y_all)
    names, B = _component_stack(images, n, what="image", like=" like I_C", dtype=np.float64)  # (N, K, 3)
    mask = np.ones(n, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    if mask.shape != (n,):
        raise BrightnessError(f"valid must have shape ({n},), got {mask.shape}")
    mask = mask & np.all(np.isfinite(y_all), axis=1) & np.all(np.isfinite(B), axis=(1, 2))
    y_all, B = y_all[mask], B[mask]
    k = len(names)
    s0 = np.zeros((k, 3)) if initial is None else _as_scales(initial, names)
    dt = crf.exposure_factor
    scales = s0.copy()
    observed = np.zeros((k, 3), dtype=bool)
    rms = np.full(3, np.nan)
    for c in range(3):
        A = B[:, :, c]
        y = np.ascontiguousarray(y_all[:, c])
        table, slopes = crf.channel_table(c)
        norms = np.linalg.norm(A, axis=0)
        obs = norms > 1e-9 * max(float(norms.max(initial=0.0)), 1e-30)
        if not obs.any():
            continue
        observed[:, c] = obs
        Ao = A[:, obs]
        if method == "lin":
            b = crf.linearize(np.repeat(y[:, None], 3, axis=1))[:, c] / dt
            scales[obs, c] = nnls(Ao, b)[0]
        else:
            unsat = (y > _INIT_LOW) & (y < _INIT_HIGH)
            rows = unsat if np.count_nonzero(unsat) >= Ao.shape[1] else np.ones(len(y), dtype=bool)
            b = crf.linearize(np.repeat(y[rows, None], 3, axis=1))[:, c] / dt
            candidates = [nnls(Ao[rows], b)[0]]
            if initial is not None:
                candidates.append(np.maximum(s0[obs, c], 0.0) if solver == "bounded-lm" else s0[obs, c])
            costs = [float(np.sum(_crf_residuals(Ao * dt, y, table, slopes, s)[0] ** 2)) for s in candidates]
            x0 = candidates[int(np.argmin(costs))]
            if solver == "lm" and len(y) < len(x0):
                raise BrightnessError(f"Levenberg-Marquardt needs at least {len(x0)} pixels, got {len(y)}")
            scales[obs, c] = _fit_channel_crf(np.ascontiguousarray(Ao * dt), y, table, slopes, x0,
                                              solver == "bounded-lm", 30, 1e-7)
        r = _crf_residuals(np.ascontiguousarray(A * dt), y, table, slopes, np.ascontiguousarray(scales[:, c]))[0]
        rms[c] = float(np.sqrt(np.mean(r**2))) if len(r) else np.nan
    return ScaleFit(names, scales, observed, rms, len(y_all), method)


# ----------------------------------------------------------------------------------------------------------------
# per-frame estimation with a moving average


class BrightnessEstimator:
    """Per-frame brightness scales averaged over the last ``window`` frames (§III-C, 30 frames in the paper).

    Each entry (component, channel) is averaged over the frames in the window in which it was observed; an entry
    not observed in the whole window keeps its last average (0 before the first observation).
    """

    def __init__(
        self,
        crf: CameraResponse,
        *,
        names: Sequence[str] = COMPONENTS,
        window: int = 30,
        method: Literal["crf", "lin"] = "crf",
        solver: Literal["bounded-lm", "lm"] = "bounded-lm",
        min_pixels: int = 10,
    ) -> None:
        if int(window) < 1:
            raise BrightnessError(f"window must be >= 1 frame, got {window}")
        if method not in ("crf", "lin"):
            raise BrightnessError(f"unknown method {method!r} (use 'crf' or 'lin')")
        self.crf = crf
        self.names = tuple(names)
        self.window = int(window)
        self.method: Literal["crf", "lin"] = method
        self.solver: Literal["bounded-lm", "lm"] = solver
        self.min_pixels = int(min_pixels)
        self._history: deque[F64] = deque(maxlen=self.window)
        self._scales = np.zeros((len(self.names), 3))
        self._seen = np.zeros((len(self.names), 3), dtype=bool)
        self.last_fit: ScaleFit | None = None

    @property
    def scales(self) -> F64:
        """(K, 3) the current averaged scales."""
        return self._scales.copy()

    def as_dict(self) -> dict[str, F64]:
        return {n: self._scales[i].copy() for i, n in enumerate(self.names)}

    def __len__(self) -> int:
        """Frames currently in the window."""
        return len(self._history)

    def reset(self) -> None:
        self._history.clear()
        self._scales[:] = 0.0
        self._seen[:] = False
        self.last_fit = None

    def push(self, fit: ScaleFit) -> F64:
        """Add a per-frame estimate to the window; returns the new average (K, 3)."""
        if fit.names != self.names:
            raise BrightnessError(f"fit has components {fit.names}, the estimator {self.names}")
        self.last_fit = fit
        frame = np.where(fit.observed, fit.scales, np.nan)
        if fit.num_pixels < self.min_pixels:
            frame[:] = np.nan
        self._history.append(frame)
        stack = np.stack(self._history)
        count = np.sum(np.isfinite(stack), axis=0)
        total = np.nansum(stack, axis=0)
        have = count > 0
        self._scales[have] = total[have] / count[have]
        self._seen |= have
        return self.scales

    def update(self, I_C: ArrayLike, images: Mapping[str, ArrayLike] | RadiosityImages, *,
               valid: ArrayLike | None = None) -> F64:
        """Fit the scales of one frame (warm-started from the current average) and add them; returns the average."""
        if isinstance(images, RadiosityImages):
            missing = set(self.names) ^ set(images.names)
        else:
            missing = set(self.names) ^ set(images)
        if missing:
            raise BrightnessError(f"radiosity images must have exactly the components {self.names}")
        if isinstance(images, Mapping):
            images = {n: images[n] for n in self.names}
        else:
            images = RadiosityImages(images.uv_px, {n: images.images[n] for n in self.names}, images.reflectance,
                                     images.valid, images.depth_m)
        initial = self._scales if self._seen.any() else None
        fit = fit_scales(I_C, images, self.crf, valid=valid, method=self.method, initial=initial, solver=self.solver)
        return self.push(fit)


# ----------------------------------------------------------------------------------------------------------------
# the reference image of the adapted map


@dataclass(frozen=True, eq=False)
class RelitImage:
    """The adapted map seen from a pose: ``color`` (H, W, 3) float32 pixel values ``f(Δt · I_B)`` in [0, 255]
    (0 where nothing was hit), ``depth_m`` (H, W) float32 z-depth (0 = no geometry), ``radiosity`` (H, W, 3)
    float32 ``I_B`` (Eq. 3) and ``valid`` (H, W) bool (the ray hit the mesh)."""

    color: F32
    depth_m: F32
    radiosity: F32
    valid: NDArray[np.bool_]

    def rgb8(self) -> NDArray[np.uint8]:
        """The colour rounded to uint8."""
        return np.clip(np.rint(self.color), 0, 255).astype(np.uint8)


def relit_image(
    lmap: LightingMap,
    components: Mapping[str, ArrayLike],
    scales: ArrayLike | Mapping[str, ArrayLike] | ScaleFit,
    T_map_cam: ArrayLike,
    camera: PinholeCamera,
    crf: CameraResponse,
) -> RelitImage:
    """Render the colour ``f(Δt · Σ_x s_x I_B̂x)`` and depth of every pixel of ``camera`` at ``T_map_cam``.

    ``scales`` are (K, 3) rows in the order of ``components``, a name → (3,) mapping, or a :class:`ScaleFit`.
    The scaled radiosity B = Σ s_x B̂_x is summed per vertex first, then interpolated once per pixel.
    """
    names, stack = _component_stack(components, lmap.mesh.num_vertices)
    s = _as_scales(scales, names).astype(np.float32)
    radiosity_v = np.einsum("vkc,kc->vc", stack, s)  # (V, 3)
    _uv, hit, corners, w, depth = _cast(lmap, camera, T_map_cam, 1)
    h, wd = camera.height, camera.width
    rad = _interpolate(radiosity_v, corners, w)  # misses have zero weights → 0
    color = crf.apply_radiosity(rad).astype(np.float32)
    color[~hit] = 0.0
    return RelitImage(color.reshape(h, wd, 3), depth.reshape(h, wd), rad.reshape(h, wd, 3), hit.reshape(h, wd))

