"""Issue 32, deliverables 2 and 6: sensor noise identified from the log by second
differences (docs/diagnose.md, "Sensor noise from the log"), written to the overlay's
[sensors] keys only when white; effects that make the test part worse are rejected."""

from __future__ import annotations

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
