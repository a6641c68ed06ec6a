"""gpsd input (drivers/gpsd.py, the gpsd transport): the JSON protocol on a recorded gpsd
stream served by a fake gpsd, reconnection, and the real gpsd fed by gpsfake.

``tests/data/gpsd/boat.jsonl`` is what gpsd 3.22 sent for ``boat.nmea`` (30 epochs of the
simulated boat, the fix lost for three of them); ``make_gpsd_capture.py`` beside them
regenerates both.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import shutil
import signal
import subprocess
from pathlib import Path

import pytest

from onboard.drivers.gpsd import SIGMA_95_1D, SIGMA_95_2D, WATCH, GpsdParser
from onboard.drivers.nmea import NmeaParser
from onboard.drivers.protocols import parser_for
from onboard.drivers.transports import GpsdTransport, open_transport, parse_url
from onboard.core.config import from_dict
from onboard.core.messages import Attitude, GnssFix, Heading
from onboard.engine import Engine
from onboard.service.intake import Intake
from onboard.apps.service_bench import free_tcp_port

DATA = Path(__file__).resolve().parent / "data" / "gpsd"
LINES = [ln for ln in (DATA / "boat.jsonl").read_bytes().split(b"\n") if ln.strip()]
TIMEOUT = 30.0
INSTALL = "gpsd/gpsfake not installed: apt-get install gpsd gpsd-clients (see README)"


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, TIMEOUT * 2))


def _tpvs() -> list[dict]:
    return [o for o in map(json.loads, LINES) if o["class"] == "TPV"]


def _nmea_positions() -> list[tuple[float, float]]:
    """The fixes of boat.nmea as our NMEA parser reads them (the recording's truth)."""
    p = NmeaParser(source="nmea", time_base="rx")
    out = []
    for k, line in enumerate((DATA / "boat.nmea").read_bytes().splitlines(keepends=True)):
        out += [(s.lat_deg, s.lon_deg) for s in p.feed(line, float(k)) if isinstance(s, GnssFix)]
    out += [(s.lat_deg, s.lon_deg) for s in p.flush() if isinstance(s, GnssFix)]
    return out


def _check_fixes(fixes: list[GnssFix], parser: GpsdParser) -> None:
    """Every fix is a TPV of mode >= 2 with its position, its 95 % errors turned into one
    sigma, and the SKY's satellites; mode-1 reports and repeated epochs are counted."""
    tpvs = _tpvs()
    with_fix = [o for o in tpvs if o["mode"] >= 2]
    times = [o.get("time") for o in with_fix]
    repeats = sum(1 for i, t in enumerate(times) if t is not None and i and times[i - 1] == t)
    assert parser.stats.rejected["no_fix"] == sum(1 for o in tpvs if o["mode"] < 2) == 2
    assert parser.stats.rejected["duplicate"] == repeats
    assert len(fixes) == len(with_fix) - repeats >= 25
    truth = _nmea_positions()
    for f in fixes:
        # the position is one of the NMEA log's to gpsd's 9 decimals (< 1 mm)
        assert min(math.hypot(f.lat_deg - a, f.lon_deg - b) for a, b in truth) < 1e-8
        assert f.fix_quality == 1 and f.alt_m == 12.0
    kept = [o for i, o in enumerate(with_fix)
            if not (i and o.get("time") and with_fix[i - 1].get("time") == o.get("time"))]
    checked = with_speed_acc = 0
    for f, o in zip(fixes, kept):  # the first report of each epoch is the one kept
        assert (f.lat_deg, f.lon_deg) == (o["lat"], o["lon"])
        if "epx" in o and "epy" in o:
            assert f.h_acc_m == pytest.approx(max(o["epx"], o["epy"]) / SIGMA_95_1D)
            checked += 1
        elif "eph" in o:
            assert f.h_acc_m == pytest.approx(o["eph"] / SIGMA_95_2D)
        if "epv" in o:
            assert f.v_acc_m == pytest.approx(o["epv"] / SIGMA_95_1D)
        if o.get("eps"):
            assert f.speed_acc_mps == pytest.approx(o["eps"] / SIGMA_95_1D)
            with_speed_acc += 1
        assert f.num_sats in (None, 0, 9) and f.sog_mps == o.get("speed")
    assert fixes[-1].num_sats == 9 and fixes[-1].hdop == 0.9
    assert checked >= 20 and with_speed_acc >= 20


async def _fake_gpsd(port: int, lines: list[bytes], watches: list[bytes],
                     close_after: int | None = None) -> asyncio.AbstractServer:
    """A gpsd stand-in: waits for the client's request line, then sends ``lines`` (the
    first ``close_after`` on the first connection, then closes it; all on the next)."""
    async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        watches.append(await reader.readline())
        n = close_after if close_after is not None and len(watches) == 1 else len(lines)
        for k in range(0, n, 7):  # in chunks that cut lines anywhere
            writer.write(b"".join(ln + b"\n" for ln in lines[k:min(k + 7, n)]))
            await writer.drain()
            await asyncio.sleep(0.001)
        if n < len(lines):
            writer.close()
            return
        await asyncio.sleep(TIMEOUT)
    return await asyncio.start_server(serve, "127.0.0.1", port)


async def _collect(tr: GpsdTransport, parser: GpsdParser, n_fixes: int) -> list[GnssFix]:
    fixes: list[GnssFix] = []
    agen = tr.__aiter__()
    try:
        while len(fixes) < n_fixes:
            data, t_rx = await asyncio.wait_for(agen.__anext__(), TIMEOUT)
            fixes += [s for s in parser.feed(data, t_rx) if isinstance(s, GnssFix)]
    finally:
        await agen.aclose()
    return fixes


@pytest.mark.integration
def test_a_recorded_gpsd_stream_from_a_fake_gpsd_gives_its_fixes_with_their_errors():
    """The transport sends ?WATCH={"enable":true,"json":true}; the recorded reports become
    GnssFix samples (mode < 2 and repeated epochs counted), through the service's intake
    into the engine's nav track."""
    port = free_tcp_port()
    times = [o.get("time") for o in _tpvs() if o["mode"] >= 2]
    n_expected = sum(1 for i, t in enumerate(times) if not (i and t and times[i - 1] == t))

    async def main():
        watches: list[bytes] = []
        server = await _fake_gpsd(port, LINES, watches)
        tr = open_transport(f"gpsd://127.0.0.1:{port}")
        assert isinstance(tr, GpsdTransport)
        parser = GpsdParser(source="gnss")
        fixes = await _collect(tr, parser, n_expected)
        server.close()
        await server.wait_closed()
        return watches, fixes, parser

    watches, fixes, parser = run(main())
    assert watches == [WATCH]
    _check_fixes(fixes, parser)
    # the same reports through the intake (parser by kind "gpsd") into the engine
    engine = Engine(from_dict({"vehicle": {"class": "rudder-boat"}}), only={"nav"})
    intake = Intake(engine)
    for k, line in enumerate(LINES):
        intake.chunk("gnss", "gpsd", line + b"\n", 1.0 + 0.1 * k)
    recs = intake.tick(1.0 + 0.1 * len(LINES))
    assert recs and recs[0].sources["position"] == "gnss"
    assert {"north", "east", "speed", "course"} <= set(recs[0].values)
    assert intake.parse_rejections()["parse:gnss:no_fix"] == 2


@pytest.mark.integration
def test_the_gpsd_transport_reconnects_and_asks_again():
    """gpsd restarts mid-stream: the connection closes after 20 lines; the transport
    reconnects with backoff and sends its WATCH again; the fixes continue."""
    port = free_tcp_port()

    async def main():
        watches: list[bytes] = []
        server = await _fake_gpsd(port, LINES, watches, close_after=20)
        events: list[str] = []
        tr = GpsdTransport(parse_url(f"gpsd://127.0.0.1:{port}"), backoff_initial_s=0.05,
                           on_event=events.append)
        parser = GpsdParser()
        fixes = await _collect(tr, parser, 25)
        server.close()
        await server.wait_closed()
        return watches, fixes, tr.stats, events

    watches, fixes, stats, events = run(main())
    assert watches == [WATCH, WATCH]
    assert stats.connects == 2 and stats.disconnects == 1
    assert any("lost (closed by peer)" in e for e in events), events
    assert len(fixes) >= 25


def test_att_sky_and_bad_reports():
    """ATT gives a heading (and an attitude with pitch and roll); SKY's used satellites
    and hdop go into the next fix; garbage, ERROR, missing positions are counted."""
    p = GpsdParser(source="gnss")
    out = p.feed(b'{"class":"ATT","device":"/dev/ttyUSB0","time":"2024-05-01T12:00:04Z",'
                 b'"heading":350.5,"pitch":2.0,"roll":-1.0}\n', 5.0)
    assert isinstance(out[0], Heading) and out[0].heading_rad == pytest.approx(math.radians(350.5))
    assert isinstance(out[1], Attitude) and out[1].roll_rad == pytest.approx(math.radians(-1.0))
    assert out[1].yaw_rad == pytest.approx(math.radians(350.5 - 360.0))
    assert [type(s) for s in p.feed(b'{"class":"ATT","heading":10.0}\n', 5.1)] == [Heading]
    p.feed(b'{"class":"SKY","hdop":1.4,"satellites":[{"PRN":1,"used":true},'
           b'{"PRN":2,"used":false},{"PRN":3,"used":true}]}\n', 5.2)
    fix = p.feed(b'{"class":"TPV","mode":2,"status":2,"lat":63.4,"lon":10.4,"eph":4.9,'
                 b'"alt":5.0}\n', 5.3)[0]
    assert isinstance(fix, GnssFix) and (fix.num_sats, fix.hdop) == (2, 1.4)
    assert fix.fix_quality == 2 and fix.alt_m is None  # DGPS; a 2-D fix has no altitude
    assert fix.h_acc_m == pytest.approx(4.9 / 2.4477) and fix.v_acc_m is None
    for bad, reason in ((b"not json\n", "json"), (b'{"class":"ERROR","message":"x"}\n', "gpsd_error"),
                        (b'{"class":"TPV","mode":3,"lat":"x","lon":1}\n', "malformed"),
                        (b'{"class":"TPV","mode":3,"lat":91.0,"lon":1.0}\n', "malformed"),
                        (b'{"class":"TPV","mode":0}\n', "no_fix"),
                        (b'{"class":"ATT","pitch":1.0}\n', "no_heading")):
        before = p.stats.rejected[reason]
        assert p.feed(bad, 6.0) == []
        assert p.stats.rejected[reason] == before + 1, bad
    assert isinstance(parser_for("gpsd", "gnss"), GpsdParser)


def test_gpsd_urls():
    assert str(parse_url("gpsd://127.0.0.1:2947")) == "gpsd://127.0.0.1:2947"
    assert parse_url("gpsd://boat-pi").port == 2947
    assert parse_url("gpsd://").host == "localhost"
    assert parse_url("gpsd:10.0.0.2:3000").port == 3000


@pytest.mark.integration
def test_the_real_gpsd_fed_by_gpsfake_gives_the_logged_fixes(tmp_path):
    """gpsfake runs a real gpsd on boat.nmea (a sentence per 0.05 s); the transport asks
    it for JSON and every fix is one of the log's positions, with gpsd's error estimates
    as its accuracy; the fix lost for three epochs gives no position. gpsd's control
    socket goes in the test's own folder (``TMPDIR``: gpsfake killed leaves it behind)."""
    if shutil.which("gpsfake") is None or shutil.which("gpsd") is None:
        pytest.skip(INSTALL)
    port = free_tcp_port()
    fake = subprocess.Popen(["gpsfake", "-q", "-1", "-c", "0.05", "-P", str(port),
                             str(DATA / "boat.nmea")], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True,
                            env=dict(os.environ, TMPDIR=str(tmp_path)))

    async def main():
        tr = GpsdTransport(parse_url(f"gpsd://127.0.0.1:{port}"), backoff_initial_s=0.1,
                           backoff_max_s=0.5)
        parser = GpsdParser(source="gnss")
        return await _collect(tr, parser, 25), parser

    try:
        fixes, parser = run(main())
    finally:
        for sig in (signal.SIGTERM, signal.SIGKILL):
            try:
                os.killpg(fake.pid, sig)
                fake.wait(3.0)
                break
            except ProcessLookupError:
                break
            except subprocess.TimeoutExpired:
                continue
    truth = _nmea_positions()
    for f in fixes:
        assert min(math.hypot(f.lat_deg - a, f.lon_deg - b) for a, b in truth) < 1e-8
    assert sum(1 for f in fixes if f.h_acc_m is not None) >= 20
    assert all(f.h_acc_m is None or 0.5 < f.h_acc_m < 20.0 for f in fixes)
    assert parser.stats.rejected["no_fix"] >= 1  # the three lost epochs (gpsd: mode 1)


def test_a_gpsd_url_needs_the_gpsd_kind(tmp_path):
    """``onboard run`` refuses a gpsd:// URL with another kind (and kind gpsd without
    one) in one line, before anything starts."""
    import argparse

    from onboard.core.config import ConfigError
    from onboard.service.daemon import main

    for kind, url in (("nmea", "gpsd://127.0.0.1:2947"), ("gpsd", "tcp:127.0.0.1:2947")):
        cfg = tmp_path / f"{kind}.toml"
        cfg.write_text(f'[[service.sources]]\nkind = "{kind}"\nurl = "{url}"\n')
        with pytest.raises(ConfigError, match=r'service.sources\[0\]: kind "gpsd" goes with'):
            main(argparse.Namespace(config=str(cfg), state_dir=str(tmp_path / "state")))
