"""Current pipeline on synthetic plants (independent of SITL): error and 2-sigma coverage.

The plants here are the regression models of vehicle_models.py with "true" coefficients,
a current and sensor noise; they are the pipeline's own specification test. The SITL
scenarios (other plants, other models) are in test_current_sitl.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.core.config import from_dict
from onboard.core.messages import ActuatorCommand, Attitude, DvlVelocity, GnssFix, Heading
from onboard.estimators.vehicle_models import ModelInputs, RegressionModel
from onboard.pipelines import current as current_mod

BOAT_TRUE = {
    "surge": {"u|u|": -0.08, "u": -0.05, "vr": 0.3, "tau_u": 0.3},
    "sway": {"v": -1.2, "v|v|": -0.5, "ur": -0.4, "r": 0.05},
    "yaw": {"r": -1.5, "r|r|": -0.5, "uv": 0.1, "u|u|dr": 0.8, "n|n|dr": 0.3},
}
TORPEDO_TRUE = {
    "surge": {"u|u|": -0.045, "wq": -0.9, "q^2": 0.0, "vr": 0.9, "r^2": 0.0,
              "sin(theta)": 0.0, "n|n|": 0.12},
    "sway": {"v|v|": -1.5, "r|r|": 0.0, "uv": -0.9, "ur": -0.5, "wp": 0.0, "pq": 0.0,
             "cos(theta)sin(phi)": 0.0, "u|u|dr": 0.1},
    "heave": {"w|w|": -1.5, "q|q|": 0.0, "uw": -0.9, "uq": 0.5, "vp": 0.0, "rp": 0.0,
              "cos(theta)cos(phi)": 0.0, "u|u|ds": -0.1},
    "yaw": {"r": -0.8, "r|r|": -0.3, "uv": 0.6, "u|u|dr": -1.2},
}


def simulate_boat(duration: float = 600.0, current=(0.3, -0.2), seed: int = 0,
                  tick: float = 0.1, leg_s: float = 60.0, current_fn=None):
    """Rudder boat, zig-zag heading legs; yields (t, samples, true current (n, e))."""
    rng = np.random.default_rng(seed)
    m = RegressionModel("surface-rudder")
    th = m.thetas_from_mapping(BOAT_TRUE)
    x = ModelInputs()
    x.n = 0.8
    nu = np.array([1.0, 0.0])
    psi, r = 0.0, 0.0
    north = east = 0.0
    h = 0.01
    n_sub = int(round(tick / h))
    headings = [0.0, 1.6, 3.2, -1.6, 0.8, 2.4, -2.4, -0.8]
    t = 0.0
    k = 0
    while t < duration - 1e-9:
        samples = []
        for _ in range(n_sub):
            ref = headings[int(t // leg_s) % len(headings)]
            x.dr = float(np.clip(0.6 * math.remainder(ref - psi, 2 * math.pi) - 0.3 * r, -0.5, 0.5))
            x.r = r
            phis = m.regressors(nu, x)
            acc = np.array([phis[i] @ th[i] for i in range(3)])
            nu = nu + h * acc[:2]
            r = r + h * acc[2]
            psi = psi + h * r
            t += h
            c = np.array(current_fn(t) if current_fn else current)
            rot = np.array([[math.cos(psi), -math.sin(psi)], [math.sin(psi), math.cos(psi)]])
            vg = rot @ nu + c
            north += h * vg[0]
            east += h * vg[1]
        k += 1
        samples.append(ActuatorCommand(t=t, throttle=x.n, rudder_rad=x.dr))
        samples.append(Heading(t=t, heading_rad=wrap(psi + rng.normal(0, 0.01))))
        samples.append(Attitude(t=t, roll_rad=0.0, pitch_rad=0.0,
                                yaw_rad=wrap(psi + rng.normal(0, 0.01)),
                                yaw_rate_rps=r + rng.normal(0, 0.005)))
        if k % 2 == 0:
            vgn = vg + rng.normal(0, 0.05, 2)
            samples.append(GnssFix(t=t, lat_deg=0.0, lon_deg=0.0, sog_mps=float(np.hypot(*vgn)),
                                   cog_rad=float(math.atan2(vgn[1], vgn[0]))))
        yield t, samples, c


def simulate_torpedo(duration: float = 600.0, current=(-0.6, 0.3, 0.02), seed: int = 0,
                     tick: float = 0.1, leg_s: float = 100.0, water_track: bool = False,
                     truth: dict = TORPEDO_TRUE, pitch: tuple[float, float] = (0.05, 0.05),
                     roll: tuple[float, float] = (0.0, 0.0)):
    """Torpedo AUV at constant depth, heading legs; DVL bottom track at 5 Hz.

    ``pitch``, ``roll``: (amplitude rad, angular frequency rad/s) of an attitude
    oscillation the stern plane does not cause (a depth-keeping autopilot on a wavy
    profile); ``truth``: the model coefficients of the plant."""
    rng = np.random.default_rng(seed)
    m = RegressionModel("torpedo")
    th = m.thetas_from_mapping(truth)
    (pa, wq), (ra, wp) = pitch, roll
    x = ModelInputs()
    x.n = 1.5 * 0.7  # 1500 rpm / rpm_scale 1000 ~ cruise
    nu = np.array([1.5, 0.0, 0.0])
    psi, r = 0.0, 0.0
    h = 0.01
    n_sub = int(round(tick / h))
    headings = [0.0, 2.0, -2.0, 1.0, 3.0, -1.0]
    t = 0.0
    k = 0
    c = np.array(current, float)
    while t < duration - 1e-9:
        samples = []
        for _ in range(n_sub):
            ref = headings[int(t // leg_s) % len(headings)]
            err = math.remainder(ref - psi, 2 * math.pi)
            x.dr = float(np.clip(-0.5 * err + 0.3 * r, -0.3, 0.3))
            x.r = r
            x.pitch = pa * math.sin(wq * t)
            x.q = pa * wq * math.cos(wq * t)
            x.roll = ra * math.sin(wp * t)
            x.p = ra * wp * math.cos(wp * t)
            phis = m.regressors(nu, x)
            acc = np.array([phis[i] @ th[i] for i in range(4)])
            nu = nu + h * acc[:3]
            r = r + h * acc[3]
            psi = psi + h * r
            t += h
        k += 1
        R = current_mod._rot(x.roll, x.pitch, psi)
        samples.append(ActuatorCommand(t=t, propeller_rpm=x.n * 1000.0, rudder_rad=x.dr,
                                       stern_plane_rad=0.0))
        samples.append(Attitude(t=t, roll_rad=x.roll, pitch_rad=x.pitch, yaw_rad=wrap(psi),
                                roll_rate_rps=x.p, pitch_rate_rps=x.q, yaw_rate_rps=r))
        if k % 2 == 0:
            if water_track:
                z = nu + rng.normal(0, 0.01, 3)
            else:
                z = nu + R.T @ c + rng.normal(0, 0.01, 3)
            samples.append(DvlVelocity(t=t, vx=z[0], vy=z[1], vz=z[2],
                                       track="water" if water_track else "bottom"))
        yield t, samples, c


def wrap(a: float) -> float:
    return math.remainder(a, 2 * math.pi)


def run(pipe, gen, after: float = 120.0):
    """Errors (after ``after`` s) and 2-sigma coverage per horizontal axis."""
    errs, stds = [], []
    for t, samples, c in gen:
        out = pipe.step(t, samples)
        if t >= after and "north" in out:
            errs.append([out["north"] - c[0], out["east"] - c[1]])
            stds.append([out["std_north"], out["std_east"]])
    e, s = np.array(errs), np.array(stds)
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    cover = np.mean(np.abs(e) <= 2 * s, axis=0)
    return rms, cover, e, s


def make(vclass: str, **section):
    cfg = from_dict({"vehicle": {"class": vclass}, "pipelines": {"current": section}})
    return current_mod.create(cfg)


def test_columns_follow_the_contract():
    boat = make("rudder-boat")
    auv = make("torpedo-auv")
    for c in ("north", "east", "std_north", "std_east"):
        assert c in boat.columns and c in auv.columns
    assert "down" in auv.columns and "down" not in boat.columns
    assert make("bluerov2").nd == 3 and make("twin-thruster-boat").model.kind == "surface-twin"
    assert make("rudder-boat", enabled=False) is None


def test_boat_known_model_constant_current():
    pipe = make("rudder-boat", model=BOAT_TRUE, identify=False)
    rms, cover, _, s = run(pipe, simulate_boat(300.0), after=90.0)
    # measured: rms [0.003, 0.003] m/s, sigma ~0.01, coverage 1.0
    assert np.all(rms < 0.02)
    assert np.all(cover > 0.9)


def test_boat_no_model_identified_online():
    pipe = make("rudder-boat")
    rms, cover, _, _ = run(pipe, simulate_boat(480.0), after=240.0)
    # measured: rms [0.003, 0.003] m/s, coverage 1.0 (first turn at 60 s)
    assert np.all(rms < 0.03)
    assert np.all(cover > 0.9)
    assert pipe.counters["rls_updates"] > 0


def test_torpedo_known_model_bottom_track():
    pipe = make("torpedo-auv", model=TORPEDO_TRUE, identify=False)
    rms, cover, _, _ = run(pipe, simulate_torpedo(300.0), after=100.0)
    # measured: rms [0.002, 0.002] m/s
    assert np.all(rms < 0.02)
    assert np.all(cover > 0.9)


def test_torpedo_hgo_observer_with_increasing_gain():
    pipe = make("torpedo-auv", model=TORPEDO_TRUE, identify=False, observer="hgo")
    rms, cover, _, _ = run(pipe, simulate_torpedo(300.0), after=100.0)
    # measured: rms [0.019, 0.036] m/s, sigma [0.06, 0.12], coverage 1.0; gamma rose from
    # 0.05 to 1.19 (gamma_max 1.29, config/gains/torpedo-auv.json). The higher the gain, the
    # noisier: a fixed gamma = 0.3 gives rms [0.003, 0.005] (the KF: 0.002)
    assert np.all(rms < 0.06)
    assert np.all(cover > 0.9)
    assert 0.05 < pipe.gamma <= pipe.gain.gamma_max + 1e-9


def test_water_track_dvl_is_a_direct_through_water_measurement():
    pipe = make("torpedo-auv", model=TORPEDO_TRUE, identify=False)
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
    pipe = make("torpedo-auv", model=TORPEDO_TRUE, identify=False)
    gen = simulate_torpedo(30.0)
    out = {}
    for t, samples, c in gen:
        out = pipe.step(t, samples)
    before = dict(out)
    bad = [DvlVelocity(t=30.05, vx=50.0, vy=50.0, vz=50.0, valid=False),
           DvlVelocity(t=30.06, vx=float("nan"), vy=0.0, vz=0.0),
           Heading(t=30.07, heading_rad=float("nan"))]
    out = pipe.step(30.1, bad)
    assert pipe.counters["rejected_invalid_dvl"] == 1
    assert pipe.counters["rejected_nonfinite"] == 2
    assert abs(out["north"] - before["north"]) < 0.01
    assert all(math.isfinite(v) for v in out.values())


def test_identified_model_survives_a_restart():
    pipe = make("rudder-boat")
    for t, samples, c in simulate_boat(200.0):
        pipe.step(t, samples)
    state = pipe.get_state()
    import json
    state = json.loads(json.dumps(state))
    fresh = make("rudder-boat")
    fresh.set_state(state)
    for a, b in zip(pipe.thetas, fresh.thetas):
        assert np.allclose(a, b)
    assert np.allclose(fresh.x[2:4], pipe.x[2:4])
    assert np.all(np.sqrt(np.diag(fresh.P)[2:4]) >= 0.2)  # current sigma inflated
    other = make("torpedo-auv")
    other.set_state(state)  # another vehicle kind: ignored
    assert np.allclose(other.thetas[0], other.model.default_thetas()[0])


def test_bad_model_config_names_the_key():
    from onboard.core.config import ConfigError
    with pytest.raises(ConfigError, match="pipelines.current.model.surge: unknown term"):
        make("rudder-boat", model={"surge": {"bogus": 1.0}})


def test_net_weight_prior_is_physically_scaled_and_configurable():
    """Unconfigured surge/sway net-weight coefficients start at g * net_weight_std (a trimmed
    vehicle is within a few percent of neutral), not at theta_std; the heave constant
    cos(theta)cos(phi) keeps theta_std (docs/current.md, "Net-weight prior")."""
    from onboard.core.config import ConfigError

    def prior_sd(p, ch, term):
        o = 2 * p.nd + sum(len(p.model.terms[c]) for c in p.model.dofs[:p.model.dofs.index(ch)])
        i = o + p.model.terms[ch].index(term)
        return math.sqrt(p.P[i, i])

    p = make("torpedo-auv")
    assert prior_sd(p, "surge", "sin(theta)") == pytest.approx(9.81 * 0.02)
    assert prior_sd(p, "sway", "cos(theta)sin(phi)") == pytest.approx(9.81 * 0.02)
    assert prior_sd(p, "heave", "cos(theta)cos(phi)") == pytest.approx(1.0)
    assert prior_sd(p, "sway", "uv") == pytest.approx(1.0)
    p = make("torpedo-auv", net_weight_std=0.005)
    assert prior_sd(p, "sway", "cos(theta)sin(phi)") == pytest.approx(9.81 * 0.005)
    # a configured coefficient keeps its relative prior
    p = make("torpedo-auv", model={"sway": {"cos(theta)sin(phi)": -0.1}})
    assert prior_sd(p, "sway", "cos(theta)sin(phi)") == pytest.approx(0.2 * 0.1 + 0.02)
    p = make("bluerov2")
    assert prior_sd(p, "heave", "cos(theta)cos(phi)") == pytest.approx(1.0)
    with pytest.raises(ConfigError, match="net_weight_std"):
        make("torpedo-auv", net_weight_std=0.0)
