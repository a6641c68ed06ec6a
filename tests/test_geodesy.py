"""The estimators' local frame (:class:`onboard.core.geo.LocalFrame`) is the WGS-84 local
tangent plane: checked against pymap3d (an independent implementation of the same
geodesy) at the equator, 22 deg N (Shenzhen) and 63 deg N (Trondheim), in both directions.

Issue 23 asks for better than 1 cm per km over a few km; the bounds below are tighter,
with the measured figure beside each.
"""

from __future__ import annotations

import math

import pytest

from onboard.core.geo import LocalFrame, ecef_to_geodetic, metres_per_degree

pymap3d = pytest.importorskip("pymap3d", reason="pip install -e '.[test]' (pymap3d)")

ORIGINS = [(0.0, 0.0), (22.6, 114.0), (63.4, 10.4), (-33.9, 151.2), (45.0, 179.99)]
"""Reference points (deg): equator, Shenzhen, Trondheim, Sydney, beside the antimeridian."""
RANGES_M = (10.0, 1000.0, 5000.0)
BEARINGS_DEG = tuple(range(0, 360, 45))


def _points(lat0: float, lon0: float):
    """Points at RANGES_M in 8 directions from the origin, as pymap3d puts them on the
    ellipsoid (height 0): (range (m), lat, lon)."""
    for d in RANGES_M:
        for b in BEARINGS_DEG:
            e, n = d * math.sin(math.radians(b)), d * math.cos(math.radians(b))
            lat, lon, _ = pymap3d.enu2geodetic(e, n, -d * d / 12.7e6, lat0, lon0, 0.0)
            yield d, float(lat), float(lon)


@pytest.mark.parametrize("origin", ORIGINS, ids=lambda o: f"{o[0]}N")
def test_to_ne_is_pymap3d_geodetic2enu(origin) -> None:
    frame = LocalFrame(*origin)
    worst = 0.0
    for d, lat, lon in _points(*origin):
        e_ref, n_ref, _ = pymap3d.geodetic2enu(lat, lon, 0.0, *origin, 0.0)
        n, e = frame.to_ne(lat, lon)
        worst = max(worst, math.hypot(n - n_ref, e - e_ref) / (d / 1000.0))
    # measured: 2e-7 m per km at most (rounding); issue 23 asks < 1 cm per km
    assert worst < 1e-6


@pytest.mark.parametrize("origin", ORIGINS, ids=lambda o: f"{o[0]}N")
def test_to_latlon_inverts_pymap3d_geodetic2enu(origin) -> None:
    """The inverse puts the plane's point on the ellipsoid: pymap3d takes it back to the
    same north/east, to d^3 / (2 R^2) (1.5 mm at 5 km)."""
    frame = LocalFrame(*origin)
    worst = 0.0
    for d in RANGES_M:
        for b in BEARINGS_DEG:
            n, e = d * math.cos(math.radians(b)), d * math.sin(math.radians(b))
            lat, lon = frame.to_latlon(n, e)
            e_ref, n_ref, _ = pymap3d.geodetic2enu(lat, lon, 0.0, *origin, 0.0)
            worst = max(worst, math.hypot(n - n_ref, e - e_ref) / (d / 1000.0))
    # measured: 0.31 mm per km at 5 km (the ellipsoid below the plane); asked < 1 cm/km
    assert worst < 0.5e-3


@pytest.mark.parametrize("lat0", [0.0, 22.6, 63.4])
def test_metres_per_degree_are_the_wgs84_radii(lat0: float) -> None:
    """East and north scales at the origin are the prime-vertical and meridional radii:
    a step of 1e-5 deg measured by pymap3d."""
    m_lat, m_lon = metres_per_degree(lat0)
    step = 1e-5
    e_ref, _, _ = pymap3d.geodetic2enu(lat0, step, 0.0, lat0, 0.0, 0.0)
    _, n_ref, _ = pymap3d.geodetic2enu(lat0 + step, 0.0, 0.0, lat0, 0.0, 0.0)
    # measured: relative 1e-10 (east), 4e-9 (north: the step's own curvature)
    assert m_lon * step == pytest.approx(float(e_ref), rel=1e-7)
    assert m_lat * step == pytest.approx(float(n_ref), rel=1e-7)


@pytest.mark.parametrize("lat0", [0.0, 22.6, 63.4])
def test_a_meridional_radius_east_scale_fails_the_check(lat0: float) -> None:
    """Negative control: the sphere of 6 367 449 m that scaled east before is 0.17 % short
    at the equator, 0.22 % at 22.6 N and 0.44 % at 63.4 N (4.4 m per km), far beyond the
    1 cm per km the tests above hold."""
    old_m_lon = math.pi / 180.0 * 6367449.0 * math.cos(math.radians(lat0))
    _, m_lon = metres_per_degree(lat0)
    short = 1.0 - old_m_lon / m_lon
    assert short == pytest.approx({0.0: 0.0017, 22.6: 0.0022, 63.4: 0.0044}[lat0], abs=2e-4)


@pytest.mark.parametrize("lat", [0.0, 22.6, 63.4, -45.0])
@pytest.mark.parametrize("h", [-200.0, 0.0, 3.0, 1500.0])
def test_ecef_to_geodetic_is_pymap3d_ecef2geodetic(lat: float, h: float) -> None:
    x, y, z = pymap3d.geodetic2ecef(lat, 10.4, h)
    lat_o, lon_o, h_o = ecef_to_geodetic(float(x), float(y), float(z))
    # measured: 1e-14 deg, 1e-9 m
    assert lat_o == pytest.approx(lat, abs=1e-11)
    assert lon_o == pytest.approx(10.4, abs=1e-11)
    assert h_o == pytest.approx(h, abs=1e-6)


def test_the_frame_wraps_across_the_antimeridian() -> None:
    frame = LocalFrame(45.0, 179.99)
    n, e = frame.to_ne(45.0, -179.99)
    e_ref, n_ref, _ = pymap3d.geodetic2enu(45.0, -179.99, 0.0, 45.0, 179.99, 0.0)
    assert (n, e) == pytest.approx((float(n_ref), float(e_ref)), abs=1e-6)
    assert e == pytest.approx(1577.0, abs=1.0)
    lat, lon = frame.to_latlon(n, e)
    assert lat == pytest.approx(45.0, abs=1e-9) and lon == pytest.approx(-179.99, abs=1e-9)
