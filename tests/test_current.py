"""Current pipeline on synthetic plants (independent of SITL): error and 2-sigma coverage.

The plants (tests/helpers/current_plants.py) are the regression models of
vehicle_models.py with "true" coefficients, a current and sensor noise; they are the
pipeline's own specification test. The SITL scenarios (other plants, other models) are in
test_current_sitl.py.
"""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from onboard.core import config as configmod
from onboard.core.messages import (Attitude, Depth, DvlVelocity, GnssFix, Heading,
                                   VelocityOverGround)
from onboard.pipelines import current as current_mod
from tests.helpers.current_plants import (
    BOAT_TRUE,
    TORPEDO_TRUE,
    current_errors,
    current_pipeline,
    simulate_boat,
    simulate_torpedo,
)


def test_columns_follow_the_contract():
    boat = current_pipeline("rudder-boat")
    auv = current_pipeline("torpedo-auv")
    for c in ("north", "east", "std_north", "std_east"):
        assert c in boat.columns and c in auv.columns
    assert "down" in auv.columns and "down" not in boat.columns
    assert current_pipeline("bluerov2").nd == 3
    assert current_pipeline("twin-thruster-boat").model.kind == "surface-twin"
    assert current_pipeline("rudder-boat", enabled=False) is None


def test_boat_known_model_constant_current():
    pipe = current_pipeline("rudder-boat", model=BOAT_TRUE, identify=False)
    rms, cover, _, s = current_errors(pipe, simulate_boat(300.0), after=90.0)
    # measured: rms [0.003, 0.003] m/s, sigma ~0.01, coverage 1.0
    assert np.all(rms < 0.02)
    assert np.all(cover > 0.9)


def test_boat_no_model_identified_online():
    pipe = current_pipeline("rudder-boat")
    rms, cover, _, _ = current_errors(pipe, simulate_boat(480.0), after=240.0)
    # measured: rms [0.003, 0.003] m/s, coverage 1.0 (first turn at 60 s)
    assert np.all(rms < 0.03)
    assert np.all(cover > 0.9)
    assert pipe.identification.rls_updates > 0


def test_torpedo_known_model_bottom_track():
    pipe = current_pipeline("torpedo-auv", model=TORPEDO_TRUE, identify=False)
    rms, cover, _, _ = current_errors(pipe, simulate_torpedo(300.0), after=100.0)
    # measured: rms [0.002, 0.002] m/s
    assert np.all(rms < 0.02)
    assert np.all(cover > 0.9)


def test_torpedo_hgo_observer_with_increasing_gain():
    """The increasing-gain law (Alessandri & Rossi), configured: gamma grows from 0.05
    with the output error up to 1.29. (The bundled gain files run a fixed gamma* instead,
    test_current_sitl.py.)"""
    # the plant's own coefficients, declared as known: with the default prior (20 %, the
    # floor 0.02 on the zero terms, 2 % net weight) carried as consider parameters, this
    # low gain, which leans on the model, puts east's one-sigma at 0.58 m/s (unpublished)
    pipe = current_pipeline("torpedo-auv", model=TORPEDO_TRUE, identify=False, observer="hgo",
                            hgo={"gamma_0": 0.05, "rho": 0.01, "gamma_max": 1.29},
                            model_rel_std=0.02,
                            theta_std_floor=1e-4, net_weight_std=0.001)
    rms, cover, _, _ = current_errors(pipe, simulate_torpedo(300.0), after=100.0)
    # measured: rms [0.019, 0.035] m/s, coverage 1.0 (one-sigma 0.06 / 0.12, coverage
    # 0.99 / 0.99: timid); gamma rose from 0.05 to 1.25. The
    # higher the gain, the noisier on this synthetic run: fixed gamma 1.29 gives rms
    # [0.020, 0.038], 3.0 [0.060, 0.124]; at gamma* = 6.4 the east component's one-sigma
    # exceeds 0.3 m/s (unpublished)
    assert np.all(rms < 0.06)
    assert np.all(cover > 0.9)
    assert 0.05 < pipe.gamma <= 1.29 + 1e-9


def test_water_track_dvl_is_a_direct_through_water_measurement():
    pipe = current_pipeline("torpedo-auv", model=TORPEDO_TRUE, identify=False)
    out = {}
    vx = None
    for t, samples, c in simulate_torpedo(60.0, water_track=True):
        out = pipe.step(t, samples)
        vx = next((s.vx for s in samples if isinstance(s, DvlVelocity)), vx)
    # through-water velocity is measured; the current is then unobservable from the DVL
    # alone (no over-ground velocity): its sigma must stay near the prior
    assert out["std_north"] > 0.3
    assert abs(out["u_r"] - vx) < 0.05


def test_invalid_and_nonfinite_inputs_are_counted_not_fused():
    pipe = current_pipeline("torpedo-auv", model=TORPEDO_TRUE, identify=False)
    gen = simulate_torpedo(30.0)
    out = {}
    for t, samples, c in gen:
        out = pipe.step(t, samples)
    before = dict(out)
    bad = [DvlVelocity(t=30.05, vx=50.0, vy=50.0, vz=50.0, valid=False),
           DvlVelocity(t=30.06, vx=float("nan"), vy=0.0, vz=0.0),
           Heading(t=30.07, heading_rad=float("nan"))]
    pipe.innovations()
    out = pipe.step(30.1, bad)
    assert pipe.samples.counters.rejected_invalid_dvl == 1
    assert pipe.samples.counters.rejected_nonfinite == 2
    # the rejected velocities are records of their channel, without an innovation
    unused = [(r.channel, r.reason, r.dof) for r in pipe.innovations() if not r.accepted]
    assert unused == [("dvl", "invalid", 3), ("dvl", "nonfinite", 3)]
    assert abs(out["north"] - before["north"]) < 0.01
    assert all(math.isfinite(v) for v in out.values())


def test_every_measurement_update_is_an_innovation_record():
    """One record per update of the joint filter (``velocity``: GNSS over ground), gated
    ones with reason ``gate``, ``z`` measured minus forecast with its full ``S``; one per
    update of the yaw RLS (``yaw_rls``); health keeps the counters only."""
    pipe = current_pipeline("rudder-boat")
    records = []
    for t, samples, _ in simulate_boat(120.0):
        pipe.step(t, samples)
        records += pipe.innovations()
    vel = [r for r in records if r.channel == "velocity"]
    assert sum(r.accepted for r in vel) == pipe.kf.counters.updates > 100
    assert sum(r.reason == "gate" for r in vel) == pipe.kf.counters.rejected_gate
    for r in vel:
        S, z = np.reshape(r.S, (r.dof, r.dof)), np.array(r.z)
        assert r.dof == 2 and np.allclose(S, S.T) and r.gate == pipe.cfg.gate_nis
        assert r.nis == pytest.approx(float(z @ np.linalg.solve(S, z)), rel=1e-9)
    rls = [r for r in records if r.channel == "yaw_rls"]
    assert len(rls) == pipe.identification.rls_updates > 0 and rls[0].dof == 1
    assert {r.channel for r in records} == {"velocity", "yaw_rls"}
    assert not any("nis" in k or "innovation" in k for k in pipe.health().flat())


def test_identified_model_survives_a_restart():
    pipe = current_pipeline("rudder-boat")
    for t, samples, c in simulate_boat(200.0):
        pipe.step(t, samples)
    state = pipe.get_state()
    import json
    state = json.loads(json.dumps(state))
    fresh = current_pipeline("rudder-boat")
    fresh.set_state(state)
    for a, b in zip(pipe.thetas, fresh.thetas):
        assert np.allclose(a, b)
    assert np.allclose(fresh.x[2:4], pipe.x[2:4])
    assert np.all(np.sqrt(np.diag(fresh.P)[2:4]) >= 0.2)  # current sigma inflated
    other = current_pipeline("torpedo-auv")
    other.set_state(state)  # another vehicle kind: ignored
    assert np.allclose(other.thetas[0], other.model.default_thetas()[0])


def test_the_hgo_model_survives_a_restart():
    """The high-gain observer's own coefficients are saved (``hgo_thetas``) and restored
    into its RLS, apart from the joint filter's; a state without them restores the joint
    filter's into both."""
    import json
    pipe = current_pipeline("rudder-boat", observer="hgo", hgo={"gamma": 0.3})
    pipe.hgo_rls.thetas[0] = pipe.hgo_rls.thetas[0] + 0.01  # as if learned
    pipe.hgo_rls.rls[0].P = 0.5 * pipe.hgo_rls.rls[0].P
    state = json.loads(json.dumps(pipe.get_state()))
    fresh = current_pipeline("rudder-boat", observer="hgo", hgo={"gamma": 0.3})
    fresh.set_state(state)
    assert np.allclose(fresh.hgo_rls.thetas[0], pipe.hgo_rls.thetas[0])
    assert np.allclose(fresh.hgo_rls.rls[0].theta, pipe.hgo_rls.thetas[0])
    assert not np.allclose(fresh.thetas[0], fresh.hgo_rls.thetas[0])
    # with their covariance: the RLS's and the observer's consider covariance
    assert np.allclose(fresh.hgo_rls.covariance(), pipe.hgo_rls.covariance())
    assert np.allclose(fresh.hgo.theta_cov, pipe.hgo_rls.covariance())
    del state["hgo_thetas"]
    older = current_pipeline("rudder-boat", observer="hgo", hgo={"gamma": 0.3})
    older.set_state(state)
    assert np.allclose(older.hgo_rls.thetas[0], older.thetas[0])
    # the joint filter's coefficients come with the joint filter's covariance
    assert np.allclose(older.hgo.theta_cov, np.asarray(state["theta_cov"]))


def test_bad_model_config_names_the_key():
    from onboard.core.config import ConfigError
    with pytest.raises(ConfigError, match="pipelines.current.model.surge: unknown term"):
        current_pipeline("rudder-boat", model={"surge": {"bogus": 1.0}})


def test_net_weight_prior_is_physically_scaled_and_configurable():
    """Unconfigured surge/sway net-weight coefficients start at g * net_weight_std (a trimmed
    vehicle is within a few percent of neutral), not at theta_std; the heave constant
    cos(theta)cos(phi) keeps theta_std (docs/current.md, "Net-weight prior")."""
    from onboard.core.config import ConfigError

    def prior_sd(p, ch, term):
        o = 2 * p.nd + sum(len(p.model.terms[c]) for c in p.model.dofs[:p.model.dofs.index(ch)])
        i = o + p.model.terms[ch].index(term)
        return math.sqrt(p.P[i, i])

    p = current_pipeline("torpedo-auv")
    assert prior_sd(p, "surge", "sin(theta)") == pytest.approx(9.81 * 0.02)
    assert prior_sd(p, "sway", "cos(theta)sin(phi)") == pytest.approx(9.81 * 0.02)
    assert prior_sd(p, "heave", "cos(theta)cos(phi)") == pytest.approx(1.0)
    assert prior_sd(p, "sway", "uv") == pytest.approx(1.0)
    p = current_pipeline("torpedo-auv", net_weight_std=0.005)
    assert prior_sd(p, "sway", "cos(theta)sin(phi)") == pytest.approx(9.81 * 0.005)
    # a configured coefficient keeps its relative prior
    p = current_pipeline("torpedo-auv", model={"sway": {"cos(theta)sin(phi)": -0.1}})
    assert prior_sd(p, "sway", "cos(theta)sin(phi)") == pytest.approx(0.2 * 0.1 + 0.02)
    p = current_pipeline("bluerov2")
    assert prior_sd(p, "heave", "cos(theta)cos(phi)") == pytest.approx(1.0)
    with pytest.raises(ConfigError, match="net_weight_std"):
        current_pipeline("torpedo-auv", net_weight_std=0.0)


SURFACE_CURRENT = (0.2, -0.3)
"""True current (north, east, m/s) of :func:`_surface_run`."""


def _surface_run(depth_m: float, seed: int = 0, observer: str = "kf", **section):
    """The torpedo AUV (config/torpedo-auv.toml, surface depth 0.5 m) at ``depth_m`` for
    120 s at 1.5 m/s through water in :data:`SURFACE_CURRENT`: heading 0 rad, then 1 rad
    from 60 s; a GNSS SOG/COG at 1 Hz with 0.05 m/s noise per axis, depth and attitude
    just before each fix. Returns the pipeline, its first output (attitude and depth only),
    its last output and the error (north, east, m/s) of its over-ground velocity
    ``R nu_r + V_c`` against the true one after 10 s."""
    cfg = configmod.load(configmod.resolve("torpedo-auv"))
    if observer != "kf":
        cfg = configmod.from_dict({**msgspec.to_builtins(cfg), "pipelines": {
            "current": {"observer": observer, **section}}})
    pipe = current_mod.create(cfg)
    rng = np.random.default_rng(seed)
    first = pipe.step(0.5, [Depth(t=0.4, depth_m=depth_m),
                            Attitude(t=0.5, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0)])
    out: dict = {}
    errors = []
    for k in range(1, 121):
        t = float(k)
        psi = 0.0 if k <= 60 else 1.0
        c, s = math.cos(psi), math.sin(psi)
        v_og = 1.5 * np.array([c, s]) + SURFACE_CURRENT
        z = v_og + rng.normal(0.0, 0.05, 2)
        out = pipe.step(t, [Depth(t=t - 0.05, depth_m=depth_m),
                            Attitude(t=t - 0.05, roll_rad=0.0, pitch_rad=0.0, yaw_rad=psi),
                            GnssFix(t=t, lat_deg=50.0, lon_deg=-4.0,
                                    sog_mps=float(np.hypot(*z)),
                                    cog_rad=float(math.atan2(z[1], z[0])))])
        if out and k > 10:  # the filter's state: the along-track current is unpublished
            u, v = out["u_r"], out["v_r"]  # before the turn (unknown)
            x = pipe.hgo.x if pipe.hgo is not None else pipe.kf.x
            u, v, cn, ce = x[0], x[1], x[3], x[4]
            estimate = np.array([c * u - s * v + cn, s * u + c * v + ce])
            errors.append(estimate - v_og)
    return pipe, first, out, np.array(errors)


def test_current_torpedo_auv_takes_a_surface_gnss_velocity():
    """At the surface (depth above ``surface_depth_m``) a torpedo AUV's GNSS SOG/COG is a
    horizontal over-ground velocity measurement ``z = (R nu_r + V_c)[:2]`` for the 3-D
    filter: every fix is fused, the filter's over-ground velocity follows the fixes, and
    after the turn the current is found. Deeper, the same fixes are ignored."""
    pipe, first, out, errors = _surface_run(depth_m=0.1)
    assert first == {}  # no velocity yet: the filter waits for one to start
    assert pipe.kf.counters.updates == 120 and pipe.kf.counters.rejected_gate == 0
    assert {"north", "east", "std_down", "w_r"} <= set(out)
    assert all(math.isfinite(v) for v in out.values())
    # the vertical current is never measured at the surface (GNSS is horizontal): unknown
    assert "down" not in out and out["std_down"] > 0.3
    # measured (seed 0): over-ground velocity RMS error 0.046 / 0.045 m/s (seeds 0-5:
    # 0.040-0.048, the fixes' own noise is 0.05); current error after the turn -0.014 /
    # +0.010 m/s (seeds 0-5: at most 0.014) at one sigma 0.076 / 0.090
    assert np.all(np.sqrt(np.mean(errors ** 2, axis=0)) < 0.08)
    current_error = np.array([out["north"], out["east"]]) - SURFACE_CURRENT
    assert np.all(np.abs(current_error) < 0.05)
    assert np.all(np.abs(current_error) < 2 * np.array([out["std_north"], out["std_east"]]))

    deep, _, out, _ = _surface_run(depth_m=5.0)
    assert deep.kf.counters.updates == 0 and out == {}  # under water: no GNSS velocity


def test_the_hgo_variant_fuses_a_surface_gnss_velocity():
    """The HGO corrects with a horizontal-only over-ground velocity (GNSS at the surface,
    2 components for a 3-D state) through those components; it used to skip every such fix
    and report its initial (zero) current while its over-ground velocity drifted."""
    pipe, _, out, errors = _surface_run(depth_m=0.1, observer="hgo", hgo={"gamma": 0.05})
    # measured (seed 0, fixed gamma 0.05): over-ground RMS error 0.051 / 0.061 m/s (the
    # fixes' noise is 0.05); before: 0.44 / 0.41 m/s with the current stuck at 0. At the
    # bundled gamma* = 6.4 with these 1 Hz fixes and no identified model (mode (b)) the
    # observer does not hold: 0.45 / 1.02 m/s (docs/current.md, HGO)
    assert np.all(np.sqrt(np.mean(errors ** 2, axis=0)) < 0.1)
    assert np.any(pipe.hgo.x[3:5] != 0.0)


def test_the_hgo_variant_runs_on_its_own_identified_model():
    """observer = "hgo" identifies its model by its own RLS (VelocityRls) from its own
    through-water velocity, not from the joint filter's coefficient states: on the boat's
    turns both learn, to different coefficients, and the HGO's current is within its
    bound. The configured model is 30 % off (surge coefficients x1.3, sway x0.7)."""
    wrong = {ch: {k: v * (1.3 if ch == "surge" else 0.7) for k, v in d.items()}
             for ch, d in BOAT_TRUE.items() if ch != "yaw"}
    pipe = current_pipeline("rudder-boat", model=wrong, observer="hgo", hgo={"gamma": 0.3})
    rms, cover, _, _ = current_errors(pipe, simulate_boat(150.0), after=90.0)
    assert pipe.counters.hgo_rls_updates > 100 and pipe.identification.rls_updates > 0
    assert any(not np.allclose(a, b) for a, b in zip(pipe.hgo_rls.thetas, pipe.thetas[:2]))
    # measured (seed 0, after 90 s): rms N/E 0.013 / 0.012 m/s, coverage 1.00 (300 s:
    # 0.015 / 0.015); 678 HGO RLS updates; sway "v" -0.84 (HGO) vs -0.87 (joint filter),
    # true -1.2: both stay near the prior on this run
    assert np.all(rms < 0.04)
    assert np.all(cover > 0.9)


def _yaw_matrix(psi: float) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_a_start_inconsistent_with_the_next_measurement_restarts_the_filter():
    """The ROV's first DVL report (at rest) and the INS velocity a moment later (0.3 m/s,
    the vehicle accelerating hard, the clocks still settling) disagree by 30 one-sigmas.
    Fused, the disagreement went through the 1.1 deg heading difference into the one
    direction the two sensors do not see, the split of the velocity over ground into
    current and through-water velocity: u_r and the current north both jumped to 6.3 m/s
    here (5.0 in the live demo run of fault-dvl-lock-loss-rov these figures are from).
    Within its first updates the filter reports that the measurement contradicts its start
    (and changes nothing); its owner starts it again from the newer measurement."""
    kf = current_pipeline("bluerov2").kf
    kf.start("bottom", np.array([-0.013, 0.004, -0.014]), _yaw_matrix(math.pi - 0.0012))
    assert kf.update("bottom", np.array([-0.013, 0.004, -0.014]), 0.012,
                     _yaw_matrix(math.pi - 0.0012)) == "accepted"
    z, R = np.array([0.05, 0.28, 0.09]), _yaw_matrix(math.pi - 0.0192)
    x0 = kf.x.copy()
    assert kf.update("earth", z, 0.01, R) == "contradicts_start"
    assert kf.nis > kf.gate_nis and np.array_equal(kf.x, x0)  # reported, nothing changed
    assert kf.restart_from("earth", z, 0.01, R) == "accepted"
    assert kf.counters.restarted == 1
    # started from the INS velocity: u_r ~ -0.05 (heading south), v_r ~ -0.28 m/s
    assert np.allclose(kf.x[:3], [-0.045, -0.281, 0.09], atol=0.002)
    assert np.allclose(kf.x[3:6], 0.0)
    # after START_UPDATES updates the gate rejects instead
    from onboard.estimators.current_kf import START_UPDATES

    for _ in range(START_UPDATES):
        kf.update("earth", np.array([0.05, 0.28, 0.09]), 0.01, _yaw_matrix(math.pi - 0.0192))
    assert kf.update("earth", np.array([0.05, 1.28, 0.09]), 0.01,
                     _yaw_matrix(math.pi - 0.0192)) == "gated"


def test_the_pipeline_says_when_its_start_was_contradicted():
    """Through the pipeline, the DVL at rest and the INS at 0.3 m/s stamped at the same
    instant: an event names the restart, and the published through-water velocity is the
    INS's."""
    pipe = current_pipeline("bluerov2")
    pipe.step(0.1, [Attitude(t=0.1, roll_rad=0.0, pitch_rad=0.0, yaw_rad=math.pi - 0.0012)])
    out = pipe.step(0.2, [
        DvlVelocity(t=0.2, vx=-0.013, vy=0.004, vz=-0.014),
        VelocityOverGround(t=0.2, v_north_mps=0.05, v_east_mps=0.28, v_down_mps=0.09)])
    assert pipe.kf.counters.restarted == 1
    assert any(e.startswith("the start was contradicted by a velocity measurement")
               for e in pipe.events), pipe.events
    assert abs(out["u_r"] + 0.05) < 0.01 and abs(out["v_r"] + 0.28) < 0.01
    # the pipeline's decision is on the record: the contradicting innovation, not the
    # restarted filter's
    (rec,) = [r for r in pipe.innovations() if r.channel == "velocity"]
    assert (rec.accepted, rec.reason) == (False, "restart") and rec.nis > rec.gate


def test_the_restored_currents_twin_starts_again_when_its_start_is_contradicted():
    """The twin filter of a restored current's probation decides as the pipeline does on
    the same contradiction: it starts again from the INS velocity."""
    from onboard.estimators.current_kf import VelocityMeasurement
    from onboard.estimators.restored_current import RestoredCurrentCheck

    twin = current_pipeline("bluerov2").kf
    check = RestoredCurrentCheck(hold_s=60.0, false_alarm_p=0.001, unknown_above_std=0.5,
                                 init_current_std=1.0)
    check.begin(twin, np.zeros(3), 0.01 * np.eye(3))
    R0, R1 = _yaw_matrix(math.pi - 0.0012), _yaw_matrix(math.pi - 0.0192)
    dvl = VelocityMeasurement("bottom", 0.2, np.array([-0.013, 0.004, -0.014]), 0.012)
    ins = VelocityMeasurement("earth", 0.2, np.array([0.05, 0.28, 0.09]), 0.01)
    check.start(dvl.kind, dvl.z, R0, math.pi)
    check.update([dvl], R0)
    assert twin.counters.restarted == 0
    check.update([ins], R1)
    assert twin.counters.restarted == 1
    assert np.allclose(twin.x[:3], [-0.045, -0.281, 0.09], atol=0.002)
