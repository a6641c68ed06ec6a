"""Model closure on synthetic kinematics: each effect found, named and measured.

The generator below is deliberately independent of the SITL plants: a first-order surge
model, a rudder-driven yaw rate, and each effect applied where physics puts it. The SITL
scenarios (tests/test_diagnose_sitl.py) are the harder test; this one pins the
identification math. Bounds carry the measured figure in a comment. The synthetic runs
are 600 s long (the figures of 900 s beside them): a selection costs ~20 % less CPU
(3.4-3.7 s against 4.2-4.7 s for the current case) and every effect is found as well; the
time-ramp and the by-run split keep 900 s.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import pytest

from onboard.offline.closure import report
from onboard.offline.closure.dataset import from_arrays
from onboard.offline.closure import model as M
from onboard.offline.closure.effects import ALL
from onboard.offline.closure.select import select, split


def synth(seed=0, T=600.0, dt=0.1, current=(0.0, 0.0), dev=(0.0, 0.0), gyro_bias=0.0,
          latency=0.0, slip=0.0, thrust_q=0.0, coupling=0.0, wave=None, heading_bias=0.0,
          harmonic2=0.0, shaft_lag=0.0, sway_lag=0.0, pivot=0.3, imu=False):
    rng = np.random.default_rng(seed)
    n = int(T / dt)
    t = np.arange(n) * dt
    thr = np.repeat(rng.uniform(0.3, 1.0, n // 400 + 1), 400)[:n]
    rud = np.sign(np.sin(2 * np.pi * t / 60)) * 0.3 * np.repeat(rng.uniform(0.5, 1, n // 300 + 1), 300)[:n]
    u = r = psi = 0.0
    s = thr[0]
    U, PSI, R = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        s = s + (1.0 - math.exp(-dt / shaft_lag)) * (thr[i] - s) if shaft_lag else thr[i]
        thrust = (1 - thrust_q) * s + thrust_q * s * abs(s)
        u += dt * (-0.5 * u + thrust - coupling * r * r * u)
        r += dt * (-1.0 * r + 0.6 * rud[i] * u)
        psi += dt * r
        U[i], PSI[i], R[i] = u, psi, r
    # Every hull sways in turns (pivot point 0.3 m ahead of the CG), the sway building up
    # behind the turn rate with time constant sway_lag: in the base model.
    rs = R.copy()
    if sway_lag:
        for i in range(1, n):
            rs[i] = rs[i - 1] + (1.0 - math.exp(-dt / sway_lag)) * (R[i] - rs[i - 1])
    vlat = -pivot * rs + slip * U * np.abs(U) + harmonic2 * np.sin(2 * PSI)
    vn = U * np.cos(PSI) - vlat * np.sin(PSI) + current[0]
    ve = U * np.sin(PSI) + vlat * np.cos(PSI) + current[1]
    if wave:
        period, amp = wave
        vn = vn + 0.8 * amp * np.sin(2 * np.pi * t / period)
        ve = ve + 0.6 * amp * np.sin(2 * np.pi * t / period)
    acc = {}
    if imu:  # a prompt accelerometer: the true acceleration over ground in body axes
        a_n, a_e = np.gradient(vn, dt), np.gradient(ve, dt)
        noise = np.random.default_rng(seed + 1000).normal(0, 0.03, (2, n))
        acc = {"acc_x": np.cos(PSI) * a_n + np.sin(PSI) * a_e + noise[0],
               "acc_y": -np.sin(PSI) * a_n + np.cos(PSI) * a_e + noise[1]}
    if latency:
        k = int(round(latency / dt))
        vn = np.r_[np.full(k, vn[0]), vn[:-k]]
        ve = np.r_[np.full(k, ve[0]), ve[:-k]]
    vn = vn + rng.normal(0, 0.05, n)
    ve = ve + rng.normal(0, 0.05, n)
    a, b = dev
    psi_m = PSI + a * np.sin(PSI) + b * np.cos(PSI) + heading_bias + rng.normal(0, 0.01, n)
    gyro = R + gyro_bias + rng.normal(0, 0.005, n)
    return from_arrays(t, psi_m, vn, ve, r=gyro, cmd_surge=thr, cmd_yaw=rud, **acc)


def detected(ds):
    doc = report.diagnosis(select(ds), "synthetic")
    return doc, {e["name"]: e for e in doc["effects"] if e["detected"]}


@functools.lru_cache(maxsize=None)
def _current_run():
    """(dataset, selection) of the 0.3/-0.2 m/s current, selected once for the tests that
    read it (a selection is the expensive part of these tests)."""
    ds = synth(current=(0.3, -0.2))
    return ds, select(ds)


def test_clean_data_detects_nothing():
    doc, found = detected(synth())
    assert found == {}
    assert doc["holdout_error_after"] == doc["holdout_error_before"]


def test_shaft_lag_and_course_lag_are_the_base_model_s_not_a_latency():
    # Every boat's propeller spins up behind its command and its sway builds up behind
    # the turn rate: neither is an effect, and neither may pose as a GNSS latency.
    ds = synth(shaft_lag=0.4, sway_lag=0.8, pivot=0.6)
    assert M.estimate_actuator_lag(ds) == pytest.approx(0.4, abs=0.1)  # measured 0.353
    _, found = detected(ds)
    assert found == {}
    # the same hull with a true 0.6 s latency: found as itself (measured 0.600 s by the
    # lateral delay search, the data having no accelerometer)
    lat = synth(latency=0.6, shaft_lag=0.4, sway_lag=0.8, pivot=0.6, imu=True)
    _, found = detected(dataclasses.replace(lat, acc_x=None, acc_y=None))
    assert set(found) == {"gps_latency"}
    assert found["gps_latency"]["params"]["seconds"] == pytest.approx(0.6, abs=0.1)
    # with an accelerometer it is measured by aligning the GNSS acceleration with the
    # IMU's, with no hull model (measured 0.607 +- 0.038 s); on the hull without a
    # latency that alignment finds no delay at all (None: the best delay is 0)
    tau, _ = ALL["gps_latency"].search(lat)
    assert tau == pytest.approx(0.6, abs=0.1)
    assert ALL["gps_latency"].search(synth(shaft_lag=0.4, sway_lag=0.8, pivot=0.6,
                                           imu=True)) is None


def test_current_is_found_with_its_components():
    doc = report.diagnosis(_current_run()[1], "synthetic")
    found = {e["name"]: e for e in doc["effects"] if e["detected"]}
    assert set(found) == {"water_current"}
    p = found["water_current"]["params"]
    # measured (T = 600 s): north 0.309, east -0.206 (900 s: 0.315, -0.207)
    assert p["north"] == pytest.approx(0.3, abs=0.03)
    assert p["east"] == pytest.approx(-0.2, abs=0.03)
    assert doc["holdout_error_after"] < 0.25 * doc["holdout_error_before"]


def test_compass_deviation_is_not_mistaken_for_a_current():
    _, found = detected(synth(dev=(0.05, 0.03)))
    assert set(found) == {"compass_deviation"}
    p = found["compass_deviation"]["params"]
    # measured: amplitude 0.055, phase 0.526 (true 0.0583, 0.540; 900 s: 0.057, 0.533)
    assert p["amplitude"] == pytest.approx(math.hypot(0.05, 0.03), abs=0.01)
    assert p["phase"] == pytest.approx(math.atan2(0.03, 0.05), abs=0.1)


def test_a_large_deviation_is_a_deviation_and_one_beyond_90_deg_is_none():
    """A 38 deg deviation (a compass beside a motor) is still found as one; the bound is
    a compass's physics (a hull's field turns the needle by at most 90 deg), not the
    small-angle model's range."""
    _, found = detected(synth(dev=(0.6, 0.3)))
    assert set(found) - {"unexplained"} == {"compass_deviation"}
    # measured: amplitude 0.727 rad for a true 0.671 (the small-angle model reads high)
    assert found["compass_deviation"]["params"]["amplitude"] == pytest.approx(0.67, abs=0.1)
    e = ALL["compass_deviation"]
    assert e.physical(np.array([1.0, 1.0])) and not e.physical(np.array([1.5, 0.6]))


def test_gyro_bias():
    _, found = detected(synth(gyro_bias=0.01))
    assert set(found) == {"gyro_bias"}
    assert found["gyro_bias"]["params"]["bias"] == pytest.approx(0.01, abs=0.001)


def test_gps_latency_is_told_from_sideslip():
    _, found = detected(synth(latency=0.6))
    assert "gps_latency" in found and "sideslip" not in found
    # measured: 0.610 s (true 0.6; 900 s: 0.546)
    assert found["gps_latency"]["params"]["seconds"] == pytest.approx(0.6, abs=0.12)


def test_sideslip_is_told_from_gps_latency_and_heading_bias():
    _, found = detected(synth(slip=0.05))
    assert set(found) == {"sideslip"}
    assert found["sideslip"]["params"]["k"] == pytest.approx(0.05, abs=0.01)


def test_heading_bias_is_told_from_sideslip():
    _, found = detected(synth(heading_bias=0.08))
    assert set(found) == {"heading_bias"}
    # lateral = -U bias: the fitted bias is the heading error (rad)
    assert found["heading_bias"]["params"]["bias"] == pytest.approx(0.08, abs=0.01)


def test_thrust_nonlinearity():
    _, found = detected(synth(thrust_q=0.8))
    assert set(found) == {"thrust_nonlinearity"}


def test_surge_yaw_coupling():
    _, found = detected(synth(coupling=2.0))
    assert set(found) == {"surge_yaw_coupling"}
    # measured: 2.15 (true 2.0; 900 s: 1.89)
    assert found["surge_yaw_coupling"]["params"]["k"] == pytest.approx(2.0, rel=0.2)


def test_wave_oscillation_period_and_amplitude():
    _, found = detected(synth(wave=(6.0, 0.2)))
    assert set(found) == {"wave_oscillation"}
    p = found["wave_oscillation"]["params"]
    # measured: period 5.997 s, amplitude 0.195 m/s (900 s: 6.001, 0.196)
    assert p["period"] == pytest.approx(6.0, abs=0.05)
    assert p["velocity_amplitude_mps"] == pytest.approx(0.2, abs=0.03)


def test_two_effects_at_once():
    _, found = detected(synth(current=(0.3, -0.2), dev=(0.05, 0.03)))
    assert set(found) == {"water_current", "compass_deviation"}
    assert found["water_current"]["params"]["north"] == pytest.approx(0.3, abs=0.03)


def test_structure_no_effect_explains_is_reported_unexplained():
    # A lateral velocity at twice the heading frequency: no effect in the vocabulary has
    # that shape (a compass deviation is a first harmonic), so it must not be forced onto one.
    doc, found = detected(synth(harmonic2=0.15))
    assert "unexplained" in found
    assert "compass_deviation" not in found and "water_current" not in found
    ev = found["unexplained"]["evidence"]
    # measured: lateral, "heading harmonic 2", held-out gain 0.81 (alone 0.81)
    assert ev["channel"] == "lateral" and ev["regressor"] == "heading harmonic 2"
    assert ev["held_out_gain"] > 0.5


def test_unexplained_looks_at_every_channel():
    # A gyro whose bias grows with time (a warming sensor): the heading channel drifts as
    # t^2, which no constant gyro bias fits on the test part; the evidence must name the
    # heading channel and time. 900 s: over 600 s the ramp stays below what the
    # selection names.
    ds = synth(T=900.0)
    ramp = 2e-5 * (ds.t - ds.t[0])  # rad/s per s: 0 -> 0.018 rad/s over 900 s
    ds2 = from_arrays(ds.t, ds.psi, ds.v_n, ds.v_e, r=ds.r + ramp, cmd_surge=ds.cmd_surge,
                      cmd_yaw=ds.cmd_yaw)
    sel = select(ds2)
    assert sel.unexplained is not None and "heading" in sel.unexplained
    assert sel.unexplained["heading"]["regressor"] == "time"


def test_three_way_split_scores_on_a_test_part_it_never_used():
    ds, sel = _current_run()
    doc = report.diagnosis(sel, "synthetic")
    parts = doc["split_parts"]
    assert parts["method"] == "forward_in_time"
    last_seen = max(b for k in ("fit", "select") for _, b in parts[k]["time_ranges_s"])
    (t0, t1), = parts["test"]["time_ranges_s"]
    assert t0 > last_seen and t1 == pytest.approx(ds.t[-1] - ds.t[0], abs=0.2)
    assert sum(parts[k]["samples"] for k in ("fit", "select", "test")) == len(ds)
    # the test part is disjoint from what was fitted and selected on
    seen = set(np.round(np.r_[sel.split.fit.t, sel.split.holdout.t], 3))
    assert not seen & set(np.round(sel.split.test.t, 3))
    # the headline figures are the test part's; the selection part's are separate
    assert doc["holdout_error_after"] == pytest.approx(
        M.score(sel.final_split.test, sel.final_fit, doc["holdout_metric"]).headline)
    assert doc["selection_error_after"] != doc["holdout_error_after"]
    # measured: test part 0.357 -> 0.073 m/s (900 s: 0.367 -> 0.072)
    assert doc["holdout_error_after"] < 0.3 * doc["holdout_error_before"]


def test_split_by_run_keeps_whole_runs_in_one_part():
    ds = synth(T=900.0)
    runs = np.array([f"run{int(k)}" for k in (ds.t - ds.t[0]) // 150], dtype=object)  # 6 runs
    ds.run = runs
    sp = split(ds)
    assert sp.parts["test"]["runs"] == ["run2", "run5"]
    assert sp.parts["select"]["runs"] == ["run1"]
    assert sp.parts["fit"]["runs"] == ["run0", "run3", "run4"]
    assert set(sp.test.run) == {"run2", "run5"}


@pytest.mark.parametrize("logged, expected", [
    # (logged left, logged right) from (port, starboard); expected mapping
    (lambda p, s: (s, p), {"swapped": True, "reversed_left": False, "reversed_right": False}),
    (lambda p, s: (-s, p), {"swapped": True, "reversed_left": True, "reversed_right": False}),
    (lambda p, s: (p, -s), {"swapped": False, "reversed_left": False, "reversed_right": True}),
])
def test_actuator_mapping_finds_swapped_and_reversed_thrusters(logged, expected):
    # A skid-steered boat: surge from the mean of the two thrusts, yaw rate from half the
    # difference (port ahead turns to starboard). The synthetic rudder plays that part.
    ds = synth()
    port, stbd = ds.cmd_surge + ds.cmd_yaw, ds.cmd_surge - ds.cmd_yaw
    left, right = logged(port, stbd)
    ds2 = from_arrays(ds.t, ds.psi, ds.v_n, ds.v_e, r=ds.r, cmd_surge=0.5 * (left + right),
                      cmd_yaw=0.5 * (left - right), cmd_left=left, cmd_right=right)
    doc, found = detected(ds2)
    assert found["actuator_mapping"]["params"] == expected
    ev = found["actuator_mapping"]["evidence"]
    # measured held-out gains (surge + yaw-rate variance left): 0.91, 0.96, 0.96 (900 s:
    # 0.84, 0.92, 0.92); the test part's ground velocity error with a reversed thruster
    # 0.483 -> 0.072 m/s (900 s: 0.439 -> 0.072)
    assert ev["held_out_gain"] > 0.3


def test_actuator_mapping_is_not_named_when_the_channels_are_right():
    ds = synth()
    port, stbd = ds.cmd_surge + ds.cmd_yaw, ds.cmd_surge - ds.cmd_yaw
    ds2 = from_arrays(ds.t, ds.psi, ds.v_n, ds.v_e, r=ds.r, cmd_surge=ds.cmd_surge,
                      cmd_yaw=ds.cmd_yaw, cmd_left=port, cmd_right=stbd)
    _, found = detected(ds2)
    assert found == {}
