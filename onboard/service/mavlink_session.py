"""The service's MAVLink session with the autopilot: find it, ask for the streams, watch them.

ArduPilot sends only HEARTBEAT on a fresh link (its ``SRn_*`` stream rates default to 0-1 Hz
on USB and most TELEM ports) until a ground station asks. For each MAVLink input with
``request_streams`` (default) the session

1. waits for the autopilot's HEARTBEAT (:class:`drivers.mavlink_link.AutopilotLink` finds
   it: not a GCS, not MAV_AUTOPILOT_INVALID, component 1 unless configured; other systems,
   components and our own component's echoes are ignored);
2. asks for every message the enabled pipelines need at its rate (:func:`needed_streams`)
   with COMMAND_LONG MAV_CMD_SET_MESSAGE_INTERVAL (511), one command per message, all at
   once, each confirmed by its COMMAND_ACK (matched in order); a message not ACCEPTED within ``ACK_TIMEOUT_S`` after
   ``ACK_TRIES`` sends is asked for with the legacy REQUEST_DATA_STREAM of the ArduPilot
   stream group that carries it (:data:`STREAM_GROUPS`), at the fastest rate any message
   of that group needs;
3. reads the parameters that say which servo output is which actuator
   (PARAM_REQUEST_READ of ``SERVOn_FUNCTION``, ``FRAME_CLASS``): they reach the engine as
   Parameter samples, in the recording too; one not answered within ``PARAM_RETRY_S`` is
   asked again, ``PARAM_TRIES`` requests in all;
4. confirms that the streams arrive: every ``RATE_WINDOW_S`` the rate received per
   message; a message below half its requested rate ``CHECK_AFTER_S`` after it was
   accepted is asked for again (and reported once), up to ``MAX_REASKS`` times, then
   reported with the rate it arrives at (a router or link that thins it), or as not sent
   when none arrived (a GNSS-less ROV's GPS_RAW_INT), and no longer asked for;
5. sends TIMESYNC requests (``tc1`` 0, ``ts1`` the service clock in ns); the autopilot's
   answers let :class:`drivers.sender_clock.SenderClock` map its boot clock without the
   one-way link delay;
6. starts over after a reboot (the boot clock went back) or a lost link (no HEARTBEAT
   for ``LINK_LOST_S``).

Health (``rates_hz``) carries ``<input>/<MSG>:requested`` and ``<input>/<MSG>:received`` per
message. Sending goes through the input's transport (:meth:`drivers.transports.Transport.send`),
which never blocks the event loop. What the session sends is not recorded (it does not
change what the service estimates); what comes back is, as every received byte.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections import deque
from dataclasses import dataclass, field
from typing import Callable

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from onboard.drivers.mavlink_link import AutopilotLink
from onboard.drivers.transports import Transport
from onboard.core.config import Config, SourceConfig
from onboard.core.vehicles import traits
from onboard.service.signing import SigningState

log = logging.getLogger(__name__)

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_RESULT_ACCEPTED = 0
ACK_TIMEOUT_S = 1.0
ACK_TRIES = 3
CHECK_AFTER_S = 5.0
RATE_WINDOW_S = 2.0
LINK_LOST_S = 5.0
MAX_REASKS = 3
"""A message still missing or slow after this many repeated requests is reported (not
sent, or the rate it arrives at) and no longer asked for (until the next reboot or
reconnection)."""
POLL_S = 0.1
SYNC_FIRST_S = 1.0
SYNC_PERIOD_S = 10.0
"""TIMESYNC requests: three 1 s apart after (re)connecting, then every 10 s."""
ACTUATOR_RATE_HZ = 10.0
"""Requested rate of the actuator outputs, depth and INS velocity (Hz)."""

STREAM_GROUPS: dict[str, int] = {
    "SCALED_IMU": 1, "RAW_IMU": 1, "SCALED_IMU2": 1, "SCALED_IMU3": 1,
    "SCALED_PRESSURE": 1, "SCALED_PRESSURE2": 1, "SCALED_PRESSURE3": 1,
    "GPS_RAW_INT": 2, "GPS2_RAW": 2, "SYSTEM_TIME": 12,
    "RC_CHANNELS": 3, "SERVO_OUTPUT_RAW": 3,
    "GLOBAL_POSITION_INT": 6,
    "ATTITUDE": 10, "RPM": 10,
    "VFR_HUD": 11,
    "DISTANCE_SENSOR": 12,
}
"""Message -> MAV_DATA_STREAM group that carries it in ArduPilot (GCS_Common.cpp
``STREAM_*_msgs``): RAW_SENSORS (1): RAW_IMU, SCALED_IMU2/3, SCALED_PRESSURE/2/3;
EXTENDED_STATUS (2): GPS_RAW_INT, GPS2_RAW; RC_CHANNELS (3): SERVO_OUTPUT_RAW, RC_CHANNELS;
POSITION (6): GLOBAL_POSITION_INT; EXTRA1 (10): ATTITUDE, RPM; EXTRA2 (11): VFR_HUD;
EXTRA3 (12): DISTANCE_SENSOR, SYSTEM_TIME. SCALED_IMU is in no group (ArduPilot's first IMU
goes out as RAW_IMU with the same scaling); the fallback asks for RAW_SENSORS for it."""

PARAMETERS = tuple(f"SERVO{n}_FUNCTION" for n in range(1, 17)) + ("FRAME_CLASS",)
"""Parameters read from the autopilot (the actuator mapping, as replay reads it from a log)."""
PARAM_RETRY_S = 2.0
PARAM_TRIES = 3
"""A parameter not answered ``PARAM_RETRY_S`` after its request is asked again, up to
``PARAM_TRIES`` requests in all (a request or its answer lost on a UDP link; ArduPilot
leaves a name it does not have unanswered, so the asking stops)."""


def needed_streams(cfg: Config, src: SourceConfig) -> dict[str, float]:
    """The MAVLink messages (name -> Hz) the configured pipelines need from the autopilot.

    IMU (SCALED_IMU) at ``sensors.imu.rate_hz``; attitude and heading (ATTITUDE) at
    ``sensors.compass.rate_hz``; GNSS (GPS_RAW_INT) at ``sensors.gnss.rate_hz``; the
    actuator outputs the ``[inputs]`` read (SERVO_OUTPUT_RAW, RC_CHANNELS, RPM) at 10 Hz;
    underwater classes also depth (SCALED_PRESSURE2) and INS velocity
    (GLOBAL_POSITION_INT) at 10 Hz; SYSTEM_TIME at 1 Hz (the boot clock when nothing else
    flows). ``src.streams`` replaces any of these (0 drops one).
    """
    s = cfg.sensors
    out: dict[str, float] = {
        "SCALED_IMU": s.imu.rate_hz,
        "ATTITUDE": s.compass.rate_hz,
        "GPS_RAW_INT": s.gnss.rate_hz,
        "SYSTEM_TIME": 1.0,
    }
    inp = cfg.inputs
    maps = [m for m in (inp.throttle, inp.rudder, inp.left, inp.right, inp.propeller_rpm,
                        inp.stern_plane) if m is not None] + list(inp.thrusters)
    by_source = {"servo": "SERVO_OUTPUT_RAW", "rc": "RC_CHANNELS", "rpm": "RPM"}
    for m in maps:
        if m.source in by_source:
            out[by_source[m.source]] = ACTUATOR_RATE_HZ
    if traits(cfg.vehicle.vehicle_class).underwater:
        out["SCALED_PRESSURE2"] = ACTUATOR_RATE_HZ
        out["GLOBAL_POSITION_INT"] = ACTUATOR_RATE_HZ
    for name, hz in src.streams.items():
        if hz > 0:
            out[name] = float(hz)
        else:
            out.pop(name, None)
    return {k: v for k, v in out.items() if v > 0}


_IDS: dict[str, int] = {cls.msgname: mid for mid, cls in mavlink2.mavlink_map.items()}


@dataclass
class StreamState:
    """One requested message."""

    name: str
    msgid: int
    rate_hz: float
    state: str = "pending"
    """``pending`` (not asked yet), ``asked`` (waiting for the ACK), ``accepted``,
    ``legacy`` (asked with REQUEST_DATA_STREAM), ``absent`` (none arrived: given up),
    ``slow`` (arrives below half the rate asked: given up asking)."""
    tries: int = 0
    t_sent: float = -math.inf
    t_accepted: float | None = None
    received_hz: float = 0.0
    t_window: float = -math.inf
    """Start of the window :attr:`received_hz` was measured over (s)."""
    warned: bool = False
    reasks: int = 0
    """Times it was asked for again because it did not arrive."""


@dataclass
class MavlinkSession:
    """The session on one MAVLink input (see the module docstring).

    ``link`` is the input's :class:`AutopilotLink` (the parser fills it); ``transport`` the
    input's transport (to send); ``clock`` the service clock; ``on_event`` the service's
    event sink.
    """

    name: str
    cfg: Config
    src: SourceConfig
    link: AutopilotLink
    transport: Transport
    clock: Callable[[], float]
    on_event: Callable[[str], None]
    signing: SigningState | None = None
    """The service's MAVLink signing state: requests are signed with its key and
    timestamps (link id 1; MAVLink out uses 0) when it is set."""
    poll_s: float = POLL_S
    """Wall seconds between polls (the demo's sped-up clock polls as often in its time)."""
    streams: dict[str, StreamState] = field(default_factory=dict)
    sent: int = 0
    sessions: int = 0
    """How many times the streams were (re)requested from the start."""
    _mav: mavlink2.MAVLink | None = None
    _reboots: int = 0
    _lost: bool = True
    _t_rate: float | None = None
    _counts_prev: dict[int, int] = field(default_factory=dict)
    _awaiting: deque[str] = field(default_factory=deque)
    """Messages asked for whose COMMAND_ACK has not come yet, in the order asked
    (ArduPilot handles and acknowledges commands in order)."""
    _legacy_sent: dict[int, float] = field(default_factory=dict)
    _next_sync: float = -math.inf
    _syncs: int = 0
    _params_asked: dict[str, tuple[float, int]] = field(default_factory=dict)
    """Parameter -> (when last asked, requests sent) since the session (re)started."""
    _params_open: tuple[str, ...] = PARAMETERS
    """The parameters that may still be asked: not yet asked, or neither answered nor
    asked :data:`PARAM_TRIES` times (the autopilot's answers are never forgotten)."""

    def __post_init__(self) -> None:
        self._mav = mavlink2.MAVLink(None, srcSystem=self.cfg.vehicle.system_id,
                                     srcComponent=self.cfg.service.mavlink.component_id or 191)
        if self.signing is not None:
            sg = self._mav.signing
            sg.secret_key = self.signing.key
            sg.link_id = 1
            sg.timestamp = self.signing.next_tx()
            sg.sign_outgoing = True
        self.wanted = needed_streams(self.cfg, self.src)

    async def run(self) -> None:
        """Poll forever (cancelled by the service at shutdown)."""
        while True:
            try:
                self.poll(self.clock())
            except Exception:  # noqa: BLE001 - a session bug must not stop the service
                log.exception("mavlink session %s failed", self.name)
            await asyncio.sleep(self.poll_s)

    # ------------------------------------------------------------------ the state machine

    def poll(self, now: float) -> None:
        """One step: notice the autopilot, a reboot or a lost link; send what is due."""
        link = self.link
        if not link.found:
            return
        if link.t_heartbeat is not None and now - link.t_heartbeat > LINK_LOST_S:
            if not self._lost:
                self._lost = True
                self.on_event(f"{self.name}: autopilot link lost (no HEARTBEAT for "
                              f"{now - link.t_heartbeat:.0f} s)")
            return
        if self._lost:
            self._lost = False
            self._start(now, "found" if self.sessions == 0 else "back")
        elif link.reboots != self._reboots:
            self._start(now, "rebooted")
        self._acks()
        self._rates(now)
        self._send_due(now)
        self._read_params(now)
        if now >= self._next_sync:
            self._syncs += 1
            self._next_sync = now + (SYNC_FIRST_S if self._syncs < 3 else SYNC_PERIOD_S)
            self._send(self._mav.timesync_encode(0, int(now * 1e9)))  # type: ignore[union-attr]

    def _start(self, now: float, why: str) -> None:
        link = self.link
        self._reboots = link.reboots
        link.reset_streams()
        self.sessions += 1
        self.streams = {n: StreamState(n, _IDS[n], hz) for n, hz in self.wanted.items() if n in _IDS}
        self._awaiting.clear()
        self._legacy_sent.clear()
        self._syncs = 0
        self._next_sync = now
        link.acks.clear()
        self.on_event(f"{self.name}: autopilot {why}: system {link.system_id} component "
                      f"{link.component_id}, type {link.mav_type}, autopilot {link.autopilot}"
                      + ("; requesting streams" if self.src.request_streams else ""))
        vclass = self.cfg.vehicle.vehicle_class
        expect = traits(vclass).heartbeat_mav_types
        if expect and link.mav_type not in expect and why == "found":
            self.on_event(f"{self.name}: the autopilot says MAV_TYPE {link.mav_type}, "
                          f"the configuration class {vclass} (expected {sorted(expect)})")
        self._params_asked.clear()
        self._params_open = PARAMETERS
        if self.src.request_streams:
            self._read_params(now)
        else:
            for st in self.streams.values():
                st.state, st.t_accepted = "accepted", now

    def _read_params(self, now: float) -> None:
        """Ask for every parameter not yet answered whose last request is due again."""
        if not self.src.request_streams:
            return
        link = self.link
        still_open = []
        for name in self._params_open:
            t_sent, tries = self._params_asked.get(name, (-math.inf, 0))
            if tries == 0 or (name not in link.params and tries < PARAM_TRIES
                              and now - t_sent >= PARAM_RETRY_S):
                tries += 1
                self._params_asked[name] = (now, tries)
                self._send(self._mav.param_request_read_encode(  # type: ignore[union-attr]
                    link.system_id, link.component_id, name.encode(), -1))
            if name not in link.params and tries < PARAM_TRIES:
                still_open.append(name)
        self._params_open = tuple(still_open)

    def _acks(self) -> None:
        acks = self.link.acks
        while acks:
            cmd, result = acks.popleft()
            if cmd != MAV_CMD_SET_MESSAGE_INTERVAL or not self._awaiting:
                continue
            st = self.streams.get(self._awaiting.popleft())
            if st is None or st.state != "asked":
                continue
            if result == MAV_RESULT_ACCEPTED:
                st.state, st.t_accepted = "accepted", self.clock()
            else:
                self._legacy(st, f"refused (MAV_RESULT {result})")

    def _send_due(self, now: float) -> None:
        if not self.src.request_streams:
            return
        if self._awaiting:
            st = self.streams[self._awaiting[0]]
            if now - st.t_sent < ACK_TIMEOUT_S:
                return
            for name in self._awaiting:  # none of them acknowledged in time
                st = self.streams[name]
                if st.tries >= ACK_TRIES:
                    self._legacy(st, "no COMMAND_ACK")
                else:
                    st.state = "pending"
            self._awaiting.clear()
        asked = False
        for st in self.streams.values():
            if st.state == "pending":
                self._ask(st, now)
                asked = True
        if asked:
            return
        for st in self.streams.values():
            if st.state in ("accepted", "legacy") and st.t_accepted is not None \
                    and now - st.t_accepted > CHECK_AFTER_S and st.t_window >= st.t_accepted \
                    and st.received_hz < 0.5 * st.rate_hz:
                if st.reasks >= MAX_REASKS:
                    if st.received_hz > 0.0:
                        st.state = "slow"
                        self.on_event(f"{self.name}: {st.name} arrives at "
                                      f"{st.received_hz:.1f} Hz, too slow for the "
                                      f"{st.rate_hz:g} Hz requested (asked "
                                      f"{st.reasks + 1} times); no longer asked")
                    else:
                        st.state = "absent"
                        self.on_event(f"{self.name}: {st.name} not sent by the autopilot "
                                      f"(asked {st.reasks + 1} times); no longer asked")
                    continue
                if not st.warned:
                    st.warned = True
                    self.on_event(f"{self.name}: {st.name} requested at {st.rate_hz:g} Hz, "
                                  f"receiving {st.received_hz:.1f} Hz; asking again")
                st.reasks += 1
                st.tries = 0
                if st.state == "legacy":
                    self._legacy_sent.pop(STREAM_GROUPS.get(st.name, -1), None)
                    self._legacy(st, "")
                    st.t_accepted = now
                    return
                self._ask(st, now)
                return

    def _ask(self, st: StreamState, now: float) -> None:
        link = self.link
        st.tries += 1
        st.t_sent = now
        st.state = "asked"
        self._awaiting.append(st.name)
        self._send(self._mav.command_long_encode(  # type: ignore[union-attr]
            link.system_id, link.component_id, MAV_CMD_SET_MESSAGE_INTERVAL, 0,
            float(st.msgid), 1e6 / st.rate_hz, 0, 0, 0, 0, 0))

    def _legacy(self, st: StreamState, why: str) -> None:
        """Ask for ``st`` with REQUEST_DATA_STREAM of its ArduPilot group."""
        group = STREAM_GROUPS.get(st.name)
        st.state = "legacy"
        st.t_accepted = self.clock()
        if group is None:
            self.on_event(f"{self.name}: {st.name}: SET_MESSAGE_INTERVAL {why}, no stream group")
            return
        rate = max(s.rate_hz for s in self.streams.values() if STREAM_GROUPS.get(s.name) == group)
        hz = max(1, int(math.ceil(rate)))
        if self._legacy_sent.get(group) == hz:
            return
        self._legacy_sent[group] = hz
        if why:
            self.on_event(f"{self.name}: {st.name}: SET_MESSAGE_INTERVAL {why}; "
                          f"REQUEST_DATA_STREAM {group} at {hz} Hz")
        link = self.link
        self._send(self._mav.request_data_stream_encode(  # type: ignore[union-attr]
            link.system_id, link.component_id, group, hz, 1))

    def _send(self, msg: object) -> None:
        if self.signing is not None:
            sg = self._mav.signing  # type: ignore[union-attr]
            sg.timestamp = self.signing.next_tx(sg.timestamp)
        buf = msg.pack(self._mav)  # type: ignore[attr-defined]
        self._mav.seq = (self._mav.seq + 1) % 256  # type: ignore[union-attr]
        if self.transport.send(buf):
            self.sent += 1

    def _rates(self, now: float) -> None:
        if self._t_rate is None:
            self._t_rate = now
            self._counts_prev = dict(self.link.counts)
            return
        dt = now - self._t_rate
        if dt < RATE_WINDOW_S:
            return
        counts = self.link.counts
        for st in self.streams.values():
            ids = (st.msgid, _IDS["RAW_IMU"]) if st.name == "SCALED_IMU" else (st.msgid,)
            n = sum(counts.get(i, 0) - self._counts_prev.get(i, 0) for i in ids)
            st.received_hz = n / dt
            st.t_window = self._t_rate
        self._counts_prev = dict(counts)
        self._t_rate = now

    def rates(self) -> dict[str, float]:
        """``<input>/<MSG>:requested`` and ``:received`` (Hz) for health."""
        out: dict[str, float] = {}
        for st in self.streams.values():
            out[f"{self.name}/{st.name}:requested"] = st.rate_hz
            out[f"{self.name}/{st.name}:received"] = round(st.received_hz, 2)
        return out
