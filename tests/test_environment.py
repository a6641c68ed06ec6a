"""Currents, waves and the numerical helpers of the simulated sea (sitl.environment,
sitl.integrate)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.sitl.environment import (
    TIDAL_M2_PERIOD_S,
    CombinedCurrent,
    Environment,
    NonuniformCurrent,
    TidalCurrent,
    UniformCurrent,
    WaveField,
)
from onboard.sitl.frames import euler_to_matrix as rotation_body_to_ned
from onboard.sitl.frames import kinematics, wrap_2pi, wrap_pi
from onboard.sitl.integrate import integrate_rk4, rk4_step

P0 = np.zeros(3)


# ---------------------------------------------------------------- currents


def test_uniform_current_is_the_same_everywhere_and_always():
    c = UniformCurrent(0.3, -0.2, 0.01)
    for t, p in [(0.0, P0), (1e4, np.array([1e3, -5e2, 30.0]))]:
        assert np.allclose(c.velocity_ned(t, p), [0.3, -0.2, 0.01])


@pytest.mark.parametrize(
    ("xi", "expected_east"),
    [(0.0, -0.3), (500.0, -0.3 * math.sqrt(2.0)), (1500.0, -0.6), (-375.0, -0.15), (-500.0, 0.0)],
)
def test_nonuniform_current_matches_the_papers_field(xi, expected_east):
    # V_f(X) = [0, -0.3 sqrt((500 + xi)/500), 0] (Fan et al., algorithms.md 4.1)
    v = NonuniformCurrent().velocity_ned(0.0, np.array([xi, 123.0, 10.0]))
    assert v[0] == 0.0 and v[2] == 0.0
    assert v[1] == pytest.approx(expected_east, abs=1e-12)


def test_nonuniform_current_is_zero_outside_its_domain():
    assert np.allclose(NonuniformCurrent().velocity_ned(0.0, np.array([-800.0, 0, 0])), 0.0)


def test_tidal_current_has_the_m2_period_by_default():
    tide = TidalCurrent(amplitude=0.5, direction=math.radians(60.0), phase=0.3, mean=0.1)
    assert TIDAL_M2_PERIOD_S == pytest.approx(12.42 * 3600.0, rel=1e-3)
    for t in (0.0, 1234.5, 20000.0):
        assert np.allclose(tide(t, P0), tide(t + TIDAL_M2_PERIOD_S, P0), atol=1e-12)


def test_tidal_current_speed_direction_and_phase():
    tide = TidalCurrent(amplitude=0.4, direction=math.radians(90.0), period=600.0, mean=0.1)
    assert np.allclose(tide(0.0, P0), [0.0, 0.5, 0.0], atol=1e-12)  # flood peak: mean + amp
    assert np.allclose(tide(150.0, P0), [0.0, 0.1, 0.0], atol=1e-12)  # slack: the mean
    assert np.allclose(tide(300.0, P0), [0.0, -0.3, 0.0], atol=1e-12)  # ebb peak
    # period from zero crossings of speed - mean
    t = np.linspace(0, 1800, 18001)
    s = np.array([tide.speed(ti) for ti in t]) - 0.1
    ups = t[1:][(s[:-1] < 0) & (s[1:] >= 0)]
    assert np.diff(ups) == pytest.approx(600.0, abs=0.2)


def test_combined_current_is_the_sum_and_flattens():
    a, b, c = UniformCurrent(0.1, 0.0), NonuniformCurrent(), TidalCurrent(0.2, 0.0, 100.0)
    comb = a + b + c
    assert isinstance(comb, CombinedCurrent) and len(comb.fields) == 3
    p = np.array([100.0, 0.0, 0.0])
    assert np.allclose(comb(7.0, p), a(7.0, p) + b(7.0, p) + c(7.0, p))


def test_current_rate_is_the_material_derivative():
    env = Environment(current=NonuniformCurrent() + TidalCurrent(0.2, 0.0, 600.0))
    p, v = np.array([100.0, 0.0, 0.0]), np.array([1.5, 0.0, 0.0])
    t = 37.0
    # analytic: tidal dV/dt + (dV_east/dxi) * v_north
    tidal = -0.2 * 2 * math.pi / 600.0 * math.sin(2 * math.pi * t / 600.0)
    grad = -0.3 / (2 * 500.0 * math.sqrt((500.0 + 100.0) / 500.0))
    assert np.allclose(env.current_rate_ned(t, p, v), [tidal, grad * 1.5, 0.0], atol=1e-7)


def test_environment_defaults_to_still_water_without_waves():
    env = Environment()
    assert np.allclose(env.current_ned(0.0, P0), 0.0)
    wm = env.wave_motion(3.0, P0)
    assert np.allclose(wm.displacement, 0.0) and wm.roll == 0.0


def test_latlon_is_the_wgs84_tangent_plane_at_the_origin():
    env = Environment(origin_lat_deg=45.0, origin_lon_deg=10.0)
    lat, lon = env.latlon(1111.3, 0.0)
    # 1/100 deg of latitude at 45 deg is 1111.4 m (WGS-84 meridional radius)
    assert lat - 45.0 == pytest.approx(0.01, rel=2e-4) and lon == pytest.approx(10.0, abs=1e-12)
    lat, lon = env.latlon(0.0, 788.6)  # 1/100 deg of longitude at 45 deg is 788.6 m
    assert lon - 10.0 == pytest.approx(0.01, rel=2e-4)
    assert lat - 45.0 == pytest.approx(0.0, abs=1e-6)  # the parallel curves off the plane
    assert Environment().latlon(1.0, 1.0) is None


# ---------------------------------------------------------------- waves


def test_regular_wave_elevation_amplitude_period_and_dispersion():
    w = WaveField.regular(height=0.6, period=4.0)
    t = np.linspace(0, 40, 4001)
    z = np.array([w.elevation(ti, 0.0, 0.0) for ti in t])
    assert z.max() == pytest.approx(0.3, rel=1e-4) and z.min() == pytest.approx(-0.3, rel=1e-4)
    assert w.elevation(1.3, 2.0, 0.0) == pytest.approx(w.elevation(5.3, 2.0, 0.0), abs=1e-12)
    assert w.wavenumbers[0] == pytest.approx((2 * math.pi / 4.0) ** 2 / 9.81)  # deep water


def test_regular_wave_particle_orbits_are_circles_that_decay_with_depth():
    w = WaveField.regular(height=1.0, period=5.0, direction=math.radians(30.0))
    k = w.wavenumbers[0]
    for depth in (0.0, 2.0):
        for t in np.linspace(0, 5, 11):
            d = w.motion(t, np.array([0.0, 0.0, depth])).displacement
            horiz = math.hypot(d[0], d[1])
            assert math.hypot(horiz, d[2]) == pytest.approx(0.5 * math.exp(-k * depth), rel=1e-9)
            if horiz > 1e-6:  # horizontal motion along the wave direction
                assert math.atan2(d[1], d[0]) % math.pi == pytest.approx(math.radians(30.0))


def test_wave_velocity_and_acceleration_are_derivatives_of_displacement():
    w = WaveField.from_spectrum(hs=0.8, tp=4.0, direction=0.4, spreading=0.3, seed=3)
    p0, vel = np.array([5.0, -3.0, 0.0]), np.array([1.0, 0.5, 0.0])
    t, h = 12.3, 1e-4

    def disp(tt):
        return w.motion(tt, p0 + vel * (tt - t), vel).displacement

    wm = w.motion(t, p0, vel)
    fd_v = (disp(t + h) - disp(t - h)) / (2 * h)
    fd_a = (disp(t + h) - 2 * disp(t) + disp(t - h)) / h**2
    assert np.allclose(wm.velocity, fd_v, atol=1e-6)
    assert np.allclose(wm.acceleration, fd_a, atol=1e-3)


def test_wave_slope_gives_wave_following_pitch():
    # a wave travelling north; a boat heading north pitches, heading east rolls
    w = WaveField.regular(height=0.4, period=4.0, direction=0.0, phase=math.pi / 2)
    k = w.wavenumbers[0]
    north = w.motion(0.0, P0, yaw=0.0)
    east = w.motion(0.0, P0, yaw=math.pi / 2)
    assert abs(north.pitch) == pytest.approx(0.2 * k, rel=1e-9) and abs(north.roll) < 1e-12
    assert abs(east.roll) == pytest.approx(0.2 * k, rel=1e-9) and abs(east.pitch) < 1e-12


def test_irregular_sea_has_the_requested_significant_height_and_is_seeded():
    w1 = WaveField.from_spectrum(hs=1.2, tp=5.0, seed=7)
    w2 = WaveField.from_spectrum(hs=1.2, tp=5.0, seed=7)
    w3 = WaveField.from_spectrum(hs=1.2, tp=5.0, seed=8)
    assert w1.significant_height == pytest.approx(1.2, rel=1e-12)
    assert np.array_equal(w1.phases, w2.phases) and not np.array_equal(w1.phases, w3.phases)
    t = np.arange(0.0, 1800.0, 0.25)
    z = np.array([w1.elevation(ti, 0.0, 0.0) for ti in t])
    # 4 std of a 30 min record; measured 1.200 m for seed 7
    assert 4.0 * z.std() == pytest.approx(1.2, rel=0.1)
    # the energy peaks near the peak period (measured 4.82 s for tp = 5 s)
    peak = 2 * math.pi / w1.omegas[np.argmax(w1.amplitudes)]
    assert peak == pytest.approx(5.0, rel=0.15)


# ---------------------------------------------------------------- integrate


def test_rk4_is_fourth_order_on_exponential_decay():
    def f(t, x):
        return -x

    errs = []
    for h in (0.1, 0.05):
        x = integrate_rk4(f, 0.0, np.array([1.0]), 2.0, h)
        errs.append(abs(x[0] - math.exp(-2.0)))
    assert errs[0] / errs[1] == pytest.approx(16.0, rel=0.1)
    assert errs[1] < 1e-7
    assert rk4_step(f, 0.0, np.array([1.0]), 0.0)[0] == 1.0


def test_integrate_rk4_uses_substeps_no_longer_than_the_max():
    calls: list[float] = []

    def f(t, x):
        calls.append(t)
        return np.zeros(1)

    integrate_rk4(f, 0.0, np.zeros(1), 0.1, 0.03)
    assert len(calls) == 4 * 4  # ceil(0.1 / 0.03) = 4 sub-steps


def test_angle_wrapping():
    assert wrap_pi(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_pi(-3 * math.pi / 2) == pytest.approx(math.pi / 2)
    assert wrap_2pi(-0.5) == pytest.approx(2 * math.pi - 0.5)


def test_rotation_is_orthonormal_and_yaw_points_the_nose():
    r = rotation_body_to_ned(0.1, -0.2, 2.0)
    assert np.allclose(r @ r.T, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    nose = rotation_body_to_ned(0.0, 0.0, math.pi / 2) @ np.array([1.0, 0.0, 0.0])
    assert np.allclose(nose, [0.0, 1.0, 0.0])  # yaw 90 deg: nose east
    nose_up = rotation_body_to_ned(0.0, 0.3, 0.0) @ np.array([1.0, 0.0, 0.0])
    assert nose_up[2] < 0.0  # positive pitch raises the nose (down is +)


def test_euler_rates_at_level_are_the_body_rates():
    assert kinematics(0.0, 0.0, 0.0, (0, 0, 0, 0.1, -0.2, 0.3))[3:] == pytest.approx(
        (0.1, -0.2, 0.3))
