"""Water Linked DVL reports out of the simulator, written from Water Linked's documents.

The DVL A50/A125 sends one JSON object per line on TCP port 16171 (Water Linked, "DVL
A50/A125 TCP JSON API", protocol ``json_v3.2``; the same fields as the serial protocol's
``wrz``/``wrs``/``wru``/``wrp`` reports). Two reports are written here, with the
documents' field names, units and order:

* the **velocity-and-transducer report**, one per velocity calculation: ``time`` (ms since
  the previous report), ``vx, vy, vz`` (m/s, the DVL's body frame: x forward, y right,
  z down), ``fom`` (figure of merit, m/s), ``covariance`` (3 x 3, (m/s)^2; the figure of
  merit is derived from it), ``altitude`` (m, to the reflecting surface along z),
  ``transducers`` (per beam: ``id`` 0-3, ``velocity`` along the beam (m/s),
  ``distance`` along the beam (m), ``rssi`` and ``nsd`` (dBm), ``beam_valid``),
  ``velocity_valid`` (lock on the surface: the velocities and altitude are valid),
  ``status`` (bit 0: high temperature), ``tracking_mode`` (``bottom`` or ``water``),
  ``format``, ``type`` (``velocity``, or ``velocity_water`` in water tracking),
  ``time_of_validity`` and ``time_of_transmission`` (Unix time, microseconds);
* the **dead reckoning report** ``position_local``: ``ts`` (Unix s), ``x, y, z`` (m,
  in the frame of the DVL's axes at the start of the run, z down), ``std`` (m),
  ``roll, pitch, yaw`` (degrees), ``type``, ``status`` (0: no error), ``format``.

What the documents leave open, the simulator chooses: without lock the velocities are
sent as 0 and the altitude as -1, as a transducer that decoded nothing sends distance -1
and velocity 0; a report flagged invalid while locked (``locked``) carries its
velocity and altitude with every beam valid, as the A50 in
``../shared/data/waterlinked_dvl_a50_json_tank`` sends 2.5-4.5 % of its reports while
driven; the four beams are tilted :data:`BEAM_TILT_RAD` from z at the azimuths
:data:`BEAM_AZIMUTHS_RAD` (ids in that order), their velocity the projection of the
DVL's velocity on the beam; without a covariance of its own a report carries
``fom^2`` on the diagonal; a report is transmitted at its time of validity.
"""

from __future__ import annotations

import json
import math
from typing import Any, Sequence

FORMAT = "json_v3.2"
"""The protocol version the reports name (Water Linked software 2.7.1 and later)."""
BEAM_TILT_RAD = math.radians(22.5)
"""Tilt of each transducer's beam from the DVL's z axis (the A50's)."""
BEAM_AZIMUTHS_RAD = tuple(math.radians(a) for a in (45.0, 135.0, 225.0, 315.0))
"""Azimuth of each beam from x towards y (rad), beam ids 0-3 in this order."""
RSSI_LOCKED_DBM = -40.0
"""Received signal strength of a beam that sees the surface (dBm)."""
RSSI_LOST_DBM = -90.0
"""Received signal strength of a beam that does not (dBm)."""
NSD_DBM = -95.0
"""Noise spectral density of every beam (dBm)."""
UNKNOWN_DISTANCE_M = -1.0
"""Distance (and altitude) sent when nothing was decoded."""
US_PER_S = 1_000_000
"""Microseconds per second (the report times)."""


def _line(report: dict[str, Any]) -> bytes:
    return json.dumps(report, allow_nan=False).encode("ascii") + b"\n"


def beam_direction(azimuth_rad: float) -> tuple[float, float, float]:
    """The unit vector of the beam at ``azimuth_rad`` in the DVL's body frame."""
    s = math.sin(BEAM_TILT_RAD)
    return s * math.cos(azimuth_rad), s * math.sin(azimuth_rad), math.cos(BEAM_TILT_RAD)


def transducers(vx: float, vy: float, vz: float, altitude_m: float,
                valid: bool) -> list[dict[str, Any]]:
    """The four beams' entries of a velocity report."""
    out = []
    for i, azimuth in enumerate(BEAM_AZIMUTHS_RAD):
        bx, by, bz = beam_direction(azimuth)
        out.append({
            "id": i,
            "velocity": bx * vx + by * vy + bz * vz if valid else 0.0,
            "distance": altitude_m / bz if valid else UNKNOWN_DISTANCE_M,
            "rssi": RSSI_LOCKED_DBM if valid else RSSI_LOST_DBM,
            "nsd": NSD_DBM,
            "beam_valid": valid,
        })
    return out


def velocity_report(vx: float, vy: float, vz: float, *, valid: bool, fom_mps: float,
                    altitude_m: float | None, dt_s: float, t_validity_s: float,
                    covariance: Sequence[float] | None = None,
                    track: str = "bottom", locked: bool | None = None) -> bytes:
    """One velocity-and-transducer report line: velocity (m/s, body frame), figure of
    merit (m/s), altitude (m; None: unknown), time since the previous report (s), time of
    validity (Unix s), row-major covariance ((m/s)^2), ``track`` ``bottom`` or ``water``.
    ``locked`` (default: ``valid``): the beams see the bottom; an invalid report flagged
    while locked carries its velocity and altitude, one without lock zeros and -1."""
    locked = valid if locked is None else locked
    if not locked:
        vx = vy = vz = 0.0
    alt = altitude_m if locked and altitude_m is not None else UNKNOWN_DISTANCE_M
    cov = list(covariance) if covariance is not None else [
        fom_mps ** 2 if i % 4 == 0 else 0.0 for i in range(9)]
    t_us = int(round(t_validity_s * US_PER_S))
    return _line({
        "time": dt_s * 1000.0, "vx": vx, "vy": vy, "vz": vz, "fom": fom_mps,
        "covariance": [cov[0:3], cov[3:6], cov[6:9]], "altitude": alt,
        "transducers": transducers(vx, vy, vz, alt, locked and alt > 0.0),
        "velocity_valid": valid, "status": 0, "tracking_mode": track, "format": FORMAT,
        "type": "velocity_water" if track == "water" else "velocity",
        "time_of_validity": t_us, "time_of_transmission": t_us,
    })


def dead_reckoning_report(x_m: float, y_m: float, z_m: float, *, t_s: float, std_m: float,
                          roll_rad: float, pitch_rad: float, yaw_rad: float) -> bytes:
    """One ``position_local`` line: position (m, z down), its standard deviation (m),
    attitude (rad, sent in degrees), time stamp (Unix s)."""
    return _line({
        "ts": t_s, "x": x_m, "y": y_m, "z": z_m, "std": std_m,
        "roll": math.degrees(roll_rad), "pitch": math.degrees(pitch_rad),
        "yaw": math.degrees(yaw_rad), "type": "position_local", "status": 0,
        "format": FORMAT,
    })
