"""The service's MAVLink session (onboard/service/mavlink_session.py) against the simulated
autopilot (sitl/autopilot.py), in simulated time without sockets: requests go from the
session's transport straight to the autopilot, its frames through the parser with the
autopilot link, as the service wires them."""

from __future__ import annotations

from collections import Counter

import pytest

from onboard.drivers.mavlink import MavlinkParser
from onboard.drivers.mavlink_link import AutopilotLink
from onboard.core.config import SourceConfig, load
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from onboard.service.mavlink_session import PARAM_TRIES, PARAMETERS, MavlinkSession
from onboard.sitl.runner import Simulation, autopilot_for


class Loop:
    """Sink for the autopilot (keeps its frames) and transport for the session (its
    requests land in the autopilot's inbox)."""

    def __init__(self) -> None:
        self.out: list[bytes] = []
        self.inbox = bytearray()
        self.up = True

    def write(self, t: float, frame: bytes) -> None:
        if self.up:
            self.out.append(frame)

    def read(self) -> bytes:
        data, self.inbox = bytes(self.inbox), bytearray()
        return data

    def close(self) -> None:
        pass

    def send(self, data: bytes) -> bool:
        self.inbox += data
        return True


class LossyLoop(Loop):
    """A link that loses the first ``lose`` PARAM_REQUEST_READs of each named parameter
    and counts every parameter request sent."""

    def __init__(self, lose: dict[str, int]) -> None:
        super().__init__()
        self.lose = dict(lose)
        self.asked: Counter[str] = Counter()
        self._mav = mavlink2.MAVLink(None)

    def send(self, data: bytes) -> bool:
        for m in self._mav.parse_buffer(data) or []:
            if m.get_type() == "PARAM_REQUEST_READ":
                self.asked[m.param_id] += 1
                if self.lose.get(m.param_id, 0) > 0:
                    self.lose[m.param_id] -= 1
                    return True
            self.inbox += m.get_msgbuf()
        return True


def run(duration: float, *, down: tuple[float, float] | None = None, loop: Loop | None = None,
        **options):
    """Fly jaiabot-turns with the session asking; returns (session, link, events,
    samples per source in the last 10 s)."""
    sim = Simulation("jaiabot-turns", 1)
    loop = loop or Loop()
    ap = autopilot_for(sim, [loop], **options)
    cfg = load("rudder-boat")
    link = AutopilotLink()
    parser = MavlinkParser(link=link)
    events: list[str] = []
    now = [0.0]
    sess = MavlinkSession("autopilot", cfg, SourceConfig(kind="mavlink", url="udp:x:1"),
                          link, loop, lambda: now[0], events.append)  # type: ignore[arg-type]
    late: Counter[str] = Counter()
    for t, samples, _ in sim.steps(duration):
        now[0] = t
        loop.up = down is None or not down[0] <= t < down[1]
        ap.emit(t, samples)
        for f in loop.out:
            for s in parser.feed(f, t + 0.01):
                if s.t >= duration - 10.0:
                    late[s.source] += 1
        loop.out.clear()
        sess.poll(t)
    return sess, link, events, late


def test_streams_requested_by_message_interval_arrive_at_their_rates():
    sess, link, events, late = run(20.0)
    assert {k: st.state for k, st in sess.streams.items()} == {
        "SCALED_IMU": "accepted", "ATTITUDE": "accepted", "GPS_RAW_INT": "accepted",
        "SYSTEM_TIME": "accepted", "SERVO_OUTPUT_RAW": "accepted"}
    rates = sess.rates()
    for name, hz in (("SCALED_IMU", 50), ("ATTITUDE", 10), ("GPS_RAW_INT", 5),
                     ("SERVO_OUTPUT_RAW", 10), ("SYSTEM_TIME", 1)):
        assert rates[f"autopilot/{name}:requested"] == hz
        assert abs(rates[f"autopilot/{name}:received"] - hz) <= 0.1 * hz, (name, rates)
    assert late["mavlink:1/SCALED_IMU"] == pytest.approx(500, abs=2)  # 10 s at 50 Hz
    assert link.params["SERVO1_FUNCTION"] == 26.0 and link.params["FRAME_CLASS"] == 2.0
    assert link.clock.sync is not None  # TIMESYNC answered
    assert not [e for e in events if "asking again" in e], events


def test_firmware_without_message_interval_falls_back_to_request_data_stream():
    sess, _, events, late = run(20.0, message_interval=False)
    assert {st.state for st in sess.streams.values()} == {"legacy"}
    assert any("REQUEST_DATA_STREAM 1 at 50 Hz" in e for e in events), events
    rates = sess.rates()
    for name, hz in (("SCALED_IMU", 50), ("ATTITUDE", 10), ("GPS_RAW_INT", 5),
                     ("SERVO_OUTPUT_RAW", 10), ("SYSTEM_TIME", 1)):
        assert abs(rates[f"autopilot/{name}:received"] - hz) <= 0.1 * hz, (name, rates)
    # ArduPilot's RAW_SENSORS group carries the IMU as RAW_IMU (decoded for ArduPilot)
    assert late["mavlink:1/RAW_IMU"] == pytest.approx(500, abs=2)


def test_a_parameter_request_lost_on_the_link_is_asked_again_and_the_asking_stops():
    loop = LossyLoop({"SERVO3_FUNCTION": 2})
    _, link, _, _ = run(10.0, loop=loop)
    assert link.params["SERVO3_FUNCTION"] == 70.0  # answered at the third request
    assert loop.asked["SERVO3_FUNCTION"] == PARAM_TRIES
    assert loop.asked["SERVO1_FUNCTION"] == 1  # answered at once, never asked again
    # a name the autopilot does not have is left unanswered: asked PARAM_TRIES times only
    missing = [p for p in PARAMETERS if p not in link.params]
    assert missing and all(loop.asked[p] == PARAM_TRIES for p in missing), loop.asked


def test_reboot_and_lost_link_restart_the_requests():
    sess, link, events, late = run(40.0, reboot_at=[10.0], down=(20.0, 27.0))
    assert link.reboots == 1
    assert any("autopilot rebooted" in e for e in events), events
    assert any("autopilot link lost" in e for e in events), events
    assert any("autopilot back" in e for e in events), events
    assert sess.sessions == 3  # found, rebooted, back
    rates = sess.rates()
    assert abs(rates["autopilot/SCALED_IMU:received"] - 50) <= 5, rates
    assert late["mavlink:1/ATTITUDE"] == pytest.approx(100, abs=2)


def test_requests_are_signed_with_the_service_key(tmp_path):
    """With the service's signing state the session's requests carry valid signatures (an
    autopilot requiring signing accepts them); without it they are unsigned."""
    from onboard.drivers.mavlink_signing import SignatureVerifier
    from onboard.service.signing import SigningState

    key = bytes(range(32))
    for signing in (SigningState(key, tmp_path / "sig.json"), None):
        loop = Loop()
        link = AutopilotLink(system_id=1, component_id=1, mav_type=11, autopilot=3,
                             t_heartbeat=0.0)
        sess = MavlinkSession("autopilot", load("rudder-boat"),
                              SourceConfig(kind="mavlink", url="udp:x:1"), link, loop,  # type: ignore[arg-type]
                              lambda: 0.0, lambda e: None, signing=signing)
        sess.poll(0.0)
        checker = MavlinkParser(verifier=SignatureVerifier(key))
        checker.feed(bytes(loop.inbox), 0.0)
        assert checker.stats.records >= 20  # 17 parameter reads, 5 intervals, TIMESYNC
        if signing is not None:
            assert not checker.stats.rejected, checker.stats.rejected
        else:
            assert checker.stats.rejected == {"unsigned": checker.stats.records}


def test_own_component_echoes_and_ground_stations_are_not_the_autopilot():
    """Our own heartbeat (component 191, MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID)
    echoed by a router and a GCS heartbeat do not lock the link; ArduPilot's does."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    def hb(sysid, compid, typ, ap):
        mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        return mav.heartbeat_encode(typ, ap, 0, 0, 4, 3).pack(mav)

    link = AutopilotLink()
    p = MavlinkParser(link=link)
    p.feed(hb(1, 191, 18, 8) + hb(255, 190, 6, 8) + hb(1, 100, 30, 8), 1.0)
    assert not link.found
    assert link.ignored == {"1.191": 1, "255.190": 1, "1.100": 1}
    p.feed(hb(1, 1, 11, 3), 2.0)
    assert (link.system_id, link.component_id, link.mav_type, link.autopilot) == (1, 1, 11, 3)


def test_a_message_the_autopilot_never_sends_is_reported_absent():
    """The BlueROV2 has no GNSS: its autopilot never sends GPS_RAW_INT. The session asks
    again three times, then reports it absent and stops asking; the others flow."""
    sim = Simulation("bluerov2-circle", 1)
    loop = Loop()
    ap = autopilot_for(sim, [loop])
    cfg = load("bluerov2")
    link = AutopilotLink()
    parser = MavlinkParser(link=link)
    events: list[str] = []
    now = [0.0]
    sess = MavlinkSession("autopilot", cfg, SourceConfig(kind="mavlink", url="udp:x:1"),
                          link, loop, lambda: now[0], events.append)  # type: ignore[arg-type]
    asked = 0
    for t, samples, _ in sim.steps(60.0):
        now[0] = t
        ap.emit(t, samples)
        for f in loop.out:
            parser.feed(f, t + 0.01)
        loop.out.clear()
        n0 = len(ap.received)
        sess.poll(t)
        ap.poll(t)
        asked += sum(1 for m in ap.received[n0:] if m == "COMMAND_LONG") if t > 40.0 else 0
    assert sess.streams["GPS_RAW_INT"].state == "absent"
    assert any("GPS_RAW_INT not sent by the autopilot" in e for e in events), events
    assert asked == 0  # nothing asked again in the last 20 s
    rates = sess.rates()
    for name, hz in (("SCALED_IMU", 50), ("ATTITUDE", 10), ("SCALED_PRESSURE2", 10),
                     ("GLOBAL_POSITION_INT", 10), ("SERVO_OUTPUT_RAW", 10)):
        assert abs(rates[f"autopilot/{name}:received"] - hz) <= 0.1 * hz, (name, rates)


def test_a_message_that_arrives_below_its_rate_is_reported_at_the_rate_it_arrives():
    """ATTITUDE asked at 25 Hz from an autopilot that sends it at 10 Hz (as a router like
    MAVProxy sends its own rate): after the repeated requests the event says the rate it
    arrives at, below the rate asked, not that the autopilot does not send it; a message
    none of which arrived (the BlueROV2's GPS_RAW_INT) is still reported as not sent."""
    sim = Simulation("bluerov2-circle", 1)
    loop = Loop()
    ap = autopilot_for(sim, [loop])
    link = AutopilotLink()
    parser = MavlinkParser(link=link)
    events: list[str] = []
    now = [0.0]
    src = SourceConfig(kind="mavlink", url="udp:x:1", streams={"ATTITUDE": 25.0})
    sess = MavlinkSession("autopilot", load("bluerov2"), src, link, loop, lambda: now[0],
                          events.append)  # type: ignore[arg-type]
    for t, samples, _ in sim.steps(60.0):
        now[0] = t
        ap.emit(t, samples)
        for f in loop.out:
            parser.feed(f, t + 0.01)
        loop.out.clear()
        sess.poll(t)
        ap.poll(t)
    att = [e for e in events if "ATTITUDE" in e and "no longer asked" in e]
    assert len(att) == 1, events
    assert att[0].startswith("autopilot: ATTITUDE arrives at 10.0 Hz, too slow for the 25 Hz "
                             "requested (asked 4 times)"), att
    assert "not sent" not in att[0]
    from onboard.service import events as service_events
    assert service_events.severity(att[0]) == service_events.MAV_SEVERITY_WARNING
    assert sess.streams["ATTITUDE"].state == "slow"
    assert sess.streams["GPS_RAW_INT"].state == "absent"
    assert any("GPS_RAW_INT not sent by the autopilot" in e for e in events), events


def test_a_vehicle_type_that_does_not_match_the_class_is_reported():
    """A BlueROV2 configuration (class bluerov2) on the rudder boat's autopilot
    (MAV_TYPE_SURFACE_BOAT 11): an event names both."""
    link = AutopilotLink(system_id=1, component_id=1, mav_type=11, autopilot=3, t_heartbeat=0.0)
    events: list[str] = []
    sess = MavlinkSession("autopilot", load("bluerov2"), SourceConfig(kind="mavlink", url="udp:x:1"),
                          link, Loop(), lambda: 0.0, events.append)  # type: ignore[arg-type]
    sess.poll(0.0)
    assert any("MAV_TYPE 11" in e and "bluerov2" in e for e in events), events
    ok: list[str] = []
    MavlinkSession("autopilot", load("rudder-boat"), SourceConfig(kind="mavlink", url="udp:x:1"),
                   link, Loop(), lambda: 0.0, ok.append).poll(0.0)  # type: ignore[arg-type]
    assert not any("MAV_TYPE" in e for e in ok), ok
