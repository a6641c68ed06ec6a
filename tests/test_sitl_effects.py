"""Injected effects: each one is in the world (truth and samples) with its parameters, and
the clean scenario carries none."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pymap3d
import pytest

from onboard.core.messages import GnssFix, Heading, Imu
from onboard.sitl.effects import Effect, external_force_ned
from onboard.sitl.environment import Environment
from onboard.sitl.plants.base import Command
from onboard.sitl.runner import simulate
from onboard.sitl.scenarios import NOMINAL_BOAT, ForcedRudderBoat, get
from onboard.sitl.sensors import GeoOrigin


def _collect(name: str, duration: float, seed: int = 1):
    truth, samples = {}, []
    for t, ss, tr in simulate(name, duration, seed):
        if tr is not None:
            truth[round(t, 3)] = tr
        samples.extend(ss)
    return truth, samples


def _speed(truth: dict, t0: float, t1: float) -> float:
    return float(np.mean([tr.u_r for t, tr in truth.items() if t0 <= t <= t1]))


def test_effect_vocabulary_is_checked():
    with pytest.raises(ValueError, match="unknown effect"):
        Effect("magic", {})
    with pytest.raises(ValueError, match="unknown parameter"):
        Effect("gps_latency", {"ms": 3})
    with pytest.raises(ValueError, match="missing"):
        Effect("compass_deviation", {"amplitude": 0.1})
    assert Effect("gyro_bias", {"z": 0.01}).params == {"x": 0.0, "y": 0.0, "z": 0.01}


def test_clean_has_no_effect_and_declares_none():
    sc = get("clean")
    assert sc.injected == () and sc.declared == ()
    truth, _ = _collect("clean", 2.0)
    assert all(k.startswith("sensor.") for k in truth[2.0].effects)


def test_water_current_is_in_the_truth_and_in_the_motion():
    truth, _ = _collect("effect-current", 30.0)
    tr = truth[20.0]
    assert (tr.current_north, tr.current_east) == (0.25, -0.15)
    assert tr.effects["water_current.north"] == 0.25
    # over ground = through water + current (heading north, straight leg)
    c, s = math.cos(tr.yaw), math.sin(tr.yaw)
    vn = c * tr.u - s * tr.v
    vn_r = c * tr.u_r - s * tr.v_r
    assert vn - vn_r == pytest.approx(0.25, abs=1e-9)


def test_compass_deviation_shows_in_the_headings():
    truth, samples = _collect("effect-compass-deviation", 55.0)  # the circle: all headings
    err, psi = [], []
    for s in samples:
        if isinstance(s, Heading) and round(s.t, 3) in truth:
            y = truth[round(s.t, 3)].yaw
            err.append(math.remainder(s.heading_rad - y, 2 * math.pi))
            psi.append(y)
    psi, err = np.array(psi), np.array(err)
    a, b, c = np.linalg.lstsq(np.column_stack([np.cos(psi), np.sin(psi), np.ones_like(psi)]),
                              err, rcond=None)[0]
    # err = A sin(psi + phi) = A sin(phi) cos(psi) + A cos(phi) sin(psi)
    assert math.hypot(a, b) == pytest.approx(0.12, abs=0.005)  # measured 0.120
    assert math.atan2(a, b) == pytest.approx(0.7, abs=0.05)
    assert abs(c) < 0.003


def test_gyro_bias_shows_in_the_gyro():
    truth, samples = _collect("effect-gyro-bias", 60.0)
    d = [s.gyro_z - truth[round(s.t, 3)].r for s in samples
         if isinstance(s, Imu) and round(s.t, 3) in truth]
    assert np.mean(d) == pytest.approx(0.01, abs=3e-4)  # white noise only otherwise


def test_gps_latency_delays_the_fixes():
    truth, samples = _collect("effect-gps-latency", 60.0)
    o = GeoOrigin(*get("effect-gps-latency").origin)

    def err(lag: float) -> float:
        e = []
        for s in samples:
            key = round(s.t - lag, 3) if isinstance(s, GnssFix) else None
            if key in truth:
                n = float(pymap3d.geodetic2enu(s.lat_deg, s.lon_deg, 0.0, o.lat0, o.lon0, 0.0)[1])
                e.append(n - truth[key].north)
        return float(np.sqrt(np.mean(np.square(e))))

    assert err(0.6) < err(0.0) and err(0.6) < err(1.2)


def _throttle_for(speed: float) -> float:
    """The effect boat's straight-line throttle for ``speed`` (m/s)."""
    return math.sqrt((NOMINAL_BOAT.d_u * speed + NOMINAL_BOAT.d_uu * speed**2)
                     / NOMINAL_BOAT.t_max)


def test_thrust_nonlinearity_changes_the_speed_for_the_same_command():
    clean, _ = _collect("clean", 30.0)
    eff, _ = _collect("effect-thrust-nonlinearity", 30.0)
    assert _speed(clean, 15, 30) == pytest.approx(1.5, abs=0.01)
    th = _throttle_for(1.5)  # the hull's feed-forward throttle for 1.5 m/s
    cubic = dataclasses.replace(NOMINAL_BOAT, thrust_exponent=3.0)
    # thrust 12.5 th^3 instead of 12.5 th^2: 1.24 m/s
    assert _speed(eff, 15, 30) == pytest.approx(cubic.steady_speed(th), abs=0.01)
    assert _speed(eff, 15, 30) < 1.4


def test_surge_yaw_coupling_slows_the_boat_in_turns_only():
    clean, _ = _collect("clean", 51.0)
    eff, _ = _collect("effect-surge-yaw-coupling", 51.0)
    assert _speed(eff, 20, 30) == pytest.approx(_speed(clean, 20, 30), abs=0.005)  # straight
    # circle at 0.3 rad/s: u' = -(d/m) u - 3 u r^2: measured 1.45 -> 1.19 m/s
    assert _speed(eff, 40, 50) < _speed(clean, 40, 50) - 0.15


def test_quadratic_drag_and_sideslip():
    clean, _ = _collect("clean", 30.0)
    drag, _ = _collect("effect-quadratic-drag", 30.0)
    slip, _ = _collect("effect-sideslip", 30.0)
    p = NOMINAL_BOAT
    u = _speed(drag, 15, 30)
    # force balance with the hull's own drag plus the injected 1.5 u^2
    assert (p.d_u + p.d_uu * u) * u + 1.5 * u * u == pytest.approx(
        p.thrust(_throttle_for(1.5)), abs=0.05)
    v = np.mean([tr.v_r for t, tr in slip.items() if 15 <= t <= 30])
    # side force 2 u^2 against the sway damping (y_v0 + y_vu u) v + y_vv v^2, u = 1.5
    a, b, c = p.y_vv, p.y_v0 + p.y_vu * 1.5, -2.0 * 1.5**2
    assert v == pytest.approx((-b + math.sqrt(b * b - 4 * a * c)) / (2 * a), abs=0.005)
    assert abs(np.mean([tr.v_r for t, tr in clean.items() if 15 <= t <= 30])) < 0.002


def test_waves_move_the_boat_at_the_wave_period():
    truth, _ = _collect("effect-waves", 40.0)
    z = np.array([tr.down for t, tr in sorted(truth.items()) if t >= 10.0])
    assert z.std() > 0.07  # 0.15 m amplitude: std 0.11 m
    crossings = np.sum(np.diff(np.sign(z - z.mean())) != 0)
    # 2 zero crossings per encounter period (2.5 s, Doppler-shifted by the boat's speed)
    assert 10 < crossings < 40
    assert truth[20.0].effects["wave_oscillation.period"] == 2.5


def test_two_effects_at_once():
    truth, _ = _collect("effect-two", 2.0)
    e = truth[2.0].effects
    assert e["water_current.north"] == 0.2 and e["compass_deviation.amplitude"] == 0.1


def test_force_effects_are_applied_to_a_surface_plant_exactly_once():
    p = NOMINAL_BOAT
    plant = ForcedRudderBoat(p)
    plant.reset(u=1.0)
    env = Environment()
    f = np.array([-2.0, 0.0, 0.0])  # 2 N pushing south, boat heading north
    th = math.sqrt((p.d_u * 1.5 + p.d_uu * 1.5**2 + 2.0) / p.t_max)
    for k in range(3000):
        plant.step(0.01, Command(throttle=th, external_force_world=f), env, k * 0.01)
    # steady: d_u u + d_uu u^2 = T(th) - 2 N  ->  u = 1.5 m/s (twice applied: 1.26 m/s)
    assert plant.x[6] == pytest.approx(1.5, abs=1e-3)


def test_external_force_effect_rotates_body_forces_into_the_earth_frame():
    f = external_force_ned((Effect("quadratic_drag", {"coefficient": 2.0}),), 1.0, 0.0,
                           math.pi / 2, 3.0)
    assert f == pytest.approx([0.0, -2.0, 0.0], abs=1e-12)  # heading east: drag points west
    assert external_force_ned((Effect("gyro_bias", {"z": 0.1}),), 1.0, 0.0, 0.0, 3.0) is None
    f = external_force_ned((Effect("surge_yaw_coupling", {"coefficient": 3.0}),), 1.5, 0.3,
                           0.0, 3.15)
    assert f[0] == pytest.approx(-3.15 * 3.0 * 1.5 * 0.09)
