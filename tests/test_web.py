"""The web page's model, server, BlueOS discovery and configuration editing
(onboard/service/web; docs/service.md, "Web page"). The page in a browser:
tests/test_web_chromium.py."""

from __future__ import annotations

import asyncio
import json
import math
import socket
import time
import urllib.error
import urllib.request
from pathlib import Path

import msgspec
import pytest

from onboard.core.config import Config, ConfigError, from_dict
from onboard.core.messages import EstimateRecord, HealthRecord
from onboard.drivers.nmea import encode_gga, encode_hdt, encode_rmc
from onboard.service.daemon import Service, check_config
from onboard.service.web.app import cockpit_extras, parse_listen, register_service, routes
from onboard.service.web.config_edit import ConfigEditor
from onboard.service.web.http import HttpServer, Request, parse_head
from onboard.service.web.view import TRACK_PERIOD_S, LiveView
from onboard.apps.service_bench import free_udp_port
from tests.helpers.web import ServerThread

LAT0, LON0 = 43.0, 5.0
TIMEOUT = 30.0


def rec(pipeline: str, t: float, vehicle: str = "boat", **values: float) -> EstimateRecord:
    std = {k[4:]: v for k, v in values.items() if k.startswith("std_")}
    return EstimateRecord(vehicle=vehicle, pipeline=pipeline, t=t, values=values, std=std)


def fed_view() -> LiveView:
    """30 s of a boat going east at 1 m/s in a 0.3 m/s northward current."""
    view = LiveView(origin=lambda name: (LAT0, LON0) if name == "nav" else None)
    for k in range(301):
        t = 0.1 * k
        view.feed_estimates([rec("nav", t, north=0.0, east=t),
                             rec("aie", t, north=0.0, east=t, speed=1.0, std_speed=0.05,
                                 heading=math.pi / 2, std_heading=0.02),
                             rec("current", t, north=0.3, east=0.0, std_north=0.05,
                                 std_east=0.1)])
    view.feed_health(HealthRecord(vehicle="boat", t=30.0, mode="surface",
                                  flags={"aie": ["heading_vs_course"], "kf": []},
                                  events=["gnss: stale"], rejected={"a": 2, "b": 1}))
    return view


def test_the_view_keeps_one_track_point_a_second_and_the_newest_values_in_display_units():
    s = fed_view().state()
    pts = s["track"]["points"]
    assert s["vehicle"] == "boat" and s["track"]["pipeline"] == "nav"
    assert len(pts) == 31 and pts[1][0] - pts[0][0] == pytest.approx(TRACK_PERIOD_S)
    assert s["origin"] == {"lat_deg": LAT0, "lon_deg": LON0}
    assert s["position"]["east_m"] == pytest.approx(30.0)
    assert s["speed"] == {"value": 1.0, "std": 0.05, "pipeline": "aie"}
    assert s["heading"]["value"] == pytest.approx(90.0)
    assert s["heading"]["std"] == pytest.approx(math.degrees(0.02))
    cur = s["current"]
    assert cur["known"] and cur["speed_mps"] == pytest.approx(0.3)
    assert cur["towards_deg"] == pytest.approx(0.0) and cur["std_east_mps"] == 0.1
    h = s["health"]
    assert h["flags"] == {"aie": ["heading_vs_course"]}  # pipelines without flags left out
    assert h["rejected"] == 3 and h["events"] == ["gnss: stale"]


def test_a_speed_whose_sigma_says_nothing_gives_way_to_the_next_pipelines():
    """An AUV under water (the fleet demo's): its aie speed withheld, its kf speed dead
    reckoned to 1.25 +- 10.62 m/s; the measured speed is shown. A kf sigma of 0.2 is
    shown; when every pipeline's says nothing, the best one's is."""
    view = LiveView()
    view.feed_estimates([rec("kf", 1.0, vehicle="auv", speed=1.25, std_speed=10.62,
                             heading=1.0, std_heading=0.01),
                         rec("nav", 1.0, vehicle="auv", speed=1.5, heading=1.02)])
    s = view.state("auv")
    assert s["speed"] == {"value": 1.5, "std": None, "pipeline": "nav"}
    assert s["heading"]["pipeline"] == "kf"
    view.feed_estimates([rec("kf", 2.0, vehicle="auv", speed=1.25, std_speed=0.2)])
    assert view.state("auv")["speed"]["pipeline"] == "kf"
    lone = LiveView()
    lone.feed_estimates([rec("kf", 1.0, vehicle="auv", speed=1.25, std_speed=10.62)])
    assert lone.state("auv")["speed"] == {"value": 1.25, "std": 10.62, "pipeline": "kf"}


def test_the_view_sends_only_newer_points_unless_the_track_started_again():
    view = fed_view()
    first = view.state()
    newer = view.state(since=first["track"]["points"][-3][0], epoch=first["epoch"])
    assert len(newer["track"]["points"]) == 2
    view.feed_estimates([rec("nav", 1.0, north=5.0, east=5.0)])  # time went back: a restart
    again = view.state(since=30.0, epoch=first["epoch"])
    assert again["epoch"] != first["epoch"] and again["track"]["points"] == [[1.0, 5.0, 5.0]]


def test_an_unknown_current_component_is_null_with_its_sigma():
    view = LiveView()
    view.feed_estimates([rec("current", 1.0, std_north=0.4, std_east=0.2)])
    cur = view.state()["current"]
    assert cur["known"] is False and cur["north_mps"] is None and cur["std_north_mps"] == 0.4


def test_the_shore_view_decodes_zenoh_json_by_key_and_takes_the_origin_from_a_location_fix():
    view = LiveView()
    enc = msgspec.json.encode
    view.feed_zenoh("onboard/boat/est/nav", enc(rec("nav", 1.0, north=100.0, east=-50.0)))
    view.feed_zenoh("onboard/boat/health", enc(HealthRecord(vehicle="boat", t=1.0)))
    view.feed_zenoh("onboard/boat/est/nav", b"not json")  # counted, skipped
    view.feed_zenoh("onboard/boat/est/nav/x", b"{}")  # another key shape: not an estimate
    fix = {"timestamp": {"sec": 1, "nsec": 0}, "frame_id": "nav", "latitude": 43.001,
           "longitude": 5.0, "altitude": 0.0}
    view.feed_zenoh("onboard/boat/fix/nav", json.dumps(fix).encode())
    s = view.state()
    assert view.bad == 1 and s["health"] is not None
    # 100 m north of the origin at 43 deg: 100 / 111,132 m per degree = 0.0009 deg
    assert s["origin"]["lat_deg"] == pytest.approx(43.001 - 100.0 / 111132.0, abs=2e-6)
    assert s["origin"]["lon_deg"] == pytest.approx(5.0 + 50.0 / 81540.0, abs=2e-6)


def test_a_record_naming_another_vehicle_than_its_key_is_left_out():
    """A router's access control vouches for the key, not for the payload: the page and
    the shore's table take a record only on its own vehicle's key (as onboard fleet)."""
    from onboard.apps.shore import ShoreView

    enc = msgspec.json.encode
    view, table = LiveView(), ShoreView()
    for feed in (view.feed_zenoh, table.feed):
        feed("onboard/boat9/est/nav", enc(rec("nav", 1.0, vehicle="boat1", north=1.0, east=2.0)))
        feed("onboard/boat9/health", enc(HealthRecord(vehicle="boat1", t=1.0)))
    assert view.vehicles == {} and view.vehicle_mismatch == 2
    assert table.vehicles() == [] and table.vehicle_mismatch == 2
    for feed in (view.feed_zenoh, table.feed):
        feed("onboard/boat9/est/nav", enc(rec("nav", 2.0, vehicle="boat9", north=1.0, east=2.0)))
        feed("onboard/boat9/health", enc(HealthRecord(vehicle="boat9", t=2.0)))
    assert view.state()["vehicle"] == "boat9" and view.state()["health"] is not None
    assert table.vehicles() == ["boat9"] and table.health["boat9"].t == 2.0


def test_blueos_metadata_has_every_field_the_helper_reads_and_points_at_the_cockpit_widget():
    meta = register_service()
    for key in ("name", "description", "icon", "company", "version", "webpage", "api"):
        assert isinstance(meta[key], str), key
    assert meta["works_in_relative_paths"] is True
    extras = cockpit_extras()
    assert meta["extras"]["cockpit"] == "/cockpit_extras.json"
    assert extras["target_system"] == "Cockpit"
    (widget,) = extras["widgets"]
    # Cockpit prefixes these with the service's base URL (no trailing slash)
    assert widget["iframe_url"].startswith("/") and widget["iframe_icon"] == "/icon.svg"


def test_request_heads_are_parsed_and_bad_ones_refused():
    req = parse_head(b"GET /api/state?since=1.5&epoch=2 HTTP/1.1\r\nHost: x\r\nAccept: */*")
    assert (req.method, req.path) == ("GET", "/api/state")
    assert req.query == {"since": "1.5", "epoch": "2"}
    assert req.headers["host"] == "x"
    with pytest.raises(Exception, match="malformed"):
        parse_head(b"GARBAGE")
    srv = HttpServer(routes(LiveView()), "127.0.0.1", 0)
    assert srv.dispatch(Request("GET", "/nope")).status == 404
    assert srv.dispatch(Request("POST", "/api/state")).status == 405
    assert srv.dispatch(Request("GET", "/api/state", {"since": "x"})).status == 400


@pytest.mark.parametrize("listen, expected", [("0.0.0.0:8110", ("0.0.0.0", 8110)),
                                              ("[::1]:80", ("::1", 80)), (":9", ("0.0.0.0", 9))])
def test_listen_addresses(listen, expected):
    assert parse_listen(listen) == expected


def test_a_bad_listen_address_is_a_config_error_naming_the_key():
    cfg = from_dict({"service": {"sources": [{"kind": "nmea", "url": "udp:0.0.0.0:1"}],
                                 "web": {"listen": "8110"}}})
    with pytest.raises(ConfigError, match=r"service\.web\.listen"):
        check_config(cfg, "x.toml")


def get(url: str) -> tuple[int, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=5) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as err:
        return err.code, err.read()


def post(url: str, obj: object) -> tuple[int, dict]:
    req = urllib.request.Request(url, json.dumps(obj).encode(), method="POST",
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=5) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


@pytest.mark.integration
def test_the_server_answers_blueos_discovery_and_the_api_over_http():
    with ServerThread(view=fed_view()) as srv:
        status, body = get(srv.url + "/")
        assert status == 200 and b"<title>onboard</title>" in body
        assert b'src="page.js"' in body and b'src="/' not in body  # relative URLs only
        status, body = get(srv.url + "/register_service")
        assert status == 200 and json.loads(body)["works_in_relative_paths"] is True
        assert json.loads(get(srv.url + "/cockpit_extras.json")[1])["widgets"]
        state = json.loads(get(srv.url + "/api/state?since=-1e300&epoch=-1")[1])
        assert len(state["track"]["points"]) == 31
        assert get(srv.url + "/page.js")[0] == 200 and get(srv.url + "/icon.svg")[0] == 200
        assert get(srv.url + "/api/config")[0] == 404  # the shore has no configuration
        with socket.create_connection(("127.0.0.1", srv.server.port)) as s:
            s.sendall(b"BROKEN\r\n\r\n")
            assert s.recv(100).startswith(b"HTTP/1.1 400")


DEPLOY = """[vehicle]
id = "webboat"
class = "rudder-boat"

[[service.sources]]
kind = "nmea"
url = "udp:127.0.0.1:{port}"
"""


def test_the_config_editor_checks_a_new_text_as_the_service_would_and_keeps_the_old_one(tmp_path):
    path = tmp_path / "deploy.toml"
    path.write_text(DEPLOY.format(port=1))
    editor = ConfigEditor([path], editable=True)
    shown = editor.show()
    assert shown["target"] == str(path) and shown["effective"]["vehicle"]["id"] == "webboat"
    bad_key = DEPLOY.format(port=1) + "\n[service.web]\nlisen = \"0.0.0.0:1\"\n"
    (err,) = editor.save(bad_key)
    assert str(path) in err and "service.web.lisen" in err  # the file and the dotted key
    (err,) = editor.check(DEPLOY.format(port=1).replace("udp:", "carrier-pigeon:"))
    assert "service.sources[0].url" in err
    assert editor.check("[vehicle\n") and path.read_text() == DEPLOY.format(port=1)
    new = DEPLOY.format(port=2)
    assert editor.save(new) == []
    assert path.read_text() == new
    assert (tmp_path / "deploy.toml.bak").read_text() == DEPLOY.format(port=1)
    assert ConfigEditor([path], editable=False).save(new) == [
        "editing is off: set service.web.edit_config = true"]


def web_config(port: int, edit: bool) -> Config:
    return from_dict({"vehicle": {"id": "webboat", "class": "rudder-boat"},
                      "service": {"sources": [{"kind": "nmea", "url": f"udp:127.0.0.1:{port}"}],
                                  "zenoh": {"enabled": False}, "mavlink": {"enabled": False},
                                  "recorder": {"enabled": False},
                                  "web": {"listen": "127.0.0.1:0", "edit_config": edit}}})


@pytest.mark.integration
def test_the_service_serves_its_own_track_and_lets_the_page_edit_its_config(tmp_path):
    port = free_udp_port()
    path = tmp_path / "deploy.toml"
    path.write_text(DEPLOY.format(port=port))
    cfg = web_config(port, edit=True)

    async def main() -> tuple[dict, tuple, tuple]:
        svc = Service(cfg, state_dir=tmp_path, config_paths=[path])
        await svc.start()
        base = f"http://127.0.0.1:{svc.web.port}"
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        t_utc = time.time()
        for k in range(25):  # 2.5 s going north at 2 m/s
            lat = LAT0 + 2.0 * 0.1 * k / 111132.0
            for line in (encode_gga(t_utc + 0.1 * k, lat, LON0),
                         encode_rmc(t_utc + 0.1 * k, lat, LON0, 2.0, 0.0), encode_hdt(0.0)):
                sock.sendto(line, ("127.0.0.1", port))
            await asyncio.sleep(0.1)
        sock.close()
        loop = asyncio.get_running_loop()
        state = json.loads((await loop.run_in_executor(None, get, base + "/api/state"))[1])
        bad = await loop.run_in_executor(None, post, base + "/api/config", {"text": "[x]\ny = 1\n"})
        good = await loop.run_in_executor(
            None, post, base + "/api/config", {"text": DEPLOY.format(port=port) + "# edited\n"})
        svc.request_stop()
        await svc.shutdown()
        return state, bad, good

    state, bad, good = asyncio.run(asyncio.wait_for(main(), TIMEOUT))
    assert state["vehicle"] == "webboat" and state["track"]["pipeline"] == "nav"
    assert len(state["track"]["points"]) >= 2  # one a second of ~2.5 s
    assert state["origin"]["lat_deg"] == pytest.approx(LAT0, abs=1e-4)
    assert state["speed"]["value"] == pytest.approx(2.0, abs=0.1)  # AIE after 2.5 s: 1.986
    assert bad[0] == 422 and "unknown" in bad[1]["errors"][0]
    assert good == (200, {"errors": [], "saved": True, "target": str(path)})
    assert path.read_text().endswith("# edited\n")


@pytest.mark.integration
def test_onboard_shore_web_serves_the_page_from_zenoh_whatever_the_encodings_schema(tmp_path):
    import subprocess
    import sys

    import zenoh

    from onboard.service.publishers.zenoh_pub import open_router, session_config
    from onboard.apps.service_bench import free_tcp_port

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    web_port = free_tcp_port()
    router = open_router(endpoint)
    pub = zenoh.open(session_config("client", [endpoint]))
    shore = subprocess.Popen([sys.executable, "-m", "onboard", "shore", "--connect", endpoint,
                              "--web", f"127.0.0.1:{web_port}"], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        assert "the page is on" in shore.stdout.readline()
        state: dict = {}
        deadline = time.monotonic() + 15
        k = 0
        while not (state.get("origin") and len(state.get("track", {}).get("points", [])) > 2):
            assert time.monotonic() < deadline, state
            k += 1
            est = rec("nav", float(k), vehicle="shoreboat", north=float(k), east=0.0)
            pub.put("onboard/shoreboat/est/nav", msgspec.json.encode(est),
                    encoding="application/json;onboard.Estimate.v1")
            fix = {"timestamp": {"sec": k, "nsec": 0}, "frame_id": "nav",
                   "latitude": LAT0 + k / 111132.0, "longitude": LON0}
            pub.put("onboard/shoreboat/fix/nav", json.dumps(fix).encode(),
                    encoding="application/json;foxglove.LocationFix")
            time.sleep(0.2)
            state = json.loads(get(f"http://127.0.0.1:{web_port}/api/state")[1])
        assert state["vehicle"] == "shoreboat"
        assert state["origin"]["lat_deg"] == pytest.approx(LAT0, abs=1e-6)
    finally:
        shore.terminate()
        shore.wait(10)
        pub.close()
        router.close()


@pytest.mark.integration
def test_idle_connections_beyond_the_limit_are_closed_and_the_page_still_answers_after():
    from onboard.service.web.http import MAX_CLIENTS

    with ServerThread(view=LiveView()) as srv:
        addr = ("127.0.0.1", srv.server.port)
        idle = [socket.create_connection(addr) for _ in range(MAX_CLIENTS)]
        time.sleep(0.2)
        with socket.create_connection(("127.0.0.1", srv.server.port)) as extra:
            extra.sendall(b"GET / HTTP/1.1\r\n\r\n")
            extra.settimeout(5)
            try:
                answer = extra.recv(100)
            except ConnectionResetError:  # closed with the request unread
                answer = b""
            assert answer == b""  # closed unanswered
        for s in idle:
            s.close()
        time.sleep(0.2)
        assert get(srv.url + "/")[0] == 200 and srv.server.refused == 1


def test_views_with_a_key_prefix_read_its_keys_only_whatever_its_segments():
    from onboard.apps.shore import ShoreView

    enc = msgspec.json.encode
    view, table = LiveView(prefix="region/north"), ShoreView(prefix="region/north")
    for feed in (view.feed_zenoh, table.feed):
        feed("region/north/boat2/est/nav",
             enc(rec("nav", 1.0, vehicle="boat2", north=1.0, east=2.0)))
        feed("onboard/boat3/est/nav", enc(rec("nav", 1.0, vehicle="boat3", north=1.0, east=2.0)))
    assert sorted(view.vehicles) == ["boat2"] and table.vehicles() == ["boat2"]
    assert view.vehicle_mismatch == 0 and table.vehicle_mismatch == 0


@pytest.mark.integration
def test_onboard_shore_prefix_follows_the_vehicles_and_the_fleet_grid_under_it(tmp_path):
    import subprocess
    import sys

    import zenoh

    from onboard.service.publishers.zenoh_pub import open_router, session_config
    from onboard.apps.service_bench import free_tcp_port

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    web_port = free_tcp_port()
    router = open_router(endpoint)
    pub = zenoh.open(session_config("client", [endpoint]))
    shore = subprocess.Popen([sys.executable, "-m", "onboard", "shore", "--connect", endpoint,
                              "--prefix", "region-a", "--web", f"127.0.0.1:{web_port}"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    grid = {"schema": 1, "utc": 1.0e9, "spacing_m": 100.0, "vehicles": [],
            "cells": [{"lat": LAT0, "lon": LON0, "north": 0.1, "east": 0.0,
                       "std_north": 0.01, "std_east": 0.01, "n_obs": 3}]}
    try:
        assert "the page is on" in shore.stdout.readline()
        state: dict = {}
        fleet: dict = {}
        deadline = time.monotonic() + 15
        k = 0
        while not (state.get("t") and fleet.get("grid")):
            assert time.monotonic() < deadline, (state, fleet)
            k += 1
            for prefix, vid in (("region-a", "boat-a"), ("onboard", "boat-o")):
                est = rec("nav", float(k), vehicle=vid, north=float(k), east=0.0)
                pub.put(f"{prefix}/{vid}/est/nav", msgspec.json.encode(est),
                        encoding="application/json;onboard.Estimate.v2")
            pub.put("region-a/fleet/current/grid", json.dumps(grid).encode(),
                    encoding="application/json;onboard.FleetGrid.v1")
            time.sleep(0.2)
            state = json.loads(get(f"http://127.0.0.1:{web_port}/api/state")[1])
            fleet = json.loads(get(f"http://127.0.0.1:{web_port}/api/fleet")[1])
        assert state["vehicle"] == "boat-a" and state["vehicles"] == ["boat-a"]
    finally:
        shore.terminate()
        shore.wait(10)
        pub.close()
        router.close()


def shore_feed(view: LiveView, origin: tuple[float, float], t: float, places: dict,
               order: str = "est-first") -> None:
    """One tick of a vehicle's service as the shore hears it: each pipeline's estimate at
    ``places[pipeline]`` (north, east; metres from ``origin``, the service's first fix)
    and its LocationFix, estimates first (as the service puts them) or fixes first (as a
    startup query may answer)."""
    from onboard.core.geo import LocalFrame
    from onboard.core.wire import location_fix

    enc = msgspec.json.encode
    frame = LocalFrame(*origin)
    recs = [EstimateRecord(vehicle="boat", pipeline=p, t=t, utc=1.8e9 + t,
                           values={"north": n, "east": e}, std={"north": 1.0, "east": 1.0})
            for p, (n, e) in places.items()]
    ests = [(f"onboard/boat/est/{r.pipeline}", enc(r)) for r in recs]
    fixes = [(f"onboard/boat/fix/{r.pipeline}", enc(location_fix(r, frame))) for r in recs]
    for key, payload in (ests + fixes if order == "est-first" else fixes[::-1] + ests[::-1]):
        view.feed_zenoh(key, payload)


def test_the_shore_map_follows_the_services_origin_across_a_restart():
    """A boat going east at 1 m/s from (43 N, 5 E); its service restarts at t = 60 s
    (service time goes on) and counts from its new first fix, 61 m east and 0 m north
    of the first: the track goes on where the boat is, the origin stays put."""
    from onboard.core.geo import LocalFrame

    o1 = (LAT0, LON0)
    o2 = LocalFrame(*o1).to_latlon(0.0, 61.0)
    view = LiveView()
    for k in range(60):
        shore_feed(view, o1, float(k), {"nav": (0.0, float(k))})
    first = view.state()
    assert first["origin"]["lat_deg"] == pytest.approx(LAT0, abs=1e-9)
    assert first["origin"]["lon_deg"] == pytest.approx(LON0, abs=1e-9)
    for k in range(61, 90):
        shore_feed(view, o2, float(k), {"nav": (0.0, float(k) - 61.0)})
    s = view.state(since=first["track"]["points"][-1][0], epoch=first["epoch"])
    assert s["origin"] == first["origin"]
    pts = view.state()["track"]["points"]
    assert [round(t) for t, _, _ in pts] == list(range(60)) + list(range(61, 90))
    for t, n, e in pts:  # every point where the boat was, 1 m a second east of o1
        assert (n, e) == (pytest.approx(0.0, abs=0.01), pytest.approx(t, abs=0.01))
    assert s["position"]["east_m"] == pytest.approx(89.0, abs=0.01)
    assert s["epoch"] != first["epoch"]  # the restart's first point was placed again


def test_a_startup_query_answering_fixes_first_pairs_each_fix_with_its_own_pipeline():
    """The queryables answer fix/aie and fix/nav before est/aie and est/nav; aie's
    position is 5 m from nav's: the origin is the service's, to the millimetre."""
    view = LiveView()
    shore_feed(view, (LAT0, LON0), 100.0, {"nav": (200.0, -80.0), "aie": (205.0, -80.0)},
               order="fix-first")
    s = view.state()
    assert s["origin"]["lat_deg"] == pytest.approx(LAT0, abs=1e-8)  # 1 mm
    assert s["origin"]["lon_deg"] == pytest.approx(LON0, abs=1e-8)
    assert s["position"]["north_m"] == pytest.approx(200.0)


def test_an_auv_under_water_keeps_its_place_from_aie_once_nav_has_no_position():
    """An AUV's nav loses north/east with GNSS: the position and the track go on with
    aie (then kf), in the same metres; nav makes them again when it has a fix."""
    view = LiveView()
    for k in range(10):
        shore_feed(view, (LAT0, LON0), float(k), {"nav": (float(k), 0.0), "aie": (float(k), 0.1)})
    enc = msgspec.json.encode
    for k in range(10, 20):
        view.feed_zenoh("onboard/boat/est/nav", enc(EstimateRecord(
            vehicle="boat", pipeline="nav", t=float(k), values={"speed": 1.0})))
        shore_feed(view, (LAT0, LON0), float(k), {"aie": (float(k), 0.1), "kf": (float(k), 0.2)})
    s = view.state()
    assert s["position"]["pipeline"] == "aie" and s["position"]["north_m"] == 19.0
    assert s["track"]["pipeline"] == "aie" and len(s["track"]["points"]) == 20
    shore_feed(view, (LAT0, LON0), 20.0, {"nav": (20.0, 0.0), "aie": (20.0, 0.1)})
    s = view.state()
    assert s["position"]["pipeline"] == "nav" and s["track"]["points"][-1] == [20.0, 20.0, 0.0]


@pytest.mark.integration
def test_a_diving_auv_replayed_into_the_shore_view_keeps_its_place(tmp_path):
    """fault-gnss-submerged (an AUV that dives and loses GNSS) replayed into MCAP, the
    channels fed to the page's model as the shore hears them: nav has no position under
    water, and the page shows aie's, in the metres of the track."""
    import subprocess
    import sys

    mcap_reader = pytest.importorskip("mcap.reader", reason="pip install 'onboard[mcap]'")
    onboard = [sys.executable, "-m", "onboard"]
    tlog, mcap = tmp_path / "auv.tlog", tmp_path / "auv.mcap"
    for argv in (["sitl", "--scenario", "fault-gnss-submerged", "--duration", "40",
                  "--tlog", str(tlog)],
                 ["replay", str(tlog), "--mcap", str(mcap), "--no-plot", "--out",
                  str(tmp_path / "out")]):
        run = subprocess.run(onboard + argv, capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr[-2000:]
    view = LiveView()
    without_nav = 0
    with open(mcap, "rb") as f:
        for _, channel, msg in mcap_reader.make_reader(f).iter_messages(log_time_order=True):
            view.feed_zenoh(channel.topic, msg.data)
            if channel.topic.endswith("/est/nav") and "north" not in json.loads(msg.data)["values"]:
                without_nav += 1
                s = view.state()
                assert s["position"] is not None and s["position"]["pipeline"] in ("aie", "kf")
    assert without_nav > 100  # 10 s and more under water
    s = view.state()
    assert s["origin"] is not None and s["track"]["points"][-1][0] == pytest.approx(s["t"], abs=1.0)
