"""The engine: validated samples in, estimates out on a fixed-rate tick, the same live and
in replay (docs/architecture.md §3).

:mod:`.engine` holds :class:`Engine` (queue and tick) and :func:`run` (a log through it);
each step of a sample's way to the pipelines is a module of its own: the time line of a
log (:mod:`.timeline`), the per-sample checks (:mod:`.checks`), magnetic headings made
true (:mod:`.declination`), the known sensor errors (:mod:`.corrections`), pressure to
depth and the surface/submerged mode (:mod:`.depth`), one source per quantity
(:mod:`.sources`), actuator outputs to commands (:mod:`.inputs`) and the GNSS latency's
fusion horizon (:mod:`.latency`).
"""

from onboard.engine.engine import Engine, TickQueue, run

__all__ = ["Engine", "TickQueue", "run"]
