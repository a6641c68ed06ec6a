"""The ESESO in replay on a bluerov2 log: ``onboard replay`` over a MAVLink tlog of the
simulator's ``bluerov2-circle`` (its own PID on the true state), the disturbance and the
velocity compared with the hidden truth.

The ESESO consumes what the log gives it generically: IMU (RAW_IMU), attitude, depth
(SCALED_PRESSURE2), DVL/INS velocity, the thruster PWM mapped to ActuatorCommand by
``config/bluerov2.toml``. Registering ``eseso`` in ``onboard.pipelines.MODULES`` is the
integrator's; the test adds it for its own run.
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from onboard import pipelines as pipelines_pkg
from onboard.core import config


@pytest.fixture(scope="module")
def replayed(tmp_path_factory) -> tuple[list[dict], list[dict], dict]:
    from onboard.offline.replay import replay
    from onboard.sitl.runner import run_to_tlog

    d = tmp_path_factory.mktemp("rov")
    run_to_tlog("bluerov2-circle", d / "run.tlog", d / "truth.jsonl", duration=30.0, seed=1)
    mp = pytest.MonkeyPatch()
    if "eseso" not in pipelines_pkg.MODULES:
        mp.setattr(pipelines_pkg, "MODULES", pipelines_pkg.MODULES + ("eseso",))
    try:
        summary = replay(str(d / "run.tlog"), config.load("bluerov2"), d / "out", plot=False)
    finally:
        mp.undo()
    rows = list(csv.DictReader(open(d / "out" / "estimates.csv")))
    truth = [json.loads(line) for line in open(d / "truth.jsonl")]
    return rows, truth, summary


def test_eseso_runs_in_replay_and_fills_its_columns(replayed) -> None:
    rows, _, summary = replayed
    assert "eseso" in summary["pipelines"]
    assert {"eseso.dist_x", "eseso.dist_y", "eseso.dist_z"} <= set(rows[0])
    filled = [r for r in rows if r["eseso.dist_x"]]
    assert len(filled) > 0.9 * len(rows)
    health = summary["pipeline_health"]["eseso"]
    # one thrust update per thruster command (the actuator's rate, not the IMU's)
    commands = summary["samples_accepted_by_type"]["actuators"]
    assert commands - 2 <= health["fused.thrust"] <= commands
    assert health["fused.dvl"] > 100


def test_replayed_disturbance_and_velocity_match_truth(replayed) -> None:
    rows, truth, _ = replayed
    t_est = np.array([float(r["t"]) for r in rows])

    def at(tr: dict, name: str) -> float:
        i = min(int(np.searchsorted(t_est, tr["t"] - 1e-9)), len(rows) - 1)
        return float(rows[i][name])

    derr, verr = [], []
    for tr in truth:
        if tr["t"] < 5.0:
            continue
        derr.append(np.linalg.norm([at(tr, "eseso.dist_x") - tr["disturbance_x"],
                                    at(tr, "eseso.dist_y") - tr["disturbance_y"],
                                    at(tr, "eseso.dist_z") - tr["disturbance_z"]]))
        verr.append(np.linalg.norm([at(tr, "eseso.u") - tr["u"], at(tr, "eseso.v") - tr["v"],
                                    at(tr, "eseso.w") - tr["w"]]))
    derr_a, verr_a = np.array(derr), np.array(verr)
    print(f"replay: disturbance RMS {np.sqrt(np.mean(derr_a ** 2)):.2f} N, max "
          f"{derr_a.max():.2f} N; velocity RMS {np.sqrt(np.mean(verr_a ** 2)):.4f} m/s")
    # measured (30 s, seed 1, INS bias states and per-axis AHRS noise): disturbance RMS
    # 0.56 N, max 1.11 N; velocity RMS 0.010 m/s
    assert np.sqrt(np.mean(derr_a ** 2)) < 2.5
    assert derr_a.max() < 5.0
    assert np.sqrt(np.mean(verr_a ** 2)) < 0.05
