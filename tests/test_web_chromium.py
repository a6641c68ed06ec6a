"""The web page in a real browser: headless Chromium (Debian ``chromium``) loads the page
fed by a 120 s simulator replay, and its screenshot shows the track and the current's
arrow; served behind a reverse proxy under ``/extensionv2/onboard/`` (as BlueOS serves
extensions), every request the page makes goes through the prefix and succeeds.

Set ``ONBOARD_WEB_SCREENSHOT=docs/figures/web-page.png`` to keep the capture (the figure
of docs/service.md)."""

from __future__ import annotations

import asyncio
import math
import os
import re
import shutil
import struct
import zlib
from pathlib import Path

import msgspec
import pytest

from onboard.core.messages import EstimateRecord, HealthRecord
from onboard.service.web.app import routes
from onboard.service.web.view import LiveView
from onboard.service.web.config_edit import ConfigEditor
from onboard.service.web.http import HttpServer
from tests.helpers.web import (CHROMIUM_INSTALL, ServerThread, chromium, dump_dom, replay_view,
                               screenshot)

pytestmark = [pytest.mark.integration,
              pytest.mark.skipif(chromium() is None, reason=f"needs Chromium: {CHROMIUM_INSTALL}")]

TRACK_RGB = (0x1F, 0x6F, 0xD0)
ARROW_RGB = (0xE0, 0x30, 0x1E)
"""The page's track and current colours (static/page.js)."""
PREFIX = "/extensionv2/onboard"


@pytest.fixture(scope="module")
def view():
    return replay_view()  # effect-current, 120 s: current 0.29 m/s towards 329 deg


def pixels_near(img, rgb: tuple[int, int, int], tol: int = 12) -> int:
    """Pixels of ``img`` (H x W x 3|4, floats 0-1) within ``tol`` of ``rgb`` per channel."""
    import numpy as np

    a = (img[..., :3] * 255.0).round()
    return int(np.all(np.abs(a - np.array(rgb)) <= tol, axis=-1).sum())


@pytest.mark.parametrize("query", ["", "?widget=1"], ids=["page", "cockpit-widget"])
def test_the_page_shows_the_track_and_the_current_arrow(view, tmp_path, query):
    mpimg = pytest.importorskip("matplotlib.image", reason="pip install 'onboard[plot]'")
    out = tmp_path / "page.png"
    with ServerThread(view=view) as srv:
        run = screenshot(srv.url + "/" + query, out, tmp_path / "profile")
    assert run.returncode == 0 and out.exists(), run.stderr[-2000:]
    img = mpimg.imread(out)
    assert img.shape[:2] == (640, 1000)
    map_part = img[:, :700]  # the panel: the right-hand 290 px (the widget's: 190 px over the map)
    # measured on the 120 s replay: 2,380 track pixels, 142 arrow pixels (a blank map: 0)
    assert pixels_near(map_part, TRACK_RGB) > 800
    assert pixels_near(map_part, ARROW_RGB) > 60
    if os.environ.get("ONBOARD_WEB_SCREENSHOT") and not query:
        shutil.copyfile(out, os.environ["ONBOARD_WEB_SCREENSHOT"])


class LoopbackServer:
    """An asyncio TCP server on a free loopback port; each subclass answers a connection in
    its ``_client(reader, writer)``; ``port`` is known after :meth:`start`."""

    port = 0
    _server: asyncio.AbstractServer | None = None

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._client, "127.0.0.1", 0)
        self.port = self._server.sockets[0].getsockname()[1]

    async def close(self) -> None:
        assert self._server is not None
        self._server.close()
        await self._server.wait_closed()


class PrefixProxy(LoopbackServer):
    """A reverse proxy serving ``backend`` under ``prefix`` (strips it, forwards the
    request, relays the answer), logging each request's path and status; anything
    outside the prefix is answered 404."""

    def __init__(self, backend_port: int, prefix: str) -> None:
        self.backend_port = backend_port
        self.prefix = prefix
        self.log: list[tuple[str, int]] = []

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        head = await reader.readuntil(b"\r\n\r\n")
        method, target, rest = head.decode("latin-1").split(" ", 2)
        if not target.startswith(self.prefix + "/"):
            self.log.append((target, 404))
            writer.write(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n"
                         b"Connection: close\r\n\r\n")
        else:
            up_r, up_w = await asyncio.open_connection("127.0.0.1", self.backend_port)
            up_w.write(f"{method} {target[len(self.prefix):]} {rest}".encode("latin-1"))
            answer = await up_r.read()  # the backend closes after each answer
            up_w.close()
            self.log.append((target, int(answer.split(b" ", 2)[1])))
            writer.write(answer)
        await writer.drain()
        writer.close()


def test_behind_a_proxy_under_a_relative_path_every_request_of_the_page_succeeds(view, tmp_path):
    backend = HttpServer(routes(view, ConfigEditor(["sitl-jaiabot"], editable=False)),
                         "127.0.0.1", 0)
    with ServerThread(backend):
        proxy = PrefixProxy(backend.port, PREFIX)
        with ServerThread(proxy):
            dom = dump_dom(f"http://127.0.0.1:{proxy.port}{PREFIX}/", tmp_path / "profile")
    paths = [p for p, _ in proxy.log]
    assert all(status == 200 for _, status in proxy.log), proxy.log
    assert f"{PREFIX}/" in paths and f"{PREFIX}/page.js" in paths
    assert f"{PREFIX}/api/config" in paths
    polls = [p for p in paths if p.startswith(f"{PREFIX}/api/state?")]
    assert len(polls) >= 2, paths  # polled every second of the 4 s of virtual time
    speed = re.search(r'id="speed"[^>]*>([^<]*)<', dom)
    assert speed and re.fullmatch(r"\d+\.\d\d ± \d\.\d\d m/s", speed.group(1)), dom[:2000]


TILE_RGB = (0xB4, 0xE6, 0xC8)


def solid_png(rgb: tuple[int, int, int], size: int = 256) -> bytes:
    """A ``size`` x ``size`` PNG of one colour (8-bit RGB, no filter)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    raw = (b"\x00" + bytes(rgb) * size) * size
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", size, size, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


class TileServer(LoopbackServer):
    """Answers every ``/{z}/{x}/{y}.png`` with one solid tile and logs (z, x, y)."""

    def __init__(self) -> None:
        self.requested: list[tuple[int, int, int]] = []
        self._png = solid_png(TILE_RGB)

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        head = await reader.readuntil(b"\r\n\r\n")
        z, x, y = map(int, re.match(rb"GET /(\d+)/(-?\d+)/(-?\d+)\.png", head).groups())
        self.requested.append((z, x, y))
        writer.write(b"HTTP/1.1 200 OK\r\nContent-Type: image/png\r\nConnection: close\r\n"
                     + f"Content-Length: {len(self._png)}\r\n\r\n".encode() + self._png)
        await writer.drain()
        writer.close()


def tile_of(lat: float, lon: float, z: int) -> tuple[int, int]:
    """The Web Mercator tile holding (lat, lon) at zoom ``z`` (the OSM wiki's formula)."""
    n = 2 ** z
    phi = math.radians(lat)
    return (int((lon + 180.0) / 360.0 * n),
            int((1.0 - math.asinh(math.tan(phi)) / math.pi) / 2.0 * n))


def test_online_the_track_is_drawn_over_the_map_tiles_of_its_place(view, tmp_path):
    mpimg = pytest.importorskip("matplotlib.image", reason="pip install 'onboard[plot]'")
    tiles = TileServer()
    out = tmp_path / "tiles.png"
    with ServerThread(view=view) as srv, ServerThread(tiles):
        url = f"http://127.0.0.1:{tiles.port}/{{z}}/{{x}}/{{y}}.png"
        run = screenshot(f"{srv.url}/?tile_url={url}", out, tmp_path / "profile")
    assert run.returncode == 0, run.stderr[-2000:]
    map_part = mpimg.imread(out)[:, :700]
    # measured: the tiles cover 98 % of the map (the rest: track, arrow, labels)
    assert pixels_near(map_part, TILE_RGB, tol=3) > 0.8 * 640 * 700
    assert pixels_near(map_part, TRACK_RGB) > 800
    origin = view.state()["origin"]
    z = max(z for z, _, _ in tiles.requested)
    assert 15 <= z <= 19  # measured 19: a track of ~100 m on ~600 px, 0.2-0.3 m per pixel
    x0, y0 = tile_of(origin["lat_deg"], origin["lon_deg"], z)
    xs = {x for zz, x, _ in tiles.requested if zz == z}
    ys = {y for zz, _, y in tiles.requested if zz == z}
    assert x0 in xs and y0 in ys  # the first fix's tile is among those drawn


def injection(where: str) -> str:
    """Markup that, put into the page as HTML, runs a script naming ``where`` in the
    page's title (its image's source is missing: the error handler runs)."""
    return f"x<img src=x onerror=\"document.title='XSS {where}'\">"


def test_vehicle_ids_flags_and_events_from_zenoh_are_shown_as_text_never_run(tmp_path):
    """Any Zenoh publisher the shore hears writes the vehicle id, the flags and the
    events the page shows: they are text, and the markup in them does not run."""
    vid = injection("vehicle")
    view = LiveView()
    enc = msgspec.json.encode
    for t in (1.0, 2.0):
        view.feed_zenoh(f"onboard/{vid}/est/nav", enc(EstimateRecord(
            vehicle=vid, pipeline="nav", t=t, values={"north": t, "east": 0.0, "speed": 1.0})))
    view.feed_zenoh(f"onboard/{vid}/health", enc(HealthRecord(
        vehicle=vid, t=2.0, flags={"aie": [injection("flag")]}, events=[injection("event")])))
    with ServerThread(view=view) as srv:
        dom = dump_dom(srv.url + "/", tmp_path / "profile")
        widget = dump_dom(srv.url + "/?widget=1&vehicle=" + injection("query").replace(" ", "%20"),
                          tmp_path / "profile2")
    title = re.search(r"<title>.*?</title>", dom).group(0)
    assert title == "<title>onboard</title>", title
    assert "<img" not in dom
    status = re.search(r'id="status"[^>]*>(.*?)</div>', dom).group(1)
    name = "<b>x&lt;img src=x onerror=\"document.title='XSS vehicle'\"&gt;</b>"
    assert status.startswith(name), status
    assert "aie: x&lt;img" in dom and "<li>x&lt;img" in dom
    assert "<title>onboard</title>" in widget and "<img" not in widget


def test_a_heading_and_a_current_bearing_just_below_360_are_shown_as_0(tmp_path):
    view = LiveView()
    view.feed_estimates([
        EstimateRecord(vehicle="boat", pipeline="aie", t=1.0,
                       values={"north": 0.0, "east": 0.0, "speed": 1.0,
                               "heading": math.radians(359.97)},
                       std={"speed": 0.05, "heading": math.radians(0.2)}),
        EstimateRecord(vehicle="boat", pipeline="current", t=1.0,
                       values={"north": 0.3, "east": -0.002},
                       std={"north": 0.02, "east": 0.02})])
    with ServerThread(view=view) as srv:
        dom = dump_dom(srv.url + "/", tmp_path / "profile")
    heading = re.search(r'id="heading"[^>]*>([^<]*)<', dom).group(1)
    current = re.search(r'id="current"[^>]*>([^<]*)<', dom).group(1)
    assert heading == "0.0 ± 0.2 °" and current == "0.30 m/s → 0°", (heading, current)


def test_a_single_vehicle_page_without_a_fleet_service_shows_no_fleet_box(view, tmp_path):
    """The page's first api/fleet poll leaves before it knows its vehicle: that vehicle is
    not 'one vehicle more', and the box stays hidden while there is nothing to tell."""
    assert view.fleet()["vehicles"] == []
    with ServerThread(view=view) as srv:
        dom = dump_dom(srv.url + "/", tmp_path / "profile")
    box = re.search(r'<div id="fleet-box"[^>]*>', dom).group(0)
    assert "hidden" in box, re.search(r'id="fleet-box".*?</div></div>', dom, re.S).group(0)
