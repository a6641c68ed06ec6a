"""Angles and local tangent-plane geometry shared by the pipelines, the drivers and the
simulator (algorithms.md §1.3).

Angle wrapping has one implementation here, with a numpy twin for arrays that returns
bit-for-bit the same values:

* :func:`wrap_pi` maps to ``(-pi, pi]``: the closed end is ``+pi``, so ``wrap_pi(-pi) ==
  wrap_pi(pi) == pi`` (heading differences, innovations, yaw);
* :func:`wrap_2pi` maps to ``[0, 2 pi)``: ``0.0`` for every multiple of ``2 pi``, for
  ``-0.0``, and for an input so little below a multiple of ``2 pi`` that ``2 pi`` would
  be the rounded result (headings and courses over ground);
* both return NaN for NaN and for an infinite angle, which has no wrapped value.

The remainder is :func:`math.fmod` (exact in IEEE arithmetic, whatever the size of the
angle), so an angle of 1e300 rad wraps as exactly as an angle of 4 rad.

Positions are projected on the WGS-84 local tangent plane about a reference point
(algorithms.md §1.3): geodetic to earth-centred earth-fixed (ECEF) coordinates on the
ellipsoid, then rotated into east/north/up at the reference. The plane is flat, so the
filters' straight-line kinematics hold in it; :func:`radii_of_curvature` gives the
ellipsoid's meridional and prime-vertical radii for the metres-per-degree scale.
"""

from __future__ import annotations

import math
from typing import Sequence

from mypy_extensions import mypyc_attr
import numpy as np
from numpy.typing import ArrayLike, NDArray

TWO_PI = 2.0 * math.pi
"""2 pi (rad), the period of an angle."""


def wrap_pi(angle: float) -> float:
    """Wrap an angle (rad) to ``(-pi, pi]`` (``+pi`` is the closed end); NaN for NaN and
    for +-inf."""
    try:
        a = math.fmod(angle + math.pi, TWO_PI)
    except ValueError:  # fmod of an infinity
        return math.nan
    if a <= 0.0:
        a += TWO_PI
    return a - math.pi


def wrap_pi_array(angle: ArrayLike) -> NDArray[np.float64]:
    """:func:`wrap_pi` of every element of ``angle`` (rad), as a new float array: the same
    operations in the same order, so each element is bit-for-bit the scalar result."""
    x = np.asarray(angle, dtype=float)
    with np.errstate(invalid="ignore"):  # fmod of an infinity is NaN, as in wrap_pi
        a = np.fmod(x + math.pi, TWO_PI)
    a = np.where(a <= 0.0, a + TWO_PI, a)
    return a - math.pi


def wrap_2pi(angle: float) -> float:
    """Wrap an angle (rad) to ``[0, 2 pi)``; ``+0.0`` for ``-0.0`` and for multiples of
    ``2 pi``; NaN for NaN and for +-inf."""
    try:
        a = math.fmod(angle, TWO_PI)
    except ValueError:  # fmod of an infinity
        return math.nan
    if a < 0.0:
        a += TWO_PI
        return a if a < TWO_PI else 0.0
    return a + 0.0  # -0.0 + 0.0 is +0.0; any other value is unchanged


def circular_stats(angles: Sequence[float]) -> tuple[float, float]:
    """The circular mean (rad, in ``(-pi, pi]``) of ``angles`` (rad) and their circular
    standard deviation ``sqrt(-2 ln R)`` (rad), ``R`` the mean resultant length (Mardia &
    Jupp 2000, §2.3): about the standard deviation for angles close together, infinite
    for angles that cancel."""
    s = sum(map(math.sin, angles))
    c = sum(map(math.cos, angles))
    r = min(math.hypot(s, c) / len(angles), 1.0)
    return math.atan2(s, c), math.sqrt(-2.0 * math.log(r)) if r > 0.0 else math.inf


WGS84_A_M = 6378137.0
"""WGS-84 semi-major axis (m)."""
WGS84_F = 1.0 / 298.257223563
"""WGS-84 flattening."""
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
"""WGS-84 first eccentricity squared."""
_GEODETIC_ITERATIONS = 4
"""Fixed-point steps of :func:`ecef_to_geodetic` (each gains ~3 orders; 4 reach the
rounding of a double within a few km of the surface)."""


def radii_of_curvature(lat_deg: float) -> tuple[float, float]:
    """(meridional radius M, prime-vertical radius N) of the WGS-84 ellipsoid (m) at
    ``lat_deg``: ``N = a / sqrt(1 - e2 sin^2 lat)``, ``M = N (1 - e2) / (1 - e2 sin^2
    lat)``."""
    s = math.sin(math.radians(lat_deg))
    w2 = 1.0 - WGS84_E2 * s * s
    n = WGS84_A_M / math.sqrt(w2)
    return n * (1.0 - WGS84_E2) / w2, n


def metres_per_degree(lat_deg: float) -> tuple[float, float]:
    """(metres per degree of latitude, metres per degree of longitude) at ``lat_deg`` on
    the WGS-84 ellipsoid: ``M pi/180`` and ``N cos(lat) pi/180``."""
    m, n = radii_of_curvature(lat_deg)
    rad = math.pi / 180.0
    return m * rad, n * math.cos(math.radians(lat_deg)) * rad


def ecef_to_geodetic(x: float, y: float, z: float) -> tuple[float, float, float]:
    """(lat, lon) in degrees and height (m) above the WGS-84 ellipsoid of an ECEF point
    (m), by fixed-point iteration on the latitude (Hofmann-Wellenhof et al., *GNSS*,
    2008, section 10.2.1); for points within a few km of the surface, not the poles' axis."""
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1.0 - WGS84_E2))
    for _ in range(_GEODETIC_ITERATIONS):
        n, h = _height(lat, p)
        lat = math.atan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
    return math.degrees(lat), math.degrees(math.atan2(y, x)), _height(lat, p)[1]


def _height(lat: float, p: float) -> tuple[float, float]:
    """(prime-vertical radius (m), height (m)) at latitude ``lat`` (rad) of a point at
    distance ``p`` (m) from the earth's axis."""
    s = math.sin(lat)
    n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * s * s)
    return n, p / math.cos(lat) - n


@mypyc_attr(allow_interpreted_subclasses=True)
class LocalFrame:
    """North/east metres on the WGS-84 tangent plane at a reference latitude/longitude
    (deg), points taken on the ellipsoid (height 0).

    :meth:`to_ne` is exact (geodetic -> ECEF -> ENU); :meth:`to_latlon` is its inverse
    for the point of the plane at zero up, dropped onto the ellipsoid along its normal, so
    ``to_ne(*to_latlon(n, e))`` returns ``(n, e)`` to ``d^3 / (2 R^2)`` (1.5 mm at
    ``d`` = 5 km). ``m_lat``, ``m_lon``: metres per degree at the reference.
    """

    __slots__ = ("lat0", "lon0", "m_lat", "m_lon", "_s0", "_c0", "_x0", "_z0")

    def __init__(self, lat0_deg: float, lon0_deg: float) -> None:
        self.lat0 = lat0_deg
        self.lon0 = lon0_deg
        self.m_lat, self.m_lon = metres_per_degree(lat0_deg)
        lat0 = math.radians(lat0_deg)
        self._s0, self._c0 = math.sin(lat0), math.cos(lat0)
        self._x0, _, self._z0 = self._ecef(lat0_deg, 0.0)

    @staticmethod
    def _ecef(lat_deg: float, dlon_deg: float) -> tuple[float, float, float]:
        """ECEF (m) of a point on the ellipsoid, the x axis in the reference's meridian."""
        lat, dlon = math.radians(lat_deg), math.radians(dlon_deg)
        s, c = math.sin(lat), math.cos(lat)
        n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * s * s)
        return n * c * math.cos(dlon), n * c * math.sin(dlon), n * (1.0 - WGS84_E2) * s

    def to_ne(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        """(north, east) in metres of a point given in degrees."""
        dlon = (lon_deg - self.lon0 + 180.0) % 360.0 - 180.0
        x, y, z = self._ecef(lat_deg, dlon)
        return -self._s0 * (x - self._x0) + self._c0 * (z - self._z0), y

    def to_latlon(self, north_m: float, east_m: float) -> tuple[float, float]:
        """(lat, lon) in degrees of a point given in local metres."""
        s0, c0 = self._s0, self._c0
        x = self._x0 - s0 * north_m
        z = self._z0 + c0 * north_m
        lat, dlon, _ = ecef_to_geodetic(x, east_m, z)
        return lat, (self.lon0 + dlon + 180.0) % 360.0 - 180.0
