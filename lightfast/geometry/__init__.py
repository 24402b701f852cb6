"""Rigid (SE(3)) and similarity (Sim(3)) transforms on NumPy arrays.

Conventions
-----------
* **Transforms.** ``T_a_b`` is a 4×4 ``float64`` matrix that maps points expressed in frame ``b`` to frame ``a``:
  ``p_a = T_a_b @ p_b`` (homogeneous), i.e. ``p_a = R_a_b p_b + t_a_b``. ``t_a_b`` is the origin of frame ``b``
  expressed in frame ``a``, in metres. Transforms chain like their names: ``T_a_c = compose(T_a_b, T_b_c)``.
* **Rotations** are 3×3 ``float64`` matrices with ``R^T R = I`` and ``det R = +1``.
* **Quaternions** are ``(x, y, z, w)`` like ROS ``geometry_msgs/Quaternion``, unit norm. :func:`matrix_to_quat`
  returns the canonical sign ``w >= 0`` (for ``w == 0`` the first non-zero of ``x, y, z`` is positive).
* **Tangent vectors.** A rotation vector ``phi`` (3,) is axis × angle in radians. A twist ``xi = (rho, phi)`` (6,)
  puts the translation part first and the rotation part second; ``se3_exp(xi) = expm([[hat(phi), rho], [0, 0]])``
  so ``rho`` is in metres but is *not* the translation of the result unless ``phi = 0``. A Sim(3) vector
  ``v = (rho, phi, lambda)`` (7,) has log-scale ``lambda`` (scale ``s = exp(lambda)``, dimensionless) and
  ``sim3_exp(v) = expm([[hat(phi) + lambda I, rho], [0, 0]])``.
* **Sim(3) matrices** are ``[[s R, t], [0, 1]]`` with ``s > 0``; they map ``p_a = s R p_b + t``.
* **Batches.** Every function accepts leading batch dimensions (``(..., 3, 3)``, ``(..., 4, 4)``, ``(..., 6)``...)
  and returns arrays with the same leading shape.

The exponential and logarithm maps use closed forms that stay accurate for small angles (Taylor expansions below
a threshold) and near ``pi`` (the rotation logarithm goes through a Shepperd quaternion and ``atan2``).

Modules: :mod:`.so3` (rotations, quaternions), :mod:`.se3` (rigid transforms), :mod:`.sim3` (similarity
transforms), :mod:`.metrics` (rotation angle and translation distance errors), :mod:`.checks` (input validation,
tolerances). Invalid input (wrong shape, non-finite values, a matrix that is not a rotation, a quaternion far from
unit norm) raises :class:`GeometryError`, whose message names the offending argument.
"""
from __future__ import annotations

from lightfast.errors import GeometryError as GeometryError
from lightfast.geometry.checks import QUAT_NORM_TOL as QUAT_NORM_TOL
from lightfast.geometry.checks import ROTATION_ATOL as ROTATION_ATOL
from lightfast.geometry.checks import Array as Array
from lightfast.geometry.metrics import rotation_angle_deg, translation_distance
from lightfast.geometry.se3 import _se3_inv_coeff as _se3_inv_coeff  # the series tests of test_geometry.py
from lightfast.geometry.se3 import compose, inverse, look_at, make_transform, se3_exp, se3_log, transform_points
from lightfast.geometry.sim3 import _sim3_coeffs as _sim3_coeffs  # the series tests of test_geometry.py
from lightfast.geometry.sim3 import sim3_exp, sim3_inverse, sim3_log
from lightfast.geometry.so3 import _so3_coeffs as _so3_coeffs  # the series tests of test_geometry.py
from lightfast.geometry.so3 import (
    hat,
    is_rotation,
    matrix_to_quat,
    project_to_so3,
    quat_to_matrix,
    so3_exp,
    so3_log,
    vee,
)
from lightfast.geometry.so3 import unit_vector as unit_vector

__all__ = [
    "compose",
    "hat",
    "inverse",
    "is_rotation",
    "look_at",
    "make_transform",
    "matrix_to_quat",
    "project_to_so3",
    "quat_to_matrix",
    "rotation_angle_deg",
    "se3_exp",
    "se3_log",
    "sim3_exp",
    "sim3_inverse",
    "sim3_log",
    "so3_exp",
    "so3_log",
    "transform_points",
    "translation_distance",
    "vee",
]
