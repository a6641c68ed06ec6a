"""AIE and KF on the real BlueBoat runs (../shared/data/blueboat_sysid_ntnu).

The logs have no truth: speed is compared with the log's own body-frame surge (an
autopilot estimate), yaw rate with its gyro yaw rate, position with its GNSS track.
Models are identified on the even-numbered runs and the filters scored on the others.
"""

from __future__ import annotations

import numpy as np
import pytest

from validation.reports.aie_validation import (
    blueboat_metrics,
    blueboat_runs,
    identify_blueboat,
    run_blueboat,
)

pytestmark = pytest.mark.data


@pytest.fixture(scope="module")
def runs(shared_data):
    if not (shared_data / "blueboat_sysid_ntnu").is_dir():
        pytest.skip("blueboat_sysid_ntnu not in the shared data")
    return blueboat_runs(shared_data)


@pytest.fixture(scope="module")
def models(runs):
    return identify_blueboat(runs[::2])


def test_identification_from_the_training_runs(models) -> None:
    surge, yaw = models
    # measured: surge a 0.622 1/s, gain 2.21 m/s^2, explains 86 % of the speed variance;
    # yaw a 1.75 1/s, gain 1.16 rad/s^2, 67 %
    assert 0.4 < surge.a < 0.9 and 1.5 < surge.gain < 3.0 and surge.fit_ratio > 0.8
    assert 1.0 < yaw.a < 2.5 and 0.7 < yaw.gain < 1.6 and yaw.fit_ratio > 0.6


def test_aie_on_held_out_runs(runs, models) -> None:
    surge, yaw = models
    acc: dict[str, list[float]] = {}
    # the logs carry no Doppler speed: both filters at the shipped defaults, which take
    # the noise the common tuning found without one by themselves (docs/aie.md 2.2, 3.3)
    for r in runs[1::2]:         # 218, 221, 223, 225, 228, 232, 234, 239
        res = run_blueboat(r, surge, yaw)
        assert res["health.surge.diverged"][0] == 0
        assert list(res["health.tuned_set.doppler"]) == [0.0, 0.0]    # AIE, KF
        for k, v in blueboat_metrics(r, res, surge, yaw).items():
            acc.setdefault(k, []).append(v)
    m = {k: float(np.mean(v)) for k, v in acc.items()}
    print(m)
    # measured (mean of the 8 test runs, gnss_position_std_m = 0.1: the logged positions are the
    # autopilot's smoothed track; the no-Doppler set): speed AIE 0.085 vs KF 0.078
    # m/s against the logged surge (a tie, the KF ahead; at the hand-tuned defaults
    # 0.094 vs 0.093), raw speed from consecutive fixes 0.134 (better on 6 of 8 runs,
    # where the logged surge is itself derived from those positions); yaw rate 0.020 vs
    # 0.024 rad/s against the gyro; position 0.34 vs 0.36 m from GNSS; the AIE inputs
    # follow the identified command maps with correlation 0.82 (surge; 0.93 at the
    # hand-tuned defaults), 0.75 (yaw)
    assert m["aie.speed"] < 1.15 * m["kf.speed"] and m["kf.speed"] < m["gps.speed"]
    assert m["aie.speed"] < 0.10
    assert m["aie.yaw_rate"] < m["kf.yaw_rate"]
    assert m["aie.position"] < 0.5
    assert m["input.surge_corr"] > 0.75
    assert m["input.yaw_corr"] > 0.5
