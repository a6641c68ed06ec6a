"""Generic CSV reader: mapping, runs, bad rows; the BlueBoat NTNU runs and their config."""

from __future__ import annotations

import math
import statistics
from pathlib import Path

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from onboard.drivers.base import UnreadableLog
from onboard.drivers.csvlog import CsvReader
from onboard.core.config import CONFIG_DIR, CsvFormat, load
from onboard.core.geo import LocalFrame
from onboard.core.messages import (
    ActuatorOutputs,
    Attitude,
    Depth,
    GnssFix,
    Heading,
    VelocityOverGround,
)
from onboard.engine.inputs import InputMapper

FMT = CsvFormat(time="ms", time_scale=0.001, lat_deg="lat", lon_deg="lon", heading="hdg",
                heading_unit="deg", yaw_rate="r", surge_mps="u", sway_mps="v", depth_m="d",
                pwm_columns=["pl", "pr"])
HEADER = "ms,lat,lon,hdg,r,u,v,d,pl,pr"


def write(path: Path, rows: list[str], header: str = HEADER) -> Path:
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


def test_row_to_samples(tmp_path: Path):
    f = write(tmp_path / "a.csv", ["1000,63.4,10.3,90,0.1,2.0,0.5,1.5,1600,1400"])
    out = list(CsvReader(f, FMT))
    kinds = [type(s).__name__ for s in out]
    assert kinds == ["GnssFix", "Heading", "VelocityOverGround", "Depth", "ActuatorOutputs"]
    fix, hdg, vog, dep, act = out
    assert fix.t == 1.0 and fix.source == "csv:a" and fix.lat_deg == 63.4
    assert hdg.heading_rad == pytest.approx(math.pi / 2)
    # heading east: surge goes east, sway (starboard) goes south
    assert vog.v_east_mps == pytest.approx(2.0) and vog.v_north_mps == pytest.approx(-0.5)
    assert dep.depth_m == 1.5 and act.pwm_us == (1600.0, 1400.0)


def test_attitude_only_with_roll_pitch_or_explicit_level_assumption(tmp_path: Path):
    f = write(tmp_path / "a.csv", ["0,63.4,10.3,45,-5.0,0,0,0,1500,1500"])
    assert not any(isinstance(s, Attitude) for s in CsvReader(f, FMT))
    level = FMT.__class__(**{**{k: getattr(FMT, k) for k in FMT.__struct_fields__},
                             "assume_level": True, "yaw_rate_unit": "deg/s"})
    (att,) = [s for s in CsvReader(f, level) if isinstance(s, Attitude)]
    assert att.yaw_rate_rps == pytest.approx(math.radians(-5.0))
    assert att.yaw_rad == pytest.approx(math.pi / 4) and att.roll_rad == 0.0


def test_bad_rows_are_skipped_and_counted(tmp_path: Path):
    f = write(tmp_path / "a.csv", [
        "0,63.4,10.3,90,0,1,0,1,1500,1500",
        "100,63.4,10.3,90,0,,0,1,1500,1500",       # empty surge: no VOG
        "200,63.4,10.3,NaN,0,1,0,1,1500,1500",     # NaN heading: no heading, no VOG
        "300,63.4,abc,90,0,1,0,1,1500,1500",       # non-numeric lon: no fix
        "400,63.4,10.3,90,0,1,0,1,1500",           # missing cell
        "xyz,63.4,10.3,90,0,1,0,1,1500,1500",      # bad time
        "250,63.4,10.3,90,0,1,0,1,1500,1500",      # time backwards
        "500,95.0,10.3,90,0,1,0,1,1500,1500",      # latitude out of range
        "",
        "600,63.4,10.3,90,0,1,0,1,inf,1500",       # infinite PWM
    ])
    r = CsvReader(f, FMT)
    out = list(r)
    assert r.stats.records == 9
    assert dict(r.stats.rejected) == {"nan": 3, "non_numeric": 1, "malformed": 1, "bad_time": 1,
                                      "time_backwards": 1, "out_of_range": 1}
    headings = [h for s in out if (h := getattr(s, "heading_rad", None)) is not None]
    assert headings and all(math.isfinite(h) for h in headings)
    assert len([s for s in out if isinstance(s, ActuatorOutputs)]) == 5


def test_directory_of_runs_joined_in_name_order(tmp_path: Path):
    d = tmp_path / "runs"
    d.mkdir()
    write(d / "run_b.csv", ["5000,63.4,10.3,0,0,1,0,0,1500,1500", "6000,63.4,10.3,0,0,1,0,0,1500,1500"])
    write(d / "run_a.csv", ["9000,63.4,10.3,0,0,1,0,0,1500,1500", "9500,63.4,10.3,0,0,1,0,0,1500,1500"])
    (d / "notes.txt").write_text("ignored")
    r = CsvReader(d, FMT)
    assert [x.name for x in r.runs] == ["run_a", "run_b"]
    a, b = r.runs
    assert (a.t_start, a.t_end, a.t_offset) == (9.0, 9.5, 0.0)
    assert b.t_start == pytest.approx(9.5 + FMT.run_gap_s) and b.t_end == pytest.approx(20.5)
    out = list(r)
    assert all(x.t <= y.t for x, y in zip(out, out[1:]))
    assert {s.source for s in out} == {"csv:run_a", "csv:run_b"}


def test_a_directory_of_csv_files_with_different_headers_is_not_one_log(tmp_path: Path):
    """A vehicle log beside a table of another kind (the Kolumbo glider's log and its DVL
    current profile): one line naming both headers, before any row is read, whichever
    config is given."""
    d = tmp_path / "glider"
    d.mkdir()
    write(d / "glider.csv", ["5000,63.4,10.3,0,0,1,0,0,1500,1500"])
    (d / "profile.csv").write_text(",z,N,E,D\n0,5,0.1,0.2,0\n")
    with pytest.raises(UnreadableLog, match=r"not runs of one log, their headers differ "
                                            r"\(glider\.csv: .*; profile\.csv: , z, N, E, D\)"):
        CsvReader(d, FMT)
    from onboard.cli import main as cli_main

    assert cli_main(["replay", str(d), "--out", str(tmp_path / "out")]) == 2
    assert not (tmp_path / "out").exists()


def test_run_column_splits_one_file(tmp_path: Path):
    fmt = CsvFormat(time="t", lat_deg="lat", lon_deg="lon", run_column="run")
    f = write(tmp_path / "all.csv", ["r1,0,1,2", "r1,1,1,2", "r2,0,1,2"], header="run,t,lat,lon")
    r = CsvReader(f, fmt)
    assert [(x.name, x.rows) for x in r.runs] == [("r1", 2), ("r2", 1)]
    assert [s.t for s in r] == [0.0, 1.0, 11.0]


def test_north_east_without_lat_lon_uses_the_origin(tmp_path: Path):
    fmt = CsvFormat(time="t", north_m="n", east_m="e", origin_lat_deg=60.0, origin_lon_deg=5.0)
    f = write(tmp_path / "ne.csv", ["0,0,0", "1,111.32,55.8"], header="t,n,e")
    a, b = list(CsvReader(f, fmt))
    # the WGS-84 tangent plane at the origin (onboard.core.geo.LocalFrame), to 1e-14 deg
    assert (a.lat_deg, a.lon_deg) == pytest.approx((60.0, 5.0), abs=1e-12)
    assert LocalFrame(60.0, 5.0).to_ne(b.lat_deg, b.lon_deg) == pytest.approx((111.32, 55.8))


def test_unreadable_inputs(tmp_path: Path):
    with pytest.raises(UnreadableLog):
        CsvReader(tmp_path / "missing.csv", FMT)
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(UnreadableLog):
        CsvReader(tmp_path / "empty.csv", FMT)
    with pytest.raises(UnreadableLog, match="'pr'"):
        CsvReader(write(tmp_path / "x.csv", ["0,1,2"], header="ms,lat,lon"), FMT)
    empty_dir = tmp_path / "nothing"
    empty_dir.mkdir()
    with pytest.raises(UnreadableLog):
        CsvReader(empty_dir, FMT)


@settings(max_examples=100, deadline=None)  # each example writes a file
@given(st.lists(st.lists(st.sampled_from(["0", "1.5", "-2", "", "nan", "inf", "x", "1e400",
                                          "63.4", "1500"]), min_size=9, max_size=11),
                max_size=6))
@example(rows=[[""] * 9, ["0"] * 9])  # a spreadsheet's empty row beside a record
def test_property_rows_never_raise_and_are_counted(tmp_path_factory, rows):
    d = tmp_path_factory.mktemp("h")
    f = write(d / "h.csv", [",".join(r) for r in rows])
    r = CsvReader(f, FMT)
    out = list(r)
    empty = sum(1 for row in rows if not any(c.strip() for c in row))  # ",,,,,,,,"
    assert r.stats.records == len(rows) - empty
    assert r.stats.skipped["empty_row"] == empty
    for s in out:
        assert math.isfinite(s.t)
        for name in s.__struct_fields__:
            v = getattr(s, name)
            if isinstance(v, float):
                assert math.isfinite(v)


def test_bundled_blueboat_config_decodes():
    cfg = load(CONFIG_DIR / "blueboat-ntnu-csv.toml")
    assert cfg.vehicle.vehicle_class == "twin-thruster-boat"
    assert cfg.csv.pwm_columns == ["thr_left", "thr_right"]
    # The thr_left column drives the starboard thruster, reversed (see the config's note).
    assert cfg.inputs.left.neutral_us == 1510 and cfg.inputs.left.channel == 2
    assert cfg.inputs.right.channel == 1 and cfg.inputs.right.reverse


@pytest.mark.data
def test_blueboat_ntnu_runs(shared_data):
    cfg = load(CONFIG_DIR / "blueboat-ntnu-csv.toml")
    r = CsvReader(shared_data / "blueboat_sysid_ntnu", cfg.csv)
    # SOURCE.md: 16 runs, 449-3098 rows each, 17,753 rows, 10 Hz, 29 NaN cells (run 216)
    assert len(r.runs) == 16 and r.runs[0].name == "fixed_00000216"
    assert sum(x.rows for x in r.runs) == 17753
    assert min(x.rows for x in r.runs) == 449 and max(x.rows for x in r.runs) == 3098
    out = list(r)
    assert r.stats.records == 17753
    assert dict(r.stats.rejected) == {"nan": 13}  # measured: 12 rows without surge/sway, 1 without lat/lon
    assert all(a.t <= b.t for a, b in zip(out, out[1:]))
    for a, b in zip(r.runs, r.runs[1:]):
        assert b.t_start == pytest.approx(a.t_end + cfg.csv.run_gap_s)
    fixes = [s for s in out if isinstance(s, GnssFix)]
    assert len(fixes) == 17752
    assert statistics.median(f.lat_deg for f in fixes) == pytest.approx(63.4015, abs=0.002)
    by_run = {}
    for f in fixes:
        by_run.setdefault(f.source, []).append(f.t)
    assert len(by_run) == 16
    dts = [b - a for ts in by_run.values() for a, b in zip(ts, ts[1:])]
    assert statistics.median(dts) == pytest.approx(0.1, abs=1e-6)
    vog = [s for s in out if isinstance(s, VelocityOverGround)]
    speed = [math.hypot(s.v_north_mps, s.v_east_mps) for s in vog]
    assert max(speed) < 4.0  # SOURCE.md: surge -2.3..+3.4 m/s
    att = [s for s in out if isinstance(s, Attitude)]
    assert max(abs(a.yaw_rate_rps) for a in att) < 1.2  # SOURCE.md: r within +-1.0 rad/s
    assert all(isinstance(s, Heading) and s.reference == "true" for s in out if isinstance(s, Heading))
    acts = [s for s in out if isinstance(s, ActuatorOutputs)]
    pwm = [p for s in acts for p in s.pwm_us]
    assert min(pwm) == 1100 and max(pwm) == 1900
    mapper = InputMapper(cfg.inputs)
    cmds = [mapper.map(s) for s in acts]
    assert all(-1.0 <= c.left <= 1.0 and -1.0 <= c.right <= 1.0 for c in cmds)
    idle = statistics.median(abs(c.left) for c in cmds)
    assert idle == 0.0  # 1510 us idle is neutral
    assert not any(isinstance(s, Depth) for s in out)


# ------------------------------------------------------------- actuator columns (source = "column")

COLUMN_CONFIG = """
[vehicle]
class = "rudder-boat"
[csv]
time = "t"
lat_deg = "lat"
lon_deg = "lon"
heading = "hdg"
heading_unit = "deg"
[inputs]
from_autopilot = false
# a glider-style log: the rudder angle in degrees (+-30 full scale) and a power level 0..1
rudder = { source = "column", column = "rudder_deg", neutral_us = 0, half_range_us = 30, full_scale = 0.5236 }
throttle = { source = "column", column = "power", neutral_us = 0, half_range_us = 1 }
"""


def _turning_boat_csv(path: Path, seconds: float = 60.0) -> Path:
    """A boat at 1.5 m/s turning at 0.05 rad/s from 20 s, the rudder at -10 deg before and
    +15 deg after (a signed column no pulse-width check would pass), 5 Hz rows."""
    rows, n, e, psi = [], 0.0, 0.0, 0.0
    for i in range(int(seconds * 5)):
        t = 1.0 + 0.2 * i
        rate = 0.05 if t >= 20.0 else 0.0
        psi += rate * 0.2
        n += 1.5 * math.cos(psi) * 0.2
        e += 1.5 * math.sin(psi) * 0.2
        lat = 63.4 + n / 111_320.0
        lon = 10.3 + e / (111_320.0 * math.cos(math.radians(63.4)))
        rudder = 15.0 if t >= 20.0 else -10.0
        rows.append(f"{t:.1f},{lat:.8f},{lon:.8f},{math.degrees(psi):.3f},{rudder},0.6")
    return write(path, rows, header="t,lat,lon,hdg,rudder_deg,power")


def test_a_column_source_maps_like_a_pulse_width():
    from onboard.core.config import from_dict
    from onboard.core.messages import ActuatorColumn

    cfg = from_dict({"inputs": {"rudder": {"source": "column", "column": "rudder_deg",
                                           "neutral_us": 0.0, "half_range_us": 30.0,
                                           "full_scale": 0.5236, "reverse": True},
                                "throttle": {"source": "column", "column": "power",
                                             "neutral_us": 0.0, "half_range_us": 1.0,
                                             "deadband_us": 0.05}}})
    m = InputMapper(cfg.inputs)
    cmd = m.map(ActuatorColumn(t=1.0, source="csv:a", column="rudder_deg", value=-15.0))
    assert cmd is not None and cmd.rudder_rad == pytest.approx(0.2618)   # reversed
    cmd = m.map(ActuatorColumn(t=1.1, source="csv:a", column="power", value=0.03))
    assert cmd is not None and cmd.throttle == 0.0                       # in the deadband
    assert m.map(ActuatorColumn(t=1.2, source="csv:a", column="other", value=1.0)) is None


def test_csv_reader_reads_actuator_columns_and_requires_them(tmp_path: Path):
    from onboard.core.messages import ActuatorColumn

    f = _turning_boat_csv(tmp_path / "g.csv", seconds=1.0)
    fmt = CsvFormat(time="t", lat_deg="lat", lon_deg="lon")
    out = [s for s in CsvReader(f, fmt, actuator_columns=["rudder_deg", "power"])
           if isinstance(s, ActuatorColumn)]
    assert [(s.column, s.value) for s in out[:2]] == [("rudder_deg", -10.0), ("power", 0.6)]
    assert len(out) == 2 * 5
    with pytest.raises(UnreadableLog, match="'rudder'"):
        CsvReader(f, fmt, actuator_columns=["rudder"])


def test_replay_of_a_csv_with_actuator_columns_feeds_the_commands(tmp_path: Path):
    """Through ``onboard replay``: every row gives a rudder and a throttle command, and
    the KF baseline, which forecasts with the commanded input, moves with them."""
    import json

    from onboard.cli import main

    log = _turning_boat_csv(tmp_path / "glider.csv")
    with_cols = tmp_path / "columns.toml"
    with_cols.write_text(COLUMN_CONFIG)
    without = tmp_path / "no-inputs.toml"
    without.write_text(COLUMN_CONFIG.split("[inputs]")[0])
    outs = {}
    for cfg in (with_cols, without):
        out = tmp_path / cfg.stem
        assert main(["replay", str(log), "--config", str(cfg), "--out", str(out),
                     "--no-plot"]) == 0
        outs[cfg.stem] = out
    summary = json.loads((outs["columns"] / "summary.json").read_text())
    accepted = summary["samples_accepted_by_type"]
    assert accepted["column"] == 2 * 300
    assert (outs["columns"] / "estimates.csv").read_text() != \
        (outs["no-inputs"] / "estimates.csv").read_text()


def test_a_column_source_on_a_log_without_columns_is_an_error():
    from onboard.drivers.logs import open_log

    log = Path(__file__).parent / "data" / "replay" / "jaiabot-turns.tlog"
    with pytest.raises(UnreadableLog, match="'rudder_deg'.*has no columns"):
        open_log(log, None, ["rudder_deg"])


def test_a_header_with_control_characters_is_named_on_one_line():
    """A header whose names hold line breaks of ``str.splitlines`` (a corrupted file: the
    fuzz campaign found ``\\x1c`` and ``\\x85``) is shown quoted in the error, which stays
    one line; printable names are shown as they are."""
    from onboard.drivers.csvlog import fitting_note

    note = fitting_note(["time", "la\x1ct", "lo\x85n", "speed"])
    assert len(note.splitlines()) == 1, note
    assert "'la\\x1ct'" in note and "time, " in note
