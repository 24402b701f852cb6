"""The current keyframes of rACR's fine alignment (paper §3.4.1) and the self-occlusion rule (§3.4.3).

* :class:`Keyframe`: an image ``D^u`` ``(H, W)`` (float, any fixed units, e.g. [0, 1]), its camera pose
  ``T_cur_cam`` = ``T_K^u`` (camera-to-current-cloud, rigid 4×4, metres with the real scale s applied, §3.3) and
  its :class:`~lightfast.camera.PinholeCamera` (optical frame, pixels).
* ``_Views``: the keyframes stacked for vectorised bilinear sampling of the (blurred) intensity and its gradient
  (intensity per px); the projection ``π`` of camera points ``(K, M, 3)`` (metres) to pixels ``(K, M)``; the
  visibility mask with the self-occlusion rule applied.
* :func:`nearest_per_pixel`: the self-occlusion rule as a vectorised z-buffer — among the points that fall into
  the same keyframe pixel (cell of ``occlusion_cell_px``), only the one nearest to the camera keeps its
  photometric terms (``np.minimum.at`` over pixel ids, no pixel loop).
* ``_pairs`` / ``_select_by_gradient``: the keyframe pairs ``u < v`` that both see a point, and the
  strongest-gradient points seen by at least two keyframes (DSO-like: flat texture carries no photometric
  information).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.camera import PinholeCamera
from lightfast.geometry import is_rotation, project_to_so3
from lightfast.racr.errors import AlignmentError

__all__ = ["Keyframe", "nearest_per_pixel"]

Array = NDArray[np.float64]

_MIN_KEYFRAMES = 2


@dataclass(frozen=True)
class Keyframe:
    """A current keyframe (§3.4.1): image ``D^u`` ``(H, W)`` (float, any fixed units), its camera pose
    ``T_cur_cam`` = T_K^u in the current-cloud frame (camera-to-cloud, real scale s applied, §3.3) and its
    pinhole camera."""

    image: Array
    T_cur_cam: Array
    camera: PinholeCamera

    def __post_init__(self) -> None:
        if not isinstance(self.camera, PinholeCamera):
            raise AlignmentError(f"keyframe camera must be a PinholeCamera, got {type(self.camera).__name__}")
        try:
            img = np.array(self.image, dtype=np.float64)
            T = np.array(self.T_cur_cam, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise AlignmentError(f"keyframe image and pose must be numeric arrays: {exc}") from None
        if img.shape != self.camera.shape:
            raise AlignmentError(f"keyframe image shape {img.shape} does not match its camera {self.camera.shape}")
        if not np.all(np.isfinite(img)):
            raise AlignmentError("keyframe image has non-finite pixels")
        if T.shape != (4, 4) or not np.all(np.isfinite(T)) or not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]):
            raise AlignmentError(f"keyframe T_cur_cam must be a finite 4x4 rigid transform, got shape {T.shape}")
        if not is_rotation(T[:3, :3], atol=1e-4):
            raise AlignmentError("keyframe T_cur_cam must be rigid ([R t; 0 0 0 1] with R a rotation)")
        T[:3, :3] = project_to_so3(T[:3, :3])
        img.flags.writeable = False
        T.flags.writeable = False
        object.__setattr__(self, "image", img)
        object.__setattr__(self, "T_cur_cam", T)

    @classmethod
    def coerce(cls, value: Keyframe | Sequence[object]) -> Keyframe:
        """A :class:`Keyframe` from itself or an ``(image, T_cur_cam, camera)`` tuple."""
        if isinstance(value, Keyframe):
            return value
        try:
            image, T, camera = value
        except (TypeError, ValueError):
            raise AlignmentError("a keyframe must be a Keyframe or an (image, T_cur_cam, camera) tuple") from None
        return cls(image, T, camera)  # type: ignore[arg-type]


def nearest_per_pixel(pixel: ArrayLike, depth: ArrayLike) -> NDArray[np.bool_]:
    """The self-occlusion rule of §3.4.3: among points that fall into the same pixel (any integer id, e.g.
    ``v * width + u``), keep only the one with the smallest ``depth`` (ties: the lowest index).

    A vectorised z-buffer: ``np.minimum.at`` of the depths into a buffer over the (compacted) pixel ids, then the
    same for the indices of the points that reach the minimum."""
    pix = np.asarray(pixel)
    z = np.asarray(depth, dtype=np.float64)
    if pix.shape != z.shape or pix.ndim != 1:
        raise AlignmentError(f"pixel and depth must be 1-d arrays of one length, got {pix.shape} and {z.shape}")
    if len(pix) == 0:
        return np.zeros(0, dtype=bool)
    if not np.issubdtype(pix.dtype, np.integer):
        raise AlignmentError(f"pixel ids must be integers, got {pix.dtype}")
    lo, hi = int(pix.min()), int(pix.max())
    if hi - lo < 8 * len(pix) + (1 << 20):
        ids, size = pix - lo, hi - lo + 1
    else:
        uniq, ids = np.unique(pix, return_inverse=True)
        size = len(uniq)
    zbuf = np.full(size, np.inf)
    np.minimum.at(zbuf, ids, z)
    nearest = np.flatnonzero(z <= zbuf[ids])
    first = np.full(size, len(pix), dtype=np.intp)
    np.minimum.at(first, ids[nearest], nearest)
    keep = np.zeros(len(pix), dtype=bool)
    keep[nearest[first[ids[nearest]] == nearest]] = True
    return keep


class _Views:
    """The keyframes prepared for vectorised sampling: for each, the (blurred) intensity and its central-difference
    gradient — with ``squared_gradient`` also the gradient of ``‖∇I‖²`` (for the Jacobian of the gradient-dependent
    weight, :func:`~lightfast.racr.fine.objective._gradient_weight`) — all keyframes stacked into one
    ``(Σ H·W, 3 or 5)`` table, plus per-keyframe intrinsics shaped ``(K, 1)``. Points are handled as ``(K, M, …)``
    arrays: point ``m`` seen by keyframe ``k``."""

    def __init__(self, keyframes: Sequence[Keyframe], blur_px: float, border_px: float, *,
                 squared_gradient: bool = False) -> None:
        tables, offsets = [], [0]
        for kf in keyframes:
            img = kf.image
            if blur_px > 0.0:
                img = cast(Array, cv2.GaussianBlur(img, (0, 0), blur_px, borderType=cv2.BORDER_REFLECT))
            gy, gx = np.gradient(img)
            cols = [img, gx, gy]
            if squared_gradient:
                qy, qx = np.gradient(gx * gx + gy * gy)
                cols += [qx, qy]
            tables.append(np.stack(cols, axis=-1).reshape(-1, len(cols)))
            offsets.append(offsets[-1] + img.size)
        self.table = np.ascontiguousarray(np.concatenate(tables), dtype=np.float64)
        cams = [kf.camera for kf in keyframes]
        col = np.array

        self.offset = col(offsets[:-1], dtype=np.intp)[:, None]
        self.width = col([c.width for c in cams], dtype=np.intp)[:, None]
        self.height = col([c.height for c in cams], dtype=np.intp)[:, None]
        self.fx = col([c.fx for c in cams])[:, None]
        self.fy = col([c.fy for c in cams])[:, None]
        self.cx = col([c.cx for c in cams])[:, None]
        self.cy = col([c.cy for c in cams])[:, None]
        self.border = border_px
        #: median gradient magnitude (intensity per px) over every pixel of the (blurred) keyframes: the image's own
        #: contrast scale, to which the gradient-dependent weight's ``c`` is relative
        self.median_gradient = float(np.median(np.hypot(self.table[:, 1], self.table[:, 2])))

    def __len__(self) -> int:
        return len(self.offset)

    def project(self, c: Array) -> tuple[Array, Array, NDArray[np.bool_]]:
        """Pixel coordinates ``u, v`` ``(K, M)`` of camera points ``c`` ``(K, M, 3)`` and whether they are usable:
        in front of the camera and at least ``border_px`` inside the image."""
        z = c[..., 2]
        front = z > 1e-9
        zi = np.where(front, 1.0 / np.where(front, z, 1.0), 0.0)
        u = self.fx * c[..., 0] * zi + self.cx
        v = self.fy * c[..., 1] * zi + self.cy
        b = self.border
        ok = front & (u >= b) & (u <= self.width - 1.0 - b) & (v >= b) & (v <= self.height - 1.0 - b)
        return u, v, ok

    def sample(self, u: Array, v: Array) -> Array:
        """Bilinear (I, ∂I/∂u, ∂I/∂v[, ∂‖∇I‖²/∂u, ∂‖∇I‖²/∂v]) ``(K, M, 3 or 5)`` at ``u, v`` ``(K, M)`` (clamped to
        the image). In float64 on purpose: ``cv2.remap`` quantises sub-pixel positions to 1/32 px, making the
        residuals piecewise constant."""
        u = np.clip(u, 0.0, self.width - 1.000001)
        v = np.clip(v, 0.0, self.height - 1.000001)
        u0 = u.astype(np.intp)
        v0 = v.astype(np.intp)
        a = (u - u0)[..., None]
        b = (v - v0)[..., None]
        i = (self.offset + v0 * self.width + u0).ravel()
        t = self.table
        shape = u.shape + (t.shape[1],)
        t00, t01 = np.take(t, i, axis=0).reshape(shape), np.take(t, i + 1, axis=0).reshape(shape)
        i += np.repeat(self.width[:, 0], u.shape[1]) if u.ndim == 2 else self.width[:, 0]
        t10, t11 = np.take(t, i, axis=0).reshape(shape), np.take(t, i + 1, axis=0).reshape(shape)
        top = t00 + a * (t01 - t00)
        return top + b * (t10 + a * (t11 - t10) - top)

    def chain(self, c: Array, grad: Array) -> Array:
        """``∂I/∂c`` ``(K, M, 3)``: the image gradient ``grad`` ``(K, M, 2)`` through the projection at ``c``."""
        zi = 1.0 / np.maximum(c[..., 2], 1e-9)
        gu = grad[..., 0] * self.fx * zi
        gv = grad[..., 1] * self.fy * zi
        return np.stack([gu, gv, -(gu * c[..., 0] + gv * c[..., 1]) * zi], axis=-1)

    def visible(self, c: Array, cell_px: int) -> tuple[NDArray[np.bool_], int]:
        """The usable projections of camera points ``c`` ``(K, M, 3)`` that survive the self-occlusion rule
        (nearest point per ``cell_px`` cell of each keyframe). Returns the ``(K, M)`` mask and how many usable
        projections the z-buffer removed."""
        u, v, ok = self.project(c)
        k_idx, m_idx = np.nonzero(ok)
        cells_u = (self.width[:, 0] // cell_px + 2)[k_idx]
        cu = np.floor((u[k_idx, m_idx] + 0.5) / cell_px).astype(np.int64)
        cv = np.floor((v[k_idx, m_idx] + 0.5) / cell_px).astype(np.int64)
        cell = (cv * cells_u + cu) * len(self) + k_idx  # unique across keyframes
        keep = nearest_per_pixel(cell, c[k_idx, m_idx, 2])
        mask = np.zeros(ok.shape, dtype=bool)
        mask[k_idx[keep], m_idx[keep]] = True
        return mask, int(len(k_idx) - np.count_nonzero(keep))


def _camera_points(P: Array, R_world_cam: Array, t_world_cam: Array) -> Array:
    """``(K, M, 3)``: points ``P`` ``(M, 3)`` in each camera ``⟨R, t⟩`` ``(K, 3, 3)``, ``(K, 3)`` (camera-to-world)."""
    return np.matmul(P[None, :, :] - t_world_cam[:, None, :], R_world_cam)


def _pairs(visible: NDArray[np.bool_]) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """``(u, v, m)`` for every point ``m`` visible in both keyframes ``u < v`` (``visible`` is ``(K, M)``)."""
    us, vs, ms = [], [], []
    K = visible.shape[0]
    for u in range(K):
        for v in range(u + 1, K):
            m = np.flatnonzero(visible[u] & visible[v])
            us.append(np.full(len(m), u, dtype=np.intp))
            vs.append(np.full(len(m), v, dtype=np.intp))
            ms.append(m)
    return np.concatenate(us), np.concatenate(vs), np.concatenate(ms)


def _select_by_gradient(c: Array, views: _Views, visible: NDArray[np.bool_], count: int) -> NDArray[np.intp]:
    """Indices of up to ``count`` points seen by ≥ 2 keyframes, strongest summed gradient magnitude first."""
    u, v, _ = views.project(c)
    g = views.sample(u, v)
    score = np.where(visible, np.hypot(g[..., 1], g[..., 2]), 0.0).sum(axis=0)
    candidates = np.flatnonzero(visible.sum(axis=0) >= _MIN_KEYFRAMES)
    if 0 < count < len(candidates):
        candidates = candidates[np.argsort(-score[candidates], kind="stable")[:count]]
    return np.sort(candidates)
