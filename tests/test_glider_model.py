"""The steady-glide model of a buoyancy-driven glider (vehicle_models.GliderModel): the
force balance it solves, its two routes to the speed agreeing, and where it declines."""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.core.so3 import euler_to_matrix
from onboard.estimators.vehicle_models import GliderModel, merckelbach_coefficients

PUMP_CC = 250.0  # a Slocum's pump stroke: +-250 cm^3 about neutral
PITCH = math.radians(25.0)


def test_published_coefficients_at_aegean_density():
    k_l, k_d0, k_d = merckelbach_coefficients(1029.0)
    # 0.5 * 1029 * 0.1 * (3.8 + 3.73), * 0.15, * (9.7 + 0.79)
    assert k_l == pytest.approx(387.6, abs=0.1)
    assert k_d0 == pytest.approx(7.72, abs=0.01)
    assert k_d == pytest.approx(539.8, abs=0.1)


def test_the_config_defaults_are_the_published_coefficients_at_the_default_density():
    from onboard.core.pipeline_config import GliderModelConfig

    c = GliderModelConfig()
    k_l, k_d0, k_d = merckelbach_coefficients(c.water_density_kgm3)
    assert (c.lift_kl, c.drag_kd0, c.drag_kd) == pytest.approx((k_l, k_d0, k_d), abs=0.05)
    g = GliderModel()
    assert (g.k_l, g.k_d0, g.k_d) == (k_l, k_d0, k_d)


@pytest.mark.parametrize("sign", [-1.0, 1.0])
def test_unpowered_glide_solves_both_routes_alike(sign):
    """The speed from the buoyancy (drag balance) and the speed from the depth rate that
    glide gives (lift balance) are the same glide: no thrust left over."""
    g = GliderModel(neutral_pump_cc=0.0)
    pitch, pump = sign * PITCH, sign * PUMP_CC
    b = g.glide_from_buoyancy(pitch, pump)
    assert b is not None
    assert abs(b.gamma) > abs(pitch)  # the path is steeper than the hull
    k = g.glide_from_depth_rate(pitch, b.w, pump)
    assert k is not None
    assert k.u_h == pytest.approx(b.u_h, rel=1e-4)
    assert k.alpha == pytest.approx(b.alpha, rel=1e-3)
    assert abs(k.thrust) < 1e-3 * abs(g.net_buoyancy(pump))


def test_depth_rate_route_balances_lift_against_net_buoyancy():
    g = GliderModel(k_l=387.6, k_d0=7.72, k_d=539.8, density=1029.0)
    s = g.glide_from_depth_rate(-PITCH, 0.37, -PUMP_CC)  # a Kolumbo dive under thrust
    assert s is not None
    b = abs(g.net_buoyancy(-PUMP_CC))
    assert g.lift(abs(s.alpha), s.speed) == pytest.approx(b * math.cos(s.gamma), rel=1e-6)
    assert s.u_h == pytest.approx(0.37 / math.tan(abs(s.gamma)))
    assert s.thrust > 0.0  # faster than the buoyancy alone: the thruster pushes
    # the body-axis velocity, rotated by the pitch, is the glide in earth axes
    v = euler_to_matrix(0.0, -PITCH, 0.0) @ np.array(s.body_velocity(-PITCH))
    assert v[0] == pytest.approx(s.u_h) and v[2] == pytest.approx(0.37)


def test_declines_where_the_depth_rate_cannot_give_the_speed():
    g = GliderModel()
    assert g.glide_from_depth_rate(math.radians(5.0), -0.1, PUMP_CC) is None  # shallow
    assert g.glide_from_depth_rate(-PITCH, -0.2, -PUMP_CC) is None  # nose down, rising
    assert g.glide_from_depth_rate(-PITCH, math.nan, -PUMP_CC) is None
    assert g.glide_from_buoyancy(-PITCH, PUMP_CC) is None  # nose down while buoyant


def test_uncertainty_grows_as_the_glide_flattens():
    g = GliderModel()
    steep = g.glide_from_depth_rate(math.radians(-35.0), 0.4, -PUMP_CC)
    flat = g.glide_from_depth_rate(math.radians(-15.0), 0.2, -PUMP_CC)
    assert steep is not None and flat is not None
    assert flat.std_u_h > 2.0 * steep.std_u_h


def test_battery_forward_pitches_down_pump_buoyant_pitches_up():
    g = GliderModel(k_pump=0.002, k_batt=13.0, batt0=-0.006)
    assert g.pitch_from_battery(-0.006, 0.0) == 0.0
    assert g.pitch_from_battery(0.0, 0.0) < 0.0
    assert g.pitch_from_battery(-0.006, PUMP_CC) > 0.0
