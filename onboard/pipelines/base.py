"""The contract every estimation pipeline fulfils.

A pipeline is pure and synchronous: numbers in, numbers out. No I/O, no clock, no
asyncio, no global state. The engine calls :meth:`Pipeline.step` once per fixed-rate tick
with the samples that arrived since the previous tick, in time order. Because the
pipeline sees only its inputs, live operation and replay give identical results.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from operator import attrgetter
from typing import Any, Callable, Mapping, Protocol, Sequence, runtime_checkable

import msgspec

from onboard.core.config import Config
from onboard.core.geo import LocalFrame
from onboard.core.messages import Innovation, Sample


class PipelineHealth(Protocol):
    """What a pipeline's :meth:`Pipeline.health` returns: its own counters and
    diagnostics as typed fields, and their flat form for the records."""

    def flat(self) -> dict[str, float]:
        """Every field by its dotted name (e.g. ``surge.steps``), in a fixed order: the
        pipeline's entry of the health record's ``counters`` (architecture.md §4.4) and
        of summary.json's ``pipeline_health``."""
        ...


class NoHealth(msgspec.Struct, frozen=True):
    """The health of a pipeline that has no filter to report on."""

    def flat(self) -> dict[str, float]:
        """Nothing."""
        return {}


@runtime_checkable
class Pipeline(Protocol):
    """One estimator family, e.g. ``aie`` or ``current``.

    A pipeline class subclasses :class:`PipelineDefaults` for the defaults of the roles
    below (a plain class: mypyc, setup.py, compiles no class that inherits attribute
    defaults from a protocol).

    Attributes:
        name: the pipeline name, the prefix of its columns in estimates.csv and its
            Zenoh key ``onboard/<id>/est/<name>``.
        columns: the quantities it can estimate (without the prefix), in the order they
            appear in estimates.csv. Fixed at construction.

    Roles: what its outputs mean, declared as class attributes (empty by default). The
    engine and the monitors read these, never a pipeline's name:

    * ``position``: the columns that are an estimated position (m, north then east,
      each with its ``std_<q>``) in the frame below.
    * ``speed``: its forward speed over ground (m/s, negative astern) and, for a vehicle
      that moves sideways, its sideways speed, each with its ``std_<q>``.
    * ``heading_dependent``: the columns computed by turning a velocity with the
      heading: unknown while the heading disagrees with the course over ground.
    * ``heading_estimate``: its published heading (rad) with its ``std_<q>``: its sigma widened
      by a compass deviation the integrity monitor detects, and withheld with its
      ``position`` while the heading disagrees with the course over ground.
    * ``current_estimate``: its water current (north, east; m/s) with its ``std_<q>``: withheld
      while it disagrees with the vehicle's drift with the thrusters idle.
    * ``unpublished_channels``: its innovation channels whose forecast is of a quantity it
      publishes without a sigma and from which no published sigma takes a factor: an NIS
      below its band there says that forecast is conservative, not that a published sigma
      is (the integrity monitor says so once, ``nis_unpublished``); above its band it is
      ``nis_out_of_band`` as on every channel (algorithms.md §9.2).
    * ``calibrating_channels``: its innovation channels whose innovations correct a
      published sigma both ways while the filter's own covariance keeps its tuning (the
      ESESO's ``thrust``: the disturbance's excess, algorithms.md §5.1): an NIS below its
      band there says the filter's forecast is conservative and the published sigma
      already narrowed (the integrity monitor says so once, ``nis_corrected``); above its
      band it is ``nis_out_of_band`` as on every channel.
    * ``regression_channels``: its innovation channels that are a regression's a-priori
      residuals rather than a filter's measurement updates (the current's yaw RLS): their
      predicted variance is the regression's own running residual variance, which no
      gain uses and no published sigma takes, so their NIS out of its band on either
      side is information (``nis_unpublished``), never ``nis_out_of_band``
      (algorithms.md §9.2).
    * ``frame``: the local tangent plane about its first fix (None: no position, or no
      fix yet).
    * ``frame_offset``: where ``frame``'s origin lies in its published position (north,
      east; m); None: its positions are metres from the first fix handed to the
      pipelines (the documented origin, architecture.md §4.2).
    """

    name: str
    columns: tuple[str, ...]
    position: tuple[str, ...]
    speed: tuple[str, ...]
    heading_dependent: tuple[str, ...]
    heading_estimate: tuple[str, ...]
    current_estimate: tuple[str, ...]
    unpublished_channels: tuple[str, ...]
    calibrating_channels: tuple[str, ...]
    regression_channels: tuple[str, ...]
    frame: LocalFrame | None
    frame_offset: tuple[float, float] | None

    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        """Advance to tick time ``t`` (s) given the new ``samples`` (time-ordered, all
        with ``sample.t <= t``); return the current estimates by quantity name. A quantity
        with no estimate yet is simply absent from the mapping."""
        ...

    def innovations(self) -> list[Innovation]:
        """The :class:`~onboard.core.messages.Innovation` records of the measurement
        updates since the last call, one per update (accepted or rejected, with the
        reason); the pipeline keeps none of them after the call."""
        ...

    def take_events(self) -> list[str]:
        """Human-readable events since the last call (e.g. a restored state discarded);
        the pipeline keeps none of them after the call. The engine moves them into its
        health events, prefixed with the pipeline name. None by default."""
        ...

    def health(self) -> PipelineHealth:
        """Its own counters and diagnostics (e.g. an axis's steps and divergences): the
        pipeline's numbers beside its innovations."""
        ...

    def lacks(self) -> str:
        """What it lacked in the samples it was given, in words ("a velocity over ground:
        ..."), for the warning of a pipeline that gave no estimate; empty when it cannot
        say (the default)."""
        ...

    def get_state(self) -> dict[str, Any]:
        """Adaptive state worth keeping across a restart (JSON-serializable)."""
        ...

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore what :meth:`get_state` returned; ignore what does not fit."""
        ...


class PipelineDefaults:
    """What a pipeline is by default (:class:`Pipeline`): its roles empty, no frame, no
    events. Every pipeline class subclasses it."""

    position: tuple[str, ...] = ()
    speed: tuple[str, ...] = ()
    heading_dependent: tuple[str, ...] = ()
    heading_estimate: tuple[str, ...] = ()
    current_estimate: tuple[str, ...] = ()
    unpublished_channels: tuple[str, ...] = ()
    calibrating_channels: tuple[str, ...] = ()
    regression_channels: tuple[str, ...] = ()
    frame: LocalFrame | None = None
    frame_offset: tuple[float, float] | None = None

    def take_events(self) -> list[str]:
        """No events (:meth:`Pipeline.take_events`)."""
        return []

    def lacks(self) -> str:
        """Nothing it can name (:meth:`Pipeline.lacks`)."""
        return ""


def unused_measurement(channel: str, t: float, dof: int, reason: str,
                       source: str = "") -> Innovation:
    """The record of a measurement rejected before any update (invalid, not finite, ...):
    without a forecast its innovation, covariance and NIS are not numbers."""
    nan = math.nan
    return Innovation(channel=channel, t=t, z=(nan,) * dof, S=(nan,) * (dof * dof),
                      nis=nan, dof=dof, accepted=False, reason=reason, source=source)


sample_time: Callable[[Sample], float] = attrgetter("t")
"""The sort key of samples: their time (s); the sort is stable, so arrival order breaks
ties."""


def split_at(samples: list[Sample], horizon: float) -> tuple[list[Sample], list[Sample]]:
    """``samples`` sorted by time in place, split into those stamped at or before
    ``horizon`` (s) and the newer ones."""
    if len(samples) > 1:
        samples.sort(key=sample_time)
    cut = bisect.bisect_right(samples, horizon, key=sample_time)
    return samples[:cut], samples[cut:]


class LateSampleHold:
    """A pipeline's own fusion horizon, held behind the tick by as much as its samples
    have arrived late (a reorder buffer sized by what it sees).

    A Water Linked DVL stamps its report with the instant it measured
    (``time_of_validity``) and sends it after its processing: it reaches the service later
    than the autopilot's frames of that instant, so a pipeline stepped at each tick would
    get it after samples newer than it. :meth:`release` hands a pipeline the samples up to
    a horizon ``tick - hold`` in time order, where ``hold`` is the largest lateness (the
    tick it arrived at minus its stamp) of the samples that arrived behind the horizon
    already passed in the last ``memory_s``, at most ``max_hold_s``. While nothing arrives
    late, ``hold`` is 0 and the samples pass through at the tick as before. The horizon
    never goes back: when ``hold`` grows, it waits for the ticks to catch up. The
    estimates of a pipeline that holds are those of its horizon, up to ``max_hold_s`` old.
    Everything here is a function of the sample and tick times, so a replay holds exactly
    as the live run did.

    Attributes:
        hold_s: the current hold (s).
        late: samples that arrived behind the horizon already passed.
        too_late: of those, samples later than ``max_hold_s`` (handed on at once, out of
            time order).
    """

    def __init__(self, max_hold_s: float, memory_s: float = 60.0) -> None:
        self.max_hold_s = max_hold_s
        self.memory_s = memory_s
        self.hold_s = 0.0
        self.late = 0
        self.too_late = 0
        self._held: list[Sample] = []
        self._horizon = -math.inf
        self._lateness: deque[tuple[float, float]] = deque()
        """(tick time, lateness) of the late arrivals within ``memory_s``."""

    def release(self, t: float, samples: Sequence[Sample]
                ) -> tuple[float, Sequence[Sample]]:
        """The tick at ``t`` (s) with its samples (time-ordered): the horizon (s) and the
        samples up to it, in time order."""
        if self.max_hold_s <= 0.0:
            return t, samples
        horizon = self._horizon
        for s in samples:
            if s.t < horizon:
                self.late += 1
                lateness = t - s.t
                if lateness > self.max_hold_s:
                    self.too_late += 1
                self._lateness.append((t, min(lateness, self.max_hold_s)))
        mem = self._lateness
        while mem and mem[0][0] < t - self.memory_s:
            mem.popleft()
        self.hold_s = max((x for _, x in mem), default=0.0)
        if not self.hold_s and not self._held:
            self._horizon = t
            return t, samples
        self._held.extend(samples)
        horizon = max(self._horizon, t - self.hold_s)
        due, self._held = split_at(self._held, horizon)
        self._horizon = horizon
        return horizon, due


class PipelineFactory(Protocol):
    """The ``create(cfg)`` function every pipeline module exposes
    (:func:`onboard.pipelines.build` calls it)."""

    def __call__(self, cfg: Config) -> Pipeline | None:
        """Build the pipeline for this configuration, or None if it does not apply."""
        ...
