"""The ESESO's published uncertainty off its design point: the model coefficients'
uncertainty in the disturbance's sigma, and measurement and IMU noise scales learnt from
the innovations (``onboard/estimators/eseso_filter.py``; docs/eseso-mpc.md "Off the design
point")."""

from __future__ import annotations

import numpy as np
import pytest

from onboard.estimators.eseso_filter import XI, EsesoFilter
from onboard.pipelines.eseso import EsesoConfig, filter_params

GRAVITY_ONLY = np.array([0.0, 0.0, -9.81])
"""Specific force (m/s^2, FRD) of a level vehicle at rest."""


def _level_filter(**overrides: object) -> EsesoFilter:
    f = EsesoFilter(filter_params(EsesoConfig(**overrides)))  # type: ignore[arg-type]
    f.initialize(np.eye(3), np.array([0.0, 0.0, 20.0]))
    return f


def test_the_model_variance_is_each_coefficient_group_times_its_force() -> None:
    f = _level_filter(mass_rel_std=0.2, damping_rel_std=0.3, thrust_rel_std=0.25)
    f.v = np.array([0.5, 0.0, 0.0])
    tau = np.array([20.0, -4.0, 0.0])
    var = f.model_force_var(GRAVITY_ONLY, np.zeros(3), tau)
    c = EsesoConfig()
    damp_x = (c.damping_linear[0] + c.damping_quadratic[0] * 0.5) * 0.5
    # at rest in acceleration the inertial force is zero: damping and thrust alone
    assert var[0] == pytest.approx((0.3 * damp_x) ** 2 + (0.25 * 20.0) ** 2)
    assert var[1] == pytest.approx((0.25 * 4.0) ** 2)
    assert var[2] == pytest.approx(0.0, abs=1e-12)
    # the thrust update keeps it; the filter's covariance P does not carry it
    P_xi = f.P[XI, XI].copy()
    f.update_thrust(GRAVITY_ONLY, np.zeros(3), np.zeros(3), tau)
    assert f.xi_model_var == pytest.approx(var)
    assert np.all(np.diag(f.P[XI, XI]) < np.diag(P_xi))


def test_without_model_uncertainty_the_model_variance_is_zero() -> None:
    f = _level_filter(mass_rel_std=0.0, damping_rel_std=0.0, thrust_rel_std=0.0)
    f.v = np.array([0.5, 0.2, 0.1])
    assert np.all(f.model_force_var(GRAVITY_ONLY, np.zeros(3), np.ones(3) * 30.0) == 0.0)


def _depth_updates(f: EsesoFilter, std: float, n: int, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(n):
        f.P[2, 2] = 1e-6  # a well-known depth: the innovation is the sensor's noise
        f.p[2] = 20.0
        f.update_depth(20.0 + rng.normal(0.0, std), 0.02 ** 2)


def test_noise_larger_than_configured_is_learnt_within_floor_and_ceiling() -> None:
    f = _level_filter(noise_adapt_updates=100, noise_scale_max=9.0)
    _depth_updates(f, 0.04, 1000)  # twice the configured 0.02 m: variance x4
    assert f.noise_scale["depth"] == pytest.approx(4.0, rel=0.25)
    assert f.S[0, 0] == pytest.approx(1e-6 + f.noise_scale["depth"] * 0.02 ** 2)
    loud = _level_filter(noise_adapt_updates=100, noise_scale_max=9.0)
    _depth_updates(loud, 0.2, 1000)  # ten times: the ceiling
    assert loud.noise_scale["depth"] == 9.0


def test_noise_as_configured_or_smaller_keeps_the_configured_noise() -> None:
    f = _level_filter(noise_adapt_updates=100)
    _depth_updates(f, 0.01, 1000)  # half the configured noise: one-sided, floor 1
    assert f.noise_scale["depth"] == 1.0
    off = _level_filter(noise_adapt_updates=0)
    _depth_updates(off, 0.04, 300)
    assert off.noise_scale == {} and off.S[0, 0] == pytest.approx(1e-6 + 0.02 ** 2)


def test_dvl_innovations_larger_than_expected_scale_the_imu_noise() -> None:
    f = _level_filter(noise_adapt_updates=50, noise_scale_max=9.0)
    rng = np.random.default_rng(1)
    for _ in range(400):
        f.propagate(GRAVITY_ONLY, np.zeros(3), 0.2)
        # velocity errors three times what the propagation's covariance allows
        f.v = rng.normal(0.0, 3.0 * np.sqrt(np.diag(f.P)[3:6]))
        f.update_body_velocity(np.zeros(3), 1e-8)
    assert f.process_scale > 3.0
    assert "dvl" not in f.noise_scale  # the DVL's own noise is its figure of merit
