"""Set and drift on a real Signal K server (npm ``signalk-server`` 2.23.0): the vehicle's
publishers send the current as NMEA 0183 ``VDR`` to the server's NMEA 0183 UDP input and
as an ``environment.current`` delta to its Signal K UDP input, and the server's REST API
(``/signalk/v1/api/vessels/self/environment/current``) shows them. One server for the
module: its start costs about 6 s of CPU."""

from __future__ import annotations

import math

import pytest

from onboard.core.config import NmeaVdrOut, SignalKOut
from onboard.core.messages import EstimateRecord
from onboard.service.publishers.chartplot import NmeaVdrPublisher, SignalKPublisher
from onboard.service.publishers.set_drift import KNOT_MPS
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
