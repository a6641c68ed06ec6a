"""The ESESO filter on its own (onboard.estimators.eseso_filter) and the one-way dependencies
of the service intake and the simulator's closed loop.

The filter's Jacobians against finite differences and the pipeline's figures are in
tests/test_eseso.py; here the filter is driven directly, without samples, and the
pipeline is checked to hand it what it configures.
"""

from __future__ import annotations

import math
from pathlib import Path

import msgspec
import numpy as np
import pytest

from onboard.core import config
from onboard.core.messages import Attitude, Depth, Imu
from onboard.core.pipeline_config import EsesoNoiseConfig, EsesoThrustersConfig
from onboard.core.so3 import euler_to_matrix
from onboard.core.stats import chi2_quantile
from onboard.estimators.eseso_filter import BI, TH, TH_Z, V_, XI, EsesoFilter, Outcome
from onboard.pipelines.eseso import Eseso, EsesoConfig, filter_params, thruster_force
from tests.helpers.imports import REPO, imports_of

GATE_1 = chi2_quantile(0.999, 1)
"""The default gate of a 1-dimensional update (10.8276)."""
GRAVITY_ONLY = np.array([0.0, 0.0, -9.81])
"""Specific force (m/s^2, FRD) of a level vehicle at rest."""


def _level_filter(**tables: object) -> EsesoFilter:
    """A filter started level at 20 m with ``[pipelines.eseso]`` keys and tables ``tables``
    (``noise={"adapt_updates": 0}``)."""
    f = EsesoFilter(filter_params(msgspec.convert(tables, EsesoConfig)))
    f.initialize(np.eye(3), np.array([0.0, 0.0, 20.0]))
    return f


def test_a_level_filter_at_rest_stays_at_rest_and_its_covariance_grows() -> None:
    f = _level_filter()
    P0 = f.P.copy()
    for _ in range(50):
        f.propagate(GRAVITY_ONLY, np.zeros(3), 0.02)
    assert np.allclose(f.p, [0.0, 0.0, 20.0], atol=1e-12)
    assert np.allclose(f.v, 0.0, atol=1e-12) and np.allclose(f.R, np.eye(3))
    assert np.all(np.diag(f.P) >= np.diag(P0))
    # the INS bias relaxes towards its stationary variance, never above it
    assert np.all(np.diag(f.P)[BI] <= 0.01 ** 2 + 1e-15)


def test_an_update_keeps_its_innovation_covariance_and_nis() -> None:
    f = _level_filter()
    prior = f.P[2, 2]
    assert f.update_depth(20.3, 0.02 ** 2, t=1.5, source="bar30") is Outcome.FUSED
    S = prior + 0.02 ** 2
    assert f.y == pytest.approx([0.3])
    assert f.S.shape == (1, 1) and f.S[0, 0] == pytest.approx(S)
    assert f.nis == pytest.approx(0.3 ** 2 / S)
    (rec,) = f.innovations  # the update's record: measured minus predicted
    assert (rec.channel, rec.t, rec.source, rec.dof) == ("depth", 1.5, "bar30", 1)
    assert rec.z == pytest.approx((0.3,)) and rec.S == pytest.approx((S,))
    assert rec.nis == f.nis and rec.gate == GATE_1 and rec.accepted
    # scalar Kalman gain on the depth
    assert f.p[2] == pytest.approx(20.0 + prior / S * 0.3)


def test_the_gate_rejects_then_fuses_down_weighted_after_max_consecutive_rejects() -> None:
    f = _level_filter(max_consecutive_rejects=2, noise={"adapt_updates": 0})
    f.P[2, 2] = 0.01
    var = 0.01
    z = 20.0 + 10.0  # NIS 5000 against the 1-dof gate of 10.83 (GATE_1)
    assert f.update_depth(z, var) is Outcome.GATED
    assert not f.update_depth(z, var)  # false: not fused
    assert f.p[2] == 20.0
    assert [(r.accepted, r.reason) for r in f.innovations] == [(False, "gate")] * 2
    nis = 10.0 ** 2 / (f.P[2, 2] + var)
    r_recover = var * nis / GATE_1
    expected = 20.0 + f.P[2, 2] / (f.P[2, 2] + r_recover) * 10.0
    assert f.update_depth(z, var) is Outcome.RECOVERED
    assert f.p[2] == pytest.approx(expected)
    assert f.innovations[-1].accepted and f.innovations[-1].nis > GATE_1


def _thrust_filter(states: str) -> EsesoFilter:
    f = _level_filter(thrust_states=states, thrust_huber=0.0)
    f.v = np.array([0.5, 0.1, 0.0])
    return f


def test_the_thrust_update_on_the_disturbance_alone_leaves_the_velocity() -> None:
    tau = np.array([20.0, -5.0, 3.0])
    only_xi, full = _thrust_filter("disturbance"), _thrust_filter("all")
    for f in (only_xi, full):
        assert f.update_thrust(GRAVITY_ONLY, np.zeros(3), np.zeros(3), tau) is Outcome.FUSED
    assert np.array_equal(only_xi.v, [0.5, 0.1, 0.0])
    assert np.allclose(only_xi.R, np.eye(3), atol=0.0)
    assert not np.allclose(full.v, [0.5, 0.1, 0.0])
    # the residual went into the disturbance, with the sign of h_tau's -xi
    h, _ = _thrust_filter("disturbance").h_tau(GRAVITY_ONLY, np.zeros(3), np.zeros(3))
    assert np.all(np.sign(only_xi.xi) == -np.sign(tau - h))


def test_the_pipeline_hands_the_filter_its_configured_noise() -> None:
    cfg = config.load("bluerov2")
    pipe = Eseso(EsesoConfig(noise=EsesoNoiseConfig(depth_std_m=0.07)), cfg.sensors)
    params = pipe.filter.params
    assert params.noise.accel_std_mps2 == cfg.sensors.imu.accel_std_mps2
    assert params.noise.gyro_std_rps == cfg.sensors.imu.gyro_std_rps
    set_here = EsesoConfig(noise=EsesoNoiseConfig(accel_std_mps2=0.3))
    assert filter_params(set_here, cfg.sensors).noise.accel_std_mps2 == 0.3
    # the typed tables reach the filter as they are (the IMU noise resolved)
    assert (params.vehicle, params.process, params.initial) == (
        pipe.cfg.vehicle, pipe.cfg.process, pipe.cfg.initial)
    pipe.step(0.0, [Attitude(t=0.0, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0),
                    Depth(t=0.0, depth_m=20.0)])
    pipe.step(0.02, [Imu(t=0.02, accel_x=0.0, accel_y=0.0, accel_z=-9.81, gyro_x=0.0,
                         gyro_y=0.0, gyro_z=0.0)])
    assert pipe.initialized and pipe.filter.p[2] == 20.0
    prior = pipe.filter.P[2, 2]
    pipe.step(0.04, [Depth(t=0.04, depth_m=20.1, source="bar30")])
    (rec,) = [r for r in pipe.innovations() if r.channel == "depth"]
    assert rec.S == pytest.approx((prior + 0.07 ** 2,))
    assert (rec.t, rec.source) == (0.04, "bar30")
    assert pipe.health().counts == {"fused.depth": 1}
    assert pipe.innovations() == []  # taken once


def test_an_attitude_update_moves_the_attitude_by_the_measured_rotation() -> None:
    f = _level_filter()
    f.P[TH, TH] = np.eye(3)  # a prior much wider than the measurement
    R_meas = euler_to_matrix(0.0, 0.0, 0.2)
    assert f.update_attitude(R_meas, 0.0, 0.0, 1e-8, 1e-8)
    assert np.allclose(f.R, R_meas, atol=1e-6)
    assert f.P[TH_Z, TH_Z] < 1e-7 and f.P[V_, V_][0, 0] == pytest.approx(0.3 ** 2)
    assert f.P[XI, XI][0, 0] == pytest.approx(40.0 ** 2)


def test_the_thrust_curve_is_quadratic_with_separate_reverse_force_and_a_deadband() -> None:
    c = EsesoThrustersConfig(deadband=0.05)
    assert thruster_force(1.0, c) == 40.0 and thruster_force(-1.0, c) == -30.0
    assert thruster_force(0.5, c) == pytest.approx(10.0)
    assert thruster_force(0.04, c) == 0.0 and thruster_force(2.0, c) == 40.0
    # a NaN command stays NaN, which the pipeline counts as rejected.command.nonfinite
    assert math.isnan(thruster_force(float("nan"), c))


def _runtime_imports(module_path: str) -> set[str]:
    return {m for _, m in imports_of(REPO / module_path)}


def test_the_intake_does_not_import_the_recorder_which_replays_through_it() -> None:
    assert "onboard.service.intake" in _runtime_imports("onboard/service/recorder.py")
    assert not any(m.startswith("onboard.service.recorder")
                   for m in _runtime_imports("onboard/service/intake.py"))


def test_the_controllers_do_not_import_the_closed_loop_runner_which_imports_them() -> None:
    assert any(m.startswith("onboard.sitl.controllers")
               for m in _runtime_imports("sitl/closed_loop.py"))
    for path in sorted((REPO / "sitl" / "controllers").glob("*.py")):
        found = _runtime_imports(str(Path(path).relative_to(REPO)))
        assert not any(m.startswith("onboard.sitl.closed_loop") for m in found), path.name
