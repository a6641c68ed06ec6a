"""How a real link delivers a device's frames: late, by a delay that wanders, in order.

A device on a schedule (an autopilot's streams, a GNSS receiver's epochs) sends on time to
within a millisecond; what reaches the computer that reads it has crossed a serial line, a
router or a tether, and arrives late by a delay that is never negative and fills and
drains like a queue (consecutive frames are late together; the real one also pauses now
and then, which this model leaves out). A frame sent at ``t`` arrives at ``t + d(t)``,
never before the frame sent before it:

    d(t) = max(0, mean + x(t)),   x a Gauss-Markov process of spread ``std`` and time
                                  constant ``tau`` (exact discretisation between frames)

:data:`ARDUSUB_TETHER` is the delay measured on the ArduSub tlog in ``../shared/data``
(``ardusub_small_logs/small.tlog``, SOURCE.md there: a BlueROV2's autopilot as its topside
ground station recorded it, through the tether and the companion's router). Its
``ATTITUDE`` frames (5,245 over 263 s at 20 Hz) are sent 49-51 ms apart by the
autopilot's own clock (``time_boot_ms``) and arrive, less the fastest arrival within 10 s,
1 / 7 / 20 / 32 ms late at the 5th / 50th / 95th / 99th percentile, with a lag-1
autocorrelation of 0.82 between frames 50 ms apart (about 0.25 s of memory). A companion
computer on the autopilot's serial line sees at most that (it is one hop before the
topside); a receiver's NMEA on a serial line adds the sentences' transmission time.

The simulator's devices otherwise send exactly on their grid, so a service they feed
never meets an input whose phase wanders; :class:`DelayedSink` puts such a link between a
live output of ``onboard sitl --realtime`` and its reader (``--link-delay tether``), and the
service bench (``onboard.apps.service_bench``) between its traffic and the service.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class LinkDelay:
    """The delay of a link (s): mean, spread and time constant of its wandering part."""

    mean_s: float
    std_s: float
    tau_s: float


ARDUSUB_TETHER = LinkDelay(mean_s=0.008, std_s=0.007, tau_s=0.25)
"""The ArduSub tlog's autopilot-to-topside delay (module docstring): a clipped normal of
mean 8 ms and spread 7 ms puts its 50th / 95th / 99th percentiles at 8 / 20 / 24 ms
(measured 7 / 20 / 32); 0.25 s of memory gives 0.82 between frames 50 ms apart."""


class DelayedClock:
    """Arrival times of a device's frames over a link of delay ``delay``.

    ``arrival(t)`` for send times ``t`` in increasing order returns when the frame sent at
    ``t`` (s) arrives: ``t + d(t)``, never before the previous frame's arrival.
    """

    def __init__(self, delay: LinkDelay, rng: np.random.Generator) -> None:
        self.delay = delay
        self.rng = rng
        self._x = delay.std_s * float(rng.standard_normal())
        self._t: float | None = None
        self._last = -math.inf

    def arrival(self, t: float) -> float:
        """The arrival time (s) of the frame sent at ``t`` (s)."""
        d = self.delay
        if self._t is not None and t > self._t:
            a = math.exp(-(t - self._t) / d.tau_s)
            self._x = a * self._x + d.std_s * math.sqrt(1.0 - a * a) * float(
                self.rng.standard_normal())
        self._t = t
        self._last = max(self._last, t + max(0.0, d.mean_s + self._x))
        return self._last


class DelayedSink:
    """A live output (``sitl.emitters``' UDP, TCP server or pseudo-terminal sink) whose
    frames leave as over a link of delay ``delay``: a frame written at simulation time
    ``t`` is sent ``DelayedClock.arrival(t) - t`` later than it was written, in order, from
    a thread of its own (the simulation never waits for it). What the reader sends back
    (:meth:`read`) is read at once. Every other attribute is the wrapped sink's."""

    def __init__(self, sink: Any, delay: LinkDelay, rng: np.random.Generator) -> None:
        self.sink = sink
        self._clock = DelayedClock(delay, rng)
        self._queue: queue.SimpleQueue[tuple[float, float, bytes] | None] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._base: float | None = None
        self._thread = threading.Thread(target=self._send, name="sitl-link", daemon=True)
        self._thread.start()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.sink, name)

    def write(self, t: float, frame: bytes) -> None:
        """Queue ``frame`` of simulation time ``t`` (s) for its arrival time."""
        now = time.monotonic()
        if self._base is None:
            self._base = now - t
        self._queue.put((max(now, self._base + self._clock.arrival(t)), t, frame))

    def read(self) -> bytes:
        """What the reader sent back (never blocks; empty for a sink that reads nothing)."""
        read = getattr(self.sink, "read", None)
        if read is None:
            return b""
        with self._lock:
            return read()

    def _send(self) -> None:
        while (item := self._queue.get()) is not None:
            due, t, frame = item
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            with self._lock:
                self.sink.write(t, frame)

    def close(self) -> None:
        """Send what is queued, then close the wrapped sink."""
        self._queue.put(None)
        self._thread.join()
        self.sink.close()
