"""The fleet's current field (sitl/current_field.py) against its closed forms: the
Lamb-Oseen profile and its peak, the Poiseuille shear across the channel and Soulsby's
power law down the water column, the tanh front, continuity where it holds (and the
front's convergence where it does not), the geodetic evaluation, and a plant taking its
current from the field at its own position."""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.sitl.current_field import (
    LAMB_OSEEN_PEAK_FACTOR, LAMB_OSEEN_PEAK_RADIUS, LambOseenEddy, SeaField, TanhFront,
    TidalChannel, UniformFlow, VehicleCurrent)
from onboard.sitl.environment import Environment
from onboard.sitl.fleet import FLEETS

UTC0 = 1_767_225_600.0
H = 0.5
"""Central-difference step (m) of the divergence checks."""


def divergence(part, n, e, d=0.0, t=UTC0, h=H):
    """dV_N/dN + dV_E/dE by central differences (1/s)."""
    vn_p, _ = part.velocity(n + h, e, d, t)
    vn_m, _ = part.velocity(n - h, e, d, t)
    _, ve_p = part.velocity(n, e + h, d, t)
    _, ve_m = part.velocity(n, e - h, d, t)
    return (vn_p - vn_m) / (2 * h) + (ve_p - ve_m) / (2 * h)


def test_lamb_oseen_profile_and_peak():
    rc, gamma = 80.0, 120.0
    eddy = LambOseenEddy(circulation=gamma, core_radius=rc)
    r = np.linspace(1.0, 600.0, 400)
    # the closed form along the east axis: counter-clockwise seen from above means the
    # water at (0, +r) (east of the centre) flows north
    vn, ve = eddy.velocity(0.0 * r, r, 0.0, UTC0)
    expected = gamma / (2 * math.pi * r) * (1 - np.exp(-r**2 / rc**2))
    np.testing.assert_allclose(vn, expected, rtol=1e-12)
    np.testing.assert_allclose(ve, 0.0, atol=1e-15)
    # the peak: where and how fast
    fine = np.linspace(0.5 * rc, 2 * rc, 20001)
    v = eddy.azimuthal(fine)
    assert fine[np.argmax(v)] == pytest.approx(LAMB_OSEEN_PEAK_RADIUS * rc, rel=1e-3)
    assert v.max() == pytest.approx(LAMB_OSEEN_PEAK_FACTOR * gamma / (2 * math.pi * rc), rel=1e-4)
    # solid-body rotation near the centre (v = Gamma r / (2 pi rc^2)), zero at it, the
    # potential vortex far away
    assert eddy.azimuthal(0.01) == pytest.approx(gamma * 0.01 / (2 * math.pi * rc**2), rel=1e-6)
    assert eddy.velocity(0.0, 0.0, 0.0, UTC0) == (0.0, -0.0)
    assert eddy.azimuthal(5000.0) == pytest.approx(gamma / (2 * math.pi * 5000.0), rel=1e-9)
    assert LambOseenEddy.with_peak(0.2, rc).azimuthal(fine).max() == pytest.approx(0.2, rel=1e-4)


def test_lamb_oseen_drifts_and_is_divergence_free():
    eddy = LambOseenEddy.with_peak(-0.15, 80.0, north0=10.0, east0=-20.0, t_ref=UTC0,
                                   drift_north=0.02, drift_east=0.05)
    later = UTC0 + 1000.0
    cn, ce = eddy.centre(later)
    assert (cn, ce) == pytest.approx((30.0, 30.0))
    # the same profile about the moved centre; clockwise: east of the centre flows south
    vn, _ = eddy.velocity(cn, ce + 90.0, 0.0, later)
    assert vn == pytest.approx(eddy.azimuthal(90.0)) and vn < 0
    rng = np.random.default_rng(3)
    n, e = rng.uniform(-300, 300, 200), rng.uniform(-300, 300, 200)
    assert np.abs(divergence(eddy, n, e, t=later)).max() < 1e-7
    # negative control: a source is not divergence-free and the check sees it
    assert divergence(Source(), 5.0, 5.0) == pytest.approx(2e-3)


class Source(UniformFlow):
    """A point source's linear flow, divergence 2e-3 1/s (the negative control)."""

    def velocity(self, north, east, depth, utc):
        return 1e-3 * north, 1e-3 * east


def test_channel_shear_vertical_profile_and_tide():
    ch = TidalChannel(amplitude=0.4, direction=math.radians(30), width=1000.0,
                      period=1200.0, t_ref=UTC0, water_depth=20.0)
    c, s = math.cos(ch.direction), math.sin(ch.direction)
    y = np.linspace(-600, 600, 241)
    n, e = -y * s, y * c  # across the channel, positive to starboard of the flood
    vn, ve = ch.velocity(n, e, 10.0, UTC0)
    speed = vn * c + ve * s
    poiseuille = 0.4 * np.clip(1 - (2 * y / 1000.0) ** 2, 0.0, None)
    np.testing.assert_allclose(speed / SOULSBY(10.0, 20.0), poiseuille, atol=1e-12)
    np.testing.assert_allclose(-vn * s + ve * c, 0.0, atol=1e-12)  # along the axis only
    # down the column: Soulsby's law below mid-depth, 1.07 above; its depth mean ~1
    z_depths = np.linspace(0.0, 19.95, 4000)
    f = ch.vertical(z_depths)
    np.testing.assert_allclose(f, [SOULSBY(d, 20.0) for d in z_depths], rtol=1e-12)
    assert f.mean() == pytest.approx(1.0, abs=0.02)
    # in time: a half period later the ebb mirrors the flood
    vn2, ve2 = ch.velocity(0.0, 0.0, 10.0, UTC0 + 600.0)
    vn1, ve1 = ch.velocity(0.0, 0.0, 10.0, UTC0)
    assert (vn2, ve2) == pytest.approx((-vn1, -ve1))
    rng = np.random.default_rng(4)
    pn, pe = rng.uniform(-400, 400, 100), rng.uniform(-400, 400, 100)
    assert np.abs(divergence(ch, pn, pe)).max() < 1e-12


def SOULSBY(depth, h):  # noqa: N802 - the closed form, written out
    z = h - depth
    return (z / (0.32 * h)) ** (1 / 7) if z < 0.5 * h else 1.07


def test_front_profile_motion_and_convergence():
    fr = TanhFront(a_north=0.1, a_east=0.0, b_north=-0.1, b_east=0.2, normal=0.0,
                   half_width=20.0, north0=100.0, t_ref=UTC0, speed=0.05)
    t = UTC0 + 200.0  # the line has moved 10 m north
    s = np.linspace(-100, 100, 201)
    vn, ve = fr.velocity(110.0 + s, 0.0 * s, 0.0, t)
    w = 0.5 * (1 + np.tanh(s / 20.0))
    np.testing.assert_allclose(vn, 0.1 - 0.2 * w, atol=1e-12)
    np.testing.assert_allclose(ve, 0.2 * w, atol=1e-12)
    # a jump in the normal (north) component: divergence (Vb - Va).n sech^2(s/L) / (2 L)
    div = divergence(fr, 110.0 + s, 0.0 * s, t=t, h=0.01)
    np.testing.assert_allclose(div, -0.2 / np.cosh(s / 20.0) ** 2 / 40.0, atol=1e-7)
    shear = TanhFront(b_east=0.2, normal=0.0, half_width=20.0)
    assert np.abs(divergence(shear, s, 0.0 * s)).max() < 1e-12


def test_sea_field_sums_parts_and_reads_lat_lon():
    sea = FLEETS["fleet-channel"].sea
    n, e = np.array([-120.0, 40.0, 300.0]), np.array([60.0, -200.0, 10.0])
    t, d = UTC0 + 123.0, 5.0
    parts = [p.velocity(n, e, d, t) for p in sea.parts]
    vn, ve = sea.local(n, e, d, t)
    np.testing.assert_allclose(vn, sum(p[0] for p in parts))
    np.testing.assert_allclose(ve, sum(p[1] for p in parts))
    lats, lons = sea.geo.to_latlon_many(n, e)
    gn, ge = sea.at(lats, lons, d, t)
    np.testing.assert_allclose(gn, vn, atol=1e-9)
    np.testing.assert_allclose(ge, ve, atol=1e-9)
    g = sea.grid(lats[:2], lons, [0.0, 5.0], [UTC0, t])
    assert np.asarray(g["north"]).shape == (2, 2, 2, 3)
    assert g["east"][1][1][0][0] == pytest.approx(float(sea.at(lats[0], lons[0], 5.0, t)[1]),
                                                  abs=1e-6)


def test_plant_takes_the_field_at_its_own_position_and_time():
    sea = SeaField((50.35, -4.15), (LambOseenEddy.with_peak(0.2, 50.0, t_ref=UTC0),))
    vc = VehicleCurrent(sea, offset_north=10.0, offset_east=-5.0, utc0=UTC0 + 30.0)
    env = Environment(current=vc)
    got = env.current_ned(12.0, np.array([30.0, 45.0, 2.0]))
    vn, ve = sea.local(40.0, 40.0, 2.0, UTC0 + 42.0)
    assert got.tolist() == pytest.approx([float(vn), float(ve), 0.0])
    assert math.hypot(*got[:2]) > 0.05


def test_the_plants_point_path_agrees_with_the_array_formulas():
    """Each part's float path (what the plants call) against its numpy formula, at random
    points spanning the eddy's core and centre, the channel's banks, the column from the
    surface to the bed and the front."""
    rng = np.random.default_rng(11)
    n = np.concatenate([rng.uniform(-800, 800, 300), [-120.0]])
    e = np.concatenate([rng.uniform(-800, 800, 300), [60.0]])
    d = np.concatenate([rng.uniform(0, 12.5, 300), [0.0]])
    t = np.concatenate([UTC0 + rng.uniform(-3000, 3000, 300), [UTC0]])
    for fleet in FLEETS.values():
        for part in fleet.sea.parts:
            vn, ve = part.velocity(n, e, d, t)
            pts = np.array([part.velocity_point(*map(float, x)) for x in zip(n, e, d, t)])
            np.testing.assert_allclose(pts[:, 0], vn, rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(pts[:, 1], ve, rtol=1e-12, atol=1e-15)
        sea = fleet.sea
        got = sea.local_point(10.0, 20.0, 5.0, UTC0 + 7.0)
        assert got == pytest.approx(tuple(float(x) for x in sea.local(10.0, 20.0, 5.0, UTC0 + 7.0)),
                                    rel=1e-12)
