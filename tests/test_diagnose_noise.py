"""Issue 32, deliverables 2 and 6: sensor noise identified from the log by second
differences (docs/diagnose.md, "Sensor noise from the log"), written to the overlay's
[sensors] keys only when white; effects that make the test part worse are rejected."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from onboard.core.config import load_all
from onboard.offline.closure import dataset, noise, overlay
from onboard.offline.closure.report import summary_text

DATA = Path(__file__).parent / "data" / "replay"


def _track(n: int = 3000, dt: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """A vehicle turning and speeding up: north (m) every ``dt`` s."""
    t = np.arange(n) * dt
    return t, 40.0 * np.sin(t / 30.0) + 0.5 * t


def test_white_noise_on_a_moving_track_is_recovered() -> None:
    t, x = _track()
    rng = np.random.default_rng(1)
    fig = noise.white_noise(t, x + rng.normal(0.0, 0.7, len(t)))
    assert fig is not None and fig["white"]
    # measured: 0.70 m (truth 0.7), lag-1 -0.66 (white: -0.67)
    assert fig["std"] == pytest.approx(0.7, rel=0.05)
    assert fig["lag1"] == pytest.approx(noise.WHITE_LAG1, abs=0.05)


def test_a_drift_cancels_and_the_white_part_remains() -> None:
    t, x = _track()
    rng = np.random.default_rng(2)
    drift = np.cumsum(rng.normal(0.0, 0.02, len(t)))  # a slow random walk, metres
    fig = noise.white_noise(t, x + drift + rng.normal(0.0, 0.5, len(t)))
    assert fig is not None
    assert fig["std"] == pytest.approx(0.5, rel=0.05)


def test_a_filtered_output_is_not_white() -> None:
    """Negative control: white noise through a 5-point moving average (an autopilot's
    filtered position) has second differences far from white; not written."""
    t, x = _track()
    rng = np.random.default_rng(3)
    smooth = np.convolve(rng.normal(0.0, 0.7, len(t)), np.ones(5) / 5.0, mode="same")
    fig = noise.white_noise(t, x + smooth)
    assert fig is not None and not fig["white"]
    assert fig["lag1"] > noise.WHITE_LAG1_MAX


def test_the_simulators_receiver_and_compass_are_recovered_from_the_golden_log() -> None:
    """The golden jaiabot-turns log (40 s; sitl/scenarios.py `_boat_sensors`: fixes with
    1.0 m white and 1.1 m of drift reporting 1.49 m, Doppler 0.1 m/s, compass 0.03 rad)."""
    cfg = load_all(["sitl-jaiabot"])
    ds = dataset.from_log(str(DATA / "jaiabot-turns.tlog"), cfg)
    found = noise.identify(ds.raw)
    # measured: 0.976 m, drift share 0.569 (true 0.548), 0.087 m/s, 0.0318 rad
    assert found["gnss_position"]["std"] == pytest.approx(1.0, rel=0.2)
    assert found["gnss_position"]["drift_share"] == pytest.approx(0.548, abs=0.1)
    assert found["gnss_velocity"]["std"] == pytest.approx(0.1, rel=0.2)
    assert found["compass"]["std"] == pytest.approx(0.03, rel=0.2)
    assert all(f["white"] for f in found.values())
    tables, _ = overlay.sensor_noise({"sensor_noise": found}, cfg)
    assert tables["sensors.gnss"] == {"drift_share": pytest.approx(0.569, abs=0.01),
                                      "velocity_std_mps": pytest.approx(0.087, abs=0.002)}
    assert tables["sensors.compass"]["heading_std_rad"] == pytest.approx(0.0318, abs=0.001)


def test_the_overlay_writes_only_white_figures() -> None:
    doc = {"sensor_noise": {
        "gnss_position": {"std": 0.008, "unit": "m", "lag1": 0.1, "samples": 900,
                          "white": False},
        "compass": {"std": 0.004, "unit": "rad", "lag1": -0.66, "samples": 900,
                    "white": True}}}
    tables, notes = overlay.sensor_noise(doc, load_all(["rudder-boat"]))
    assert tables == {"sensors.compass": {"heading_std_rad": 0.004}}
    assert any("not white" in n for n in notes)


def test_the_summary_says_an_effect_was_tried_and_rejected() -> None:
    doc = {"effects": [], "holdout_metric": "ground_velocity_rmse_mps",
           "holdout_error_before": 0.219, "holdout_error_after": 0.219,
           "rejected_on_test": [{"name": "compass_deviation", "test_error_without": 0.219,
                                 "test_error_with": 0.238}]}
    text = summary_text(doc)
    assert "Tried and rejected: compass deviation" in text and "0.219 -> 0.238" in text


def test_the_test_part_decides_rejection() -> None:
    from onboard.offline.closure.model import Score
    from onboard.offline.closure.select import _worse_on_test

    def score(x: float) -> Score:
        return Score(headline=x, channels={}, metric="ground_velocity_rmse_mps")

    assert _worse_on_test(score(0.238), score(0.219))
    assert not _worse_on_test(score(0.219), score(0.238))
    assert not _worse_on_test(score(0.219), score(0.219))


DRIFT_RATE = 2 * 1.1 ** 2 / 120.0
"""The drift's rate of change (m^2/s per axis) of a 1.1 m Gauss-Markov wander over 120 s."""


def _drifting_fixes(seed: int, drift_m: float = 1.1, tau_s: float = 120.0,
                    duration_s: float = 1800.0, dt: float = 0.2) -> dict:
    """A boat at 1.5 m/s turning 90 deg every minute; 5 Hz fixes with 1.0 m of white
    noise and a Gauss-Markov wander of ``drift_m`` over ``tau_s`` per axis, reporting
    ``hypot(1.0, drift_m)``, and velocities with 0.1 m/s of noise (``Dataset.raw`` rows)."""
    rng = np.random.default_rng(seed)
    n = int(duration_s / dt)
    t = np.arange(n) * dt
    psi = np.cumsum(np.where(t % 60.0 < 10.0, math.pi / 20.0, 0.0) * dt)
    v = 1.5 * np.c_[np.cos(psi), np.sin(psi)]
    p = np.vstack([np.zeros(2), np.cumsum(0.5 * (v[1:] + v[:-1]) * dt, axis=0)])
    phi = math.exp(-dt / tau_s)
    b = np.zeros((n, 2))
    b[0] = drift_m * rng.standard_normal(2)
    for k in range(1, n):
        b[k] = phi * b[k - 1] + drift_m * math.sqrt(1.0 - phi * phi) * rng.standard_normal(2)
    fix = p + b + rng.standard_normal((n, 2))
    vel = v + 0.1 * rng.standard_normal((n, 2))
    acc = math.hypot(1.0, drift_m)
    return {"fixes": [(t[k], *fix[k]) for k in range(n)],
            "gnss_velocity": [(t[k], *vel[k]) for k in range(n)],
            "gnss_accuracy": [(t[k], acc) for k in range(n)]}


def test_the_drifts_rate_is_measured_from_the_fixes_against_their_velocity() -> None:
    """Four 30-minute runs: the rate within 0.8-1.35 of the true 0.0202 m^2/s (measured
    0.017-0.026 on eight); without a drift it is not invented (median 0.0008, at most
    0.0046 on eight)."""
    for seed in range(4):
        raw = _drifting_fixes(seed)
        d = noise.receiver_drift(raw["fixes"], raw["gnss_velocity"], 0.1)
        assert 0.8 * DRIFT_RATE <= d["rate_m2_per_s"] <= 1.35 * DRIFT_RATE, (seed, d)
    still = [noise.receiver_drift(*(lambda r: (r["fixes"], r["gnss_velocity"]))(
        _drifting_fixes(seed, drift_m=0.0)), 0.1)["rate_m2_per_s"] for seed in range(4)]
    assert float(np.median(still)) < 0.1 * DRIFT_RATE, still


def test_the_overlay_writes_the_correlation_time_that_gives_the_measured_rate() -> None:
    """With the reported accuracy's drift share, ``drift_tau_s = 2 share h^2 / rate``:
    the filter's rate is the measured one (true 120 s); a log shorter than 300 s gives
    none (the golden log's test above)."""
    found = noise.identify(_drifting_fixes(1))
    g = found["gnss_position"]
    share, h = g["drift_share"], g["reported_std"]
    assert 2 * share * h * h / g["drift_tau_s"] == pytest.approx(g["drift"]["rate_m2_per_s"])
    assert 80.0 <= g["drift_tau_s"] <= 160.0, g
    tables, notes = overlay.sensor_noise({"sensor_noise": found}, load_all(["rudder-boat"]))
    assert tables["sensors.gnss"]["drift_tau_s"] == float(f"{g['drift_tau_s']:.3g}")
    assert any("drift_tau_s" in n for n in notes)


def test_a_receiver_that_understates_its_accuracy_is_set_aside_for_the_noise_measured() -> None:
    """Fixes whose white noise alone (3.06 m) is twice the accuracy they report (1.49 m,
    the noise-boat-3x receiver's): the reported accuracy is no basis for their noise, and
    ``drift_share`` would clip to 0 and write nothing. The overlay sets it aside in every
    position pipeline and writes the noise measured, white and drift together. Negative
    control: a receiver whose reported accuracy holds its white part keeps it."""
    fig = {"std": 3.06, "unit": "m", "lag1": -0.67, "samples": 2999, "white": True,
           "reported_std": 1.49, "drift_share": 0.0, "reported_understates": True,
           "drift": {"std": 3.3, "tau_s": 120.0, "rate_m2_per_s": 0.18, "span_s": 600.0}}
    tables, notes = overlay.sensor_noise({"sensor_noise": {"gnss_position": fig}},
                                         load_all(["rudder-boat"]))
    assert tables == {"pipelines.aie": {"gnss_accuracy": False},
                      "pipelines.kf": {"gnss_accuracy": False},
                      "sensors.gnss": {"position_std_m": 4.5, "drift_share": 0.538,
                                       "drift_tau_s": 120.0}}
    assert any("set aside" in n for n in notes)
    holds = dict(fig, std=1.2, drift_share=0.35, reported_understates=False)
    tables, _ = overlay.sensor_noise({"sensor_noise": {"gnss_position": holds}},
                                     load_all(["rudder-boat"]))
    assert tables == {"sensors.gnss": {"drift_share": 0.35}}
    assert noise.UNDERSTATES * 1.49 < 3.06
