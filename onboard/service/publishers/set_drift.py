"""Set and drift: a water current as chart plotters show it, and the two wire forms they read.

A current is estimated as north and east components (m/s, the direction it flows to).
Sailors read it as *set* (the direction it flows to, degrees true or magnetic, clockwise
from north) and *drift* (its speed; knots on NMEA 0183, m/s in Signal K). Everything here
is pure (numbers in, text or a dict out): the vehicle's publishers
(:mod:`.chartplot`) and the fleet service use the same functions on any (north, east) pair.

* NMEA 0183 ``VDR`` (Set and Drift; NMEA 0183 v4.11 and every version since 1.5)::

      $--VDR,x.x,T,x.x,M,x.x,N*hh<CR><LF>
             set true, set magnetic (empty where the declination is unknown), drift (knots)

  ``hh`` is the XOR of every byte between ``$`` and ``*``, two upper-case hex digits.
* Signal K ``environment.current`` (Signal K specification 1.7, ``vessels/<id>/environment/
  current``): ``{"setTrue": rad, "setMagnetic": rad, "drift": m/s}`` in a delta
  ``{"context": ..., "updates": [{"source": ..., "timestamp": ISO-8601, "values":
  [{"path": "environment.current", "value": {...}}]}]}``; ``setMagnetic`` is left out where
  the declination is unknown (every property is optional in the schema).

Magnetic set = true set - declination (east positive): a current flowing to 090 T under a
declination of 10 E flows to 080 M.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any

from onboard.core.messages import EstimateRecord

__all__ = ["KNOT_MPS", "SetDrift", "current_of", "iso8601", "nmea_checksum", "set_drift",
           "signalk_delta", "vdr_sentence"]

KNOT_MPS = 1852.0 / 3600.0
"""One knot in m/s (the international nautical mile, 1852 m, per hour)."""
SIGNALK_PATH = "environment.current"
VDR_TALKER = "II"
"""NMEA 0183 talker of integrated instrumentation (the talker of a computed set and drift)."""


@dataclass(frozen=True)
class SetDrift:
    """A current as set and drift.

    Attributes:
        set_true_rad: direction it flows to, clockwise from true north, in [0, 2 pi).
        set_magnetic_rad: the same from magnetic north; None where the declination is unknown.
        drift_mps: its speed (m/s).
    """

    set_true_rad: float
    set_magnetic_rad: float | None
    drift_mps: float

    @property
    def drift_kn(self) -> float:
        """The drift in knots."""
        return self.drift_mps / KNOT_MPS


def set_drift(north_mps: float, east_mps: float, declination_deg: float | None = None) -> SetDrift:
    """Set and drift of the current (``north_mps``, ``east_mps``) (m/s, the direction it
    flows to); ``declination_deg`` (east positive) gives the magnetic set, None leaves it
    unknown. A current of exactly zero has set 0."""
    set_true = math.atan2(east_mps, north_mps) % math.tau
    set_mag = None
    if declination_deg is not None and math.isfinite(declination_deg):
        set_mag = (set_true - math.radians(declination_deg)) % math.tau
    return SetDrift(set_true, set_mag, math.hypot(north_mps, east_mps))


def current_of(rec: EstimateRecord | None) -> tuple[float, float] | None:
    """(north, east) (m/s) of a ``current`` record when both are known, else None: a
    component the data do not determine, or one the integrity monitor withheld, is absent
    from the published record (architecture.md §4.4), and then there is no set to show."""
    if rec is None:
        return None
    n, e = rec.values.get("north"), rec.values.get("east")
    if n is None or e is None or not (math.isfinite(n) and math.isfinite(e)):
        return None
    return n, e


def nmea_checksum(body: str) -> str:
    """The NMEA 0183 checksum of ``body`` (the characters between ``$`` and ``*``): the
    XOR of their bytes as two upper-case hex digits."""
    x = 0
    for b in body.encode("ascii"):
        x ^= b
    return f"{x:02X}"


def vdr_sentence(sd: SetDrift, talker: str = VDR_TALKER) -> str:
    """The ``VDR`` sentence of ``sd`` with its checksum and CR LF: set to 0.1 degree,
    drift to 0.01 knot, the magnetic set empty where unknown."""
    mag = "" if sd.set_magnetic_rad is None else _degrees(sd.set_magnetic_rad)
    body = f"{talker}VDR,{_degrees(sd.set_true_rad)},T,{mag},M,{sd.drift_kn:.2f},N"
    return f"${body}*{nmea_checksum(body)}\r\n"


def _degrees(rad: float) -> str:
    """An angle in [0, 2 pi) as degrees to 0.1 in [0, 360): 359.96 deg is ``0.0``."""
    return f"{round(math.degrees(rad), 1) % 360.0:.1f}"


def iso8601(utc_s: float) -> str:
    """Seconds since the Unix epoch as Signal K's ISO-8601 UTC time
    (``2026-11-29T00:41:54.123Z``, milliseconds)."""
    dt = datetime.fromtimestamp(utc_s, tz=timezone.utc)
    return dt.strftime("%Y-%m-%dT%H:%M:%S.") + f"{dt.microsecond // 1000:03d}Z"


def signalk_delta(sd: SetDrift, utc_s: float, context: str = "vessels.self",
                  label: str = "onboard") -> dict[str, Any]:
    """The Signal K delta of ``sd`` at ``utc_s`` (s since the Unix epoch) for ``context``
    (``vessels.self``, or ``vessels.urn:mrn:...`` of another vessel), its source labelled
    ``label``."""
    value: dict[str, float] = {"setTrue": sd.set_true_rad, "drift": sd.drift_mps}
    if sd.set_magnetic_rad is not None:
        value["setMagnetic"] = sd.set_magnetic_rad
    return {"context": context,
            "updates": [{"source": {"label": label, "type": "onboard"},
                         "timestamp": iso8601(utc_s),
                         "values": [{"path": SIGNALK_PATH, "value": value}]}]}
