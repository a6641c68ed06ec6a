"""The UTC of a log's clock (drivers/logclock.py): GPS week and time of week against
published instants and against pymavlink's DataFlash clock, the readers that carry UTC
and those that do not, the runs of a CSV directory and a service recording's meta record.
"""

from __future__ import annotations

import calendar
import json
from pathlib import Path

import pytest

from onboard.drivers.dataflash import DataflashReader
from onboard.drivers.logclock import LogClock, gps_to_utc, iso8601, log_clock
from onboard.drivers.logs import open_log
from onboard.drivers.recording import RawRecord, RecordingWriter
from onboard.core import config as configmod
from tests.helpers.dataflash_log import gps_timed_log

REPO = Path(__file__).resolve().parents[1]
JAIABOT = REPO / "tests/data/replay/jaiabot-turns.tlog"
DVL_V3 = REPO / "tests/data/dvl_json/a50.jsonl"

WEEK_2048_UTC = calendar.timegm((2019, 4, 6, 23, 59, 42))
"""The start of GPS week 2048 (the second week-number rollover) in UTC: 2019-04-07T00:00:00
GPS time, 18 leap seconds ahead of UTC."""
WEEK_1024_UTC = calendar.timegm((1999, 8, 21, 23, 59, 47))
"""The start of GPS week 1024 (the first rollover) in UTC: 13 leap seconds then."""
GPS_TIME = (2262, 345_600_000)
"""GPS week and time of week (ms) of the synthetic log's first timed GPS record: a
Wednesday of May 2023."""


def _first(log: Path, cfg=None):
    fmt, reader = open_log(log, *((cfg.csv, ()) if cfg is not None else ()))
    first = next(iter(reader))
    return fmt, reader, first


def test_gps_time_becomes_utc_with_the_leap_seconds_of_its_day():
    assert gps_to_utc(0, 0) == calendar.timegm((1980, 1, 6, 0, 0, 0))
    assert gps_to_utc(2048, 0) == WEEK_2048_UTC
    assert gps_to_utc(1024, 0) == WEEK_1024_UTC


def _dataflash(tmp_path: Path, week: int, tow_ms: int) -> Path:
    """The synthetic boat with GPS time (tests/helpers/dataflash_log.py)."""
    path = tmp_path / "gps.bin"
    path.write_bytes(gps_timed_log(week, tow_ms))
    return path


def test_a_dataflash_log_is_in_utc_from_its_first_gps_time_as_pymavlink_reads_it(tmp_path):
    """pymavlink's DFReader (ArduPilot's own log tool) stamps every record from the first
    GPS time as we do: TimeUS plus (GPS time less 18 s) minus that record's TimeUS."""
    from pymavlink import mavutil

    path = _dataflash(tmp_path, *GPS_TIME)
    fmt, reader, first = _first(path)
    clock = log_clock(fmt, reader, path, first.t)
    assert clock.utc and "GPS record" in clock.source
    log = mavutil.mavlink_connection(str(path))
    stamps = []
    while (m := log.recv_match(type="GPS")) is not None:
        stamps.append((m.TimeUS / 1e6, m._timestamp))
    assert len(stamps) == 12
    for t, theirs in stamps:
        assert clock.to_utc(t) == pytest.approx(theirs, abs=1e-6)
    assert iso8601(clock.to_utc(12.0)).startswith("2023-05-")


def test_a_dataflash_log_without_gps_time_has_no_utc(tmp_path):
    path = _dataflash(tmp_path, 0, 0)
    fmt, reader, first = _first(path)
    clock = log_clock(fmt, reader, path, first.t)
    assert not clock.utc and clock.to_utc(first.t) is None
    assert clock.source.startswith("no UTC") and "time since boot" in clock.source
    assert DataflashReader(path).gps_time is None


def test_a_tlog_and_a_dvl_capture_are_in_utc_as_stamped():
    fmt, reader, first = _first(JAIABOT)
    clock = log_clock(fmt, reader, JAIABOT, first.t)
    # the simulator's tlog starts on 2026-01-01 (its record stamps)
    assert clock.utc and clock.to_utc(first.t) == first.t
    assert clock.summary(first.t)["start"] == "2026-01-01T00:00:00.000Z"
    fmt, reader, first = _first(DVL_V3)
    assert log_clock(fmt, reader, DVL_V3, first.t).to_utc(first.t) == first.t


def test_a_clock_that_reads_before_2000_is_no_date(tmp_path):
    """A DVL json_v1 capture is timed from 0 (the sum of its intervals): no UTC."""
    v1 = tmp_path / "v1.txt"
    v1.write_text("".join(
        json.dumps({"time": 200.0, "vx": 0.1, "vy": 0.0, "vz": 0.0, "fom": 0.01,
                    "altitude": 1.0, "velocity_valid": True, "status": 0,
                    "format": "json_v1", "transducers": []}) + "\n" for _ in range(3)))
    fmt, reader, first = _first(v1)
    clock = log_clock(fmt, reader, v1, first.t)
    assert not clock.utc and "json_v1" in clock.source
    assert clock.summary(first.t) == {"utc": False, "source": clock.source, "start": None}


DDBOAT_GPS_LINE = ("{stamp} - INFO - Temperature l,r are 24 26 deg.C /cmd motors l,r are "
                   "b'dirl: 1, motl: 0, dirr: 1, motr: 0\\r' /GPS [4825.0835, 'N', 428.4051, "
                   "'W', {hhmmss}, 'A'] /IMU: MAG [225, -3715, 1858] /\n")


def _ddboat(tmp_path: Path, lines: list[tuple[str, str]]) -> Path:
    """A DDBoat log of GPS lines, each (line stamp, GPS hhmmss)."""
    path = tmp_path / "ddboat.log"
    path.write_text("".join(DDBOAT_GPS_LINE.format(stamp=a, hhmmss=b) for a, b in lines))
    return path


def test_a_ddboat_log_is_put_on_utc_by_its_gps_time_of_day(tmp_path):
    """The boat's clock 53 min 54 s behind its GPS (as DDBOAT8_t_2022_9_2_0_0.log): UTC
    is the GPS time of day on the lines' date, the offset said in the source; a repeated
    GPS time (an old fix) is not counted."""
    path = _ddboat(tmp_path, [("2022-09-02 11:41:14,000", "123508.0"),
                              ("2022-09-02 11:41:15,000", "123509.0"),
                              ("2022-09-02 11:41:15,500", "123509.0"),
                              ("2022-09-02 11:41:16,000", "123510.0")])
    fmt, reader, first = _first(path)
    clock = log_clock(fmt, reader, path, first.t)
    assert clock.utc and clock.offsets == ((first.t, 3234.0),)
    assert clock.summary(first.t)["start"] == "2022-09-02T12:35:08.000Z"
    assert "GPS" in clock.source and "-0.90 h, -0:53:54, from UTC" in clock.source


def test_a_ddboat_gps_time_across_midnight_is_of_the_day_it_reads(tmp_path):
    """A GPS time of day 12 h or more from the line's stamp is of the day before or after
    the line's date: a boat clock on UTC+2 across its midnight (its GPS still on the day
    before), one on UTC-2 before its midnight (its GPS on the next day)."""
    path = _ddboat(tmp_path, [("2022-09-02 23:59:58,000", "215958.0"),
                              ("2022-09-03 00:00:01,000", "220001.0")])
    fmt, reader, first = _first(path)
    clock = log_clock(fmt, reader, path, first.t)
    assert clock.offsets == ((first.t, -7200.0),)
    assert clock.summary(first.t)["start"] == "2022-09-02T21:59:58.000Z"
    late = _ddboat(tmp_path, [("2022-09-02 23:59:58,000", "015958.0")])
    fmt, reader, first = _first(late)
    assert log_clock(fmt, reader, late, first.t).summary(first.t)["start"] == \
        "2022-09-03T01:59:58.000Z"


def test_a_ddboat_log_without_a_gps_fix_keeps_its_stamps_as_utc(tmp_path):
    path = tmp_path / "ddboat.log"
    path.write_text(DDBOAT_GPS_LINE.format(stamp="2022-09-02 11:41:14,000", hhmmss="123508.0")
                    .replace("'A']", "'V']"))
    fmt, reader, first = _first(path)
    clock = log_clock(fmt, reader, path, first.t)
    assert clock.offsets == ((first.t, 0.0),) and "taken as UTC" in clock.source


def _posix_csv_runs(tmp_path: Path, starts_ms: tuple[float, ...]) -> Path:
    """Copies of the BlueBoat run whose time column is POSIX ms from ``starts_ms``."""
    import csv

    src = list(csv.reader(open(REPO / "tests/data/csv/blueboat-run.csv")))
    col = src[0].index("original_timestamp")
    t0 = float(src[1][col])
    d = tmp_path / "runs"
    d.mkdir()
    for k, start in enumerate(starts_ms):
        rows = [src[0]] + [r[:col] + [f"{float(r[col]) - t0 + start:.3f}"] + r[col + 1:]
                           for r in src[1:]]
        with open(d / f"run_{k}.csv", "w", newline="") as f:
            csv.writer(f).writerows(rows)
    return d


def test_each_run_of_a_csv_directory_keeps_its_own_utc(tmp_path):
    """Two runs an hour apart are joined on one time line 10 s apart; their UTC is not."""
    start = calendar.timegm((2024, 6, 1, 12, 0, 0)) * 1000.0
    d = _posix_csv_runs(tmp_path, (start, start + 3_600_000.0))
    cfg = configmod.load_all([str(REPO / "config/blueboat-ntnu-csv.toml")])
    fmt, reader, first = _first(d, cfg)
    clock = log_clock(fmt, reader, d, first.t)
    r0, r1 = reader.runs
    assert clock.utc and r1.t_start - r0.t_end < 60.0  # joined
    assert clock.to_utc(r0.t_start) == pytest.approx(start / 1000.0)
    assert clock.to_utc(r1.t_start) == pytest.approx(start / 1000.0 + 3600.0)


def test_a_csv_in_time_since_boot_has_no_utc():
    cfg = configmod.load_all([str(REPO / "config/blueboat-ntnu-csv.toml")])
    log = REPO / "tests/data/csv/blueboat-run.csv"
    fmt, reader, first = _first(log, cfg)
    clock = log_clock(fmt, reader, log, first.t)
    assert not clock.utc and "CSV time column" in clock.source


def test_a_recording_is_in_utc_from_the_wall_clock_of_its_meta_record(tmp_path):
    path = tmp_path / "onboard-1-0000.onbrec"
    wall, mono = calendar.timegm((2025, 3, 1, 8, 0, 0)) + 0.25, 1234.5
    with RecordingWriter(path, fsync=False) as w:
        w.write(RawRecord(t=mono, source="recorder", kind="meta",
                          data=json.dumps({"wall_time": wall, "clock": mono}).encode()))
    clock = log_clock("recording", None, path, mono)
    assert clock.utc and clock.to_utc(mono + 10.0) == pytest.approx(wall + 10.0)
    assert log_clock("recording", None, tmp_path, mono).offsets == clock.offsets
    bare = tmp_path / "bare" / "x.onbrec"
    bare.parent.mkdir()
    with RecordingWriter(bare, fsync=False) as w:
        w.write(RawRecord(t=1.0, source="recorder", kind="meta", data=b"{}"))
    assert not log_clock("recording", None, bare, 1.0).utc


def test_the_offsets_apply_from_their_start_and_the_first_before_it():
    c = LogClock("two runs", ((100.0, 1000.0), (200.0, 5000.0)))
    assert [c.to_utc(t) for t in (50.0, 150.0, 250.0)] == [1050.0, 1150.0, 5250.0]
    # to the nearest millisecond, carried into the seconds
    assert iso8601(0.0006) == "1970-01-01T00:00:00.001Z"
    assert iso8601(59.9996) == "1970-01-01T00:01:00.000Z"


@pytest.mark.data
def test_real_logs_with_and_without_utc(shared_data):
    """Measured: the ArduSub tlog from 2023-05-04 17:15 (the topside's clock), its NMEA
    capture from 2023-09-01 22:56 (the RMC sentences; the lines' prefixes are 7 h off), the
    Shenzhen NMEA from 2024-12-05 02:27 (RMC date and time), the survey boat's Test1 from
    2018-04-18 (its GPS started on a default date in 2009 and jumped twice), the DDBoat
    from 2022-09-02 12:35 (its GPS time; the boat's clock read 11:41); the ArduSub
    DataFlash (no GPS records) and the BlueBoat CSV (ms since boot) have no UTC."""
    want = {"ardusub_small_logs/small.tlog": "2023-05-04T17:15",
            # its line prefixes read 15:56, local time: the RMC sentences say 22:56 UTC
            "ardusub_small_logs/nmea_log.txt": "2023-09-01T22:56",
            "usv_rtk_gnss_heading_nmea_shenzhen/202412051037.txt": "2024-12-05T02:27",
            "survey_boat_arduino_rc/Test1_counterclockwise.TXT": "2018-04-18T17:4",
            # its lines read 11:41:14, its first GPS line 12:35:08 (UTC)
            "ddboat_ensta_log/DDBOAT8_t_2022_9_2_0_0.log": "2022-09-02T12:35:0",
            "ardusub_small_logs/small.BIN": None}
    for name, start in want.items():
        log = shared_data / name
        fmt, reader, first = _first(log)
        got = log_clock(fmt, reader, log, first.t).summary(first.t)["start"]
        assert (got or "").startswith(start or "") and (got is None) == (start is None), name
