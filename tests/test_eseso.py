"""ESESO pipeline (onboard.pipelines.eseso): the maths against numbers, and the contract.

The closed-loop figures (disturbance within 4 N, state errors against truth) are in
tests/test_closed_loop.py; replay on a bluerov2 log in tests/test_eseso_replay.py.
"""

from __future__ import annotations

import copy
import math

import msgspec
import numpy as np
import pytest

from onboard.core import config
from onboard.core.messages import ActuatorCommand, Attitude, Depth, DvlVelocity, GnssFix, Imu
from onboard.core.so3 import euler_to_matrix, log_so3
from onboard.estimators.eseso_filter import N_ERR, EsesoFilter
from onboard.pipelines import eseso
from onboard.pipelines.base import Pipeline

RNG = np.random.default_rng(3)


def _filter_in_motion() -> EsesoFilter:
    f = eseso.Eseso(eseso.EsesoConfig(thrust_states="all")).filter
    f.initialized = True
    f.R = euler_to_matrix(0.05, -0.08, 2.0)
    f.v = np.array([0.6, -0.4, 0.1])
    f.b_a = np.array([0.01, -0.02, 0.03])
    f.b_g = np.array([1e-3, -2e-3, 5e-4])
    f.xi = np.array([30.0, -20.0, 8.0])
    f.b_ins = np.array([0.01, -0.008])
    return f


def _error(a: EsesoFilter, b: EsesoFilter) -> np.ndarray:
    """``b ⊟ a``: the error-state vector (21 + the 2 INS bias states) of state b about
    nominal a (right perturbation)."""
    return np.concatenate([b.p - a.p, b.v - a.v, log_so3(a.R.T @ b.R), b.b_a - a.b_a,
                           b.b_g - a.b_g, b.g - a.g, b.xi - a.xi, b.b_ins - a.b_ins])


def test_create_applies_to_bluerov2_and_to_configs_that_enable_it() -> None:
    rov = eseso.create(config.load("bluerov2"))
    assert rov is not None and isinstance(rov, Pipeline)
    assert {"dist_x", "dist_y", "dist_z", "std_dist_x"} <= set(rov.columns)
    boat = config.load("rudder-boat")
    assert eseso.create(boat) is None
    data = msgspec.to_builtins(boat)
    data["pipelines"]["eseso"] = {"enabled": True}
    assert eseso.create(config.from_dict(data)) is not None
    data["pipelines"]["eseso"] = {"enabled": True, "mass_kgg": 3}
    with pytest.raises(config.ConfigError, match="pipelines.eseso"):
        eseso.create(config.from_dict(data))


def test_thrust_model_jacobian_matches_finite_differences() -> None:
    f = _filter_in_motion()
    f_m = np.array([0.4, -0.3, -9.7])
    w_m = np.array([0.05, -0.1, 0.6])
    h0, H = f.h_tau(f_m, w_m)
    num = np.zeros_like(H)
    eps = 1e-6
    for i in range(N_ERR):
        g = copy.deepcopy(f)
        dx = np.zeros(N_ERR)
        dx[i] = eps
        g.inject(dx)
        num[:, i] = (g.h_tau(f_m, w_m)[0] - h0) / eps
    assert np.allclose(H, num, atol=2e-4 * max(1.0, np.abs(num).max()))


def test_propagation_jacobian_matches_finite_differences() -> None:
    f = _filter_in_motion()
    f_m = np.array([0.4, -0.3, -9.7])
    w_m = np.array([0.05, -0.1, 0.6])
    dt = 0.02
    nom = copy.deepcopy(f)
    nom.propagate(f_m, w_m, dt)
    eps = 1e-6
    n = N_ERR
    num = np.zeros((n, n))
    for i in range(n):
        g = copy.deepcopy(f)
        dx = np.zeros(n)
        dx[i] = eps
        g.inject(dx)
        g.propagate(f_m, w_m, dt)
        num[:, i] = _error(nom, g) / eps
    assert np.allclose(nom.F, num, atol=1e-5)


def _hover_samples(xi_true: np.ndarray, duration: float, seed: int = 0) -> list:
    """A level BlueROV2 holding station at 20 m against a constant push ``xi_true`` (N,
    body): thrust = -xi - (W - B) e3 (2 N down against the net buoyancy),
    IMU/attitude/depth/DVL with noise."""
    rng = np.random.default_rng(seed)
    cfg = eseso.EsesoConfig()
    K = np.asarray(cfg.thrusters.allocation)
    net_weight_n = cfg.vehicle.weight_n - cfg.vehicle.buoyancy_n
    tau = -xi_true - net_weight_n * np.array([0.0, 0.0, 1.0])
    forces = np.linalg.pinv(K) @ tau
    cmds = tuple(float(math.copysign(math.sqrt(abs(x) / (40.0 if x >= 0 else 30.0)), x))
                 for x in forces)
    out: list = []
    for k in range(int(duration * 50)):
        t = k / 50.0
        out.append(Imu(t=t, accel_x=rng.normal(0, 0.05), accel_y=rng.normal(0, 0.05),
                       accel_z=-9.81 + rng.normal(0, 0.05), gyro_x=rng.normal(0, 0.005),
                       gyro_y=rng.normal(0, 0.005), gyro_z=rng.normal(0, 0.005)))
        if k % 5 == 0:
            out.append(Attitude(t=t, roll_rad=rng.normal(0, 0.005), pitch_rad=rng.normal(0, 0.005),
                                yaw_rad=0.3 + rng.normal(0, 0.01)))
            out.append(Depth(t=t, depth_m=20.0 + rng.normal(0, 0.02)))
            out.append(ActuatorCommand(t=t, thrusters=cmds))
        if k % 10 == 0:
            out.append(DvlVelocity(t=t, vx=rng.normal(0, 0.01), vy=rng.normal(0, 0.01),
                                   vz=rng.normal(0, 0.01), fom_mps=0.01))
    return out


def _run(f: eseso.Eseso, samples: list, tick_hz: float = 20.0,
         records: list | None = None) -> dict[str, float]:
    """Step ``f`` at ``tick_hz`` through ``samples``; the innovation records taken after
    each step (as the engine does) go to ``records``; returns the last estimates."""
    out: dict[str, float] = {}
    i = 0
    t_end = samples[-1].t
    k = 0
    while i < len(samples):
        t = k / tick_hz
        batch = []
        while i < len(samples) and samples[i].t <= t:
            batch.append(samples[i])
            i += 1
        out = dict(f.step(t, batch)) or out
        taken = f.innovations()
        if records is not None:
            records.extend(taken)
        k += 1
        if t > t_end + 1:
            break
    return out


def test_a_constant_push_is_estimated_in_newtons_body_frame() -> None:
    xi_true = np.array([35.0, -25.0, 8.0])
    f = eseso.create(config.load("bluerov2"))
    est = _run(f, _hover_samples(xi_true, 6.0))
    xi = np.array([est["dist_x"], est["dist_y"], est["dist_z"]])
    # measured: |error| 0.3 N after 6 s (accelerometer noise 0.05 m/s^2 x 13 kg, averaged)
    assert np.linalg.norm(xi - xi_true) < 1.5
    # the published sigma is the lumped disturbance's covariance (XI's x row) with the
    # excess its thrust innovations show, negative here: measured 0.59 N against P's
    # 0.60 after 6 s
    pub = f.filter.published_disturbance_var()[0]
    assert est["std_dist_x"] == pytest.approx(math.sqrt(pub))
    assert est["std_dist_x"] <= math.sqrt(f.filter.P[18, 18])
    assert est["std_dist_x"] < 1.0
    # earth-frame columns are R xi
    R = euler_to_matrix(est["roll"], est["pitch"], est["yaw"])
    assert np.allclose(R @ xi, [est["dist_north"], est["dist_east"], est["dist_down"]])
    assert abs(est["down"] - 20.0) < 0.05 and abs(est["yaw"] - 0.3) < 0.02


def test_covariance_stays_symmetric_positive_definite_and_every_update_has_a_record() -> None:
    f = eseso.create(config.load("bluerov2"))
    records: list = []
    _run(f, _hover_samples(np.array([10.0, 5.0, 0.0]), 3.0, seed=1), records=records)
    assert np.allclose(f.filter.P, f.filter.P.T)
    assert np.linalg.eigvalsh(f.filter.P).min() > 0
    h = f.health().flat()
    dims = {"thrust": 3, "attitude": 3, "depth": 1, "dvl": 3}
    for ch, dof in dims.items():
        recs = [r for r in records if r.channel == ch]
        assert len(recs) == h[f"fused.{ch}"] + h.get(f"rejected.{ch}.gate", 0)
        for r in recs:
            assert r.dof == dof and len(r.z) == dof and len(r.S) == dof * dof
            assert math.isfinite(r.nis)
    assert not any(k.endswith("nis") or "innovation" in k for k in h)  # counters only
    assert h["fused.dvl"] > 10


def test_gnss_is_not_fused_when_submerged_and_bad_samples_are_counted() -> None:
    f = eseso.create(config.load("bluerov2"))
    samples = _hover_samples(np.zeros(3), 2.0)
    samples.append(GnssFix(t=2.0, lat_deg=22.3, lon_deg=114.2))
    samples.append(Imu(t=2.01, accel_x=float("nan"), accel_y=0, accel_z=-9.8, gyro_x=0,
                       gyro_y=0, gyro_z=0))
    samples.append(DvlVelocity(t=2.01, vx=0, vy=0, vz=0, valid=False))
    records: list = []
    _run(f, samples, records=records)
    h = f.health().flat()
    assert h["rejected.gnss.submerged"] == 1
    assert h["rejected.imu.nonfinite"] == 1
    assert h["rejected.dvl.invalid"] == 1
    unused = [(r.channel, r.reason) for r in records if not r.accepted]
    assert unused == [("gnss_pos", "submerged"), ("dvl", "invalid")]


def test_gnss_position_and_velocity_are_fused_at_the_surface() -> None:
    f = eseso.Eseso(msgspec.convert({"initial": {"position_std_m": 10.0}},
                                    eseso.EsesoConfig))
    rng = np.random.default_rng(5)
    samples = []
    for k in range(200):
        t = k / 50.0
        samples.append(Imu(t=t, accel_x=0, accel_y=0, accel_z=-9.81, gyro_x=0, gyro_y=0,
                           gyro_z=0))
        if k % 10 == 0:
            samples.append(Attitude(t=t, roll_rad=0, pitch_rad=0, yaw_rad=0))
            samples.append(GnssFix(t=t, lat_deg=22.3 + rng.normal(0, 3e-6), lon_deg=114.2,
                                   sog_mps=0.0, cog_rad=0.0, h_acc_m=0.3))
    est = _run(f, samples)
    # the first fused fix is the local origin; 19 fixes of 0.3 m take the position std
    # from 10 m to ~0.1 m
    assert abs(est["north"]) < 1.0 and abs(est["east"]) < 1.0  # measured 0.37, 0.0 m
    assert est["std_north"] < 0.2
    assert f.counters.get("fused.gnss_vel") > 5


def test_adaptive_state_round_trips() -> None:
    f = eseso.create(config.load("bluerov2"))
    _run(f, _hover_samples(np.array([10.0, 0.0, 0.0]), 2.0))
    st = f.get_state()
    g = eseso.create(config.load("bluerov2"))
    g.set_state(st)
    g.set_state({"b_a": ["x", 1, 2], "xi": None})  # ignored
    assert np.allclose(g.filter.b_a, f.filter.b_a) and np.allclose(g.filter.xi, f.filter.xi)


def test_reset_jacobian_keeps_attitude_covariance_consistent() -> None:
    f = _filter_in_motion()
    f.P = np.eye(N_ERR) * 0.01
    H = np.zeros((3, N_ERR))
    H[:, 6:9] = np.eye(3)
    f.update("attitude", np.array([0.05, -0.02, 0.1]), H, np.eye(3) * 1e-4)
    # after the reset the attitude block is G P G^T with G = I - [dtheta/2]x: symmetric,
    # positive, and smaller than before the update
    Pth = f.P[6:9, 6:9]
    assert np.allclose(Pth, Pth.T) and np.linalg.eigvalsh(Pth).min() > 0
    assert np.trace(Pth) < 0.03


def test_bench_step_cost_reports_per_tick_figures() -> None:
    from onboard.apps.bench import eseso_step_cost

    res = eseso_step_cost(2.0)
    assert {"per_tick_us_p50", "per_tick_us_p99", "per_imu_sample_us"} <= set(res)
    assert res["ticks"] == 40


def test_heading_alone_fixes_the_yaw_when_there_is_no_attitude_stream() -> None:
    from onboard.core.messages import Heading

    f = eseso.create(config.load("bluerov2"))
    samples = []
    for k in range(250):
        t = k / 50.0
        samples.append(Imu(t=t, accel_x=0, accel_y=0, accel_z=-9.81, gyro_x=0, gyro_y=0,
                           gyro_z=0))
        if k % 5 == 0:
            samples.append(Heading(t=t, heading_rad=1.0))
    est = _run(f, samples)
    # levelled from gravity after 1 s with the yaw unknown (std pi), then 40 headings
    assert abs(est["yaw"] - 1.0) < 0.02
    assert abs(est["roll"]) < 0.01 and abs(est["pitch"]) < 0.01
    assert f.counters.get("fused.heading") > 30


def test_ins_velocity_bias_is_a_state_and_only_the_white_noise_is_r() -> None:
    """The INS velocity over ground is v + b + n with b a Gauss-Markov bias, and b is a
    state of the filter. Hovering with a DVL and an INS biased by (0.03, -0.02) m/s, the
    filter attributes the offset to the INS bias, not to the velocity (the DVL holds it),
    and the vog NIS is about its dimension, not ~0.1 as with the GNSS velocity R."""
    from onboard.core.messages import VelocityOverGround

    f = eseso.create(config.load("bluerov2"))
    assert f.r_ins == pytest.approx(0.02 ** 2)
    rng = np.random.default_rng(7)
    samples = _hover_samples(np.zeros(3), 60.0, seed=7)
    dvl_only = _run(eseso.create(config.load("bluerov2")), list(samples))
    bias = np.array([0.03, -0.02])
    for k in range(600):
        t = k / 10.0 + 0.001
        n = rng.normal(0, 0.02, 2)
        samples.append(VelocityOverGround(t=t, v_north_mps=bias[0] + n[0],
                                          v_east_mps=bias[1] + n[1]))
    samples.sort(key=lambda s: s.t)
    records: list = []
    est = _run(f, samples, records=records)
    nis = [r.nis for r in records if r.channel == "vog"]
    assert np.allclose(f.filter.b_ins, bias, atol=0.006)
    # the velocity is where the DVL alone puts it (within its 0.007 m/s std), not pulled
    # towards the INS bias (measured: 0.6 and 1.3 mm/s apart)
    assert abs(est["vel_north"] - dvl_only["vel_north"]) < 0.004
    assert abs(est["vel_east"] - dvl_only["vel_east"]) < 0.004
    # the bias is 3 sigma of its 0.01 m/s prior: the first seconds are large
    assert 1.6 < np.mean(nis[100:]) < 2.4


def test_attitude_noise_is_roll_pitch_and_compass_yaw() -> None:
    """The AHRS yaw is the compass heading: its noise is the heading's (0.02 rad from
    [sensors.compass]); roll and pitch are [pipelines.eseso] attitude_std_rad."""
    f = eseso.create(config.load("bluerov2"))
    assert f.r_att == pytest.approx(0.005 ** 2)
    assert f.r_att_yaw == pytest.approx(0.02 ** 2)
    f.filter.initialized = True
    f.filter.P = np.zeros((N_ERR, N_ERR))
    f._on_attitude(Attitude(t=0.0, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0))
    S = np.reshape(f.innovations()[-1].S, (3, 3))
    assert np.allclose(np.diag(S), [0.005 ** 2, 0.005 ** 2, 0.02 ** 2])
