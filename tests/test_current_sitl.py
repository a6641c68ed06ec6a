"""Current pipeline on the SITL scenarios, against truth (error and 2-sigma coverage).

Mode (a) "configured model" uses coefficients identified by the pipeline itself in a
calm-water run of the same vehicle and mission (WVAM step 1), see
onboard/tools/reports/current_validation.py. Measured figures (seed 1, full durations) are in
the comments; the bounds leave margin for other seeds. Long runs are marked slow.
"""

from __future__ import annotations

import pytest

import onboard.tools.reports.current_validation as cv


def _mode_a(scenario: str, config: str, duration: float, **extra):
    model = cv.calm_model(scenario, config, duration=300.0)
    return cv.run(scenario, {"model": model, **extra}, config, duration=duration, seed=1)


@pytest.mark.slow
def test_gavia_tidal_configured_model_beats_the_paper_on_every_axis():
    r = _mode_a("gavia-tidal", "torpedo-auv", 600.0)
    m = cv.metrics(r, after=60.0)
    # measured (600 s): error std N/E/D 0.017 / 0.009 / 0.006 m/s vs the paper's
    # 0.094 / 0.066 / 0.032; 2-sigma coverage 0.94 / 1.00 / 1.00; converged in < 1 s
    for ax, paper in zip(("north", "east", "down"), cv.PAPER_GAVIA_STD):
        assert m[ax]["std"] < paper
    assert m["north"]["cover2"] > 0.85 and m["east"]["cover2"] > 0.9
    peak, peaking, settle = cv.transient(r)
    assert settle < 10.0


@pytest.mark.slow
def test_gavia_tidal_without_model_reports_along_track_as_unknown():
    """A straight run with no surge model cannot separate the along-track current from the
    through-water speed: the estimate is poor, and the one-sigma says so."""
    r = cv.run("gavia-tidal", {}, "torpedo-auv", duration=300.0, seed=1)
    m = cv.metrics(r, after=60.0)
    # measured (300 s, seeds 1 / 2): north rms 1.17 / 1.26 m/s with sigma ~1.09 (coverage
    # 1.00); east rms 0.047 / 0.046 with sigma 0.13 / 0.15 (coverage 1.00). The steady
    # propeller-torque roll makes the sway net-weight term a near-constant side force that
    # trades against a cross-track current within its prior: with the loose prior
    # (theta_std, 1 m/s^2) east was 0.058 / 0.052 at sigma 0.24 / 0.25; with the net-weight
    # prior (net_weight_std, 0.02 g) it is back to the 0.047 of before attitude reached the
    # model (docs/current.md, "Net-weight prior")
    assert m["north"]["cover2"] > 0.9
    assert m["north"]["sigma"] > 0.5
    assert m["east"]["rms"] < 0.1
    assert m["east"]["cover2"] > 0.9
    assert m["east"]["sigma"] < 0.2


@pytest.mark.slow
def test_spheroid_sawtooth_configured_model_rms_below_3cm():
    r = _mode_a("spheroid-sawtooth", "spheroid", 600.0)
    m = cv.metrics(r, after=100.0)
    # measured: rms N/E 0.006 / 0.010 m/s, 2-sigma coverage 0.96 / 0.84 (the heading
    # switches: peak 0.029 m/s just after each switch, 0.008 rms between them)
    assert m["north"]["rms"] <= 0.03 and m["east"]["rms"] <= 0.03
    assert m["north"]["cover2"] > 0.8 and m["east"]["cover2"] > 0.75


@pytest.mark.slow
def test_spheroid_sawtooth_flow_observer():
    r = _mode_a("spheroid-sawtooth", "spheroid", 600.0, observer="flow")
    m = cv.metrics(r, after=100.0)
    # measured: rms N/E 0.012 / 0.023 m/s, coverage 0.99 / 0.99 (the KF: 0.006 / 0.010)
    assert m["north"]["rms"] < 0.1 and m["east"]["rms"] < 0.1


@pytest.mark.slow
def test_surface_boat_constant_current_without_model():
    r = cv.run("effect-current", {}, "rudder-boat", duration=600.0, seed=1)
    m = cv.metrics(r, after=120.0)
    # measured: rms N/E 0.007 / 0.007 m/s after 120 s, 2-sigma coverage 1.00 / 1.00
    assert m["north"]["rms"] <= 0.05 and m["east"]["rms"] <= 0.05
    assert m["north"]["cover2"] > 0.9 and m["east"]["cover2"] > 0.9


@pytest.mark.slow
def test_surface_boat_tracks_a_current_changing_over_minutes():
    r = cv.run(cv.boat_tidal_scenario(), {}, "rudder-boat", duration=900.0, seed=1)
    m = cv.metrics(r, after=120.0)
    # measured: rms N/E 0.022 / 0.033 m/s, coverage 1.00 / 1.00 (0.3 m/s amplitude, 10 min)
    assert m["north"]["rms"] <= 0.05 and m["east"]["rms"] <= 0.05
    assert m["north"]["cover2"] > 0.85 and m["east"]["cover2"] > 0.85


def test_surface_boat_short_run_converges_after_turns():
    """Fast check (150 s of effect-current): the first circle makes the current observable."""
    r = cv.run("effect-current", {}, "rudder-boat", duration=150.0, seed=2)
    m = cv.metrics(r, after=90.0)
    # measured: rms N/E ~0.005 m/s after 90 s, coverage 1.0
    assert m["north"]["rms"] < 0.05 and m["east"]["rms"] < 0.05
    assert m["north"]["cover2"] > 0.9 and m["east"]["cover2"] > 0.9
