"""``onboard fleet --history``: the currents of an ``onboard batch`` table
(``current.parquet``, docs/batch.md) added as the records they were published as, so that
yesterday's survey, replayed, is served as a field (docs/fleet.md)."""

from __future__ import annotations

import json
import subprocess
import sys

import msgspec
import numpy as np
import pytest

from onboard.core.errors import UsageError
from onboard.fleet.field import HISTORY_S
from onboard.fleet.service import FleetService
from tests.helpers.fleet_scenarios import UTC0, eddy, fleet

pa = pytest.importorskip("pyarrow", reason="the batch extra: pip install -e '.[batch]'")
pq = pytest.importorskip("pyarrow.parquet")


def write_table(path, recs, extra=()):
    """``recs`` (EstimateRecords of ``current``) as rows of current.parquet, with the
    batch's own schema, plus the rows ``extra`` (dicts of columns)."""
    from onboard.offline.batch_tables import current_schema

    rows = [{"name": "log", "vehicle": r.vehicle, "t_s": r.t,
             "utc": None if r.utc is None else round(r.utc * 1000.0),
             "lat": r.lat_deg, "lon": r.lon_deg, "north": r.values["north"],
             "east": r.values["east"], "std_north": r.std.get("north"),
             "std_east": r.std.get("east"), "flags": [], "pipeline": "current",
             "position_std_m": r.position_std_m, "down": r.values.get("down"),
             "std_down": r.std.get("down")}
            for r in recs] + [dict({"down": None, "std_down": None}, **row) for row in extra]
    schema = current_schema()
    pq.write_table(pa.table({k: [row[k] for row in rows] for k in schema.names},
                            schema=schema), path)


def with_down(rec):
    """``rec`` with a down current, as an underwater vehicle's record has, for two of the
    fleet's vehicles (boats' records have none)."""
    if rec.vehicle not in ("v0", "v1"):
        return rec
    return msgspec.structs.replace(rec, values={**rec.values, "down": -0.02},
                                   std={**rec.std, "down": 0.01})


def ms_record(rec):
    """``rec`` with its UTC rounded to the table's millisecond."""
    return msgspec.structs.replace(rec, utc=round(rec.utc * 1000.0) / 1000.0)


@pytest.fixture(scope="module")
def survey():
    return fleet("eddy", seed=31, vehicles=4, duration_s=900.0, rate_hz=1.0)


def test_a_batch_table_makes_the_field_its_records_make_live(survey, tmp_path):
    recs = [with_down(msgspec.structs.replace(survey.record(i), position_std_m=float(2 + i % 7)))
            for i in range(len(survey.t))]   # places as sure as dead reckoning says
    dive = {"name": "glider", "vehicle": "glider-1", "t_s": 3600.0,
            "utc": round(UTC0 * 1000.0), "lat": recs[0].lat_deg, "lon": recs[0].lon_deg,
            "north": 0.1, "east": 0.0, "std_north": 0.01, "std_east": 0.01, "flags": [],
            "pipeline": "dac", "position_std_m": None}
    no_time = dict(dive, vehicle="boat-x", pipeline="current", utc=None)
    path = tmp_path / "current.parquet"
    write_table(path, recs, [dive, no_time])

    history = FleetService()
    counts = history.load_history(path)
    assert counts == {"rows": len(recs) + 2, "added": len(recs), "dive_average": 1,
                      "no_time": 1}
    assert history.received == {"history": len(recs) + 1}
    assert sorted(history.newest) == sorted({r.vehicle for r in recs})
    for vehicle, track in history.tracks.items():   # a point per 5 s of its 900 s
        assert 170 <= len(track) <= 181 and np.all(np.diff([p[0] for p in track]) >= 5.0)

    live = FleetService()
    enc = msgspec.json.Encoder()
    for r in sorted(recs, key=lambda r: r.utc):   # as they were received
        assert live.feed(enc.encode(ms_record(r)), "application/json;onboard.Estimate.v2")
    a, b = history.step(refit=True), live.step(refit=True)
    assert a is not None and b is not None
    assert history.field.hyper == pytest.approx(live.field.hyper, rel=1e-9)
    lat, lon = survey.plane.to_latlon(100.0, -200.0)
    got = history.answer(lat, lon, UTC0 + 600.0)
    want = live.answer(lat, lon, UTC0 + 600.0)
    assert got.north == pytest.approx(want.north, abs=1e-12)
    assert got.std_east == pytest.approx(want.std_east, abs=1e-12)
    assert got.down is not None and got.down == pytest.approx(want.down, abs=1e-12)
    truth = eddy(np.array(100.0), np.array(-200.0), 600.0)
    assert abs(got.north - float(truth[0])) < 3 * got.std_north + 0.01
    assert abs(got.east - float(truth[1])) < 3 * got.std_east + 0.01


def test_a_field_served_from_its_history_is_written_to_the_mcap_once(survey, tmp_path):
    pytest.importorskip("mcap", reason="the mcap extra: pip install -e '.[mcap]'")
    path = tmp_path / "current.parquet"
    write_table(path, [survey.record(i) for i in range(0, len(survey.t), 10)])
    service = FleetService(mcap=tmp_path / "field.mcap")
    service.load_history(path)
    for _ in range(3):   # nothing new between the grids
        assert service.step() is not None
    service.close()
    assert service.grids == 3 and service.mcap.messages == 2   # one grid, its arrows


def test_rows_older_than_the_history_before_the_newest_are_counted(survey, tmp_path):
    recs = [survey.record(i) for i in range(0, len(survey.t), 10)]
    old = [msgspec.structs.replace(r, utc=r.utc - HISTORY_S - 1000.0) for r in recs[:5]]
    path = tmp_path / "current.parquet"
    write_table(path, old + recs)
    counts = FleetService().load_history(tmp_path)   # a folder: its current.parquet
    assert counts == {"rows": len(recs) + 5, "added": len(recs), "too_old": 5}


def test_a_table_written_before_its_added_columns_places_its_rows_exactly(survey, tmp_path):
    recs = [survey.record(i) for i in range(0, len(survey.t), 10)]
    path = tmp_path / "current.parquet"
    write_table(path, [msgspec.structs.replace(r, position_std_m=50.0) for r in recs])
    placed = FleetService()
    placed.load_history(path)
    pq.write_table(pq.read_table(path).drop(["position_std_m", "down", "std_down"]), path)
    service = FleetService()
    assert service.load_history(path) == {"rows": len(recs), "added": len(recs)}
    live = FleetService()
    for r in sorted(recs, key=lambda r: r.utc):   # live records without a position sigma
        live.field.add_record(ms_record(r))
    place = service.field.gather().place
    assert place == pytest.approx(live.field.gather().place, abs=1e-9)
    assert np.all(placed.field.gather().place > place + 10.0)   # the column's 50 m


def test_a_table_whose_times_have_no_zone_is_read_in_utc(survey, tmp_path, monkeypatch):
    """A day written out by another tool with its ``utc`` column's zone dropped (a
    timestamp without a zone) is read as UTC, not as the shore machine's local time (on
    a laptop in Paris the field stood an hour or two from its records' times)."""
    import time

    recs = [survey.record(i) for i in range(0, len(survey.t), 10)]
    path = tmp_path / "current.parquet"
    write_table(path, recs)
    table = pq.read_table(path)
    i = table.schema.get_field_index("utc")
    naive = table.set_column(i, "utc", table["utc"].cast(pa.timestamp("ms")))
    pq.write_table(naive, tmp_path / "naive.parquet")
    monkeypatch.setenv("TZ", "Europe/Paris")
    time.tzset()
    try:
        aware, local = FleetService(), FleetService()
        aware.load_history(path)
        local.load_history(tmp_path / "naive.parquet")
    finally:
        monkeypatch.undo()
        time.tzset()
    assert local.field.newest_utc == aware.field.newest_utc == \
        max(round(r.utc * 1000.0) / 1000.0 for r in recs)


def test_a_file_that_is_not_a_batch_table_is_a_usage_error(tmp_path):
    with pytest.raises(UsageError, match="no-such.parquet: not a current.parquet"):
        FleetService().load_history(tmp_path / "no-such.parquet")
    other = tmp_path / "runs.parquet"
    pq.write_table(pa.table({"log": ["a"], "status": ["ok"]}), other)
    with pytest.raises(UsageError, match="runs.parquet: not a current.parquet"):
        FleetService().load_history(other)


@pytest.mark.integration
def test_onboard_fleet_serves_a_batch_table_on_zenoh(survey, tmp_path):
    """The command: a peer listening on a port, the table's field answering a query
    before any vehicle publishes, its page drawing the vehicles' tracks, and its MCAP
    file finished when it is stopped as systemd stops it (SIGTERM)."""
    import urllib.request

    import zenoh

    from onboard.apps.service_bench import free_tcp_port
    from onboard.service.publishers.zenoh_pub import session_config

    recs = [survey.record(i) for i in range(len(survey.t))]
    path = tmp_path / "current.parquet"
    write_table(path, recs)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    proc = subprocess.Popen([sys.executable, "-m", "onboard", "fleet", "--mode", "peer",
                             "--listen", endpoint, "--history", str(path), "--period", "0.5",
                             "--web", "127.0.0.1:0", "--mcap", str(tmp_path / "field.mcap")],
                            stdout=subprocess.PIPE, text=True)
    shore = None
    try:
        first = proc.stdout.readline()
        assert f"{path}: {len(recs):,} of {len(recs):,} currents added" in first, first
        url = ""
        while "vehicles" not in (line := proc.stdout.readline()):   # the first grid
            assert proc.poll() is None, "onboard fleet ended"
            url = line.split("the page is on ")[1].strip() if "the page is on " in line else url
        with urllib.request.urlopen(url + "api/fleet", timeout=5.0) as r:
            layer = json.loads(r.read())
        assert sorted(layer["tracks"]) == sorted({r.vehicle for r in recs})
        assert all(len(track) > 100 for track in layer["tracks"].values())
        shore = zenoh.open(session_config("client", connect=[endpoint]))
        lat, lon = survey.plane.to_latlon(100.0, -200.0)
        replies = list(shore.get(
            f"onboard/fleet/current?lat={lat};lon={lon};utc={UTC0 + 600.0}", timeout=10.0))
        assert len(replies) == 1 and replies[0].ok is not None
        doc = json.loads(replies[0].ok.payload.to_bytes())
        truth = eddy(np.array(100.0), np.array(-200.0), 600.0)
        assert doc["n_obs"] > 0
        assert abs(doc["north"] - float(truth[0])) < 3 * doc["std_north"] + 0.01
    finally:
        if shore is not None:
            shore.close()
        proc.terminate()
        rc = proc.wait(timeout=10.0)
    assert rc == 0
    from mcap.reader import make_reader

    with open(tmp_path / "field.mcap", "rb") as f:   # finished: its summary is there
        stats = make_reader(f).get_summary().statistics
    assert stats.message_count == 2      # the history's one grid, as FleetGrid and GeoJSON


def test_the_mcap_path_is_checked_before_zenoh_opens(tmp_path):
    """``--mcap`` follows the output rules of architecture.md §4.1: one line and exit 2 for
    a directory that does not exist or a file that exists (without ``--force``), before
    any Zenoh session; the existing file is left as it was."""
    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"yesterday's field")
    for mcap, words in ((tmp_path / "none" / "x.mcap", "does not exist"),
                        (existing, "exists; --force replaces it")):
        r = subprocess.run([sys.executable, "-m", "onboard", "fleet", "--connect",
                            "tcp/127.0.0.1:9", "--mcap", str(mcap)],
                           capture_output=True, text=True, timeout=60.0)
        assert r.returncode == 2 and words in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert existing.read_bytes() == b"yesterday's field"


def test_a_missing_history_file_is_one_line_and_exit_2(tmp_path):
    r = subprocess.run([sys.executable, "-m", "onboard", "fleet", "--mode", "peer",
                        "--listen", "tcp/127.0.0.1:0", "--history",
                        str(tmp_path / "none.parquet")], capture_output=True, text=True,
                       timeout=60.0)
    assert r.returncode == 2, r.stderr
    assert "none.parquet: not a current.parquet of onboard batch" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.integration
def test_a_simulated_survey_batched_then_served_is_the_sea_it_flew_in(tmp_path):
    """The operator's evening: the fleet's logs replayed by ``onboard batch`` (each
    vehicle with its configs, as ``onboard sitl --fleet`` prints them), their tables
    given to the fleet. Where the vehicles were after their estimators' first two
    minutes, the field is the simulator's water to within the vehicles' own errors
    (measured on seeds 1 and 3: RMS 0.047-0.049 m/s, at most 0.096 m/s off, 0.82 within
    1.96 sigma: the field there is the vehicles' estimates, which lag fleet-demo's
    20-minute tide); a table whose times or places were not the records' would put the
    field a tide's 0.5 m/s off, or nowhere."""
    import pandas as pd

    from onboard.cli import main as cli

    sim = tmp_path / "sim"
    assert cli(["sitl", "--fleet", "fleet-demo", "--out", str(sim), "--duration", "240",
                "--seed", "3"]) == 0
    service = FleetService()
    for vehicle, config in (("boat-1", "sitl-rudder-boat"), ("boat-2", "sitl-twin-thruster"),
                            ("auv-1", "torpedo-auv")):
        out = tmp_path / vehicle
        assert cli(["batch", str(sim / f"{vehicle}.tlog"), "--config", config,
                    "--config", str(sim / f"{vehicle}.toml"), "--out", str(out)]) == 0
        counts = service.load_history(out / "current.parquet")
        assert counts["added"] == counts["rows"] > 500, counts
    assert sorted(service.newest) == ["auv-1", "boat-1", "boat-2"]
    service.step(refit=True)
    truth = pd.read_csv(sim / "truth-current.csv")
    errors, z = [], []
    for _, row in truth[truth.t > 120.0].iloc[::50].iterrows():
        p = service.field.predict(row.lat_deg, row.lon_deg, row.utc)
        if p.north is not None:
            e = (p.north - row.current_north, p.east - row.current_east)
            errors.append(e)
            z += [abs(e[0]) / p.std_north, abs(e[1]) / p.std_east]
    assert len(errors) > 50   # 66 of 66 known here
    assert np.abs(errors).max() < 0.15 and np.mean(np.array(z) < 1.96) > 0.7
