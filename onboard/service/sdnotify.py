"""The systemd notify protocol (sd_notify(3)) without libsystemd.

With ``Type=notify`` systemd passes ``$NOTIFY_SOCKET`` (a filesystem path, or an abstract
socket name starting with ``@``); the service sends newline-separated ``KEY=VALUE``
datagrams on an ``AF_UNIX``/``SOCK_DGRAM`` socket:

* ``READY=1`` once sensors and publishers are up (startup is complete);
* ``STATUS=...`` a one-line human-readable state, shown by ``systemctl status``;
* ``WATCHDOG=1`` keep-alive; with ``WatchdogSec=`` systemd passes ``$WATCHDOG_USEC`` and
  kills and restarts the service when no ping arrives in time. The service pings from
  its estimator loop itself (every tick checks :meth:`Notifier.watchdog`), so a stalled
  loop, not just a dead process, gets restarted;
* ``STOPPING=1`` at the start of a graceful shutdown.

Outside systemd (no ``$NOTIFY_SOCKET``) every call is a cheap no-op. A send failure is
counted, never raised.
"""

from __future__ import annotations

import os
import socket
import time
from typing import Callable, Mapping


class Notifier:
    """Talks to systemd over ``$NOTIFY_SOCKET``.

    Parameters:
        environ: the environment to read ``NOTIFY_SOCKET``, ``WATCHDOG_USEC`` and
            ``WATCHDOG_PID`` from (default ``os.environ``).
        clock: monotonic clock (s) for watchdog pacing.
    """

    def __init__(self, environ: Mapping[str, str] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        env = os.environ if environ is None else environ
        self.clock = clock
        addr = env.get("NOTIFY_SOCKET", "")
        self.address: str | bytes | None = None
        if addr.startswith("@"):
            self.address = "\0" + addr[1:]
        elif addr.startswith("/"):
            self.address = addr
        self.watchdog_s: float | None = None
        usec = env.get("WATCHDOG_USEC", "")
        pid = env.get("WATCHDOG_PID", "")
        if usec.isdigit() and int(usec) > 0 and (not pid or pid == str(os.getpid())):
            self.watchdog_s = int(usec) / 1e6
        self.sent = 0
        self.errors = 0
        self.ready_sent = False
        self._last_ping = -float("inf")
        self._sock: socket.socket | None = None
        if self.address is not None:
            try:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
                self._sock.setblocking(False)
            except OSError:
                self._sock = None

    @property
    def enabled(self) -> bool:
        """True when running under systemd with a notify socket."""
        return self._sock is not None

    @property
    def watchdog_interval_s(self) -> float | None:
        """How often to ping (half of ``WatchdogSec``), or None without a watchdog."""
        return None if self.watchdog_s is None else self.watchdog_s / 2.0

    def send(self, **fields: str | int) -> bool:
        """Send ``KEY=VALUE`` lines (keys upper-cased); False when not sent."""
        if self._sock is None or self.address is None:
            return False
        msg = "\n".join(f"{k.upper()}={_one_line(str(v))}" for k, v in fields.items())
        try:
            self._sock.sendto(msg.encode("utf-8", "replace"), self.address)
        except OSError:
            self.errors += 1
            return False
        self.sent += 1
        return True

    def ready(self, status: str = "") -> bool:
        """``READY=1`` (with a STATUS line when given)."""
        self.ready_sent = True
        if status:
            return self.send(READY=1, STATUS=status)
        return self.send(READY=1)

    def status(self, text: str) -> bool:
        """``STATUS=text``: the line ``systemctl status`` shows."""
        return self.send(STATUS=text)

    def watchdog(self, now: float | None = None) -> bool:
        """Ping the watchdog if half its interval has passed; call this every loop turn."""
        if self.watchdog_s is None or self._sock is None:
            return False
        now = self.clock() if now is None else now
        if now - self._last_ping < self.watchdog_s / 2.0:
            return False
        self._last_ping = now
        return self.send(WATCHDOG=1)

    def stopping(self, status: str = "") -> bool:
        """``STOPPING=1`` (with a STATUS line when given): the service is shutting down."""
        if status:
            return self.send(STOPPING=1, STATUS=status)
        return self.send(STOPPING=1)

    def close(self) -> None:
        """Close the notification socket; later messages are not sent."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def _one_line(text: str) -> str:
    return " ".join(text.split())[:400]
