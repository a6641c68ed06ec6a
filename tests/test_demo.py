"""``onboard demo``: SITL over real links -> service -> Zenoh router -> shore, scored vs truth."""

from __future__ import annotations

import argparse
import asyncio
import io
import socket

import pytest

from onboard.core.messages import EstimateRecord
from onboard.tools.demo import main, run_demo, score
from onboard.tools.service_bench import free_tcp_port
from sitl.truth import TruthRecord


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
    assert res.recording and (tmp_path / "state" / "adaptive.json").exists()
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
    assert rows["current.north"].rmse == pytest.approx(0.1) and rows["current.north"].unit == "m/s"
