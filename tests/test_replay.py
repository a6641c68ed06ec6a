"""``onboard replay`` end to end: outputs, determinism, bad input, every vehicle class."""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys

from pathlib import Path

import pytest

from onboard.cli import main as cli_main
from onboard.sitl.runner import run_to_tlog

pytestmark = pytest.mark.integration


def onboard(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "onboard", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def jaiabot_tlog(tmp_path_factory):
    p = tmp_path_factory.mktemp("jaiabot") / "jaiabot.tlog"
    run_to_tlog("jaiabot-turns", p, None, duration=60.0, seed=3)
    return p


def test_replay_writes_estimates_summary_and_track(jaiabot_tlog, tmp_path):
    r = onboard("replay", str(jaiabot_tlog), "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    rows = list(csv.reader(open(tmp_path / "estimates.csv")))
    header = rows[0]
    assert header[0] == "t" and float(rows[1][0]) == 0.0
    for col in ("aie.north", "aie.east", "aie.heading", "aie.speed", "aie.yaw_rate",
                "aie.surge_input", "aie.yaw_input", "kf.north", "kf.east", "kf.heading",
                "kf.speed", "current.north", "current.east", "current.std_north"):
        assert col in header
    assert len(rows) > 500  # 60 s at 10 Hz
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["vehicle_class"] == "rudder-boat"
    assert "SERVO1_FUNCTION=26" in summary["config"]
    assert summary["time_span"]["duration_s"] == pytest.approx(60.0, abs=1.0)
    assert summary["read"]["rejected"] == {}
    assert (tmp_path / "track.png").stat().st_size > 5000


def test_replay_is_deterministic_byte_for_byte(jaiabot_tlog, tmp_path):
    for d in ("a", "b"):
        assert onboard("replay", str(jaiabot_tlog), "--out", str(tmp_path / d),
                       "--no-plot").returncode == 0
    assert (tmp_path / "a" / "estimates.csv").read_bytes() == \
        (tmp_path / "b" / "estimates.csv").read_bytes()


@pytest.mark.parametrize("content", [b"", b"\x00\x01garbage" * 100, b"not a log at all\n"])
def test_unreadable_input_exits_2_with_one_line(tmp_path, content):
    p = tmp_path / "bad.tlog"
    p.write_bytes(content)
    r = onboard("replay", str(p), "--out", str(tmp_path / "out"))
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


def test_missing_file_and_bad_config_exit_2(tmp_path, jaiabot_tlog):
    assert onboard("replay", str(tmp_path / "nope.tlog")).returncode == 2
    bad = tmp_path / "bad.toml"
    bad.write_text("[vehicle]\nclass = 'boat'\n")
    r = onboard("replay", str(jaiabot_tlog), "--config", str(bad))
    assert r.returncode == 2 and "vehicle.class" in r.stderr


def test_corrupted_tlog_is_replayed_with_counted_rejections(jaiabot_tlog, tmp_path):
    data = bytearray(jaiabot_tlog.read_bytes())
    for i in range(1000, len(data), 5000):
        data[i] ^= 0x5A
    p = tmp_path / "damaged.tlog"
    p.write_bytes(bytes(data))
    r = onboard("replay", str(p), "--out", str(tmp_path / "out"), "--no-plot")
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert sum(summary["read"]["rejected"].values()) > 0


@pytest.mark.parametrize("scenario, cls, columns", [
    # current: a component is an empty cell while unknown (the along-track one on these
    # 30 s straight starts); its one-sigma is always there
    ("twin-thruster-turns", "twin-thruster-boat", ("aie.speed", "kf.speed", "current.std_north")),
    ("bluerov2-circle", "bluerov2", ("eseso.dist_x", "eseso.dist_y", "eseso.dist_z")),
    ("gavia-tidal", "torpedo-auv", ("current.east", "current.std_north", "current.std_down")),
])
def test_every_vehicle_class_is_detected_and_estimated(tmp_path, scenario, cls, columns):
    p = tmp_path / "log.tlog"
    run_to_tlog(scenario, p, None, duration=30.0, seed=2)
    r = onboard("replay", str(p), "--out", str(tmp_path / "out"), "--no-plot")
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["vehicle_class"] == cls
    rows = list(csv.DictReader(open(tmp_path / "out" / "estimates.csv")))
    for col in columns:
        assert any(row[col] for row in rows[-50:]), col


def test_a_pipeline_that_fails_is_counted_in_the_summary(tmp_path, monkeypatch) -> None:
    """A pipeline that raises is restarted by the engine; the replay's summary counts it
    (``pipeline:<name>:error``), so a crash never passes for a quiet run."""
    from onboard.pipelines.surge_heading import SurgeHeadingPipeline

    def broken(self, t):
        raise RuntimeError("broken on purpose")

    monkeypatch.setattr(SurgeHeadingPipeline, "_output", broken)
    log = Path(__file__).resolve().parent / "data" / "replay" / "jaiabot-turns.tlog"
    assert cli_main(["replay", str(log), "--out", str(tmp_path), "--no-plot"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["rejected"]["pipeline:aie:error"] > 100
    assert summary["rejected"]["pipeline:kf:error"] > 100
    restarted = {w["pipeline"]: w for w in summary["warnings"]
                 if w["code"] == "pipeline_restarted"}
    assert set(restarted) == {"aie", "kf"}
    assert "broken on purpose" in restarted["aie"]["message"]
    assert restarted["aie"]["t_end"] - restarted["aie"]["t_start"] > 30.0  # one line, 40 s


def test_a_log_without_a_heading_says_why_it_gives_no_estimate(tmp_path, capsys) -> None:
    """A DVL-only capture (body velocities, no compass, no GNSS): each pipeline that gives
    nothing says what it lacks, in summary.json and at the end of the output."""
    log = Path(__file__).resolve().parent / "data" / "dvl_json" / "a50.jsonl"
    assert cli_main(["replay", str(log), "--out", str(tmp_path), "--no-plot"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    none = {w["pipeline"]: w["message"] for w in summary["warnings"]
            if w["code"] == "no_estimate"}
    assert set(none) == {"nav", "aie", "kf", "current"}
    assert "needs a heading" in none["current"] and "dvl (8)" in none["current"]
    out = capsys.readouterr().out
    assert "4 warnings:" in out and "current gave no estimate" in out


def test_a_capture_of_fixes_without_speed_and_course(tmp_path):
    """An NMEA capture of positions (GGA) and a heading (HDT), no RMC or VTG: the current
    gives nothing, and says its GNSS fixes carry no speed and course (not that its inputs
    never lined up), while aie and kf track the positions; with RMC's speed and course
    beside them the current estimates."""
    from onboard.drivers.nmea import encode_gga, encode_hdt, encode_rmc

    def capture(name: str, rmc: bool) -> Path:
        lines = []
        for k in range(600):   # 2 min at 5 Hz, heading north at 1 m/s
            t = 1_767_225_600.0 + 0.2 * k
            lat = 41.49 + k * 0.2 / 111_000.0
            lines.append(encode_gga(t, lat, -71.42))
            if rmc:
                lines.append(encode_rmc(t, lat, -71.42, 1.0, 0.0))
            lines.append(encode_hdt(0.0))
        log = tmp_path / name
        log.write_bytes(b"".join(lines))
        return log

    out = tmp_path / "gga"
    assert cli_main(["replay", str(capture("gga.nmea", False)), "--out", str(out),
                     "--no-plot"]) == 0
    none = {w["pipeline"]: w["message"] for w in
            json.loads((out / "summary.json").read_text())["warnings"]
            if w["code"] == "no_estimate"}
    assert re.search(r"the log's 59\d GNSS fixes carry no speed and course", none["current"])
    # the first heading came between the first two fixes: the track's step from a point
    # without a heading once made the aie/kf positions NaN for the rest of the run
    summary = json.loads((out / "summary.json").read_text())
    assert not {k: n for k, n in summary["withheld"].items() if k.endswith(":nonfinite")}
    last = list(csv.DictReader(open(out / "estimates.csv")))[-1]
    assert float(last["aie.north"]) == pytest.approx(119.8, abs=3.0)
    assert float(last["kf.north"]) == pytest.approx(119.8, abs=3.0)
    out = tmp_path / "rmc"
    assert cli_main(["replay", str(capture("rmc.nmea", True)), "--out", str(out),
                     "--no-plot"]) == 0
    assert not [w for w in json.loads((out / "summary.json").read_text())["warnings"]
                if w["code"] == "no_estimate" and w["pipeline"] == "current"]


@pytest.mark.data
def test_an_ardusub_log_replayed_as_a_boat_says_so(shared_data, tmp_path) -> None:
    """small.BIN (a disarmed BlueROV2 on a bench, HEARTBEAT MAV_TYPE_SUBMARINE) forced to
    the rudder-boat configuration: the run says the class disagrees, and that the log has
    no position source."""
    log = shared_data / "ardusub_small_logs" / "small.BIN"
    if not log.exists():
        pytest.skip(f"{log} not present")
    assert cli_main(["replay", str(log), "--out", str(tmp_path), "--no-plot",
                     "--config", "rudder-boat"]) == 0
    codes = {w["code"] for w in json.loads((tmp_path / "summary.json").read_text())["warnings"]}
    assert {"class_mismatch", "no_position_source"} <= codes


def test_progress_says_how_far_into_the_log_not_its_raw_stamp(capsys):
    """A glider's CSV stamps its rows with the date (1.57e9 s): the progress line counts
    from the first sample."""
    from onboard.core.messages import Heading
    from onboard.offline.replay import _Progress

    progress = _Progress(True)
    samples = (Heading(t=1_574_790_000.0 + k, source="c", heading_rad=0.0) for k in range(1100))
    assert sum(1 for _ in progress.wrap(samples)) == 1100
    err = capsys.readouterr().err
    assert "1,024 samples, 1,023 s into the log" in err and "1574" not in err


def test_a_folder_of_csv_runs_names_the_logs_it_does_not_read(tmp_path, capsys):
    """A day's folder holding a CSV run, a tlog, an NMEA capture and a README, replayed
    with a [csv] mapping: the CSV run is replayed as alone, and the tlog and the NMEA
    capture, which a folder's replay does not read, are named in summary.json's
    read.skipped_files and in a ``logs_not_read`` warning listed first (the README
    named as no log, with no warning)."""
    import shutil

    data = Path(__file__).resolve().parent / "data"
    config = str(Path(__file__).resolve().parents[1] / "config" / "blueboat-ntnu-csv.toml")
    day = tmp_path / "day1"
    day.mkdir()
    shutil.copyfile(data / "csv" / "blueboat-run.csv", day / "blueboat-run.csv")
    shutil.copyfile(data / "replay" / "jaiabot-turns.tlog", day / "jaiabot.tlog")
    shutil.copyfile(data / "nmea" / "gnss-compass.nmea", day / "gnss.txt")
    (day / "README.md").write_text("# day 1\n")
    for log, out in ((day, "folder"), (day / "blueboat-run.csv", "alone")):
        assert cli_main(["replay", str(log), "--config", config, "--out",
                         str(tmp_path / out), "--no-plot"]) == 0
    printed = capsys.readouterr().out
    assert (tmp_path / "folder" / "estimates.csv").read_bytes() == \
        (tmp_path / "alone" / "estimates.csv").read_bytes()
    read = json.loads((tmp_path / "folder" / "summary.json").read_text())["read"]
    assert read["skipped"] == {"log_file": 2, "other_file": 1}
    assert [(f["file"], f["why"].split(",")[0]) for f in read["skipped_files"]] == [
        ("README.md", "not a log (a document (.md))"), ("gnss.txt", "a text capture"),
        ("jaiabot.tlog", "a MAVLink telemetry log (tlog)")]
    warnings = json.loads((tmp_path / "folder" / "summary.json").read_text())["warnings"]
    assert warnings[0]["code"] == "logs_not_read"
    assert "gnss.txt, jaiabot.tlog" in warnings[0]["message"]
    assert "onboard batch day1" in warnings[0]["message"]
    assert "logs_not_read: 2 log(s) in day1 not read: gnss.txt, jaiabot.tlog" in printed
    alone = json.loads((tmp_path / "alone" / "summary.json").read_text())
    assert "skipped_files" not in alone["read"] and "skipped" not in alone["read"]
