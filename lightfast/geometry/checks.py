"""Input validation of :mod:`lightfast.geometry`: float64 arrays of the expected trailing shape, rotations, 4×4
transforms, and the tolerances they are checked with.

A rotation ``R`` (3×3) must satisfy ``|R^T R - I| <= atol`` entrywise and ``det R > 0``; a transform (4×4) must have
the bottom row ``[0, 0, 0, 1]``. Failures raise :class:`~lightfast.errors.GeometryError` naming the argument.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lightfast.errors import GeometryError

__all__ = ["QUAT_NORM_TOL", "ROTATION_ATOL", "Array"]

Array = NDArray[np.float64]

#: Tolerance of the orthonormality check applied to rotation inputs of the log maps and conversions.
ROTATION_ATOL = 1e-6
#: A quaternion whose norm differs from 1 by more than this raises; closer ones are normalized.
QUAT_NORM_TOL = 1e-3


def _as_float(x: ArrayLike, name: str, tail: tuple[int, ...]) -> Array:
    """``x`` as a float64 array whose trailing dimensions are ``tail``; finite values only."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GeometryError(f"{name} must be a numeric array, got {type(x).__name__}: {exc}") from None
    if a.ndim < len(tail) or a.shape[a.ndim - len(tail) :] != tail:
        want = "(..., " + ", ".join(str(n) for n in tail) + ")"
        raise GeometryError(f"{name} must have shape {want}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise GeometryError(f"{name} contains non-finite values (NaN or inf)")
    return a


def _orthonormality_error(R: Array) -> Array:
    """Max-abs deviation of ``R^T R`` from identity, per matrix (shape ``(...)``)."""
    RtR = np.swapaxes(R, -1, -2) @ R
    return np.max(np.abs(RtR - np.eye(3)), axis=(-2, -1))


def _check_rotation(R: Array, name: str, atol: float) -> None:
    err = _orthonormality_error(R)
    det = np.linalg.det(R)
    bad = (err > atol) | (det <= 0.0)
    if np.any(bad):
        worst = float(np.max(err))
        raise GeometryError(
            f"{name} is not a rotation matrix (max |R^T R - I| = {worst:.3g}, min det = {float(np.min(det)):.3g}, "
            f"atol = {atol:g}); use project_to_so3 to repair a drifted rotation"
        )


def _check_bottom_row(T: Array, name: str) -> None:
    bottom = T[..., 3, :].reshape(-1, 4)
    bad = np.any(np.abs(bottom - [0.0, 0.0, 0.0, 1.0]) > 1e-9, axis=-1)
    if np.any(bad):
        raise GeometryError(f"{name} must have bottom row [0, 0, 0, 1], got {bottom[np.argmax(bad)].tolist()}")


def _transform(T: ArrayLike, name: str) -> Array:
    T = _as_float(T, name, (4, 4))
    _check_bottom_row(T, name)
    return T

