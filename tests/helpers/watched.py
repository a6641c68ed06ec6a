"""Pipelines as the integrity monitor sees them (``IntegrityMonitor.watch``): their names
and roles only, for tests that feed the monitor samples and records by hand."""

from __future__ import annotations


class Boat:
    """A pipeline with a heading and a position (``aie``)."""

    name = "aie"
    position = ("north", "east")
    speed = ("speed",)
    heading_dependent: tuple[str, ...] = ()
    heading_estimate = ("heading",)
    current_estimate: tuple[str, ...] = ()
    frame = None
    frame_offset = None


class Current:
    """A pipeline that publishes a current (``current``)."""

    name = "current"
    position: tuple[str, ...] = ()
    speed: tuple[str, ...] = ()
    heading_dependent = ("north", "east", "u_r", "v_r")
    heading_estimate: tuple[str, ...] = ()
    current_estimate = ("north", "east")
    frame = None
    frame_offset = None
