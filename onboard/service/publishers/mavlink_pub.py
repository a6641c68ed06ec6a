"""MAVLink publisher: estimates to the autopilot and ground stations (architecture.md §4.5).

The service speaks as component 191 (MAV_COMP_ID_ONBOARD_COMPUTER) on the vehicle's
system id, MAVLink 2, by default to ``udpout:127.0.0.1:14550`` where ground stations
listen. What it sends:

=================  ===========================================================  =========
message            content                                                      rate
=================  ===========================================================  =========
HEARTBEAT          MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID,           1 Hz
                   MAV_STATE_ACTIVE (MAV_STATE_STANDBY until the first estimate)
NAMED_VALUE_FLOAT  ``CUR_N``, ``CUR_E``, ``CUR_D`` water current (m/s, NED);     rate_hz
                   ``CUR_SN``, ``CUR_SE`` its one-sigma (m/s); ``THR_EST`` surge
                   input (AIE, m/s^2 = force/mass); ``TRQ_EST`` yaw input (AIE,
                   rad/s^2 = moment/inertia); ``SPD_EST`` speed (m/s, AIE, else KF)
DEBUG_VECT         ``DIST`` ESESO disturbance force, body FRD (N);               rate_hz
                   ``DIST_NED`` the same in NED (N)
WIND_COV           the **water current** (not wind): wind_x/y/z = current        rate_hz
                   north/east/down (m/s, the direction it flows to; wind_z NaN
                   where the down is not estimated, a boat), var_horiz =
                   std_north^2 + std_east^2, var_vert = std_down^2 (m^2/s^2,
                   variances as PX4 sends them, not common.xml's 1-STD;
                   NaN if unknown), horiz_accuracy = hypot(std_north,
                   std_east), vert_accuracy = std_down (m/s, 0 if unknown),
                   wind_alt = -depth (m MSL; 0, the surface, without a depth),
                   so ground stations draw it with their wind widget
ESTIMATOR_STATUS   health: test ratios sqrt(NIS)/3 (1 = a 3-sigma innovation) of    1 Hz
                   the velocity (vel_ratio), position (pos_horiz_ratio), depth
                   (pos_vert_ratio) and heading (mag_ratio) channels; flags
                   VELOCITY_HORIZ / POS_HORIZ_REL when estimating (not while a
                   pipeline fails speed_mismatch / position_residual or
                   heading_course_mismatch or heading_source_mismatch, which
                   withhold the headings and positions), GPS_GLITCH when GNSS
                   fixes were rejected since the last report
STATUSTEXT         events (source lost or silent, state restored or corrupt),   <= 1 per
                   rate-limited by a token bucket (burst 5); the number           2 s avg
                   suppressed is reported when the bucket refills; an event
                   longer than 50 bytes is sent in chunks of one ``id``
                   (``chunk_seq`` 0, 1, ...; at most STATUSTEXT_MAX_CHUNKS),
                   which ground stations join
ODOMETRY           only with ``odometry = true``: position NED (m, from the     rate_hz
                   first fix), heading, body-frame surge speed
=================  ===========================================================  =========

Links: ``udpout:`` is a non-blocking socket; ``zenoh:PREFIX`` puts every frame on
``PREFIX/in`` of the service's Zenoh session (BlueOS's mavlink-server routes it to the
autopilot and ground stations; :class:`onboard.drivers.transports.ZenohWriter`); every
other pymavlink URL (a serial port, ``tcp:``) is written by a :class:`WriterThread`, so a full serial buffer or a stalled TCP
peer never blocks the estimator loop (frames beyond its queue are dropped and counted).

Signing: with ``signing_key_file`` every frame is signed (MAVLink 2 signing, link id 0).
The file holds the 32-byte secret as raw bytes or 64 hex digits, or a passphrase whose
SHA-256 is the key (MAVProxy's ``signing setup``). It must be readable by its owner only
(mode 0600 or stricter); otherwise the service refuses to start. ``require_signing =
true`` without a key file is a configuration error. Given the service's
:class:`onboard.service.signing.SigningState`, the timestamp of every frame comes from it: above
every timestamp sent before, across restarts, even when the wall clock went back
(docs/security.md); without one, from the wall clock at start.
"""

from __future__ import annotations

import logging
import math
import queue
import socket
import threading
import time
from typing import TYPE_CHECKING, Callable, Sequence

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from onboard.drivers.mavlink_signing import SIGNING_EPOCH, signing_timestamp
from onboard.core.config import MavlinkOut
from onboard.core.messages import EstimateRecord, HealthRecord
from onboard.service.events import severity as event_severity
from onboard.service.publishers.pacing import next_due
from onboard.service.signing import check_signing, load_signing_key

if TYPE_CHECKING:
    from onboard.service.signing import SigningState

__all__ = ["COMPONENT_ID", "MavlinkPublisher", "SIGNING_EPOCH", "WriterThread", "check_signing",
           "load_signing_key"]

log = logging.getLogger(__name__)

COMPONENT_ID = 191
NAMED_VALUES: dict[tuple[str, str], str] = {
    ("current", "north"): "CUR_N",
    ("current", "east"): "CUR_E",
    ("current", "down"): "CUR_D",
    ("current", "std_north"): "CUR_SN",
    ("current", "std_east"): "CUR_SE",
    ("aie", "surge_input"): "THR_EST",
    ("aie", "yaw_input"): "TRQ_EST",
}
"""(pipeline, quantity) -> NAMED_VALUE_FLOAT name (at most 10 characters)."""
DEBUG_VECTORS: dict[str, tuple[str, tuple[str, str, str]]] = {
    "DIST": ("eseso", ("dist_x", "dist_y", "dist_z")),
    "DIST_NED": ("eseso", ("dist_north", "dist_east", "dist_down")),
}
"""DEBUG_VECT name -> (pipeline, (x, y, z) quantities)."""
class _UdpOut:
    """A non-blocking UDP sender (``udpout:HOST:PORT``); send errors are counted."""

    def __init__(self, host: str, port: int) -> None:
        self.addr = (host, port)
        self.sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET,
                                  socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.errors = 0

    def write(self, buf: bytes) -> None:
        try:
            self.sock.sendto(buf, self.addr)
        except OSError:  # nobody listening (ICMP), buffer full: drop, never block
            self.errors += 1

    def close(self) -> None:
        self.sock.close()


class WriterThread:
    """A link whose writes may block (a serial port, TCP) written from its own thread:
    :meth:`write` only queues the frame, so the event loop never waits on a full serial
    buffer or a stalled TCP peer; beyond ``max_frames`` waiting, frames are dropped and
    counted (``dropped``); a write error is counted (``errors``) and writing goes on.

    Parameters:
        link: anything with ``write(bytes)`` and ``close()`` (a pymavlink connection).
        max_frames: frames allowed to wait.
    """

    def __init__(self, link: object, max_frames: int = 512) -> None:
        self.link = link
        self.dropped = 0
        self.errors = 0
        self.written = 0
        self._q: queue.Queue[bytes | None] = queue.Queue(max_frames)
        self._thread = threading.Thread(target=self._run, name="mavlink-out", daemon=True)
        self._thread.start()

    def write(self, buf: bytes) -> None:
        """Queue ``buf`` for the writer thread (dropped and counted when the queue is full)."""
        try:
            self._q.put_nowait(bytes(buf))
        except queue.Full:
            self.dropped += 1

    def _run(self) -> None:
        while True:
            buf = self._q.get()
            if buf is None:
                return
            try:
                self.link.write(buf)  # type: ignore[attr-defined]
                self.written += 1
            except Exception as err:  # noqa: BLE001 - a serial hiccup never stops writing
                self.errors += 1
                log.debug("mavlink out write failed: %s", err)

    def close(self, timeout: float = 2.0) -> None:
        """Stop the thread (after the frames queued, or ``timeout`` s), close the link."""
        try:
            self._q.put(None, timeout=timeout)
        except queue.Full:
            pass
        self._thread.join(timeout)
        try:
            self.link.close()  # type: ignore[attr-defined]
        except Exception:  # noqa: BLE001
            pass


def _open_link(url: str, zenoh_session: Callable[[], object | None] | None = None) -> object:
    scheme, _, rest = url.partition(":")
    if scheme == "zenoh":
        from onboard.drivers.transports import ZENOH_TX_SUFFIX, ZenohWriter, parse_url

        prefix = parse_url(url).path
        return ZenohWriter(zenoh_session or (lambda: None), f"{prefix}/{ZENOH_TX_SUFFIX}")
    if scheme in ("udpout", "udp") and rest:
        host, _, port = rest.rpartition(":")
        return _UdpOut(host or "127.0.0.1", int(port))
    from pymavlink import mavutil  # serial ports, tcp:, tcpin: ...

    return WriterThread(mavutil.mavlink_connection(url, autoreconnect=True))


RATIO_KINDS = ("heading", "depth", "velocity", "position")
"""ESTIMATOR_STATUS's test ratios: ``mag_ratio`` (heading), ``pos_vert_ratio`` (depth),
``vel_ratio`` (velocity) and ``pos_horiz_ratio`` (position)."""


def ratio_kind(channel: str) -> str | None:
    """Which ESTIMATOR_STATUS ratio an innovation channel feeds (None: none): heading and
    attitude channels the heading ratio, depth the vertical position, rates and
    velocities (Doppler speed, DVL, velocity over ground) the velocity, increments and
    positions the horizontal position."""
    c = channel.lower()
    if c.startswith(("heading", "yaw")) or c.endswith("heading") or "attitude" in c:
        return "heading"
    if "depth" in c:
        return "depth"
    if any(w in c for w in ("rate", "vel", "dvl", "vog", "water", "speed")):
        return "velocity"
    if "increment" in c or "pos" in c:
        return "position"
    return None


STATUSTEXT_BYTES = 50
"""The text of one STATUSTEXT (MAVLink's ``char[50]``)."""
STATUSTEXT_MAX_CHUNKS = 8
"""An event is sent in at most this many STATUSTEXT chunks (400 bytes: a warning with its
remedy, the configuration key and value, fits), for one token of the rate limit."""
POSITION_PIPELINES = ("aie", "kf", "eseso", "nav")
"""The pipelines whose ``north``, ``east`` are a position (m): the current's and a
glider's dive current's are the water's velocity (m/s)."""
POSITION_FLAGS = ("position_residual", "heading_course_mismatch", "heading_source_mismatch")
"""Integrity flags (:mod:`onboard.monitor.integrity`) under which ESTIMATOR_STATUS
claims no horizontal position: a position off the fixes, or positions withheld while
the heading disagrees with the course over ground."""


HEARTBEAT_PERIOD_S = 1.0
"""Period (s) of HEARTBEAT."""
ACCURACY_UNKNOWN = 0.0
"""WIND_COV's ``horiz_accuracy`` / ``vert_accuracy`` (m/s) when the sigma is not known
(common.xml: "0 if unknown"; its other fields are NaN if unknown)."""


def estimator_test_ratios(health: HealthRecord) -> dict[str, float]:
    """Per ESTIMATOR_STATUS ratio, the largest test ratio (NIS over its gate; above 1 a
    measurement is rejected) among the channels that feed it since the previous health
    record; 0 where no channel does."""
    out = dict.fromkeys(RATIO_KINDS, 0.0)
    for channels in health.innovations.values():
        for name, ch in channels.items():
            kind = ratio_kind(name)
            r = ch.test_ratio_max
            if kind is not None and r is not None and r > out[kind]:
                out[kind] = r
    return out


class MavlinkPublisher:
    """Sends estimates, health and events as MAVLink 2 (see the module docstring).

    Parameters:
        cfg: the ``[service.mavlink]`` table.
        system_id: the vehicle's MAVLink system id.
        clock: the service clock (s) used for pacing.
        signing: the service's signing state (key and persisted timestamps); None: the key
            is read from ``cfg`` and timestamps start at the wall clock.
        zenoh_session: the service's Zenoh session (None while not open), for a
            ``zenoh:`` url.
    """

    def __init__(self, cfg: MavlinkOut, system_id: int,
                 clock: Callable[[], float] = time.monotonic,
                 signing: "SigningState | None" = None,
                 zenoh_session: Callable[[], object | None] | None = None) -> None:
        self.cfg = cfg
        self.signing_state = signing
        self.zenoh_session = zenoh_session
        self.system_id = system_id
        self.clock = clock
        self.t_start = clock()
        self.link: object | None = None
        self.mav: mavlink2.MAVLink | None = None
        self.sent = 0
        self.suppressed = 0
        self._latest: dict[str, EstimateRecord] = {}
        self._next_hb = -math.inf
        self._next_est = -math.inf
        self._est_period = 1.0 / cfg.rate_hz if cfg.rate_hz > 0 else 0.2
        self._tokens = 5.0
        self._t_tokens = self.t_start
        self._text_id = 0
        self._gnss_rejected = 0
        self.signing = False

    def start(self) -> None:
        """Open the link; set up signing when a key file is configured."""
        cfg = self.cfg
        key = self.signing_state.key if self.signing_state is not None else check_signing(cfg)
        self.link = _open_link(cfg.url, self.zenoh_session)
        self.mav = mavlink2.MAVLink(self.link, srcSystem=self.system_id,
                                    srcComponent=cfg.component_id or COMPONENT_ID)
        self.mav.robust_parsing = True
        if key is not None:
            sg = self.mav.signing
            sg.secret_key = key
            sg.link_id = 0
            sg.timestamp = signing_timestamp(time.time())
            sg.sign_outgoing = True
            self.signing = True

    def _boot_ms(self, now: float) -> int:
        return int((now - self.t_start) * 1000.0) & 0xFFFFFFFF

    def _send(self, msg: object) -> None:
        if self.mav is None:
            return
        if self.signing and self.signing_state is not None:
            sg = self.mav.signing
            sg.timestamp = self.signing_state.next_tx(sg.timestamp)
        try:
            self.mav.send(msg)
            self.sent += 1
        except Exception as err:  # noqa: BLE001 - a serial hiccup never stops the loop
            log.debug("mavlink send failed: %s", err)

    def publish_estimates(self, records: Sequence[EstimateRecord], now: float | None = None) -> None:
        """Keep the newest record per pipeline; send at ``rate_hz``; heartbeat at 1 Hz."""
        now = self.clock() if now is None else now
        for r in records:
            self._latest[r.pipeline] = r
        if now >= self._next_hb:
            self._next_hb = next_due(self._next_hb, now, HEARTBEAT_PERIOD_S)
            self._heartbeat()
        if now >= self._next_est and self._latest:
            self._next_est = next_due(self._next_est, now, self._est_period)
            self._send_estimates(now)

    def _heartbeat(self) -> None:
        state = (mavlink2.MAV_STATE_ACTIVE if self._latest else mavlink2.MAV_STATE_STANDBY)
        self._send(mavlink2.MAVLink_heartbeat_message(
            mavlink2.MAV_TYPE_ONBOARD_CONTROLLER, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, state, 3))

    def _send_estimates(self, now: float) -> None:
        ms = self._boot_ms(now)
        usec = int(now * 1e6)
        lat = self._latest
        for (pipe, q), name in NAMED_VALUES.items():
            rec = lat.get(pipe)
            if rec is not None and q in rec.values:
                self._send(mavlink2.MAVLink_named_value_float_message(
                    ms, name.encode(), float(rec.values[q])))
        spd = next((lat[p].values["speed"] for p in ("aie", "kf")
                    if p in lat and "speed" in lat[p].values), None)
        if spd is not None:
            self._send(mavlink2.MAVLink_named_value_float_message(ms, b"SPD_EST", float(spd)))
        for name, (pipe, qs) in DEBUG_VECTORS.items():
            rec = lat.get(pipe)
            if rec is not None and all(q in rec.values for q in qs):
                x, y, z = (float(rec.values[q]) for q in qs)
                self._send(mavlink2.MAVLink_debug_vect_message(name.encode(), usec, x, y, z))
        cur = lat.get("current")
        if cur is not None and "north" in cur.values and "east" in cur.values:
            v, s = cur.values, cur.std
            sn, se = s.get("north", math.nan), s.get("east", math.nan)
            sd = s.get("down", math.nan)
            h_acc = math.hypot(sn, se)
            nav = lat.get("nav")
            depth = nav.values.get("depth") if nav is not None else None
            alt = -float(depth) if depth is not None else 0.0  # MSL: the surface, or -depth
            self._send(mavlink2.MAVLink_wind_cov_message(
                usec, float(v["north"]), float(v["east"]), float(v.get("down", math.nan)),
                sn * sn + se * se, sd * sd, alt,
                h_acc if math.isfinite(h_acc) else ACCURACY_UNKNOWN,
                abs(sd) if math.isfinite(sd) else ACCURACY_UNKNOWN))
        if self.cfg.odometry:
            self._odometry(usec)

    def _odometry(self, usec: int) -> None:
        src = next((self._latest[p] for p in ("kf", "aie", "nav") if p in self._latest
                    and {"north", "east", "heading"} <= self._latest[p].values.keys()), None)
        if src is None:
            return
        v = src.values
        yaw = float(v["heading"])
        q = [math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)]
        depth = float(self._latest["nav"].values.get("depth", 0.0)) if "nav" in self._latest else 0.0
        cov = [math.nan] * 21
        self._send(mavlink2.MAVLink_odometry_message(
            usec, mavlink2.MAV_FRAME_LOCAL_NED, mavlink2.MAV_FRAME_BODY_FRD,
            float(v["north"]), float(v["east"]), depth, q,
            float(v.get("speed", math.nan)), math.nan, math.nan,
            math.nan, math.nan, float(v.get("yaw_rate", math.nan)), cov, cov, 0,
            mavlink2.MAV_ESTIMATOR_TYPE_NAIVE, 0))

    def publish_health(self, health: HealthRecord, now: float | None = None) -> None:
        """ESTIMATOR_STATUS from the pipelines' innovation test ratios; STATUSTEXT for its
        events."""
        now = self.clock() if now is None else now
        ratios = estimator_test_ratios(health)
        flags = 0
        vals = {q for r in self._latest.values() for q in r.values}
        speed_flagged = any("speed_mismatch" in f for f in health.flags.values())
        if ({"speed", "north"} & vals or "current" in self._latest) and not speed_flagged:
            flags |= mavlink2.ESTIMATOR_VELOCITY_HORIZ
        position_flagged = any(code in f for f in health.flags.values()
                               for code in POSITION_FLAGS)
        placed = [r for p, r in self._latest.items() if p in POSITION_PIPELINES
                  and {"north", "east"} <= r.values.keys()]   # a withheld one has none
        if placed and not position_flagged:
            flags |= mavlink2.ESTIMATOR_POS_HORIZ_REL
        gnss_rej = sum(n for k, n in health.rejected.items() if k.startswith("gnss:"))
        if gnss_rej > self._gnss_rejected:
            flags |= mavlink2.ESTIMATOR_GPS_GLITCH
        self._gnss_rejected = gnss_rej
        acc = [r.std[q] for r in placed for q in ("north", "east") if q in r.std]
        h_acc = max(acc) if acc and not position_flagged else math.nan   # unknown, not 0
        self._send(mavlink2.MAVLink_estimator_status_message(
            int(now * 1e6), flags, ratios["velocity"], ratios["position"], ratios["depth"],
            ratios["heading"], 0.0, 0.0, float(h_acc), 0.0))
        for ev in health.events:
            self.event(ev, now=now)

    def event(self, text: str, severity: int | None = None, now: float | None = None) -> bool:
        """STATUSTEXT ``text`` (first 50 characters) if the rate limit allows; else count it.

        Default severity: the event's (:func:`onboard.service.events.severity`: WARNING for
        losses, failures and errors, INFO otherwise), as the service's log has it.
        """
        now = self.clock() if now is None else now
        self._tokens = min(5.0, self._tokens + max(0.0, now - self._t_tokens) * 0.5)
        self._t_tokens = now
        if self._tokens < 1.0:
            self.suppressed += 1
            return False
        self._tokens -= 1.0
        if severity is None:
            severity = event_severity(text)
        if self.suppressed and self._tokens >= 1.0:
            self._tokens -= 1.0
            self._send(mavlink2.MAVLink_statustext_message(
                mavlink2.MAV_SEVERITY_NOTICE, f"onboard: {self.suppressed} msgs suppressed".encode()))
            self.suppressed = 0
        self._statustext(severity, text.encode("utf-8", "replace"))
        return True

    def _statustext(self, severity: int, data: bytes) -> None:
        """``data`` as one STATUSTEXT, or, longer than :data:`STATUSTEXT_BYTES`, as chunks
        of one non-zero ``id`` (MAVLink's long-statustext: ``chunk_seq`` from 0, the last
        chunk the one with a null byte, so a chunk of exactly 50 bytes is followed by an
        empty one), at most :data:`STATUSTEXT_MAX_CHUNKS`."""
        n = STATUSTEXT_BYTES
        if len(data) <= n:
            self._send(mavlink2.MAVLink_statustext_message(severity, data))
            return
        chunks = [data[i:i + n] for i in range(0, min(len(data), n * STATUSTEXT_MAX_CHUNKS), n)]
        if len(chunks[-1]) == n and len(chunks) < STATUSTEXT_MAX_CHUNKS:
            chunks.append(b"")
        self._text_id = self._text_id % 0xFFFF + 1
        for k, chunk in enumerate(chunks):
            self._send(mavlink2.MAVLink_statustext_message(severity, chunk, id=self._text_id,
                                                           chunk_seq=k))

    def close(self) -> None:
        """Close the link; publishing afterwards sends nothing."""
        link = self.link
        self.link = None
        self.mav = None
        if link is not None:
            try:
                link.close()  # type: ignore[attr-defined]
            except Exception:  # noqa: BLE001
                pass
