"""The simulated autopilot's MAVLink side (sitl/autopilot.py) against ArduPilot's behaviour:
heartbeats only until asked, SET_MESSAGE_INTERVAL with its ACK, REQUEST_DATA_STREAM groups,
parameters on request, reboot, other components; and the service's autopilot link
(drivers/mavlink_link.py) that filters and time-stamps what it receives."""

from __future__ import annotations

from collections import Counter

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from onboard.core.messages import GnssFix
from onboard.drivers.mavlink import MavlinkParser
from onboard.drivers.mavlink_link import AutopilotLink
from onboard.drivers.sender_clock import SenderClock
from onboard.sitl.autopilot import REBOOT_S, SimAutopilot
from onboard.sitl.runner import Simulation, autopilot_for


class LoopSink:
    """A sink that keeps what the autopilot wrote and hands it what the test sends."""

    def __init__(self) -> None:
        self.out: list[tuple[float, bytes]] = []
        self.inbox = bytearray()

    def write(self, t: float, frame: bytes) -> None:
        self.out.append((t, frame))

    def read(self) -> bytes:
        data, self.inbox = bytes(self.inbox), bytearray()
        return data

    def close(self) -> None:
        pass


GCS = mavlink2.MAVLink(None, srcSystem=42, srcComponent=191)


def send(sink: LoopSink, msg) -> None:
    sink.inbox += msg.pack(GCS)


def decoded(sink: LoopSink, t0: float = -1.0, t1: float = 1e9) -> list:
    mav = mavlink2.MAVLink(None)
    out = []
    for t, f in sink.out:
        if t0 <= t < t1:
            out += [m for m in mav.parse_buffer(f) or [] if m.get_type() != "BAD_DATA"]
    return out


def fly(ap: SimAutopilot, sim: Simulation, t0: float, t1: float, steps) -> None:
    for t, samples, _ in steps:
        if t >= t1:
            break
        ap.emit(t, samples)


@pytest.fixture
def rig():
    sim = Simulation("jaiabot-turns", 1)
    sink = LoopSink()
    ap = autopilot_for(sim, [sink])
    return sim, sink, ap, sim.steps(60.0)


def test_heartbeat_only_until_asked_then_the_requested_rates(rig):
    sim, sink, ap, steps = rig
    fly(ap, sim, 0, 5.0, steps)
    types = Counter(m.get_type() for m in decoded(sink))
    assert set(types) == {"HEARTBEAT"} and 4 <= types["HEARTBEAT"] <= 6, types
    # SET_MESSAGE_INTERVAL: ATTITUDE at 5 Hz, SCALED_IMU at 20 Hz (from the 50 Hz IMU:
    # samples 60 and 40 ms apart, 20 Hz on average)
    send(sink, GCS.command_long_encode(1, 1, 511, 0, 30, 200000, 0, 0, 0, 0, 0))
    send(sink, GCS.command_long_encode(1, 1, 511, 0, 26, 50000, 0, 0, 0, 0, 0))
    send(sink, GCS.command_long_encode(1, 1, 511, 0, 99999, 50000, 0, 0, 0, 0, 0))  # unknown
    n0 = len(sink.out)
    fly(ap, sim, 5.0, 15.0, steps)
    msgs = decoded(sink, 5.0, 15.0)
    acks = [(m.command, m.result) for m in msgs if m.get_type() == "COMMAND_ACK"]
    assert acks == [(511, 0), (511, 0), (511, 4)]  # ACCEPTED, ACCEPTED, FAILED
    rate = Counter(m.get_type() for m in msgs)
    assert rate["ATTITUDE"] / 10.0 == pytest.approx(5.0, rel=0.05)  # measured 5.0
    assert rate["SCALED_IMU"] / 10.0 == pytest.approx(20.0, rel=0.05)  # measured 20.0
    assert "GPS_RAW_INT" not in rate and "SERVO_OUTPUT_RAW" not in rate
    assert len(sink.out) > n0
    # -1 stops it
    send(sink, GCS.command_long_encode(1, 1, 511, 0, 30, -1, 0, 0, 0, 0, 0))
    fly(ap, sim, 15.0, 20.0, steps)
    rate = Counter(m.get_type() for m in decoded(sink, 15.5, 20.0))
    assert "ATTITUDE" not in rate and rate["SCALED_IMU"] == 90  # 4.5 s at 20 Hz


def test_request_data_stream_groups_and_parameters(rig):
    sim, sink, ap, steps = rig
    fly(ap, sim, 0, 1.0, steps)
    send(sink, GCS.request_data_stream_encode(1, 1, 10, 4, 1))  # EXTRA1: ATTITUDE (+RPM)
    send(sink, GCS.request_data_stream_encode(1, 1, 1, 10, 1))  # RAW_SENSORS: RAW_IMU
    send(sink, GCS.request_data_stream_encode(1, 1, 3, 2, 1))   # RC_CHANNELS: SERVO_OUTPUT_RAW
    send(sink, GCS.param_request_read_encode(1, 1, b"SERVO3_FUNCTION", -1))
    send(sink, GCS.param_request_read_encode(1, 1, b"NO_SUCH_PARAM", -1))
    fly(ap, sim, 1.0, 11.0, steps)
    msgs = decoded(sink, 1.0, 11.0)
    rate = Counter(m.get_type() for m in msgs)
    assert rate["ATTITUDE"] / 10 == pytest.approx(4.0, rel=0.05)
    assert rate["RAW_IMU"] / 10 == pytest.approx(10.0, rel=0.05) and "SCALED_IMU" not in rate
    assert rate["SERVO_OUTPUT_RAW"] / 10 == pytest.approx(2.0, rel=0.1)
    params = {m.param_id: m.param_value for m in msgs if m.get_type() == "PARAM_VALUE"}
    assert params == {"SERVO3_FUNCTION": 70.0}
    send(sink, GCS.param_request_list_encode(1, 1))
    fly(ap, sim, 11.0, 12.0, steps)
    params = {m.param_id: m.param_value for m in decoded(sink, 11.0, 12.0)
              if m.get_type() == "PARAM_VALUE"}
    assert params["SERVO1_FUNCTION"] == 26.0 and params["FRAME_CLASS"] == 2.0
    assert params["SR0_EXTRA1"] == 0.0


def test_reboot_restarts_the_boot_clock_and_stops_the_streams(rig):
    sim, sink, ap, steps = rig
    ap.reboot_at = [20.0]
    fly(ap, sim, 0, 10.0, steps)
    send(sink, GCS.command_long_encode(1, 1, 511, 0, 30, 100000, 0, 0, 0, 0, 0))
    fly(ap, sim, 10.0, 30.0, steps)
    before = [m for m in decoded(sink, 15.0, 20.0) if m.get_type() == "ATTITUDE"]
    during = decoded(sink, 20.0, 20.0 + REBOOT_S - 0.01)
    after = decoded(sink, 20.0 + REBOOT_S, 30.0)
    assert before and before[-1].time_boot_ms >= 19900
    assert during == []  # silent while it boots
    assert {m.get_type() for m in after} == {"HEARTBEAT"}  # streams off until asked again
    send(sink, GCS.command_long_encode(1, 1, 511, 0, 30, 100000, 0, 0, 0, 0, 0))
    fly(ap, sim, 30.0, 32.0, steps)
    att = [m for m in decoded(sink, 30.0, 32.0) if m.get_type() == "ATTITUDE"]
    assert att and att[0].time_boot_ms < 11000  # counts from the reboot at 20 s


def test_the_link_ignores_other_components_and_maps_the_boot_clock():
    """A GCS at 255 and a camera at component 100 send ATTITUDE/SCALED_IMU/GPS_RAW_INT
    look-alikes; the parser with an AutopilotLink decodes the autopilot's only, and stamps
    them with its boot time mapped to the receive clock (a constant 30 ms link delay plus
    0-40 ms jitter: the stamps are within 1 ms of measurement time + 30 ms)."""
    sim = Simulation("jaiabot-turns", 1)
    sink = LoopSink()
    ap = autopilot_for(sim, [sink], stream_unasked=True, others=True)
    for t, samples, _ in sim.steps(20.0):
        ap.emit(t, samples)
    link = AutopilotLink()
    parser = MavlinkParser(link=link)
    out = []
    for k, (t, f) in enumerate(sink.out):
        delay = 0.030 + 0.040 * ((k * 7919) % 13) / 12.0
        out += parser.feed(f, t + delay)
    assert link.system_id == 1 and link.component_id == 1 and link.mav_type == 11
    assert link.ignored["255.190"] > 500 and link.ignored["1.100"] > 500
    assert {s.source.split("/")[0] for s in out} == {"mavlink:1"}
    att = [s for s in out if type(s).__name__ == "Attitude"]
    assert att and max(abs(a.yaw_rad - 2.0) < 1e-6 for a in att) is False  # no look-alike
    # measured-time stamps: ATTITUDE at k/10 s -> stamp = k/10 + 0.030 (the least delay)
    errs = [abs(a.t - (round(a.t * 10) / 10 + 0.030)) for a in att[20:]]
    assert max(errs) < 1e-3, max(errs)  # measured 0.0 (ms rounding of time_boot_ms)


def test_the_dvl_drivers_frames_are_taken_from_the_companion_not_the_autopilot():
    """BlueOS's Water Linked DVL extension posts VISION_POSITION_DELTA through mavlink2rest
    as system 255, component 0; the autopilot only receives it. The simulator sends it so,
    unasked, and the link locked on the autopilot takes it (with the ground station's and
    the camera's look-alikes still ignored): before, the simulator sent it as the
    autopilot, and a live service would have dropped every DVL frame of a real vehicle."""
    sim = Simulation("bluerov2-circle", 1)
    sink = LoopSink()
    ap = autopilot_for(sim, [sink], stream_unasked=False, others=True)
    for t, samples, _ in sim.steps(10.0):
        ap.emit(t, samples)
    senders = Counter((f[5], f[6]) for _, f in sink.out
                      if (f[7] | (f[8] << 8) | (f[9] << 16))
                      == mavlink2.MAVLINK_MSG_ID_VISION_POSITION_DELTA)
    assert set(senders) == {(255, 0)} and senders[(255, 0)] >= 45   # 5 Hz, unasked
    link = AutopilotLink()
    parser = MavlinkParser(link=link)
    out = []
    for t, f in sink.out:
        out += parser.feed(f, t + 0.03)
    dvl = [s for s in out if type(s).__name__ == "DvlVelocity"]
    assert len(dvl) >= 0.9 * senders[(255, 0)] and link.companion["255.0"] == senders[(255, 0)]
    assert link.ignored["255.190"] > 0 and "255.0" not in link.ignored


def test_boot_clock_reboot_and_jump():
    c = SenderClock()
    for k in range(100):
        assert c.update(10.0 + k * 0.1, 1000.0 + k * 0.1 + 0.02) == pytest.approx(1000.0 + k * 0.1 + 0.02)
    c.update(0.5, 1010.5)  # boot clock back from 19.9 s to 0.5 s: a reboot
    assert c.reboots == 1 and c.offset == pytest.approx(1010.0)
    c.update(5.0, 1012.0)  # 3.5 s of boot time in 1.5 s: the boot clock jumped ahead
    assert c.jumps == 1 and c.offset == pytest.approx(1007.0)


def test_servo_function_parameters_move_the_input_mapping():
    """The config says rudder on SERVO2; the autopilot's SERVO1_FUNCTION=26 (GroundSteering)
    moves it to SERVO1 (an event says so); with ``from_autopilot = false`` it stays."""
    from onboard.core.config import from_dict
    from onboard.core.messages import ActuatorCommand, ActuatorOutputs, Parameter
    from onboard.engine import Engine

    def cfg(from_autopilot: bool):
        return from_dict({"vehicle": {"class": "rudder-boat"}, "inputs": {
            "rudder": {"source": "servo", "channel": 2, "half_range_us": 500, "full_scale": 0.5},
            "throttle": {"source": "servo", "channel": 3, "half_range_us": 500},
            "from_autopilot": from_autopilot}})

    for follow, want in ((True, 0.5), (False, 0.0)):
        eng = Engine(cfg(follow), pipelines=[])
        eng.push(Parameter(t=1.0, source="mavlink:1/PARAM_VALUE", name="SERVO1_FUNCTION", value=26.0))
        eng.push(Parameter(t=1.0, source="mavlink:1/PARAM_VALUE", name="SERVO2_FUNCTION", value=0.0))
        eng.push(ActuatorOutputs(t=1.1, source="mavlink:1/SERVO_OUTPUT_RAW",
                                 pwm_us=(2000.0, 1500.0, 1600.0)))
        cmds = [s for s in eng.queue.pending if isinstance(s, ActuatorCommand)]
        assert cmds and cmds[-1].rudder_rad == pytest.approx(want)
        assert cmds[-1].throttle == pytest.approx(0.2)
        moved = [e for e in eng.events if e.startswith("inputs: rudder on SERVO1")]
        assert bool(moved) is follow, eng.events


def test_timesync_removes_the_one_way_delay():
    """Frames delayed 30-70 ms; a TIMESYNC exchange over a symmetric 30 ms link (60 ms
    round trip) gives the true offset: stamps within 1 ms of the measurement time instead
    of 30 ms after it."""
    sim = Simulation("jaiabot-turns", 1)
    sink = LoopSink()
    ap = autopilot_for(sim, [sink], stream_unasked=True)
    link = AutopilotLink()
    parser = MavlinkParser(link=link)
    att = []
    k = 0
    for t, samples, _ in sim.steps(20.0):
        if abs(t - 5.0) < 1e-9:  # our request leaves at t + 30 ms (our clock = sim clock)
            send(sink, GCS.timesync_encode(0, int(round((t - 0.030) * 1e9))))
        n0 = len(sink.out)
        ap.emit(t, samples)
        for tt, f in sink.out[n0:]:
            k += 1
            delay = 0.030 + 0.040 * ((k * 7919) % 13) / 12.0
            if f[7] == 111:  # the TIMESYNC answer: 30 ms back
                delay = 0.030
            out = parser.feed(f, tt + delay)
            att += [s for s in out if type(s).__name__ == "Attitude"]
    assert link.clock.sync is not None and link.clock.sync[1] == pytest.approx(0.060)
    late = [a for a in att if a.t > 6.0]
    errs = [abs(a.t - round(a.t * 10) / 10) for a in late]
    assert max(errs) < 1e-3, max(errs)  # measured 0.0 (without TIMESYNC: 30 ms)


def test_the_autopilots_frames_are_numbered_as_sent_and_parse_whole():
    """The encoder numbers every frame it packs, those the autopilot does not send (not
    asked for) too: a receiver counted 9-12 % of a lossless loopback link as lost. The
    frames sent are numbered in order and each parses with pymavlink, checksum and all."""
    sim = Simulation("jaiabot-turns", 1)
    sink = LoopSink()
    ap = autopilot_for(sim, [sink], stream_unasked=False)
    send(sink, GCS.command_long_encode(1, 1, 511, 0, 30, 100_000, 0, 0, 0, 0, 0))  # ATTITUDE
    for t, samples, _ in sim.steps(5.0):
        ap.emit(t, samples)
    mine = [f for _, f in sink.out if f[5] == 1 and f[6] == 1]
    assert len(mine) > 5
    seqs = [f[4] for f in mine]
    assert all((b - a) % 256 == 1 for a, b in zip(seqs, seqs[1:])), seqs[:40]
    mav = mavlink2.MAVLink(None)
    parsed = [m for f in mine for m in (mav.parse_buffer(f) or [])]
    assert len(parsed) == len(mine) and not any(m.get_type() == "BAD_DATA" for m in parsed)


def test_every_command_is_answered_as_ardupilot_answers():
    """GET_MESSAGE_INTERVAL gets MESSAGE_INTERVAL (-1: not streamed) and an ACK; a command
    this autopilot does not model gets COMMAND_ACK UNSUPPORTED, not silence; SYSID_THISMAV
    is a parameter, as on every ArduPilot."""
    sim = Simulation("jaiabot-turns", 1)
    sink = LoopSink()
    ap = autopilot_for(sim, [sink], stream_unasked=False)
    send(sink, GCS.command_long_encode(1, 1, 511, 0, 30, 200_000, 0, 0, 0, 0, 0))
    send(sink, GCS.command_long_encode(1, 1, 510, 0, 30, 0, 0, 0, 0, 0, 0))
    send(sink, GCS.command_long_encode(1, 1, 510, 0, 24, 0, 0, 0, 0, 0, 0))
    send(sink, GCS.command_long_encode(1, 1, 246, 0, 1, 0, 0, 0, 0, 0, 0))   # reboot
    send(sink, GCS.param_request_read_encode(1, 1, b"SYSID_THISMAV", -1))
    for t, samples, _ in sim.steps(0.5):
        ap.emit(t, samples)
    got = decoded(sink)
    acks = [(m.command, m.result) for m in got if m.get_type() == "COMMAND_ACK"]
    assert acks == [(511, 0), (510, 0), (510, 0), (246, 3)], acks
    ivs = [(m.message_id, m.interval_us) for m in got if m.get_type() == "MESSAGE_INTERVAL"]
    assert ivs == [(30, 200_000), (24, -1)]
    assert [m.param_value for m in got if m.get_type() == "PARAM_VALUE"
            and m.param_id == "SYSID_THISMAV"] == [1.0]


def test_gps_raw_int_goes_out_at_the_rate_asked_fix_or_not() -> None:
    """ArduPilot sends GPS_RAW_INT at the rate asked whatever its receiver gives: asked
    faster than the receiver's fixes, the newest fix again with its time_usec (as 2 of
    the ArduSub tlog's 528), which the service's parser drops as one measurement; in an
    outage, NO_FIX at the last fix's place and time_usec (held, as the ArduSub tlog's
    loss at 79-82 s), which it rejects as no fix. The simulator sent fixes only as the
    receiver made them, and nothing at all in an outage."""
    sim = Simulation("fault-gnss-outage", 1)   # no fix from 30 s to 150 s
    sink = LoopSink()
    ap = autopilot_for(sim, [sink])
    steps = sim.steps(45.0)
    fly(ap, sim, 0, 1.0, steps)
    fixes_hz = sim.scenario.sensors.gnss.rate_hz
    send(sink, GCS.command_long_encode(1, 1, 511, 0, 24, int(1e6 / (2 * fixes_hz)),
                                       0, 0, 0, 0, 0))
    fly(ap, sim, 1.0, 45.0, steps)
    gps = [m for m in decoded(sink, 2.0, 28.0) if m.get_type() == "GPS_RAW_INT"]
    assert len(gps) / 26.0 == pytest.approx(2 * fixes_hz, rel=0.05)
    assert len({m.time_usec for m in gps}) / 26.0 == pytest.approx(fixes_hz, rel=0.05)
    assert {m.fix_type for m in gps} == {3}
    lost = [m for m in decoded(sink, 31.5, 45.0) if m.get_type() == "GPS_RAW_INT"]
    assert len(lost) / 13.5 == pytest.approx(2 * fixes_hz, rel=0.05)
    assert {m.fix_type for m in lost} == {1} and all(m.lat != 0 for m in lost)
    last_fix = [m for m in decoded(sink, 28.0, 31.5) if m.get_type() == "GPS_RAW_INT"
                and m.fix_type == 3][-1]
    assert {(m.time_usec, m.lat, m.lon) for m in lost} == {
        (last_fix.time_usec, last_fix.lat, last_fix.lon)}
    parser = MavlinkParser()
    fixes = [x for t, f in sink.out for x in parser.feed(f, t) if isinstance(x, GnssFix)]
    sent = [m for m in decoded(sink) if m.get_type() == "GPS_RAW_INT"]
    assert len(fixes) == len({m.time_usec for m in sent if m.fix_type == 3})
    assert parser.stats.rejected["no_fix"] == sum(1 for m in sent if m.fix_type == 1)
    assert parser.stats.rejected["repeated_fix"] == len(sent) - len(fixes) - len(
        [m for m in sent if m.fix_type == 1])
