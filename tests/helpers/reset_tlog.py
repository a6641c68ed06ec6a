"""A tlog whose logger clock goes back 1000 s after 10 s of data: the time line's clock
reset, for the readers' and the replay's tests."""

from __future__ import annotations

from pathlib import Path

START_S = 1.7e9
"""The logger's first stamp (Unix s, 2023-11-14 22:13:20 UTC)."""
BACK_S = 1000.0
"""How far the clock goes back after the first 10 s (s)."""


def write_reset_tlog(path: Path, heartbeat: bool = False) -> Path:
    """Write 100 samples at 10 Hz (an attitude and a position each, and a HEARTBEAT with
    ``heartbeat``), then 100 more from :data:`BACK_S` earlier; return ``path``."""
    from pymavlink.dialects.v20 import ardupilotmega as mav

    from onboard.drivers.tlog import TlogWriter

    m = mav.MAVLink(None, 1, 1)
    with TlogWriter(path) as w:
        for base in (START_S, START_S - BACK_S):
            for i in range(100):
                t = base + 0.1 * i
                if heartbeat:
                    w.write(t, m.heartbeat_encode(10, 3, 0, 0, 4, 3).pack(m))
                w.write(t, m.attitude_encode(0, 0.0, 0, 0.1 * i, 0, 0, 0.01).pack(m))
                w.write(t, m.global_position_int_encode(
                    0, int(48e7 + i * 10), int(-4e7), 0, 0, 100, 0, 0, 100).pack(m))
    return path
