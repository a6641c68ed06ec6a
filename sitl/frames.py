"""The simulator's reference frames: its geodesy, rotations and angle wrapping, computed
independently of the estimators' (docs/sitl.md "What the simulator computes
independently").

The estimators project fixes with :mod:`onboard.core.geo` and rotate with
:mod:`onboard.core.so3`; a convention error shared by the simulator and the estimators
would cancel in every comparison with truth. So the simulator takes:

* latitude/longitude from pymap3d (``enu2geodetic``: the simulator's north/east plane is
  the WGS-84 tangent plane at the scenario's origin, a point at zero up);
* rotations (intrinsic ZYX Euler angles: yaw, pitch, roll; body FRD to earth NED) in its
  own plain-float code wherever it runs while simulating (the plants' right-hand side,
  four times a step; their truth and ideal IMU; the magnetometer of every IMU frame; the
  sensors' true velocity): :func:`kinematics`, :func:`euler_to_matrix`,
  :func:`ned_to_body_fast`, :func:`body_to_ned_fast`, ~3 us against ~20-40 us for a
  :class:`scipy.spatial.transform.Rotation`. ``tests/test_sitl_frames.py`` checks them
  against scipy's ``Rotation`` (:func:`rotation`, :func:`body_to_ned`) and against the
  time derivative of scipy's rotation (the Euler rates);
* angles wrapped by :func:`math.remainder` and ``%``, not the estimators' ``fmod`` code.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

try:
    import pymap3d
    from pymap3d.ellipsoid import Ellipsoid
except ImportError as exc:  # pragma: no cover - the extra is in [test] and [all]
    raise ImportError("the simulator needs pymap3d: pip install 'onboard[sim]'") from exc

TWO_PI = 2.0 * math.pi
"""2 pi (rad)."""
EULER_ORDER = "ZYX"
"""scipy's sequence for (yaw, pitch, roll): intrinsic rotations about z, then y, then x."""


# -- geodesy ------------------------------------------------------------------------------

WGS84 = Ellipsoid.from_name("wgs84")
"""pymap3d's WGS-84 ellipsoid, built once (pymap3d builds it on every call otherwise)."""


class GeoOrigin:
    """The simulator's north/east plane about ``(lat0, lon0)`` (deg), mapped to latitude
    and longitude by pymap3d (the WGS-84 tangent plane at the origin, up 0).

    A pymap3d call costs ~110 us whatever its size (its per-call array handling), a
    vectorized one ~1-2 us a point in batches of 100: where the positions can wait
    (the truth records), convert them with :meth:`to_latlon_many`."""

    __slots__ = ("lat0", "lon0")

    def __init__(self, lat0_deg: float, lon0_deg: float) -> None:
        self.lat0 = float(lat0_deg)
        self.lon0 = float(lon0_deg)

    def to_latlon(self, north_m: float, east_m: float) -> tuple[float, float]:
        """(lat, lon) in degrees of the point at ``north_m``, ``east_m`` (m)."""
        lat, lon, _ = pymap3d.enu2geodetic(east_m, north_m, 0.0, self.lat0, self.lon0, 0.0,
                                           ell=WGS84)
        return float(lat), float(lon)

    def to_latlon_many(self, north_m: Sequence[float],
                       east_m: Sequence[float]) -> tuple[list[float], list[float]]:
        """:meth:`to_latlon` of many points (m) in one pymap3d call: (lats, lons) in
        degrees."""
        lat, lon, _ = pymap3d.enu2geodetic(np.asarray(east_m, dtype=float),
                                           np.asarray(north_m, dtype=float), 0.0,
                                           self.lat0, self.lon0, 0.0, ell=WGS84)
        return np.atleast_1d(lat).tolist(), np.atleast_1d(lon).tolist()


# -- rotations ----------------------------------------------------------------------------

def rotation(roll: float, pitch: float, yaw: float) -> Rotation:
    """The body-to-NED rotation of ZYX Euler angles (rad)."""
    return Rotation.from_euler(EULER_ORDER, (yaw, pitch, roll))


def euler_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """The 3x3 body-to-NED rotation matrix (``x_ned = R @ x_frd``) of ZYX Euler angles:
    its columns are the body axes in NED (:func:`_axes`; the plants' truth and ideal IMU
    call it at every step, where scipy would cost ~20 us)."""
    return np.array(_axes(roll, pitch, yaw)).T


def body_to_ned(roll: float, pitch: float, yaw: float,
                v: Sequence[float]) -> tuple[float, float, float]:
    """A body (FRD) vector in NED axes."""
    x, y, z = rotation(roll, pitch, yaw).apply(np.asarray(v, dtype=float)).tolist()
    return x, y, z


def ned_to_body(roll: float, pitch: float, yaw: float,
                v: Sequence[float]) -> tuple[float, float, float]:
    """A NED vector in body (FRD) axes."""
    r = rotation(roll, pitch, yaw)
    x, y, z = r.apply(np.asarray(v, dtype=float), inverse=True).tolist()
    return x, y, z


def _axes(roll: float, pitch: float, yaw: float):
    """The body axes in NED (the columns of the body-to-NED matrix) ``(x_b, y_b, z_b)``,
    each a 3-tuple, from the elementary rotations about z, y, x."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    # x_b = Rz Ry e1; y_b = Rz Ry Rx e2; z_b = Rz Ry Rx e3
    xb = (cy * cp, sy * cp, -sp)
    yb = (-sy * cr + cy * sp * sr, cy * cr + sy * sp * sr, cp * sr)
    zb = (sy * sr + cy * sp * cr, -cy * sr + sy * sp * cr, cp * cr)
    return xb, yb, zb


def ned_to_body_fast(roll: float, pitch: float, yaw: float,
                     v: Sequence[float]) -> tuple[float, float, float]:
    """:func:`ned_to_body` in plain floats, for the plants' right-hand side: the
    components of ``v`` along the body axes."""
    xb, yb, zb = _axes(roll, pitch, yaw)
    return (xb[0] * v[0] + xb[1] * v[1] + xb[2] * v[2],
            yb[0] * v[0] + yb[1] * v[1] + yb[2] * v[2],
            zb[0] * v[0] + zb[1] * v[1] + zb[2] * v[2])


def body_to_ned_fast(roll: float, pitch: float, yaw: float,
                     v: Sequence[float]) -> tuple[float, float, float]:
    """:func:`body_to_ned` in plain floats, for the sensors' samples (the true velocity
    over ground of every GNSS fix, INS and DVL report): ``v`` along the body axes
    (:func:`_axes`), summed in NED."""
    xb, yb, zb = _axes(roll, pitch, yaw)
    return (xb[0] * v[0] + yb[0] * v[1] + zb[0] * v[2],
            xb[1] * v[0] + yb[1] * v[1] + zb[1] * v[2],
            xb[2] * v[0] + yb[2] * v[1] + zb[2] * v[2])


def kinematics(roll: float, pitch: float, yaw: float,
               nu: Sequence[float]) -> tuple[float, float, float, float, float, float]:
    """``(N', E', D', roll', pitch', yaw')`` of a body moving at ``nu = (u, v, w, p, q,
    r)`` (m/s, rad/s, body FRD): the velocity along the body axes in NED, and the Euler
    rates that make the body rate ``omega = roll' e1 + pitch' Rx^T e2 + yaw' (Ry Rx)^T
    e3`` (each rate about its own intermediate axis), solved for the rates."""
    u, v, w, p, q, r = nu[0], nu[1], nu[2], nu[3], nu[4], nu[5]
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    # R (u, v, w) = Rz Ry Rx (u, v, w), one elementary rotation at a time
    vy = v * cr - w * sr                  # Rx (u, v, w) = (u, vy, vz)
    vz = v * sr + w * cr
    hx = u * cp + vz * sp                 # Ry (u, vy, vz) = (hx, vy, hz)
    hz = -u * sp + vz * cp
    # body rates of the pitch and yaw axes: e_pitch = (0, cr, -sr), e_yaw = (-sp, sr cp, cr cp)
    yaw_rate = (sr * q + cr * r) / cp
    return (cy * hx - sy * vy, sy * hx + cy * vy, hz,
            p + sp * yaw_rate, cr * q - sr * r, yaw_rate)


def skew(w: Sequence[float]) -> np.ndarray:
    """The 3x3 matrix ``S(w)`` with ``S(w) a = w x a``, from numpy's cross products: row
    ``i`` is ``e_i x w``."""
    return np.cross(np.eye(3), np.asarray(w, dtype=float))


# -- angles -------------------------------------------------------------------------------

def wrap_pi(angle: float) -> float:
    """``angle`` (rad) to ``[-pi, pi]`` (IEEE remainder by 2 pi)."""
    return math.remainder(angle, TWO_PI)


def wrap_2pi(angle: float) -> float:
    """``angle`` (rad) to ``[0, 2 pi)``."""
    a = angle % TWO_PI
    return 0.0 if a >= TWO_PI else a
