"""The UTC of an NMEA capture as its RMC sentences give it, read without the drivers:
the oracle of the exports' times (tests/test_exports.py, tests/test_mcap.py)."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path


def rmc_times(path: Path) -> list[float]:
    """POSIX times (s) of every RMC sentence with a date and a time, status A, in file
    order: ``ddmmyy`` and ``hhmmss[.ss]`` read as UTC."""
    out = []
    for line in path.read_text(errors="replace").splitlines():
        i = line.find("$")
        f = line[i:].split("*")[0].split(",")
        if i < 0 or f[0][3:] != "RMC" or len(f) < 10 or f[2] != "A" or not (f[1] and f[9]):
            continue
        day = datetime.strptime(f[9] + f[1][:6], "%d%m%y%H%M%S").replace(tzinfo=timezone.utc)
        out.append(day.timestamp() + float("0" + f[1][6:]))
    return out
