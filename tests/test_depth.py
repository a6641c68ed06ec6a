"""Pressure to depth and the surface/submerged mode (onboard.engine.depth)."""

from __future__ import annotations

import pytest

from onboard.core.config import DepthNoise
from onboard.core.messages import Depth, Pressure
from onboard.engine.depth import GRAVITY, SUBMERGED, SURFACE, DepthMode


def test_pressure_becomes_depth_by_hydrostatics():
    """d = (p - p_surface) / (rho g): 10 m of sea water is 100.5 kPa over the surface."""
    dm = DepthMode(DepthNoise(water_density_kgm3=1025.0, surface_pressure_pa=101325.0))
    d = dm.depth(Pressure(t=3.0, source="bar30", pressure_pa=101325.0 + 1025.0 * GRAVITY * 10.0,
                          temperature_c=12.0))
    assert isinstance(d, Depth) and d.depth_m == pytest.approx(10.0, rel=1e-12)
    assert (d.t, d.source, d.temperature_c) == (3.0, "bar30", 12.0)


def test_mode_follows_the_newest_depth_across_the_surface_threshold():
    dm = DepthMode(DepthNoise(surface_depth_m=0.3))
    assert dm.mode == SURFACE and dm.depth_m is None and not dm.submerged
    dm.observe(Depth(t=1.0, depth_m=0.31))
    assert dm.mode == SUBMERGED and dm.submerged and dm.depth_m == 0.31
    dm.observe(Depth(t=2.0, depth_m=0.3))  # at the threshold: surface
    assert dm.mode == SURFACE
