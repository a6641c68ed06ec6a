"""The field's current at one place as set and drift, for a chart plotter (``onboard fleet
--vdr``, ``--signalk``, ``--at``; docs/chartplotters.md).

Each vehicle's service sends its own current to a chart plotter
(:mod:`onboard.service.publishers.chartplot`). A boat that estimates none, the operator's
support boat or a mooring, can show the fleet's: the field's current where it is, now.
The place (``--at``) is

* ``LAT,LON``: a fixed place (a mooring, the survey's site); or
* ``signalk:http://HOST:PORT``: the own vessel's ``navigation.position`` as the Signal K
  server there knows it, read from its REST API (``/signalk/v1/api/vessels/self/
  navigation/position``) every :data:`POLL_PERIOD_S` in a thread of its own, so a slow
  server never holds the fleet's loop. A position whose timestamp has not moved for
  :data:`PLACE_STALE_S` is not used (the boat's GNSS lost or the server stopped).

Every :data:`CHART_PERIOD_S` the field's prediction there at this machine's clock is sent
as an NMEA 0183 ``VDR`` sentence and/or a Signal K ``environment.current`` delta for
``vessels.self``, only while both components are known (and, with ``--max-std``, their
larger sigma is within it); otherwise nothing is sent and the reason is counted
(``no_place``, ``unknown``, ``imprecise``): a plotter then times out rather than show a
guess. The magnetic set is left out (VDR's field empty, Signal K's property absent): the
fleet service knows no declination, and a plotter applies its own variation.
"""

from __future__ import annotations

import json
import math
import threading
import time
import urllib.error
import urllib.request
from typing import Callable

from onboard.core.config import ConfigError
from onboard.fleet.messages import FleetCurrent
from onboard.service.publishers.chartplot import UdpSender, parse_udp_url
from onboard.service.publishers.set_drift import set_drift, signalk_delta, vdr_sentence

__all__ = ["CHART_PERIOD_S", "FieldSetDrift", "FixedPlace", "SignalKPlace", "parse_place"]

CHART_PERIOD_S = 1.0
"""Seconds between two sends (chart plotters expect set and drift about once a second)."""
POLL_PERIOD_S = 1.0
"""Seconds between two reads of the Signal K server's own-vessel position."""
PLACE_STALE_S = 10.0
"""A Signal K position whose timestamp has not changed for this long (s) is not used."""
HTTP_TIMEOUT_S = 2.0
"""Seconds a read of the Signal K server may take."""
POSITION_PATH = "/signalk/v1/api/vessels/self/navigation/position"
"""The own vessel's position on a Signal K server's REST API."""
SIGNALK_LABEL = "onboard-fleet"
"""The deltas' source label (the vehicles' own are ``onboard``)."""


class Place:
    """Where the current is wanted."""

    def where(self) -> tuple[float, float] | None:
        """(lat, lon) in degrees, or None while unknown."""
        raise NotImplementedError

    def start(self) -> None:
        """Start following the place (nothing for a fixed one)."""

    def close(self) -> None:
        """Stop following it."""


class FixedPlace(Place):
    """A place that does not move."""

    def __init__(self, lat_deg: float, lon_deg: float) -> None:
        self.lat, self.lon = lat_deg, lon_deg

    def where(self) -> tuple[float, float]:
        return self.lat, self.lon

    def __str__(self) -> str:
        return f"{self.lat:.6f},{self.lon:.6f}"


class SignalKPlace(Place):
    """The own vessel's position on a Signal K server, read in a thread (module docstring).

    Attributes:
        reads: answers read with a position in them.
        problem: why the last read gave no position (None after a good one).
    """

    def __init__(self, base_url: str, period_s: float = POLL_PERIOD_S,
                 stale_s: float = PLACE_STALE_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.url = base_url.rstrip("/") + POSITION_PATH
        self.period_s, self.stale_s, self.clock = period_s, stale_s, clock
        self.reads = 0
        self.problem: str | None = "not read yet"
        self._lock = threading.Lock()
        self._position: tuple[float, float] | None = None
        self._stamp: object = None
        self._moved = -math.inf   # clock() when the position's timestamp last changed
        self._stop = threading.Event()

    def start(self) -> None:
        """Start reading the position in a thread."""
        threading.Thread(target=self._poll, name="signalk-place", daemon=True).start()

    def where(self) -> tuple[float, float] | None:
        with self._lock:
            if self._position is None or self.clock() - self._moved > self.stale_s:
                return None
            return self._position

    def read(self) -> None:
        """Read the position once (the thread does every ``period_s``)."""
        try:
            with urllib.request.urlopen(self.url, timeout=HTTP_TIMEOUT_S) as r:
                doc = json.load(r)
            pos = position_of(doc)
        except urllib.error.HTTPError as err:
            self.problem = f"{self.url}: HTTP {err.code}"
            return
        except (urllib.error.URLError, OSError, ValueError) as err:
            self.problem = f"{self.url}: {getattr(err, 'reason', err)}"
            return
        stamp = doc.get("timestamp")
        with self._lock:
            if stamp != self._stamp or self._position is None:
                self._stamp, self._moved = stamp, self.clock()
            self._position = pos
            still = self.clock() - self._moved
        self.reads += 1
        self.problem = (f"its position not updated for {still:.0f} s"
                        if still > self.stale_s else None)

    def _poll(self) -> None:
        while True:
            self.read()
            if self._stop.wait(self.period_s):
                return

    def close(self) -> None:
        self._stop.set()

    def __str__(self) -> str:
        return f"the own vessel on {self.url.removesuffix(POSITION_PATH)}"


def position_of(doc: object) -> tuple[float, float]:
    """(lat, lon) of a Signal K ``navigation.position`` answer ``{"value": {"latitude":
    .., "longitude": ..}, "timestamp": ..}``; ValueError when it holds no real place."""
    value = doc.get("value") if isinstance(doc, dict) else None
    if not isinstance(value, dict):
        raise ValueError("no position in the answer")
    lat, lon = value.get("latitude"), value.get("longitude")
    if not all(isinstance(x, (int, float)) and math.isfinite(x) for x in (lat, lon)):
        raise ValueError(f"not a position: {value!r}")
    if abs(lat) > 90.0 or abs(lon) > 180.0:
        raise ValueError(f"not a position: {value!r}")
    return float(lat), float(lon)


def parse_place(text: str) -> Place:
    """The place of ``--at``: ``LAT,LON`` (degrees) or ``signalk:http://HOST:PORT``;
    ValueError saying what is wrong."""
    if text.startswith("signalk:"):
        url = text.removeprefix("signalk:")
        if not url.startswith(("http://", "https://")):
            raise ValueError(f"{text!r}: expected signalk:http://HOST:PORT")
        return SignalKPlace(url)   # started by FieldSetDrift.start
    try:
        lat, lon = (float(x) for x in text.split(","))
    except ValueError:
        raise ValueError(f"{text!r}: expected LAT,LON (degrees) or "
                         "signalk:http://HOST:PORT") from None
    if not (math.isfinite(lat) and math.isfinite(lon) and abs(lat) <= 90.0
            and abs(lon) <= 180.0):
        raise ValueError(f"{text!r}: a latitude within +-90 and a longitude within +-180")
    return FixedPlace(lat, lon)


def udp_output(url: str, flag: str) -> UdpSender:
    """A :class:`UdpSender` to ``udp:HOST:PORT`` (opened by :meth:`FieldSetDrift.start`);
    ValueError naming ``flag``."""
    try:
        return UdpSender(*parse_udp_url(url, flag))
    except ConfigError as err:
        raise ValueError(str(err)) from None


class FieldSetDrift:
    """The field's current at a :class:`Place` as set and drift over UDP (module docstring).

    Parameters:
        predict: the field at (lat, lon, utc) as a :class:`FleetCurrent`.
        place: where.
        vdr: where the ``VDR`` sentences go, or None.
        signalk: where the Signal K deltas go, or None.
        max_std_mps: hold back a current whose larger one-sigma (m/s) is above this; 0 off.
        clock: the UTC clock (s since the Unix epoch) the field is asked at.

    Attributes:
        sent: currents sent (a sentence and a delta of one current count once).
        held_back: currents not sent, by reason.
    """

    def __init__(self, predict: Callable[[float, float, float], FleetCurrent], place: Place,
                 vdr: UdpSender | None = None, signalk: UdpSender | None = None,
                 max_std_mps: float = 0.0, clock: Callable[[], float] = time.time) -> None:
        self.predict, self.place = predict, place
        self.vdr, self.signalk = vdr, signalk
        self.max_std_mps, self.clock = max_std_mps, clock
        self.sent = 0
        self.held_back: dict[str, int] = {}

    def start(self) -> None:
        """Open the sockets and start following the place."""
        for out in (self.vdr, self.signalk):
            if out is not None:
                out.resolve()
        self.place.start()

    def send(self) -> str:
        """Send the current at the place now; return ``sent`` or why it was held back."""
        where = self.place.where()
        if where is None:
            return self._hold("no_place")
        utc = self.clock()
        here = self.predict(*where, utc)
        if here.north is None or here.east is None:
            return self._hold("unknown")
        if self.max_std_mps > 0.0 and max(here.std_north, here.std_east) > self.max_std_mps:
            return self._hold("imprecise")
        sd = set_drift(here.north, here.east)
        if self.vdr is not None:
            self.vdr.send(vdr_sentence(sd).encode("ascii"))
        if self.signalk is not None:
            delta = signalk_delta(sd, utc, "vessels.self", SIGNALK_LABEL)
            self.signalk.send(json.dumps(delta, separators=(",", ":")).encode() + b"\n")
        self.sent += 1
        return "sent"

    def _hold(self, why: str) -> str:
        self.held_back[why] = self.held_back.get(why, 0) + 1
        return why

    def summary(self) -> str:
        """``set and drift: 12 sent; held back: unknown 3`` for the service's line."""
        held = ", ".join(f"{k} {n:,}" for k, n in sorted(self.held_back.items()))
        failed = sum(out.errors for out in (self.vdr, self.signalk) if out is not None)
        problem = getattr(self.place, "problem", None)
        return (f"set and drift: {self.sent:,} sent" + (f"; held back: {held}" if held else "")
                + (f"; {failed:,} datagrams failed" if failed else "")
                + (f"; no place: {problem}" if problem else ""))

    def close(self) -> None:
        """Stop following the place; close the sockets."""
        self.place.close()
        for out in (self.vdr, self.signalk):
            if out is not None:
                out.close()
