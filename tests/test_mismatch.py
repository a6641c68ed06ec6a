"""Model mismatch (sitl.mismatch, validation.reports.mismatch): the plant perturbed from
outside, the estimators and controllers on the nominal model.

Default suite: the perturbations do what they say on each plant, and one short run per
estimator and controller under a mismatch case with a stated bound. The whole campaign
(docs/mismatch.md) is ``slow``; its tests assert the claims the docs make from it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from onboard.sitl import mismatch as mm
from onboard.sitl.environment import Environment
from onboard.sitl.plants.base import Command
from onboard.sitl.plants.bluerov2 import BlueROV2, BlueROV2Params
from onboard.sitl.plants.rudder_boat import RudderBoat, RudderBoatParams
from onboard.sitl.plants.torpedo_auv import TorpedoAUV
from onboard.sitl.sensors import DvlConfig, ImuConfig


# --------------------------------------------------------------------------- perturbations


def test_cases_are_named_and_nominal_changes_nothing() -> None:
    assert list(mm.CASES)[0] == "nominal" and mm.get("nominal").is_nominal
    assert {"mass+20", "mass-20", "damping+30", "damping-30", "thrust-15", "lag0.15",
            "noise2x", "worst"} <= set(mm.CASES)
    plant = BlueROV2()
    assert mm.perturb_plant(plant, "nominal") is plant
    assert mm.perturb_plant(plant, "noise2x") is plant  # noise is the sensors'
    with pytest.raises(mm.MismatchError, match="unknown mismatch case"):
        mm.get("mass+50")


def test_bluerov2_mass_and_damping_are_scaled_in_a_copy() -> None:
    q = BlueROV2Params()
    p = mm.perturb_params(q, "mass+20")
    assert p.m == pytest.approx(1.2 * q.m)
    assert np.allclose(p.added_mass, 1.2 * np.asarray(q.added_mass))
    assert np.allclose(p.mass_matrix[0, 0], 1.2 * q.mass_matrix[0, 0])
    assert (p.weight, p.buoyancy, p.d_lin) == (q.weight, q.buoyancy, q.d_lin)
    d = mm.perturb_params(q, "damping-30")
    assert np.allclose(d.d_lin, 0.7 * np.asarray(q.d_lin))
    assert np.allclose(d.d_quad, 0.7 * np.asarray(q.d_quad))
    assert BlueROV2Params() == q  # the nominal parameters are untouched


def _surge_force(plant: BlueROV2, cmd: tuple[float, ...], seconds: float = 0.0) -> float:
    env = Environment()
    plant.reset(down=20.0)
    for k in range(int(round(seconds / 0.01))):
        plant.step(0.01, Command(thrusters=cmd), env, k * 0.01)
    if seconds == 0.0:
        plant.step(0.01, Command(thrusters=cmd), env, 0.0)
    return plant.truth(seconds, env).force_x


def test_bluerov2_thrust_and_lag_act_on_the_command() -> None:
    cmd = (0.6, 0.6, -0.6, -0.6, 0.0, 0.0)  # pure surge
    nominal = _surge_force(BlueROV2(), cmd)
    assert nominal > 30.0
    weak = _surge_force(mm.perturb_plant(BlueROV2(), "thrust-15"), cmd)
    assert weak == pytest.approx(0.85 * nominal, rel=1e-6)
    # first-order lag, 0.15 s: after one time constant 1 - 1/e of a step (the lag state
    # starts at the first command, so step from zero first)
    lagged = mm.perturb_plant(BlueROV2(), "lag0.15")
    env = Environment()
    lagged.reset(down=20.0)
    lagged.step(0.01, Command(thrusters=(0.0,) * 6), env, 0.0)
    for k in range(15):
        lagged.step(0.01, Command(thrusters=cmd), env, 0.01 * (k + 1))
    # thrust ~ command^2: the lagged command is (1 - 1/e) of the step
    frac = math.sqrt(lagged.truth(0.16, env).force_x / nominal)
    assert frac == pytest.approx(1.0 - math.exp(-1.0), abs=0.01)


def test_torpedo_mass_drag_and_thrust() -> None:
    nom = TorpedoAUV()
    p = mm.perturb_plant(TorpedoAUV(), "worst")
    assert p.params.m == pytest.approx(1.2 * nom.params.m)
    assert p.params.weight == nom.params.weight  # trim unchanged
    assert p.params.x_udot == pytest.approx(1.2 * nom.params.x_udot)
    assert p.params.x_uu == pytest.approx(0.7 * nom.params.x_uu)
    assert p.params.k_t == pytest.approx(0.85 * nom.params.k_t)
    assert p._mass[0, 0] == pytest.approx(1.2 * nom._mass[0, 0])
    assert p._mm_lag_s == 0.15


def test_rudder_boat_parameters_and_a_missing_parameter_is_an_error() -> None:
    q = RudderBoatParams()
    p = mm.perturb_params(q, "worst")
    assert (p.m, p.i_z, p.t_max) == pytest.approx((1.2 * q.m, 1.2 * q.i_z, 0.85 * q.t_max))
    assert (p.d_u, p.n_rr) == pytest.approx((0.7 * q.d_u, 0.7 * q.n_rr))
    assert p.y_d == q.y_d and p.x_r == q.x_r  # the rudder's force is not damping
    plant = mm.perturb_plant(RudderBoat(), "thrust-15")
    assert isinstance(plant, RudderBoat) and plant.params.t_max == pytest.approx(0.85 * 12.5)
    with pytest.raises(mm.MismatchError, match="no mismatch table"):
        mm.perturb_params(DvlConfig(), "mass+20")


def test_sensor_noise_doubles_but_biases_stay() -> None:
    imu = mm.scale_noise(ImuConfig(), 2.0)
    base = ImuConfig()
    assert imu.accel_noise_std == 2 * base.accel_noise_std
    assert imu.gyro_noise_std == 2 * base.gyro_noise_std
    assert (imu.accel_bias_std, imu.gyro_bias_walk) == (base.accel_bias_std,
                                                         base.gyro_bias_walk)


def test_perturbed_scenario_runs_with_the_perturbed_plant() -> None:
    from onboard.sitl import scenarios
    from onboard.sitl.runner import Simulation

    sc = mm.perturb_scenario("jaiabot-turns", "worst")
    assert sc.name == "jaiabot-turns+worst"
    base = scenarios.get("jaiabot-turns")
    assert sc.sensors.gnss.position_std_m == 2 * base.sensors.gnss.position_std_m
    sim = Simulation(sc, seed=1)
    assert sim.plant.params.m == pytest.approx(1.2 * RudderBoatParams().m)
    n = sum(len(s) for _, s, _ in sim.steps(5.0))
    assert n > 100
    assert dataclasses.replace(base) == base  # the registered scenario is untouched


# --------------------------------------------------------------------------- estimators


def test_boat_aie_and_kf_under_the_worst_case() -> None:
    """jaiabot-turns, 90 s (errors after 30 s), seed 1, plant ``worst`` (mass +20 %,
    damping -30 %, thrust -15 %, lag 0.15 s, noise x2) against the nominal config.
    Measured: speed RMSE AIE 0.101, KF 0.097 m/s (0.174 and 0.164 with the declared noise
    kept: the sensors' doubled noise, learned from the innovations and applied, algorithms.md
    §9). The learned noise says what the config got wrong: the Doppler speed's and the
    heading's one-sigma 1.93x the nominal run's (true 2x); the position increment's 1.37x
    (its innovations carry the GNSS drift, which the run's doubling leaves as it was)."""
    from validation.reports.mismatch import boat_run

    r = boat_run("worst", seed=1, duration=90.0)
    assert r["speed_rmse_mps"]["aie"] < 0.13
    assert r["speed_rmse_mps"]["kf"] < 0.13
    assert r["speed_rmse_mps"]["aie"] < 1.10 * r["speed_rmse_mps"]["kf"]
    nominal = boat_run("nominal", seed=1, duration=90.0)
    for p in ("aie", "kf"):
        for channel in ("surge.rate", "heading.increment"):
            ratio = r["noise_std"][p][channel] / nominal["noise_std"][p][channel]
            assert 1.6 < ratio < 2.5, (p, channel, ratio)


# --------------------------------------------------------------------------- controllers

casadi = pytest.importorskip("casadi", reason="the MPCs need the 'mpc' extra (casadi)")


def test_ampc_and_offset_free_nmpc_hold_the_circle_under_the_worst_case() -> None:
    """The circle under the push, 20 s (metrics after 10 s), seed 1, plant ``worst`` (mass
    +20 %, damping -30 %, thrust -15 %, lag 0.15 s, noise x2), the ESESO and the MPCs on
    the nominal model. Measured: AMPC 0.059 m, offset-free NMPC 0.061 m; the plain NMPC
    with no mismatch at all does 0.14-0.17 m (tests/test_closed_loop.py, docs/mismatch.md).
    Bound 0.1 m each. The ESESO's disturbance error against the push is 12.5 N: its xi is
    the lumped force (push + model error), not the push (docs/mismatch.md)."""
    from onboard.sitl.closed_loop import simulate

    for c in ("ampc", "nmpc-of"):
        rep = simulate(c, duration=20.0, seed=1, mismatch="worst")[0]
        assert rep["mismatch"] == "worst"
        assert rep["tracking_rmse_m"] < 0.1, (c, rep["tracking_rmse_m"])


# --------------------------------------------------------------------------- the campaign

CAMPAIGN_SEEDS = (1, 2, 3)
"""The seeds of docs/mismatch.md's table (durations: circle 30 s, gavia-tidal and
jaiabot-turns 200 s)."""


@pytest.fixture(scope="module")
def campaign_rov() -> dict:
    from validation.reports.mismatch import run_campaign

    return run_campaign(list(mm.CASES), CAMPAIGN_SEEDS, 30.0, 200.0, 200.0, ("rov",))["rov"]


@pytest.mark.slow
def test_campaign_circle_claims(campaign_rov) -> None:
    """docs/mismatch.md, "What holds": in every case and seed both disturbance-carrying MPCs
    track below 0.6 times the plain NMPC's error (measured at most 0.46, worst case seed 3)
    and below the PID's; the AMPC beats the offset-free NMPC in the seed counts the docs
    give, and loses on every seed under a thruster lag."""
    for case, per in campaign_rov.items():
        for i, seed in enumerate(CAMPAIGN_SEEDS):
            tr = {c: per[c][i]["tracking_rmse_m"] for c in per}
            for c in ("ampc", "nmpc-of"):
                assert tr[c] < 0.6 * tr["nmpc"], (case, seed, tr)
                assert tr[c] < tr["pid"], (case, seed, tr)
    from validation.reports.mismatch import ampc_against_offset_free

    score = {case: ampc_against_offset_free(per) for case, per in campaign_rov.items()}
    # measured (seeds better / worse by > 2 %, 2026-11-29): nominal 3/0, mass+20 2/0,
    # mass-20 1/0, damping+30 0/0, damping-30 3/0, thrust-15 0/0, lag0.15 0/3, noise2x 0/2,
    # worst 2/0: better in 11 of 27 case-seeds, worse in 5
    assert score["nominal"] == (3, 0), score
    assert score["lag0.15"][1] == 3, score
    assert sum(b for b, _ in score.values()) >= 11, score
    assert sum(w for _, w in score.values()) <= 5, score


@pytest.mark.slow
def test_campaign_estimator_claims() -> None:
    """docs/mismatch.md: the current KF's model (a) error grows tenfold with a damping
    mismatch, sevenfold with the thrust curve 15 % off, and stays within 0.03 m/s under
    mass, lag and noise. On the rudder boat (both filters tuned by one protocol, both
    learning their noise) the KF is ahead of the AIE on speed in every case and seed
    (measured: the AIE 1.15-1.33x the KF; 1.01-1.04x with damping -30 %; 1.02-1.14x with
    doubled noise), and the AIE ahead on heading wherever the noise is as declared
    (0.025-0.028 against 0.028-0.029 rad); with doubled noise they tie on heading (within
    3 %)."""
    from validation.reports.mismatch import run_campaign

    res = run_campaign(list(mm.CASES), CAMPAIGN_SEEDS, 30.0, 200.0, 200.0, ("gavia", "boat"))
    for case, runs in res["gavia"].items():
        rms = float(np.mean([r["current_rms_mps"] for r in runs]))
        if case.startswith(("damping", "thrust")) or case == "worst":
            assert rms > 0.1, (case, rms)
        else:
            assert rms < 0.03, (case, rms)
    for case, runs in res["boat"].items():
        for r in runs:
            sp, hd = r["speed_rmse_mps"], r["heading_rmse_rad"]
            assert sp["kf"] < sp["aie"] < 1.4 * sp["kf"], (case, r)
            if case in ("noise2x", "worst"):
                assert abs(hd["aie"] - hd["kf"]) < 0.03 * hd["kf"], (case, r)
            else:
                assert hd["aie"] < hd["kf"], (case, r)
