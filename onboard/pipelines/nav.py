"""The measured navigation track: what the sensors say, before any estimator.

Not an estimator but the reference every estimate is compared with: GNSS position in the
local tangent plane about the first fix (algorithms.md §1.3), speed and course over
ground, heading (compass or autopilot attitude), velocity over ground from an INS or DVL
navigation solution, and depth. Each value holds the latest measurement; a value whose
sensor has been silent for ``stale_s`` seconds is dropped rather than repeated.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping, Sequence

from mypy_extensions import mypyc_attr

from onboard.core.config import Config
from onboard.core.geo import LocalFrame, wrap_2pi
from onboard.core.messages import (
    Attitude,
    Depth,
    GnssFix,
    Heading,
    Innovation,
    Sample,
    VelocityOverGround,
)
from onboard.pipelines.base import NoHealth, PipelineDefaults

HEADING_HOLD_S = 1.0
"""An ``Attitude`` yaw within this long (s) after a ``Heading`` sample is not used; the
engine's source selector lets one heading source through, and an ``Attitude`` whose yaw
it did not select (``yaw_selected`` False) gives no heading."""


@mypyc_attr(allow_interpreted_subclasses=True)
class NavTrack(PipelineDefaults):
    """Latest measured position, heading, speed and depth (pipeline ``nav``).

    It declares no roles: its position and speed are the measurements the estimates are
    checked against, not estimates; ``frame`` is the local frame about its first fix."""

    name = "nav"
    columns = ("north", "east", "speed", "course", "heading", "v_north", "v_east", "depth")

    def __init__(self, stale_s: float = 5.0) -> None:
        self.stale_s = stale_s
        self.frame: LocalFrame | None = None
        self._values: dict[str, tuple[float, float]] = {}  # quantity -> (t, value)
        self._t_heading = -math.inf  # time (s) of the newest Heading sample
        self._handlers: dict[type, Callable[[NavTrack, Any], None] | None] = {}

    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        """Take the newest measurements from ``samples``; return those at most
        ``stale_s`` seconds older than the tick time ``t`` (s)."""
        handlers = self._handlers
        for s in samples:
            cls = type(s)
            h = handlers[cls] if cls in handlers else self._handler(cls)
            if h is not None:
                h(self, s)
        stale = self.stale_s
        out = {k: v for k, (ts, v) in self._values.items() if t - ts <= stale}
        if "speed" not in out and "v_north" in out:
            out["speed"] = math.hypot(out["v_north"], out["v_east"])
        return out

    def _handler(self, cls: type) -> Callable[[NavTrack, Any], None] | None:
        """The intake function for a sample class (None: not used), cached per class;
        subclasses get their base's handler. The class's functions, not methods bound to
        this object, so that a copy of it (the GNSS latency's fork) handles its samples
        itself."""
        h: Callable[[NavTrack, Any], None] | None = None
        for base, fn in ((GnssFix, NavTrack._on_fix), (Heading, NavTrack._on_heading),
                         (Attitude, NavTrack._on_attitude),
                         (VelocityOverGround, NavTrack._on_vog), (Depth, NavTrack._on_depth)):
            if issubclass(cls, base):
                h = fn
                break
        self._handlers[cls] = h
        return h

    def _on_fix(self, s: GnssFix) -> None:
        if self.frame is None:
            self.frame = LocalFrame(s.lat_deg, s.lon_deg)
        n, e = self.frame.to_ne(s.lat_deg, s.lon_deg)
        values, t = self._values, s.t
        values["north"] = (t, n)
        values["east"] = (t, e)
        if s.sog_mps is not None:
            values["speed"] = (t, s.sog_mps)
        if s.cog_rad is not None:
            values["course"] = (t, wrap_2pi(s.cog_rad))

    def _on_heading(self, s: Heading) -> None:
        self._t_heading = s.t
        self._values["heading"] = (s.t, wrap_2pi(s.heading_rad))

    def _on_attitude(self, s: Attitude) -> None:
        if s.yaw_selected and s.t - self._t_heading > HEADING_HOLD_S:
            self._values["heading"] = (s.t, wrap_2pi(s.yaw_rad))

    def _on_vog(self, s: VelocityOverGround) -> None:
        self._values["v_north"] = (s.t, s.v_north_mps)
        self._values["v_east"] = (s.t, s.v_east_mps)

    def _on_depth(self, s: Depth) -> None:
        self._values["depth"] = (s.t, s.depth_m)

    def innovations(self) -> list[Innovation]:
        """None: the measured track makes no measurement update."""
        return []

    def health(self) -> NoHealth:
        """Nothing: the measured track has no filter to report on."""
        return NoHealth()

    def get_state(self) -> dict[str, Any]:
        """Nothing: the measured track keeps no adaptive state."""
        return {}

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Nothing to restore (see :meth:`get_state`)."""
        return None


def create(cfg: Config) -> NavTrack:
    """Pipeline ``nav`` (every vehicle class)."""
    return NavTrack()
