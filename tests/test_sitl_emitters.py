"""Emitters end to end: bytes out of a pty, a UDP socket and a TCP server parse back with
pymavlink and the project's own parsers, every frame and every checksum right."""

from __future__ import annotations

import dataclasses as dc
import os
import select
import socket
import threading
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from onboard.drivers.dvl_json import DvlJsonParser
from onboard.drivers.nmea import NmeaParser
from onboard.drivers.pd6 import Pd6Parser
from onboard.core.messages import DvlVelocity, GnssFix, Heading
from onboard.sitl.emitters import FileSink, PtySink, TcpServerSink, UdpSink
from onboard.sitl import scenarios
from onboard.sitl.runner import run, run_to_tlog, simulate

pytestmark = pytest.mark.integration


class _PtyReader(threading.Thread):
    """Reads a pty slave until ``stop`` is set and nothing more arrives."""

    def __init__(self, path: str) -> None:
        super().__init__(daemon=True)
        self.fd = os.open(path, os.O_RDONLY | os.O_NOCTTY)
        self.data = bytearray()
        self.stop = threading.Event()

    def run(self) -> None:
        while True:
            r, _, _ = select.select([self.fd], [], [], 0.2)
            if r:
                chunk = os.read(self.fd, 65536)
                if not chunk:
                    break
                self.data += chunk
            elif self.stop.is_set():
                break
        os.close(self.fd)


def _parse_mavlink(data: bytes) -> tuple[dict[str, int], int]:
    """(message counts, bad frames) as pymavlink parses the byte stream."""
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    counts: dict[str, int] = {}
    bad = 0
    for m in mav.parse_buffer(bytes(data)) or []:
        name = m.get_type()
        if name == "BAD_DATA":
            bad += 1
        counts[name] = counts.get(name, 0) + 1
    return counts, bad


def test_mavlink_through_a_pty_parses_without_a_bad_frame():
    sink = PtySink(drain_s=20.0)  # generous: the reader thread may be slow on a busy machine
    reader = _PtyReader(sink.path)
    reader.start()
    summary = run("jaiabot-turns", 8.0, seed=1, mavlink=[sink])
    reader.stop.set()
    reader.join(5)
    counts, bad = _parse_mavlink(reader.data)
    assert bad == 0 and sink.dropped == 0
    assert sum(counts.values()) == summary.frames["mavlink"]
    assert counts["GPS_RAW_INT"] == 41 and counts["SCALED_IMU"] == 401


def test_nmea_through_a_pty_has_right_checksums():
    sink = PtySink(drain_s=20.0)  # generous: the reader thread may be slow on a busy machine
    reader = _PtyReader(sink.path)
    reader.start()
    summary = run("jaiabot-turns", 10.0, seed=2, nmea=[sink])
    reader.stop.set()
    reader.join(5)
    text = bytes(reader.data)
    assert text.count(b"$GPGGA") == 51 and text.count(b"$HEHDT") == 101
    parser = NmeaParser()
    samples = parser.feed(text, 0.0) + parser.flush()
    assert not parser.stats.rejected
    fixes = [s for s in samples if isinstance(s, GnssFix)]
    assert len(fixes) == summary.samples["GnssFix"] == 51
    assert sum(isinstance(s, Heading) for s in samples) == 101
    assert all(f.sog_mps is not None and f.cog_rad is not None for f in fixes)


def test_the_nmea_output_goes_on_every_epoch_through_a_gnss_outage(tmp_path):
    """fault-gnss-outage loses the fix from 30 s: the receiver still sends GGA, RMC and
    VTG every 0.2 s, quality 0, ``V`` and ``N`` from 30 s on; the driver counts each such
    epoch as ``no_fix`` and takes no fix from it; the tlog is the same with or without the
    NMEA output (its epochs without a fix draw nothing and reach no controller)."""
    nmea = tmp_path / "run.nmea"
    summary = run_to_tlog("fault-gnss-outage", tmp_path / "a.tlog", duration=34.0, seed=1,
                          nmea_path=nmea)
    run_to_tlog("fault-gnss-outage", tmp_path / "b.tlog", duration=34.0, seed=1)
    assert (tmp_path / "a.tlog").read_bytes() == (tmp_path / "b.tlog").read_bytes()
    lines = nmea.read_bytes().splitlines()
    gga = [ln.split(b",") for ln in lines if ln.startswith(b"$GPGGA")]
    rmc = [ln.split(b",") for ln in lines if ln.startswith(b"$GPRMC")]
    vtg = [ln for ln in lines if ln.startswith(b"$GPVTG")]
    assert len(gga) == len(rmc) == len(vtg) == 5 * 34 + 1  # every epoch, fix or not
    tod = [float(g[1]) for g in gga]
    assert tod == pytest.approx([k * 0.2 for k in range(171)])  # 00:00:00.00 on
    lost = [g[6] == b"0" for g in gga]
    assert lost == [k >= 150 for k in range(171)]  # from 30 s
    assert all((r[2] == b"V") == k for r, k in zip(rmc, lost))
    assert sum(v.split(b"*")[0].endswith(b",N") for v in vtg) == 21
    assert summary.samples["GnssFix"] == 150 and summary.samples["GnssNoFix"] == 21
    parser = NmeaParser(time_base="utc")
    samples = parser.feed(nmea.read_bytes(), 0.0) + parser.flush()
    assert sum(isinstance(s, GnssFix) for s in samples) == 150
    assert parser.stats.rejected == {"no_fix": 2 * 21}  # each epoch, and its VTG


def test_the_tlog_logs_each_epoch_without_a_fix_as_ardupilot_does(tmp_path):
    """fault-gnss-outage loses the fix from 30 s: each receiver epoch without one is a
    GPS_RAW_INT of fix_type NO_FIX at the last fix's place and ``time_usec``, held as
    AP_GPS holds ``last_fix_time_ms`` (the ArduSub tlog of ../shared/data through its
    loss at 79-82 s); the tlog reader counts each ``no_fix`` and takes the 150 fixes
    (docs/sitl.md)."""
    from pymavlink import mavutil

    from onboard.drivers.tlog import TlogReader

    path = tmp_path / "a.tlog"
    run_to_tlog("fault-gnss-outage", path, duration=34.0, seed=1)
    log = mavutil.mavlink_connection(str(path))
    gps = []
    while (m := log.recv_match(type="GPS_RAW_INT")) is not None:
        gps.append(m)
    assert [m.fix_type for m in gps] == [3] * 150 + [1] * 21  # 5 Hz, the fix lost at 30 s
    last = gps[149]
    assert {(m.time_usec, m.lat, m.lon, m.alt) for m in gps[150:]} == {
        (last.time_usec, last.lat, last.lon, last.alt)}
    assert {(m.eph, m.cog, m.satellites_visible) for m in gps[150:]} == {(65535, 65535, 0)}
    reader = TlogReader(path)
    assert sum(isinstance(s, GnssFix) for s in reader) == 150
    assert reader.stats.rejected["no_fix"] == 21


def test_the_nmea_output_sends_an_empty_hdt_while_the_heading_is_invalid(tmp_path):
    """jaiabot-turns with the compass's ``invalid_windows`` option (2.0-2.5 s): an empty
    HDT every 0.1 s in the window, which the driver counts as ``empty``; the headings of
    ``simulate`` skip the window."""
    base = scenarios.get("jaiabot-turns")
    sc = dc.replace(base, sensors=dc.replace(base.sensors, compass=dc.replace(
        base.sensors.compass, invalid_windows=((2.0, 0.5),))))
    nmea = tmp_path / "run.nmea"
    run(sc, 4.0, seed=1, nmea=[FileSink(nmea)])
    hdt = [ln.split(b"*")[0] for ln in nmea.read_bytes().splitlines() if b"HDT" in ln]
    assert len(hdt) == 41
    assert [h == b"$HEHDT,,T" for h in hdt] == [20 <= k < 25 for k in range(41)]
    parser = NmeaParser()
    samples = parser.feed(nmea.read_bytes(), 0.0) + parser.flush()
    assert sum(isinstance(s, Heading) for s in samples) == 36
    assert parser.stats.rejected == {"empty": 5}
    t_head = [round(s.t, 1) for _, ss, _ in simulate(sc, 4.0, seed=1) for s in ss
              if isinstance(s, Heading)]
    assert t_head == [k / 10 for k in range(41) if not 20 <= k < 25]


def test_pd6_through_a_pty_parses():
    sink = PtySink(drain_s=20.0)  # generous: the reader thread may be slow on a busy machine
    reader = _PtyReader(sink.path)
    reader.start()
    run("gavia-tidal", 6.0, seed=1, pd6=[sink])
    reader.stop.set()
    reader.join(5)
    parser = Pd6Parser()
    samples = parser.feed(bytes(reader.data), 0.0)
    assert not parser.stats.rejected
    dvl = [s for s in samples if isinstance(s, DvlVelocity) and s.track == "bottom"]
    assert len(dvl) == 31  # 5 Hz over 6 s
    assert all(0.3 < s.vx < 0.8 for s in dvl if s.valid)  # ~0.55 m/s over ground


def test_mavlink_over_udp_arrives_intact():
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    port = rx.getsockname()[1]
    rx.settimeout(0.5)
    datagrams: list[bytes] = []
    ran = threading.Event()

    def receive() -> None:
        while True:  # until the run is over and the socket drained
            try:
                datagrams.append(rx.recv(4096))
            except socket.timeout:
                if ran.is_set():
                    return

    th = threading.Thread(target=receive, daemon=True)
    th.start()
    summary = run("effect-current", 5.0, seed=1, mavlink=[UdpSink("127.0.0.1", port)])
    ran.set()
    th.join(5)
    rx.close()
    counts, bad = _parse_mavlink(b"".join(datagrams))
    assert bad == 0
    assert len(datagrams) == sum(counts.values()) == summary.frames["mavlink"]


def test_mavlink_tcp_server_and_dvl_json_server():
    mav_srv = TcpServerSink("127.0.0.1", 0)
    dvl_srv = TcpServerSink("127.0.0.1", 0)
    clients = []
    for srv in (mav_srv, dvl_srv):
        c = socket.create_connection(("127.0.0.1", srv.port))
        c.settimeout(0.5)
        clients.append(c)
    assert mav_srv.wait_for_client(2.0) and dvl_srv.wait_for_client(2.0)
    received = [bytearray(), bytearray()]
    ran = threading.Event()

    def receive(i: int) -> None:
        # until the run is over and the socket drained (a busy machine can leave it silent
        # for longer than the timeout before the first frame)
        while True:
            try:
                chunk = clients[i].recv(65536)
            except socket.timeout:
                if ran.is_set():
                    return
                continue
            if not chunk:
                return
            received[i] += chunk

    threads = [threading.Thread(target=receive, args=(i,), daemon=True) for i in (0, 1)]
    for th in threads:
        th.start()
    summary = run("bluerov2-circle", 6.0, seed=1, mavlink=[mav_srv], dvl_json=[dvl_srv])
    ran.set()
    for th in threads:
        th.join(5)
    for c in clients:
        c.close()
    counts, bad = _parse_mavlink(received[0])
    assert bad == 0 and sum(counts.values()) == summary.frames["mavlink"]
    assert counts["VISION_POSITION_DELTA"] == 31
    parser = DvlJsonParser()
    samples = parser.feed(bytes(received[1]), 0.0)
    assert not parser.stats.rejected
    vel = [s for s in samples if isinstance(s, DvlVelocity)]
    assert len(vel) == 31 and all(s.valid for s in vel)


def test_pty_never_blocks_without_a_reader():
    sink = PtySink(max_pending=4096)
    t0 = time.perf_counter()
    for i in range(2000):
        sink.write(0.0, bytes(100))
    sink.close(drain_s=0.0)
    assert time.perf_counter() - t0 < 2.0
    assert sink.dropped > 0


def test_pymavlink_opens_the_pty_as_a_serial_port():
    """What a ground station or the service does: mavutil on the printed /dev/pts path."""
    from pymavlink import mavutil

    sink = PtySink(drain_s=20.0)
    conn = mavutil.mavlink_connection(sink.path, baud=115200)
    got: dict[str, int] = {}

    def receive() -> None:
        import serial

        while True:
            try:
                m = conn.recv_match(blocking=True, timeout=1.0)
            except serial.SerialException:  # the simulator closed the pty: unplugged
                return
            if m is None:
                return
            got[m.get_type()] = got.get(m.get_type(), 0) + 1

    th = threading.Thread(target=receive, daemon=True)
    th.start()
    summary = run("twin-thruster-turns", 4.0, seed=3, mavlink=[sink])
    th.join(10)
    conn.close()
    assert got.get("BAD_DATA", 0) == 0
    assert sum(got.values()) == summary.frames["mavlink"]
    assert got["HEARTBEAT"] == 5 and got["PARAM_VALUE"] == 2
