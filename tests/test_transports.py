"""Async transports: URL parsing, UDP, TCP and pseudo-terminal reads, reconnect with backoff."""

from __future__ import annotations

import asyncio
import os
import socket
import threading

import pytest

from onboard.drivers.transports import (
    KERNEL_STAMPS,
    TcpTransport,
    TransportUrlError,
    UdpTransport,
    open_transport,
    parse_url,
)
from onboard.apps.service_bench import free_tcp_port, free_udp_port
from tests.helpers.ptys import pty_behind

TIMEOUT = 20.0  # generous: a loaded 2-core CI machine


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, TIMEOUT * 2))


def test_parse_url_accepts_the_documented_forms():
    assert parse_url("serial:/dev/ttyUSB0:57600").baud == 57600
    assert parse_url("serial:/dev/ttyUSB0").path == "/dev/ttyUSB0"
    assert parse_url("pty:/tmp/gps").path == "/tmp/gps"
    u = parse_url("udp:0.0.0.0:14551")
    assert (u.scheme, u.host, u.port) == ("udp", "0.0.0.0", 14551)
    t = parse_url("tcp:192.168.2.95:16171")
    assert (t.scheme, t.host, t.port) == ("tcp", "192.168.2.95", 16171)
    assert str(parse_url("tcp:[::1]:5000")) == "tcp:::1:5000"


@pytest.mark.parametrize("bad", ["", "udp", "udp:host", "udp:h:x", "serial:/dev/x:0",
                                 "ftp:a:1", "tcp::5", "udp:h:70000"])
def test_parse_url_rejects_malformed_urls_with_a_reason(bad):
    with pytest.raises(TransportUrlError):
        parse_url(bad)


async def _take(tr, n, timeout=TIMEOUT):
    out = []
    agen = tr.__aiter__()
    try:
        while len(out) < n:
            out.append(await asyncio.wait_for(agen.__anext__(), timeout))
    finally:
        await agen.aclose()
    return out


@pytest.mark.integration
def test_udp_transport_yields_each_datagram_with_its_receive_time():
    port = free_udp_port()
    clock_values = iter(range(100, 200))

    async def main():
        tr = open_transport(f"udp:127.0.0.1:{port}", clock=lambda: float(next(clock_values)))
        assert isinstance(tr, UdpTransport)

        async def send():
            while not tr.stats.connected:
                await asyncio.sleep(0.01)
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            for i in range(3):
                s.sendto(b"msg%d" % i, ("127.0.0.1", port))
            s.close()

        sender = asyncio.create_task(send())
        got = await _take(tr, 3)
        await sender
        return got, tr.stats

    got, stats = run(main())
    assert [d for d, _ in got] == [b"msg0", b"msg1", b"msg2"]
    assert [t for _, t in got] == sorted(t for _, t in got)
    assert stats.chunks == 3 and stats.bytes == 12


@pytest.mark.integration
def test_tcp_transport_reconnects_after_the_server_goes_away():
    port = free_tcp_port()

    async def main():
        conns = []

        async def serve(reader, writer):
            conns.append(writer)
            writer.write(b"hello %d\n" % len(conns))
            await writer.drain()

        server = await asyncio.start_server(serve, "127.0.0.1", port)
        tr = TcpTransport(parse_url(f"tcp:127.0.0.1:{port}"), backoff_initial_s=0.05,
                          backoff_max_s=0.2)
        agen = tr.__aiter__()
        first = await asyncio.wait_for(agen.__anext__(), TIMEOUT)
        # the server drops the client and stops listening: the transport backs off...
        for w in conns:
            w.close()
        server.close()
        await server.wait_closed()
        await asyncio.sleep(0.3)
        # ...and reconnects once the server is back
        server = await asyncio.start_server(serve, "127.0.0.1", port)
        second = await asyncio.wait_for(agen.__anext__(), TIMEOUT)
        await agen.aclose()
        server.close()
        await server.wait_closed()
        return first, second, tr.stats

    first, second, stats = run(main())
    assert first[0] == b"hello 1\n"
    assert second[0].startswith(b"hello ")
    assert stats.connects >= 2 and stats.disconnects >= 1


@pytest.mark.integration
def test_pty_transport_reads_and_reopens_a_pseudo_terminal_that_disappears(tmp_path):
    link = str(tmp_path / "gps")
    events: list[str] = []

    async def main():
        master = pty_behind(link)
        tr = open_transport(f"pty:{link}", on_event=events.append, backoff_initial_s=0.05,
                            backoff_max_s=0.2)
        agen = tr.__aiter__()
        task = asyncio.ensure_future(agen.__anext__())
        while not tr.stats.connected:
            await asyncio.sleep(0.01)
        os.write(master, b"$GPHDT,1.0,T*00\r\n")
        first = await asyncio.wait_for(task, TIMEOUT)
        os.close(master)  # the device is unplugged: the reader sees EIO/EOF
        await asyncio.sleep(0.2)
        master2 = pty_behind(link)  # and comes back (udev recreates the symlink)
        task = asyncio.ensure_future(agen.__anext__())
        while tr.stats.connects < 2:
            await asyncio.sleep(0.01)
        os.write(master2, b"again\r\n")
        second = await asyncio.wait_for(task, TIMEOUT)
        await agen.aclose()
        os.close(master2)
        return first, second, tr.stats

    first, second, stats = run(main())
    assert first[0].startswith(b"$GPHDT")
    assert second[0].startswith(b"again")
    assert stats.connects == 2 and stats.disconnects == 1
    assert any("lost" in e for e in events)


@pytest.mark.integration
def test_a_missing_serial_port_is_retried_not_fatal(tmp_path):
    events: list[str] = []

    async def main():
        tr = open_transport(f"serial:{tmp_path / 'ttyNONE'}:115200", backoff_initial_s=0.01,
                            backoff_max_s=0.02, on_event=events.append)
        agen = tr.__aiter__()
        task = asyncio.ensure_future(agen.__anext__())
        await asyncio.sleep(0.3)
        assert not task.done()  # still trying, no exception
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        return tr.stats

    stats = run(main())
    assert not stats.connected and "ENOENT" in stats.last_error
    assert len(events) == 1 and "cannot open" in events[0]  # said once, not every retry


@pytest.mark.integration
def test_a_second_udp_listener_on_a_taken_port_fails_and_says_so():
    """A UDP input's port is its own: a second transport (a second ``onboard run``) on
    the same address cannot bind it (EADDRINUSE), says so once, and the datagrams keep
    going to the first."""
    port = free_udp_port()
    events: list[str] = []
    got: list[bytes] = []

    async def main():
        first = open_transport(f"udp:127.0.0.1:{port}")
        second = open_transport(f"udp:127.0.0.1:{port}", backoff_initial_s=0.01,
                                backoff_max_s=0.02, on_event=events.append)
        pumps = [asyncio.create_task(first.pump(lambda d, t: got.append(d)))]
        while not first.stats.connected:
            await asyncio.sleep(0.01)
        pumps.append(asyncio.create_task(second.pump(lambda d, t: got.append(b"2" + d))))
        while not second.stats.last_error:
            await asyncio.sleep(0.01)
        await asyncio.sleep(0.1)  # several retries
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for i in range(3):
            s.sendto(b"msg%d" % i, ("127.0.0.1", port))
        s.close()
        while len(got) < 3:
            await asyncio.sleep(0.01)
        for p in pumps:
            p.cancel()
        await asyncio.gather(*pumps, return_exceptions=True)
        return second.stats

    stats = run(main())
    assert got == [b"msg0", b"msg1", b"msg2"]
    assert not stats.connected and stats.connects == 0
    assert stats.last_error.startswith("EADDRINUSE: Address already in use")
    assert events == [f"udp:127.0.0.1:{port}: cannot open (EADDRINUSE: Address already in "
                      f"use: another process listens on UDP port {port}); retrying"]


def test_serial_paths_with_colons_keep_the_default_baud():
    u = parse_url("serial:/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0-port0")
    assert u.path == "/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0-port0"
    assert u.baud == 115200


@pytest.mark.integration
def test_pump_delivers_udp_datagrams_in_order_and_ends_on_a_sink_error():
    """``pump``: each datagram handed to the sink from the read callback, with its receive
    time and counted; an exception of the sink ends the pump as a SinkError (a consumer's
    bug is not a lost link: no reconnection)."""
    from onboard.drivers.transports import SinkError

    port = free_udp_port()
    clock_values = iter(range(100, 200))
    got: list[tuple[bytes, float]] = []

    def sink(data: bytes, t_rx: float) -> None:
        if data == b"bad":
            raise KeyError("consumer bug")
        got.append((data, t_rx))

    async def main():
        tr = open_transport(f"udp:127.0.0.1:{port}", clock=lambda: float(next(clock_values)))
        pump = asyncio.create_task(tr.pump(sink))
        while not tr.stats.connected:
            await asyncio.sleep(0.01)
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for i in range(3):
            s.sendto(b"msg%d" % i, ("127.0.0.1", port))
        while len(got) < 3:
            await asyncio.sleep(0.01)
        s.sendto(b"bad", ("127.0.0.1", port))
        s.close()
        with pytest.raises(SinkError) as info:
            await asyncio.wait_for(pump, TIMEOUT)
        assert isinstance(info.value.__cause__, KeyError)
        return tr.stats

    stats = run(main())
    assert got == [(b"msg0", 100.0), (b"msg1", 101.0), (b"msg2", 102.0)]
    assert stats.chunks == 4 and stats.connects == 1 and stats.disconnects == 0
    assert not stats.connected


@pytest.mark.integration
@pytest.mark.skipif(not KERNEL_STAMPS, reason="datagrams carry no kernel receive time here")
def test_polled_udp_inputs_are_read_at_the_drain_in_the_order_and_at_the_time_received():
    """``pump(sink, poller)``: nothing is read until ``Poller.drain``, which reads every
    queued datagram of both sockets, in the order they were sent across the two, each
    stamped with its kernel receive time (not the drain's); while watched, a datagram is
    delivered without a drain; a send answers the last sender."""
    import time

    from onboard.drivers.transports import Poller

    ports = free_udp_port(), free_udp_port()
    got: list[tuple[bytes, float]] = []

    async def main():
        poller = Poller(time.monotonic)
        trs = [open_transport(f"udp:127.0.0.1:{p}") for p in ports]
        pumps = [asyncio.create_task(tr.pump(lambda d, t: got.append((d, t)), poller))
                 for tr in trs]
        while not all(tr.stats.connected for tr in trs):
            await asyncio.sleep(0.01)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        tx.bind(("127.0.0.1", 0))
        sent = []
        for i in range(6):
            sent.append(time.monotonic())
            tx.sendto(b"m%d" % i, ("127.0.0.1", ports[i % 2]))
            await asyncio.sleep(0.01)
        await asyncio.sleep(0.05)
        unread = list(got)  # the loop ran for 100 ms: no datagram read yet
        t_drain = time.monotonic()
        n = poller.drain()
        await asyncio.sleep(0.01)
        answered = trs[0].send(b"reply")
        reply = tx.recv(100)
        poller.watch()
        tx.sendto(b"w", ("127.0.0.1", ports[1]))
        t_w = time.monotonic()
        while len(got) < 7 and time.monotonic() - t_w < TIMEOUT:
            await asyncio.sleep(0.005)
        poller.unwatch()
        tx.sendto(b"late", ("127.0.0.1", ports[0]))
        await asyncio.sleep(0.05)
        after_unwatch = len(got)
        poller.drain()
        for p in pumps:
            p.cancel()
        await asyncio.gather(*pumps, return_exceptions=True)
        tx.close()
        return unread, n, sent, t_drain, answered, reply, after_unwatch

    unread, n, sent, t_drain, answered, reply, after_unwatch = run(main())
    assert unread == [] and n == 6
    assert [d for d, _ in got[:6]] == [b"m%d" % i for i in range(6)]
    stamps = [t for _, t in got[:6]]
    assert stamps == sorted(stamps)
    for t_sent, t_rx in zip(sent, stamps):  # the kernel's time, not the drain's (>= 50 ms on)
        assert t_sent <= t_rx < t_sent + 0.01 < t_drain - 0.03
    assert answered and reply == b"reply"
    assert got[6][0] == b"w" and after_unwatch == 7 and got[7][0] == b"late"


@pytest.mark.integration
@pytest.mark.skipif(not KERNEL_STAMPS, reason="datagrams carry no kernel receive time here")
def test_poller_wait_blocks_until_a_datagram_is_queued_or_the_timeout():
    """``Poller.wait``: False at once without sockets; with nothing queued, False after
    the timeout (blocking); True as soon as a datagram is queued, which it leaves for the
    drain."""
    import time

    from onboard.drivers.transports import Poller

    port = free_udp_port()
    got: list[bytes] = []

    async def main():
        poller = Poller(time.monotonic)
        t0 = time.monotonic()
        empty = poller.wait(0.5)
        t_empty = time.monotonic() - t0
        tr = open_transport(f"udp:127.0.0.1:{port}")
        pump = asyncio.create_task(tr.pump(lambda d, t: got.append(d), poller))
        while not tr.stats.connected:
            await asyncio.sleep(0.01)
        t0 = time.monotonic()
        idle = poller.wait(0.02)
        t_idle = time.monotonic() - t0
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            threading.Timer(0.01, tx.sendto, (b"x", ("127.0.0.1", port))).start()
            t0 = time.monotonic()
            ready = poller.wait(TIMEOUT)
            t_ready = time.monotonic() - t0
            unread = list(got)
            n = poller.drain()
        pump.cancel()
        await asyncio.gather(pump, return_exceptions=True)
        return empty, t_empty, idle, t_idle, ready, t_ready, unread, n

    empty, t_empty, idle, t_idle, ready, t_ready, unread, n = run(main())
    assert not empty and t_empty < 0.1
    assert not idle and t_idle >= 0.019
    assert ready and t_ready < TIMEOUT / 2 and unread == [] and n == 1 and got == [b"x"]


@pytest.mark.integration
def test_pump_reopens_a_pty_that_disappears_and_times_out_an_idle_one(tmp_path):
    """``pump`` on a serial port: the chunks delivered, the device unplugged and back is
    reopened, and with an idle timeout a silent port is closed and reopened."""
    link = str(tmp_path / "gps")
    events: list[str] = []
    got: list[bytes] = []

    async def main():
        master = pty_behind(link)
        tr = open_transport(f"pty:{link}", on_event=events.append, backoff_initial_s=0.05,
                            backoff_max_s=0.2, idle_timeout_s=1.0)
        pump = asyncio.create_task(tr.pump(lambda data, t_rx: got.append(data)))
        deadline = asyncio.get_running_loop().time() + TIMEOUT

        async def until(cond):
            while not cond():
                assert asyncio.get_running_loop().time() < deadline, (events, got)
                await asyncio.sleep(0.01)

        await until(lambda: tr.stats.connected)
        os.write(master, b"$GPHDT,1.0,T*00\r\n")
        await until(lambda: got)
        os.close(master)  # unplugged
        await until(lambda: tr.stats.disconnects >= 1)
        master2 = pty_behind(link)
        await until(lambda: tr.stats.connects >= 2)
        os.write(master2, b"again\r\n")
        await until(lambda: len(got) >= 2)
        await until(lambda: any("idle" in e for e in events))  # 1 s without a byte
        await until(lambda: tr.stats.connects >= 3)
        pump.cancel()
        with pytest.raises(asyncio.CancelledError):
            await pump
        os.close(master2)
        return tr.stats

    stats = run(main())
    assert got[0].startswith(b"$GPHDT") and b"".join(got[1:]).startswith(b"again")
    assert any("lost (EIO" in e or "lost (end of file" in e or "lost" in e for e in events)
    assert stats.disconnects >= 2 and not stats.connected


def test_a_read_cancelled_as_its_data_comes_is_cancelled():
    """A TCP input's read is cancelled (the service stopping) in the same turn of the loop
    as its data arrives: the cancellation wins. With asyncio.wait_for, Python 3.11
    returned the data and dropped the cancellation, so the input read on and the
    service's stop (onboard demo --fleet's DVL, a systemctl stop) never ended."""
    import asyncio

    from onboard.drivers.transports import TcpTransport

    async def run() -> bool:
        tr = TcpTransport(parse_url("tcp:127.0.0.1:9"), idle_timeout_s=10.0)
        data: asyncio.Future[bytes] = asyncio.get_running_loop().create_future()
        task = asyncio.create_task(tr._idle(data))
        await asyncio.sleep(0)          # the read waits
        data.set_result(b"$GPGGA")      # the data comes ...
        task.cancel()                   # ... and the stop, in one turn
        try:
            await task
        except asyncio.CancelledError:
            return True
        return False

    assert asyncio.run(run())
