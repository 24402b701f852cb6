"""Pose error metrics: rotation angle (degrees) and translation distance (metres) between poses.

Inputs are rotations ``(..., 3, 3)`` or rigid transforms ``(..., 4, 4)`` (their rotation blocks / translations), or
translations ``(..., 3)`` in metres; batches broadcast and the result has the leading shape. Conventions in
:mod:`lightfast.geometry`.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from lightfast.geometry.checks import ROTATION_ATOL, Array, _as_float, _check_rotation, _transform
from lightfast.geometry.so3 import _quat_from_matrix

__all__ = ["rotation_angle_deg", "translation_distance"]


def _rotation_block(R: ArrayLike, name: str) -> Array:
    a = np.asarray(R, dtype=np.float64)
    if a.ndim >= 2 and a.shape[-2:] == (4, 4):
        a = _transform(a, name)[..., :3, :3]
    a = _as_float(a, name, (3, 3))
    _check_rotation(a, name, ROTATION_ATOL)
    return a


def rotation_angle_deg(R: ArrayLike, R_ref: ArrayLike | None = None) -> Array:
    """Rotation angle in degrees ``[0, 180]`` of ``R``, or of ``R_ref^T R`` (the error of ``R`` w.r.t. ``R_ref``).

    Accepts rotations ``(..., 3, 3)`` or rigid transforms ``(..., 4, 4)`` (their rotation blocks); batches
    broadcast. Returns a float array of the leading shape (a NumPy float for single inputs).
    """
    Ra = _rotation_block(R, "R")
    if R_ref is not None:
        Rb = _rotation_block(R_ref, "R_ref")
        Ra = np.swapaxes(Rb, -1, -2) @ Ra
    q = _quat_from_matrix(Ra)
    return np.degrees(2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3])))


def _translation_part(x: ArrayLike, name: str) -> Array:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim >= 2 and a.shape[-2:] == (4, 4):
        return _transform(a, name)[..., :3, 3]
    return _as_float(a, name, (3,))


def translation_distance(a: ArrayLike, b: ArrayLike) -> Array:
    """Euclidean distance (m) between two translations ``(..., 3)`` or the translations of transforms ``(..., 4, 4)``.

    Inputs may mix both forms; batches broadcast. Returns a float array of the leading shape (a NumPy float for
    single inputs).
    """
    return np.linalg.norm(_translation_part(a, "a") - _translation_part(b, "b"), axis=-1)
