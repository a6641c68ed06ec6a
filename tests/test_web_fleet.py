"""The web page's fleet layer: the fleet service's grid (``<prefix>/fleet/current/grid``,
``onboard.FleetGrid.v1``) fed to the page's model as the shore receives it, served on
``api/fleet``, and drawn by headless Chromium as arrows where the field is known and
nothing where it is null, with the vehicles' tracks and their own estimates.

Set ``ONBOARD_FLEET_SCREENSHOT=docs/figures/web-fleet.png`` to keep the capture."""

from __future__ import annotations

import json
import os
import re
import shutil
import urllib.request

import pytest

from onboard.service.web.view import LiveView
from tests.helpers.web import CHROMIUM_INSTALL, ServerThread, chromium, dump_dom, screenshot

FLEET_RGB = (0x7B, 0x1F, 0xA2)
FLEET_TRACK_RGB = (0x2E, 0x7D, 0x32)
FLEET_VEHICLE_RGB = (0xEF, 0x6C, 0x00)
"""The fleet layer's colours (static/page.js)."""
GRID_KEY = "onboard/fleet/current/grid"
LAT0, LON0, SPACING_M = 43.0, 5.0, 200.0
COLS = ROWS = 6
KNOWN_COLS = 3
"""The west half of the grid knows the field (0.3 m/s towards north), the east half not."""


def synthetic_grid(utc: float, *, known_cols: int = KNOWN_COLS, unplaced: bool = False,
                   lon0: float = LON0) -> dict:
    """A 6 x 6 grid of 200 m cells about (43 N, 5 E): the first ``known_cols`` columns
    (west) known, the rest null; two vehicles moving north in the west half (and with
    ``unplaced`` a third whose records carry no position: an AUV before any fix)."""
    m_lat, m_lon = 111132.95, 111319.49 * 0.7313537  # cos(43 deg)
    cells = []
    for i in range(ROWS):
        for j in range(COLS):
            lat = LAT0 + (i - (ROWS - 1) / 2) * SPACING_M / m_lat
            lon = wrap(lon0 + (j - (COLS - 1) / 2) * SPACING_M / m_lon)
            known = j < known_cols
            std = 0.01 if i % 2 == 0 else 0.2  # every other row uncertain: drawn faded
            cells.append({"lat": lat, "lon": lon, "utc": utc,
                          "north": 0.3 if known else None, "east": 0.0 if known else None,
                          "std_north": std if known else None, "std_east": std if known else None,
                          "n_obs": 12 if known else 0})
    vehicles = [{"vehicle": f"bot{k}", "utc": utc,
                 "lat": LAT0 + ((utc - 1000.0) * 4.0 - 450.0) / m_lat,
                 "lon": wrap(lon0 - (250.0 + 150.0 * k) / m_lon),
                 "north": 0.28, "east": 0.02, "std_north": 0.03, "std_east": 0.03}
                for k in range(2)]
    if unplaced:
        vehicles.append({"vehicle": "auv", "utc": utc, "lat": None, "lon": None,
                         "north": 0.25, "east": 0.05, "std_north": 0.04, "std_east": 0.04})
    return {"schema": 1, "utc": utc, "spacing_m": SPACING_M, "cells": cells, "vehicles": vehicles}


def wrap(lon: float) -> float:
    """A longitude within [-180, 180), as a GNSS gives it."""
    return (lon + 180.0) % 360.0 - 180.0


def fleet_view(known_cols: int = KNOWN_COLS, n: int = 12, unplaced: bool = False,
               lon0: float = LON0) -> LiveView:
    """A LiveView fed ``n`` grids 5 s apart on the grid's key, as the shore receives them."""
    view = LiveView()
    for k in range(n):
        view.feed_zenoh(GRID_KEY, json.dumps(synthetic_grid(
            1000.0 + 5.0 * k, known_cols=known_cols, unplaced=unplaced, lon0=lon0)).encode())
    return view


def test_the_newest_grid_is_kept_and_each_vehicle_leaves_a_track():
    view = fleet_view()
    view.feed_zenoh(GRID_KEY, json.dumps(synthetic_grid(1020.0)).encode())  # late: ignored
    view.feed_zenoh(GRID_KEY, b"[1, 2]")  # not a grid: counted
    assert view.bad == 1
    f = view.fleet()
    assert f["grid"]["utc"] == 1055.0 and len(f["grid"]["cells"]) == 36
    assert sorted(f["tracks"]) == ["bot0", "bot1"] and len(f["tracks"]["bot0"]) == 12
    assert view.fleet(since=1055.0)["grid"] is None  # nothing newer than what the page has
    assert view.vehicles == {}  # the grid is no vehicle


def test_api_fleet_serves_the_grid_with_its_null_cells_as_null():
    with ServerThread(view=fleet_view()) as srv:
        with urllib.request.urlopen(srv.url + "/api/fleet?since=0") as r:
            f = json.load(r)
    unknown = [c for c in f["grid"]["cells"] if c["north"] is None]
    assert len(unknown) == ROWS * (COLS - KNOWN_COLS)
    assert all(c["east"] is None and c["n_obs"] == 0 for c in unknown)


def pixels_near(img, rgb: tuple[int, int, int], tol: int = 12) -> int:
    import numpy as np

    a = (img[..., :3] * 255.0).round()
    return int(np.all(np.abs(a - np.array(rgb)) <= tol, axis=-1).sum())


def purple_tinted(img) -> int:
    """Pixels with any tint of the field's purple, however faded over the light map: red
    and blue both above green (the map, its grid and labels are grey-blue, the vehicles'
    colours orange and red, the track blue: none is)."""
    import numpy as np

    a = (img[..., :3] * 255.0).round()
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    return int(np.sum((r > g + 8) & (b > g + 8)))


@pytest.mark.integration
@pytest.mark.skipif(chromium() is None, reason=f"needs Chromium: {CHROMIUM_INSTALL}")
def test_the_page_draws_arrows_where_the_field_is_known_and_nothing_where_it_is_null(tmp_path):
    mpimg = pytest.importorskip("matplotlib.image", reason="pip install 'onboard[plot]'")
    out = tmp_path / "fleet.png"
    with ServerThread(view=fleet_view()) as srv:
        run = screenshot(srv.url + "/?tiles=0", out, tmp_path / "profile")
    assert run.returncode == 0 and out.exists(), run.stderr[-2000:]
    img = mpimg.imread(out)
    # the map is the left 710 px; the grid is centred on it, its west half left of x = 355;
    # the top 40 px hold the legends
    west, east = img[40:, :345], img[40:, 365:700]
    # measured: 459 opaque arrow pixels in the west half (9 opaque arrows, 9 faded
    # ones, which are not counted), the tracks 120, the vehicles' own estimates 221
    assert pixels_near(west, FLEET_RGB) > 300
    assert pixels_near(west, FLEET_TRACK_RGB) > 60  # the two vehicles' tracks
    assert pixels_near(west, FLEET_VEHICLE_RGB) > 100  # their own estimates
    assert purple_tinted(west) > 1000  # measured 1,742: the faded arrows too
    assert purple_tinted(east) == 0  # the null cells: nothing, not even faded
    if os.environ.get("ONBOARD_FLEET_SCREENSHOT"):
        shutil.copyfile(out, os.environ["ONBOARD_FLEET_SCREENSHOT"])


@pytest.mark.integration
@pytest.mark.skipif(chromium() is None, reason=f"needs Chromium: {CHROMIUM_INSTALL}")
def test_a_grid_across_the_antimeridian_is_drawn_as_anywhere_else(tmp_path):
    """The same grid with its middle column on 180 deg (its east cells at -179.99): the
    page draws it as at 5 E (its centre was the mean longitude, about 0, and the cells
    past the antimeridian 40 000 km west of the others: every arrow off the map)."""
    mpimg = pytest.importorskip("matplotlib.image", reason="pip install 'onboard[plot]'")
    out = tmp_path / "fleet.png"
    with ServerThread(view=fleet_view(lon0=179.999)) as srv:
        run = screenshot(srv.url + "/?tiles=0", out, tmp_path / "profile")
    assert run.returncode == 0 and out.exists(), run.stderr[-2000:]
    img = mpimg.imread(out)
    west, east = img[40:, :345], img[40:, 365:700]
    assert pixels_near(west, FLEET_RGB) > 300
    assert pixels_near(west, FLEET_TRACK_RGB) > 60
    assert purple_tinted(east) == 0


@pytest.mark.integration
@pytest.mark.skipif(chromium() is None, reason=f"needs Chromium: {CHROMIUM_INSTALL}")
def test_a_long_vehicle_id_is_cut_on_the_map(tmp_path):
    """A vehicle id of 300 characters (any id a key can carry) is drawn as a label of 16:
    the whole id ran across the map over the east half's cells."""
    mpimg = pytest.importorskip("matplotlib.image", reason="pip install 'onboard[plot]'")
    view = LiveView()
    for k in range(12):
        grid = synthetic_grid(1000.0 + 5.0 * k)
        grid["vehicles"][0]["vehicle"] = "x" * 300
        view.feed_zenoh(GRID_KEY, json.dumps(grid).encode())
    out = tmp_path / "fleet.png"
    with ServerThread(view=view) as srv:
        run = screenshot(srv.url + "/?tiles=0", out, tmp_path / "profile")
    assert run.returncode == 0 and out.exists(), run.stderr[-2000:]
    img = mpimg.imread(out)
    assert pixels_near(img[40:, :345], FLEET_VEHICLE_RGB) > 100   # the vehicles, labelled
    assert pixels_near(img[40:, 365:700], FLEET_VEHICLE_RGB, tol=40) == 0


@pytest.mark.integration
@pytest.mark.skipif(chromium() is None, reason=f"needs Chromium: {CHROMIUM_INSTALL}")
def test_a_vehicle_without_a_position_is_counted_not_drawn_at_0_0(tmp_path):
    """An AUV that never had a fix is listed in the grid without a position: the panel
    names it, and the map keeps the fleet's extent (drawn at lat 0, lon 0, it put the
    fleet 5,000 km away and every arrow under a pixel)."""
    mpimg = pytest.importorskip("matplotlib.image", reason="pip install 'onboard[plot]'")
    out = tmp_path / "fleet.png"
    with ServerThread(view=fleet_view(unplaced=True)) as srv:
        dom = dump_dom(srv.url + "/?tiles=0", tmp_path / "profile")
        run = screenshot(srv.url + "/?tiles=0", out, tmp_path / "profile2")
    text = re.search(r'id="fleet"[^>]*>([^<]*)<', dom)
    assert text and "3 vehicles (auv without a position) · 200 m cells" in text.group(1), \
        dom[:2000]
    assert run.returncode == 0 and out.exists(), run.stderr[-2000:]
    img = mpimg.imread(out)
    assert pixels_near(img[40:, :345], FLEET_RGB) > 300  # the arrows as without it


@pytest.mark.integration
@pytest.mark.skipif(chromium() is None, reason=f"needs Chromium: {CHROMIUM_INSTALL}")
def test_the_panel_counts_the_known_and_unknown_cells(tmp_path):
    with ServerThread(view=fleet_view()) as srv:
        dom = dump_dom(srv.url + "/?tiles=0", tmp_path / "profile")
    text = re.search(r'id="fleet"[^>]*>([^<]*)<', dom)
    assert text, dom[:2000]
    assert text.group(1).startswith("18 cells known · 18 unknown · 2 vehicles · 200 m cells")
    # a page without a vehicle yet keeps polling: it waits, with no HTTP error
    assert re.search(r'id="status"[^>]*>waiting for a vehicle', dom), dom[:2000]


@pytest.mark.integration
def test_onboard_shore_web_for_one_vehicle_still_hears_the_fleet_grid():
    import subprocess
    import sys
    import time

    import zenoh

    from onboard.apps.service_bench import free_tcp_port
    from onboard.service.publishers.zenoh_pub import open_router, session_config

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    web_port = free_tcp_port()
    router = open_router(endpoint)
    pub = zenoh.open(session_config("client", [endpoint]))
    # --vehicle: onboard/shoreboat/** does not match the grid's key; its own subscription does
    shore = subprocess.Popen([sys.executable, "-m", "onboard", "shore", "--connect", endpoint,
                              "--vehicle", "shoreboat", "--web", f"127.0.0.1:{web_port}"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert "the page is on" in shore.stdout.readline()
        grid: dict | None = None
        deadline = time.monotonic() + 15
        k = 0
        while grid is None:
            assert time.monotonic() < deadline
            k += 1
            pub.put(GRID_KEY, json.dumps(synthetic_grid(1000.0 + k)).encode(),
                    encoding="application/json;onboard.FleetGrid.v1")
            time.sleep(0.2)
            with urllib.request.urlopen(f"http://127.0.0.1:{web_port}/api/fleet") as r:
                grid = json.load(r)["grid"]
        assert len(grid["cells"]) == ROWS * COLS and grid["spacing_m"] == SPACING_M
    finally:
        shore.terminate()
        shore.wait(10)
        pub.close()
        router.close()


def two_vehicle_view() -> LiveView:
    """Two vehicles followed by the view itself (their own estimates, no fleet service):
    ``alpha`` going north, ``beta`` going east 300 m away, both in a 0.2 m/s current."""
    from onboard.core.messages import EstimateRecord

    origins = {"alpha": (LAT0, LON0), "beta": (LAT0, LON0 + 0.004)}
    view = LiveView(origin=lambda _p: None)
    for k in range(60):
        t = float(k)
        for vid, (n, e) in (("alpha", (2.0 * t, 0.0)), ("beta", (0.0, 2.0 * t))):
            view.feed_estimates([
                EstimateRecord(vehicle=vid, pipeline="nav", t=t, values={"north": n, "east": e}),
                EstimateRecord(vehicle=vid, pipeline="current", t=t,
                               values={"north": 0.0, "east": 0.2},
                               std={"north": 0.02, "east": 0.02})])
    for vid, o in origins.items():
        view.vehicles[vid].origin = o
    return view


def test_without_a_fleet_service_the_other_vehicles_are_the_fleet_layer():
    f = two_vehicle_view().fleet(shown="alpha")
    assert f["grid"] is None
    (beta,) = f["vehicles"]  # alpha is the page's own layer
    assert beta["vehicle"] == "beta" and beta["east"] == 0.2 and beta["std_north"] == 0.02
    assert beta["lat"] == pytest.approx(LAT0) and beta["lon"] > LON0 + 0.004
    assert len(f["tracks"]["beta"]) == 12  # one point per 5 s of its 60 s
    # without the page's vehicle named, the one api/state shows by default (the first)
    assert [v["vehicle"] for v in two_vehicle_view().fleet(shown="")["vehicles"]] == ["beta"]


@pytest.mark.integration
@pytest.mark.skipif(chromium() is None, reason=f"needs Chromium: {CHROMIUM_INSTALL}")
def test_the_page_draws_the_other_vehicles_track_and_current(tmp_path):
    mpimg = pytest.importorskip("matplotlib.image", reason="pip install 'onboard[plot]'")
    out = tmp_path / "two.png"
    with ServerThread(view=two_vehicle_view()) as srv:
        run = screenshot(srv.url + "/?tiles=0&vehicle=alpha", out, tmp_path / "profile")
    assert run.returncode == 0 and out.exists(), run.stderr[-2000:]
    map_part = mpimg.imread(out)[:, :700]
    # measured: beta's dashed track 56 px, its dot, arrow and label 91 px; a blank page: 0
    assert pixels_near(map_part, FLEET_TRACK_RGB) > 30
    assert pixels_near(map_part, FLEET_VEHICLE_RGB) > 45
    assert pixels_near(map_part, FLEET_RGB) == 0  # no grid: no field
