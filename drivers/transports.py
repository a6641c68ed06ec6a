"""Async byte transports: serial ports (real and pseudo-terminals), UDP, TCP and Zenoh.

Every transport is an async iterator of ``(data, t_rx)``: a chunk of bytes exactly as
received and its receive time ``t_rx`` in seconds on the caller's clock (default
:func:`time.monotonic`). Transports know nothing of protocols; a stream parser
(:mod:`drivers.protocols`) turns the chunks into samples.

URLs (:class:`onboard.core.config.SourceConfig`)::

    serial:/dev/ttyUSB0:115200    a serial port at 115200 baud (8N1, raw; default 115200)
    pty:/tmp/gps                  a pseudo-terminal (or any tty) by path; baud ignored
    udp:0.0.0.0:14551             listen for datagrams on this address
    tcp:192.168.2.95:16171        connect as a TCP client
    gpsd://127.0.0.1:2947         a TCP client of gpsd that sends ?WATCH on every connection
                                  (port 2947 when omitted; also gpsd:HOST:PORT)
    zenoh:mavlink_raw             MAVLink frames over Zenoh as BlueOS's mavlink-server carries
                                  them: received on ``<prefix>/out``, sent on ``<prefix>/in``
                                  (:class:`ZenohTransport`; the session is the caller's)

A port that disappears (USB serial unplugged, the pty's other end closed, TCP peer gone,
UDP bind failing) never ends the iteration: the transport counts the loss, waits with
exponential backoff (``backoff_initial_s`` doubling up to ``backoff_max_s``, reset after a
connection that lasted ``backoff_reset_s``) and opens it again. The only way out is
cancelling the task that iterates.

Faults that give no error are found too:

* ``idle_timeout_s``: a connection that delivers no byte for this long is closed and
  opened again (``lost (idle: no data for N s)``): a TCP instrument that power-cycled
  (its old connection is never closed), a peer that vanished without a FIN (half-open),
  a serial device re-enumerated behind a ``/dev/serial/by-id`` link that left the old
  descriptor silent;
* TCP keepalive (idle :data:`KEEPALIVE_IDLE_S`, then :data:`KEEPALIVE_COUNT` probes every
  :data:`KEEPALIVE_INTERVAL_S`) and ``TCP_USER_TIMEOUT`` make the kernel drop a half-open
  connection even without an idle timeout;
* a serial port is always reopened by the path given, so a ``/dev/serial/by-id/...``
  link re-pointed to a new device node after a USB re-enumeration is followed.

Serial and pty reads use pyserial to configure the port (raw, non-blocking) and
``loop.add_reader`` on its file descriptor, so no thread and no serial_asyncio.

Besides iterating, a consumer can have the chunks delivered: :meth:`Transport.pump` calls
``sink(data, t_rx)`` for every chunk, with the same reconnection. UDP and serial ports call
the sink from the read callback itself, without waking a task per chunk (the service's
intake runs so, at a fraction of the CPU time of the iteration); TCP iterates.

A UDP transport pumped with a :class:`Poller` is not read per datagram at all: its socket
stays in the kernel's queue until the consumer calls :meth:`Poller.drain` (the service: at
each tick), which reads every queued datagram with non-blocking ``recvmsg`` until there is
none, each stamped with the time the kernel received it (``SO_TIMESTAMPNS``) on the
transport's clock; between :meth:`Poller.watch` and :meth:`Poller.unwatch` a datagram wakes
the loop, which drains at once (the service: while a tick waits for a fresh sample);
:meth:`Poller.wait` blocks for a datagram, the loop with it, for a bounded time (the
service: for a sample due within a millisecond or two). One wake-up then serves every
datagram queued since the last, and the stamps are the same as if each had been read the
moment it arrived (closer: they leave out the wake-up's delay).

:meth:`Transport.send` writes back on the open connection (the service asks the autopilot
for its streams): to the serial port, to the TCP server, or to the address the last
datagram came from on UDP (as a ground station answers an autopilot). It never blocks: what
the connection cannot take now is queued up to ``TX_QUEUE_BYTES`` and the rest dropped and
counted (``stats.tx_dropped``).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import math
import os
import platform
import select
import socket
import struct
import sys
import time
from collections import deque
from dataclasses import dataclass, field
from typing import AsyncIterator, Awaitable, Callable, Literal, TypeVar

from onboard.drivers.gpsd import DEFAULT_PORT, WATCH

T = TypeVar("T")
Clock = Callable[[], float]
Chunk = tuple[bytes, float]

READ_SIZE = 65536
"""Largest read per wake-up (bytes)."""
GPSD_PORT = DEFAULT_PORT
"""gpsd's TCP port, when a gpsd URL gives none."""
GPSD_WATCH = WATCH
"""What a gpsd client sends to receive JSON reports (gpsd_json(5); drivers/gpsd.py)."""
KEEPALIVE_IDLE_S = 5
"""TCP keepalive: seconds of silence before the first probe."""
KEEPALIVE_INTERVAL_S = 2
"""TCP keepalive: seconds between probes."""
KEEPALIVE_COUNT = 3
"""TCP keepalive: unanswered probes before the kernel drops the connection."""
USER_TIMEOUT_MS = 10000
"""TCP_USER_TIMEOUT: how long sent data may stay unacknowledged (ms)."""
DEFAULT_IDLE_TIMEOUT_S = {"tcp": 10.0, "gpsd": 10.0}
"""The idle timeout when the configuration gives none, per scheme (others: never)."""
TX_QUEUE_BYTES = 65536
"""Most bytes queued for sending on one connection; beyond it a send is dropped."""
ZENOH_KEY_WILDCARDS = "*$?#"
"""Characters a Zenoh key prefix of a ``zenoh:`` URL may not contain."""
ZENOH_RX_SUFFIX = "out"
"""mavlink-server publishes every MAVLink frame it routes on ``<prefix>/out``."""
ZENOH_TX_SUFFIX = "in"
"""mavlink-server injects the bytes it receives on ``<prefix>/in`` into its router."""
ZENOH_MAVLINK_ENCODING = "application/octet-stream;mavlink"
"""The encoding of raw MAVLink frames (mavlink-server's ``mavlink_raw/out``)."""
SESSION_POLL_S = 0.1
"""How often (s) a Zenoh transport looks whether the caller's session is open yet."""


POLL_BATCH = 1024
"""Most datagrams one :meth:`Poller.drain` reads from one socket (the rest wait for the
next drain), so that a flood cannot hold the event loop."""
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
"""Linux's socket option (and control message type, ``SCM_TIMESTAMPNS``) that stamps each
datagram with the system clock when the kernel received it, as a ``struct timespec``
(asm-generic/socket.h: 35 on every architecture but SPARC and PA-RISC; Python's socket
module names it from 3.12 on)."""
KERNEL_STAMPS = (sys.platform.startswith("linux") and hasattr(socket.socket, "recvmsg")
                 and not platform.machine().startswith(("sparc", "parisc")))
"""Whether datagrams carry their kernel receive time (Linux): a UDP transport is drained
by a :class:`Poller` only then (else it is read per datagram)."""
_TIMESPEC = struct.Struct("@ll")
"""``struct timespec`` (seconds, nanoseconds) of an ``SCM_TIMESTAMPNS`` message."""
_ANC_SIZE = socket.CMSG_SPACE(_TIMESPEC.size) if KERNEL_STAMPS else 0


class IdleTimeout(OSError):
    """A connection delivered nothing for its idle timeout."""


class SinkError(Exception):
    """An exception raised by the sink of :meth:`Transport.pump` (a bug in the consumer,
    not a lost connection): ends the pump with the original as ``__cause__``."""


class TransportUrlError(ValueError):
    """A source URL that does not parse."""


@dataclass(frozen=True)
class TransportSpec:
    """A parsed source URL."""

    scheme: Literal["serial", "pty", "udp", "tcp", "gpsd", "zenoh"]
    path: str = ""
    host: str = ""
    port: int = 0
    baud: int = 115200

    def __str__(self) -> str:
        if self.scheme == "serial":
            return f"serial:{self.path}:{self.baud}"
        if self.scheme in ("pty", "zenoh"):
            return f"{self.scheme}:{self.path}"
        if self.scheme == "gpsd":
            return f"gpsd://{self.host}:{self.port}"
        return f"{self.scheme}:{self.host}:{self.port}"


def parse_url(url: str) -> TransportSpec:
    """Parse a source URL (see the module docstring); raise TransportUrlError."""
    scheme, sep, rest = url.partition(":")
    if not sep or not rest:
        raise TransportUrlError(f"{url!r}: expected scheme:address (serial:, pty:, udp:, tcp:)")
    if scheme == "serial":
        path, _, baud = rest.rpartition(":")
        if not path or not baud.isdigit():  # no baud; or a by-path name with colons
            path, baud = rest, "115200"   # (give the baud explicitly for such names)
        b = int(baud)
        if b <= 0:
            raise TransportUrlError(f"{url!r}: baud rate must be positive")
        return TransportSpec("serial", path=path, baud=b)
    if scheme == "pty":
        return TransportSpec("pty", path=rest)
    if scheme == "zenoh":
        prefix = rest.strip("/")
        if not prefix or any(c in prefix for c in ZENOH_KEY_WILDCARDS) or "//" in prefix:
            raise TransportUrlError(f"{url!r}: expected zenoh:PREFIX, a Zenoh key without "
                                    "wildcards (e.g. zenoh:mavlink_raw)")
        return TransportSpec("zenoh", path=prefix)
    if scheme == "gpsd":
        rest = rest.removeprefix("//")
        if not rest.rpartition(":")[2].isdigit():  # no port given
            rest = f"{rest or 'localhost'}:{GPSD_PORT}"
    if scheme in ("udp", "tcp", "gpsd"):
        host, _, port = rest.rpartition(":")
        try:
            p = int(port)
        except ValueError:
            raise TransportUrlError(f"{url!r}: port {port!r} is not an integer") from None
        if not host or not 0 <= p <= 65535:
            raise TransportUrlError(f"{url!r}: expected {scheme}:HOST:PORT")
        return TransportSpec(scheme, host=host.strip("[]"), port=p)  # type: ignore[arg-type]
    raise TransportUrlError(f"{url!r}: unknown scheme {scheme!r} (serial, pty, udp, tcp, gpsd, "
                            "zenoh)")


@dataclass
class TransportStats:
    """What a transport has seen; read by the service for health."""

    chunks: int = 0
    bytes: int = 0
    connects: int = 0
    disconnects: int = 0
    dropped_chunks: int = 0
    """Chunks lost because the consumer fell behind (bounded internal queue)."""
    last_error: str = ""
    connected: bool = False
    t_last_rx: float | None = None
    errors: list[str] = field(default_factory=list)
    tx_bytes: int = 0
    """Bytes handed to the connection by :meth:`Transport.send`."""
    tx_dropped: int = 0
    """Sends refused: no connection (or no UDP peer yet), or the queue full."""


class Transport:
    """Base: reconnect loop with exponential backoff around one connection attempt.

    Subclasses implement :meth:`_session`, an async generator of chunks for one
    connection that returns (or raises OSError) when the connection is lost.
    """

    def __init__(self, spec: TransportSpec, *, clock: Clock = time.monotonic,
                 backoff_initial_s: float = 0.1, backoff_max_s: float = 5.0,
                 backoff_reset_s: float = 5.0, queue_size: int = 1024,
                 on_event: Callable[[str], None] | None = None,
                 idle_timeout_s: float | None = None) -> None:
        """``idle_timeout_s``: close and reopen a connection silent this long (s); None:
        :data:`DEFAULT_IDLE_TIMEOUT_S` of the scheme; 0: never."""
        self.spec = spec
        if idle_timeout_s is None:
            idle_timeout_s = DEFAULT_IDLE_TIMEOUT_S.get(spec.scheme, 0.0)
        self.idle_timeout_s = idle_timeout_s
        self.clock = clock
        self.backoff_initial_s = backoff_initial_s
        self.backoff_max_s = backoff_max_s
        self.backoff_reset_s = backoff_reset_s
        self.queue_size = queue_size
        self.stats = TransportStats()
        self._on_event = on_event
        self._tx: Callable[[bytes], bool] | None = None
        self._t_wall_rx = 0.0

    def send(self, data: bytes) -> bool:
        """Write ``data`` on the open connection without blocking; False (counted in
        ``stats.tx_dropped``) when there is none or it cannot take it."""
        tx = self._tx
        ok = False
        if tx is not None:
            try:
                ok = tx(data)
            except OSError:
                ok = False
        if ok:
            self.stats.tx_bytes += len(data)
        else:
            self.stats.tx_dropped += 1
        return ok

    def drained_by(self, poller: "Poller | None") -> bool:
        """Whether :meth:`pump` with ``poller`` leaves the reading to its drains."""
        return False

    def _event(self, text: str) -> None:
        if self._on_event is not None:
            self._on_event(text)

    async def __aiter__(self) -> AsyncIterator[Chunk]:
        delay = self.backoff_initial_s
        while True:
            t_open = time.monotonic()
            try:
                async with contextlib.aclosing(self._session()) as session:
                    async for chunk in session:
                        yield chunk
                reason = "closed by peer"
            except (OSError, EOFError, ValueError) as err:  # serial.SerialException is OSError
                reason = _describe(err)
            except (asyncio.CancelledError, GeneratorExit):
                self.stats.connected = False
                raise
            delay = await self._retry(reason, t_open, delay)

    async def pump(self, sink: Callable[[bytes, float], None],
                   poller: "Poller | None" = None) -> None:
        """Call ``sink(data, t_rx)`` for every chunk, in order, forever: the chunks and the
        reconnection of the iteration, delivered by the read callback itself where the
        transport has one (UDP, serial), so that no task wakes per chunk.

        With ``poller``, a UDP transport (where the kernel stamps datagrams,
        :data:`KERNEL_STAMPS`) is read only when the poller drains it (see the module
        docstring); other transports ignore it.

        The sink runs on the event loop and must not block. An exception it raises ends
        the pump with :class:`SinkError` (from the original). Only cancelling the task
        stops it otherwise.
        """
        delay = self.backoff_initial_s
        while True:
            t_open = time.monotonic()
            try:
                await self._pump_session(sink, poller)
                reason = "closed by peer"
            except SinkError:
                self.stats.connected = False
                raise
            except (OSError, EOFError, ValueError) as err:
                reason = _describe(err)
            except asyncio.CancelledError:
                self.stats.connected = False
                raise
            delay = await self._retry(reason, t_open, delay)

    async def _pump_session(self, sink: Callable[[bytes, float], None],
                            poller: "Poller | None" = None) -> None:
        """One connection of :meth:`pump`; by default the iteration of :meth:`_session`."""
        async with contextlib.aclosing(self._session()) as session:
            async for data, t_rx in session:
                try:
                    sink(data, t_rx)
                except Exception as err:  # noqa: BLE001 - the consumer's bug, not the link's
                    raise SinkError(f"sink failed: {err!r}") from err

    def _deliverer(self, sink: Callable[[bytes, float], None],
                   fail: Callable[[BaseException], None]) -> Callable[[bytes, float], None]:
        """``(data, t_rx) ->`` count the chunk and hand it to ``sink``; a sink exception
        goes to ``fail`` as a :class:`SinkError`."""
        stats = self.stats
        failed = False
        watch = self.idle_timeout_s > 0
        self._t_wall_rx = time.monotonic()

        def deliver(data: bytes, t_rx: float) -> None:
            nonlocal failed
            if failed:
                return
            stats.chunks += 1
            stats.bytes += len(data)
            stats.t_last_rx = t_rx
            if watch:
                self._t_wall_rx = time.monotonic()
            try:
                sink(data, t_rx)
            except Exception as err:  # noqa: BLE001 - the consumer's bug, not the link's
                failed = True
                e = SinkError(f"sink failed: {err!r}")
                e.__cause__ = err
                fail(e)
        return deliver

    async def _until_lost(self, lost: asyncio.Future[None]) -> None:
        """Wait for ``lost`` (raises what ended the connection); with an idle timeout,
        raise :class:`IdleTimeout` once no chunk came for ``idle_timeout_s`` wall seconds
        (as the iteration does)."""
        idle = self.idle_timeout_s
        if idle <= 0:
            await lost
            return
        while True:
            remaining = self._t_wall_rx + idle - time.monotonic()
            if remaining <= 0:
                raise IdleTimeout(errno.ETIMEDOUT, f"idle: no data for {idle:g} s")
            await asyncio.wait((lost,), timeout=remaining)
            if lost.done():
                lost.result()
                return

    async def _retry(self, reason: str, t_open: float, delay: float) -> float:
        """After a session ended for ``reason``: count and report it, wait ``delay``;
        return the next delay (exponential backoff, reset after a long session)."""
        was_connected = self.stats.connected
        self.stats.connected = False
        if was_connected:
            self.stats.disconnects += 1
            self._event(f"{self.spec}: lost ({reason})")
        elif reason != self.stats.last_error:  # first failure, or a different one
            self._event(f"{self.spec}: cannot open ({reason}); retrying")
        self.stats.last_error = reason
        if time.monotonic() - t_open >= self.backoff_reset_s:
            delay = self.backoff_initial_s
        await asyncio.sleep(delay)
        return min(delay * 2.0, self.backoff_max_s)

    async def _idle(self, aw: Awaitable[T]) -> T:
        """Await ``aw`` for at most ``idle_timeout_s`` (when set); raise IdleTimeout."""
        if self.idle_timeout_s > 0:
            # asyncio.timeout, not wait_for: Python 3.11's wait_for can swallow a
            # cancellation that comes as the data does, and the service's stop would wait
            # on this read (CPython gh-86296)
            try:
                async with asyncio.timeout(self.idle_timeout_s):
                    return await aw
            except TimeoutError:
                raise IdleTimeout(errno.ETIMEDOUT,
                                  f"idle: no data for {self.idle_timeout_s:g} s") from None
        return await aw

    def _connected(self) -> None:
        self.stats.connected = True
        self.stats.connects += 1
        self._event(f"{self.spec}: connected")

    def _count(self, data: bytes, t_rx: float) -> Chunk:
        self.stats.chunks += 1
        self.stats.bytes += len(data)
        self.stats.t_last_rx = t_rx
        return data, t_rx

    async def _session(self) -> AsyncIterator[Chunk]:  # pragma: no cover - abstract
        raise NotImplementedError
        yield  # noqa


def _describe(err: BaseException) -> str:
    if isinstance(err, IdleTimeout):
        return err.strerror
    if isinstance(err, OSError) and err.errno is not None:
        return f"{errno.errorcode.get(err.errno, err.errno)}: {err.strerror}"
    return str(err) or type(err).__name__


class _Mailbox:
    """A bounded hand-off from a loop callback to the iterating coroutine."""

    def __init__(self, size: int, stats: TransportStats) -> None:
        self._q: deque[Chunk | BaseException] = deque()
        self._size = size
        self._stats = stats
        self._waiter: asyncio.Future[None] | None = None

    def put(self, item: Chunk | BaseException) -> None:
        if not isinstance(item, BaseException) and len(self._q) >= self._size:
            self._stats.dropped_chunks += 1
            return
        self._q.append(item)
        w = self._waiter
        if w is not None and not w.done():
            w.set_result(None)

    async def get(self) -> Chunk:
        while not self._q:
            self._waiter = asyncio.get_running_loop().create_future()
            try:
                await self._waiter
            finally:
                self._waiter = None
        item = self._q.popleft()
        if isinstance(item, BaseException):
            raise item
        return item


class SerialTransport(Transport):
    """A serial port or pseudo-terminal, read with ``loop.add_reader`` (no thread).

    The port is opened with pyserial (raw mode, 8N1, non-blocking). End of file or an I/O
    error (the device unplugged, the pty master closed) ends the session; the port is
    then reopened with backoff, which also covers a device that is not there yet.
    """

    async def _session(self) -> AsyncIterator[Chunk]:
        box = _Mailbox(self.queue_size, self.stats)
        port, fd = self._open_port(lambda data, t_rx: box.put((data, t_rx)), box.put)
        try:
            while True:
                data, t_rx = await self._idle(box.get())
                yield self._count(data, t_rx)
        finally:
            self._close_port(port, fd)

    async def _pump_session(self, sink: Callable[[bytes, float], None],
                            poller: "Poller | None" = None) -> None:
        lost: asyncio.Future[None] = asyncio.get_running_loop().create_future()

        def fail(err: BaseException) -> None:
            if not lost.done():
                lost.set_exception(err)

        port, fd = self._open_port(self._deliverer(sink, fail), fail)
        try:
            await self._until_lost(lost)
        finally:
            self._close_port(port, fd)

    def _open_port(self, deliver: Callable[[bytes, float], None],
                   fail: Callable[[BaseException], None]) -> tuple[object, int]:
        """Open the port; read it with ``loop.add_reader``: chunks to ``deliver``, the
        end (EOF, I/O error) to ``fail``. Returns (pyserial port, fd)."""
        import serial  # pyserial

        spec = self.spec
        if not os.path.exists(spec.path):
            raise FileNotFoundError(errno.ENOENT, "no such device", spec.path)
        port = serial.Serial()
        port.port = spec.path
        port.baudrate = spec.baud
        port.timeout = 0
        port.exclusive = spec.scheme == "serial"
        try:
            port.open()
        except serial.SerialException as err:
            raise OSError(errno.EIO, str(err)) from None
        fd = port.fileno()
        loop = asyncio.get_running_loop()
        clock = self.clock

        def readable() -> None:
            try:
                data = os.read(fd, READ_SIZE)
            except BlockingIOError:
                return
            except OSError as err:
                loop.remove_reader(fd)
                fail(err)
                return
            if not data:
                loop.remove_reader(fd)
                fail(EOFError("end of file"))
                return
            deliver(data, clock())

        loop.add_reader(fd, readable)
        pending = bytearray()

        def flush() -> None:
            try:
                n = os.write(fd, pending)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                pending.clear()
                loop.remove_writer(fd)
                return
            del pending[:n]
            if not pending:
                loop.remove_writer(fd)

        def tx(data: bytes) -> bool:
            if len(pending) + len(data) > TX_QUEUE_BYTES:
                return False
            idle = not pending
            pending.extend(data)
            if idle:
                flush()
                if pending:
                    loop.add_writer(fd, flush)
            return True

        self._tx = tx
        self._connected()
        return port, fd

    def _close_port(self, port: object, fd: int) -> None:
        self._tx = None
        loop = asyncio.get_running_loop()
        loop.remove_reader(fd)
        loop.remove_writer(fd)
        try:
            port.close()  # type: ignore[attr-defined]
        except Exception:  # noqa: BLE001 - closing a vanished device may fail
            pass


class _UdpProtocol(asyncio.DatagramProtocol):
    def __init__(self, deliver: Callable[[bytes, float], None],
                 fail: Callable[[BaseException], None], clock: Clock) -> None:
        self.deliver = deliver
        self.fail = fail
        self.clock = clock
        self.peer: object | None = None
        """Where the last datagram came from: where :meth:`Transport.send` answers."""

    def datagram_received(self, data: bytes, addr: object) -> None:
        self.peer = addr
        self.deliver(data, self.clock())

    def error_received(self, exc: Exception) -> None:  # ICMP errors: not fatal for a listener
        pass

    def connection_lost(self, exc: Exception | None) -> None:
        self.fail(exc if exc is not None else EOFError("socket closed"))


class UdpTransport(Transport):
    """Listens for datagrams on ``host:port``; each datagram is one chunk."""

    def drained_by(self, poller: "Poller | None") -> bool:
        return poller is not None and KERNEL_STAMPS

    async def _session(self) -> AsyncIterator[Chunk]:
        box = _Mailbox(self.queue_size, self.stats)
        transport = await self._bind(lambda data, t_rx: box.put((data, t_rx)), box.put)
        try:
            while True:
                data, t_rx = await box.get()
                yield self._count(data, t_rx)
        finally:
            self._tx = None
            transport.close()

    async def _pump_session(self, sink: Callable[[bytes, float], None],
                            poller: "Poller | None" = None) -> None:
        lost: asyncio.Future[None] = asyncio.get_running_loop().create_future()

        def fail(err: BaseException) -> None:
            if not lost.done():
                lost.set_exception(err)

        if self.drained_by(poller):
            assert poller is not None
            await self._polled_session(self._deliverer(sink, fail), lost, poller)
            return
        transport = await self._bind(self._deliverer(sink, fail), fail)
        try:
            await self._until_lost(lost)
        finally:
            self._tx = None
            transport.close()

    async def _polled_session(self, deliver: Callable[[bytes, float], None],
                              lost: asyncio.Future[None], poller: "Poller") -> None:
        """One binding of the socket, read by ``poller``'s drains (stamped by the kernel);
        sends answer the last datagram's sender."""
        sock = self._socket()
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        polled = _PolledSocket(sock, deliver, poller.clock())

        def tx(data: bytes) -> bool:
            if polled.peer is None:
                return False
            try:
                sock.sendto(data, polled.peer)
            except (BlockingIOError, InterruptedError):  # the socket's buffer is full
                return False
            return True

        self._tx = tx
        poller.add(polled)
        self._connected()
        try:
            await self._until_lost(lost)
        finally:
            self._tx = None
            poller.remove(polled)
            sock.close()

    def _socket(self) -> socket.socket:
        """A non-blocking datagram socket bound to the transport's address.

        The address is the transport's alone: no SO_REUSEADDR (a unicast listener needs
        none, and with it a second process would bind the same port and take the
        datagrams), so a port another socket holds fails with EADDRINUSE, which the
        reconnect loop reports once as ``cannot open (EADDRINUSE: ...)``.
        """
        family = socket.AF_INET6 if ":" in self.spec.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            try:
                sock.bind((self.spec.host, self.spec.port))
            except OSError as err:
                if err.errno == errno.EADDRINUSE:
                    raise OSError(errno.EADDRINUSE,
                                  f"Address already in use: another process listens on "
                                  f"UDP port {self.spec.port}") from None
                raise
            sock.setblocking(False)
        except OSError:
            sock.close()
            raise
        return sock

    async def _bind(self, deliver: Callable[[bytes, float], None],
                    fail: Callable[[BaseException], None]) -> asyncio.DatagramTransport:
        """Bind the socket: datagrams to ``deliver``, its loss to ``fail``."""
        loop = asyncio.get_running_loop()
        sock = self._socket()
        proto = _UdpProtocol(deliver, fail, self.clock)
        transport, _ = await loop.create_datagram_endpoint(lambda: proto, sock=sock)

        def tx(data: bytes) -> bool:
            if proto.peer is None or transport.get_write_buffer_size() > TX_QUEUE_BYTES:
                return False
            transport.sendto(data, proto.peer)
            return True

        self._tx = tx
        self._connected()
        return transport

    @property
    def local_port(self) -> int:
        """The UDP port listened on."""
        return self.spec.port


class _PolledSocket:
    """A UDP transport's socket as a :class:`Poller` reads it."""

    def __init__(self, sock: socket.socket, deliver: Callable[[bytes, float], None],
                 t_open: float) -> None:
        self.sock = sock
        self.fd = sock.fileno()
        self.deliver = deliver
        self.peer: object | None = None
        """Where the last datagram came from: where :meth:`Transport.send` answers."""
        self.t_floor = t_open
        """No datagram still queued was received before this time (the bind, then the
        previous drain): the earliest stamp a datagram can be given."""

    def read(self, out: list[tuple[float, "_PolledSocket", bytes]], now: float,
             wall_ns: int, speed: float) -> None:
        """Append ``(t_rx, self, data)`` for every datagram queued (at most
        :data:`POLL_BATCH`): ``t_rx`` is ``now`` less the datagram's age since the kernel
        stamped it (``wall_ns``: the system clock at ``now``; ``speed``: clock seconds per
        wall second), kept between ``t_floor`` and ``now`` and in the order received."""
        recvmsg = self.sock.recvmsg
        floor = self.t_floor
        level, kind = socket.SOL_SOCKET, SO_TIMESTAMPNS
        for _ in range(POLL_BATCH):
            try:
                data, anc, _, addr = recvmsg(READ_SIZE, _ANC_SIZE)
            except (BlockingIOError, InterruptedError):
                floor = now  # every datagram received before now has been read
                break
            except OSError:  # an ICMP error of an earlier send: not fatal for a listener
                continue
            t_rx = now
            for lvl, typ, payload in anc:
                if lvl == level and typ == kind and len(payload) >= _TIMESPEC.size:
                    sec, nsec = _TIMESPEC.unpack_from(payload)
                    t_rx = now - speed * (wall_ns - sec * 1_000_000_000 - nsec) * 1e-9
            t_rx = min(max(t_rx, floor), now)
            floor = t_rx
            self.peer = addr
            out.append((t_rx, self, data))
        self.t_floor = floor


class Poller:
    """Reads the sockets of UDP transports when asked, not per datagram (module docstring).

    :meth:`drain` reads every datagram queued on every socket and hands them to their
    transports' sinks in the order the kernel received them, stamped on ``clock`` (the
    transports' clock; ``speed``: its seconds per wall second). Between :meth:`watch` and
    :meth:`unwatch`, a socket becoming readable wakes the event loop, which drains. A
    polled transport's idle timeout counts from the last drain that read a datagram, so
    the consumer must drain more often than that.
    """

    def __init__(self, clock: Clock = time.monotonic, speed: float = 1.0) -> None:
        self.clock = clock
        self.speed = speed
        self.sockets: list[_PolledSocket] = []
        self.watching = False
        self.on_data: Callable[[], None] | None = None
        self._poll = select.poll()
        """The sockets, for :meth:`wait`."""

    def add(self, polled: _PolledSocket) -> None:
        """Read ``polled`` from now on."""
        self.sockets.append(polled)
        self._poll.register(polled.fd, select.POLLIN)
        if self.watching:
            asyncio.get_running_loop().add_reader(polled.fd, self._readable)

    def remove(self, polled: _PolledSocket) -> None:
        """Stop reading ``polled`` (its transport closes it)."""
        if polled in self.sockets:
            self.sockets.remove(polled)
            self._poll.unregister(polled.fd)
            if self.watching:
                asyncio.get_running_loop().remove_reader(polled.fd)

    def wait(self, timeout_s: float) -> bool:
        """Block until a socket has a datagram queued or ``timeout_s`` (wall s, rounded up
        to the millisecond) has passed, the caller's event loop with it; return whether one
        has. Without sockets, return False at once."""
        if not self.sockets or timeout_s <= 0:
            return False
        return bool(self._poll.poll(math.ceil(timeout_s * 1000.0)))

    def drain(self) -> int:
        """Read every queued datagram of every socket and deliver them, oldest first;
        return how many."""
        got: list[tuple[float, _PolledSocket, bytes]] = []
        now, wall_ns = self.clock(), time.time_ns()
        for polled in self.sockets:
            polled.read(got, now, wall_ns, self.speed)
        if not got:
            return 0
        if len(self.sockets) > 1:
            got.sort(key=_first)
        for t_rx, polled, data in got:
            polled.deliver(data, t_rx)
        return len(got)

    def watch(self, on_data: Callable[[], None] | None = None) -> None:
        """Until :meth:`unwatch`, drain whenever a socket becomes readable, then call
        ``on_data()``."""
        self.on_data = on_data
        if not self.watching:
            self.watching = True
            loop = asyncio.get_running_loop()
            for polled in self.sockets:
                loop.add_reader(polled.fd, self._readable)

    def _readable(self) -> None:
        if self.drain() and self.on_data is not None:
            self.on_data()

    def unwatch(self) -> None:
        """Leave the datagrams in the kernel's queues until the next :meth:`drain`."""
        if self.watching:
            self.watching = False
            loop = asyncio.get_running_loop()
            for polled in self.sockets:
                loop.remove_reader(polled.fd)


def _first(item: tuple[float, _PolledSocket, bytes]) -> float:
    return item[0]


def set_keepalive(sock: socket.socket) -> None:
    """TCP_NODELAY, keepalive probes (:data:`KEEPALIVE_IDLE_S`, :data:`KEEPALIVE_INTERVAL_S`,
    :data:`KEEPALIVE_COUNT`) and ``TCP_USER_TIMEOUT`` (:data:`USER_TIMEOUT_MS`) where the
    platform has them, so that the kernel drops a half-open connection."""
    opts = [(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1),
            (socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)]
    for name, value in (("TCP_KEEPIDLE", KEEPALIVE_IDLE_S), ("TCP_KEEPINTVL", KEEPALIVE_INTERVAL_S),
                        ("TCP_KEEPCNT", KEEPALIVE_COUNT), ("TCP_USER_TIMEOUT", USER_TIMEOUT_MS)):
        if hasattr(socket, name):
            opts.append((socket.IPPROTO_TCP, getattr(socket, name), value))
    for level, opt, value in opts:
        try:
            sock.setsockopt(level, opt, value)
        except OSError:
            pass


class TcpTransport(Transport):
    """A TCP client; reconnects when the server goes away, goes silent for
    ``idle_timeout_s`` or stops answering keepalive probes (:func:`set_keepalive`)."""

    connect_timeout_s = 5.0
    greeting = b""
    """Bytes sent on every new connection (the gpsd transport's WATCH request)."""

    async def _session(self) -> AsyncIterator[Chunk]:
        async with asyncio.timeout(self.connect_timeout_s):
            reader, writer = await asyncio.open_connection(self.spec.host, self.spec.port)
        sock = writer.get_extra_info("socket")
        if sock is not None:
            set_keepalive(sock)

        def tx(data: bytes) -> bool:
            if writer.is_closing() or writer.transport.get_write_buffer_size() > TX_QUEUE_BYTES:
                return False
            writer.write(data)
            return True

        try:
            if self.greeting:
                writer.write(self.greeting)
                async with asyncio.timeout(self.connect_timeout_s):
                    await writer.drain()
            self._tx = tx
            self._connected()
            while True:
                data = await self._idle(reader.read(READ_SIZE))
                if not data:
                    return
                yield self._count(data, self.clock())
        finally:
            self._tx = None
            writer.close()
            try:
                async with asyncio.timeout(1.0):
                    await writer.wait_closed()
            except (OSError, TimeoutError):
                pass


class GpsdTransport(TcpTransport):
    """A client of gpsd: a TCP connection that asks for JSON reports (:data:`GPSD_WATCH`)
    on every (re)connection; the reports are parsed by :mod:`drivers.gpsd`."""

    greeting = GPSD_WATCH


class ZenohWriter:
    """Puts byte strings on one Zenoh key of a session that may not be open yet:
    ``session()`` returns it or None. A write without a session is refused (False);
    Zenoh's put drops under congestion and never blocks."""

    def __init__(self, session: Callable[[], object | None], key: str) -> None:
        self.session = session
        self.key = key
        self.errors = 0
        self._pub: object | None = None
        self._of: object | None = None

    def write(self, data: bytes) -> bool:
        """Put ``data`` on the key; False (counted in ``errors``) when it cannot."""
        sess = self.session()
        if sess is None:
            self.errors += 1
            return False
        try:
            if self._pub is None or self._of is not sess:
                import zenoh

                self._pub = sess.declare_publisher(  # type: ignore[attr-defined]
                    self.key, encoding=zenoh.Encoding(ZENOH_MAVLINK_ENCODING), express=True)
                self._of = sess
            self._pub.put(bytes(data))  # type: ignore[attr-defined]
        except Exception:  # noqa: BLE001 - a closed session: zenoh raises its ZError
            self.errors += 1
            self._pub = None
            return False
        return True

    def close(self) -> None:
        """Undeclare the publisher (the session stays the caller's)."""
        pub, self._pub = self._pub, None
        if pub is not None:
            try:
                pub.undeclare()  # type: ignore[attr-defined]
            except Exception:  # noqa: BLE001 - the session may be closed already
                pass


class ZenohTransport(Transport):
    """MAVLink over Zenoh the way BlueOS's mavlink-server carries it (its ``zenohraw``
    driver): every frame arrives as one sample on ``<prefix>/out`` (encoding
    ``application/octet-stream;mavlink``), and the bytes put on ``<prefix>/in`` are
    parsed and routed to the autopilot. Each sample is one chunk, stamped by the clock
    when Zenoh delivers it (on Zenoh's thread) and handed to the event loop in order.

    The session is the caller's (``session()``: the service's ``[service.zenoh]``
    session, or None while it is not open): the transport waits for it, subscribes, and
    counts a closed session as a lost connection (then subscribes again).
    """

    def __init__(self, spec: TransportSpec, *, session: Callable[[], object | None],
                 **kwargs: object) -> None:
        super().__init__(spec, **kwargs)  # type: ignore[arg-type]
        self.session = session
        self.rx_key = f"{spec.path}/{ZENOH_RX_SUFFIX}"
        self.tx_key = f"{spec.path}/{ZENOH_TX_SUFFIX}"

    async def _wait_session(self) -> object:
        while True:
            sess = self.session()
            if sess is not None:
                return sess
            await asyncio.sleep(SESSION_POLL_S)

    async def _session(self) -> AsyncIterator[Chunk]:
        box = _Mailbox(self.queue_size, self.stats)
        sub, writer = await self._subscribe(lambda data, t_rx: box.put((data, t_rx)))
        try:
            while True:
                data, t_rx = await self._idle(box.get())
                yield self._count(data, t_rx)
        finally:
            self._unsubscribe(sub, writer)

    async def _pump_session(self, sink: Callable[[bytes, float], None],
                            poller: "Poller | None" = None) -> None:
        lost: asyncio.Future[None] = asyncio.get_running_loop().create_future()

        def fail(err: BaseException) -> None:
            if not lost.done():
                lost.set_exception(err)

        sub, writer = await self._subscribe(self._deliverer(sink, fail))
        try:
            await self._until_lost(lost)
        finally:
            self._unsubscribe(sub, writer)

    async def _subscribe(self, deliver: Callable[[bytes, float], None]
                         ) -> tuple[object, ZenohWriter]:
        """Subscribe to ``<prefix>/out`` once the session is open: each sample's bytes to
        ``deliver`` on the event loop; sends go to ``<prefix>/in``."""
        sess = await self._wait_session()
        loop = asyncio.get_running_loop()
        clock = self.clock

        def on_sample(sample: object) -> None:  # on a Zenoh thread
            data = sample.payload.to_bytes()  # type: ignore[attr-defined]
            t_rx = clock()
            try:
                loop.call_soon_threadsafe(deliver, data, t_rx)
            except RuntimeError:  # the loop is closed: the service is stopping
                pass

        try:
            sub = sess.declare_subscriber(self.rx_key, on_sample)  # type: ignore[attr-defined]
        except Exception as err:  # noqa: BLE001 - a closed session raises ZError
            raise OSError(errno.ENOTCONN, f"zenoh subscriber on {self.rx_key}: {err}") from None
        writer = ZenohWriter(lambda: sess, self.tx_key)
        self._tx = writer.write
        self._connected()
        return sub, writer

    def _unsubscribe(self, sub: object, writer: ZenohWriter) -> None:
        self._tx = None
        writer.close()
        try:
            sub.undeclare()  # type: ignore[attr-defined]
        except Exception:  # noqa: BLE001 - the session may be closed already
            pass


def open_transport(url: str, *, zenoh_session: Callable[[], object | None] | None = None,
                   **kwargs: object) -> Transport:
    """The transport for a source URL; ``kwargs`` go to :class:`Transport`;
    ``zenoh_session`` gives a ``zenoh:`` URL its session (None while not open)."""
    spec = parse_url(url)
    if spec.scheme == "zenoh":
        if zenoh_session is None:
            raise TransportUrlError(f"{url!r}: a zenoh: source needs a Zenoh session")
        return ZenohTransport(spec, session=zenoh_session, **kwargs)
    cls = {"serial": SerialTransport, "pty": SerialTransport, "udp": UdpTransport,
           "tcp": TcpTransport, "gpsd": GpsdTransport}[spec.scheme]
    return cls(spec, **kwargs)  # type: ignore[arg-type]
