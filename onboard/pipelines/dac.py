"""A glider's depth-averaged current, dive by dive (pipeline ``dac``; the estimator is
:class:`onboard.estimators.dive_average.DiveAverage`, algorithms.md §3.7).

A thin adapter: fixes into the local frame about the first one, each depth sample with
the newest pitch, heading and pump volume, and at each tick the newest dive's current.
Built only where ``[pipelines.dac] enabled = true`` (config/slocum-glider.toml); the glider
model is ``[pipelines.current.glider]``'s (its defaults, the Slocum's published
coefficients, where the config has none).

``columns``: north, east (m/s) of the newest dive's depth-averaged current and their
``std_*``; ``dive_start``, ``dive_end``: the times (s, the log's clock) of the two fixes
that bound it; ``place_north``, ``place_east``: their midpoint (m from the first fix),
where the dive's current applies. Nothing before the first dive has ended.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import msgspec

from onboard.core.config import Config
from onboard.core.geo import LocalFrame
from onboard.core.messages import ActuatorCommand, Attitude, Depth, GnssFix, Heading, Sample
from onboard.core.pipeline_config import GliderModelConfig
from onboard.estimators.dive_average import MAX_DEPTH_INTERVAL_S, DiveAverage
from onboard.pipelines.base import PipelineDefaults
from onboard.pipelines.current_samples import glider_model


class DacHealth(msgspec.Struct, frozen=True):
    """The dives so far (:class:`DiveAveragePipeline.health`)."""

    dives: int
    """Dives that gave a current."""
    unfollowed: int
    """Dives the log was too sparse to follow (no current)."""

    def flat(self) -> dict[str, float]:
        """``dives``, ``unfollowed``."""
        return {"dives": float(self.dives), "unfollowed": float(self.unfollowed)}


class DiveAveragePipeline(PipelineDefaults):
    """Pipeline ``dac`` (module docstring)."""

    name = "dac"
    columns = ("north", "east", "std_north", "std_east", "dive_start", "dive_end",
               "place_north", "place_east")

    def __init__(self, dac: DiveAverage) -> None:
        self.dac = dac
        self._frame: LocalFrame | None = None
        self._pitch = (-math.inf, math.nan)     # (t, value)
        self._heading = (-math.inf, math.nan)
        self._pump = 0.0

    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        """Take ``samples`` in order; the newest dive's current at tick ``t`` (s)."""
        dac = self.dac
        for s in samples:
            if isinstance(s, GnssFix):
                if self._frame is None:
                    self._frame = LocalFrame(s.lat_deg, s.lon_deg)
                dac.fix(s.t, *self._frame.to_ne(s.lat_deg, s.lon_deg))
            elif isinstance(s, Heading):
                self._heading = (s.t, s.heading_rad)
            elif isinstance(s, Attitude):
                self._pitch = (s.t, s.pitch_rad)
                if s.yaw_selected and s.t - self._heading[0] > MAX_DEPTH_INTERVAL_S:
                    self._heading = (s.t, s.yaw_rad)
            elif isinstance(s, ActuatorCommand) and s.pump_cc is not None:
                self._pump = s.pump_cc
            elif isinstance(s, Depth):
                dac.depth(s.t, s.depth_m, self._fresh(self._pitch, s.t),
                          self._fresh(self._heading, s.t), self._pump)
        d = dac.latest
        if d is None:
            return {}
        return {"north": d.north, "east": d.east, "std_north": d.std_north,
                "std_east": d.std_east,
                "dive_start": d.t_start, "dive_end": d.t_end,
                "place_north": d.place[0], "place_east": d.place[1]}

    @staticmethod
    def _fresh(measured: tuple[float, float], t: float) -> float:
        """The value of ``measured`` (its time, value) at ``t``: NaN when older than
        :data:`.dive_average.MAX_DEPTH_INTERVAL_S`."""
        return measured[1] if t - measured[0] <= MAX_DEPTH_INTERVAL_S else math.nan

    def lacks(self) -> str:
        """What kept every dive from giving a current."""
        if self._frame is None:
            return "a GNSS fix at the surface before and after a dive: the log has none"
        return (f"a dive of at least {self.dac.min_dive_s:.0f} s between two surface fixes, "
                f"its flight followed by depth, pitch and heading samples "
                f"({self.dac.unfollowed} dive(s) too sparsely logged)")

    def innovations(self) -> list:
        """None: a dive's current is computed, not a filter's update."""
        return []

    def health(self) -> DacHealth:
        """Its dives so far."""
        return DacHealth(self.dac.dives, self.dac.unfollowed)

    def get_state(self) -> dict[str, Any]:
        """Nothing: each dive stands alone."""
        return {}

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Nothing to restore (see :meth:`get_state`)."""
        return None


def create(cfg: Config) -> DiveAveragePipeline | None:
    """Pipeline ``dac`` where the config enables it."""
    pc = cfg.pipelines.dac
    if not pc.enabled:
        return None
    glider = cfg.pipelines.current.glider or GliderModelConfig()
    return DiveAveragePipeline(DiveAverage(
        glider_model(glider), surface_depth_m=cfg.sensors.depth.surface_depth_m,
        position_std_m=cfg.sensors.gnss.position_std_m, min_dive_s=pc.min_dive_s,
        heading_std=cfg.sensors.compass.heading_std_rad,
        lift_rel_std=pc.lift_rel_std, pitch_bias_std=pc.pitch_bias_std_rad,
        trim_std=pc.trim_std_cc,
        vertical_displacement_std=pc.vertical_displacement_std_m,
        vertical_displacement_time_s=pc.vertical_displacement_time_s))
