"""Set and drift for chart plotters: the pure conversion (any north/east pair), the NMEA 0183
``VDR`` sentence read back by an independent parser (pynmeagps), the Signal K delta against
the specification's ``environment.current`` schema, and the vehicle's publishers: they send
the newest known current at their rate, nothing for an unknown or withheld one."""

from __future__ import annotations

import json
import math
import socket

import pytest

from onboard.core.config import ConfigError, NmeaVdrOut, SignalKOut, from_dict
from onboard.core.messages import EstimateRecord
from onboard.service.publishers.chartplot import NmeaVdrPublisher, SignalKPublisher
from onboard.service.publishers.set_drift import (
    KNOT_MPS,
    current_of,
    nmea_checksum,
    set_drift,
    signalk_delta,
    vdr_sentence,
)


def test_set_is_where_the_current_flows_to_clockwise_from_north_and_drift_its_speed():
    for (n, e), set_deg in {(1.0, 0.0): 0.0, (0.0, 1.0): 90.0, (-1.0, 0.0): 180.0,
                            (0.0, -1.0): 270.0, (0.3, -0.3): 315.0}.items():
        sd = set_drift(n, e)
        assert math.degrees(sd.set_true_rad) == pytest.approx(set_deg, abs=1e-9)
        assert sd.drift_mps == pytest.approx(math.hypot(n, e))
        assert sd.set_magnetic_rad is None  # no declination: magnetic unknown
    # 090 T under a declination of 10 deg E is 080 M; 005 T under 10 deg E is 355 M
    assert math.degrees(set_drift(0.0, 1.0, 10.0).set_magnetic_rad) == pytest.approx(80.0)
    assert math.degrees(set_drift(1.0, 0.0875, 10.0).set_magnetic_rad) == pytest.approx(
        355.0, abs=0.01)
    assert set_drift(0.0, 0.0).set_true_rad == 0.0


def test_the_vdr_sentence_reads_back_with_pynmeagps_set_magnetic_and_knots():
    pynmeagps = pytest.importorskip("pynmeagps", reason="pip install 'onboard[sim]'")
    sd = set_drift(-0.25, 0.4, declination_deg=-3.5)  # 0.47 m/s towards 122.0 T, 125.5 M
    line = vdr_sentence(sd)
    assert line.endswith("\r\n") and line.startswith("$IIVDR,")
    msg = pynmeagps.NMEAReader.parse(line.encode(), validate=pynmeagps.VALCKSUM)
    assert msg.msgID == "VDR" and msg.talker == "II"
    assert msg.dirT == pytest.approx(math.degrees(math.atan2(0.4, -0.25)) % 360, abs=0.05)
    assert msg.dirM == pytest.approx((msg.dirT + 3.5) % 360, abs=0.1)
    assert msg.spd == pytest.approx(math.hypot(-0.25, 0.4) / KNOT_MPS, abs=0.005)
    assert msg.dirTu == "T" and msg.dirMu == "M" and msg.spdu == "N"


def test_a_vdr_without_declination_has_an_empty_magnetic_field_and_a_wrong_checksum_fails():
    pynmeagps = pytest.importorskip("pynmeagps", reason="pip install 'onboard[sim]'")
    line = vdr_sentence(set_drift(0.1, 0.0))
    assert line == "$IIVDR,0.0,T,,M,0.19,N*" + nmea_checksum("IIVDR,0.0,T,,M,0.19,N") + "\r\n"
    msg = pynmeagps.NMEAReader.parse(line.encode(), validate=pynmeagps.VALCKSUM)
    assert msg.dirM == ""
    # a set within 0.05 deg west of north reads 0.0, never 360.0 (the field is [0, 360))
    assert vdr_sentence(set_drift(1.0, -1e-4)).startswith("$IIVDR,0.0,T,")
    bad = line.replace("0.19", "0.18")  # negative control: the checksum no longer matches
    with pytest.raises(pynmeagps.NMEAParseError):
        pynmeagps.NMEAReader.parse(bad.encode(), validate=pynmeagps.VALCKSUM)


# The Signal K specification's environment.current (schemas/groups/environment.json, v1.7):
# an object whose setTrue, setMagnetic (rad) and drift (m/s) are numbers.
ENVIRONMENT_CURRENT = {"setTrue": "rad", "setMagnetic": "rad", "drift": "m/s"}


def test_the_signalk_delta_holds_environment_current_in_radians_and_metres_per_second():
    sd = set_drift(0.0, -0.5, declination_deg=12.0)
    d = signalk_delta(sd, 1_764_000_000.25, "vessels.urn:mrn:imo:mmsi:123456789", "bot3")
    assert d["context"] == "vessels.urn:mrn:imo:mmsi:123456789"
    (up,) = d["updates"]
    assert up["timestamp"] == "2025-11-24T16:00:00.250Z"
    assert up["source"]["label"] == "bot3"
    (v,) = up["values"]
    assert v["path"] == "environment.current"
    assert set(v["value"]) == set(ENVIRONMENT_CURRENT)
    assert v["value"]["setTrue"] == pytest.approx(1.5 * math.pi)
    assert v["value"]["setMagnetic"] == pytest.approx(1.5 * math.pi - math.radians(12.0))
    assert v["value"]["drift"] == pytest.approx(0.5)
    no_mag = signalk_delta(set_drift(0.0, -0.5), 0.0)["updates"][0]["values"][0]["value"]
    assert set(no_mag) == {"setTrue", "drift"}


def current_record(t: float, north: float | None, east: float | None,
                   std: float = 0.05) -> EstimateRecord:
    values = {k: v for k, v in (("north", north), ("east", east)) if v is not None}
    return EstimateRecord(vehicle="boat", pipeline="current", t=t, values=values,
                          std={"north": std, "east": std})


@pytest.fixture
def listener():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.5)
    yield sock
    sock.close()


def received(sock: socket.socket) -> list[bytes]:
    out = []
    try:
        while True:
            out.append(sock.recv(4096))
            sock.settimeout(0.05)
    except socket.timeout:
        return out


def test_the_vdr_publisher_sends_the_known_current_at_its_rate_and_nothing_unknown(listener):
    port = listener.getsockname()[1]
    pub = NmeaVdrPublisher(NmeaVdrOut(enabled=True, url=f"udp:127.0.0.1:{port}", rate_hz=2.0),
                           declination=lambda: 2.0)
    pub.start()
    try:
        # 10 Hz ticks for 2 s: a known current the first second, then north withheld
        for k in range(20):
            t = 0.1 * k
            north = 0.3 if t < 1.0 else None
            pub.publish_estimates([current_record(t, north, 0.1)], now=t)
        got = received(listener)
    finally:
        pub.close()
    assert len(got) == 2  # 2 Hz over the first second: t = 0.0 and 0.5
    assert all(g.startswith(b"$IIVDR,18.4,T,16.4,M,0.61,N*") for g in got), got
    assert pub.held_back == 10  # the second second: no north, nothing sent


def test_the_vdr_publisher_keeps_its_rate_on_a_jittered_tick(listener):
    """10 Hz ticks up to 10 ms early or late: one VDR a second over 120 s (a tick a little
    before the due time does not push the next by a whole tick)."""
    import random

    rng = random.Random(2)
    port = listener.getsockname()[1]
    pub = NmeaVdrPublisher(NmeaVdrOut(enabled=True, url=f"udp:127.0.0.1:{port}", rate_hz=1.0))
    pub.start()
    try:
        for k in range(1200):
            t = 0.1 * k + rng.uniform(-0.01, 0.01)
            pub.publish_estimates([current_record(t, 0.3, 0.1)], now=t)
        got = received(listener)
    finally:
        pub.close()
    assert len(got) == 120


def test_the_signalk_publisher_holds_back_a_current_whose_sigma_is_above_its_bound(listener):
    port = listener.getsockname()[1]
    cfg = SignalKOut(enabled=True, url=f"udp:127.0.0.1:{port}", rate_hz=10.0, max_std_mps=0.1)
    pub = SignalKPublisher(cfg, wall_clock=lambda: 0.0)
    pub.start()
    try:
        pub.publish_estimates([current_record(0.0, 0.2, 0.0, std=0.3)], now=0.0)
        pub.publish_estimates([current_record(0.1, 0.2, 0.0, std=0.05)], now=0.1)
        got = received(listener)
    finally:
        pub.close()
    assert len(got) == 1 and pub.held_back == 1
    delta = json.loads(got[0])
    assert delta["updates"][0]["values"][0]["value"] == {"setTrue": 0.0, "drift": 0.2}
    assert delta["updates"][0]["timestamp"] == "1970-01-01T00:00:00.000Z"


def test_the_outputs_are_off_by_default_and_a_bad_url_names_its_key():
    cfg = from_dict({})
    assert not cfg.service.nmea_vdr.enabled and not cfg.service.signalk.enabled
    with pytest.raises(ConfigError, match=r"service\.signalk\.url: expected udp:HOST:PORT"):
        SignalKPublisher(SignalKOut(url="tcp:127.0.0.1:3000"))
    with pytest.raises(ConfigError, match="talker"):
        from_dict({"service": {"nmea_vdr": {"talker": "gp"}}})
    with pytest.raises(ConfigError, match=r"service\.nmea_vdr\.url: expected str matching"):
        from_dict({"service": {"nmea_vdr": {"url": "udpout:127.0.0.1:10110"}}})
    assert current_of(current_record(0.0, 0.1, None)) is None


@pytest.mark.integration
def test_the_service_sends_each_ticks_current_to_the_enabled_outputs(tmp_path, listener):
    import asyncio

    from onboard.service.daemon import Service

    port = listener.getsockname()[1]
    cfg = from_dict({"vehicle": {"id": "vdrboat", "class": "rudder-boat"},
                     "corrections": {"declination_deg": 5.0},
                     "service": {"zenoh": {"enabled": False}, "mavlink": {"enabled": False},
                                 "recorder": {"enabled": False},
                                 "nmea_vdr": {"enabled": True, "url": f"udp:127.0.0.1:{port}"}}})

    async def main() -> list:
        svc = Service(cfg, state_dir=tmp_path)
        await svc.start()
        svc.intake.tick = lambda t: [current_record(t, 0.0, 0.2)]  # the tick's records
        svc._tick(1.0, svc.clock.now())
        pubs = list(svc.chartplot)
        svc.request_stop()
        await svc.shutdown()
        return pubs

    pubs = asyncio.run(asyncio.wait_for(main(), 30.0))
    assert [type(p).__name__ for p in pubs] == ["NmeaVdrPublisher"]  # signalk: off
    (line,) = received(listener)
    assert line.startswith(b"$IIVDR,90.0,T,85.0,M,0.39,N*")  # the configured declination


def test_a_host_name_is_looked_up_off_the_loop_and_again_later_while_it_does_not_resolve():
    import time

    now = [0.0]
    pub = NmeaVdrPublisher(NmeaVdrOut(enabled=True, url="udp:no-such-host.invalid:10110"),
                           clock=lambda: now[0])
    pub.start()  # a name: looked up in a thread, no exception
    try:
        pub.udp._lookup.join(10)
        for k in range(30):  # 30 s at 1 Hz
            now[0] = float(k)
            pub.publish_estimates([current_record(now[0], 0.1, 0.1)])
            if pub.udp._lookup is not None:
                pub.udp._lookup.join(10)
        assert pub.sent == 0 and pub.udp.errors == 30
        assert pub.udp._t_lookup == 20.0  # looked up at 0, 10 and 20 s
    finally:
        pub.close()
    local = NmeaVdrPublisher(NmeaVdrOut(enabled=True, url="udp:localhost:9"))
    local.start()
    deadline = time.monotonic() + 10
    while local.udp.sock is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert local.udp.sock is not None  # a name that resolves: the socket opens
    local.close()


def test_nothing_is_sent_while_the_health_record_flags_the_current_pipeline(listener):
    from onboard.core.messages import HealthRecord

    port = listener.getsockname()[1]
    pub = NmeaVdrPublisher(NmeaVdrOut(enabled=True, url=f"udp:127.0.0.1:{port}", rate_hz=10.0))
    pub.start()
    try:
        flagged = HealthRecord(vehicle="boat", t=0.0, flags={"current": ["nis_out_of_band"]})
        pub.publish_health(flagged)
        pub.publish_estimates([current_record(0.0, 0.2, 0.0)], now=0.0)
        pub.publish_health(HealthRecord(vehicle="boat", t=1.0, flags={"aie": ["speed_mismatch"]}))
        pub.publish_estimates([current_record(1.0, 0.2, 0.0)], now=1.0)
        got = received(listener)
    finally:
        pub.close()
    assert pub.held_back == 1 and len(got) == 1  # another pipeline's flag: sent
