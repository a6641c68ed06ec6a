"""The measured navigation track: what the sensors say, before any estimator.

Not an estimator but the reference every estimate is compared with: GNSS position in the
local tangent plane about the first fix (algorithms.md §1.3), speed and course over
ground, heading (compass or autopilot attitude), velocity over ground from an INS or DVL
navigation solution, and depth. Each value holds the latest measurement; a value whose
sensor has been silent for ``stale_s`` seconds is dropped rather than repeated.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

from onboard.config import Config
from onboard.messages import Attitude, Depth, GnssFix, Heading, Sample, VelocityOverGround
from onboard.pipelines.geo import LocalFrame, wrap_2pi


class NavTrack:
    """Latest measured position, heading, speed and depth (pipeline ``nav``)."""

    name = "nav"
    columns = ("north", "east", "speed", "course", "heading", "v_north", "v_east", "depth")

    def __init__(self, stale_s: float = 5.0) -> None:
        self.stale_s = stale_s
        self.frame: LocalFrame | None = None
        self._values: dict[str, tuple[float, float]] = {}  # quantity -> (t, value)
        self._heading_from_attitude_only = True

    def _set(self, t: float, **values: float) -> None:
        for k, v in values.items():
            self._values[k] = (t, v)

    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        for s in samples:
            if isinstance(s, GnssFix):
                if self.frame is None:
                    self.frame = LocalFrame(s.lat_deg, s.lon_deg)
                n, e = self.frame.to_ne(s.lat_deg, s.lon_deg)
                self._set(s.t, north=n, east=e)
                if s.sog_mps is not None:
                    self._set(s.t, speed=s.sog_mps)
                if s.cog_rad is not None:
                    self._set(s.t, course=wrap_2pi(s.cog_rad))
            elif isinstance(s, Heading):
                self._heading_from_attitude_only = False
                self._set(s.t, heading=wrap_2pi(s.heading_rad + (s.declination_rad or 0.0)))
            elif isinstance(s, Attitude) and self._heading_from_attitude_only:
                self._set(s.t, heading=wrap_2pi(s.yaw_rad))
            elif isinstance(s, VelocityOverGround):
                self._set(s.t, v_north=s.v_north_mps, v_east=s.v_east_mps)
            elif isinstance(s, Depth):
                self._set(s.t, depth=s.depth_m)
        out = {k: v for k, (ts, v) in self._values.items() if t - ts <= self.stale_s}
        if "speed" not in out and "v_north" in out:
            out["speed"] = math.hypot(out["v_north"], out["v_east"])
        return out

    def health(self) -> Mapping[str, float]:
        return {}

    def get_state(self) -> dict[str, Any]:
        return {}

    def set_state(self, state: Mapping[str, Any]) -> None:
        return None


def create(cfg: Config) -> NavTrack:
    return NavTrack()
