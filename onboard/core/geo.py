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

Positions are projected about a reference point with the equirectangular formulas of
algorithms.md §1.3 (accurate to well under a metre over a few kilometres, which is the
range of a small-vehicle mission).
"""

from __future__ import annotations

import math

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


def metres_per_degree(lat_deg: float) -> tuple[float, float]:
    """(metres per degree of latitude, metres per degree of longitude) at ``lat_deg``."""
    lat = math.radians(lat_deg)
    m_lat = 111132.954 - 559.822 * math.cos(2 * lat) + 1.175 * math.cos(4 * lat)
    m_lon = math.pi / 180.0 * 6367449.0 * math.cos(lat)
    return m_lat, m_lon


class LocalFrame:
    """North/east metres about a reference latitude/longitude (deg)."""

    __slots__ = ("lat0", "lon0", "m_lat", "m_lon")

    def __init__(self, lat0_deg: float, lon0_deg: float) -> None:
        self.lat0 = lat0_deg
        self.lon0 = lon0_deg
        self.m_lat, self.m_lon = metres_per_degree(lat0_deg)

    def to_ne(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        """(north, east) in metres of a point given in degrees."""
        dlon = (lon_deg - self.lon0 + 180.0) % 360.0 - 180.0
        return (lat_deg - self.lat0) * self.m_lat, dlon * self.m_lon

    def to_latlon(self, north_m: float, east_m: float) -> tuple[float, float]:
        """(lat, lon) in degrees of a point given in local metres."""
        return self.lat0 + north_m / self.m_lat, self.lon0 + east_m / self.m_lon
