"""Set and drift on a real Signal K server (npm ``signalk-server`` 2.23.0): the vehicle's
publishers send the current as NMEA 0183 ``VDR`` to the server's NMEA 0183 UDP input and
as an ``environment.current`` delta to its Signal K UDP input, and the server's REST API
(``/signalk/v1/api/vessels/self/environment/current``) shows them; the deltas pass the
specification's own validator (``@signalk/signalk-schema``, shipped with the server). One
server for the module: its start costs about 6 s of CPU."""

from __future__ import annotations

import json
import math
import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

import pytest

from onboard.core.config import NmeaVdrOut, SignalKOut
from onboard.core.messages import EstimateRecord
from onboard.fleet.chartplot import FieldSetDrift, SignalKPlace, udp_output
from onboard.service.publishers.chartplot import NmeaVdrPublisher, SignalKPublisher
from onboard.service.publishers.set_drift import (
    KNOT_MPS,
    nmea_checksum,
    set_drift,
    signalk_delta,
)
from tests.helpers.fleet_scenarios import UTC0, fleet
from tests.helpers.signalk import SIGNALK_INSTALL, SignalKServer, signalk_server

pytestmark = [pytest.mark.integration,
              pytest.mark.skipif(signalk_server() is None,
                                 reason=f"needs signalk-server: {SIGNALK_INSTALL}")]

CURRENT = "/signalk/v1/api/vessels/self/environment/current"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with SignalKServer(signalk_server(), tmp_path_factory.mktemp("signalk")) as srv:
        srv.before = srv.get(CURRENT)  # nothing sent yet
        yield srv


def current(north: float, east: float) -> EstimateRecord:
    return EstimateRecord(vehicle="boat", pipeline="current", t=0.0,
                          values={"north": north, "east": east},
                          std={"north": 0.04, "east": 0.04})


def send(pub, north: float, east: float) -> None:
    pub.start()
    try:
        pub.publish_estimates([current(north, east)], now=0.0)
    finally:
        pub.close()


def test_the_server_shows_the_set_and_drift_of_the_vdr_sentences(server):
    assert server.before is None  # negative control: the path is absent before we send
    pub = NmeaVdrPublisher(NmeaVdrOut(enabled=True, url=f"udp:127.0.0.1:{server.nmea_port}"),
                           declination=lambda: -3.5)
    send(pub, -0.25, 0.4)  # 0.472 m/s towards 122.0 T, 125.5 M
    got = server.wait_for(CURRENT, lambda g: g.get("sentence") == "VDR")
    assert got is not None and got.get("sentence") == "VDR", got
    v = got["value"]
    assert math.degrees(v["setTrue"]) == pytest.approx(
        math.degrees(math.atan2(0.4, -0.25)), abs=0.05)  # to 0.1 degree on the wire
    assert math.degrees(v["setMagnetic"]) == pytest.approx(math.degrees(v["setTrue"]) + 3.5,
                                                           abs=0.1)
    assert v["drift"] == pytest.approx(math.hypot(0.25, 0.4), abs=0.005 * KNOT_MPS)
    assert got["$source"].startswith("onboard-nmea.")


def test_the_server_shows_the_set_and_drift_of_the_signalk_deltas(server):
    pub = SignalKPublisher(SignalKOut(enabled=True, url=f"udp:127.0.0.1:{server.sk_port}"))
    send(pub, 0.1, -0.3)
    got = server.wait_for(CURRENT, lambda g: str(g.get("$source", "")).startswith("onboard-sk."))
    assert got is not None and got["$source"].startswith("onboard-sk."), got
    assert got["value"]["setTrue"] == pytest.approx(math.atan2(-0.3, 0.1) % math.tau)
    assert got["value"]["drift"] == pytest.approx(math.hypot(0.1, -0.3))
    assert "setMagnetic" not in got["value"]  # no declination: left out, not guessed


def rmc(lat: float, lon: float, utc: float) -> bytes:
    """An NMEA 0183 RMC sentence of a fix at ``lat``, ``lon`` (deg) at ``utc``."""
    t = time.gmtime(utc)
    la, lo = abs(lat), abs(lon)
    body = (f"GPRMC,{time.strftime('%H%M%S', t)}.00,A,{int(la):02d}{(la % 1) * 60:08.5f},"
            f"{'N' if lat >= 0 else 'S'},{int(lo):03d}{(lo % 1) * 60:08.5f},"
            f"{'E' if lon >= 0 else 'W'},0.5,45.0,{time.strftime('%d%m%y', t)},,,A")
    return f"${body}*{nmea_checksum(body)}\r\n".encode("ascii")


def test_the_fleets_current_where_the_server_says_its_vessel_is(server):
    """``onboard fleet --at signalk:http://... --signalk udp:...``: the fleet reads the own
    vessel's position from the server (given to it here as an RMC sentence), and the
    server then shows the field's set and drift there."""
    f = fleet("tidal_channel", seed=4, vehicles=4, duration_s=600.0, rate_hz=1.0)
    service = f.fitted_service()
    utc = UTC0 + float(f.t[-1])
    place = SignalKPlace(f"http://127.0.0.1:{server.http_port}", period_s=0.2)
    chart = FieldSetDrift(service.answer, place, signalk=udp_output(
        f"udp:127.0.0.1:{server.sk_port}", "--signalk"), clock=lambda: utc)
    chart.start()
    try:
        assert chart.send() == "no_place"   # negative control: the server knows no position
        lat, lon = (float(x) for x in f.plane.to_latlon(f.north_m[-1], f.east_m[-1]))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as gps:
            gps.sendto(rmc(lat, lon, time.time()), ("127.0.0.1", server.nmea_port))
        deadline = time.monotonic() + 20.0
        while place.where() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        at = place.where()
        assert at is not None, place.problem
        assert at == pytest.approx((lat, lon), abs=1e-6)   # RMC's 1e-5 minute
        assert chart.send() == "sent"
    finally:
        chart.close()
    here = service.answer(*at, utc)
    drift = math.hypot(here.north, here.east)   # 0.61 m/s: no other test's
    got = server.wait_for(CURRENT, lambda g: g["value"]["drift"] == pytest.approx(drift))
    assert got is not None and got["$source"].startswith("onboard-sk."), got
    assert got["value"]["setTrue"] == pytest.approx(math.atan2(here.east, here.north) % math.tau)
    assert got["value"]["drift"] == pytest.approx(math.hypot(here.north, here.east))


SCHEMA_CHECK = r"""
const schema = require('@signalk/signalk-schema');
const deltas = JSON.parse(require('fs').readFileSync(0, 'utf8'));
console.log(JSON.stringify(deltas.map((d) => {
  const envelope = schema.validateDelta(JSON.parse(JSON.stringify(d))).valid;
  const full = schema.deltaToFull(d);  // the vessel tree the delta makes
  const vessel = Object.values(full.vessels)[0];
  const r = schema.validateVessel({mmsi: '230099999', environment: vessel.environment});
  // the tree lacks the identity a whole document needs: keep the errors of our path only
  const ours = r.errors.filter((e) => e.dataPath.includes('/environment/current'));
  return [envelope, ours.map((e) => `${e.message} ${e.dataPath}`)];
})));
"""


def test_the_deltas_conform_to_the_signalk_schema_and_a_wrong_one_does_not():
    """The specification's own validator (@signalk/signalk-schema, which the server ships):
    the delta's envelope and the environment.current it sets (types, units, no unknown
    property, the timestamp's pattern)."""
    modules = Path(signalk_server()).resolve().parents[2]  # .../node_modules
    good = [signalk_delta(set_drift(0.1, -0.3, 4.0), 1_764_000_000.5,
                          "vessels.urn:mrn:imo:mmsi:123456789"),
            signalk_delta(set_drift(0.1, -0.3), 0.0, "vessels.urn:mrn:imo:mmsi:123456789")]
    wrong = json.loads(json.dumps(good[0]))
    wrong["updates"][0]["values"][0]["value"]["drift"] = "0.3 m/s"  # negative control
    run = subprocess.run([shutil.which("node"), "-e", SCHEMA_CHECK],
                         input=json.dumps(good + [wrong]), capture_output=True, text=True,
                         timeout=60, env=dict(os.environ, NODE_PATH=str(modules)))
    assert run.returncode == 0, run.stderr[-2000:]
    (env0, err0), (env1, err1), (env2, err2) = json.loads(run.stdout)
    assert env0 and env1 and err0 == [] and err1 == []
    assert env2 and any("drift" in e for e in err2), err2
