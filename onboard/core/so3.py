"""Rotations: the rotation group for the error-state filters (Sola, "Quaternion kinematics
for the error-state Kalman filter", 2017; the ESESO paper eqs. (6)-(8)) and the ZYX Euler
angles of every vehicle (Fossen, *Handbook of Marine Craft Hydrodynamics and Motion
Control*, 2nd ed., 2021, eqs. 2.18, 2.40, 2.41).

Conventions: a rotation matrix ``R`` maps body (FRD) vectors into the earth (NED) frame,
``x_ned = R @ x_frd``. Perturbations are *right* (local, body-frame) ones,
``R_true = R @ Exp(dtheta)``, as in the ESESO paper eq. (6). Angles in radians.

The ZYX rotation lives here, beside its inverse :func:`matrix_to_euler` and the other
maps between rotation representations, and not in :mod:`onboard.core.geo`, which is about
positions on the earth. Its formula is written once (:func:`_zyx_entries`); the reference
:func:`euler_to_matrix` returns a numpy matrix, and the plain-float fast paths for the
simulator's integrator (:func:`body_to_ned`, :func:`ned_to_body`,
:func:`euler_kinematics`) use the same entries, computed in the same order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

_EPS = 1e-9


def frozen_eye(n: int) -> Array:
    """The ``n`` x ``n`` identity, read-only: made once and shared by the hot paths that add
    to it (a matrix filled in place from it starts as a ``copy()``)."""
    eye = np.eye(n)
    eye.setflags(write=False)
    return eye


_I3 = frozen_eye(3)
"""The identity the functions below add to."""


def cross(a: Array, b: Array) -> Array:
    """``a x b`` of two 3-vectors (numpy's ``cross`` costs ~10x more on tiny arrays)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def skew(w: Array) -> Array:
    """The 3x3 skew-symmetric matrix ``[w]x`` with ``[w]x @ a == cross(w, a)``."""
    return np.array(
        [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]], dtype=float
    )


def exp_so3(theta: Array) -> Array:
    """``Exp(theta)``: rotation vector (rad) to rotation matrix, Rodrigues' formula (paper
    eq. 7): ``cos|t| I + (1 - cos|t|) a a^T + sin|t| [a]x``, ``a = t/|t|``."""
    angle = math.sqrt(float(theta[0] ** 2 + theta[1] ** 2 + theta[2] ** 2))
    K = skew(theta)
    if angle < 1e-6:
        # second-order series, exact to O(angle^3)
        return _I3 + K + 0.5 * (K @ K)
    s = math.sin(angle) / angle
    c = (1.0 - math.cos(angle)) / (angle * angle)
    return _I3 + s * K + c * (K @ K)


def log_so3(R: Array) -> Array:
    """``Log(R)``: rotation matrix to rotation vector (rad), the inverse of :func:`exp_so3`
    for angles in [0, pi]."""
    cos_a = max(-1.0, min(1.0, 0.5 * (float(np.trace(R)) - 1.0)))
    angle = math.acos(cos_a)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-6:
        return 0.5 * v
    if math.pi - angle < 1e-4:
        # near pi: axis from the symmetric part, R = 2 a a^T - I
        B = 0.5 * (R + _I3)
        i = int(np.argmax(np.diag(B)))
        a = B[:, i] / math.sqrt(max(B[i, i], _EPS))
        if float(a @ v) < 0.0:
            a = -a
        return angle * a / np.linalg.norm(a)
    return angle / (2.0 * math.sin(angle)) * v


def right_jacobian(theta: Array) -> Array:
    """Right Jacobian of SO(3), ``Exp(t + d) ~= Exp(t) Exp(Jr(t) d)`` (Sola, Deray and
    Atchuthan, "A micro Lie theory for state estimation in robotics", 2018)."""
    angle = float(np.linalg.norm(theta))
    K = skew(theta)
    if angle < 1e-6:
        return _I3 - 0.5 * K + (K @ K) / 6.0
    a2 = angle * angle
    return (
        _I3
        - (1.0 - math.cos(angle)) / a2 * K
        + (angle - math.sin(angle)) / (a2 * angle) * (K @ K)
    )


def _zyx_entries(cr: float, sr: float, cp: float, sp: float, cy: float,
                 sy: float) -> tuple[float, float, float, float, float, float, float, float,
                                     float]:
    """The nine entries, row by row, of the body-to-earth rotation ``R(Theta)`` from the
    cosines and sines of roll, pitch and yaw (Fossen eq. 2.18)."""
    return (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
            sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
            -sp, cp * sr, cp * cr)


def _zyx(roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    """:func:`_zyx_entries` of the angles (rad)."""
    return _zyx_entries(math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                        math.cos(yaw), math.sin(yaw))


def euler_to_matrix(roll: float, pitch: float, yaw: float) -> Array:
    """Body-to-earth rotation from ZYX Euler angles (rad), Fossen eq. 2.18 (the ESESO
    paper's ``R_Theta``): the reference the plain-float functions below are tested
    against."""
    e = _zyx(roll, pitch, yaw)
    return np.array((e[0:3], e[3:6], e[6:9]))


def body_to_ned(roll: float, pitch: float, yaw: float,
                v: Sequence[float]) -> tuple[float, float, float]:
    """``R(Theta) v``: a body (FRD) vector in the earth (NED) frame, on plain floats
    (several times faster than a numpy product for one vector)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _zyx(roll, pitch, yaw)
    x, y, z = v
    return (r00 * x + r01 * y + r02 * z, r10 * x + r11 * y + r12 * z,
            r20 * x + r21 * y + r22 * z)


def ned_to_body(roll: float, pitch: float, yaw: float,
                v: Sequence[float]) -> tuple[float, float, float]:
    """``R(Theta)^T v``: an earth (NED) vector in the body (FRD) frame, on plain floats."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _zyx(roll, pitch, yaw)
    n, e, d = v
    return (r00 * n + r10 * e + r20 * d, r01 * n + r11 * e + r21 * d,
            r02 * n + r12 * e + r22 * d)


def euler_rate_matrix(roll: float, pitch: float) -> Array:
    """``T(Theta)`` with ``[roll', pitch', yaw'] = T @ [p, q, r]`` (Fossen eq. 2.41); the
    reference for :func:`euler_kinematics`. Singular at pitch = +-pi/2, which none of our
    vehicles reaches."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, tp = math.cos(pitch), math.tan(pitch)
    return np.array(
        [
            [1.0, sr * tp, cr * tp],
            [0.0, cr, -sr],
            [0.0, sr / cp, cr / cp],
        ]
    )


def euler_kinematics(roll: float, pitch: float, yaw: float,
                     nu: Sequence[float]) -> tuple[float, float, float, float, float, float]:
    """``J(Theta) nu`` (Fossen eq. 2.40) on plain floats: ``(N', E', D', roll', pitch',
    yaw')`` from the body velocity and rates ``nu = [u, v, w, p, q, r]`` (m/s, rad/s),
    i.e. ``R(Theta) [u, v, w]`` and ``T(Theta) [p, q, r]`` with the trigonometric functions
    evaluated once (the simulator's RK4 derivative)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _zyx_entries(
        cr, sr, cp, sp, math.cos(yaw), math.sin(yaw))
    u, v, w, p, q, r = nu
    a = sr * q + cr * r
    return (r00 * u + r01 * v + r02 * w, r10 * u + r11 * v + r12 * w,
            r20 * u + r21 * v + r22 * w, p + a * sp / cp, cr * q - sr * r, a / cp)


def matrix_to_euler(R: Array) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in rad of a body-to-earth rotation (ZYX); yaw in (-pi, pi]."""
    pitch = -math.asin(max(-1.0, min(1.0, float(R[2, 0]))))
    roll = math.atan2(float(R[2, 1]), float(R[2, 2]))
    yaw = math.atan2(float(R[1, 0]), float(R[0, 0]))
    return roll, pitch, yaw


def orthonormalize(R: Array) -> Array:
    """The nearest rotation matrix (SVD projection); removes round-off drift."""
    U, _, Vt = np.linalg.svd(R)
    out = U @ Vt
    if np.linalg.det(out) < 0.0:
        U[:, -1] = -U[:, -1]
        out = U @ Vt
    return out
