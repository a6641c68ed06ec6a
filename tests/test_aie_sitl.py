"""AIE and KF against SITL truth (sitl.runner), through the real engine and input mapping.

The README's figures of these runs (speed and heading RMSE per filter and seed, the GNSS
outage) are recomputed and checked against docs/figures.json by tests/test_figures.py,
on the same runs (``onboard/tools/reports/runs.py`` flies each once per session). The
tests here state the claims those figures support (orderings, goals, convergence,
coverage), with the goal named where it is not met.
The goal: AIE speed RMSE <= 0.8 x KF and < 0.10 m/s; AIE heading below the KF.
"""

from __future__ import annotations

import pytest

from onboard.tools.reports import runs
from onboard.tools.reports.aie_validation import convergence_step, run_sitl, sitl_metrics


@pytest.fixture(scope="module")
def jaiabot():
    return runs.aie_run("jaiabot-turns", 1)


@pytest.fixture(scope="module")
def twin():
    return runs.aie_run("twin-thruster-turns", 1)


def test_jaiabot_turns_aie_beats_the_kf_and_the_raw_gnss_speed(jaiabot) -> None:
    m = sitl_metrics(jaiabot)
    a, k, nav = m["aie"], m["kf"], m["nav"]
    print(m)
    # measured (docs/aie.md 3.1, seeds 1-3, the hull with its 0.3 s shaft lag): speed AIE
    # 0.050-0.052, KF 0.078-0.079 against the raw GNSS speed over ground 0.100-0.101 m/s
    # (AIE 0.65x the KF, the goal 0.8x). The KF's default thrust map is wrong for this
    # boat; its input-bias state takes most of that out (without it: KF 0.094-0.097, AIE
    # 0.53x; the identified model of config/sitl-jaiabot.toml:
    # aie.jaiabot_turns.speed_rmse.kf_identified).
    # Heading 0.0228 vs 0.0242 rad; position 0.96 vs 0.96 m (a tie: both follow the
    # Doppler speed)
    assert a["speed"] < 0.08
    assert a["speed"] < 0.8 * nav["speed"]
    assert a["speed"] < 0.8 * k["speed"]
    assert k["speed"] < nav["speed"]
    assert a["heading"] < k["heading"]
    assert a["position"] < 1.3 and a["position"] < 1.1 * k["position"]
    # input estimates against truth.surge_input / yaw_input (the truth is thrust/m11
    # alone; AIE's input also carries the nonlinear drag)
    assert a["surge_input"] < 0.5     # measured 0.433 m/s^2 (0.425 without the shaft lag)
    assert a["yaw_input"] < 0.31      # measured 0.253 rad/s^2 (0.257)


def test_twin_thruster_turns_aie_beats_the_kf_and_the_raw_gnss_speed(twin) -> None:
    m = sitl_metrics(twin)
    a, k, nav = m["aie"], m["kf"], m["nav"]
    print(m)
    # measured seed 1 (0.3 s motor lag): see docs/figures.json aie.twin_thruster_turns.*;
    # heading 0.0361 vs 0.0389 rad (0.0313 each with the former 0.15 s lag); position
    # 0.99 vs 0.99 m; surge input 0.429 m/s^2
    assert a["speed"] < 0.8 * nav["speed"] and k["speed"] < nav["speed"]
    assert a["speed"] < k["speed"]
    assert a["heading"] < 1.01 * k["heading"]
    assert a["position"] < 1.3 and a["position"] < 1.05 * k["position"]
    assert a["surge_input"] < 0.6
    # measured 1.061 rad/s^2 with the 0.3 s motor lag (the former bound, 1.0, held with
    # a 0.15 s lag)
    assert a["yaw_input"] < 1.15


def test_no_divergence_and_surge_coefficients_converge(jaiabot, twin) -> None:
    for run in (jaiabot, twin):
        h = run.pipelines[0].health()
        assert h["surge.diverged"] == 0 and h["heading.diverged"] == 0
    # measured: surge theta within 20 % of its final value after 461 of its 0.2 s steps
    # (92 s; paper: ~100 steps), on the rate innovation; the heading coefficients (10 Hz
    # steps, lambda = 0.999) keep adapting
    assert 0 <= convergence_step(jaiabot.theta["surge"]) < 750


_position_coverage = runs.position_coverage


def test_published_position_sigma_covers_the_truth(jaiabot) -> None:
    """``std_north``/``std_east`` against SITL truth (docs/aie.md, "Published
    uncertainty"): per-axis errors within 1 and 2 sigma, ticks after 10 s. Gaussian
    would be 0.68 / 0.95; the aim for 2 sigma is 0.85-0.99."""
    c1a, c2a = _position_coverage(jaiabot, "aie")
    c1k, c2k = _position_coverage(jaiabot, "kf")
    print(f"coverage aie {c1a:.3f}/{c2a:.3f} kf {c1k:.3f}/{c2k:.3f}")
    # measured seed 1: aie 0.95 / 1.00, kf 0.95 / 1.00: conservative since the Doppler
    # speed made the track ~2x better (0.98 m RMS) while the gnss_std_m floor (1.5 m,
    # the configured one-fix sigma) stayed; the Gaussian 0.68 / 0.95 is not met
    for c1, c2 in ((c1a, c2a), (c1k, c2k)):
        assert c2 >= 0.85
        assert 0.5 <= c1


def test_position_sigma_grows_in_a_gnss_outage_and_covers_the_truth() -> None:
    """fault-gnss-outage (no fix 30-150 s): the sigma grows while the fixes are missing,
    drops when they return, and still covers the error."""
    import numpy as np

    run = runs.aie_run("fault-gnss-outage", 1)
    for p in ("aie", "kf"):
        c1, c2 = _position_coverage(run, p)
        o1, o2 = _position_coverage(run, p, 30.0, 150.0)
        print(f"{p}: coverage {c1:.3f}/{c2:.3f}, in the outage {o1:.3f}/{o2:.3f}")
        # measured seed 1: aie 0.83 / 1.00 (outage 0.70 / 1.00), kf 0.87 / 1.00
        # (outage 0.78 / 1.00)
        assert c2 >= 0.85
        assert o2 >= 0.9 and o1 >= 0.5
        sd = run.est[f"{p}.std_north"]
        err = np.hypot(run.est[f"{p}.north"] - run.truth["north"],
                       run.est[f"{p}.east"] - run.truth["east"])
        out = (run.t >= 30.0) & (run.t < 150.0)
        at = {x: float(sd[np.searchsorted(run.t, x)]) for x in (25.0, 40.0, 140.0, 175.0)}
        print(p, "std_north", at, "max error in the outage", np.nanmax(err[out]))
        # dead reckoning through the 120 s outage: the position follows the speed and
        # heading estimates, so neither the error nor the sigma balloons (it was held,
        # with a sigma of 130-150 m, before). Measured: max horizontal error 5.2 m (aie),
        # 15.1 m (kf: its thrust map is wrong; seeds 1-3: aie.gnss_outage.* of
        # docs/figures.json); std_north aie 1.5 m at 25 s, 1.6 at 40 s,
        # 1.7 at 140 s, 1.5 at 175 s (max 2.7 m); kf 1.5, 1.9, 2.9, 1.5 (max 8.6 m)
        assert np.nanmax(err[out]) < (10.0 if p == "aie" else 25.0)
        assert at[25.0] < 4.0 and at[40.0] >= at[25.0] and at[140.0] < 15.0
        assert at[175.0] < 1.5 * at[25.0]


def _degraded(name: str, start: float, duration: float, factor: float):
    """Scenario ``name`` with the receiver's white position noise ``factor`` times larger
    from ``start`` for ``duration`` s, and its reported ``h_acc_m`` saying so."""
    import dataclasses

    from onboard.sitl.scenarios import get

    sc = get(name)
    g = dataclasses.replace(sc.sensors.gnss,
                            degraded_windows=((start, duration, factor),))
    return dataclasses.replace(sc, sensors=dataclasses.replace(sc.sensors, gnss=g))


def test_receiver_accuracy_as_noise_through_a_multipath_period() -> None:
    """jaiabot-turns for 90 s with 5x the position noise from 30 s on (reported in
    h_acc_m): taking each fix's own accuracy (gnss_accuracy, default) against the
    configured 1.5 m always, RMSE 40-90 s. Full 300 s runs on seeds 1-3: docs/aie.md."""
    import numpy as np

    from onboard.tools.reports.aie_validation import _rmse

    sc = _degraded("jaiabot-turns", 30.0, 60.0, 5.0)
    res = {}
    for acc in (True, False):
        run = run_sitl(sc, duration=90.0, seed=1, aie_table={"gnss_accuracy": acc})
        w = run.t >= 40.0
        for p in ("aie", "kf"):
            e = run.est
            res[acc, p] = (
                _rmse((e[f"{p}.speed"] - run.truth["speed"])[w]),
                _rmse(np.hypot(e[f"{p}.north"] - run.truth["north"],
                               e[f"{p}.east"] - run.truth["east"])[w]))
    print(res)
    # measured seed 1: position AIE 1.13 vs 1.51 m, KF 1.16 vs 1.50 m; speed AIE 0.0465
    # vs 0.0465, KF 0.0994 vs 0.0991 m/s (a tie: the Doppler speed carries the speed,
    # and its noise is not degraded by code multipath)
    for p in ("aie", "kf"):
        assert res[True, p][1] < 0.85 * res[False, p][1]
        assert res[True, p][0] < 1.02 * res[False, p][0]


def test_effect_waves_aie_and_kf_below_the_raw_speed() -> None:
    """effect-waves (undeclared 2.5 s regular waves moving the boat +-0.38 m/s), first
    120 s: between fixes the published speed follows the accelerometer (imu_aiding), so
    the wave's acceleration the first-order model lacks is in it. Full 600 s runs, seeds
    1-3: docs/aie.md 3.1.1."""
    m = sitl_metrics(run_sitl("effect-waves", duration=120.0, seed=1))
    a, k, nav = m["aie"]["speed"], m["kf"]["speed"], m["nav"]["speed"]
    print(f"effect-waves 120 s: aie {a:.4f} kf {k:.4f} raw {nav:.4f}")
    # measured seed 1: AIE 0.066, KF 0.053 against the raw 0.085 m/s (without the
    # accelerometer, 600 s: AIE 0.088, KF 0.091 against 0.073)
    assert a < 0.9 * nav
    assert k < 0.8 * nav


EFFECT_ROWS = ("clean", "effect-current", "effect-sideslip", "effect-waves",
               "effect-gps-latency", "effect-thrust-nonlinearity", "effect-quadratic-drag",
               "effect-surge-yaw-coupling", "effect-compass-deviation", "effect-heading-bias",
               "effect-gyro-bias", "effect-two")


@pytest.mark.slow
@pytest.mark.parametrize("scenario", EFFECT_ROWS)
def test_every_rudder_boat_effect_scenario_aie_and_kf_below_the_raw_speed(scenario) -> None:
    """docs/aie.md 3.1.1, seed 1, 600 s: the AIE and the KF speed below the raw receiver
    speed at the ticks on every surface-boat effect scenario."""
    m = runs.aie_metrics(scenario, 1)
    a, k, nav = m["aie"]["speed"], m["kf"]["speed"], m["nav"]["speed"]
    print(f"{scenario}: aie {a:.4f} kf {k:.4f} raw {nav:.4f}")
    # measured: AIE 0.027-0.096 (0.52-0.86x raw, the largest on effect-waves and
    # effect-gps-latency), KF 0.040-0.101 (0.67-0.89x)
    assert a < 0.95 * nav
    assert k < 0.95 * nav
