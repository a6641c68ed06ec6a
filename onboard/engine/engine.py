"""The engine: time-ordered samples in, fixed-rate pipeline ticks out.

One engine serves live operation and replay (architecture.md §3). It queues and ticks;
each step of the way is a named module:

* :meth:`Engine.admit` puts each sample on the time line first (:mod:`onboard.engine.timeline`):
  a single stamp far from its neighbours is dropped and counted (``<type>:time_outlier``),
  a confirmed clock jump starts a new segment (:meth:`Engine.start_segment`);
* :meth:`Engine.push` takes one sample through
  1. the value checks of :mod:`onboard.engine.checks` (a rejection is counted with its reason),
  2. magnetic headings made true (:mod:`onboard.engine.declination`: the configured declination,
     the sensor's own, or the World Magnetic Model at the first fix),
  3. the ``[corrections]`` (:class:`onboard.engine.corrections.SampleCorrector`),
  4. the time checks (backwards in its stream, older than ``max_sample_age_s``),
  5. pressure to depth and the surface/submerged mode (:mod:`onboard.engine.depth`; GNSS is
     accepted only at the surface),
  6. one source per quantity (:mod:`onboard.engine.sources`),
  7. the queue, with the normalized command of a raw actuator output
     (:mod:`onboard.engine.inputs`);
* :meth:`Engine.tick` hands each pipeline the samples queued since the previous tick, in
  time order, and collects its estimates as :class:`~onboard.core.messages.EstimateRecord`.
  With a GNSS latency correction the queue is a :class:`onboard.engine.latency.FixedLagQueue`:
  the pipelines fuse at ``tick - gnss_latency_s`` and the estimates are forecast to the
  tick.

:func:`run` drives an engine from any time-ordered iterable of samples on a fixed tick grid
``t0 + k / rate_hz``; the live service calls ``push``/``tick`` from its own monotonic
timer instead. Given the same samples and tick times, the output is identical.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from typing import Callable, Iterable, Mapping, Protocol, Sequence

from onboard.core.config import Config
from onboard.core.geo import LocalFrame
from onboard.core.vehicles import traits
from onboard.core.wire import LocationFix, location_fix
from onboard.core.messages import (
    ActuatorColumn,
    ActuatorOutputs,
    Depth,
    EstimateRecord,
    GnssFix,
    Heading,
    HealthRecord,
    Parameter,
    Pressure,
    PropellerRpm,
    RcChannels,
    Sample,
    VelocityOverGround,
)
from onboard.engine.corrections import SampleCorrector
from onboard.engine.declination import DeclinationCorrector
from onboard.engine.depth import DepthMode
from onboard.monitor.alerts import Alerts
from onboard.monitor.innovations import InnovationMonitor
from onboard.monitor.integrity import WATCHED, IntegrityMonitor
from onboard.engine.inputs import InputMapper
from onboard.engine.latency import FixedLagQueue
from onboard.pipelines import build
from onboard.pipelines.base import Pipeline, sample_time
from onboard.engine.sources import SourceSelector
from onboard.engine.timeline import Jump, Timeline, outlier_words
from onboard.engine.whereabouts import NOWHERE, Place, Whereabouts
from onboard.engine.checks import checker_for, sample_type

__all__ = ["Engine", "SampleCorrector", "TickQueue", "run"]

STALE_AFTER_S = 3.0
"""A sample stream (type, source) with no accepted sample for this long is reported
stale in the health events (e.g. GNSS lost while the same serial line still carries the
compass, or a DVL that only reports ``valid=False``), and again when it comes back."""
FUTURE_TOLERANCE_S = 1.0
"""Live, a sample stamped more than this after the receive clock is rejected as
``future``."""
RESTART_AFTER_S = 600.0
"""A clock jump forward longer than this (s), or any jump back, restarts the pipelines
with their adaptive state (:meth:`Engine.start_segment`): their state is not carried
across that much unseen time, and none of them walks across it. Shorter forward jumps
are gaps the pipelines bridge themselves (the aie/kf restart their chains past
``max_gap_s``; the current filter predicts across them)."""
_NEVER_STALE = {str(Parameter.__struct_config__.tag)}  # type: ignore[attr-defined]
"""The tags of streams sent once, not periodically (an autopilot's parameters, sent when
asked)."""

_DEPTH_OR_GNSS = {Pressure, Depth, GnssFix}
_RAW_ACTUATORS = {ActuatorOutputs, RcChannels, PropellerRpm, ActuatorColumn}

TickCallback = Callable[[float, Sequence[EstimateRecord]], None]


class SampleQueue(Protocol):
    """What :meth:`Engine.tick` needs of its queue (:class:`TickQueue` without a GNSS
    latency, :class:`onboard.engine.latency.FixedLagQueue` with one)."""

    pending: list[Sample]
    t_sensor: float | None

    def put(self, sample: Sample) -> None:
        """Queue one sample for the pipelines."""

    def open_tick(self, t: float, n_pipelines: int) -> None:
        """Take the samples of the tick at ``t`` (s)."""

    def step(self, i: int, pipeline: Pipeline) -> Mapping[str, float]:
        """Step the ``i``-th pipeline; return the estimates to publish."""
        ...

    def restarted(self, i: int) -> None:
        """The ``i``-th pipeline was replaced by a fresh one."""

    def close_tick(self) -> None:
        """End the tick."""

    def reset(self) -> None:
        """The pipelines' state was replaced."""


class TickQueue:
    """The samples queued since the previous tick, handed to every pipeline at the next
    tick in time order (stable: arrival order breaks ties).

    Attributes:
        pending: the samples waiting for the next tick, in arrival order.
        t_sensor: the newest sample time (s) of the last tick, None if it had none.
    """

    def __init__(self) -> None:
        """An empty queue."""
        self.pending: list[Sample] = []
        self.t_sensor: float | None = None
        self._t = 0.0
        self._batch: list[Sample] = []

    def put(self, sample: Sample) -> None:
        """Queue ``sample`` for the next tick."""
        self.pending.append(sample)

    def open_tick(self, t: float, n_pipelines: int) -> None:
        """Take every queued sample, sorted by time, for the tick at ``t`` (s)."""
        batch = self.pending
        if len(batch) > 1:
            batch.sort(key=sample_time)
        self.pending = []
        self._t = t
        self._batch = batch
        self.t_sensor = batch[-1].t if batch else None

    def step(self, i: int, pipeline: Pipeline) -> Mapping[str, float]:
        """Step ``pipeline`` to the tick with the tick's samples."""
        return pipeline.step(self._t, self._batch)

    def restarted(self, i: int) -> None:
        """Nothing to do: the queue holds no pipeline state."""

    def close_tick(self) -> None:
        """Let the tick's samples go."""
        self._batch = []

    def reset(self) -> None:
        """Nothing to do: the queue holds no pipeline state."""


def std_columns(pipeline: Pipeline) -> dict[str, str]:
    """``std_<q>`` -> ``<q>`` for the columns of ``pipeline`` (fixed at its construction)."""
    return {c: c[4:] for c in pipeline.columns if c.startswith("std_")}


class Engine:
    """Feeds validated samples into pipelines on ticks. Not thread-safe; one owner.

    Attributes:
        pipelines: the pipelines, in column order.
        queue: the samples waiting for the pipelines (:class:`TickQueue`, or a
            :class:`onboard.engine.latency.FixedLagQueue` with a GNSS latency correction).
        accepted: samples accepted, by ``(type, source)``.
        rejected: samples rejected, by ``<type>:<reason>``.
        depth_mode: pressure to depth and the surface/submerged mode.
        pipeline_errors: exceptions raised by each pipeline (it is then restarted).
        nonfinite: estimates left out of the records because they were not finite, per
            pipeline (a NaN or infinite value is an unknown quantity, published absent).
        latest: the newest record of each pipeline.
        monitor: the innovations of every pipeline's updates, per channel
            (:class:`onboard.monitor.innovations.InnovationMonitor`).
        declination: magnetic headings to true (:mod:`onboard.engine.declination`); its
            ``report`` is the declination in use.
    """

    def __init__(self, cfg: Config, pipelines: list[Pipeline] | None = None,
                 only: set[str] | None = None, select_sources: bool = True,
                 fresh_estimates: bool = True) -> None:
        """Run ``pipelines``, by default those :func:`onboard.pipelines.build` makes for
        ``cfg`` (restricted to the pipeline names in ``only`` when given).
        ``select_sources`` False passes every source of every quantity through (model
        closure looks at each sensor's own measurements, not at the one chosen).
        ``fresh_estimates`` False: with a GNSS latency correction, return the estimates
        at the fusion horizon ``tick - gnss_latency_s`` (no forecast, no copies of the
        pipelines; for collectors that record what was fused)."""
        self.cfg = cfg
        self.pipelines = build(cfg, only) if pipelines is None else pipelines
        corrector = SampleCorrector(cfg.corrections)
        self.correct: Callable[[Sample], Sample] | None = \
            corrector if corrector.active else None
        """``[corrections]`` applied to each validated sample (None: none configured)."""
        self.declination = DeclinationCorrector(cfg.corrections.declination_deg)
        self.queue: SampleQueue = (
            FixedLagQueue(corrector.latency_s, forecast=fresh_estimates)
            if corrector.latency_s > 0.0 else TickQueue())
        self.mapper = InputMapper(cfg.inputs)
        self.max_age = cfg.engine.max_sample_age_s
        self.accepted: Counter[tuple[str, str]] = Counter()
        self.rejected: Counter[str] = Counter()
        self.depth_mode = DepthMode(cfg.sensors.depth)
        self.latest: dict[str, EstimateRecord] = {}
        self.whereabouts = Whereabouts(
            dead_reckon=traits(cfg.vehicle.vehicle_class).underwater)
        """The UTC and position every record carries (:mod:`onboard.engine.whereabouts`;
        a replay or the service sets its ``utc_of``)."""
        self.t_first: float | None = None
        self.t_newest = -math.inf
        self._last_t: dict[tuple[str, str], float] = {}
        self._kinds: dict[type, tuple[str, Callable[[Sample], str | None]]] = {}
        """Per sample class: its tag and its value checker (onboard.engine.checks)."""
        self._std_names = {p.name: std_columns(p) for p in self.pipelines}
        """Per pipeline name: its ``std_<q>`` columns -> ``<q>`` (:func:`std_columns`)."""
        self.pipeline_errors: Counter[str] = Counter()
        self.nonfinite: Counter[str] = Counter()
        self.monitor = InnovationMonitor()
        self.events: list[str] = []
        """Human-readable events (pipeline restarts, stale streams) for the health
        channel; each is in one :meth:`health` record (the next after it happened)."""
        self.alerts = Alerts(self.events)
        """Warnings for the user (pipeline restarts, integrity; the replay adds its own);
        each new one is also an event."""
        holonomic = traits(cfg.vehicle.vehicle_class).holonomic
        self.integrity = IntegrityMonitor(self.alerts, holonomic,
                                          cfg.sensors.gnss.position_std_m,
                                          cfg.sensors.gnss.velocity_std_mps,
                                          cfg.sensors.dvl.velocity_std_mps,
                                          cfg.corrections.gnss_latency_s)
        """Each estimate against the independent measurements (:mod:`onboard.monitor.integrity`):
        warnings, flags, and the values it withholds; it reads the pipelines' roles."""
        self.integrity.watch(self.pipelines)
        self._events_reported = 0
        self.selector = SourceSelector(cfg.sources, self.events)
        self.select_sources = select_sources
        """One source per quantity (``[sources]``); its switches are events."""
        self.stale: set[tuple[str, str]] = set()
        """The sample streams now stale (see :data:`STALE_AFTER_S`)."""
        self.timeline = Timeline(cfg.engine.time_jump_s)
        """The segments of the run and its outliers (:meth:`admit`)."""

    def local_frame(self, name: str) -> tuple[LocalFrame, tuple[float, float]] | None:
        """The local frame of pipeline ``name``'s published north/east (about its first
        fix) and the published position (north, east; m) of the frame's origin, or None
        (no such pipeline, no position, no fix yet): what turns its estimates into
        latitude and longitude (:func:`onboard.core.wire.location_fix`)."""
        p = next((q for q in self.pipelines if q.name == name), None)
        if p is None or p.frame is None:
            return None
        offset = p.frame_offset
        return p.frame, (offset if offset is not None else (0.0, 0.0))

    def location_fixes(self, records: Sequence[EstimateRecord]) -> list[LocationFix]:
        """The positions among ``records`` as Foxglove LocationFixes (latitude and
        longitude from each pipeline's :meth:`local_frame`;
        :func:`onboard.core.wire.location_fix`)."""
        out: list[LocationFix] = []
        for rec in records:
            if "north" not in rec.values:
                continue
            frame = self.local_frame(rec.pipeline)
            if frame is not None:
                fix = location_fix(rec, *frame)
                if fix is not None:
                    out.append(fix)
        return out

    @property
    def columns(self) -> list[str]:
        """``t`` then ``<pipeline>.<quantity>`` for every pipeline, in order."""
        return ["t"] + [f"{p.name}.{c}" for p in self.pipelines for c in p.columns]

    @property
    def mode(self) -> str:
        """``"surface"`` or ``"submerged"``, from the newest depth."""
        return self.depth_mode.mode

    @property
    def depth_m(self) -> float | None:
        """The newest depth (m), None before the first."""
        return self.depth_mode.depth_m

    # --------------------------------------------------------------------- time line

    def admit(self, sample: Sample, now: float | None = None) -> list[Sample]:
        """Put ``sample`` on the time line (:mod:`onboard.engine.timeline`); return the samples
        it releases, to :meth:`push` in order. Outliers are counted
        (``<type>:time_outlier``) and warned of; after a release that confirmed a jump,
        :attr:`timeline` ``.jump`` is set and the caller ticks what it has, then calls
        :meth:`start_segment` before pushing the released samples. Live, ``now`` is the
        receive time (s): the receive clock is the time line
        (:meth:`onboard.engine.timeline.Timeline.admit_at`) and no jump is ever confirmed."""
        timeline = self.timeline
        released = (timeline.admit(sample) if now is None
                    else timeline.admit_at(sample, now))
        if timeline.outliers:
            self._count_outliers(now)
        return released

    def finish(self) -> list[Sample]:
        """The run ended: samples still held on the time line are outliers; return the
        samples its end releases (the start of a log of few stamps), to :meth:`push`."""
        released = self.timeline.flush()
        self._count_outliers()
        return released

    def _count_outliers(self, now: float | None = None) -> None:
        """Count and warn of the time line's outliers, and clear its list; ``now``: the
        receive time (s) they are judged against live."""
        outliers = self.timeline.outliers
        if not outliers:
            return
        ref = self.timeline.newest if now is None else now
        for s in outliers:
            kind, _ = self._checker(s)
            self._reject(kind, "time_outlier")
        n = self.time_outliers()
        if now is None:
            message = outlier_words(n, outliers[-1].t, ref)
        else:
            message = (f"{n} sample(s) stamped far from their neighbours were dropped (the "
                       f"last {outliers[-1].t - now:+.6g} s off the receive clock)")
        self.alerts.warn("time_outlier", f"{message}; counted in rejected <type>:time_outlier",
                         ref, details="a corrupted or mistyped time stamp, or a sender whose "
                         "clock is not the others'; the samples after them were kept")
        outliers.clear()

    def time_outliers(self) -> int:
        """Samples dropped so far as outliers of the time line (all types)."""
        return sum(v for k, v in self.rejected.items() if k.endswith(":time_outlier"))

    def start_segment(self, jump: Jump) -> None:
        """A confirmed clock jump (:class:`onboard.engine.timeline.Jump`): warn, and when it goes
        back or forward more than :data:`RESTART_AFTER_S`, forget the stream times,
        move the source selection's times with the clock, and restart the pipelines
        from their own adaptive state (:meth:`get_state`)."""
        step = jump.step_s
        what = jump.words()
        restart = not 0.0 <= step <= RESTART_AFTER_S
        self.alerts.warn("time_jump", f"{what}: a new time segment and a new run in "
                         "estimates.csv start here (summary.json time_span.segments)",
                         jump.t_after, details="durations count each segment, not the "
                         "time between them; " + ("the pipelines restart from their "
                         "adaptive state" if restart else "the pipelines carry on"))
        self.events.append(f"time: {what}; new segment")
        if not restart:
            return
        self._last_t.clear()
        self.t_newest = -math.inf
        self.stale.clear()
        self.selector.shift(step)
        state = self.get_state()
        self.pipelines = [next(iter(build(self.cfg, {p.name})), p) for p in self.pipelines]
        self._std_names = {p.name: std_columns(p) for p in self.pipelines}
        self.integrity.watch(self.pipelines)
        self.set_state(state)

    # ------------------------------------------------------------------------- push

    def push(self, sample: Sample, now: float | None = None) -> bool:
        """Check, correct and queue one sample; return False (and count why) if rejected.

        ``now`` is the receive clock in live operation, used to reject stamps from the
        future; replay passes None.
        """
        cls = type(sample)
        kind, check = self._kinds.get(cls) or self._checker(sample)
        reason = check(sample)
        if reason is None and now is not None and sample.t > now + FUTURE_TOLERANCE_S:
            reason = "future"
        if reason is None:
            if cls is Heading:
                sample, reason = self._true_heading(sample)  # type: ignore[arg-type]
            elif cls is GnssFix and self.declination.needs_fix:
                self._observe_fix(sample)  # type: ignore[arg-type]
        if reason is None:
            if self.correct is not None:
                sample = self.correct(sample)
            key = (kind, sample.source)   # the sample's stream
            reason = self._out_of_order(key, sample.t)
        if reason is None and type(sample) in _DEPTH_OR_GNSS:
            sample, reason = self._depth_and_mode(sample)
            key = (kind, sample.source)
        if reason is not None:
            return self._reject(kind, reason)
        self._accept(key, sample.t)
        chosen = self.selector.admit(sample) if self.select_sources else sample
        if chosen is not None:  # None: another source of its quantity is active
            self._enqueue(chosen, sample)
        return True

    def _true_heading(self, s: Heading) -> tuple[Heading, str | None]:
        """``s`` relative to true north (:mod:`onboard.engine.declination`), or the rejection
        reason ``no_declination`` while a magnetic heading waits for the first fix; a
        magnetic heading used as it is raises the ``no_declination`` warning."""
        s, outcome = self.declination.heading(s)
        if outcome == "wait":
            return s, "no_declination"
        if outcome == "uncorrected":
            message, details = self.declination.warning
            self.alerts.warn("no_declination", message, s.t, details=details)
        return s, None

    def _observe_fix(self, fix: GnssFix) -> None:
        """Show the first fix to the declination (the World Magnetic Model's position
        and date); warn when its value is unreliable there, and tell the truth of the
        magnetic headings used as true before it."""
        warning = self.declination.observe_fix(fix)
        if warning:
            self.alerts.warn("declination_unreliable", warning[0], fix.t, details=warning[1])
        if self.declination.uncorrected:
            message, details = self.declination.warning
            self.alerts.revise("no_declination", message, details=details)

    def _checker(self, sample: Sample) -> tuple[str, Callable[[Sample], str | None]]:
        """The tag and the value checker of the sample's class (:mod:`onboard.engine.checks`)."""
        cls = type(sample)
        k = self._kinds.get(cls)
        if k is None:
            k = self._kinds[cls] = (sample_type(sample), checker_for(cls))
        return k

    def _reject(self, kind: str, reason: str) -> bool:
        self.rejected[f"{kind}:{reason}"] += 1
        return False

    def _out_of_order(self, stream: tuple[str, str], t: float) -> str | None:
        """``backwards`` if ``t`` (s) is older than the newest accepted of its ``stream``
        (type, source), ``late`` if older than ``max_sample_age_s`` behind the newest
        accepted sample; else None."""
        last = self._last_t.get(stream)
        if last is not None and t < last:
            return "backwards"
        if t < self.t_newest - self.max_age:
            return "late"
        return None

    def _depth_and_mode(self, sample: Sample) -> tuple[Sample, str | None]:
        """A pressure as its depth; a depth sets the mode; a GNSS fix while submerged is
        rejected (``submerged``)."""
        if type(sample) is Pressure:
            sample = self.depth_mode.depth(sample)  # type: ignore[arg-type]
        if type(sample) is Depth:
            self.depth_mode.observe(sample)  # type: ignore[arg-type]
            return sample, None
        return sample, "submerged" if self.depth_mode.submerged else None

    def _accept(self, stream: tuple[str, str], t: float) -> None:
        """Count a sample of ``stream`` (type, source) at ``t`` (s) accepted and note its
        time."""
        self._last_t[stream] = t
        if t > self.t_newest:
            self.t_newest = t
        if self.t_first is None:
            self.t_first = t
        self.accepted[stream] += 1

    def _enqueue(self, chosen: Sample, raw: Sample) -> None:
        """Queue ``chosen`` (``raw`` as the source selector passed it), and with a raw
        actuator output its normalized command; a parameter may move an input channel
        (an event)."""
        self.queue.put(chosen)
        if type(chosen) in WATCHED:
            self.integrity.observe(chosen)
            if type(chosen) is GnssFix:
                self.whereabouts.observe(chosen)  # type: ignore[arg-type]
            elif type(chosen) is VelocityOverGround:
                self.whereabouts.observe_velocity(chosen)  # type: ignore[arg-type]
        cls = type(raw)
        if cls in _RAW_ACTUATORS and self.mapper.active:
            cmd = self.mapper.map(raw)
            if cmd is not None:
                self.queue.put(cmd)
                self.integrity.observe(cmd)
        elif cls is Parameter:
            for change in self.mapper.parameter(raw.name, raw.value):  # type: ignore[attr-defined]
                self.events.append(f"inputs: {change}")

    # ------------------------------------------------------------------------- tick

    def tick(self, t: float) -> list[EstimateRecord]:
        """Step every pipeline to time ``t`` (s) with the samples queued so far (with a
        GNSS latency, see :class:`onboard.engine.latency.FixedLagQueue`); return the records of
        the pipelines that have estimates. A pipeline that raises is restarted and the
        others carry on."""
        queue = self.queue
        queue.open_tick(t, len(self.pipelines))
        stepped = []
        computed = []   # (name, values) as stepped, before any is withheld
        monitor, integrity = self.monitor, self.integrity
        for i, p in enumerate(self.pipelines):
            values: Mapping[str, float] | None
            try:
                values = queue.step(i, p)
            except Exception as err:  # a pipeline bug must not stop the others
                self._recover(i, p, err, t)
                values = None
                queue.restarted(i)
            self._take_events(p)
            innovations = p.innovations()
            if innovations:  # most ticks make no measurement update
                monitor.add(p.name, innovations)
                integrity.innovations(p.name, innovations)
            if values:
                stepped.append((p, self._published(p, t, values), queue.t_sensor))
                computed.append((p.name, values))
        queue.close_tick()
        integrity.counters_at(t)
        records = self._records(t, stepped)
        # judged as computed: a position or speed withheld from the records still is
        integrity.positions_at(t, computed)
        integrity.speeds_at(t, computed)
        return records

    def _take_events(self, p: Pipeline) -> None:
        """Move a pipeline's own events (e.g. restored state discarded) into the health
        events, prefixed with its name."""
        pev = p.take_events()
        if pev:
            self.events.extend(f"{p.name}: {e}" for e in pev)

    def _published(self, p: Pipeline, t: float, values: Mapping[str, float]
                   ) -> Mapping[str, float]:
        """``p``'s values at ``t`` as published: non-finite ones and those the integrity
        monitor withholds left out, those it amends (a widened sigma) amended."""
        if not math.isfinite(sum(values.values())):  # NaN and infinities propagate
            values = self._finite(p.name, values)
        integrity = self.integrity
        if integrity.amends:
            values = dict(values)
            integrity.amend(p.name, t, values)  # type: ignore[arg-type]
        withheld = integrity.withheld(p.name)
        if withheld:
            values = self._withhold(p.name, values, withheld)
        return values

    def _records(self, t: float, stepped: Sequence[tuple[Pipeline, Mapping[str, float],
                                                          float | None]]
                 ) -> list[EstimateRecord]:
        """The records of the pipelines ``stepped`` at ``t`` (each with its published
        values and its newest sample's time), all with the tick's UTC and the vehicle's
        position (:mod:`onboard.engine.whereabouts`)."""
        if not stepped:
            return []
        where = self.whereabouts
        place = where.place(t, ((v, self.local_frame(p.name)) for p, v, _ in stepped
                                if "north" in v))
        utc = where.utc(t)
        return [self._record(p, t, v, ts, utc, place) for p, v, ts in stepped]

    def _record(self, p: Pipeline, t: float, values: Mapping[str, float],
                t_sensor: float | None, utc: float | None = None,
                place: Place = NOWHERE) -> EstimateRecord:
        """The record of ``p``'s published estimates at ``t`` (UTC ``utc``, the vehicle
        at ``place``), also kept as :attr:`latest`."""
        std_names = self._std_names.get(p.name)
        if std_names is None:  # a pipeline put in after construction
            std_names = self._std_names[p.name] = std_columns(p)
        # the std_ entries in the order of values
        std = {std_names[k]: v for k, v in values.items() if k in std_names} \
            if std_names else {}
        rec = EstimateRecord(vehicle=self.cfg.vehicle.id, pipeline=p.name, t=t,
                             values=dict(values), std=std, t_sensor=t_sensor,
                             sources=self.selector.active, utc=utc, lat_deg=place.lat_deg,
                             lon_deg=place.lon_deg, position_std_m=place.std_m)
        self.latest[p.name] = rec
        return rec

    def _finite(self, name: str, values: Mapping[str, float]) -> dict[str, float]:
        """``values`` without its non-finite entries, each counted in :attr:`nonfinite`.
        A record must not carry NaN or infinity: JSON has neither (msgspec writes
        ``null``, which a subscriber decoding ``EstimateRecord`` rejects whole, losing
        the finite estimates beside it), and architecture.md §5 publishes an unknown
        quantity as absent."""
        out = {}
        for k, v in values.items():
            if math.isfinite(v):
                out[k] = v
            else:
                self.nonfinite[name] += 1
        return out

    def _withhold(self, name: str, values: Mapping[str, float],
                  withheld: tuple[str, ...]) -> dict[str, float]:
        """``values`` without the quantities the integrity monitor withholds (published
        as unknown while a check fails, :mod:`onboard.monitor.integrity`), each counted."""
        out = {k: v for k, v in values.items() if k not in withheld}
        self.integrity.count_withheld(name, len(values) - len(out))
        return out

    def _recover(self, i: int, p: Pipeline, err: Exception, t: float) -> None:
        """Count a pipeline's failure, report it, and restart it from its configuration
        (its adaptive state is lost; the other pipelines carry on)."""
        self.pipeline_errors[p.name] += 1
        self.alerts.warn("pipeline_restarted",
                         f"{p.name} failed ({type(err).__name__}: {err}) and was restarted "
                         f"from its configuration; [pipelines.{p.name}] enabled = false "
                         "leaves it out", t, pipeline=p.name,
                         details="what it had learned is lost at each restart (counted "
                         f"in rejected pipeline:{p.name}:error); a failing pipeline is a "
                         "bug: please report it with the log")
        fresh = build(self.cfg, only={p.name})
        if fresh:
            self.pipelines[i] = fresh[0]
            self._std_names[fresh[0].name] = std_columns(fresh[0])
            self.integrity.watch(self.pipelines)
        return None

    def health(self, t: float, rates_hz: dict[str, float] | None = None,
               events: list[str] | None = None) -> HealthRecord:
        """The innovations of every pipeline per channel, their counters, the rejection
        counts, and the events since the previous call (``events`` first), stale streams
        among them."""
        self._check_stale(t)
        return HealthRecord(vehicle=self.cfg.vehicle.id, t=t, rates_hz=rates_hz or {},
                            rejected=self.rejections(), withheld=self.withheld(),
                            innovations=self.monitor.snapshot(),
                            counters=self.counters(),
                            events=(events or []) + self._new_events(), mode=self.mode,
                            sources=self.selector.active, flags=self.integrity.active(),
                            declination=self.declination.report)

    def rejections(self) -> dict[str, int]:
        """What was refused on the way in: samples by ``<type>:<reason>``, and per
        pipeline its failures (``pipeline:<name>:error``, each a restart). The estimates
        left out on the way out are apart: :meth:`withheld`."""
        rejected = dict(self.rejected)
        rejected.update({f"pipeline:{k}:error": n for k, n in self.pipeline_errors.items()})
        return rejected

    def withheld(self) -> dict[str, int]:
        """The estimate values left out of the records: as not finite
        (``pipeline:<name>:nonfinite``), or withheld by a failed integrity check
        (``pipeline:<name>:flagged``; the rows: ``integrity.withheld_rows``)."""
        out = {f"pipeline:{k}:nonfinite": n for k, n in self.nonfinite.items()}
        out.update({f"pipeline:{k}:flagged": n for k, n in self.integrity.flagged.items()})
        return out

    def counters(self) -> dict[str, dict[str, float | None]]:
        """Every pipeline's :meth:`~onboard.pipelines.base.Pipeline.health` in its flat
        form (a value that is not finite as None: JSON has no NaN)."""
        return {p.name: {k: (float(v) if math.isfinite(v) else None)
                         for k, v in p.health().flat().items()} for p in self.pipelines}

    def _new_events(self) -> list[str]:
        new = self.events[self._events_reported:][-10:]
        if len(self.events) > 100:
            del self.events[:-50]
        self._events_reported = len(self.events)
        return new

    def _check_stale(self, t: float) -> None:
        for key, last in self._last_t.items():
            if key[0] in _NEVER_STALE:
                continue
            quiet = t - last
            if quiet > STALE_AFTER_S:
                if key not in self.stale:
                    self.stale.add(key)
                    self.events.append(f"{key[0]}:{key[1]}: stale, no sample accepted "
                                       f"for {quiet:.0f} s")
            elif key in self.stale:
                self.stale.discard(key)
                self.events.append(f"{key[0]}:{key[1]}: samples again")

    def get_state(self) -> dict:
        """Adaptive state of every pipeline, for persistence across restarts."""
        return {p.name: p.get_state() for p in self.pipelines}

    def set_state(self, state: dict) -> list[str]:
        """Restore what :meth:`get_state` returned, pipeline by pipeline (a pipeline
        missing from ``state`` keeps its fresh state). A saved state is input: a pipeline
        that cannot take its entry (a malformed or foreign one) is left as its
        ``set_state`` left it, and named in the returned lines (``"current
        (AttributeError: ...)"``); none when every entry was taken."""
        self.queue.reset()
        failed = []
        for p in self.pipelines:
            if isinstance(state.get(p.name), dict):
                try:
                    p.set_state(state[p.name])
                except Exception as err:  # noqa: BLE001 - whatever a bad file makes it raise
                    failed.append(f"{p.name} ({type(err).__name__}: {str(err)[:60]})")
        return failed



def run(engine: Engine, samples: Iterable[Sample], on_tick: TickCallback,
        *, gap_s: float = 10.0, tick_times: Iterable[float] | None = None) -> int:
    """Replay ``samples`` (time-ordered) through ``engine``; return the number of ticks.

    Every sample goes through the time line first (:meth:`Engine.admit`): the log starts
    where its first stamps agree, outliers are dropped, and a clock jump back or beyond :data:`RESTART_AFTER_S` gets a last tick of
    the old segment, then :meth:`Engine.start_segment` and a new grid from the new
    segment's first stamp. Ticks fall on the grid ``t0 + k / rate_hz`` from the (segment's)
    first sample's time ``t0``; each tick at time ``T`` sees exactly the samples with
    ``t <= T``. Across a gap in the log longer than ``gap_s`` seconds the grid jumps
    forward to the first sample after it instead of ticking through empty time. With
    ``tick_times`` (a recording of live ticks) those times are used instead of the grid
    and the time line, which reproduces a live run exactly.
    """
    period = 1.0 / engine.cfg.engine.rate_hz
    ticks = 0
    if tick_times is not None:
        it = iter(tick_times)
        next_t = next(it, math.inf)
        for s in samples:
            while s.t > next_t:
                on_tick(next_t, engine.tick(next_t))
                ticks += 1
                next_t = next(it, math.inf)
            engine.push(s)
        for t in ([next_t] if next_t < math.inf else []) + list(it):
            on_tick(t, engine.tick(t))
            ticks += 1
        return ticks
    t0 = None
    k = 0
    next_t = math.inf
    for s_in in itertools.chain(samples, (None,)):   # None: the end, which may release
        released = engine.admit(s_in) if s_in is not None else engine.finish()
        if not released:
            continue
        jump = engine.timeline.jump
        if jump is not None and t0 is not None and not 0.0 <= jump.step_s <= RESTART_AFTER_S:
            # a new segment: tick what the old one has, then a new grid from its first stamp
            on_tick(next_t, engine.tick(next_t))
            ticks += 1
            t0 = None
        if jump is not None:
            engine.start_segment(jump)
        for s in released:
            if t0 is None:
                t0 = s.t
                next_t = t0
                k = 0
            if s.t > next_t:
                if s.t - next_t > gap_s:
                    # the last tick before the gap, then the grid's first time at or
                    # after the sample: no tick falls in the gap
                    on_tick(next_t, engine.tick(next_t))
                    ticks += 1
                    k = math.ceil((s.t - t0) / period)
                    next_t = t0 + k * period
                while s.t > next_t:
                    on_tick(next_t, engine.tick(next_t))
                    ticks += 1
                    k += 1
                    next_t = t0 + k * period
            engine.push(s)
    if t0 is not None:
        on_tick(next_t, engine.tick(next_t))
        ticks += 1
    return ticks
