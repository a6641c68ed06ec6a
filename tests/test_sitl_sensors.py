"""Sensor models: their errors have the configured statistics, and are reproducible."""

from __future__ import annotations

import math

import numpy as np
import pymap3d
import pytest

from onboard.core.messages import Attitude, DvlPosition, DvlVelocity, GnssFix, Heading, Imu
from onboard.sitl.sensors import (
    A50_FOM,
    ActuatorConfig,
    ActuatorModel,
    Compass,
    CompassConfig,
    DepthConfig,
    DepthSensor,
    Dvl,
    DvlConfig,
    GeoOrigin,
    Gnss,
    GnssConfig,
    HeadingInvalid,
    ImuConfig,
    PwmChannel,
    WorldView,
    sensor_rng,
)
from onboard.sitl.sensors import (
    Imu as ImuSensor,
)
from onboard.sitl.truth import TruthRecord

ORIGIN = GeoOrigin(41.49, -71.42)


def _truth(t: float = 0.0, *, north=10.0, east=-5.0, down=0.0, yaw=0.5, u=1.0, v=0.0, w=0.0,
           r=0.0) -> TruthRecord:
    return TruthRecord(t=t, north=north, east=east, down=down, roll=0.0, pitch=0.0, yaw=yaw,
                       u=u, v=v, w=w, p=0.0, q=0.0, r=r, u_r=u, v_r=v, w_r=w)


def _view(t: float, truth: TruthRecord, **kw) -> WorldView:
    c, s = math.cos(truth.yaw), math.sin(truth.yaw)
    return WorldView(t=t, truth=truth, specific_force=(0.0, 0.0, -9.81),
                     angular_rate=(0.0, 0.0, truth.r),
                     v_ned=(c * truth.u - s * truth.v, s * truth.u + c * truth.v, truth.w), **kw)


def _ne(fix: GnssFix) -> tuple[float, float]:
    """North/east (m) of a fix, back through pymap3d (the simulator's own geodesy)."""
    e, n, _ = pymap3d.geodetic2enu(fix.lat_deg, fix.lon_deg, 0.0, ORIGIN.lat0, ORIGIN.lon0, 0.0)
    return float(n), float(e)


def _run_gnss(cfg: GnssConfig, n: int, seed: int = 3, **truth_kw) -> list[GnssFix]:
    g = Gnss(cfg, ORIGIN, sensor_rng(seed, "gnss"))
    out = []
    for k in range(n):
        t = k / cfg.rate_hz
        out += g.measure(_view(t, _truth(t, **truth_kw)))
    return out


def test_gnss_white_noise_std_matches_configured():
    fixes = _run_gnss(GnssConfig(rate_hz=5.0, position_std_m=1.0, drift_std_m=0.0), 4000)
    err = np.array([_ne(f) for f in fixes]) - (10.0, -5.0)
    # measured 0.99 / 1.01 m over 4000 fixes; the sample std of 4000 normals is within 5 %
    assert np.allclose(err.std(axis=0), 1.0, rtol=0.06)
    assert np.all(np.abs(err.mean(axis=0)) < 0.06)


def test_gnss_drift_is_slow_and_of_configured_size():
    cfg = GnssConfig(rate_hz=1.0, position_std_m=0.0, drift_std_m=2.0, drift_tau_s=30.0)
    fixes = _run_gnss(cfg, 6000)
    e = np.array([_ne(f)[0] for f in fixes]) - 10.0
    lag1 = np.corrcoef(e[:-1], e[1:])[0, 1]
    assert lag1 == pytest.approx(math.exp(-1.0 / 30.0), abs=0.01)  # measured 0.967
    assert e.std() == pytest.approx(2.0, rel=0.2)  # measured 2.00 m


def test_gnss_sog_cog_derive_from_noisy_true_velocity():
    fixes = _run_gnss(GnssConfig(velocity_std_mps=0.05), 2000, yaw=0.5, u=2.0)
    sog = np.array([f.sog_mps for f in fixes])
    cog = np.array([f.cog_rad for f in fixes])
    assert sog.mean() == pytest.approx(2.0, abs=0.01)
    assert sog.std() == pytest.approx(0.05, rel=0.1)
    assert cog.mean() == pytest.approx(0.5, abs=0.005)


def test_no_gnss_fix_underwater_and_fixes_at_the_surface():
    assert _run_gnss(GnssConfig(), 50, down=5.0) == []
    assert _run_gnss(GnssConfig(), 50, down=0.31) == []
    assert len(_run_gnss(GnssConfig(), 50, down=0.2)) == 50


def test_gnss_latency_reports_the_past_position_late():
    cfg = GnssConfig(rate_hz=5.0, position_std_m=0.0, drift_std_m=0.0, latency_s=0.6)
    g = Gnss(cfg, ORIGIN, sensor_rng(0, "gnss"))
    got = []
    for k in range(50):
        t = k * 0.2
        tr = _truth(t, north=3.0 * t)  # moving north at 3 m/s
        got += g.measure(_view(t, tr))
    assert got[0].t == pytest.approx(0.6)
    for f in got:
        assert _ne(f)[0] == pytest.approx(3.0 * (f.t - 0.6), abs=1e-6)


def test_gnss_outages_remove_fixes():
    fixes = _run_gnss(GnssConfig(rate_hz=1.0, outage_rate_hz=0.01, outage_mean_s=20.0), 3000)
    # expected availability 1 / (1 + 0.01 * 20) = 0.83; measured 0.80
    assert 0.7 < len(fixes) / 3000 < 0.95


def test_imu_injected_gyro_bias_is_visible_and_noise_as_configured():
    cfg = ImuConfig(rate_hz=100.0, gyro_noise_std=0.003, gyro_bias_std=0.0, gyro_bias_walk=0.0,
                    gyro_bias_injected=(0.0, 0.0, 0.01))
    imu = ImuSensor(cfg, sensor_rng(1, "imu"))
    gz = np.array([imu.measure(_view(k / 100, _truth(r=0.2)))[0].gyro_z for k in range(5000)])
    assert (gz - 0.2).mean() == pytest.approx(0.01, abs=2e-4)  # measured 0.01002
    assert gz.std() == pytest.approx(0.003, rel=0.05)
    assert imu.error_state()["sensor.gyro_bias_z"] == pytest.approx(0.01)


def test_imu_turn_on_bias_differs_per_seed_and_repeats_per_seed():
    def bias(seed):
        imu = ImuSensor(ImuConfig(gyro_bias_std=1e-3), sensor_rng(seed, "imu"))
        return imu.total_gyro_bias.copy()
    assert np.array_equal(bias(4), bias(4))
    assert not np.array_equal(bias(4), bias(5))


def test_imu_reports_specific_force():
    imu = ImuSensor(ImuConfig(accel_noise_std=0.0, accel_bias_std=0.0, accel_bias_walk=0.0),
                    sensor_rng(0, "imu"))
    s = imu.measure(_view(0.0, _truth()))[0]
    assert isinstance(s, Imu)
    assert (s.accel_x, s.accel_y, s.accel_z) == (0.0, 0.0, -9.81)


def test_compass_deviation_follows_amplitude_sin_heading_plus_phase():
    cfg = CompassConfig(noise_std_rad=0.0, hard_iron_rad=0.1, hard_iron_phase_rad=0.7,
                        offset_rad=0.02)
    c = Compass(cfg, sensor_rng(0, "compass"))
    for psi in np.linspace(-3.0, 3.0, 13):
        out = c.measure(_view(0.0, _truth(yaw=float(psi))))
        h = next(s for s in out if isinstance(s, Heading))
        a = next(s for s in out if isinstance(s, Attitude))
        err = math.remainder(h.heading_rad - psi, 2 * math.pi)
        assert err == pytest.approx(0.02 + 0.1 * math.sin(psi + 0.7), abs=1e-9)
        assert math.remainder(a.yaw_rad - h.heading_rad, 2 * math.pi) == pytest.approx(0.0)


def test_compass_motor_interference_grows_with_thrust():
    c = Compass(CompassConfig(noise_std_rad=0.0, motor_rad_per_thrust=0.05),
                sensor_rng(0, "compass"))
    h = c.measure(_view(0.0, _truth(yaw=1.0), thrust=0.8))[0]
    assert h.heading_rad - 1.0 == pytest.approx(0.04)


def test_compass_sends_no_heading_in_its_invalid_windows_and_the_same_ones_after():
    """In ``invalid_windows`` no Heading (a HeadingInvalid per epoch when asked), the AHRS
    attitude goes on; the headings after the window are those of a compass without it."""
    cfg = CompassConfig(invalid_windows=((0.5, 0.3),))
    plain = Compass(CompassConfig(), sensor_rng(4, "compass"))
    gappy = Compass(cfg, sensor_rng(4, "compass"))
    asked = Compass(cfg, sensor_rng(4, "compass"))
    asked.report_invalid = True
    for k in range(15):
        v = _view(k / 10.0, _truth(yaw=1.0))
        a, b, c = plain.measure(v), gappy.measure(v), asked.measure(v)
        if 5 <= k < 8:
            assert [type(s) for s in b] == [Attitude]
            assert [type(s) for s in c] == [HeadingInvalid, Attitude]
            assert b[0] == a[1]
        else:
            assert a == b == c and isinstance(a[0], Heading)


def test_dvl_reports_invalid_not_zero_when_lock_is_lost():
    d = Dvl(DvlConfig(max_altitude_m=30.0, dropout_rate_hz=0.0), sensor_rng(0, "dvl"))
    tr = _truth(down=10.0, u=1.2, v=0.1)
    ok = d.measure(_view(0.0, tr, altitude=20.0))
    lost = d.measure(_view(0.2, tr, altitude=35.0))
    v_ok = next(s for s in ok if isinstance(s, DvlVelocity))
    v_lost = next(s for s in lost if isinstance(s, DvlVelocity))
    assert v_ok.valid and v_ok.vx == pytest.approx(1.2, abs=0.05) and v_ok.altitude_m > 19
    assert not v_lost.valid and v_lost.altitude_m is None and v_lost.fom_mps >= 1.0
    assert d.lock_losses == 1
    assert any(isinstance(s, DvlPosition) for s in ok)


def test_dvl_random_dropouts_and_water_track():
    d = Dvl(DvlConfig(dropout_rate_hz=0.05, dropout_mean_s=2.0, water_track=True),
            sensor_rng(2, "dvl"))
    tr = _truth(down=10.0, u=1.0)
    tr.u_r = 0.4  # 0.6 m/s of current from behind
    out = [s for k in range(3000) for s in d.measure(_view(k * 0.2, tr, altitude=10.0))]
    bottom = [s for s in out if isinstance(s, DvlVelocity) and s.track == "bottom"]
    water = [s for s in out if isinstance(s, DvlVelocity) and s.track == "water" and s.valid]
    invalid = sum(not s.valid for s in bottom) / len(bottom)
    assert 0.02 < invalid < 0.2  # expected 0.05 * 2 / (1 + 0.1) = 0.09; measured 0.11
    assert np.mean([s.vx for s in water]) == pytest.approx(0.4, abs=0.005)


def _dvl_run(fom: dict[str, float], seed: int = 5, n: int = 5000):
    """A DVL with the figure of merit ``fom`` (:class:`DvlConfig` fields) 10 m above the
    bottom at 1 m/s, without dropouts: its bottom-track reports, its noise's std (m/s)."""
    cfg = DvlConfig(dropout_rate_hz=0.0, **fom)
    d = Dvl(cfg, sensor_rng(seed, "dvl"))
    tr = _truth(down=10.0, u=1.0)
    out = [s for k in range(n) for s in d.measure(_view(k * 0.2, tr, altitude=10.0))
           if isinstance(s, DvlVelocity)]
    return out, cfg.velocity_std_mps + cfg.velocity_std_per_m * 10.0


def test_dvl_figure_of_merit_is_an_estimate_that_wanders_not_the_noise():
    """The fom (and the covariance, its square) varies report to report, log-normal
    about 0.55 times the noise's std with a memory of ~0.15 s, independently of the
    report's own error; the noise keeps the configured std."""
    out, std = _dvl_run(A50_FOM)
    good = [s for s in out if s.valid]
    fom = np.array([s.fom_mps for s in good])
    log_ratio = np.log(fom / std)
    assert 0.27 < log_ratio.std() < 0.33  # fom_log_std 0.3
    assert 0.2 < np.corrcoef(log_ratio[:-1], log_ratio[1:])[0, 1] < 0.33  # exp(-0.2 / 0.15)
    assert np.sqrt(np.mean(fom ** 2)) / std == pytest.approx(0.55, rel=0.03)  # fom_scale
    assert all(s.covariance == (f * f, 0.0, 0.0, 0.0, f * f, 0.0, 0.0, 0.0, f * f)
               for s, f in zip(good, fom))
    err = np.array([s.vx - 1.0 for s in good])
    assert err.std() == pytest.approx(std, rel=0.05)  # the noise is the configured one
    assert abs(np.corrcoef(np.abs(err), fom)[0, 1]) < 0.05  # the fom does not know it


def test_dvl_flags_a_few_locked_reports_invalid_as_the_a50_does():
    """~3 % of the locked reports come flagged invalid with their altitude and a velocity
    2.5 times noisier, their fom 1.5 times higher; they are not lock losses."""
    out, std = _dvl_run(A50_FOM)
    flagged = [s for s in out if not s.valid]
    assert 0.02 < len(flagged) / len(out) < 0.04
    assert all(s.altitude_m is not None and s.altitude_m > 9.5 for s in flagged)
    assert np.std([s.vx - 1.0 for s in flagged]) == pytest.approx(2.5 * std, rel=0.15)
    assert np.median([s.fom_mps for s in flagged]) > 1.2 * np.median(
        [s.fom_mps for s in out if s.valid])


def _a50_reports(folder, name: str) -> list[dict]:
    """A capture file's reports, consecutive duplicate lines (the capture's) dropped."""
    import json

    recs, prev = [], None
    for line in (folder / name).read_text().splitlines():
        if line.strip() and line != prev:
            recs.append(json.loads(line))
        prev = line
    return recs


def _neighbour_distance(v: np.ndarray) -> np.ndarray:
    """Each report's velocity minus the mean of its 6 neighbours (3 each side), rows 3..n-4."""
    return np.array([v[i] - np.r_[v[i - 3:i], v[i + 1:i + 4]].mean(axis=0)
                     for i in range(3, len(v) - 3)])


def _lag1_tau(log_f: np.ndarray, dt_s: float) -> float:
    """Correlation time (s) from the lag-1 correlation of a series sampled every dt_s."""
    return -dt_s / math.log(np.corrcoef(log_f[:-1], log_f[1:])[0, 1])


def test_dvl_figure_of_merit_varies_as_the_a50_capture_s(shared_data):
    """Ranges from the capture, the simulated DVL inside them. At rest (the first reports of
    out20210528.txt, below 0.02 m/s): the fom's RMS over the velocity's scatter
    (0.53 about its mean, 0.62 by its neighbours' distance / sqrt(7/6)), the fom's log-std
    (0.10) and memory (0.30 s), and the correlation of the fom's log with the log of the
    report's distance to its neighbours (-0.20: the fom does not predict the error).
    Driven (the circle and straight runs, above 0.05 m/s): the fom's log about its
    log-speed trend, std 0.33-0.34, memory 0.11-0.12 s. 0.4-4.5 % of reports flagged invalid
    with four beams on the bottom. The simulation has no speed trend: its fom's log-std and
    memory lie between the resting and the driven capture's."""
    folder = shared_data / "waterlinked_dvl_a50_json_tank"
    recs = _a50_reports(folder, "out20210528.txt")
    v = np.array([[r["vx"], r["vy"], r["vz"]] for r in recs])
    speed = np.linalg.norm(v, axis=1)
    n_rest = int(np.argmax(speed >= 0.02))  # the ROV sits still, then is driven away
    assert 100 <= n_rest <= 115 and all(r["velocity_valid"] for r in recs[:n_rest])
    v_rest, f_rest = v[:n_rest], np.array([r["fom"] for r in recs[:n_rest]])
    dt = np.median([r["time"] for r in recs]) / 1000.0
    d = _neighbour_distance(v_rest)
    fom_rms = np.sqrt(np.mean(f_rest ** 2))
    scale_lo = fom_rms / np.sqrt(np.mean((v_rest - v_rest.mean(axis=0)) ** 2))
    scale_hi = fom_rms / np.sqrt(np.mean(d ** 2) / (7.0 / 6.0))
    log_std_rest = np.log(f_rest).std()
    tau_rest = _lag1_tau(np.log(f_rest), dt)
    corr_rest = np.corrcoef(np.log(f_rest[3:-3]),
                            np.log(np.sqrt(np.mean(d ** 2, axis=1))))[0, 1]
    assert 0.5 < scale_lo < scale_hi < 0.65
    assert 0.08 < log_std_rest < 0.12 and 0.25 < tau_rest < 0.35
    assert -0.3 < corr_rest < -0.1
    log_std_driven, tau_driven, flagged = [], [], []
    for name in ("out20210528.txt", "out20210528_circle.txt",
                 "out20210528_straight+turn360.txt"):
        recs = _a50_reports(folder, name)
        flagged.append(np.mean([not r["velocity_valid"] and r["altitude"] > 0
                                and all(b["beam_valid"] for b in r["transducers"])
                                for r in recs]))
        if name == "out20210528.txt":
            continue
        idx = np.array([i for i, r in enumerate(recs) if r["velocity_valid"]
                        and math.hypot(r["vx"], r["vy"], r["vz"]) > 0.05])
        lf = np.log([recs[i]["fom"] for i in idx])
        ls = np.log([math.hypot(recs[i]["vx"], recs[i]["vy"], recs[i]["vz"]) for i in idx])
        assert np.corrcoef(lf, ls)[0, 1] > 0.65  # the A50's fom follows the speed
        e = lf - np.polyval(np.polyfit(ls, lf, 1), ls)
        nxt = np.diff(idx) == 1
        log_std_driven.append(e.std())
        tau_driven.append(-dt / math.log(np.corrcoef(e[:-1][nxt], e[1:][nxt])[0, 1]))
    assert 0.3 < min(log_std_driven) <= max(log_std_driven) < 0.37
    assert 0.08 < min(tau_driven) <= max(tau_driven) < 0.15
    assert 0.003 < min(flagged) and max(flagged) < 0.05

    out, std = _dvl_run(A50_FOM)
    good = [s for s in out if s.valid]
    lf = np.log([s.fom_mps for s in good])
    err = np.array([[s.vx - 1.0, s.vy, s.vz] for s in good])
    assert scale_lo < np.sqrt(np.mean(np.exp(2 * lf))) / err.std() < scale_hi
    assert log_std_rest < lf.std() < max(log_std_driven)
    assert min(tau_driven) < _lag1_tau(lf, 0.2) < tau_rest
    d = _neighbour_distance(err)
    corr = np.corrcoef(lf[3:-3], np.log(np.sqrt(np.mean(d ** 2, axis=1))))[0, 1]
    assert abs(corr - corr_rest) < 3.0 / math.sqrt(n_rest - 6)  # as uninformative
    assert min(flagged) < np.mean([not s.valid for s in out]) < max(flagged)


def test_depth_sensor_pressure_is_consistent():
    ds = DepthSensor(DepthConfig(depth_std_m=0.02), sensor_rng(0, "depth"))
    vals = [ds.measure(_view(0.0, _truth(down=20.0)))[0] for _ in range(2000)]
    d = np.array([v.depth_m for v in vals])
    assert d.mean() == pytest.approx(20.0, abs=0.003)
    assert d.std() == pytest.approx(0.02, rel=0.1)
    v = vals[0]
    assert v.pressure_pa == pytest.approx(101325.0 + 1025.0 * 9.80665 * v.depth_m)


def test_actuator_pwm_quantized_saturated_and_deadband_applied_to_the_plant():
    a = ActuatorModel(ActuatorConfig(channels=(
        PwmChannel(channel=1, deadband_us=25), PwmChannel(channel=3, reverse=True))),
        sensor_rng(0, "actuators"))
    eff = a.apply((0.05, 0.5))  # 0.05 * 400 = 20 us: inside the deadband
    assert a.pwm[0] == 1520.0 and eff[0] == 0.0
    assert a.pwm[2] == 1300.0 and eff[1] == pytest.approx(0.5)
    eff = a.apply((1.7, -0.12345))
    assert a.pwm[0] == 1900.0 and eff[0] == 1.0  # saturated
    assert a.pwm[2] == 1549.0 and eff[1] == pytest.approx(-49 / 400)  # 1 us quantization
    out = a.measure(_view(0.0, _truth()))[0]
    assert out.pwm_us[:3] == (1900.0, 0.0, 1549.0)


def test_dvl_default_figure_of_merit_is_the_noise_own_std_and_flags_nothing():
    """Without :data:`A50_FOM` the figure of merit is the noise's std, report by report,
    and no locked report is flagged (what the ESESO's figures are measured with)."""
    out, std = _dvl_run({}, n=500)
    assert all(s.valid and s.fom_mps == pytest.approx(std, rel=1e-12) for s in out)
