"""EstimateRecord schema 2: every record says when (``utc``) and where (``lat_deg``,
``lon_deg``) its tick was (architecture.md §4.4; onboard/engine/whereabouts.py)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import msgspec
import pytest

from onboard.cli import main as cli_main
from onboard.core.geo import LocalFrame
from onboard.core.messages import SCHEMA_VERSION, EstimateRecord, GnssFix
from onboard.core.wire import ESTIMATE_SCHEMA, location_fix
from onboard.engine.whereabouts import FIX_MAX_AGE_S, Whereabouts
from onboard.offline.batch_tables import clock_of

NMEA = Path(__file__).parent / "data" / "nmea" / "gnss-compass.nmea"


def test_the_schema_is_version_2_and_a_version_1_record_still_decodes():
    assert SCHEMA_VERSION == 2 and ESTIMATE_SCHEMA == "onboard.Estimate.v2"
    v1 = b'{"schema":1,"vehicle":"b","pipeline":"kf","t":2.0,"values":{"speed":1.5}}'
    rec = msgspec.json.decode(v1, type=EstimateRecord)
    assert (rec.utc, rec.lat_deg, rec.lon_deg) == (None, None, None)
    # the three fields are on every schema-2 record, null when unknown
    doc = json.loads(msgspec.json.encode(EstimateRecord(vehicle="b", pipeline="kf", t=1.0,
                                                        values={})))
    assert doc["utc"] is None and doc["lat_deg"] is None and doc["lon_deg"] is None


def test_the_position_is_the_fresh_fix_else_a_pipelines_own():
    where = Whereabouts()
    frame = (LocalFrame(43.0, 5.0), (0.0, 0.0))
    kf = ({"north": 111.0, "east": 0.0}, frame)
    assert where.position(10.0, [kf]) == pytest.approx((43.0 + 111.0 / 111_132.0, 5.0),
                                                       abs=2e-6)
    where.observe(GnssFix(t=10.0, lat_deg=44.0, lon_deg=6.0))
    assert where.position(10.0 + FIX_MAX_AGE_S, [kf]) == (44.0, 6.0)
    assert where.position(10.1 + FIX_MAX_AGE_S, [kf])[0] == pytest.approx(43.001, abs=1e-5)
    assert where.position(30.0, []) == (None, None)
    where.observe(GnssFix(t=40.0, lat_deg=0.0, lon_deg=0.0, fix_quality=0))  # no fix
    assert where.position(40.0, []) == (None, None)
    assert where.utc(5.0) is None
    where.utc_of = lambda t: 1.7e9 + t
    assert where.utc(5.0) == 1.7e9 + 5.0


def test_a_location_fix_is_stamped_in_utc_where_the_record_knows_it():
    frame = LocalFrame(43.0, 5.0)
    rec = EstimateRecord(vehicle="b", pipeline="kf", t=12.5, values={"north": 1.0,
                                                                     "east": 2.0})
    assert location_fix(rec, frame).timestamp.sec == 12
    rec = msgspec.structs.replace(rec, utc=1_780_000_000.25)
    fix = location_fix(rec, frame)
    assert (fix.timestamp.sec, fix.timestamp.nsec) == (1_780_000_000, 250_000_000)


def test_the_service_clock_gives_the_system_clocks_utc():
    from onboard.service.daemon import ServiceClock

    clock = ServiceClock()
    assert clock.utc(clock.now()) == pytest.approx(time.time(), abs=0.05)
    fast = ServiceClock(speed=10.0)
    t = fast.now()
    assert fast.utc(t + 100.0) - fast.utc(t) == pytest.approx(100.0)  # its own time line


def test_a_replay_carries_the_logs_utc_and_position_and_summary_json_its_clock(tmp_path):
    """An NMEA capture is on the RMC sentences' UTC: every record in the MCAP carries its
    tick's UTC (the MCAP's log time) and the GNSS position; summary.json's ``utc`` holds
    the clock that batch reads instead of reopening the log."""
    pytest.importorskip("mcap")
    from mcap.reader import make_reader

    out = tmp_path / "out"
    assert cli_main(["replay", str(NMEA), "--out", str(out),
                     "--no-plot", "--mcap", str(tmp_path / "e.mcap")]) == 0
    summary = json.loads((out / "summary.json").read_text())
    utc = summary["utc"]
    assert utc["start"] == "2024-05-01T12:00:00.000Z" and utc["start_s"] == 1714564800.0
    assert utc["offsets"] == [[1714564800.0, 0.0]]
    clock = clock_of(summary)
    assert clock is not None and clock.to_utc(1714564801.5) == 1714564801.5
    n = 0
    with open(tmp_path / "e.mcap", "rb") as f:
        for schema, _, msg in make_reader(f).iter_messages():
            if schema.name != ESTIMATE_SCHEMA:
                continue
            rec = msgspec.json.decode(msg.data, type=EstimateRecord)
            assert rec.utc == pytest.approx(msg.log_time / 1e9, abs=1e-6)
            assert rec.lat_deg == pytest.approx(63.435, abs=1e-3)
            assert rec.lon_deg == pytest.approx(10.3917, abs=1e-3)
            n += 1
    assert n > 100  # 154 records (5 s at 10 Hz of nav, aie and kf)
    assert clock_of({"utc": {"utc": True, "source": "x", "start": None}}) is None  # older


def test_a_log_without_utc_gives_records_without_utc(tmp_path):
    """The negative control: a log stamped in time since boot has ``utc`` null."""
    from onboard.core.config import Config
    from onboard.engine import Engine, run

    engine = Engine(Config())
    fixes = [GnssFix(t=10.0 + 0.2 * k, lat_deg=43.0 + 1e-6 * k, lon_deg=5.0)
             for k in range(40)]
    recs: list[EstimateRecord] = []
    run(engine, fixes, lambda t, rs: recs.extend(rs))
    assert recs and all(r.utc is None for r in recs)
    assert all(r.lat_deg == pytest.approx(43.0, abs=1e-4) for r in recs)
