"""Exports and plots of a replay (issue 24, item 7; issue 30): the ``run`` column of
estimates.csv, summary.json's origin and runs, ``--geojson`` (RFC 7946), track.png, and
``--gpx`` read back with gpxpy: its tracks, points and their UTC times where the log has
UTC, none where it does not."""

from __future__ import annotations

import csv
import json
import math
from datetime import datetime, timezone
from pathlib import Path

import pytest

from onboard.cli import main as cli_main
from onboard.core.geo import LocalFrame
from onboard.offline.exports import ARROW_SCALE_S, feature_collection
from tests.helpers.nmea_times import rmc_times

REPO = Path(__file__).resolve().parents[1]
JAIABOT = REPO / "tests/data/replay/jaiabot-turns.tlog"
BLUEBOAT_CSV = REPO / "tests/data/csv/blueboat-run.csv"
BLUEBOAT_CONFIG = REPO / "config/blueboat-ntnu-csv.toml"


@pytest.fixture(scope="module")
def jaiabot(tmp_path_factory) -> Path:
    """The golden Jaiabot log replayed with ``--geojson``."""
    out = tmp_path_factory.mktemp("jaiabot")
    assert cli_main(["replay", str(JAIABOT), "--out", str(out), "--no-plot",
                     "--geojson", str(out / "track.geojson")]) == 0
    return out


def _check_rfc7946(doc: dict) -> None:
    """The structure RFC 7946 requires of a FeatureCollection of LineStrings: every
    position [lon, lat] in range, at least two per LineString, properties an object."""
    assert doc["type"] == "FeatureCollection" and isinstance(doc["features"], list)
    for f in doc["features"]:
        assert f["type"] == "Feature" and isinstance(f["properties"], dict)
        g = f["geometry"]
        assert g["type"] == "LineString" and len(g["coordinates"]) >= 2
        for pos in g["coordinates"]:
            assert len(pos) == 2 and all(isinstance(x, float) and math.isfinite(x)
                                         for x in pos)
            assert -180.0 <= pos[0] <= 180.0 and -90.0 <= pos[1] <= 90.0


def test_estimates_csv_has_a_run_column_after_t_and_the_summary_its_runs(jaiabot):
    rows = list(csv.reader(open(jaiabot / "estimates.csv")))
    assert rows[0][:2] == ["t", "run"] and {r[1] for r in rows[1:]} == {"0"}
    s = json.loads((jaiabot / "summary.json").read_text())
    assert s["columns"] == rows[0]
    (run,) = s["runs"]
    assert run["run"] == 0 and run["rows"] == len(rows) - 1
    assert run["t_start"] == 0.0 and run["t_end"] == float(rows[-1][0])


def test_the_summary_gives_the_origin_of_the_positions(jaiabot):
    s = json.loads((jaiabot / "summary.json").read_text())
    o = s["origin"]
    # the SITL's home (the scenario's first fix)
    assert -90 < o["lat_deg"] < 90 and -180 < o["lon_deg"] < 180
    rows = list(csv.DictReader(open(jaiabot / "estimates.csv")))
    first = next(r for r in rows if r["nav.north"])
    assert abs(float(first["nav.north"])) < 5.0 and abs(float(first["nav.east"])) < 5.0


def test_geojson_is_rfc_7946_with_a_track_per_pipeline_in_lon_lat_order(jaiabot):
    doc = json.loads((jaiabot / "track.geojson").read_text())
    _check_rfc7946(doc)
    s = json.loads((jaiabot / "summary.json").read_text())
    assert s["geojson"]["features"] == len(doc["features"])
    tracks = {f["properties"]["pipeline"]: f for f in doc["features"]
              if f["properties"]["kind"] == "track"}
    assert set(tracks) == {"nav", "aie", "kf"}  # the current is no track
    lon, lat = tracks["nav"]["geometry"]["coordinates"][0]
    o = s["origin"]
    # longitude first: the first fix is the origin, within its first few metres
    assert abs(lat - o["lat_deg"]) < 1e-4 and abs(lon - o["lon_deg"]) < 1e-4
    assert doc["name"] == "jaiabot-turns.tlog"


def test_a_current_arrow_points_where_the_water_flows_scaled_by_its_time():
    """0.5 m/s toward the east at the origin: an arrow 30 m long toward 90 deg."""
    frame = LocalFrame(48.0, -4.0)
    cols = {"t": [0.0, 0.1], "run": [0.0, 0.0], "nav.north": [0.0, 0.0],
            "nav.east": [0.0, 0.0], "current.north": [0.0, 0.0], "current.east": [0.5, 0.5],
            "current.std_north": [0.1, 0.1], "current.std_east": [0.1, 0.1]}
    doc = feature_collection(cols, {"lat_deg": 48.0, "lon_deg": -4.0})
    _check_rfc7946(doc)
    (arrow,) = [f for f in doc["features"] if f["properties"]["kind"] == "current"]
    (lon0, lat0), (lon1, lat1) = arrow["geometry"]["coordinates"]
    n, e = frame.to_ne(lat1, lon1)
    assert (lon0, lat0) == (-4.0, 48.0)
    assert n == pytest.approx(0.0, abs=0.01) and e == pytest.approx(0.5 * ARROW_SCALE_S, abs=0.01)
    assert arrow["properties"]["toward_deg"] == pytest.approx(90.0)


def test_runs_are_separate_tracks_and_no_origin_is_no_feature():
    cols = {"t": [0.0, 0.1, 0.2, 0.3], "run": [0.0, 0.0, 1.0, 1.0],
            "aie.north": [0.0, 1.0, 50.0, 51.0], "aie.east": [0.0, 0.0, 0.0, 0.0]}
    doc = feature_collection(cols, {"lat_deg": 48.0, "lon_deg": -4.0},
                             [{"run": 0, "name": "a"}, {"run": 1, "name": "b"}])
    assert [(f["properties"]["run"], f["properties"]["run_name"]) for f in doc["features"]] \
        == [(0, "a"), (1, "b")]
    assert feature_collection(cols, None)["features"] == []


def test_a_directory_of_csv_runs_numbers_its_runs(tmp_path):
    """Two copies of one BlueBoat run in a folder: two runs, named after their files."""
    d = tmp_path / "runs"
    d.mkdir()
    for name in ("a_run.csv", "b_run.csv"):
        (d / name).write_text(BLUEBOAT_CSV.read_text())
    out = tmp_path / "out"
    assert cli_main(["replay", str(d), "--config", str(BLUEBOAT_CONFIG), "--out", str(out),
                     "--no-plot"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert [(r["run"], r["name"]) for r in s["runs"]] == [(0, "a_run"), (1, "b_run")]
    rows = list(csv.DictReader(open(out / "estimates.csv")))
    assert sum(r["run"] == "1" for r in rows) == s["runs"][1]["rows"] > 0


def test_track_png_draws_positions_one_line_per_run_and_the_current_apart():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from onboard.offline.plots import track_figure

    cols = {"t": [0.0, 0.1, 0.2, 0.3], "run": [0.0, 0.0, 1.0, 1.0],
            "aie.north": [0.0, 1.0, 50.0, 51.0], "aie.east": [0.0, 0.0, 0.0, 0.0],
            "current.north": [0.1, 0.1, 0.1, 0.1], "current.east": [0.2, 0.2, 0.2, 0.2]}
    fig = track_figure(cols, "log.tlog")
    track, panel = fig.axes
    assert track.get_title() == "Track: log.tlog (2 runs)"
    (line,) = track.get_lines()  # aie only: the current (m/s) is not a position
    north = list(line.get_ydata())
    # the two runs are not joined: a break (NaN) between 1 m and 50 m
    assert north[:2] == [0.0, 1.0] and math.isnan(north[2]) and north[3:] == [50.0, 51.0]
    assert panel.collections and "Current" in panel.get_title()
    plt.close(fig)


def test_gpx_has_a_track_per_pipeline_and_run_in_gpx_1_1(tmp_path):
    import xml.etree.ElementTree as ET

    out = tmp_path / "out"
    assert cli_main(["replay", str(JAIABOT), "--out", str(out), "--no-plot",
                     "--gpx", str(tmp_path / "t.gpx")]) == 0
    ns = {"g": "http://www.topografix.com/GPX/1/1"}
    root = ET.parse(tmp_path / "t.gpx").getroot()
    assert root.tag == "{http://www.topografix.com/GPX/1/1}gpx" and root.get("version") == "1.1"
    names = [t.find("g:name", ns).text for t in root.findall("g:trk", ns)]
    assert names == ["nav run 0", "aie run 0", "kf run 0"]
    o = json.loads((out / "summary.json").read_text())["origin"]
    first = root.find("g:trk/g:trkseg/g:trkpt", ns)
    assert abs(float(first.get("lat")) - o["lat_deg"]) < 1e-4
    assert abs(float(first.get("lon")) - o["lon_deg"]) < 1e-4


# ------------------------------------------------------------------ GPX read back by gpxpy


def _gpx_replay(log: Path, out: Path, *extra: str):
    """Replay ``log`` with --gpx and --geojson; (the GPX as gpxpy reads it, the GeoJSON,
    the summary)."""
    gpxpy = pytest.importorskip("gpxpy", reason="needs gpxpy: pip install -e '.[test]'")
    assert cli_main(["replay", str(log), "--out", str(out), "--no-plot", *extra,
                     "--gpx", str(out / "t.gpx"), "--geojson", str(out / "t.geojson")]) == 0
    with open(out / "t.gpx") as f:
        gpx = gpxpy.parse(f)
    return (gpx, json.loads((out / "t.geojson").read_text()),
            json.loads((out / "summary.json").read_text()))


def _utc_of_rows(out: Path, start_utc: float, pipeline: str) -> list[float]:
    """The UTC (POSIX s) of the rows of estimates.csv where ``pipeline`` has a position:
    the log's UTC start plus their ``t``."""
    rows = csv.DictReader(open(out / "estimates.csv"))
    return [start_utc + float(r["t"]) for r in rows if r[pipeline + ".north"]]


def test_gpx_reads_back_with_its_tracks_points_and_utc_times(tmp_path):
    """The simulator's tlog is stamped from 2026-01-01T00:00:00Z: every point of every
    track has the UTC of its row, to the millisecond, and the same position as GeoJSON."""
    gpx, fc, s = _gpx_replay(JAIABOT, tmp_path)
    assert s["utc"]["utc"] and s["utc"]["start"] == "2026-01-01T00:00:00.000Z"
    assert "point times in UTC from the tlog's record stamps" in gpx.description
    assert gpx.name == "jaiabot-turns.tlog"
    tracks = [f for f in fc["features"] if f["properties"]["kind"] == "track"]
    assert [t.name for t in gpx.tracks] == \
        [f"{f['properties']['pipeline']} run {f['properties']['run']}" for f in tracks]
    start = datetime(2026, 1, 1, tzinfo=timezone.utc).timestamp()
    for trk, feature in zip(gpx.tracks, tracks):
        (seg,) = trk.segments
        coords = feature["geometry"]["coordinates"]
        assert len(seg.points) == feature["properties"]["points"] == len(coords)
        assert [[p.longitude, p.latitude] for p in seg.points] == coords
        want = _utc_of_rows(tmp_path, start, feature["properties"]["pipeline"])
        got = [p.time.timestamp() for p in seg.points]
        assert all(p.time.utcoffset().total_seconds() == 0 for p in seg.points)
        assert got == pytest.approx(want, abs=1e-3)
    t0, t1 = gpx.get_time_bounds()
    assert (t1 - t0).total_seconds() == pytest.approx(40.0, abs=0.2)  # the 40 s log


def test_gpx_of_a_log_without_utc_has_no_times_and_says_why(tmp_path):
    """The BlueBoat CSV is stamped in ms since the autopilot booted: the points have no
    time (rather than dates in 1970), and the description says so."""
    gpx, fc, s = _gpx_replay(BLUEBOAT_CSV, tmp_path, "--config", str(BLUEBOAT_CONFIG))
    assert s["utc"] == {"utc": False, "start": None, "source": s["utc"]["source"],
                        "start_s": None, "offsets": []}
    assert "no point times (no UTC: the CSV time column reads before 2000" in gpx.description
    points = [p for t in gpx.tracks for seg in t.segments for p in seg.points]
    assert points and all(p.time is None for p in points)
    assert len(gpx.tracks) == sum(f["properties"]["kind"] == "track" for f in fc["features"])


@pytest.mark.data
def test_gpx_of_a_real_nmea_capture_is_timed_by_its_rmc_dates(shared_data, tmp_path):
    """Shenzhen USV, 2024-12-05: the point times lie within the capture's first and last
    RMC date and time, as the sentences read them (parsed here on their own)."""
    log = shared_data / "usv_rtk_gnss_heading_nmea_shenzhen" / "202412051037.txt"
    gpx, _, s = _gpx_replay(log, tmp_path)
    stamps = rmc_times(log)
    t0, t1 = gpx.get_time_bounds()
    assert min(stamps) - 1.0 <= t0.timestamp() and t1.timestamp() <= max(stamps) + 1.0
    assert t1.timestamp() - t0.timestamp() > 0.9 * s["time_span"]["duration_s"]
