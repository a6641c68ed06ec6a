"""AIE and KF against SITL truth (sitl.runner), through the real engine and input mapping.

The README's figures of these runs (speed and heading RMSE per filter and seed, the GNSS
outage) are recomputed and checked against docs/figures.json by tests/test_figures.py,
on the same runs (``validation/reports/runs.py`` flies each once per session). The
tests here state the claims those figures support (orderings, goals, convergence,
coverage), with the goal named where it is not met.
Both filters run with the defaults of the common tuning protocol (docs/aie.md section
2.1): tuned alike, AIE and KF tie on speed (the former goal "AIE <= 0.8 x KF" held only
against a KF at an untuned ``v_d = 1``); the AIE stays ahead on heading.
"""

from __future__ import annotations

import pytest

from validation.reports import runs
from validation.reports.aie_validation import convergence_step, run_sitl, sitl_metrics


@pytest.fixture(scope="module")
def jaiabot():
    return runs.aie_run("jaiabot-turns", 1)


@pytest.fixture(scope="module")
def twin():
    return runs.aie_run("twin-thruster-turns", 1)


def test_jaiabot_turns_aie_and_kf_tuned_alike_tie_on_speed_below_the_raw_gnss_speed(
        jaiabot) -> None:
    m = sitl_metrics(jaiabot)
    a, k, nav = m["aie"], m["kf"], m["nav"]
    print(m)
    # measured seed 1 (docs/figures.json aie.jaiabot_turns.*, seeds 1-3 in docs/aie.md
    # 3.1), both filters at the tuned defaults: speed AIE 0.0458, KF 0.0403, raw GNSS
    # 0.0998 m/s (seeds 1-3: AIE 0.043-0.046, KF 0.036-0.040): the KF is ahead, AIE
    # 1.14x the KF. The former bound, AIE < 0.8 x KF, held only against the KF at its
    # untuned v_d = 1 (0.079). Heading AIE 0.0251 vs KF 0.0275 rad; position 0.96 vs
    # 0.96 m (a tie: both follow the Doppler speed)
    assert a["speed"] < 0.05
    assert a["speed"] < 0.5 * nav["speed"] and k["speed"] < 0.5 * nav["speed"]
    assert a["speed"] < 1.25 * k["speed"]     # a tie within 25 %, the KF ahead
    assert a["heading"] < k["heading"]
    assert a["position"] < 1.3 and a["position"] < 1.1 * k["position"]
    # input estimates against truth.surge_input / yaw_input (the truth is thrust/m11
    # alone; AIE's input also carries the nonlinear drag)
    assert a["surge_input"] < 0.5     # measured 0.431 m/s^2 (0.433 before the tuning)
    # measured 0.445 rad/s^2: the tuned heading axis (r_d 0.29, v_d 1.7, for heading RMSE
    # and an honest heading sigma) lets its input estimate move more (0.253 at r_d 1,
    # v_d 0.3); the tuning's objective does not weigh the input estimates
    assert a["yaw_input"] < 0.5


def test_twin_thruster_turns_aie_and_kf_tie_below_the_raw_gnss_speed(twin) -> None:
    m = sitl_metrics(twin)
    a, k, nav = m["aie"], m["kf"], m["nav"]
    print(m)
    # measured seed 1 (0.3 s motor lag; docs/figures.json aie.twin_thruster_turns.*):
    # speed AIE 0.0535, KF 0.0508, raw 0.0998 m/s (AIE 1.05x the KF: a tie); heading
    # 0.0323 vs 0.0346 rad; position 0.99 vs 0.99 m
    assert a["speed"] < 0.8 * nav["speed"] and k["speed"] < 0.8 * nav["speed"]
    assert a["speed"] < 1.15 * k["speed"]
    assert a["heading"] < 1.01 * k["heading"]
    assert a["position"] < 1.3 and a["position"] < 1.05 * k["position"]
    assert a["surge_input"] < 0.6     # measured 0.429 m/s^2
    assert a["yaw_input"] < 1.15      # measured 1.069 rad/s^2 (1.061 before the tuning)


def test_no_divergence_and_surge_coefficients_converge(jaiabot, twin) -> None:
    for run in (jaiabot, twin):
        h = run.pipelines[0].health()
        assert h.surge.diverged == 0 and h.heading.diverged == 0
    # measured: surge theta within 20 % of its final value after 849 of its 1493 0.2 s
    # steps (170 s; paper: ~100 steps), on the rate innovation; 457 before [sensors.gnss]
    # drift_share, with the relative error's path the same within 0.002: it sits at
    # 0.15-0.17 from step 700 to 850 and one step there now crosses 0.2. The heading
    # coefficients (10 Hz steps, lambda = 0.999) keep adapting
    assert 0 <= convergence_step(jaiabot.theta["surge"]) < 900


_position_coverage = runs.position_coverage


def test_published_position_sigma_covers_the_truth(jaiabot) -> None:
    """``std_north``/``std_east`` against SITL truth (docs/aie.md, "Published
    uncertainty"): per-axis errors within 1 and 2 sigma, ticks after 10 s. Gaussian
    would be 0.68 / 0.95; the aim for 2 sigma is 0.85-0.99."""
    c1a, c2a = _position_coverage(jaiabot, "aie")
    c1k, c2k = _position_coverage(jaiabot, "kf")
    print(f"coverage aie {c1a:.3f}/{c2a:.3f} kf {c1k:.3f}/{c2k:.3f}")
    # measured seed 1: aie 0.95 / 1.00, kf 0.95 / 1.00: conservative since the Doppler
    # speed made the track ~2x better (0.98 m RMS) while the gnss_position_std_m floor (1.5 m,
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
        # measured seed 1 (tuned defaults): aie 0.93 / 1.00 (outage 0.93 / 1.00), kf
        # 0.94 / 1.00 (outage 0.95 / 1.00)
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
        # with a sigma of 130-150 m, before). Measured seed 1 at the tuned defaults: max
        # horizontal error 3.8 m (aie), 3.8 m (kf) (seeds 1-3: aie.gnss_outage.* of
        # docs/figures.json); std_north aie 1.5 m at 25 s, 1.6 at 40 s, 1.8 at 140 s,
        # 1.5 at 175 s; kf 1.5, 1.7, 2.2, 1.5
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

    from validation.reports.aie_validation import _rmse

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
    # measured seed 1 at the tuned defaults: AIE 0.068, KF 0.070 against the raw 0.085
    # m/s (0.80x, 0.82x; before the common tuning AIE 0.066, KF 0.053: the tuning gave
    # the KF's wave figure up for the turning runs, docs/aie.md 2.1; without the
    # accelerometer, 600 s: AIE 0.081, KF 0.093 against 0.073)
    assert a < 0.9 * nav
    assert k < 0.9 * nav


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
    # measured at the tuned defaults: AIE 0.026-0.097 (0.51-0.92x raw, the largest on
    # effect-waves), KF 0.026-0.087 (0.51-0.96x, the largest on effect-waves: 0.070
    # against 0.073; 0.049 before the common tuning, docs/aie.md 2.1)
    assert a < 0.95 * nav
    assert k < (0.99 if scenario == "effect-waves" else 0.95) * nav
