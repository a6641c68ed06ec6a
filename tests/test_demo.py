"""``onboard demo``: SITL over real links -> service -> Zenoh router -> shore, scored vs truth."""

from __future__ import annotations

import argparse
import asyncio
import io
import math
import socket
from pathlib import Path

import pytest

from onboard.core.messages import EstimateRecord
from onboard.apps.demo import main, run_demo, score
from onboard.apps.service_bench import free_tcp_port
from onboard.sitl.truth import TruthRecord


@pytest.mark.integration
def test_demo_runs_end_to_end_and_prints_the_truth_comparison(tmp_path):
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", 0))
    out = io.StringIO()
    try:
        res = asyncio.run(run_demo("jaiabot-turns", 8.0, speed=8.0, out_dir=tmp_path,
                                   router_endpoint=f"tcp/127.0.0.1:{free_tcp_port()}",
                                   mavlink_out=f"udpout:127.0.0.1:{listener.getsockname()[1]}",
                                   out=out, keep_state=False))
        listener.settimeout(2.0)
        got_mavlink = listener.recv(65536)
    finally:
        listener.close()
    text = out.getvalue()
    assert res.sources == {"autopilot": "mavlink", "gps": "nmea"}  # UDP and a pty
    assert res.frames["mavlink"] > 100 and res.frames["nmea"] > 50
    assert len(res.estimates) > 20, text  # ~10 Hz nav over 8 s, received over Zenoh
    cols = {r.column for r in res.scores}
    assert {"nav.north", "nav.east", "nav.heading"} <= cols
    nav_north = next(r for r in res.scores if r.column == "nav.north")
    assert nav_north.rmse < 10.0  # GNSS noise 1.5 m; measured ~1.3 m
    assert "estimates vs the simulator's truth" in text and "RMSE" in text
    assert res.recording
    # a fresh temporary state, deleted at the end: nothing left for the next run
    assert not (tmp_path / "state").exists() and not Path(res.state_file).exists()
    assert got_mavlink[:1] in (b"\xfd", b"\xfe")  # MAVLink out reached the GCS port
    assert res.health is not None and res.health.vehicle == res.vehicle


def test_demo_rejects_a_bad_duration_with_a_usage_error():
    from onboard.core.errors import UsageError

    with pytest.raises(UsageError):
        main(argparse.Namespace(duration=-1.0, scenario=None, realtime=False))


def test_scores_compare_angles_wrapped_and_positions_from_the_first_estimate():
    truth = [TruthRecord(t=0.1 * k, north=10.0 + k, east=0.0, down=0.0, roll=0.0, pitch=0.0,
                         yaw=3.1, u=1.0, v=0.0, w=0.0, p=0.0, q=0.0, r=0.0, u_r=1.0, v_r=0.0,
                         w_r=0.0, current_north=0.2) for k in range(10)]
    hist = [EstimateRecord(vehicle="v", pipeline="nav", t=0.1 * k,
                           values={"north": float(k), "heading": -3.1, "speed": 1.0})
            for k in range(10)]
    hist += [EstimateRecord(vehicle="v", pipeline="current", t=0.1 * k, values={"north": 0.3})
             for k in range(10)]
    rows = {r.column: r for r in score(hist, truth)}
    assert rows["nav.north"].rmse == pytest.approx(0.0, abs=1e-9)
    assert rows["nav.heading"].rmse == pytest.approx(4.77, abs=0.01)  # 3.1 vs -3.1 rad: 4.77 deg, not 355
    assert rows["nav.speed"].rmse == pytest.approx(0.0)
    # a current without a published sigma is not scored: unknown
    assert rows["current.north"].n == 0 and rows["current.north"].unit == "m/s"


@pytest.mark.integration
def test_demo_truth_table_shows_filters_beating_the_raw_speed_and_no_phantom_current(tmp_path):
    """The done-when of issue 15 on the demo's own output: aie.speed and kf.speed below
    nav.speed (the raw GNSS speed over ground) in the truth table, and the current of a
    still-water run either shown as unknown or, where shown, right."""
    out = io.StringIO()
    res = asyncio.run(run_demo("jaiabot-turns", 60.0, speed=10.0, out_dir=tmp_path,
                               router_endpoint=f"tcp/127.0.0.1:{free_tcp_port()}",
                               mavlink_out="udpout:127.0.0.1:9", out=out))
    text = out.getvalue()
    rows = {r.column: r for r in res.scores}
    nav = rows["nav.speed"].rmse
    # measured on a quiet machine: aie 0.030, kf 0.057, nav 0.099 m/s; under heavy load
    # 0.113 / 0.110 / 0.161 (late live estimates misalign with the truth in every row)
    assert rows["aie.speed"].rmse < nav and rows["kf.speed"].rmse < nav, text
    assert rows["aie.speed"].raw == "nav.speed" and rows["aie.speed"].raw_rmse == nav
    assert "nav.speed" in text.split("aie.speed", 1)[1].splitlines()[0]
    for col in ("current.north", "current.east"):
        r = rows[col]
        # measured: unknown over the whole 60 s (published sigma 0.26-1.23 m/s; the
        # estimate reached 1.0 m/s along track with a truth of 0)
        if r.n == 0:
            assert math.isnan(r.rmse) and r.total > 0
            assert any(line.startswith(col) and "unknown" in line
                       for line in text.splitlines()), text
        else:
            assert r.rmse < 0.1, text
    assert "adaptive state" in text and "fresh" in text


def test_current_is_known_only_once_its_sigma_has_stayed_small():
    from onboard.apps.demo import CURRENT_SETTLE_S, current_known

    def rec(t: float, sd: float) -> EstimateRecord:
        return EstimateRecord(vehicle="v", pipeline="current", t=t,
                              values={"north": 0.5, "east": 0.0},
                              std={"north": sd, "east": 0.01})

    hist = [rec(0.1 * k, 1.0 if k < 50 else 0.05) for k in range(300)]
    hist.append(EstimateRecord(vehicle="v", pipeline="current", t=30.0, values={"north": 0.5}))
    known = current_known(hist)
    assert not any(known[0.1 * k] for k in range(50))             # sigma 1 m/s: unknown
    assert not known[0.1 * 60]                                     # small, not yet settled
    assert known[0.1 * (50 + int(CURRENT_SETTLE_S * 10) + 5)]     # settled
    assert not known[30.0]                                         # no sigma: unknown
    truth = [TruthRecord(t=0.1 * k, north=0.0, east=0.0, down=0.0, roll=0.0, pitch=0.0,
                         yaw=0.0, u=1.0, v=0.0, w=0.0, p=0.0, q=0.0, r=0.0, u_r=1.0, v_r=0.0,
                         w_r=0.0, current_north=0.2) for k in range(300)]
    rows = {r.column: r for r in score(hist[:50], truth)}
    assert rows["current.north"].n == 0 and rows["current.north"].total == 50
    full = {r.column: r for r in score(hist, truth)}["current.north"]
    assert 0 < full.n < 300 and full.rmse == pytest.approx(0.3)   # 0.5 vs 0.2 once known
    from onboard.apps.demo import format_scores
    assert "unknown" in format_scores(list(rows.values()))
