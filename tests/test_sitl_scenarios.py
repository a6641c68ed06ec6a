"""Scenarios: every one writes a tlog pymavlink reads without a bad frame, with the truth
beside it; runs are deterministic; the CLI lists and runs them."""

from __future__ import annotations

import json
from collections import Counter

import pytest
from pymavlink import mavutil

from onboard.cli import main as onboard_main
from onboard.core.errors import UsageError
from onboard.sitl import scenarios
from onboard.sitl.runner import read_truth, run_to_tlog, simulate

PAPER_SCENARIOS = ["jaiabot-turns", "twin-thruster-turns", "bluerov2-circle", "gavia-tidal",
                   "spheroid-sawtooth"]
EFFECT_SCENARIOS = ["effect-current", "effect-compass-deviation", "effect-gyro-bias",
                    "effect-gps-latency", "effect-thrust-nonlinearity",
                    "effect-surge-yaw-coupling", "effect-waves", "effect-two", "clean"]

EXPECTED_MESSAGES = {
    "rudder-boat": {"HEARTBEAT", "PARAM_VALUE", "GPS_RAW_INT", "ATTITUDE", "SCALED_IMU",
                    "SERVO_OUTPUT_RAW", "VFR_HUD"},
    "twin-thruster-boat": {"HEARTBEAT", "PARAM_VALUE", "GPS_RAW_INT", "ATTITUDE", "SCALED_IMU",
                           "SERVO_OUTPUT_RAW", "VFR_HUD"},
    "bluerov2": {"HEARTBEAT", "PARAM_VALUE", "GLOBAL_POSITION_INT", "ATTITUDE",
                 "SCALED_IMU", "SCALED_PRESSURE2", "SERVO_OUTPUT_RAW", "VISION_POSITION_DELTA",
                 "DISTANCE_SENSOR"},
    "torpedo-auv": {"HEARTBEAT", "PARAM_VALUE", "GLOBAL_POSITION_INT", "ATTITUDE", "SCALED_IMU",
                    "SCALED_PRESSURE2", "SERVO_OUTPUT_RAW", "RPM", "VISION_POSITION_DELTA"},
    "spheroid": {"HEARTBEAT", "PARAM_VALUE", "GLOBAL_POSITION_INT", "ATTITUDE", "SCALED_IMU",
                 "SCALED_PRESSURE2", "SERVO_OUTPUT_RAW", "RPM", "VISION_POSITION_DELTA"},
}
EXPECTED_BY_SCENARIO = {
    # the ArduSub-like INS stream of issue 22: no DVL, depth or GNSS message of its own
    "remus-ins-steps": {"HEARTBEAT", "PARAM_VALUE", "GLOBAL_POSITION_INT", "ATTITUDE",
                        "SCALED_IMU", "SERVO_OUTPUT_RAW", "RPM"},
}


def _pymavlink_types(path) -> Counter:
    """Message counts as pymavlink's plain recv_match loop sees them (BAD_DATA included)."""
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    seen: Counter = Counter()
    while True:
        m = conn.recv_match()
        if m is None:
            break
        seen[m.get_type()] += 1
    conn.close()
    return seen


def test_the_contract_names_exist():
    for name in PAPER_SCENARIOS + EFFECT_SCENARIOS:
        assert name in scenarios.SCENARIOS


@pytest.mark.parametrize("name", list(scenarios.SCENARIOS))
def test_each_scenario_writes_a_tlog_pymavlink_reads_without_a_bad_frame(name, tmp_path):
    sc = scenarios.get(name)
    tlog, truth = tmp_path / "run.tlog", tmp_path / "truth.jsonl"
    summary = run_to_tlog(name, tlog, truth, duration=6.0, seed=1,
                          meta_path=tmp_path / "meta.json")
    seen = _pymavlink_types(tlog)
    assert seen["BAD_DATA"] == 0
    assert sum(seen.values()) == summary.frames["mavlink"]
    assert EXPECTED_BY_SCENARIO.get(name, EXPECTED_MESSAGES[sc.vehicle.vehicle_class]) \
        <= set(seen)
    records = read_truth(truth)
    assert len(records) == 61 and records[0].t == 0.0 and records[-1].t == pytest.approx(6.0)
    for e in sc.injected:  # the truth carries every injected effect's parameters
        for k, v in e.params.items():
            assert records[-1].effects[f"{e.name}.{k}"] == v
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert {d["name"] for d in meta["declared_effects"]} == set(sc.declared)


def test_servo_functions_identify_the_vehicle(tmp_path):
    """HEARTBEAT type and SERVOn_FUNCTION let `onboard replay` tell the vehicles apart."""
    want = {"jaiabot-turns": (11, {"SERVO1_FUNCTION": 26, "SERVO3_FUNCTION": 70}),
            "twin-thruster-turns": (11, {"SERVO1_FUNCTION": 73, "SERVO3_FUNCTION": 74}),
            "bluerov2-circle": (12, {f"SERVO{i}_FUNCTION": 32 + i for i in range(1, 7)}),
            "gavia-tidal": (12, {"SERVO1_FUNCTION": 21, "SERVO2_FUNCTION": 19,
                                 "SERVO3_FUNCTION": 70})}
    for name, (mav_type, params) in want.items():
        got = {}
        types = set()
        for _, samples, _ in simulate(name, duration=0.0):
            for s in samples:
                if type(s).__name__ == "Parameter":
                    got[s.name] = s.value
                if type(s).__name__ == "VehicleInfo":
                    types.add(s.mav_type)
        assert got == params and types == {mav_type}


def test_same_seed_gives_identical_bytes_and_another_seed_does_not(tmp_path):
    paths = []
    for i, seed in enumerate((7, 7, 8)):
        p = tmp_path / f"{i}.tlog"
        run_to_tlog("effect-two", p, tmp_path / f"{i}.jsonl", duration=15.0, seed=seed)
        paths.append(p)
    a, b, c = (p.read_bytes() for p in paths)
    assert a == b and a != c
    assert (tmp_path / "0.jsonl").read_bytes() == (tmp_path / "1.jsonl").read_bytes()


def test_tlog_reads_back_with_the_project_reader(tmp_path):
    from onboard.drivers.tlog import TlogReader
    from onboard.sitl.emitters import DEFAULT_EPOCH_S

    run_to_tlog("jaiabot-turns", tmp_path / "j.tlog", duration=5.0, seed=2)
    reader = TlogReader(tmp_path / "j.tlog")
    samples = list(reader)
    assert not reader.stats.rejected
    assert samples[0].t == DEFAULT_EPOCH_S  # the log starts at simulation t = 0
    kinds = Counter(type(s).__name__ for s in samples)
    assert kinds["GnssFix"] == 26 and kinds["Imu"] == 251  # 5 Hz and 50 Hz over 5 s


def test_no_gnss_fix_from_a_submerged_auv():
    kinds = Counter(type(s).__name__ for _, ss, _ in simulate("gavia-tidal", 5.0) for s in ss)
    assert kinds["GnssFix"] == 0 and kinds["VelocityOverGround"] == 51


def test_bluerov2_circle_flies_the_circle_under_the_push(tmp_path):
    """The circle (r = 2 m, 0.5 m/s: the spec's 1.5 m/s needs ~115 N of thrust where the six
    T200s give ~99 N) under 56.6 N of push; the scenario's own PID keeps on it."""
    from onboard.sitl.runner import run

    s = run("bluerov2-circle", 30.0, seed=0, truth_path=tmp_path / "t.jsonl")
    # measured 0.41 m RMS over 30 s from rest (the start-up transient dominates)
    assert s.tracking["rms_position_error_m"] < 0.6
    truth = read_truth(tmp_path / "t.jsonl")
    assert truth[-1].disturbance_x is not None
    assert abs(truth[-1].down - 20.0) < 0.5


def test_unknown_scenario_is_a_usage_error(capsys):
    with pytest.raises(UsageError):
        scenarios.get("no-such-scenario")
    assert onboard_main(["sitl", "--scenario", "no-such-scenario"]) == 2
    assert "unknown scenario" in capsys.readouterr().err


def test_cli_lists_every_scenario(capsys):
    assert onboard_main(["sitl", "--list"]) == 0
    out = capsys.readouterr().out
    for name in scenarios.SCENARIOS:
        assert name in out


def test_cli_writes_tlog_truth_metadata_and_report(tmp_path, capsys):
    tlog = tmp_path / "c.tlog"
    rc = onboard_main(["sitl", "--scenario", "effect-current", "--duration", "4", "--seed", "3",
                       "--tlog", str(tlog), "--truth", str(tmp_path / "c.jsonl"),
                       "--report", str(tmp_path / "r.json")])
    assert rc == 0
    assert tlog.stat().st_size > 0 and (tmp_path / "c.jsonl").stat().st_size > 0
    meta = json.loads((tmp_path / "c.scenario.json").read_text())
    assert meta["declared_effects"] == [] and "water_current" not in json.dumps(meta)
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["scenario"] == "effect-current" and report["frames"]["mavlink"] > 0


def test_tick_rate_keeps_every_sensor_rate():
    from onboard.sitl.runner import _tick_rate

    assert _tick_rate([50, 10, 5, 1, 10]) == 50
    assert _tick_rate([100, 20, 5, 1]) == 100
    assert _tick_rate([50, 3, 10]) == 150
    assert _tick_rate([200, 7, 10]) == 200  # lcm 1400: the fastest rate, 7 Hz rounded
    assert _tick_rate([50, 2.5]) == 100


@pytest.mark.parametrize("argv, message", [
    (["--scenario", "clean", "--link", "serial:/dev/x"], "--link"),
    (["--scenario", "clean", "--dvl", "tcp:127.0.0.1:0"], "has no DVL"),
    (["--scenario", "gavia-tidal", "--dvl", "udp:1.2.3.4:5"], "--dvl expects"),
    (["--scenario", "clean", "--duration", "-1"], "--duration"),
    (["--scenario", "clean", "--controller", "pid"], "bluerov2-circle"),
    ([], "--scenario"),
])
def test_cli_bad_usage_exits_2_with_one_line(argv, message, capsys):
    assert onboard_main(["sitl", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_docs_list_every_scenario_and_effect():
    from pathlib import Path

    from onboard.sitl.effects import VOCABULARY

    doc = (Path(__file__).resolve().parent.parent / "docs" / "sitl.md").read_text()
    for name in scenarios.SCENARIOS:
        assert f"`{name}`" in doc
    for effect in VOCABULARY:
        assert f"`{effect}`" in doc


def test_realtime_mode_paces_to_the_wall_clock():
    from onboard.sitl.runner import run

    s = run("clean", 1.0, seed=0, realtime=True)
    assert s.wall_s >= 0.95  # never faster than real time (slower only on a loaded machine)


def test_cli_controller_report_is_merged_and_strict_json(tmp_path):
    report = tmp_path / "r.json"
    rc = onboard_main(["sitl", "--scenario", "bluerov2-circle", "--controller", "pid",
                       "--duration", "3", "--tlog", str(tmp_path / "c.tlog"),
                       "--report", str(report)])
    assert rc == 0
    text = report.read_text()
    assert "NaN" not in text and "Infinity" not in text
    d = json.loads(text)
    assert d["tracking"]["rms_position_error_m"] > 0
    if "controller_report" in d:  # the controllers package's policy has a report()
        assert d["controller_report"]["controller"] == "pid"


def test_batched_truth_positions_are_the_one_by_one_ones():
    """simulate() fills the truth's latitude/longitude 100 records per pymap3d call
    (runner.TRUTH_LATLON_BATCH); the stream is the one Simulation.steps gives converting
    each record alone: same steps in the same order, same positions (measured: identical)."""
    from onboard.sitl.runner import TRUTH_LATLON_BATCH, Simulation

    duration = 25.0  # 251 records: two full batches and a partial one
    batched = list(simulate("jaiabot-turns", duration, seed=3))
    single = list(Simulation("jaiabot-turns", 3).steps(duration))
    truths = [tr for _, _, tr in batched if tr is not None]
    assert len(truths) == 251 > 2 * TRUTH_LATLON_BATCH
    assert [t for t, _, _ in batched] == [t for t, _, _ in single]
    for (_, sa, ta), (_, sb, tb) in zip(batched, single):
        assert sa == sb and ta == tb and (ta is None or ta.lat_deg is not None)
