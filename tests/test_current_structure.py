"""The current pipeline's pieces on their own: the estimator classes driven without the
pipeline, the adapter reporting exactly its variant's estimate, and a state file written by
the previous layout (one 969-line CurrentPipeline) still loading.

Units: SI; angles in rad; current (north, east[, down]) in m/s.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.core.messages import Attitude, GnssFix
from onboard.core.so3 import euler_to_matrix
from onboard.estimators.current_hgo import CurrentHighGainObserver, repeated_step
from onboard.estimators.current_kf import CurrentKalmanFilter
from onboard.estimators.flow_observer import FlowObserver
from onboard.estimators.hgo import GainDesign, IncreasingGain
from onboard.estimators.model_identification import (
    GRAVITY,
    HeadingDiversity,
    ModelIdentification,
    StateVariableFilter,
    floor_along_track,
)
from onboard.estimators.noise_learning import FLOOR, WINDOW, Consistency
from onboard.estimators.vehicle_models import ModelInputs, RegressionModel
from tests.helpers.current_plants import (
    BOAT_TRUE,
    TORPEDO_TRUE,
    current_pipeline,
    simulate_torpedo,
)

IDENTIFICATION = {
    "identify": True, "model_rel_std": 0.2, "theta_std": 1.0, "theta_std_floor": 0.02,
    "net_weight_std": 0.02, "forgetting": 0.9995, "identify_max_current_std": 0.1,
    "identify_min_rate": 0.03, "identify_after_turn_s": 30.0, "identify_straight": False,
    "identify_min_speed": 0.2, "yaw_rls_p0": 1e6, "yaw_forgetting": 0.9995,
    "svf_cutoff_hz": 0.3, "heading_memory_s": 300.0, "heading_diversity": 0.85}
"""The ``[pipelines.current]`` defaults of the identification, as its arguments (the
estimator names the symbol, the configuration adds the unit: ``identify_min_rate_rps``)."""

FILTER = {"init_current_std": 1.0, "current_walk": 0.01, "accel_std": 0.02,
          "model_error_time_s": 1.0, "turn_accel_gain": 1.0, "prior_accel_std": 0.3,
          "gate_nis": 30.0, "calibrate": True, "calibrate_block": 50}
"""The ``[pipelines.current]`` defaults of the joint Kalman filter, as its arguments
(``init_current_std`` is ``initial_current_std_mps`` in the configuration)."""


def _rot2(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def boat_run(seconds: float, current=(0.3, -0.2), seed: int = 0):
    """The rudder boat of BOAT_TRUE, a rudder step every 40 s; yields every 0.1 s
    ``(inputs, R, z)``: the model inputs, the rotation and a GNSS-like velocity over ground
    (0.05 m/s noise per axis)."""
    rng = np.random.default_rng(seed)
    model = RegressionModel("surface-rudder")
    th = model.thetas_from_mapping(BOAT_TRUE)
    x = ModelInputs()
    x.n = 0.8
    nu, psi, r = np.array([1.0, 0.0]), 0.0, 0.0
    c = np.array(current)
    for k in range(round(seconds / 0.1)):
        x.dr = 0.3 if (k // 400) % 2 else -0.3
        for _ in range(10):
            x.r = r
            acc = [model.regressors(nu, x)[i] @ th[i] for i in range(3)]
            nu = nu + 0.01 * np.array(acc[:2])
            r += 0.01 * acc[2]
            psi += 0.01 * r
        R = _rot2(psi)
        yield x, R, R @ nu + c + rng.normal(0.0, 0.05, 2)


def _identification(configured=BOAT_TRUE, **kw) -> ModelIdentification:
    return ModelIdentification(RegressionModel("surface-rudder"), configured,
                               **{**IDENTIFICATION, **kw})


# --------------------------------------------------------------------------- joint filter


def test_the_current_keys_reach_the_identification_and_the_joint_filter():
    """Each ``[pipelines.current]`` key with a unit suffix reaches the estimator argument
    it sets (the estimators keep the symbol's name, the configuration adds the unit)."""
    pipe = current_pipeline(
        "rudder-boat", identify_max_current_std_mps=0.15, identify_min_rate_rps=0.05,
        identify_min_speed_mps=0.3, max_speed_through_water_mps=8.0,
        prior_accel_std_mps2=0.4, accel_std_mps2=0.03, current_walk_mps_rts=0.02,
        initial_current_std_mps=0.8)
    ident, kf = pipe.identification, pipe.kf
    assert (ident.identify_max_current_std, ident.identify_min_rate,
            ident.identify_min_speed) == (0.15, 0.05, 0.3)
    assert (kf.max_speed_through_water, kf.prior_accel_std, kf.accel_std, kf.current_walk,
            kf.init_current_std) == (8.0, 0.4, 0.03, 0.02, 0.8)
    default = current_pipeline("rudder-boat")  # negative control: the defaults differ
    assert (default.kf.accel_std, default.identification.identify_min_rate) == (0.02, 0.03)


def test_the_joint_kalman_filter_finds_the_current_without_the_pipeline():
    """Driven directly with a known model: the current is found, and the exposed
    innovation, its covariance and NIS are those of the update's own equations."""
    ident = _identification(identify=False)
    kf = CurrentKalmanFilter(ident, **FILTER)
    first = True
    for inputs, R, z in boat_run(200.0):
        if first:
            kf.start("earth", z, R)
            first = False
            continue
        kf.predict(0.1, inputs)
        x0, P0 = kf.x.copy(), kf.P.copy()
        assert kf.update("earth", z, 0.05, R) == "accepted"
        H = np.hstack([R, np.eye(2)])
        assert np.allclose(kf.y, z - H @ x0, rtol=0, atol=1e-12)
        assert np.allclose(kf.S, H @ P0 @ H.T + 0.05 ** 2 * np.eye(2), rtol=1e-12, atol=1e-15)
        assert kf.nis == pytest.approx(float(kf.y @ np.linalg.solve(kf.S, kf.y)), rel=1e-9)
    current, std, _ = kf.current_estimate()
    # measured: error (-0.0003, 0.002) m/s at one-sigma (0.059, 0.055): the boat turns all
    # the time, and the model error grows with the turn rate (turn_accel_gain)
    assert abs(current[0] - 0.3) < 0.02 and abs(current[1] + 0.2) < 0.02
    assert max(std) < 0.1
    assert kf.counters.updates == 1999 and kf.counters.rejected_gate == 0


def test_the_joint_filter_resets_on_a_runaway_and_keeps_finite_coefficients():
    ident = _identification(configured={})
    kf = CurrentKalmanFilter(ident, **FILTER)
    kf.start("earth", np.array([1.0, 0.0]), np.eye(2))
    kf.x[4] = 0.123  # a coefficient "learned"
    z = np.array([400.0, -300.0])
    x0 = kf.x.copy()
    # in its first updates the filter reports the contradiction and changes nothing; its
    # owner starts it again from the measurement, and the state then runs away
    assert kf.update("earth", z, 0.05, np.eye(2)) == "contradicts_start"
    assert np.array_equal(kf.x, x0) and kf.counters.restarted == 0
    assert kf.restart_from("earth", z, 0.05, np.eye(2)) == "reset"
    assert kf.counters.restarted == 1
    assert kf.counters.diverged == 1 and not kf.started
    assert np.all(kf.x[:4] == 0.0) and kf.x[4] == 0.123
    assert ident.thetas[0][0] == 0.123  # the identification sees the state's coefficients


def test_the_surface_surge_rows_carry_the_speed_lost_in_turns():
    x = ModelInputs()
    x.r, x.dr, x.n, x.left, x.right = -0.5, 0.3, 0.8, 0.6, 0.2
    rudder = RegressionModel("surface-rudder")
    twin = RegressionModel("surface-twin")
    # rudder drag X_dd u^2 delta^2 where the rudder angle is known; hull drag in a turn
    # u|r| on the skid-steered boat, which has no rudder angle
    assert rudder.terms["surge"][-1] == "u|u|dr^2"
    assert rudder.regressor_rows([1.5, 0.1], x)[0][-1] == pytest.approx(1.5 * 1.5 * 0.09)
    assert twin.terms["surge"][-2:] == ("tau_astern", "u|r|")
    assert twin.regressor_rows([1.5, 0.1], x)[0][-1] == pytest.approx(0.75)
    # and the astern part of the thrust, which a turn on the spot uses (weaker than ahead)
    x.left, x.right = 0.6, -0.5
    assert twin.regressor_rows([0.0, 0.0], x)[0][3:5] == pytest.approx((0.36 - 0.25, -0.25))
    # their coefficients are drags, never positive, as the quadratic dampings'
    assert [rudder.terms[c][j] for c, d in zip(rudder.dofs, rudder.drag_terms) for j in d] \
        == ["u|u|", "u|u|dr^2", "v|v|"]


def test_an_anti_damping_estimate_is_projected_onto_a_drag():
    """A positive quadratic damping estimate (a sway v|v| of +3.3 made the BlueBoat log's
    through-water speed run away to 1e9 m/s) is projected onto 0 after the update; the
    correlated coefficient moves with it (weighted by the covariance)."""
    ident = _identification(configured={})
    kf = CurrentKalmanFilter(ident, **FILTER)
    kf.start("earth", np.array([1.0, 0.0]), np.eye(2))
    ident.identifying = True
    o = 4  # surge coefficients u|u|, u, vr, tau_u, u|u|dr^2 follow nu_r and V_c
    kf.x[o] = 0.5
    kf.P[o, o + 1] = kf.P[o + 1, o] = 0.5  # u|u| and u correlated (rho 0.5)
    x_u = kf.x[o + 1]
    assert kf.update("earth", np.array([1.0, 0.0]), 0.05, np.eye(2)) == "accepted"
    assert kf.x[o] == 0.0 and ident.thetas[0][0] == 0.0
    assert kf.x[o + 1] < x_u - 0.2  # the linear damping takes its share of the change


def test_a_through_water_speed_beyond_physics_is_flagged_not_published():
    ident = _identification(configured={"sway": {"v|v|": 50.0}}, identify=False)
    kf = CurrentKalmanFilter(ident, **FILTER, max_speed_through_water=10.0)
    kf.start("earth", np.array([1.0, 2.0]), np.eye(2))
    inputs = ModelInputs()
    for _ in range(5):
        kf.predict(0.1, inputs)
    assert kf.runaway and kf.counters.runaway == 1  # one episode, counted once
    kf.x[:2] = [1.0, 0.0]
    kf.predict(0.1, inputs)
    assert not kf.runaway
    pipe = current_pipeline("rudder-boat")
    pipe.step(0.9, [Attitude(t=0.9, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0),
                    GnssFix(t=0.9, lat_deg=0.0, lon_deg=0.0, sog_mps=1.2, cog_rad=0.1)])
    pipe.kf.runaway = True
    out = pipe._outputs()
    assert "north" not in out and "east" not in out and "std_north" in out


# --------------------------------------------------------------------------- high-gain observer


def test_the_high_gain_observer_finds_the_current_without_the_pipeline():
    ident = _identification(identify=False)
    model = ident.model
    hgo = CurrentHighGainObserver(model, GainDesign.analytic(), IncreasingGain(0.3, 0.0, 0.3),
                                  np.diag([1.0, 1.0, 1.0, 1.0]), accel_std=0.02,
                                  model_error_time_s=1.0, current_walk=0.01)
    first = True
    for inputs, R, z in boat_run(200.0):
        if first:
            hgo.x[:2] = R.T @ z
            first = False
            continue
        hgo.predict(0.1, inputs, ident.thetas)
        x0, P0 = hgo.x.copy(), hgo.covariance().copy()
        assert hgo.update("earth", z, 0.05, 0.1, R, inputs)
        H = np.hstack([R, np.eye(2)])
        assert np.allclose(hgo.y, z - H @ x0, rtol=0, atol=1e-12)
        assert np.allclose(hgo.S, H @ P0 @ H.T + 0.05 ** 2 * np.eye(2), rtol=1e-12, atol=1e-15)
        assert hgo.nis == pytest.approx(float(hgo.y @ np.linalg.solve(hgo.S, hgo.y)), rel=1e-9)
    current, std, _ = hgo.current_estimate()
    assert hgo.gamma == 0.3
    # measured: error (-0.003, -0.007) m/s at one-sigma (0.032, 0.016)
    assert abs(current[0] - 0.3) < 0.03 and abs(current[1] + 0.2) < 0.03
    assert max(std) < 0.1


def test_the_high_gain_observers_model_uncertainty_widens_its_sigma_not_its_estimate():
    """The coefficients' covariance is a consider parameter (Schmidt): it reaches the
    published one-sigma through the regressors and leaves the estimate (the LMI gain's)
    exactly as it was."""
    ident = _identification(identify=False)
    model = ident.model
    nt = sum(len(t) for t in ident.thetas[:2])

    def observer(theta_cov):
        hgo = CurrentHighGainObserver(model, GainDesign.analytic(), IncreasingGain(0.3, 0.0, 0.3),
                                      np.diag([1.0, 1.0, 1.0, 1.0]), accel_std=0.02,
                                      model_error_time_s=1.0, current_walk=0.01)
        if theta_cov is not None:
            hgo.consider(theta_cov)
        return hgo

    plain, known, uncertain = (observer(None), observer(np.zeros((nt, nt))),
                               observer(np.diag((0.2 * np.concatenate(ident.thetas[:2])) ** 2)))
    for i, (inputs, R, z) in enumerate(boat_run(100.0)):
        for hgo in (plain, known, uncertain):
            if i == 0:
                hgo.x[:2] = R.T @ z
                continue
            hgo.predict(0.1, inputs, ident.thetas)
            hgo.update("earth", z, 0.05, 0.1, R, inputs)
    assert np.array_equal(plain.x, uncertain.x)
    assert np.allclose(plain.P, known.P, rtol=1e-9, atol=1e-15)
    std_plain, std_uncertain = plain.current_estimate()[1], uncertain.current_estimate()[1]
    # measured (100 s): one-sigma (0.020, 0.031) m/s without, (0.101, 0.175) with 20 % on
    # every coefficient, for an error of (-0.008, -0.000)
    assert all(b > 2.0 * a for a, b in zip(std_plain, std_uncertain))


def test_repeated_step_is_the_sub_steps_one_by_one():
    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 7, 1001):
        F = np.eye(6) + 0.01 * rng.normal(size=(6, 6))
        U, q = rng.normal(size=(6, 4)), rng.random(6)
        Phi, Gam, Q = np.eye(6), np.zeros((6, 4)), np.zeros((6, 6))
        for _ in range(n):
            Phi, Gam, Q = F @ Phi, F @ Gam + U, F @ Q @ F.T + np.diag(q)
        for got, want in zip(repeated_step(F, U, q, n), (Phi, Gam, Q)):
            assert np.allclose(got, want, rtol=1e-12, atol=1e-12 * float(np.max(np.abs(want))))


def test_a_diverging_high_gain_correction_is_refused_and_counted():
    model = RegressionModel("surface-rudder")
    hgo = CurrentHighGainObserver(model, GainDesign.analytic(), IncreasingGain(1.0, 0.0, 1.0),
                                  np.eye(4), accel_std=0.02, model_error_time_s=1.0,
                                  current_walk=0.01)
    x0 = hgo.x.copy()
    assert not hgo.update("earth", np.array([1e6, 0.0]), 0.05, 1.0, np.eye(2), ModelInputs())
    assert hgo.diverged == 1
    assert np.array_equal(hgo.x, x0)
    assert hgo.update("water", np.array([1e6, 0.0]), 0.05, 1.0, np.eye(2), ModelInputs())


# --------------------------------------------------------------------------- flow observer


def test_the_flow_observer_current_is_over_ground_minus_through_water():
    model = RegressionModel("torpedo")
    flow = FlowObserver(model)
    R = euler_to_matrix(0.0, 0.1, 0.7)
    with pytest.raises(ValueError):
        flow.current(R)
    flow.step(0.0, 0.7, ModelInputs(), model.thetas_from_mapping(TORPEDO_TRUE),
              np.array([1.2, 0.05, 0.01]))
    # GNSS at the surface: horizontal only, the vertical from the caller's estimate
    flow.observe_velocity("earth", np.array([1.0, 0.5]), 0.1, R,
                          v_g_estimate=np.array([0.0, 0.0, 0.2]))
    assert np.allclose(R @ flow.v_g, [1.0, 0.5, 0.2], rtol=0, atol=1e-12)
    c, std, _ = flow.current(R)
    assert np.allclose(c, R @ (flow.v_g - np.array([1.2, 0.05, 0.01])), rtol=0, atol=1e-15)
    assert np.all(std >= 0.1)  # at least the measurement's own one-sigma
    flow.observe_velocity("water", np.array([1.1, 0.0, 0.0]), 0.02, R)
    assert flow.current(R)[0] is None  # through water: no current in it


def test_the_flow_observer_heading_innovation_statistics():
    model = RegressionModel("torpedo")
    th = model.thetas_from_mapping(TORPEDO_TRUE)
    flow = FlowObserver(model, psi_std=0.01)
    x = ModelInputs()
    flow.step(0.0, 0.0, x, th, np.array([1.5, 0.0, 0.0]))
    prior_var = flow.Pz[0, 0]
    flow.step(0.1, 0.05, x, th, np.array([1.5, 0.0, 0.0]))
    assert flow.e == pytest.approx(0.05)
    assert flow.S == pytest.approx(prior_var + 0.01 ** 2)
    assert flow.nis == pytest.approx(0.05 ** 2 / flow.S)


# --------------------------------------------------------------------------- identification


def test_the_coefficient_prior():
    ident = ModelIdentification(RegressionModel("torpedo"), {"sway": {"uv": -0.5}},
                                **IDENTIFICATION)
    terms = ident.model.terms
    sway = ident.prior_sd[1]
    assert sway[terms["sway"].index("uv")] == pytest.approx(0.2 * 0.5 + 0.02)
    assert sway[terms["sway"].index("cos(theta)sin(phi)")] == pytest.approx(GRAVITY * 0.02)
    assert ident.prior_sd[2][terms["heave"].index("cos(theta)cos(phi)")] == 1.0
    assert ident.prior_dof == [True, False, True] and ident.masked == [True, False, True]
    assert ident.n_theta == sum(len(terms[c]) for c in ("surge", "sway", "heave"))
    assert ident.tr_theta_max == pytest.approx(sum(ident.theta_var0))
    assert ident.yaw_rls is not None and ident.svf is not None
    fixed = ModelIdentification(RegressionModel("rov"), {}, **{**IDENTIFICATION,
                                                               "identify": False})
    assert fixed.n_theta == 0 and fixed.theta_var0 == [] and fixed.yaw_rls is None


def test_forgetting_stops_at_the_prior_trace():
    ident = _identification(configured={})
    assert ident.forgetting_factor(0.0, 0.1) == pytest.approx(0.9995)
    assert ident.forgetting_factor(0.0, 0.2) == pytest.approx(0.9995 ** 2)
    assert ident.forgetting_factor(ident.tr_theta_max, 0.1) == 1.0
    assert ident.forgetting_factor(2 * ident.tr_theta_max, 0.1) == 1.0


def test_the_identification_schedule():
    ident = _identification(configured={})
    assert not ident.should_identify(10.0, False, 1e-4, 1e-4)  # filter not started
    assert not ident.should_identify(10.0, True, 0.2 ** 2, 1e-4)  # current still unknown
    assert not ident.should_identify(10.0, True, 1e-4, 1e-4)  # no turn yet
    ident.observe_motion(10.0, 0.1, 0.1, 0.0)
    assert ident.last_turn_t == 10.0
    assert ident.should_identify(30.0, True, 1e-4, 1e-4)
    assert not ident.should_identify(41.0, True, 1e-4, 1e-4)  # 31 s after the turn
    straight = _identification(configured={}, identify_straight=True)
    assert straight.should_identify(41.0, True, 1e-4, 1e-4)


def test_a_prior_mask_lifts_once_its_dof_is_learned():
    ident = _identification(configured={})
    assert ident.masked == [True, True]
    var = np.array(ident.theta_var0)
    n_surge = ident.sizes[0]
    var[:n_surge] *= 0.2  # surge learned, sway not
    ident.lift_masks(var)
    assert ident.masked == [False, True]


def test_heading_diversity_and_the_along_track_floor():
    h = HeadingDiversity(memory_s=100.0)
    h.restart(0.3)
    for _ in range(50):
        h.update(10.0, 0.3 + math.pi)  # reversing course: the same lateral axis
    assert h.length() == pytest.approx(1.0, abs=1e-12)
    for _ in range(200):
        h.update(1.0, 0.0)
        h.update(1.0, math.pi / 2)  # two headings 90 deg apart: no common axis
    assert h.length() < 0.02
    cov = np.diag([0.01 ** 2, 0.02 ** 2])
    std = floor_along_track(cov, 0.0, 1.0)  # heading north: the floor is on north only
    assert std == [pytest.approx(1.0), pytest.approx(0.02)]
    std = floor_along_track(cov, math.pi / 4, 1.0)  # north-east: on both, sum of variances 1
    # the variance along the heading becomes 1, the cross-track one stays
    assert std[0] ** 2 + std[1] ** 2 == pytest.approx(1.0 + 0.5 * (0.01 ** 2 + 0.02 ** 2))
    assert floor_along_track(np.diag([4.0, 0.0]), 0.0, 1.0) == [2.0, 0.0]  # already above


def test_the_state_variable_filter_differentiates_what_it_filters():
    """``d/dt (H y) = H (dy/dt)``: the derivative output of the filtered sine equals the
    filtered cosine (the sine's derivative) once the start transient has decayed, up to the
    discretization (measured: 0.5 % of the amplitude at 50 Hz, 2.4 % at 10 Hz)."""
    w0, dt = 0.5, 0.02
    a, b = StateVariableFilter(1, 0.3), StateVariableFilter(1, 0.3)
    worst = 0.0
    for k in range(3000):
        t = dt * k
        a.update(dt, [math.sin(w0 * t)])
        b.update(dt, [w0 * math.cos(w0 * t)])
        if t > 20.0:
            worst = max(worst, abs(a.dy[0] - b.y[0]))
    assert worst < 0.01 * w0


# --------------------------------------------------------------------------- the adapter


@pytest.mark.parametrize("observer", ["kf", "hgo", "flow"])
def test_the_pipeline_reports_its_variants_estimate(observer):
    """The adapter's current is the chosen estimator's, and the joint filter (which
    identifies the model) runs under every variant."""
    pipe = current_pipeline("torpedo-auv", model=TORPEDO_TRUE, identify=False,
                            observer=observer)
    nd = pipe.nd
    out = {}
    for t, samples, _ in simulate_torpedo(30.0):
        out = pipe.step(t, samples)
        if not out:
            continue
        if observer == "kf":
            expect = pipe.kf.x[nd:2 * nd]
        elif observer == "hgo":
            expect = pipe.hgo.x[nd:]
        elif pipe.flow.ready:
            expect = pipe.flow.current(pipe._R())[0]
        else:
            continue
        for ax, e in zip(("north", "east", "down"), expect):
            if ax in out:  # absent while unknown (one-sigma above unknown_above_std_mps)
                assert out[ax] == e
    assert pipe.kf.counters.updates > 100
    assert (pipe.hgo is not None) == (observer == "hgo")
    assert (pipe.flow is not None) == (observer == "flow")
    assert out["std_north"] > 0 and math.isfinite(out.get("north", 0.0))


def test_the_surface_rotation_is_the_yaw_block_of_the_zyx_rotation():
    pipe = current_pipeline("rudder-boat")
    pipe.step(1.0, [Attitude(t=1.0, roll_rad=0.1, pitch_rad=0.2, yaw_rad=2.5)])
    assert np.array_equal(pipe._R(), euler_to_matrix(0.0, 0.0, 2.5)[:2, :2])


PREVIOUS_STATE = {
    "model_kind": "surface-rudder",
    "thetas": {"surge": {"u|u|": -0.862005, "u": 0.604034, "vr": 0.0124383, "tau_u": 0.956138},
               "sway": {"v": -1.95417, "v|v|": -0.0581658, "ur": -0.231942, "r": -0.172992},
               "yaw": {"r": -1.75039, "r|r|": -0.541695, "uv": 0.00679884,
                       "u|u|dr": 0.0384299, "n|n|dr": 2.52144}},
    "current": [0.304425, -0.195719],
    "current_std": [0.0532064, 0.0417309],
    "theta_cov": [
        [0.33438, -0.37712, -0.00166035, -0.0917177, 0.00035903, 3.78528e-05, -0.00135256,
         -0.00111138],
        [-0.37712, 0.624762, 0.00176273, -0.28872, -8.73137e-05, -4.61407e-06, 0.000755373,
         0.000682851],
        [-0.00166035, 0.00176273, 1.04411, 0.00231128, 6.81688e-06, 1.90503e-06,
         -0.000485322, -0.000391485],
        [-0.0917177, -0.28872, 0.00231128, 0.802876, -0.000241471, -2.07306e-05, 0.00128286,
         0.00111537],
        [0.00035903, -8.73137e-05, 6.81688e-06, -0.000241471, 0.739595, -0.0209441,
         0.0761171, 0.0592239],
        [3.78528e-05, -4.61407e-06, 1.90503e-06, -2.07306e-05, -0.0209441, 1.05682,
         0.00774378, 0.00609298],
        [-0.00135256, 0.000755373, -0.000485322, 0.00128286, 0.0761171, 0.00774378, 0.507964,
         -0.437987],
        [-0.00111138, 0.000682851, -0.000391485, 0.00111537, 0.0592239, 0.00609298,
         -0.437987, 0.70994]],
    "yaw_rls": {"names": ["r", "r|r|", "uv", "u|u|dr", "n|n|dr"],
                "theta": [-1.75039, -0.541695, 0.00679884, 0.0384299, 2.52144],
                "P": [[4.70596, -7.68774, 0.539213, -1.24736, 0.561235],
                      [-7.68774, 33.8726, -0.388866, 2.01744, -9.34113],
                      [0.539213, -0.388866, 2.01777, 0.353343, -0.759353],
                      [-1.24736, 2.01744, 0.353343, 6.48609, -14.2171],
                      [0.561235, -9.34113, -0.759353, -14.2171, 37.3118]],
                "sigma2": 0.000478548, "n_updates": 1498},
}
"""A rudder boat's saved state as the previous layout wrote it (after 150 s of the
synthetic boat; numbers rounded to 6 digits)."""


def test_a_state_saved_by_the_previous_layout_loads():
    pipe = current_pipeline("rudder-boat")
    pipe.set_state(PREVIOUS_STATE)
    st = pipe.get_state()
    # the surge's rudder-drag term came later: it starts at 0 with its prior variance (1),
    # the saved terms keep their values and covariance
    assert st["thetas"]["surge"].pop("u|u|dr^2") == 0.0
    assert st["thetas"] == PREVIOUS_STATE["thetas"]
    old = [0, 1, 2, 3, 5, 6, 7, 8]  # the saved terms' places among the 9 of now
    assert np.array(st["theta_cov"])[np.ix_(old, old)].tolist() == PREVIOUS_STATE["theta_cov"]
    assert st["theta_cov"][4][4] == 1.0 and sum(map(abs, st["theta_cov"][4])) == 1.0
    assert st["current"] == PREVIOUS_STATE["current"]
    assert st["current_std"] == [0.2, 0.2]  # inflated: it may have changed meanwhile
    assert st["yaw_rls"]["theta"] == PREVIOUS_STATE["yaw_rls"]["theta"]
    assert np.allclose(st["yaw_rls"]["P"], PREVIOUS_STATE["yaw_rls"]["P"], rtol=1e-12)
    assert st["yaw_rls"]["n_updates"] == 1498
    assert pipe.thetas[2].tolist() == PREVIOUS_STATE["yaw_rls"]["theta"]
    # the coefficients in the state are the restored ones, uncorrelated with the rest
    assert pipe.kf.x[4:].tolist() == [
        *PREVIOUS_STATE["thetas"]["surge"].values(), 0.0,
        *PREVIOUS_STATE["thetas"]["sway"].values()]
    assert np.all(pipe.kf.P[:4, 4:] == 0.0)
    # and the filter runs on from there
    out = pipe.step(1.0, [Attitude(t=0.9, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0),
                          GnssFix(t=1.0, lat_deg=0.0, lon_deg=0.0, sog_mps=1.2, cog_rad=0.1)])
    assert all(math.isfinite(v) for v in out.values())


def test_a_state_that_does_not_fit_is_ignored():
    pipe = current_pipeline("rudder-boat")
    before = pipe.get_state()
    pipe.set_state({**PREVIOUS_STATE, "model_kind": "torpedo"})
    assert pipe.get_state() == before
    bad = {**PREVIOUS_STATE, "thetas": {"surge": {"u": float("nan")}}}
    pipe.set_state(bad)
    assert pipe.get_state() == before
    # a covariance of the wrong shape: the coefficients are taken, their prior kept
    pipe.set_state({**PREVIOUS_STATE, "theta_cov": [[1.0]]})
    st = pipe.get_state()
    assert st["thetas"]["surge"].pop("u|u|dr^2") == 0.0  # not in the saved state
    assert st["thetas"] == PREVIOUS_STATE["thetas"]
    assert st["theta_cov"] == before["theta_cov"]


def test_the_hgo_rls_identifies_the_velocity_dofs_from_the_observer_velocity():
    """VelocityRls (the high-gain observer's own identification, Kim et al. §II.B) on the
    exact through-water velocity of the synthetic boat model, from the generic prior (mode
    (b)): the identified surge and sway models predict the acceleration far better than the
    prior. The damping projection undoes some updates on the way (the generic surge prior
    starts at zero damping, and the first data often pull it positive) without keeping
    the identification from converging."""
    from onboard.estimators.model_identification import VelocityRls
    from onboard.pipelines.current import CurrentConfig, _identification
    from tests.helpers.current_plants import BOAT_TRUE
    model = RegressionModel("surface-rudder")
    ident = _identification(CurrentConfig(), model)
    rls = VelocityRls(ident, noise_std=0.02, forgetting=1.0, svf_cutoff_hz=0.3)
    true = model.thetas_from_mapping(BOAT_TRUE)
    prior = [t.copy() for t in rls.thetas]
    x = ModelInputs()
    nu = np.array([0.5, 0.0])
    h, tick = 0.02, 0.1
    errs_prior, errs_rls = [], []
    for k in range(1500):  # 150 s, throttle and rudder varied
        t = k * tick
        x.n = 0.6 + 0.3 * math.sin(0.05 * t)
        x.dr = 0.3 * math.sin(0.21 * t)
        for _ in range(int(tick / h)):
            phis = model.regressors(nu, x)
            acc = np.array([phis[i] @ true[i] for i in range(3)])
            nu = nu + h * acc[:2]
            x.r = x.r + h * acc[2]
        rls.step(tick, nu.tolist(), x, learn=True)
        if t > 100.0:
            phis = model.regressors(nu, x)
            errs_prior.append([phis[i] @ (prior[i] - true[i]) for i in range(2)])
            errs_rls.append([phis[i] @ (rls.thetas[i] - true[i]) for i in range(2)])
    rms_prior = np.sqrt(np.mean(np.square(errs_prior), axis=0))
    rms_rls = np.sqrt(np.mean(np.square(errs_rls), axis=0))
    # measured: acceleration error rms surge / sway over the last 50 s, prior 0.021 /
    # 0.035 m/s^2, identified 0.0015 / 0.00008
    assert np.all(rms_rls < 0.2 * rms_prior)
    # measured: 344 of 1500 surge/sway updates undone
    assert rls.n_updates == 1500 and rls.n_rejected < 750
    assert rls.masked == [False, False]  # learned: the along-track floor is lifted


def test_the_hgo_rls_keeps_a_damped_model():
    """An update that would make a DOF's own damping non-negative is undone (projection)."""
    from onboard.estimators.model_identification import VelocityRls
    from onboard.pipelines.current import CurrentConfig, _identification
    model = RegressionModel("surface-rudder")
    rls = VelocityRls(_identification(CurrentConfig(), model), noise_std=1e-3,
                      forgetting=1.0, svf_cutoff_hz=0.3)
    x = ModelInputs()
    before = [t.copy() for t in rls.thetas]
    # a sway velocity growing with itself: the data say "undamped"; the prior's
    # sway damping must survive
    for k in range(50):
        rls.step(0.1, [1.0, 0.05 * 1.2 ** k], x, learn=True)
    _, _, J = model.linearize([1.0, 0.5], x, [t.tolist() for t in rls.thetas])
    assert J[1][1] < 0.0
    assert rls.n_rejected > 0
    assert np.all(np.isfinite(np.concatenate(rls.thetas)))
    assert not np.array_equal(before[0], rls.thetas[0]) or rls.n_rejected >= 50


def test_the_published_factor_weighs_every_direction_of_s_alike():
    """The current's published factor (algorithms.md §9.1) is read from the velocity rows'
    innovations whitened by their ``S``. A current known loosely along the track and well
    across it: ``S = diag(1, 0.01)``, the forecast timid along (true factor 0.2) and right
    across (1). By the trace, ``z^T z / tr S`` is the wide direction's and the factor 0.21
    would narrow the well-known component five times below its errors; whitened, every
    direction weighs alike (the NIS per dimension 0.60, the factor 0.58)."""
    kf = CurrentKalmanFilter(_identification(identify=False), **FILTER)
    r_var = 0.001
    S = np.diag([1.0, 0.01])
    forecast = S - r_var * np.eye(2)
    truth = r_var * np.eye(2) + np.diag([0.2, 1.0]) @ forecast   # what the innovations are
    rng = np.random.default_rng(3)
    by_trace = Consistency()
    for _ in range(WINDOW):
        y = rng.multivariate_normal(np.zeros(2), truth)
        kf._observe_whitened(y, S, r_var)
        by_trace.observe(y, float(np.trace(S)), 2 * r_var)
    expected = 1.0 - (1.0 - 0.5 * (0.2008 + 1.0)) / (0.5 * (0.999 + 0.9))
    assert kf.earth_whitened.forecast_factor(FLOOR) == pytest.approx(expected, abs=0.08)
    assert by_trace.forecast_factor(FLOOR) == pytest.approx(0.21, abs=0.05)   # the control
    ratio = kf.earth_whitened.ratio
    kf._observe_whitened(np.ones(2), np.diag([1.0, -1e-12]), r_var)   # not positive definite
    assert kf.earth_whitened.ratio == ratio                             # no sample, no error
