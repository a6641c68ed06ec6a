"""The fleet's field as set and drift for a chart plotter (``onboard fleet --at ... --vdr
... --signalk ...``, onboard/fleet/chartplot.py): what is sent is the field's prediction
at the place, nothing is sent where the field does not know, a Signal K position that
stops moving is not used, and bad flags are a usage error. The real Signal K server's
view of it is in tests/test_signalk.py."""

from __future__ import annotations

import json
import math
import socket
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from onboard.cli import main as cli_main
from onboard.fleet.chartplot import (
    POSITION_PATH,
    FieldSetDrift,
    FixedPlace,
    SignalKPlace,
    parse_place,
    udp_output,
)
from onboard.service.publishers.set_drift import KNOT_MPS
from tests.helpers.fleet_scenarios import UTC0, fleet


@pytest.fixture(scope="module")
def service():
    f = fleet("tidal_channel", seed=4, vehicles=4, duration_s=600.0, rate_hz=1.0)
    svc = f.fitted_service()
    last = len(f.t) - 1
    svc.place = f.plane.to_latlon(f.north_m[last], f.east_m[last])   # a vehicle's last
    svc.utc = UTC0 + float(f.t[last])
    return svc


def listener() -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(2.0)
    return sock


def chart_to(service, place, max_std_mps: float = 0.0):
    """A FieldSetDrift of ``service`` at ``place`` at the fleet's last time, sending VDR
    and Signal K to two loopback listeners."""
    vdr_in, sk_in = listener(), listener()
    chart = FieldSetDrift(service.answer, place,
                          vdr=udp_output(f"udp:127.0.0.1:{vdr_in.getsockname()[1]}", "--vdr"),
                          signalk=udp_output(f"udp:127.0.0.1:{sk_in.getsockname()[1]}",
                                             "--signalk"),
                          max_std_mps=max_std_mps, clock=lambda: service.utc)
    chart.start()
    return chart, vdr_in, sk_in


def test_the_set_and_drift_sent_are_the_fields_at_the_place(service):
    lat, lon = service.place
    here = service.answer(float(lat), float(lon), service.utc)
    assert here.north is not None and here.std_north < 0.05   # a vehicle was just there
    chart, vdr_in, sk_in = chart_to(service, FixedPlace(float(lat), float(lon)))
    try:
        assert chart.send() == "sent" and chart.sent == 1
        fields = vdr_in.recv(200).decode("ascii").split("*")[0].split(",")
        delta = json.loads(sk_in.recv(2000))
    finally:
        chart.close()
    set_true = math.atan2(here.east, here.north) % math.tau
    assert fields[0] == "$IIVDR" and fields[2] == "T" and fields[3] == ""   # no magnetic
    assert float(fields[1]) == pytest.approx(math.degrees(set_true), abs=0.05)
    assert float(fields[5]) * KNOT_MPS == pytest.approx(math.hypot(here.north, here.east),
                                                        abs=0.005 * KNOT_MPS)
    update = delta["updates"][0]
    assert delta["context"] == "vessels.self" and update["source"]["label"] == "onboard-fleet"
    value = update["values"][0]["value"]
    assert value["setTrue"] == pytest.approx(set_true)
    assert value["drift"] == pytest.approx(math.hypot(here.north, here.east))
    assert "setMagnetic" not in value


def test_nothing_is_sent_where_the_field_does_not_know_or_is_not_precise_enough(service):
    far = FixedPlace(43.6, 6.5)   # 60 km from the fleet
    assert service.answer(43.6, 6.5, service.utc).north is None
    chart, vdr_in, _ = chart_to(service, far)
    try:
        assert chart.send() == "unknown"
        with pytest.raises(TimeoutError):
            vdr_in.recv(200)
    finally:
        chart.close()
    lat, lon = (float(x) for x in service.place)
    strict, vdr_in, _ = chart_to(service, FixedPlace(lat, lon), max_std_mps=1e-4)
    try:
        assert strict.send() == "imprecise"
        assert strict.held_back == {"imprecise": 1} and strict.sent == 0
        assert "held back: imprecise 1" in strict.summary()
    finally:
        strict.close()


class Position(BaseHTTPRequestHandler):
    """A Signal K server's position answer: ``answer`` (a dict) as JSON."""

    answer: dict = {}

    def do_GET(self):  # noqa: N802 - http.server's name
        body = json.dumps(self.answer).encode()
        self.send_response(200 if self.path == POSITION_PATH else 404)
        self.send_header("Content-Type", "application/json")
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):
        pass


@pytest.fixture
def position_server():
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), Position)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    yield httpd
    httpd.shutdown()


def answer(lat: float, lon: float, stamp: str) -> dict:
    return {"value": {"latitude": lat, "longitude": lon}, "timestamp": stamp,
            "$source": "gps.GP"}


def test_a_signalk_position_is_followed_and_not_used_once_it_stops_moving(position_server):
    now = [100.0]
    place = SignalKPlace(f"http://127.0.0.1:{position_server.server_port}",
                         stale_s=10.0, clock=lambda: now[0])
    assert place.where() is None and place.problem == "not read yet"
    Position.answer = answer(43.1, 5.9, "2026-12-01T10:00:00.000Z")
    place.read()
    assert place.where() == (43.1, 5.9) and place.problem is None
    now[0] += 9.0
    Position.answer = answer(43.1001, 5.9, "2026-12-01T10:00:00.000Z")  # same stamp
    place.read()
    assert place.where() == (43.1001, 5.9)
    now[0] += 2.0                                       # 11 s since its stamp moved
    place.read()
    assert place.where() is None                        # stale: not used
    assert place.problem == "its position not updated for 11 s"
    Position.answer = answer(43.1002, 5.9, "2026-12-01T10:00:11.000Z")
    place.read()
    assert place.where() == (43.1002, 5.9) and place.problem is None
    Position.answer = {"value": None, "timestamp": "x"}  # the boat lost its position
    place.read()
    assert "no position" in place.problem
    Position.answer = answer(91.0, 5.9, "2026-12-01T10:00:12.000Z")
    place.read()
    assert "not a position" in place.problem
    gone = SignalKPlace("http://127.0.0.1:1")           # nothing listens there
    gone.read()
    assert gone.where() is None and "127.0.0.1:1" in gone.problem


def test_the_places_and_outputs_are_checked():
    assert isinstance(parse_place("43.1,-5.9"), FixedPlace)
    assert isinstance(parse_place("signalk:http://10.0.0.2:3000"), SignalKPlace)
    for bad in ("43.1", "91,0", "0,181", "nan,0", "north,east", "signalk:10.0.0.2:3000"):
        with pytest.raises(ValueError):
            parse_place(bad)
    with pytest.raises(ValueError, match="--vdr"):
        udp_output("tcp:127.0.0.1:10110", "--vdr")


@pytest.mark.parametrize("flags, words", [
    (["--vdr", "udp:127.0.0.1:10110"], "go together"),
    (["--at", "43.1,5.9"], "go together"),
    (["--at", "91,5.9", "--vdr", "udp:127.0.0.1:10110"], "latitude"),
    (["--at", "43.1,5.9", "--signalk", "127.0.0.1:8375"], "udp:HOST:PORT"),
    (["--at", "43.1,5.9", "--vdr", "udp:127.0.0.1:10110", "--max-std", "-1"], "--max-std"),
])
def test_bad_set_and_drift_flags_stop_the_fleet_before_it_connects(flags, words, capsys):
    # a Zenoh endpoint nobody serves: reaching it would be a different error
    rc = cli_main(["fleet", "--connect", "tcp/127.0.0.1:1", *flags])
    assert rc == 2
    assert words in capsys.readouterr().err
