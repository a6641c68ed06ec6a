"""Transport faults that give no error: a silent TCP peer, a half-open connection, a
serial device re-enumerated behind its /dev/serial/by-id link (drivers/transports.py)."""

from __future__ import annotations

import asyncio
import os
import socket

import pytest

from onboard.drivers.transports import (
    DEFAULT_IDLE_TIMEOUT_S,
    KEEPALIVE_COUNT,
    KEEPALIVE_IDLE_S,
    KEEPALIVE_INTERVAL_S,
    USER_TIMEOUT_MS,
    TcpTransport,
    open_transport,
    parse_url,
)
from onboard.core.config import from_dict
from onboard.apps.service_bench import free_tcp_port
from tests.helpers.ptys import pty_behind

TIMEOUT = 20.0  # generous: a loaded 2-core CI machine


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, TIMEOUT * 2))


@pytest.mark.integration
def test_a_tcp_instrument_that_power_cycles_is_reconnected_after_the_idle_timeout():
    """A DVL on TCP power-cycles: its old connection is never closed (no FIN, no RST: the
    instrument that held it is gone) and stays silent; it accepts a new one when it is
    back. The transport closes the silent connection after idle_timeout_s (0.3 s here)
    and reads the new one, with a ``lost (idle: ...)`` event. Without the idle timeout it
    would wait on the dead connection for ever (checked: no second chunk in 1.5 s)."""
    port = free_tcp_port()

    async def main(idle: float):
        conns: list[asyncio.StreamWriter] = []

        async def serve(reader, writer):
            conns.append(writer)
            writer.write(b'{"type":"velocity","boot":%d}\n' % len(conns))
            await writer.drain()
            # then silent: the connection stays open, as a power-cycled peer leaves it

        server = await asyncio.start_server(serve, "127.0.0.1", port)
        events: list[str] = []
        tr = TcpTransport(parse_url(f"tcp:127.0.0.1:{port}"), backoff_initial_s=0.05,
                          backoff_max_s=0.2, idle_timeout_s=idle, on_event=events.append)
        agen = tr.__aiter__()
        first = await asyncio.wait_for(agen.__anext__(), TIMEOUT)
        try:
            second = await asyncio.wait_for(agen.__anext__(), 1.5 if idle == 0 else TIMEOUT)
        except asyncio.TimeoutError:
            second = None
        await agen.aclose()
        for w in conns:
            w.close()
        server.close()
        await server.wait_closed()
        return first, second, tr.stats, events

    first, second, stats, events = run(main(0.3))
    assert first[0] == b'{"type":"velocity","boot":1}\n'
    assert second is not None and second[0] == b'{"type":"velocity","boot":2}\n'
    assert stats.connects == 2 and stats.disconnects == 1
    assert any("lost (idle: no data for 0.3 s)" in e for e in events), events
    # the control: idle timeout off, the dead connection holds the transport
    _, second, stats, _ = run(main(0.0))
    assert second is None and stats.connects == 1


@pytest.mark.integration
def test_a_peer_that_vanishes_without_fin_is_detected_and_the_socket_probes_it():
    """A half-open connection: the peer's host is gone without a FIN (here the server
    stops reading and writing but never closes; on loopback the kernel would still answer
    keepalive probes, so the idle timeout is what ends it in the test). The transport
    reconnects after idle_timeout_s, and its socket carries the keepalive and user-timeout
    options that let the kernel drop such a connection on a real link (probes after 5 s,
    every 2 s, 3 lost -> dropped ~11 s after the last byte)."""
    port = free_tcp_port()

    async def main():
        conns: list[asyncio.StreamWriter] = []
        opts: dict[str, int] = {}

        async def serve(reader, writer):
            conns.append(writer)
            writer.write(b"x%d\n" % len(conns))
            await writer.drain()

        server = await asyncio.start_server(serve, "127.0.0.1", port)
        tr = open_transport(f"tcp:127.0.0.1:{port}", idle_timeout_s=0.4,
                            backoff_initial_s=0.05)
        agen = tr.__aiter__()
        await asyncio.wait_for(agen.__anext__(), TIMEOUT)
        # the client's socket: the server's peer of the first accepted connection
        peer = conns[0].get_extra_info("peername")
        for fd in os.listdir("/proc/self/fd"):
            try:
                s = socket.socket(fileno=os.dup(int(fd)))
            except OSError:
                continue
            try:
                if s.type == socket.SOCK_STREAM and s.getsockname() == peer:
                    opts = {
                        "keepalive": s.getsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE),
                        "idle": s.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPIDLE),
                        "interval": s.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPINTVL),
                        "count": s.getsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPCNT),
                        "user_timeout": s.getsockopt(socket.IPPROTO_TCP, socket.TCP_USER_TIMEOUT),
                    }
            except OSError:
                pass
            finally:
                s.close()
        second = await asyncio.wait_for(agen.__anext__(), TIMEOUT)
        await agen.aclose()
        for w in conns:
            w.close()
        server.close()
        await server.wait_closed()
        return second, tr.stats, opts

    second, stats, opts = run(main())
    assert second[0] == b"x2\n" and stats.connects == 2
    assert opts == {"keepalive": 1, "idle": KEEPALIVE_IDLE_S, "interval": KEEPALIVE_INTERVAL_S,
                    "count": KEEPALIVE_COUNT, "user_timeout": USER_TIMEOUT_MS}


@pytest.mark.integration
def test_a_serial_device_re_enumerated_behind_its_by_id_link_is_followed(tmp_path):
    """USB re-enumeration: /dev/serial/by-id/usb-... is re-pointed to a new device node
    while the old node stays open and silent (no EIO: the old master is kept open). The
    transport, opened by the by-id path, goes idle after 0.3 s, reopens the path and
    reads the new device. (A node that vanishes with EIO is reopened at once:
    test_transports.py.)"""
    by_id = tmp_path / "serial" / "by-id"
    by_id.mkdir(parents=True)
    link = str(by_id / "usb-u-blox_AG_u-blox_GNSS_receiver-if00")
    events: list[str] = []

    async def main():
        old = pty_behind(link)
        tr = open_transport(f"serial:{link}:115200", idle_timeout_s=0.3,
                            backoff_initial_s=0.05, on_event=events.append)
        agen = tr.__aiter__()
        task = asyncio.ensure_future(agen.__anext__())
        while not tr.stats.connected:
            await asyncio.sleep(0.01)
        os.write(old, b"$GPGGA,first\r\n")
        first = await asyncio.wait_for(task, TIMEOUT)
        new = pty_behind(link)  # re-enumerated: the old node still open, silent
        task = asyncio.ensure_future(agen.__anext__())
        while tr.stats.connects < 2:
            await asyncio.sleep(0.01)
        os.write(new, b"$GPGGA,second\r\n")
        second = await asyncio.wait_for(task, TIMEOUT)
        await agen.aclose()
        os.close(old)
        os.close(new)
        return first, second, tr.stats

    first, second, stats = run(main())
    assert first[0].startswith(b"$GPGGA,first")
    assert second[0].startswith(b"$GPGGA,second")
    assert stats.connects == 2 and stats.disconnects == 1
    assert any("idle" in e for e in events), events


def test_idle_timeouts_default_per_scheme_and_come_from_the_config():
    """TCP and gpsd default to 10 s, serial/pty/UDP to never; a source's
    ``idle_timeout_s`` overrides (0 = never)."""
    assert DEFAULT_IDLE_TIMEOUT_S == {"tcp": 10.0, "gpsd": 10.0}
    assert open_transport("tcp:127.0.0.1:1").idle_timeout_s == 10.0
    assert open_transport("gpsd://127.0.0.1").idle_timeout_s == 10.0
    assert open_transport("serial:/dev/ttyUSB0").idle_timeout_s == 0.0
    assert open_transport("udp:0.0.0.0:1").idle_timeout_s == 0.0
    assert open_transport("tcp:127.0.0.1:1", idle_timeout_s=0.0).idle_timeout_s == 0.0
    cfg = from_dict({"service": {"sources": [
        {"kind": "dvl-json", "url": "tcp:192.168.194.95:16171", "idle_timeout_s": 3.0}]}})
    assert cfg.service.sources[0].idle_timeout_s == 3.0
    assert from_dict({"service": {"sources": [
        {"kind": "nmea", "url": "pty:/tmp/x"}]}}).service.sources[0].idle_timeout_s is None
