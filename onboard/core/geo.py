"""Local tangent-plane geometry shared by the pipelines (algorithms.md §1.3).

Positions are projected about a reference point with the equirectangular formulas of
algorithms.md §1.3 (accurate to well under a metre over a few kilometres, which is the
range of a small-vehicle mission).
"""

from __future__ import annotations

import math


def wrap_pi(angle: float) -> float:
    """Wrap an angle (rad) to (-pi, pi]."""
    a = math.fmod(angle + math.pi, 2.0 * math.pi)
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi


def wrap_2pi(angle: float) -> float:
    """Wrap an angle (rad) to [0, 2*pi)."""
    a = math.fmod(angle, 2.0 * math.pi)
    return a + 2.0 * math.pi if a < 0.0 else a


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
