"""Regenerate the gpsd test material in ``tests/data/gpsd``.

* ``boat.nmea``: 30 s of the simulator's ``jaiabot-turns`` GNSS at 1 Hz as NMEA 0183
  (GGA, RMC, VTG, HDT from :class:`sitl.emitters.NmeaEncoder`, plus a GSA with the DOPs
  and a GSV, so that gpsd computes its error estimates), after three epochs without a fix
  and with the fix lost for epochs 15 to 17 (GGA quality 0, RMC ``V``, GSA mode 1);
* ``boat.jsonl``: what a real gpsd (``gpsfake``, Debian packages ``gpsd`` and
  ``gpsd-clients``) sends a client that asked ``?WATCH={"enable":true,"json":true}`` while
  it reads ``boat.nmea``: VERSION, DEVICES, WATCH, then TPV, SKY, ATT...

Run only when the material should change::

    python tests/data/gpsd/make_gpsd_capture.py
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
DATE = "010524"
"""The capture's date (1 May 2024), as RMC's ddmmyy."""


def nmea_lines() -> list[bytes]:
    """The NMEA log: three no-fix epochs, then 30 fixes at 1 Hz with GSA, GSV and HDT."""
    from onboard.drivers.nmea import _wrap
    from onboard.core.messages import GnssFix, Heading
    from onboard.sitl.emitters import NmeaEncoder
    from onboard.sitl.runner import simulate

    fixes, headings = [], []
    for _, samples, _ in simulate("jaiabot-turns", 32.0, seed=5):
        for s in samples:
            if isinstance(s, GnssFix) and (not fixes or s.t >= fixes[-1].t + 0.999):
                fixes.append(s)
            elif isinstance(s, Heading) and s.source == "compass":
                headings.append(s)
    enc = NmeaEncoder(epoch_s=1714564800.0)  # 2024-05-01 12:00:00 UTC
    out: list[bytes] = []
    for k in range(3):
        tod = f"1159{57 + k:02d}.00"
        out.append(_wrap(f"GPGGA,{tod},,,,,0,00,99.9,,M,,M,,"))
        out.append(_wrap(f"GPRMC,{tod},V,,,,,,,{DATE},,,N"))
    for k, fix in enumerate(fixes[:30]):
        if 15 <= k <= 17:  # the fix lost for three epochs
            tod = enc_tod(enc, fix.t + 3.0 - fixes[0].t)
            out.append(_wrap(f"GPGGA,{tod},,,,,0,00,99.9,,M,,M,,"))
            out.append(_wrap(f"GPRMC,{tod},V,,,,,,,{DATE},,,N"))
            out.append(_wrap("GPGSA,A,1,,,,,,,,,,,,,99.9,99.9,99.9"))
            continue
        fix = GnssFix(t=fix.t + 3.0 - fixes[0].t, source=fix.source, lat_deg=fix.lat_deg,
                      lon_deg=fix.lon_deg, alt_m=12.0, fix_quality=1, num_sats=9, hdop=0.9,
                      sog_mps=fix.sog_mps, cog_rad=fix.cog_rad)
        h = min(headings, key=lambda s: abs(s.t - (fix.t - 3.0 + fixes[0].t)))
        lines = enc.encode([fix, Heading(t=fix.t, heading_rad=h.heading_rad)])
        out += lines[:2]
        out.append(_wrap("GPGSA,A,3,02,04,07,12,15,19,24,25,29,,,,1.6,0.9,1.3"))
        out.append(_wrap("GPGSV,3,1,09,02,74,042,45,04,18,190,36,07,67,279,42,12,29,323,38"))
        out.append(_wrap("GPGSV,3,2,09,15,45,100,40,19,30,210,35,24,55,060,44,25,12,300,30"))
        out.append(_wrap("GPGSV,3,3,09,29,20,150,33"))
        out += lines[2:]
    return [ln.rstrip(b"\r\n") + b"\r\n" for ln in out]


def enc_tod(enc: object, t: float) -> str:
    """NMEA hhmmss.ss of the encoder's epoch plus ``t`` s."""
    tod = (getattr(enc, "epoch_s") + t) % 86400.0
    h, rem = divmod(tod, 3600.0)
    m, sec = divmod(rem, 60.0)
    return f"{int(h):02d}{int(m):02d}{sec:05.2f}"


def free_port() -> int:
    """A free TCP port on loopback."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def capture(nmea: Path, port: int, seconds: float) -> list[bytes]:
    """Run gpsfake on ``nmea`` at 1 sentence per 0.05 s and read its JSON for
    ``seconds``."""
    fake = subprocess.Popen(["gpsfake", "-q", "-1", "-c", "0.05", "-P", str(port), str(nmea)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 10.0
        while True:
            try:
                sock = socket.create_connection(("127.0.0.1", port), timeout=1.0)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        sock.sendall(b'?WATCH={"enable":true,"json":true}\n')
        sock.settimeout(0.5)
        data = b""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                chunk = sock.recv(65536)
            except socket.timeout:
                continue
            if not chunk:
                break
            data += chunk
        sock.close()
    finally:
        stop(fake)
    return [ln for ln in data.split(b"\n") if ln.strip()]


def stop(proc: subprocess.Popen) -> None:
    """End gpsfake and the gpsd it started (its own process group)."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(3.0)
            return
        except subprocess.TimeoutExpired:
            continue


def main() -> int:
    """Write ``boat.nmea`` and ``boat.jsonl``."""
    if shutil.which("gpsfake") is None:
        print("gpsfake not found: apt-get install gpsd gpsd-clients", file=sys.stderr)
        return 1
    nmea = HERE / "boat.nmea"
    nmea.write_bytes(b"".join(nmea_lines()))
    lines = capture(nmea, free_port(), 30.0)
    (HERE / "boat.jsonl").write_bytes(b"".join(ln.rstrip(b"\r") + b"\n" for ln in lines))
    print(f"{len(lines)} JSON lines", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
