"""EstimateRecord schema 2: every record says when (``utc``) and where (``lat_deg``,
``lon_deg``) its tick was (architecture.md §4.4; onboard/engine/whereabouts.py)."""

from __future__ import annotations

import json
import math
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
    pytest.importorskip("mcap", reason="pip install 'onboard[mcap]'")
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


def test_a_diving_vehicle_is_dead_reckoned_from_its_last_fix_with_a_growing_sigma():
    """An AUV's last surface fix carried forward with its velocity over ground: 1 m/s
    north from 0.1 s to 100 s puts it 99.9 m north of the fix, its sigma grown from the
    fix's 2 m to sqrt(2^2 + (1 % of 99.9 m)^2 + (0.005 m/s x 100 s)^2) = 2.29 m; a boat (no dead
    reckoning) keeps the pipeline's position, with that pipeline's sigma."""
    from onboard.core.messages import VelocityOverGround
    from onboard.engine.whereabouts import DR_MAX_GAP_S

    frame = LocalFrame(43.0, 5.0)
    kf = ({"north": 500.0, "east": 0.0, "std_north": 40.0, "std_east": 30.0},
          (frame, (0.0, 0.0)))
    fix = GnssFix(t=0.0, lat_deg=43.0, lon_deg=5.0, h_acc_m=2.0)
    auv, boat = Whereabouts(dead_reckon=True), Whereabouts()
    for where in (auv, boat):
        where.observe(fix)
        assert where.place(1.0, [kf]) == (43.0, 5.0, 2.0)     # the fresh fix
        for k in range(1, 1001):
            where.observe_velocity(VelocityOverGround(t=0.1 * k, v_north_mps=1.0,
                                                      v_east_mps=0.0))
    lat, lon, std = auv.place(100.0, [kf])
    assert frame.to_ne(lat, lon) == pytest.approx((100.0 - 0.1, 0.0), abs=1e-6)
    assert std == pytest.approx(math.sqrt(2.0 ** 2 + 0.999 ** 2 + 0.5 ** 2))  # 99.9 m run
    lat, lon, std = boat.place(100.0, [kf])                  # no reckoning: the pipeline's
    assert frame.to_ne(lat, lon) == pytest.approx((500.0, 0.0), abs=1e-4) and std == 40.0
    # the navigation solution silent too long: no reckoned position; the pipeline's
    assert auv.place(100.0 + DR_MAX_GAP_S + 0.1, [kf]).std_m == 40.0
    auv.observe_velocity(VelocityOverGround(t=200.0, v_north_mps=1.0, v_east_mps=0.0))
    assert auv.place(200.0, []) == (None, None, None)        # broken until the next fix


def test_a_record_carries_its_position_sigma_and_the_field_weighs_it():
    """``position_std_m`` on the record (additive, null when unknown); the field takes a
    record placed within MAX_POSITION_STD_M and refuses one beyond it."""
    from onboard.fleet.field import MAX_POSITION_STD_M, observation

    rec = EstimateRecord(vehicle="a", pipeline="current", t=1.0, utc=1.78e9, lat_deg=43.0,
                         lon_deg=5.0, values={"north": 0.1, "east": 0.2},
                         std={"north": 0.02, "east": 0.02}, position_std_m=8.0)
    assert json.loads(msgspec.json.encode(rec))["position_std_m"] == 8.0
    assert observation(rec)[0].position_std_m == 8.0
    lost = msgspec.structs.replace(rec, position_std_m=MAX_POSITION_STD_M + 1.0)
    assert observation(lost) == (None, "position_uncertain")
    v1 = b'{"schema":1,"vehicle":"b","pipeline":"kf","t":2.0,"values":{}}'
    assert msgspec.json.decode(v1, type=EstimateRecord).position_std_m is None
