"""AIE and KF against SITL truth (sitl.runner), through the real engine and input mapping.

Bounds are the measured figures (seed 1, 300 s, RMSE after 30 s) with a margin; where the
issue's goal is not met the honest bound is kept and the goal is named in the comment.
Goal of issue 4: AIE speed RMSE <= 0.8 x KF and < 0.10 m/s; AIE heading below the KF.
"""

from __future__ import annotations

import pytest

pytest.importorskip("sitl.runner")

from onboard.reports.aie_validation import convergence_step, run_sitl, sitl_metrics  # noqa


@pytest.fixture(scope="module")
def jaiabot():
    return run_sitl("jaiabot-turns", seed=1)


@pytest.fixture(scope="module")
def twin():
    return run_sitl("twin-thruster-turns", seed=1)


def test_jaiabot_turns_aie_beats_the_kf_on_speed_heading_and_position(jaiabot) -> None:
    m = sitl_metrics(jaiabot)
    a, k = m["aie"], m["kf"]
    # measured: speed AIE 0.259 vs KF 0.461 m/s (0.56 x: meets <= 0.8 x; misses the
    # < 0.10 m/s goal with the default model -- with a model identified from another log
    # AIE reaches 0.107 and the KF 0.085, docs/aie.md 3.2); heading 0.0223 vs 0.0239
    # rad; position 2.83 vs 3.36 m
    assert a["speed"] < 0.8 * k["speed"]
    assert a["speed"] < 0.31
    assert a["heading"] < k["heading"]
    assert a["position"] < k["position"]
    # input estimates against truth.surge_input / yaw_input: 0.331 m/s^2, 0.257 rad/s^2
    # (the truth is thrust/m11 alone; AIE's input also carries the nonlinear drag)
    assert a["surge_input"] < 0.4
    assert a["yaw_input"] < 0.31


def test_twin_thruster_turns_aie_matches_the_kf(twin) -> None:
    m = sitl_metrics(twin)
    a, k = m["aie"], m["kf"]
    # measured: speed AIE 0.1854 vs KF 0.1851 m/s (1.00 x: the <= 0.8 x goal is NOT met
    # on this boat, whose nominal thrust map is close to the truth); heading 0.03129 vs
    # 0.03126 rad (a tie on this seed, so the "below the KF" goal is not met here; 0.0306
    # vs 0.0311 over seeds 1-3); position 1.85 vs 1.90 m
    assert a["speed"] < 1.05 * k["speed"]
    assert a["speed"] < 0.22
    assert a["heading"] < 1.01 * k["heading"]
    assert a["position"] < 1.05 * k["position"]
    # input errors: 0.496 m/s^2, 0.836 rad/s^2 (spins on the spot are fast)
    assert a["surge_input"] < 0.6
    assert a["yaw_input"] < 1.0


def test_no_divergence_and_surge_coefficients_converge(jaiabot, twin) -> None:
    for run in (jaiabot, twin):
        h = run.pipelines[0].health()
        assert h["surge.diverged"] == 0 and h["heading.diverged"] == 0
    # measured: surge theta within 20 % of its final value after 174 steps (paper: ~100);
    # on the twin-thruster run it still moves at the end (290 of 297), and the heading
    # coefficients (10 Hz steps, lambda = 0.999) keep adapting on both
    assert 0 <= convergence_step(jaiabot.theta["surge"]) < 220
