"""``onboard batch``: a folder of mixed logs with one broken file, locally and on a Dask
``LocalCluster``; every good log's estimates.csv identical to a single ``onboard replay``;
runs.parquet and current.parquet read back; resuming, ``--force``, name collisions, exit
statuses; the season report; the docs' queries (docs/batch.md) run on the tables."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from onboard.cli import main as cli_main
from onboard.offline import batch, batch_tables
from onboard.offline.closure.report import unit_of
from onboard.sitl.runner import run_to_tlog

pa = pytest.importorskip("pyarrow", reason="onboard batch needs the batch extra")
import pyarrow.parquet as pq  # noqa: E402

pytestmark = pytest.mark.integration  # child processes, a Dask cluster

REPO = Path(__file__).resolve().parent.parent
DATA = REPO / "tests" / "data"
CURRENT_SIM_S = 120.0
"""Length of the simulated log whose current converges and is published (s)."""
BROKEN = b"this is no telemetry log\n" * 100


def onboard(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "onboard", *args], capture_output=True,
                          text=True, timeout=600, cwd=cwd)


@pytest.fixture(scope="module")
def season(tmp_path_factory) -> Path:
    """Simulated logs (two named run.tlog in two folders), an NMEA capture, a CSV log, a
    README and a broken tlog."""
    d = tmp_path_factory.mktemp("logs") / "season"
    (d / "a").mkdir(parents=True)
    (d / "b").mkdir()
    shutil.copy(DATA / "replay" / "jaiabot-turns.tlog", d / "a" / "run.tlog")
    shutil.copy(DATA / "replay" / "gavia-tidal.tlog", d / "b" / "run.tlog")
    shutil.copy(DATA / "nmea" / "gnss-compass.nmea", d)
    shutil.copy(DATA / "csv" / "blueboat-run.csv", d)
    run_to_tlog("effect-current", d / "current.tlog", None, duration=CURRENT_SIM_S, seed=1)
    (d / "README.md").write_text("# notes of the season\n")
    (d / "broken.tlog").write_bytes(BROKEN)
    return d


@pytest.fixture(scope="module")
def local(season) -> tuple[subprocess.CompletedProcess, Path]:
    """``onboard batch`` of the season on two local processes."""
    out = season.parent / "season-out"
    return onboard("batch", str(season), "--out", str(out), "--jobs", "2"), out


def _rows(out: Path) -> dict[str, dict]:
    return {r["name"]: r for r in pq.read_table(out / "runs.parquet").to_pylist()}


def test_exit_3_names_the_broken_log_and_skips_what_is_no_log(local, season):
    r, out = local
    assert r.returncode == 3, r.stderr
    last = r.stdout.strip().splitlines()
    assert last[-1].startswith(f"failed {season / 'broken.tlog'}: ")
    assert "not a MAVLink telemetry log" in last[-1]
    assert f"skipped {season / 'README.md'}: not a log" in r.stdout
    assert last[-2].startswith("5 of 6 logs replayed")


def test_runs_table_has_a_row_per_log(local, season):
    _, out = local
    table = pq.read_table(out / "runs.parquet")
    assert table.column_names == list(batch_tables.ROW_KEYS)
    assert table.schema.field("utc_start").type == pa.timestamp("ms", tz="UTC")
    rows = _rows(out)
    assert sorted(rows) == ["a__run.tlog", "b__run.tlog", "blueboat-run.csv",
                            "broken.tlog", "current.tlog", "gnss-compass.nmea"]
    broken = rows["broken.tlog"]
    assert broken["status"] == "failed" and "not a MAVLink telemetry log" in broken["error"]
    assert broken["log"] == str(season / "broken.tlog")
    good = [r for r in rows.values() if r is not broken]
    assert all(r["status"] == "ok" and r["error"] is None for r in good)
    cur = rows["current.tlog"]
    assert cur["vehicle_class"] == "rudder-boat" and cur["format"] == "tlog"
    assert cur["duration_s"] == pytest.approx(CURRENT_SIM_S, abs=0.5)
    assert cur["utc_start"] is not None and cur["samples"] > 0
    assert 0.0 < cur["current_fraction"] <= 1.0 and cur["current_speed_median_mps"] > 0.0
    # the sigma of the current published, not of the rows where it was withheld
    import numpy as np

    est = batch_tables.read_estimates(out / "current.tlog" / "estimates.csv")
    known = np.isfinite(est["current.north"]) & np.isfinite(est["current.east"])
    rms = np.sqrt((est["current.std_north"] ** 2 + est["current.std_east"] ** 2) / 2.0)
    assert cur["current_std_median_mps"] == pytest.approx(np.median(rms[known]))
    assert cur["current_std_median_mps"] < 0.5 * np.median(rms)   # what it said before
    assert dict(cur["availability"])["current"] > 0.0
    assert dict(rows["b__run.tlog"]["warnings"])["no_position_source"] == 1
    assert rows["blueboat-run.csv"]["config"].startswith("from blueboat-ntnu-csv")


def test_current_table_holds_every_published_current(local):
    _, out = local
    table = pq.read_table(out / "current.parquet")
    assert table.column_names == ["name", "vehicle", "t_s", "utc", "lat", "lon", "north",
                                  "east", "std_north", "std_east", "flags", "pipeline",
                                  "position_std_m", "down", "std_down"]   # additive, 2026-11-30
    rows = [r for r in table.to_pylist() if r["name"] == "current.tlog"]
    assert {r["pipeline"] for r in rows} == {"current"}
    est = batch_tables.read_estimates(out / "current.tlog" / "estimates.csv")
    import numpy as np

    published = np.isfinite(est["current.north"]) & np.isfinite(est["current.east"])
    assert len(rows) == int(published.sum()) > 0
    assert all(r["vehicle"] == "rudder-boat" and r["utc"] is not None for r in rows)
    # the log's own UTC, to the millisecond (a float of seconds taken as milliseconds
    # put it in January 1970)
    start = _rows(out)["current.tlog"]["utc_start"]
    assert (rows[0]["utc"] - start).total_seconds() == pytest.approx(rows[0]["t_s"], abs=1.0)
    assert len({r["utc"] for r in rows[:20]}) == len(rows[:20])  # 0.1 s apart, all distinct
    assert all(r["lat"] is not None and abs(r["lat"] - 41.49) < 0.1 for r in rows)
    assert rows[0]["north"] == pytest.approx(est["current.north"][published][0])
    # the place the records carried: a fresh fix's accuracy (the simulated receiver's)
    assert all(0.0 < r["position_std_m"] < 10.0 for r in rows)


def test_every_good_log_identical_to_a_single_replay(local, tmp_path):
    _, out = local
    for name, row in _rows(out).items():
        if row["status"] != "ok":
            continue
        config = ["--config", "blueboat-ntnu-csv"] if name.endswith(".csv") else []
        single = tmp_path / name
        assert cli_main(["replay", row["log"], "--out", str(single), "--no-plot",
                         *config]) == 0
        assert (single / "estimates.csv").read_bytes() == \
            (out / name / "estimates.csv").read_bytes(), name


def test_resumes_and_force_redoes(season, tmp_path):
    logs = [str(season / "gnss-compass.nmea"), str(season / "blueboat-run.csv")]
    out = tmp_path / "out"
    assert onboard("batch", *logs, "--out", str(out), "--jobs", "1").returncode == 0
    done = {p: p.stat().st_mtime_ns for p in out.glob("*/run.json")}
    assert len(done) == 2
    again = onboard("batch", *logs, "--out", str(out))
    assert again.returncode == 0 and again.stderr.count("skipped (done before)") == 2
    assert "2 of 2 logs replayed (2 of them by a run before: skipped)" in again.stdout
    assert {p: p.stat().st_mtime_ns for p in out.glob("*/run.json")} == done
    assert len(pq.read_table(out / "runs.parquet")) == 2
    forced = onboard("batch", *logs, "--out", str(out), "--force")
    assert forced.returncode == 0 and "skipped" not in forced.stderr
    assert all(p.stat().st_mtime_ns != t for p, t in done.items())
    # a batch killed in a log's replay: its folder says so, the next run redoes that log
    killed = out / "gnss-compass.nmea"
    (killed / "run.json").write_text(json.dumps({"log": logs[0], "status": "running"}))
    resumed = onboard("batch", *logs, "--out", str(out))
    assert resumed.returncode == 0 and resumed.stderr.count("skipped (done before)") == 1
    assert json.loads((killed / "run.json").read_text())["status"] == "ok"
    # a run.json cut short (a crash or a power loss while it was written): redone too
    for cut in ("", '{"log": "'):
        (killed / "run.json").write_text(cut)
        resumed = onboard("batch", *logs, "--out", str(out))
        assert resumed.returncode == 0, resumed.stdout
        assert resumed.stderr.count("skipped (done before)") == 1
        assert json.loads((killed / "run.json").read_text())["status"] == "ok"
    assert not list(out.glob("*/run.json.part"))
    # other configs are other inputs: those logs are redone, no --force needed
    overlay = tmp_path / "overlay.toml"
    overlay.write_text("[sensors.gnss]\nposition_std_m = 2.0\n")
    other = onboard("batch", logs[0], "--out", str(out), "--config", "rudder-boat",
                    "--config", str(overlay))
    assert other.returncode == 0 and "skipped" not in other.stderr
    assert onboard("batch", logs[0], "--out", str(out), "--config", "rudder-boat",
                   "--config", str(overlay)).stderr.count("skipped (done before)") == 1
    overlay.write_text("[sensors.gnss]\nposition_std_m = 3.0\n")   # the same file, edited
    assert "skipped" not in onboard("batch", logs[0], "--out", str(out), "--config",
                                    "rudder-boat", "--config", str(overlay)).stderr


def test_resumes_whatever_path_names_the_season(tmp_path):
    """The season given again by another path to the same folder (relative from another
    folder, through ``..``, through a symbolic link): its logs are the same logs, skipped,
    not refused as another command's outputs; ``log`` is the absolute path without
    ``..``."""
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(DATA / "nmea" / "gnss-compass.nmea", logs)
    (tmp_path / "sub").mkdir()
    (tmp_path / "link").symlink_to(logs)
    first = onboard("batch", "../logs", "--out", "../out", "--jobs", "1",
                    cwd=tmp_path / "sub")
    assert first.returncode == 0, first.stdout + first.stderr
    assert _rows(tmp_path / "out")["gnss-compass.nmea"]["log"] == \
        str(logs / "gnss-compass.nmea")
    for args, cwd in ((("logs", "--out", "out"), tmp_path),
                      ((str(tmp_path / "link"), "--out", str(tmp_path / "out")), None)):
        again = onboard("batch", *args, cwd=cwd)
        assert again.returncode == 0, again.stdout + again.stderr
        assert again.stderr.count("skipped (done before)") == 1


def test_a_folder_of_another_command_is_not_overwritten(season, tmp_path):
    out = tmp_path / "out"
    (out / "gnss-compass.nmea").mkdir(parents=True)
    (out / "gnss-compass.nmea" / "estimates.csv").write_text("t\n")
    r = onboard("batch", str(season / "gnss-compass.nmea"), "--out", str(out))
    assert r.returncode == 2 and "holds a previous run's estimates.csv" in r.stdout
    assert onboard("batch", str(season / "gnss-compass.nmea"), "--out", str(out),
                   "--force").returncode == 0


def test_a_log_refused_a_folder_leaves_its_owner_s_run_alone(tmp_path):
    """Two seasons into one ``--out``, a log of each with the same name: the second is
    refused its folder (another log's outputs) and fails without writing there, so the
    first season still resumes that log."""
    for season in ("sA", "sB"):
        (tmp_path / season).mkdir()
        shutil.copy(DATA / "nmea" / "gnss-compass.nmea", tmp_path / season)
    out = tmp_path / "out"
    assert onboard("batch", str(tmp_path / "sA"), "--out", str(out)).returncode == 0
    run = (out / "gnss-compass.nmea" / "run.json").read_bytes()
    other = onboard("batch", str(tmp_path / "sB"), "--out", str(out))
    assert other.returncode == 2 and "holds a previous run's" in other.stdout
    assert (out / "gnss-compass.nmea" / "run.json").read_bytes() == run
    again = onboard("batch", str(tmp_path / "sA"), "--out", str(out))
    assert again.returncode == 0 and "skipped (done before)" in again.stderr


def test_names_that_collide_get_their_own_folders():
    assert batch.folder_names(["x/a/run.tlog", "x/b/run.tlog", "y.bin"]) == \
        ["a__run.tlog", "b__run.tlog", "y.bin"]
    assert batch.folder_names(["p/a/run.tlog", "q/a/run.tlog"]) == \
        ["p__a__run.tlog", "q__a__run.tlog"]
    assert batch.folder_names(["a.tlog", "a.tlog"]) == ["a.tlog", "a.tlog-2"]
    # found in a folder given: its path below that folder, whatever else is added there
    assert batch.folder_names(["s/one/run.tlog"], ["s"]) == ["one__run.tlog"]
    assert batch.folder_names(["s/one/run.tlog", "s/two/run.tlog"], ["s", "s"]) == \
        ["one__run.tlog", "two__run.tlog"]
    # names the joining makes alike are numbered, never the machine's path
    assert batch.folder_names(["/abs/s/a__run.tlog", "/abs/s/a/run.tlog", "/abs/s/b/run.tlog"],
                              ["/abs/s"] * 3) == ["a__run.tlog", "a__run.tlog-2",
                                                  "b__run.tlog"]


def test_a_name_too_long_for_a_folder_is_shortened_alike_run_after_run():
    """A log deep in long-named folders: its folder's name fits a file system's 255
    bytes (it failed, "File name too long"), ends with its file name and is the same
    every run; two such logs keep apart."""
    deep = "s/" + "/".join(f"a_long_folder_name_of_a_survey_session_{k:02d}_ü"
                           for k in range(8))
    logs = [f"{deep}/x/run.tlog", f"{deep}/y/run.tlog", "s/short/run.tlog"]
    names = batch.folder_names(logs, ["s"] * 3)
    assert all(len(n.encode()) <= batch.NAME_MAX_BYTES for n in names)
    assert names[0].startswith("~") and names[0].endswith("__x__run.tlog")
    assert names[0] != names[1] and names[2] == "short__run.tlog"
    assert batch.folder_names(logs[:1], ["s"]) == names[:1]
    long_file = "s/" + "b" * 300 + ".tlog"
    name = batch.folder_names([long_file], ["s"])[0]
    assert len(name.encode()) <= batch.NAME_MAX_BYTES and name.endswith("bbb.tlog")


def test_a_folder_of_csv_runs_is_one_log_and_of_different_csvs_is_searched(tmp_path):
    """CSV files with one header are the runs of one log; beside a vehicle log, a table of
    another kind without a time column (the Kolumbo glider's DVL current profile) is not a
    log; a README quoting an NMEA sentence is a document, not a log."""
    runs = tmp_path / "runs"
    runs.mkdir()
    for i in (1, 2):
        (runs / f"run{i}.csv").write_text("time,lat,lon\n0,41.5,-71.4\n")
    (runs / "README.md").write_text("# runs\n")
    assert batch.find_logs([str(runs)]).logs == [str(runs)]
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    (mixed / "glider.csv").write_text("time,lat,lon\n0,41.5,-71.4\n")
    (mixed / "profile.csv").write_text(",z,N,E,D\n0,5,0.1,0.2,0\n")
    (mixed / "README_upstream.md").write_text(
        "Data sample:\n\n$GPGGA,022718.80,2234.03506362,N,11431.92532083,E,4,19,0.9,"
        "3.4038,M,-1.3415,M,00,0000*7F\n")
    found = batch.find_logs([str(mixed)])
    assert found.logs == [str(mixed / "glider.csv")]
    assert found.skipped[0] == (str(mixed / "README_upstream.md"), "a document (.md)")
    assert found.skipped[1][0] == str(mixed / "profile.csv")
    assert found.skipped[1][1].startswith("a CSV table with no time column (, z, N, E, D)")
    # named, it is a log (and fails with its reason); a config's time column makes it one
    assert batch.find_logs([str(mixed / "profile.csv")]).logs == [str(mixed / "profile.csv")]
    assert str(mixed / "profile.csv") in batch.find_logs([str(mixed)], ["Z"]).logs
    tables = tmp_path / "tables"
    tables.mkdir()
    for i in (1, 2):
        (tables / f"profile{i}.csv").write_text(",z,N,E,D\n0,5,0.1,0.2,0\n")
    assert not batch.is_log_dir(tables) and batch.find_logs([str(tables)]).logs == []


def test_a_link_to_a_folder_searched_already_is_not_followed_again(tmp_path):
    """A season holding a symbolic link to a folder above it (a loop): its logs found
    once, at their own path, not at the deepest path the links allow (its folder name too
    long to write; with two such links the search never ended)."""
    season = tmp_path / "season"
    (season / "x").mkdir(parents=True)
    (season / "x" / "run.tlog").write_bytes(BROKEN)
    (season / "x" / "back").symlink_to(season)
    found = batch.find_logs([str(season)])
    assert found.logs == [str(season / "x" / "run.tlog")]
    assert batch.folder_names(found.logs, found.bases) == ["x__run.tlog"]


def test_binary_data_named_csv_is_skipped_as_binary(tmp_path):
    """A binary file named ``.csv`` in a folder searched: skipped as binary data, its
    bytes (terminal escapes among them) not printed as a CSV header."""
    (tmp_path / "s").mkdir()
    for name, data in (("escapes.csv", b"\x1b[2J\x8f\x01\x9aPK\x03\x04" * 50),
                       ("nul.csv", b"PK\x03\x04\x14\x00\x00\x00" * 50)):
        (tmp_path / "s" / name).write_bytes(data)
    found = batch.find_logs([str(tmp_path / "s")])
    assert found.logs == []
    assert [why for _, why in found.skipped] == \
        ["binary data in no format this tool reads"] * 2


def test_a_worker_that_dies_fails_its_log_alone(season):
    from concurrent.futures import ProcessPoolExecutor

    task = batch.Task(str(season / "gnss-compass.nmea"), "unused", "gnss-compass.nmea")
    with ProcessPoolExecutor(max_workers=1) as pool:
        row = batch._result(pool.submit(os._exit, 1), task)
    assert row["status"] == "failed" and row["name"] == "gnss-compass.nmea"
    assert row["error"].startswith("the worker failed: BrokenProcessPool")


def test_bad_usage_and_nothing_readable_exit_2(season, tmp_path):
    r = onboard("batch", str(tmp_path / "missing"), "--out", str(tmp_path / "o1"))
    assert r.returncode == 2 and "no such file or directory" in r.stderr
    r = onboard("batch", str(season / "a"), "--out", str(tmp_path / "o2"), "--jobs", "0")
    assert r.returncode == 2 and "--jobs 0" in r.stderr
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "README.md").write_text("# nothing here\n")
    r = onboard("batch", str(notes), "--out", str(tmp_path / "o3"))
    assert r.returncode == 2 and "no log found" in r.stderr
    r = onboard("batch", str(season / "broken.tlog"), "--out", str(tmp_path / "o4"))
    assert r.returncode == 2 and "no log could be read" in r.stderr
    assert "broken.tlog" in r.stdout.strip().splitlines()[-1]
    r = onboard("batch", str(season / "a"), "--out", str(season / "a" / "out"))
    assert r.returncode == 2 and "inside the input directory" in r.stderr
    r = onboard("batch", str(season / "a"), "--out", str(tmp_path / "o5"), "--config",
                str(tmp_path / "nowhere.toml"))
    assert r.returncode == 2 and f"--config {tmp_path / 'nowhere.toml'}" in r.stderr


def test_on_a_dask_local_cluster(season, local, tmp_path):
    distributed = pytest.importorskip("distributed", reason="pip install 'onboard[batch]'")
    _, local_out = local
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("current.tlog", "broken.tlog", "gnss-compass.nmea"):
        shutil.copy(season / name, logs / name)
    out = tmp_path / "out"
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as cluster:
        # paths relative to a folder the workers do not run in: sent absolute
        r = onboard("batch", "logs", "--out", "out", "--scheduler",
                    cluster.scheduler_address, cwd=tmp_path)
    assert r.returncode == 3, r.stderr
    assert r.stdout.strip().splitlines()[-1].startswith(f"failed {logs / 'broken.tlog'}")
    rows = _rows(out)
    assert {n: r["status"] for n, r in rows.items()} == {
        "current.tlog": "ok", "broken.tlog": "failed", "gnss-compass.nmea": "ok"}
    for name in ("current.tlog", "gnss-compass.nmea"):
        assert (out / name / "estimates.csv").read_bytes() == \
            (local_out / name / "estimates.csv").read_bytes()
    assert pq.read_table(out / "current.parquet").num_rows == \
        len([r for r in pq.read_table(local_out / "current.parquet").to_pylist()
             if r["name"] == "current.tlog"])


def test_an_unreachable_scheduler_is_bad_usage(season, tmp_path, monkeypatch, capsys):
    """Nothing listening, or a server that accepts and never answers as Dask does: one
    line, exit 2, within :data:`batch.SCHEDULER_CONNECT_S`, and no ``--out`` made."""
    pytest.importorskip("distributed", reason="pip install 'onboard[batch]'")
    r = onboard("batch", str(season / "gnss-compass.nmea"), "--out", str(tmp_path / "o"),
                "--scheduler", "tcp://127.0.0.1:9")
    assert r.returncode == 2 and "--scheduler tcp://127.0.0.1:9: cannot connect" in r.stderr
    silent = socket.create_server(("127.0.0.1", 0))   # accepts, says nothing
    monkeypatch.setattr(batch, "SCHEDULER_CONNECT_S", 2.0)
    address = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
    try:
        assert cli_main(["batch", str(season / "gnss-compass.nmea"), "--out",
                         str(tmp_path / "o"), "--scheduler", address]) == 2
    finally:
        silent.close()
    assert "no Dask scheduler answered within 2 s" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_diagnose_writes_the_season_report(season, tmp_path):
    out = tmp_path / "out"
    r = onboard("batch", str(season / "current.tlog"), str(season / "a" / "run.tlog"),
                "--out", str(out), "--diagnose")
    assert r.returncode == 0, r.stderr
    rows = _rows(out)
    cur = rows["current.tlog"]
    doc = (out / "current.tlog" / "diagnose" / "diagnosis.json").read_text()
    import json

    found = [e["name"] for e in json.loads(doc)["effects"] if e["detected"]]
    assert cur["diagnosed"] and cur["effects"] == found
    assert cur["holdout_error_after"] <= cur["holdout_error_before"]
    short = rows["run.tlog"]
    assert short["status"] == "ok" and not short["diagnosed"]
    assert "too short" in short["diagnose_error"]
    report = (out / "season.md").read_text()
    # the config was detected (its id is the class's): the vehicle is named with its folder
    assert report in r.stdout and "| rudder-boat (season) |" in report
    assert "water_current" in found   # each parameter named with its unit
    assert "| north (m/s) |" in report and "| east (m/s) |" in report


def test_season_report_per_vehicle_and_effect():
    def row(name, vehicle, utc, effects, params, diagnosed=True):
        r = batch_tables.empty_row(name, name)
        r.update(vehicle_id=vehicle, utc_start=utc, diagnosed=diagnosed, effects=effects,
                 effect_params=params)
        return r

    rows = [row("l2", "boat", "2026-06-02T00:00:00.000Z", ["heading_bias"],
                {"heading_bias.bias": math.radians(6.0)}),
            row("l1", "boat", "2026-06-01T00:00:00.000Z", ["heading_bias"],
                {"heading_bias.bias": math.radians(2.0)}),
            row("l3", "boat", "2026-06-03T00:00:00.000Z", [], {}),
            row("l4", "boat", None, ["heading_bias"], {"heading_bias.bias": 9.0},
                diagnosed=False),
            row("g1", "glider", None, [], {})]
    report = batch_tables.season_report(rows, unit_of)
    # in the unit diagnose's report shows (deg), not diagnosis.json's rad
    assert "| boat | heading_bias | 2 of 3 | bias (deg) | 4 | 2.83 | 2 | 6 | 2 -> 6 |" in report
    assert "| glider | none | 0 of 1 |" in report


def test_season_report_averages_angles_on_the_circle():
    """A compass mounted backwards: biases of 179 and -179 deg are 180 deg on average
    (0 arithmetically), 1.4 deg apart; a deviation's amplitude is no angle on the
    circle."""
    def row(name, bias, amplitude):
        r = batch_tables.empty_row(name, name)
        r.update(vehicle_id="boat", diagnosed=True,
                 effects=["heading_bias", "compass_deviation"],
                 effect_params={"heading_bias.bias": math.radians(bias),
                                "compass_deviation.amplitude": math.radians(amplitude),
                                "compass_deviation.phase": math.radians(bias)})
        return r

    report = batch_tables.season_report([row("a", 179.0, 2.0), row("b", -179.0, 4.0)],
                                         unit_of)
    assert "| boat | heading_bias | 2 of 2 | bias (deg) | 180 | 1.41 | -179 | 179 | " \
        "179 -> -179 |" in report
    assert "| phase (deg) | 180 | 1.41 |" in report
    assert "| amplitude (deg) | 3 | 1.41 | 2 | 4 | 2 -> 4 |" in report


def test_season_report_tells_apart_vehicles_a_detected_config_does_not_name():
    """Logs replayed with a config detected from them (or fitted to their CSV header)
    carry its id, the class's or the generic ``vehicle``: two boats in two folders are
    two vehicles in the report, not one with two compasses."""
    def row(log, config, bias):
        r = batch_tables.empty_row(log, Path(log).name)
        r.update(vehicle_id="vehicle", config=config, diagnosed=True,
                 effects=["heading_bias"], effect_params={"heading_bias.bias": bias})
        return r

    detected = "detected: no vehicle evidence in a text log; generic config"
    rows = [row("/logs/usv/a.txt", detected, 2.0), row("/logs/usv/b.txt", detected, 2.2),
            row("/logs/survey/c.txt", detected, -1.0),
            row("/logs/x/d.csv", f"from blueboat-ntnu-csv {batch_tables.FITTED_CONFIG}", 0.5),
            row("/logs/y/e.txt", "from boat1.toml", 1.5)]
    report = batch_tables.season_report(rows, unit_of)
    assert "| vehicle (usv) | heading_bias | 2 of 2 | bias (deg) | 120.3 |" in report
    assert "| vehicle (survey) | heading_bias | 1 of 1 |" in report
    assert "| vehicle (x) | heading_bias | 1 of 1 |" in report
    assert "| vehicle | heading_bias | 1 of 1 | bias (deg) | 85.94 |" in report  # --config


def test_the_docs_queries_run_on_the_tables(local, monkeypatch, capsys):
    """Every Python block of docs/batch.md runs on the tables (``season-out``)."""
    pytest.importorskip("duckdb", reason="pip install duckdb")
    pytest.importorskip("pandas", reason="pip install pandas")
    _, out = local
    monkeypatch.chdir(out.parent)
    blocks = re.findall(r"```python\n(.*?)```", (REPO / "docs" / "batch.md").read_text(),
                        re.S)
    assert len(blocks) >= 3
    for code in blocks:
        exec(compile(code, "docs/batch.md", "exec"), {})
    assert "current.tlog" in capsys.readouterr().out


def test_the_vehicle_install_stays_lean():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    core = " ".join(project["dependencies"])
    for heavy in ("dask", "distributed", "pyarrow", "pandas", "duckdb"):
        assert heavy not in core
    assert {"dask[distributed]", "pyarrow"} <= {
        re.split(r"[<>=]", d)[0] for d in project["optional-dependencies"]["batch"]}
    assert "onboard[batch]" in project["optional-dependencies"]["test"]


@pytest.mark.data
@pytest.mark.slow   # 16 s; each of these logs is replayed alone by tests/test_real_logs.py
def test_a_current_without_utc_has_rows_without_utc():
    """A log without UTC (the BlueBoat CSVs' time since boot) whose current is published:
    its rows carry a null ``utc``, not a failed log (a clock with no offsets says None)."""
    import numpy as np

    from onboard.drivers.logclock import LogClock

    cols = {"t": np.array([0.0, 0.1]), "current.north": np.array([0.1, 0.2]),
            "current.east": np.array([0.0, np.nan])}
    summary = {"origin": None, "warnings": [],
               "time_span": {"start": 1444.2, "segments": [{"start": 1444.2}]}}
    rows = batch_tables.current_rows(cols, summary, LogClock("no UTC", ()),
                                     [(None, None, None)] * 2)
    assert rows["utc"] == [None] and rows["north"] == [0.1] and rows["t_s"] == [0.0]


def test_real_logs_beside_notes(shared_data, tmp_path):
    """A folder of real logs (a tlog, a DataFlash .bin, an NMEA capture) and its
    SOURCE.md: every log replayed as a single replay would, the notes skipped."""
    src = shared_data / "ardusub_small_logs"
    out = tmp_path / "out"
    r = onboard("batch", str(src), "--out", str(out))
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"skipped {src / 'SOURCE.md'}: not a log" in r.stdout
    rows = _rows(out)
    assert sorted(rows) == ["nmea_log.txt", "small.BIN", "small.tlog"]
    for name, row in rows.items():
        assert row["status"] == "ok" and row["duration_s"] > 0
        single = tmp_path / name
        assert cli_main(["replay", row["log"], "--out", str(single), "--no-plot"]) == 0
        assert (single / "estimates.csv").read_bytes() == \
            (out / name / "estimates.csv").read_bytes(), name


def test_progress_redraws_one_line_on_a_terminal_and_prints_a_line_per_log_otherwise(
        monkeypatch, capsys):
    monkeypatch.setattr(batch, "PROGRESS_EVERY_S", 0.05)
    p = batch.Progress(2, tty=True)
    import time

    time.sleep(0.2)   # a long log: the elapsed time is redrawn while it runs
    p.add({"status": "ok", "name": "x", "duration_s": 1800.0})
    p.add({"status": "failed", "name": "y", "error": "bad"})
    p.close()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.count("\r") >= 3
    assert err.rstrip().endswith("2/2 logs, 1 failed, 0.50 log-h replayed, 0 s")
    # a log a run before replayed is counted done, its hours not as replayed now
    p = batch.Progress(2, tty=True)
    p.add({"status": "ok", "name": "x", "duration_s": 3600.0}, skipped=True)
    p.add({"status": "ok", "name": "y", "duration_s": 1800.0})
    p.close()
    assert capsys.readouterr().err.rstrip().endswith(
        "2/2 logs (1 done before), 0 failed, 0.50 log-h replayed, 0 s")
    p = batch.Progress(2, tty=False)
    p.add({"status": "ok", "name": "x"}, skipped=True)
    p.add({"status": "failed", "name": "y", "error": "bad"})
    p.close()
    assert capsys.readouterr().err == "[1/2] skipped (done before) x\n[2/2] failed y: bad\n"


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (Linux /proc)."""
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            kids.append(int(stat.parent.name))
    return kids


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_to_the_batch_alone_stops_its_workers_and_exits_130(season, tmp_path,
                                                                     signum):
    """SIGTERM or SIGINT to the batch process alone (not its process group): exit 130,
    its local workers gone, the logs they ran left ``running`` for the next run."""
    import time

    logs = tmp_path / "logs"
    logs.mkdir()
    for k in range(6):
        shutil.copy(season / "current.tlog", logs / f"run{k}.tlog")
    out = tmp_path / "out"
    p = subprocess.Popen([sys.executable, "-m", "onboard", "batch", str(logs), "--out",
                          str(out), "--jobs", "2"], stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL,   # a worker left would hold a pipe
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not any(
            '"running"' in f.read_text() for f in out.glob("*/run.json")):
        time.sleep(0.01)
    workers = _children(p.pid)
    assert workers, "no worker started"
    p.send_signal(signum)
    try:
        assert p.wait(timeout=30) == 130
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and any(map(_alive, workers)):
            time.sleep(0.05)
        assert not [w for w in workers if _alive(w)], "workers left running"
    finally:
        for w in filter(_alive, workers):
            os.kill(w, signal.SIGKILL)
