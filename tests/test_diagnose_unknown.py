"""``onboard diagnose`` on effects outside its catalog (issue 16, item 2).

Each scenario injects an effect no module of ``onboard/offline/closure/effects`` describes; the
diagnosis must either name a catalog effect that truly matches it (with what is
different, e.g. drift per window) or report ``unexplained`` with the channel and the
regressor that carries the structure, and never force the nearest name. Seed 1, the
rudder boat of the effect scenarios, ``config/sitl-rudder-boat.toml``; measured figures
beside each bound. The thruster swap runs in the default suite; the others (about a
minute each) with ``-m slow``; the per-channel ``unexplained`` logic itself is pinned
fast in tests/test_closure_synthetic.py.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from onboard.core import config
from onboard.offline.diagnose import diagnose
from onboard.sitl.runner import run_to_tlog

CONFIG = Path(__file__).resolve().parent.parent / "config"
CFG = CONFIG / "sitl-rudder-boat.toml"


def _diagnose(name: str, tmp_path: Path, cfg: Path = CFG) -> dict:
    run_to_tlog(name, tmp_path / "log.tlog", tmp_path / "truth.jsonl", seed=1)
    return diagnose(str(tmp_path / "log.tlog"), config.load(cfg), tmp_path / "out")


def _found(doc: dict) -> dict:
    return {e["name"]: e for e in doc["effects"] if e["detected"]}


@pytest.mark.slow
def test_rotating_current_is_a_current_whose_drift_is_reported(tmp_path):
    # truth: 0.3 m/s toward 0.3 rad + 60 deg * t / 600 s; fit and selection parts cover
    # 0-480 s, where the direction turns from 17 to 65 deg.
    doc = _diagnose("effect-rotating-current", tmp_path)
    f = _found(doc)
    assert "water_current" in f
    p = f["water_current"]["params"]
    # measured: 0.215 / 0.210 m/s (0.30 m/s toward 44 deg: the mean over 0-480 s, 41 deg)
    assert math.hypot(p["north"], p["east"]) == pytest.approx(0.3, abs=0.05)
    assert math.degrees(math.atan2(p["east"], p["north"])) == pytest.approx(41.0, abs=8.0)
    drift = f["water_current"]["evidence"]["drift"]
    # measured per 96 s window: north 0.260 -> 0.149, east 0.119 -> 0.272 m/s; slopes
    # -1.19 +- 0.40 and +1.44 +- 0.46 m/s per hour (truth -1.18 and +1.58 at mid-run).
    # North's slope is 2.996 sigma, just short of "changing" on its own: the effect's
    # drift lists both components once one of them changes (onboard/offline/closure/report.py)
    assert drift["north"]["slope_per_hour"] < 0 < drift["east"]["slope_per_hour"]
    assert drift["north"]["last"] < drift["north"]["first"] - 0.08
    # a constant current does not hold on the test part: 0.180 m/s there against 0.106
    # on the selection part
    assert doc["holdout_error_after"] > 1.3 * doc["selection_error_after"]


@pytest.mark.slow
def test_soft_iron_is_unexplained_not_a_first_harmonic_deviation(tmp_path):
    # truth: heading error 0.08 sin(2 psi + 0.4), which no catalog effect has.
    doc = _diagnose("effect-soft-iron", tmp_path)
    f = _found(doc)
    assert "compass_deviation" not in f and "water_current" not in f
    assert "heading_bias" not in f and "gyro_bias" not in f
    ev = f["unexplained"]["evidence"]
    # measured: heading channel, "heading harmonic 2", held-out gain 0.87; lateral
    # channel "speed x heading harmonic 2", 0.69
    assert ev["channel"] == "heading" and ev["regressor"] == "heading harmonic 2"
    assert ev["held_out_gain"] > 0.6
    assert ev["lateral"]["regressor"] == "speed x heading harmonic 2"


@pytest.mark.slow  # ~25-70 s; the default suite keeps the same mapping (swapped, left
# reversed) found on synthetic data: test_closure_synthetic.py::
# test_actuator_mapping_finds_swapped_and_reversed_thrusters
def test_swapped_and_reversed_thrusters_are_found(tmp_path):
    # truth: SERVO1 (ThrottleLeft in the config) drives the starboard thruster reversed,
    # SERVO3 the port one; read with config/twin-thruster-boat.toml as it stands.
    doc = _diagnose("effect-thruster-swap", tmp_path, CONFIG / "twin-thruster-boat.toml")
    f = _found(doc)
    assert f["actuator_mapping"]["params"] == {
        "swapped": True, "reversed_left": True, "reversed_right": False}
    # measured: ground velocity on the test part 0.559 -> 0.109 m/s
    assert doc["holdout_error_after"] < 0.4 * doc["holdout_error_before"]


@pytest.fixture(scope="module")
def wind(tmp_path_factory) -> dict:
    """The diagnosis of effect-wind (truth: 5 m/s wind toward 2.0 rad, 114.6 deg, on
    0.15 / 0.3 m^2 of hull), made once for its two tests."""
    return _diagnose("effect-wind", tmp_path_factory.mktemp("wind"))


@pytest.mark.slow
def test_wind_drift_is_named_toward_the_wind_and_lowers_the_held_out_error(wind):
    f = _found(wind)
    # the leeway across the heading is a drift over ground, named as such: measured
    # toward 113.3 deg (0.47 m/s); a lateral "speed x heading harmonic 1" is left
    # unexplained (held-out gain 0.42)
    c = f["water_current"]["params"]
    assert math.degrees(math.atan2(c["east"], c["north"])) == pytest.approx(114.6, abs=20.0)
    # measured: test part 0.433 -> 0.138 m/s
    assert wind["holdout_error_after"] < 0.4 * wind["holdout_error_before"]


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "known miss on the realistic hull (since 9fce3ac: the rudder boat's 0.3 s shaft lag, "
    "a biased IMU, the base model's shaft and course lags): once the current is chosen, "
    "wind_force's held-out gain is -0.14 (t 8.7); before that change it was named "
    "toward 112.5 deg, 0.49 m/s^2"))
def test_wind_is_a_heading_dependent_force_not_only_a_current(wind):
    p = _found(wind)["wind_force"]["params"]
    assert math.degrees(math.atan2(p["east"], p["north"])) == pytest.approx(114.6, abs=10.0)


@pytest.mark.slow
def test_thrust_loss_mid_run_is_reported_as_a_change_not_a_fixed_effect(tmp_path):
    # truth: 35 % of the thrust lost from 240 s (of 600; fit and selection parts 0-480 s).
    doc = _diagnose("effect-thrust-loss", tmp_path)
    f = _found(doc)
    assert set(f) <= {"unexplained"}
    ev = f["unexplained"]["evidence"]
    # measured: along channel, "time x surge command", held-out gain 0.91
    assert ev["channel"] == "along" and ev["regressor"] == "time x surge command"
    drift = doc["drift"]
    assert drift["params"]["surge.b"]["changing"]
    # the command gain of the windows wholly before the loss against those wholly after
    # (the window across 240 s mixes both): measured 2.15 -> 1.61 m/s^2 (0.75; truth
    # 0.65). The first window alone (1.93) is low: it holds the start from rest, which the
    # 0.3 s shaft lag of the rudder boat (since 9fce3ac) makes slower to fit.
    def mean_b(inside) -> float:
        bs = [w["params"]["surge.b"] for w in drift["windows"] if inside(w)]
        return sum(bs) / len(bs)

    before = mean_b(lambda w: w["t1"] <= 240.0)
    after = mean_b(lambda w: w["t0"] >= 240.0)
    assert after < 0.8 * before


@pytest.mark.slow
def test_gnss_time_jitter_is_not_named_a_latency(tmp_path):
    # truth: each fix's time tag off by N(0, 0.15 s): no mean latency, nothing to name.
    doc = _diagnose("effect-gnss-jitter", tmp_path)
    f = _found(doc)
    # measured: nothing named, nothing unexplained; test part 0.101 m/s
    assert "gps_latency" not in f or f["gps_latency"]["params"]["seconds"] < 0.1
    assert not set(f) - {"gps_latency", "unexplained"}
