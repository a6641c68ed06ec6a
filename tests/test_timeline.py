"""Time that cannot be fooled (issue 22, item 6): a single stamp far in the future or the
past is a counted ``time_outlier`` and the samples after it are kept; a real clock jump
starts a new segment, durations count the segments; nothing spins.

Before: one CSV stamp moved +1e12 ms made the replay spin for over ten minutes (the
current filter predicted across 1e9 s in 0.1 s steps); +1e8 ms rejected every later row
as ``time_backwards`` and reported a 100,150 s duration.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from onboard.cli import main as cli_main
from onboard.core.messages import Imu
from onboard.drivers.dataflash import DataflashReader
from onboard.core.stamps import ANCHOR_STAMPS
from onboard.engine.timeline import CONFIRM_STAMPS, TIME_JUMP_S, Timeline
from tests.helpers import dataflash_log as df
from tests.helpers.reset_tlog import write_reset_tlog

REPO = Path(__file__).resolve().parents[1]
CSV = REPO / "tests/data/csv/blueboat-run.csv"
CONFIG = REPO / "config/blueboat-ntnu-csv.toml"
BAD_ROW = 7
"""The row (1-based, after the header; every column filled) whose stamp the tests move.
The file also has a row 0.3 s back (``time_backwards``), one short row (``malformed``)
and an empty heading."""


def imu(t: float) -> Imu:
    return Imu(t=t, accel_x=0.0, accel_y=0.0, accel_z=-9.81, gyro_x=0.0, gyro_y=0.0,
               gyro_z=0.0)


def admit_all(tl: Timeline, times: list[float]) -> list[float]:
    out = [s.t for t in times for s in tl.admit(imu(t))]
    return out + [s.t for s in tl.flush()]


def started(tl: Timeline, t0: float = 0.0) -> list[float]:
    """Start ``tl`` with :data:`ANCHOR_STAMPS` agreeing stamps from ``t0`` (0.1 s apart);
    the stamps released."""
    return [s.t for k in range(ANCHOR_STAMPS) for s in tl.admit(imu(t0 + 0.1 * k))]


# ------------------------------------------------------------------- the rule itself

def test_a_single_stamp_far_ahead_is_an_outlier_and_the_later_samples_are_kept():
    tl = Timeline()
    assert admit_all(tl, [0.0, 0.1, 1e9, 0.2, 0.3, 0.4]) == [0.0, 0.1, 0.2, 0.3, 0.4]
    assert [s.t for s in tl.outliers] == [1e9]
    assert len(tl.segments) == 1 and tl.duration_s == pytest.approx(0.4)


def test_a_sparse_log_is_one_segment_where_its_jump_span_covers_its_silences():
    """A glider's .sbd logs a cycle every 4-60 s: with ``[engine] time_jump_s = 120`` a
    run of stamps 45 s apart is one segment and none is an outlier; with the default
    10 s most of them were outliers (the amadeus .sbd: 26 % used). A silence beyond the
    span is still a jump."""
    stamps = [45.0 * k for k in range(20)] + [45.0 * 19 + 300.0 + 45.0 * k for k in range(5)]
    wide = Timeline(jump_s=120.0)
    assert admit_all(wide, stamps) == stamps and not wide.outliers
    assert len(wide.segments) == 2
    narrow = Timeline()
    assert len(admit_all(narrow, stamps)) < len(stamps) // 2


def test_a_single_stamp_far_back_is_an_outlier_too():
    tl = Timeline()
    assert admit_all(tl, [500.0, 500.1, 0.0, 500.2, 500.3]) == [500.0, 500.1, 500.2, 500.3]
    assert [s.t for s in tl.outliers] == [0.0]


def test_a_clock_that_goes_back_and_stays_there_is_a_jump_with_two_segments():
    tl = Timeline()
    released = started(tl, 500.0)
    for t in [3.0, 3.1, 3.2]:
        released += [s.t for s in tl.admit(imu(t))]
        if tl.jump is not None:
            jump = tl.jump
    assert released == pytest.approx([500.0, 500.1, 500.2, 500.3, 500.4, 3.0, 3.1, 3.2])
    assert jump.t_before == pytest.approx(500.4) and jump.t_after == 3.0
    assert [(s.start, s.end) for s in tl.segments] == [
        (500.0, pytest.approx(500.4)), (3.0, 3.2)]
    assert tl.duration_s == pytest.approx(0.6)


def test_a_stamp_is_held_only_until_its_side_has_CONFIRM_STAMPS_stamps():
    tl = Timeline()
    started(tl)
    far = 2 * TIME_JUMP_S
    held = [tl.admit(imu(far + 0.1 * k)) for k in range(CONFIRM_STAMPS)]
    assert all(r == [] for r in held[:-1]) and len(held[-1]) == CONFIRM_STAMPS


def test_samples_still_held_when_the_run_ends_are_outliers():
    tl = Timeline()
    assert admit_all(tl, [0.0, 0.1, 1e6]) == [0.0, 0.1]
    assert [s.t for s in tl.outliers] == [1e6]


# ---------------------------------------------------- the start: a consensus, not a row

@pytest.mark.parametrize("bad", [[1e9], [-1e9], [1e9, 1e9 + 0.1], [1e9, -1e9]],
                         ids=["far-ahead", "far-back", "two-agreeing", "both-sides"])
def test_bad_first_stamps_are_outliers_and_the_log_starts_where_the_rest_agree(bad):
    """Before: the first stamp was trusted; a bad one started a segment of its own and the
    real stamps came as a clock jump (issue 30: "time_jump [-837399.4--837399.4 s]")."""
    tl = Timeline()
    good = [0.1 * k for k in range(8)]
    assert admit_all(tl, [*bad, *good]) == pytest.approx(good)
    assert sorted(s.t for s in tl.outliers) == sorted(bad)
    assert [(s.start, s.end) for s in tl.segments] == [(0.0, pytest.approx(0.7))]


def test_the_start_is_decided_after_ANCHOR_STAMPS_distinct_stamps_and_released_in_order():
    tl = Timeline()
    out = [[s.t for s in tl.admit(imu(t))] for t in [5.0, 5.0, 5.1, 5.2, 5.3, 5.4, 5.5]]
    # two samples share the first stamp: the fifth distinct stamp (the sixth sample) decides
    assert out[:5] == [[]] * 5 and out[5] == [5.0, 5.0, 5.1, 5.2, 5.3, 5.4]
    assert out[6] == [5.5]


def test_a_log_of_fewer_stamps_than_the_anchor_waits_for_is_released_at_its_end():
    tl = Timeline()
    assert [s.t for t in [7.0, 7.1, 1e9] for s in tl.admit(imu(t))] == []
    assert [s.t for s in tl.flush()] == [7.0, 7.1] and [s.t for s in tl.outliers] == [1e9]


def test_two_disagreeing_stamps_keep_the_first_as_before_any_anchoring():
    tl = Timeline()
    assert admit_all(tl, [3.0, 500.0]) == [3.0]


def test_a_clock_jump_within_the_first_stamps_loses_the_minority_before_it():
    """The rule's price, written down in docs/architecture.md §3: a log whose clock steps
    within its first ANCHOR_STAMPS stamps starts after the step; the stamps before it are
    counted outliers, not a segment of their own."""
    tl = Timeline()
    assert admit_all(tl, [3.0, 3.1, 500.0, 500.1, 500.2, 500.3]) == pytest.approx(
        [500.0, 500.1, 500.2, 500.3])
    assert [s.t for s in tl.outliers] == [3.0, 3.1] and len(tl.segments) == 1


def test_largest_group_chains_slow_stamps_and_breaks_ties_by_order():
    from onboard.core.stamps import largest_group

    # a glider's 8 s steps chain into one group although 0 and 32 are 32 s apart
    assert largest_group([0.0, 8.0, 16.0, 1e9, 24.0], TIME_JUMP_S) == (0.0, 24.0)
    assert largest_group([500.0, 3.0], TIME_JUMP_S) == (500.0, 500.0)
    assert largest_group([3.0, 500.0, 500.1], TIME_JUMP_S) == (500.0, 500.1)


# ------------------------------------------------------------------- the words of time

def test_a_stamp_is_named_as_a_utc_time_or_as_seconds_on_the_logs_clock():
    from onboard.engine.timeline import duration_words, stamp_words

    assert stamp_words(1683220541.05) == "2023-05-04 17:15:41.0 UTC"
    assert stamp_words(1444.25) == "t = 1,444.2 s"
    assert duration_words(10.36) == "10.4 s"
    assert duration_words(837399.4) == "837,399 s (9.7 days)"


def test_a_jump_says_from_what_stamp_to_what():
    from onboard.engine.timeline import Jump

    back = Jump(1683220804.4, 1682383405.0).words()
    assert back.startswith("the log's clock went back 837,399 s (9.7 days), from "
                           "2023-05-04 17:20:04.4 UTC to 2023-04-25 00:43:25.0 UTC")
    assert Jump(292.2, 401.2).words().startswith(
        "no sample for 109.0 s, from t = 292.2 s to t = 401.2 s")


def test_log_time_counts_the_segments_never_negative():
    from onboard.engine.timeline import log_time

    segments = [(1000.0, 1010.0), (3.0, 8.0)]  # the clock went back after 10 s
    assert log_time(segments, 1000.0) == 0.0
    assert log_time(segments, 1005.0) == 5.0
    assert log_time(segments, 5.0) == 12.0  # 10 s of the first segment + 2 s
    assert log_time(segments, 1.0) == 0.0   # before every segment: the start
    assert log_time([], 5.0) == 0.0


def test_a_warning_after_a_gap_names_its_span_in_estimates_csv_too(capsys):
    """After a 109-s gap (small.BIN) the span along the segments (26.6 s: the gap not
    counted) is not where the rows are in estimates.csv (t 135.6): the printed span says
    both; without a gap, one."""
    from onboard.offline.replay import print_warnings

    segments = [{"start": 265.6, "end": 292.2}, {"start": 401.2, "end": 401.3}]
    warnings = [{"code": "time_jump", "t_start": 401.2, "t_end": 401.2, "message": "m"},
                {"code": "x", "t_start": 270.0, "t_end": 280.0, "message": "m"}]
    print_warnings(warnings, 0.0, segments)
    out = capsys.readouterr().out
    assert "time_jump [26.6-26.6 s; estimates.csv t 135.6 to 135.6]: m" in out
    assert "x [4.4-14.4 s]: m" in out


# --------------------------------------------------------------- replays of a CSV log

def moved_csv(tmp_path: Path, shift_ms: float, rows: range = range(BAD_ROW, BAD_ROW + 1)) -> Path:
    """The BlueBoat test CSV with the stamps of ``rows`` moved by ``shift_ms``."""
    lines = CSV.read_text().splitlines()
    for i in rows:
        cells = lines[i].split(",")
        cells[0] = repr(float(cells[0]) + shift_ms)
        lines[i] = ",".join(cells)
    path = tmp_path / "moved.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def replay(tmp_path: Path, log: Path, config: Path | None = CONFIG) -> dict:
    out = tmp_path / "out"
    args = ["--config", str(config)] if config else []
    assert cli_main(["replay", str(log), *args, "--out", str(out), "--no-plot"]) == 0
    return json.loads((out / "summary.json").read_text())


def baseline(tmp_path: Path) -> dict:
    return replay(tmp_path / "base", CSV)


@pytest.mark.parametrize("shift_ms", [1e12, 1e8, -1e8])
def test_one_csv_stamp_moved_far_is_an_outlier_and_the_rows_after_it_are_kept(
        tmp_path, shift_ms):
    base = baseline(tmp_path)
    s = replay(tmp_path, moved_csv(tmp_path, shift_ms))
    # the moved row is the only one lost, counted by the reader (drivers.csvlog._RowClock)
    assert s["read"]["by_type"]["row"] == base["read"]["by_type"]["row"] - 1
    assert s["read"]["rejected"] == {**base["read"]["rejected"], "time_outlier": 1}
    # its 5 samples, no more (before: +1e8 ms lost every later row as time_backwards)
    assert sum(base["accepted"].values()) - sum(s["accepted"].values()) == 5
    # the duration of the unmoved file: 1.1 s (before: 100,150 s at +1e8 ms)
    assert s["time_span"]["duration_s"] == pytest.approx(base["time_span"]["duration_s"])
    assert len(s["time_span"]["segments"]) == 1
    assert s["rows"] == base["rows"]
    assert "time_outlier" in {w["code"] for w in s["warnings"]}


def test_a_csv_clock_that_goes_back_loses_the_rows_until_it_catches_up(tmp_path):
    """A clock stepped back inside one CSV run: the rows stay in time order (readers yield
    samples in time order), so the rows behind are ``time_backwards``, as in a tlog.
    The engine's time line makes segments of a clock that goes back when a reader passes
    it on (test_a_clock_that_goes_back_and_stays_there_is_a_jump_with_two_segments)."""
    base = baseline(tmp_path)
    lines = CSV.read_text().splitlines()
    s = replay(tmp_path, moved_csv(tmp_path, -400_000.0, range(BAD_ROW, len(lines))))
    # rows 1-6 used; rows 7-15 rejected: 7 time_backwards (the 400 s step and the row
    # 0.3 s back among them), the last row a time_outlier, one short row malformed; row 6
    # has no heading (nan)
    assert s["read"]["by_type"]["row"] == BAD_ROW - 1
    assert s["read"]["rejected"] == {"malformed": 1, "nan": 1, "time_backwards": 7,
                                     "time_outlier": 1}
    assert len(s["time_span"]["segments"]) == 1


@pytest.mark.parametrize("shift_ms", [1e12, -1e12])
def test_a_csv_whose_first_row_is_stamped_far_off_loses_that_row_only(tmp_path, shift_ms):
    """Issue 30: "a CSV whose first row has a timestamp of 1e12 ms keeps 2 of 486 rows
    (time_backwards)": the first row anchored the run's clock. Now the run starts where
    its first rows agree (onboard.core.stamps.Anchor) and the moved row is the outlier."""
    base = baseline(tmp_path)
    s = replay(tmp_path, moved_csv(tmp_path, shift_ms, range(1, 2)))
    assert s["read"]["by_type"]["row"] == base["read"]["by_type"]["row"] - 1
    assert s["read"]["rejected"] == {**base["read"]["rejected"], "time_outlier": 1}
    # the file's 1.2 s less the first row's 0.1 s (before: 0.0 s at +1e12 ms)
    assert s["time_span"]["duration_s"] == pytest.approx(
        base["time_span"]["duration_s"] - 0.1)
    assert len(s["time_span"]["segments"]) == 1 and s["runs"][0]["t_start"] == 0.0
    assert "time_outlier" in {w["code"] for w in s["warnings"]}


def test_a_clock_that_jumps_1e9_s_ahead_and_stays_makes_a_segment_without_spinning(tmp_path):
    """The pipelines restart from their state at the new segment (beyond
    onboard.engine.engine.RESTART_AFTER_S): none of them predicts across 1e9 s (0.4 s here)."""
    base = baseline(tmp_path)
    lines = CSV.read_text().splitlines()
    s = replay(tmp_path, moved_csv(tmp_path, 1e12, range(BAD_ROW, len(lines))))
    assert len(s["time_span"]["segments"]) == 2
    assert s["time_span"]["duration_s"] == pytest.approx(
        base["time_span"]["duration_s"] - 0.05)
    assert s["read"]["rejected"] == base["read"]["rejected"]
    assert sum(s["accepted"].values()) == sum(base["accepted"].values())
    assert "time_jump" in {w["code"] for w in s["warnings"]}
    assert s["ticks"] < 2 * base["ticks"]


# -------------------------------------------------------------------- DataFlash bytes

def test_a_dataflash_record_stamped_far_ahead_is_an_outlier_and_costs_nothing_else(tmp_path):
    """Before: flipped bytes in small.BIN gave a "14627691589702.8 s" duration, and one
    record far ahead emptied the re-ordering window: later records were ``time_backwards``."""
    bad = df.record("IMU2", 2**62 + 700_000, 0.0, 0.0, 0.0, 0.0, 0.0, -9.8)
    data = df.synthetic_log()
    good = tmp_path / "good.bin"
    good.write_bytes(data)
    expected = [s.t for s in DataflashReader(good)]
    cut = data.index(df.record("ATT", 1_000_010, 0, 150, 0, -200, 0, 9000, 0, 0, 3))
    for name, content in [("end.bin", data + bad), ("mid.bin", data[:cut] + bad + data[cut:])]:
        log = tmp_path / name
        log.write_bytes(content)
        reader = DataflashReader(log)
        assert [s.t for s in reader] == expected  # the late IMU2 record re-ordered too
        assert reader.stats.rejected == {"time_outlier": 1}
    s = replay(tmp_path, log, config=None)
    assert s["read"]["rejected"] == {"time_outlier": 1}
    assert s["time_span"]["duration_s"] == pytest.approx(2.0, abs=0.01)  # 1.9999 s
    assert "time_outlier" in {w["code"] for w in s["warnings"]}


def test_a_dataflash_log_whose_first_stamp_is_far_ahead_loses_that_record_only(tmp_path):
    """Before: the first record's stamp anchored the re-ordering window far ahead, so
    nothing was re-ordered (the late IMU2 record was ``time_backwards``)."""
    data = df.synthetic_log()
    good = tmp_path / "good.bin"
    good.write_bytes(data)
    expected = [s.t for s in DataflashReader(good)]
    first = data.index(df.record("PARM", 1000, b"FRAME_CLASS", 2.0))
    bad = df.record("PARM", 2**62 + 1000, b"FRAME_CLASS", 2.0)
    log = tmp_path / "first.bin"
    log.write_bytes(data[:first] + bad + data[first + len(bad):])
    reader = DataflashReader(log)
    assert [s.t for s in reader] == expected[1:]
    assert reader.stats.rejected == {"time_outlier": 1}


@pytest.mark.data
def test_small_bin_is_24_s_of_data_in_two_segments_not_135_s(tmp_path, shared_data):
    """ArduSub's small.BIN: 26.6 s of samples, then two parameter records 109 s later.
    Before: "135.6 s"; now the two segments' 26.6 s and a ``time_jump`` warning."""
    s = replay(tmp_path, shared_data / "ardusub_small_logs/small.BIN", config=None)
    segments = s["time_span"]["segments"]
    assert len(segments) == 2
    assert segments[1]["start"] - segments[0]["end"] == pytest.approx(109.0, abs=0.1)
    assert s["time_span"]["duration_s"] == pytest.approx(26.6, abs=0.1)  # 26.61 s
    assert "time_jump" in {w["code"] for w in s["warnings"]}


@pytest.mark.data
def test_500_flipped_bytes_in_small_bin_give_a_duration_within_the_log(tmp_path, shared_data):
    """Before: a "14627691589702.8 s" duration. Three seeds of 500 random bit flips."""
    import random

    clean = (shared_data / "ardusub_small_logs/small.BIN").read_bytes()
    for seed in range(3):
        data = bytearray(clean)
        rng = random.Random(seed)
        for _ in range(500):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        log = tmp_path / f"flipped{seed}.BIN"
        log.write_bytes(bytes(data))
        s = replay(tmp_path / str(seed), log, config=None)
        # measured 30.8, 26.8, 35.0 s (clean: 26.6 s; a flipped low byte of TimeUS moves
        # a stamp by less than TIME_JUMP_S and stays); each seed's bad stamps are counted
        assert 20.0 < s["time_span"]["duration_s"] < 40.0
        assert s["read"]["rejected"]["time_outlier"] > 0  # measured 13-22


# ------------------------------------------- the same time line live and in the readers

def test_the_readers_and_the_time_line_judge_stamps_on_the_same_figure():
    from onboard.drivers import base, csvlog, dataflash

    assert base.TIME_JUMP_S == csvlog.TIME_JUMP_S == dataflash.TIME_JUMP_S == TIME_JUMP_S


def test_live_a_stamp_far_behind_the_receive_clock_is_a_counted_and_warned_outlier():
    """The live service puts its samples on the receive clock's time line: one stamped an
    hour back (a source's clock that stepped) is a ``time_outlier``, counted and warned as
    in a replay, and the samples after it are kept; nothing is held, nothing spins."""
    from onboard.core.config import Config
    from onboard.drivers.protocols import encode_sample
    from onboard.engine import Engine
    from onboard.service.intake import Intake

    engine = Engine(Config())
    intake = Intake(engine)
    for k, t in enumerate([100.0, 100.1, 100.2 - 3600.0, 100.3, 100.4]):
        intake.chunk("imu", "sample", encode_sample(imu(t)), 100.0 + 0.1 * k)
        intake.tick(100.0 + 0.1 * k + 0.05)
    assert engine.rejected["imu:time_outlier"] == 1
    assert sum(engine.accepted.values()) == 4
    (alert,) = [a for a in engine.alerts if a.code == "time_outlier"]
    assert "-3600.05 s off the receive clock" in alert.message
    assert any(e.startswith("time_outlier") for e in engine.events)  # health, STATUSTEXT
    assert len(engine.timeline.segments) == 1


def test_a_tlog_clock_reset_is_a_segment_not_every_later_record_lost(tmp_path):
    """A tlog whose logger clock went back 1000 s: before, every later record was
    ``time_backwards`` until the clock caught up; now the reader passes the step on and the
    engine's time line makes it a second segment. A step back of 0.5 s stays
    ``time_backwards``."""
    from pymavlink.dialects.v20 import ardupilotmega as mav

    from onboard.drivers.tlog import TlogReader, TlogWriter

    p = tmp_path / "reset.tlog"
    m = mav.MAVLink(None, 1, 1)
    t0 = 1.7e9
    times = [t0 + 0.1 * k for k in range(30)] + [t0 + 2.5] \
        + [t0 - 1000.0 + 0.1 * k for k in range(30)]
    with TlogWriter(p) as w:
        for t in times:
            w.write(t, m.attitude_encode(0, 0.1, 0, 0, 0, 0, 0).pack(m))
    r = TlogReader(p)
    out = list(r)
    assert len(out) == 60 and r.stats.rejected == {"time_backwards": 1}
    tl = Timeline()
    released = [s for x in out for s in tl.admit(x)]
    tl.flush()
    assert len(released) == 60 and len(tl.segments) == 2
    assert tl.segments[1].start == pytest.approx(t0 - 1000.0)


def test_a_single_tlog_stamp_far_back_is_passed_on_and_is_the_time_lines_outlier(tmp_path):
    from pymavlink.dialects.v20 import ardupilotmega as mav

    from onboard.drivers.tlog import TlogReader, TlogWriter

    p = tmp_path / "one.tlog"
    m = mav.MAVLink(None, 1, 1)
    t0 = 1.7e9
    times = [t0 + 0.1 * k for k in range(30)]
    times[10] -= 1e6
    with TlogWriter(p) as w:
        for t in times:
            w.write(t, m.attitude_encode(0, 0.1, 0, 0, 0, 0, 0).pack(m))
    r = TlogReader(p)
    out = list(r)
    assert len(out) == 30 and not r.stats.rejected
    tl = Timeline()
    released = [s for x in out for s in tl.admit(x)]
    tl.flush()
    assert len(released) == 29 and [s.t for s in tl.outliers] == [pytest.approx(times[10])]


def test_an_nmea_utc_clock_reset_is_passed_on_a_small_step_back_is_not():
    from onboard.drivers.nmea import NmeaParser, encode_gga

    day = 1_733_011_200.0  # 2024-12-01 00:00 UTC
    p = NmeaParser(time_base="utc", date=day)
    out = []
    for t in [day + 3600.0, day + 3601.0, day + 3600.5, day + 3000.0, day + 3001.0]:
        out += p.feed_line(encode_gga(t, 48.0, -4.0))
    out += p.poll(1e12)
    assert [round(s.t - day, 1) for s in out] == [3600.0, 3601.0, 3000.0, 3001.0]
    assert p.stats.rejected == {"time_backwards": 1}


def test_a_dvl_json_capture_clock_reset_is_passed_on_a_small_step_back_is_not(tmp_path):
    from onboard.drivers.dvl_json import DvlJsonLogReader

    def report(t: float) -> str:
        return json.dumps({"type": "velocity", "time": 100.0, "vx": 0.1, "vy": 0.0,
                           "vz": 0.0, "fom": 0.01, "altitude": 1.0, "velocity_valid": True,
                           "status": 0, "time_of_validity": int(t * 1e6),
                           "time_of_transmission": int(t * 1e6)})

    times = [1000.0, 1001.0, 1000.5, 500.0, 501.0]
    path = tmp_path / "dvl.txt"
    path.write_text("\n".join(report(t) for t in times) + "\n")
    r = DvlJsonLogReader(path)
    out = list(r)
    assert [s.t for s in out] == [1000.0, 1001.0, 500.0, 501.0]
    assert r.stats.rejected == {"time_backwards": 1}


def test_a_tlog_clock_reset_replays_as_two_segments_with_a_time_jump(tmp_path):
    """End to end: 10 s of data, the logger's clock back 1000 s, 10 s more (before: the
    second half was lost as ``time_backwards``)."""
    log = write_reset_tlog(tmp_path / "reset.tlog", heartbeat=True)
    s = replay(tmp_path, log)
    assert [seg["duration_s"] for seg in s["time_span"]["segments"]] == \
        [pytest.approx(9.9), pytest.approx(9.9)]
    assert "time_jump" in {w["code"] for w in s["warnings"]} and not s["read"]["rejected"]


# ----------------------------------------- text readers: a bad first stamp costs itself

FAR_S = 2 * 365.25 * 86400.0
"""How far the first stamp of the text-capture tests is moved ahead (s): two years."""


def _stamp(t: float, sep: str = ".") -> str:
    import time

    return time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(t)) + f"{sep}{int(t * 1000) % 1000:03d}"


@pytest.mark.parametrize("kind", ["nmea", "ddboat"])
def test_a_text_capture_whose_first_line_is_stamped_far_ahead_keeps_every_later_line(
        tmp_path, kind):
    """Before: a text capture's reader dropped every sample older than its newest, so a
    first line stamped two years ahead lost the whole capture (``time_backwards``). Now
    the readers drop only a sample a little behind (drivers.base.TimeOrder) and the
    engine's time line drops the far one as an outlier."""
    from onboard.drivers.nmea import encode_gga
    from onboard.drivers.textlog import open_text_log

    day = 1_662_076_800.0  # 2022-09-02 00:00 UTC
    times = [day + 42_000.0 + 0.2 * k for k in range(40)]
    times[0] += FAR_S
    if kind == "nmea":
        lines = [f"{_stamp(t)} | DEBUG | recv - " + encode_gga(t, 48.4, -4.5).decode().strip()
                 for t in times]
    else:
        lines = [f"{_stamp(t, ',')} - INFO - /cmd motors l,r are b'dirl: 0, motl: {k}, "
                 f"dirr: 0, motr: {k}\\r' /GPS timeout /" for k, t in enumerate(times)]
    path = tmp_path / f"{kind}.txt"
    path.write_text("\n".join(lines) + "\n")
    reader = open_text_log(path)
    stamps = [s.t for s in reader]
    assert stamps == pytest.approx(times) and not reader.stats.rejected
    tl = Timeline()
    assert len(admit_all(tl, stamps)) == len(times) - 1
    assert [s.t for s in tl.outliers] == [pytest.approx(times[0])]


def test_a_pd6_capture_whose_first_ensemble_is_stamped_far_ahead_keeps_the_later_ones(
        tmp_path):
    from onboard.drivers.pd6 import Pd6LogReader, encode_ensemble

    t0 = 1_717_245_015.0
    times = [t0 + FAR_S] + [t0 + 0.2 * k for k in range(1, 10)]
    path = tmp_path / "dvl.pd6"
    path.write_bytes(b"".join(encode_ensemble(t, 0.5, 0.0, 0.0) for t in times))
    reader = Pd6LogReader(path)
    stamps = sorted({s.t for s in reader})
    assert stamps == pytest.approx(sorted(times)) and not reader.stats.rejected
