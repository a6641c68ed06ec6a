"""``onboard demo``: SITL over real links -> service -> Zenoh router -> shore, scored vs truth."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import io
import math
import re
import socket
import time
from pathlib import Path

import pytest

from onboard.core.messages import EstimateRecord
from onboard.apps.demo import main, run_demo, score
from onboard.apps.service_bench import free_tcp_port
from onboard.sitl.truth import TruthRecord
from tests.helpers.live_demo import demo_that_kept_up


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
    res, text = demo_that_kept_up("jaiabot-turns", 60.0, speed=10.0, out_dir=tmp_path,
                                  mavlink_out="udpout:127.0.0.1:9")
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


def _current_rec(t: float, values: dict[str, float], std: dict[str, float]) -> EstimateRecord:
    return EstimateRecord(vehicle="v", pipeline="current", t=t, values=values, std=std)


@pytest.mark.integration
def test_the_default_demo_shows_the_current_converging_with_its_sigma(tmp_path):
    """Issue 30's done-when: `onboard demo` as it starts by default (effect-current, 150 s:
    a 0.29 m/s current the boat is not told about) shows the current unknown with its
    sigma first, then known with its sigma, and compares it with the simulated current."""
    from onboard.apps.demo import DEFAULT_DURATION_S, DEFAULT_SCENARIO

    res, text = demo_that_kept_up(out_dir=tmp_path, mavlink_out="udpout:127.0.0.1:9")
    assert res.scenario == DEFAULT_SCENARIO and res.duration_s == DEFAULT_DURATION_S
    rows = {r.column: r for r in res.scores}
    for col in ("current.north", "current.east"):
        # measured on a quiet machine: known in 730 of ~1170 samples from t = 77 s, RMSE
        # 0.015 / 0.012 m/s at a mean published sigma of 0.043 / 0.040; with the simulator
        # 7 s late under heavy load, known from t = 121 s, within 0.08 m/s
        assert rows[col].n > 0 and rows[col].rmse < 0.1, text
        assert rows[col].sigma < 0.1, text
    live = [line for line in text.splitlines() if line.startswith("  t=")]
    assert any("unknown (sigma" in line for line in live), text      # the first leg
    both = re.compile(r"current N [+-]0\.\d+ ± 0\.\d+ E [+-]0\.\d+ ± 0\.\d+ m/s")
    assert any(both.search(line) for line in live), text             # converged, with sigma
    assert "water current in the simulator: 0.29 m/s toward 329°" in text
    assert re.search(r"estimated at t=\d+ s: 0\.[23]\d m/s toward 3[0-4]\d° "
                     r"\(N \+0\.2\d\d ± 0\.\d+, E -0\.[12]\d\d ± 0\.\d+", text), text
    assert rows["aie.speed"].rmse < rows["nav.speed"].rmse, text  # measured 0.038 / 0.061


def test_the_demo_config_takes_the_simulated_sensors_noise():
    from onboard.apps.demo import demo_base_config, with_sensor_noise
    from onboard.core.config import load
    from onboard.sitl.scenarios import get

    sc = get("effect-current")  # GNSS 0.5 m white + 0.3 m drift, 0.05 m/s; compass 0.015 rad
    cfg, note = demo_base_config(sc, "rudder-boat")
    g = cfg.sensors.gnss
    assert g.position_std_m == pytest.approx(math.hypot(0.5, 0.3))
    assert g.drift_share == pytest.approx(0.09 / 0.34)
    assert g.velocity_std_mps == 0.05 and cfg.sensors.compass.heading_std_rad == 0.015
    assert cfg.sensors.imu.accel_std_mps2 == 0.03 and "simulated sensors" in note
    # negative control: the bundled config says 1.5 m, and a scenario with a calibrated
    # config keeps that config's own figures
    assert load("rudder-boat").sensors.gnss.position_std_m == 1.5
    jaia, note = demo_base_config(get("jaiabot-turns"), "rudder-boat")
    assert jaia == load("sitl-jaiabot") and "held-out" in note
    rov, note = demo_base_config(get("bluerov2-circle"), "bluerov2")
    assert rov == load("bluerov2") and note == "bundled bluerov2"  # sensors as configured
    no_gnss = dataclasses.replace(sc.sensors, gnss=None)
    assert with_sensor_noise(load("rudder-boat"), no_gnss).sensors.gnss == \
        load("rudder-boat").sensors.gnss


def test_the_live_line_shows_progress_and_the_current_with_its_sigma_or_unknown():
    from onboard.apps.demo import live_line
    from onboard.apps.shore import ShoreView

    view = ShoreView()
    assert live_line(view, "v", 150.0) == "waiting for estimates ..."
    view.estimates[("v", "nav")] = EstimateRecord(vehicle="v", pipeline="nav", t=42.0,
                                                  values={"north": 12.0, "east": -3.0})
    view.estimates[("v", "aie")] = EstimateRecord(vehicle="v", pipeline="aie", t=42.0,
                                                  values={"speed": 1.5, "heading": math.pi / 2})
    view.estimates[("v", "current")] = _current_rec(42.0, {"east": -0.15},
                                                    {"north": 0.97, "east": 0.05})
    line = live_line(view, "v", 150.0)
    assert line.startswith("t=  42 of 150 s")
    assert "nav N +12.0 E -3.0 m" in line and "aie 1.50 m/s 90°" in line
    assert "current N unknown (sigma 0.97) E -0.150 ± 0.050 m/s" in line
    view.estimates[("v", "current")] = _current_rec(60.0, {"north": 0.25, "east": -0.15},
                                                    {"north": 0.03, "east": 0.02})
    assert "current N +0.250 ± 0.030 E -0.150 ± 0.020 m/s" in live_line(view, "v", 150.0)
    assert live_line(view, "other", 150.0) == "waiting for estimates ..."


def test_the_notes_say_what_a_bad_looking_row_means_and_only_then():
    from onboard.apps.demo_truth import ScoreRow, notes

    def row(col, rmse, std, **kw):
        return ScoreRow(col, 100, rmse, std, "u", **kw)

    # the figure: aie.yaw_input RMSE 0.55 against a truth spread of 0.25
    said = notes([row("aie.yaw_input", 0.55, 0.25)], {"heading": 2.25})
    assert len(said) == 1 and "first-order heading model" in said[0]
    assert "a = 2.25 1/s" in said[0] and "judge the filter by its heading rows" in said[0]
    assert notes([row("aie.yaw_input", 0.20, 0.25)]) == []        # negative control
    behind = [row("nav.speed", 0.06, 0.5), row("kf.speed", 0.08, 0.5, raw="nav.speed",
                                                sigma=0.07)]
    assert len(notes(behind)) == 1 and "above the raw nav.speed's 0.060" in notes(behind)[0]
    behind[1].rmse = 0.05
    assert notes(behind) == []
    over = notes([row("current.north", 0.05, 0.0, sigma=0.01)])
    assert len(over) == 1 and "5.0 times better than it did" in over[0]
    assert notes([row("current.north", 0.015, 0.0, sigma=0.04)]) == []


def test_the_current_story_tells_unknown_then_known_against_the_simulated_current():
    from onboard.apps.demo_truth import CURRENT_SETTLE_S, current_story

    truth = [TruthRecord(t=0.1 * k, north=0.0, east=0.0, down=0.0, roll=0.0, pitch=0.0,
                         yaw=0.0, u=1.0, v=0.0, w=0.0, p=0.0, q=0.0, r=0.0, u_r=1.0, v_r=0.0,
                         w_r=0.0, current_north=0.25, current_east=-0.15) for k in range(400)]
    hist = [_current_rec(0.1 * k, {}, {"north": 1.0, "east": 0.9}) for k in range(100)]
    unknown = current_story(hist, truth, 0.3)
    assert "0.29 m/s toward 329°" in unknown[0] and "run longer" in unknown[1]
    hist += [_current_rec(0.1 * k, {"north": 0.24, "east": -0.16}, {"north": 0.05, "east": 0.04})
             for k in range(100, 400)]
    story = current_story(hist, truth, 0.3)
    assert "estimated at t=40 s: 0.29 m/s toward 326° (N +0.240 ± 0.050, E -0.160 ± 0.040" \
        in story[1]
    assert "until t=10 s" in story[2] and f"from t={10 + CURRENT_SETTLE_S:.0f} s" in story[2]
    assert current_story([], truth, 0.3) == []


def test_an_unknown_current_is_blamed_on_too_few_turns_only_where_there_were_few():
    """The story's reason for a current never published: a vehicle that held one heading
    did not turn enough; one that went round a circle did (an ROV without a surge model)."""
    from onboard.apps.demo_truth import current_story, headings_held

    assert headings_held([0.0] * 5) == 0.0
    assert headings_held([0.1 * k for k in range(63)]) > 350.0
    assert headings_held([math.radians(d) for d in (350.0, 10.0, 40.0)]) == pytest.approx(50.0)

    def truth(yaw):
        return TruthRecord(t=0.0, north=0.0, east=0.0, down=0.0, roll=0.0, pitch=0.0, yaw=yaw,
                           u=1.0, v=0.0, w=0.0, p=0.0, q=0.0, r=0.0, u_r=1.0, v_r=0.0,
                           w_r=0.0, current_north=0.0, current_east=0.0)
    hist = [_current_rec(0.1 * k, {}, {"north": 1.0, "east": 0.9}) for k in range(100)]
    straight = current_story(hist, [truth(0.3)] * 100, 0.3)[1]
    assert "did not turn enough" in straight and "run longer" in straight
    circle = current_story(hist, [truth(0.1 * k) for k in range(100)], 0.3)[1]
    assert "turned through 354°" in circle and "did not turn enough" not in circle


def test_headings_are_rounded_then_wrapped_never_360():
    from onboard.apps.demo import live_line
    from onboard.apps.shore import ShoreView, fmt_bearing, fmt_value

    assert fmt_bearing(359.97, 1) == "0.0" and fmt_bearing(359.6, 0) == "0"
    assert fmt_bearing(-0.2, 0) == "0" and fmt_bearing(359.4, 0) == "359"
    view = ShoreView()
    view.estimates[("v", "aie")] = EstimateRecord(vehicle="v", pipeline="aie", t=1.0,
                                                  values={"speed": 1.0, "heading": -0.001})
    assert "aie 1.00 m/s 0°" in live_line(view, "v", 150.0)
    assert fmt_value("heading", math.radians(359.99)) == "heading=0.0°"


def _ctrl_c(argv: list[str], cwd, ready: str, timeout_s: float = 120.0):
    """Run ``onboard`` with ``argv`` in ``cwd`` in a session of its own, send Ctrl-C
    (SIGINT) to its whole process group once a stdout line holds ``ready``; return the
    process, its stdout and stderr, the wall seconds it took to stop, and the processes
    still running in ``cwd``."""
    import os
    import signal
    import subprocess
    import sys
    import threading

    proc = subprocess.Popen([sys.executable, "-m", "onboard", *argv], cwd=cwd,
                            start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    out: list[str] = []
    seen = threading.Event()

    def read() -> None:
        for line in proc.stdout:
            out.append(line)
            if ready in line:
                seen.set()

    threading.Thread(target=read, daemon=True).start()
    try:
        assert seen.wait(timeout_s), "".join(out)[-3000:]
        os.killpg(proc.pid, signal.SIGINT)
        t0 = time.monotonic()
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            pass
        took = time.monotonic() - t0
        time.sleep(1.0)
        left = {pid: cmd for pid, cmd in _running_in(cwd).items() if pid != proc.pid}
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        for pid in _running_in(cwd):  # what this test started and left (a failure)
            os.kill(pid, signal.SIGKILL)
    return proc, "".join(out), proc.stderr.read(), took, list(left.values())


def _running_in(cwd) -> dict[int, str]:
    """The processes (pid -> command line) whose working directory is ``cwd``."""
    import os

    found = {}
    for pid in os.listdir("/proc"):
        try:
            if pid.isdigit() and os.readlink(f"/proc/{pid}/cwd") == str(cwd):
                with open(f"/proc/{pid}/cmdline") as f:
                    found[int(pid)] = f.read().replace("\0", " ")
        except OSError:
            pass
    return found


@pytest.mark.integration
def test_ctrl_c_stops_the_demo_and_its_simulator_without_a_traceback(tmp_path):
    proc, out, err, took, left = _ctrl_c(["demo", "--duration", "120"], tmp_path, "t=  ")
    assert proc.returncode == 130, (out[-2000:], err[-2000:])
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err[-3000:]
    assert left == [] and took < 20.0


@pytest.mark.slow
@pytest.mark.integration
def test_ctrl_c_stops_the_fleet_demo_every_vehicle_and_the_fleet_service(tmp_path):
    """Ctrl-C to the fleet demo's process group once the AUV publishes (its DVL over
    TCP): every service and simulator stopped, the fleet service too, exit 130."""
    proc, out, err, took, left = _ctrl_c(["demo", "--fleet", "--duration", "200"], tmp_path,
                                         "auv-1 | t=")
    assert proc.returncode == 130, (out[-2000:], err[-2000:])
    assert "Traceback" not in err and "left behind" not in err, err[-3000:]
    assert left == [] and took < 30.0, (left, took)
