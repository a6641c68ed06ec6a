"""Chart plotter publishers: the vehicle's current as set and drift (architecture.md §4.5).

=================  ===============================================  ================
output             what                                             configured by
=================  ===============================================  ================
NMEA 0183 ``VDR``  ``$IIVDR,<set T>,T,<set M>,M,<drift kn>,N*hh``  ``[service.nmea_vdr]``
                   over UDP (OpenCPN, a Signal K server's NMEA
                   0183 UDP input)
Signal K delta     ``environment.current`` {``setTrue``,          ``[service.signalk]``
                   ``setMagnetic``, ``drift``} over UDP (a
                   Signal K server's "Signal K" UDP input)
=================  ===============================================  ================

Both take the newest record of the ``current`` pipeline and send it at most ``rate_hz``
times a second, and only while its north and east are known: a component the data do not
determine, or one the integrity monitor withheld, is absent from the published record, and
then nothing is sent (a chart plotter keeps showing the last set and drift until its own
timeout, never a guessed one); nor while the newest health record flags the ``current``
pipeline (an integrity check that keeps the values but doubts them: ``nis_out_of_band``,
:mod:`onboard.monitor.integrity`). ``max_std_mps`` (0 off) also holds back a current whose
larger one-sigma is above it. The magnetic set uses the engine's declination where it is
known (:class:`onboard.core.messages.DeclinationReport`), else its field is empty (VDR)
or absent (Signal K). Signal K's timestamp is the record's ``utc`` where it carries one,
else the system clock. Sends are non-blocking and never wait on the network; a refused or
failed datagram is counted in ``errors``. The formatting is :mod:`.set_drift`'s.
"""

from __future__ import annotations

import json
import math
from abc import ABC, abstractmethod
import socket
import threading
import time
from typing import Callable, Sequence

from onboard.core.config import ConfigError, NmeaVdrOut, SignalKOut
from onboard.core.messages import EstimateRecord, HealthRecord
from onboard.service.publishers.pacing import next_due
from onboard.service.publishers.set_drift import (
    SetDrift,
    current_of,
    set_drift,
    signalk_delta,
    vdr_sentence,
)

__all__ = ["CURRENT_PIPELINE", "NmeaVdrPublisher", "SetDriftPublisher", "SignalKPublisher",
           "UdpSender", "parse_udp_url"]

CURRENT_PIPELINE = "current"
"""The pipeline whose ``north``/``east`` (and their ``std``) are the current sent."""

RESOLVE_RETRY_S = 10.0
"""Seconds between two lookups of a host name that did not resolve."""
DeclinationFn = Callable[[], "float | None"]
"""The declination in use (deg, east positive), or None while unknown."""


def parse_udp_url(url: str, key: str) -> tuple[str, int]:
    """(host, port) of ``udp:HOST:PORT``; anything else is a ConfigError naming ``key``."""
    scheme, _, rest = url.partition(":")
    host, _, port = rest.rpartition(":")
    if scheme != "udp" or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"{key}: expected udp:HOST:PORT, got {url!r}")
    return host.strip("[]"), int(port)


class UdpSender:
    """A non-blocking UDP socket to one host and port; a send that fails is counted, not
    raised. A numeric address is used at once; a host name is looked up in a thread of its
    own (a lookup may wait seconds on an unreachable DNS server, and the estimator loop must
    not), once, and again after :data:`RESOLVE_RETRY_S` while it does not resolve (the
    network not up yet); until then sends are counted in ``errors``. A broadcast address
    (``x.x.x.255``) is allowed to broadcast."""

    def __init__(self, host: str, port: int, clock: Callable[[], float] = time.monotonic) -> None:
        self.host, self.port = host, port
        self.clock = clock
        self.addr: tuple | None = None
        self.sock: socket.socket | None = None
        self.sent = 0
        self.errors = 0
        self._t_lookup = -math.inf
        self._lookup: threading.Thread | None = None

    def resolve(self) -> None:
        """Open the socket for a numeric address now, else start a lookup of the name in a
        thread (unless one runs, or failed less than :data:`RESOLVE_RETRY_S` ago)."""
        try:
            self._open(socket.getaddrinfo(self.host, self.port, type=socket.SOCK_DGRAM,
                                          flags=socket.AI_NUMERICHOST)[0])
            return
        except OSError:  # not a numeric address: a name
            pass
        now = self.clock()
        busy = self._lookup is not None and self._lookup.is_alive()
        if busy or now - self._t_lookup < RESOLVE_RETRY_S:
            return
        self._t_lookup = now
        self._lookup = threading.Thread(target=self._look_up, name="udp-lookup", daemon=True)
        self._lookup.start()

    def _look_up(self) -> None:
        try:
            self._open(socket.getaddrinfo(self.host, self.port, type=socket.SOCK_DGRAM)[0])
        except OSError:
            pass  # tried again after RESOLVE_RETRY_S

    def _open(self, info: tuple) -> None:
        family, _, _, _, addr = info
        sock = socket.socket(family, socket.SOCK_DGRAM)
        sock.setblocking(False)
        if family == socket.AF_INET and addr[0].endswith(".255"):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        self.addr, self.sock = addr, sock

    def send(self, payload: bytes) -> None:
        """Send one datagram now, or count it in ``errors``."""
        sock = self.sock
        if sock is None:
            self.resolve()
            self.errors += 1
            return
        try:
            sock.sendto(payload, self.addr)
            self.sent += 1
        except OSError:  # nobody listening (ICMP), buffer full: drop, never block
            self.errors += 1

    def close(self) -> None:
        """Close the socket."""
        if self.sock is not None:
            self.sock.close()


class SetDriftPublisher(ABC):
    """The newest known current as set and drift, at most ``rate_hz`` a second, over UDP;
    each output says how a datagram reads (:meth:`payload`).

    Parameters:
        url: ``udp:HOST:PORT``.
        key: the configuration table (named in errors).
        rate_hz: the most datagrams a second.
        max_std_mps: hold back a current whose larger one-sigma (m/s) is above this; 0 off.
        declination: the engine's declination (deg east) or None; None: always unknown.
        clock: the service clock (s) the rate is paced on.
    """

    def __init__(self, url: str, key: str, rate_hz: float, max_std_mps: float = 0.0,
                 declination: DeclinationFn | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.addr = parse_udp_url(url, f"{key}.url")
        self.period_s = 1.0 / rate_hz
        self.max_std_mps = max_std_mps
        self.declination = declination or (lambda: None)
        self.clock = clock
        self.udp: UdpSender | None = None
        self.held_back = 0
        """Records of the current not sent: unknown, flagged, or their sigma above the bound."""
        self.flags: list[str] = []
        """The integrity flags of the ``current`` pipeline in the newest health record."""
        self._next = -math.inf

    def start(self) -> None:
        """Open the socket (a host name: once it resolves, :class:`UdpSender`)."""
        self.udp = UdpSender(*self.addr, clock=self.clock)
        self.udp.resolve()

    @property
    def sent(self) -> int:
        """Datagrams sent."""
        return 0 if self.udp is None else self.udp.sent

    def publish_estimates(self, records: Sequence[EstimateRecord], now: float | None = None) -> None:
        """Send the tick's ``current`` record when its set is known and a period has passed."""
        rec = next((r for r in records if r.pipeline == CURRENT_PIPELINE), None)
        if rec is None or self.udp is None:
            return
        now = self.clock() if now is None else now
        if now < self._next:
            return
        ne = current_of(rec)
        if ne is None or self.flags or not self._precise(rec):
            self.held_back += 1
            return
        self._next = next_due(self._next, now, self.period_s)
        sd = set_drift(*ne, declination_deg=self.declination())
        self.udp.send(self.payload(sd, rec))

    def publish_health(self, h: HealthRecord) -> None:
        """Keep the ``current`` pipeline's integrity flags (nothing is sent while any)."""
        self.flags = list(h.flags.get(CURRENT_PIPELINE, ()))

    def _precise(self, rec: EstimateRecord) -> bool:
        if self.max_std_mps <= 0.0:
            return True
        std = max(rec.std.get("north", math.inf), rec.std.get("east", math.inf))
        return std <= self.max_std_mps

    @abstractmethod
    def payload(self, sd: SetDrift, rec: EstimateRecord) -> bytes:
        """The datagram of ``sd``, the set and drift of ``rec``."""

    def close(self) -> None:
        """Close the socket."""
        if self.udp is not None:
            self.udp.close()


class NmeaVdrPublisher(SetDriftPublisher):
    """``VDR`` sentences over UDP (``[service.nmea_vdr]``)."""

    def __init__(self, cfg: NmeaVdrOut, declination: DeclinationFn | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(cfg.url, "service.nmea_vdr", cfg.rate_hz, cfg.max_std_mps,
                         declination, clock)
        self.talker = cfg.talker

    def payload(self, sd: SetDrift, rec: EstimateRecord) -> bytes:
        return vdr_sentence(sd, self.talker).encode("ascii")


class SignalKPublisher(SetDriftPublisher):
    """Signal K ``environment.current`` deltas over UDP (``[service.signalk]``)."""

    def __init__(self, cfg: SignalKOut, declination: DeclinationFn | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 wall_clock: Callable[[], float] = time.time) -> None:
        super().__init__(cfg.url, "service.signalk", cfg.rate_hz, cfg.max_std_mps,
                         declination, clock)
        self.context = cfg.context
        self.label = cfg.label
        self.wall_clock = wall_clock

    def payload(self, sd: SetDrift, rec: EstimateRecord) -> bytes:
        utc = getattr(rec, "utc", None)  # EstimateRecord schema 2 carries the tick's UTC
        utc = utc if isinstance(utc, (int, float)) else self.wall_clock()
        delta = signalk_delta(sd, utc, self.context, self.label)
        return json.dumps(delta, separators=(",", ":")).encode() + b"\n"
