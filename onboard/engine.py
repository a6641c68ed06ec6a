"""The engine: time-ordered samples in, fixed-rate pipeline ticks out.

One engine serves live operation and replay (architecture.md §3):

* :meth:`Engine.push` checks a sample (:mod:`onboard.validate`), counts a rejection with
  its reason, takes the configured sensor errors out of it (``[corrections]``,
  :class:`SampleCorrector`), converts pressure to depth, tracks surface/submerged mode (GNSS is accepted
  only at the surface), maps raw actuator outputs to a normalized command
  (:mod:`onboard.inputs`), lets through only the active source of each quantity
  (:mod:`onboard.sources`) and queues the sample for the next tick;
* :meth:`Engine.tick` hands each pipeline the samples queued since the previous tick, in
  time order, and collects its estimates as :class:`~onboard.core.messages.EstimateRecord`.
  With a GNSS latency correction the samples of the last ``gnss_latency_s`` seconds are
  held back to the next tick: a fix re-stamped earlier still comes in time order.

:func:`run` drives an engine from any time-ordered iterable of samples on a fixed tick grid
``t0 + k / rate_hz``; the live service calls ``push``/``tick`` from its own monotonic
timer instead. Given the same samples and tick times, the output is identical.
"""

from __future__ import annotations

import bisect
import copy
import math
from collections import Counter
from operator import attrgetter
from typing import Callable, Iterable, Mapping, Sequence

import msgspec

from onboard.core.config import Config, Corrections
from onboard.core.geo import wrap_2pi, wrap_pi
from onboard.core.messages import (
    ActuatorColumn,
    ActuatorOutputs,
    Attitude,
    Depth,
    EstimateRecord,
    GnssFix,
    Heading,
    HealthRecord,
    Imu,
    Parameter,
    Pressure,
    PropellerRpm,
    RcChannels,
    Sample,
)
from onboard.inputs import InputMapper
from onboard.pipelines import build
from onboard.pipelines.base import Pipeline
from onboard.sources import SourceSelector, pattern_matches
from onboard.validate import checker_for, sample_type

GRAVITY = 9.80665
"""Standard gravity, m/s^2 (used for pressure -> depth)."""
STALE_AFTER_S = 3.0
"""A sample stream (type, source) with no accepted sample for this long is reported
stale in the health events (e.g. GNSS lost while the same serial line still carries the
compass, or a DVL that only reports ``valid=False``), and again when it comes back."""
_NEVER_STALE = {"parameter"}
"""Streams sent once, not periodically."""

_SPECIAL = {Pressure, Depth, GnssFix}
_RAW_ACTUATORS = {ActuatorOutputs, RcChannels, PropellerRpm, ActuatorColumn}

TickCallback = Callable[[float, Sequence[EstimateRecord]], None]


class SampleCorrector:
    """The ``[corrections]`` of a configuration applied to one validated sample.

    * ``GnssFix``: time stamp minus ``gnss_latency_s`` (the instant it measured);
    * ``Heading`` and ``Attitude`` yaw (of the ``heading_sources``, default all): the
      heading error ``e(psi) = offset + sum_k (s_k sin k psi + c_k cos k psi)`` (or the
      deviation card interpolated) is a function of the true heading ``psi``; the
      measured ``m = psi + e(psi)`` is inverted by fixed-point iteration
      ``psi <- m - e(psi)`` from ``psi = m`` (three rounds: the error of a deviation
      ``A`` shrinks as ``A^4``, below 1e-5 rad for ``A`` = 0.1 rad);
    * ``Imu`` gyro rates and ``Attitude`` body rates: minus ``gyro_bias_rps``.

    Other samples pass unchanged.
    """

    ITERATIONS = 3

    def __init__(self, c: Corrections) -> None:
        """Precompute what ``c`` asks for (:attr:`active` False when nothing)."""
        self.latency_s = float(c.gnss_latency_s)
        self.gyro = tuple(float(x) for x in c.gyro_bias_rps)
        self.offset = float(c.heading_offset_rad)
        self.sin = tuple(float(x) for x in c.heading_harmonics_sin)
        self.cos = tuple(float(x) for x in c.heading_harmonics_cos)
        table = sorted((math.radians(h) % (2 * math.pi), math.radians(e))
                       for h, e in c.heading_deviation_table)
        if table:  # periodic: repeat the first point one turn on
            table.append((table[0][0] + 2 * math.pi, table[0][1]))
        self.table = table
        self.sources = list(c.heading_sources)
        self.has_gyro = any(g != 0.0 for g in self.gyro)
        self.has_heading = bool(self.offset != 0.0 or any(self.sin) or any(self.cos)
                                or self.table)
        self.active = self.latency_s > 0.0 or self.has_gyro or self.has_heading
        self._for_source: dict[str, bool] = {}

    def heading_error(self, psi: float) -> float:
        """The heading error (rad) at true heading ``psi`` (rad)."""
        e = self.offset
        for k, a in enumerate(self.sin, 1):
            e += a * math.sin(k * psi)
        for k, b in enumerate(self.cos, 1):
            e += b * math.cos(k * psi)
        if self.table:
            x = psi % (2 * math.pi)
            xs = [h for h, _ in self.table]
            i = bisect.bisect_right(xs, x)
            if i == 0:  # before the first point: between the last and the first
                (h0, e0), (h1, e1) = self.table[-2], self.table[-1]
                x += 2 * math.pi
            elif i >= len(self.table):
                (h0, e0), (h1, e1) = self.table[-2], self.table[-1]
            else:
                (h0, e0), (h1, e1) = self.table[i - 1], self.table[i]
            e += e0 + (e1 - e0) * (x - h0) / (h1 - h0) if h1 > h0 else e0
        return e

    def true_heading(self, measured: float) -> float:
        """The true heading (rad, unwrapped) whose reading is ``measured`` (rad)."""
        psi = measured
        for _ in range(self.ITERATIONS):
            psi = measured - self.heading_error(psi)
        return psi

    def _heading_source(self, source: str) -> bool:
        ok = self._for_source.get(source)
        if ok is None:
            ok = self._for_source[source] = not self.sources or any(
                pattern_matches(p, source) for p in self.sources)
        return ok

    def __call__(self, sample: Sample) -> Sample:
        """``sample`` with the corrections applied (a new sample, or itself)."""
        cls = type(sample)
        if cls is GnssFix:
            if self.latency_s > 0.0:
                return msgspec.structs.replace(sample, t=sample.t - self.latency_s)
        elif cls is Heading:
            if self.has_heading and self._heading_source(sample.source):
                return msgspec.structs.replace(
                    sample, heading_rad=wrap_2pi(self.true_heading(sample.heading_rad)))
        elif cls is Imu:
            if self.has_gyro:
                gx, gy, gz = self.gyro
                return msgspec.structs.replace(sample, gyro_x=sample.gyro_x - gx,
                                               gyro_y=sample.gyro_y - gy,
                                               gyro_z=sample.gyro_z - gz)
        elif cls is Attitude:
            changes: dict[str, float] = {}
            if self.has_heading and self._heading_source(sample.source):
                changes["yaw_rad"] = wrap_pi(self.true_heading(sample.yaw_rad))
            if self.has_gyro:
                for name, g in zip(("roll_rate_rps", "pitch_rate_rps", "yaw_rate_rps"),
                                   self.gyro):
                    v = getattr(sample, name)
                    if v is not None and g != 0.0:
                        changes[name] = v - g
            if changes:
                return msgspec.structs.replace(sample, **changes)
        return sample


class Engine:
    """Feeds validated samples into pipelines on ticks. Not thread-safe; one owner.

    Attributes:
        pipelines: the pipelines, in column order.
        accepted: samples accepted, by ``(type, source)``.
        rejected: samples rejected, by ``<type>:<reason>``.
        mode: ``"surface"`` or ``"submerged"`` (from the newest depth).
        pipeline_errors: exceptions raised by each pipeline (it is then restarted).
        nonfinite: estimates left out of the records because they were not finite, per
            pipeline (a NaN or infinite value is an unknown quantity, published absent).
        latest: the newest record of each pipeline.
    """

    def __init__(self, cfg: Config, pipelines: list[Pipeline] | None = None,
                 only: set[str] | None = None, select_sources: bool = True,
                 fresh_estimates: bool = True) -> None:
        """Run ``pipelines``, by default those :func:`onboard.pipelines.build` makes for
        ``cfg`` (restricted to the pipeline names in ``only`` when given).
        ``select_sources`` False passes every source of every quantity through (model
        closure looks at each sensor's own measurements, not at the one chosen).
        ``fresh_estimates`` False: with a GNSS latency correction, return the estimates
        at the fusion horizon ``tick - gnss_latency_s`` (no shadow copies, see
        :meth:`tick`; for collectors that record what was fused)."""
        self.cfg = cfg
        self.pipelines = build(cfg, only) if pipelines is None else pipelines
        corrector = SampleCorrector(cfg.corrections)
        self.correct: Callable[[Sample], Sample] | None = \
            corrector if corrector.active else None
        """``[corrections]`` applied to each validated sample (None: none configured)."""
        self.hold_s = corrector.latency_s
        """Samples newer than ``tick - hold_s`` wait for a later tick (GNSS latency)."""
        self.mapper = InputMapper(cfg.inputs)
        self.max_age = cfg.engine.max_sample_age_s
        self.accepted: Counter[tuple[str, str]] = Counter()
        self.rejected: Counter[str] = Counter()
        self.mode = "surface"
        self.depth_m: float | None = None
        self.latest: dict[str, EstimateRecord] = {}
        self.t_first: float | None = None
        self.t_newest = -math.inf
        self._last_t: dict[tuple[str, str], float] = {}
        self._kinds: dict[type, tuple[str, Callable[[Sample], str | None]]] = {}
        """Per sample class: its tag and its value checker (onboard.validate)."""
        self._std_names: dict[int, tuple[Pipeline, dict[str, str]]] = {}
        """Per pipeline (by id, with the pipeline itself so that the id stays its own):
        ``std_<q>`` column -> ``<q>``, from its columns."""
        self._pending: list[Sample] = []
        self._fresh: list[Sample] = []
        """With a GNSS latency: the samples queued since the previous tick."""
        self._shadows: list[Pipeline] | None = None
        """With a GNSS latency: per pipeline, a copy fed every sample up to
        ``_shadow_t`` in time order, whose estimates are published (see :meth:`tick`)."""
        self._shadow_t = -math.inf
        self.fresh_estimates = fresh_estimates
        self._ticks = 0
        self.pipeline_errors: Counter[str] = Counter()
        self.nonfinite: Counter[str] = Counter()
        self.events: list[str] = []
        """Human-readable events (pipeline restarts, stale streams) for the health
        channel; each is in one :meth:`health` record (the next after it happened)."""
        self._events_reported = 0
        self.selector = SourceSelector(cfg.sources, self.events)
        self.select_sources = select_sources
        """One source per quantity (``[sources]``); its switches are events."""
        self.stale: set[tuple[str, str]] = set()
        """The sample streams now stale (see :data:`STALE_AFTER_S`)."""
        depth_cfg = cfg.sensors.depth
        self._rho_g = depth_cfg.water_density_kgm3 * GRAVITY
        self._p_surface = depth_cfg.surface_pressure_pa
        self._surface_depth = depth_cfg.surface_depth_m

    @property
    def columns(self) -> list[str]:
        """``t`` then ``<pipeline>.<quantity>`` for every pipeline, in order."""
        return ["t"] + [f"{p.name}.{c}" for p in self.pipelines for c in p.columns]

    def _reject(self, kind: str, reason: str) -> bool:
        self.rejected[f"{kind}:{reason}"] += 1
        return False

    def push(self, sample: Sample, now: float | None = None) -> bool:
        """Check and queue one sample; return False (and count why) if rejected.

        ``now`` is the receive clock in live operation, used to reject stamps from the
        future; replay passes None.
        """
        cls = type(sample)
        k = self._kinds.get(cls)
        if k is None:
            k = self._kinds[cls] = (sample_type(sample), checker_for(cls))
        kind, check = k
        reason = check(sample)
        if reason is not None:
            return self._reject(kind, reason)
        if now is not None and sample.t > now + 1.0:
            return self._reject(kind, "future")
        if self.correct is not None:
            sample = self.correct(sample)
        t = sample.t
        key = (kind, sample.source)
        last = self._last_t.get(key)
        if last is not None and t < last:
            return self._reject(kind, "backwards")
        if t < self.t_newest - self.max_age:
            return self._reject(kind, "late")
        if cls in _SPECIAL:
            if cls is Pressure:
                sample = Depth(t=t, source=sample.source,
                               depth_m=(sample.pressure_pa - self._p_surface) / self._rho_g,
                               pressure_pa=sample.pressure_pa, temperature_c=sample.temperature_c)
                cls = Depth
            if cls is Depth:
                self.depth_m = sample.depth_m
                self.mode = "submerged" if sample.depth_m > self._surface_depth else "surface"
            elif cls is GnssFix and self.mode == "submerged":
                return self._reject(kind, "submerged")
        self._last_t[key] = t
        if t > self.t_newest:
            self.t_newest = t
        if self.t_first is None:
            self.t_first = t
        self.accepted[key] += 1
        chosen = self.selector.admit(sample) if self.select_sources else sample
        if chosen is None:  # another source of its quantity is active
            return True
        self._pending.append(chosen)
        if self.hold_s > 0.0 and self.fresh_estimates:
            self._fresh.append(chosen)
        if cls in _RAW_ACTUATORS and self.mapper.active:
            cmd = self.mapper.map(sample)
            if cmd is not None:
                self._pending.append(cmd)
                if self.hold_s > 0.0 and self.fresh_estimates:
                    self._fresh.append(cmd)
        elif cls is Parameter:
            for change in self.mapper.parameter(sample.name, sample.value):
                self.events.append(f"inputs: {change}")
        return True

    def tick(self, t: float) -> list[EstimateRecord]:
        """Step every pipeline to time ``t`` (s) with the samples queued so far.

        With a GNSS latency correction (``hold_s`` > 0) the pipelines are stepped to the
        fusion horizon ``t - hold_s`` with the samples up to it, in time order; the newer
        ones wait for a later tick, so that a fix stamped ``hold_s`` earlier than it
        arrives still comes before them. The estimates at ``t`` come from a copy of each
        pipeline (a shadow) that has every sample up to the newest, in time order: the
        output is as fresh as without the correction and no state is fed out of order.
        A shadow takes the new samples as they come while they are in order; a sample
        older than its newest (a re-stamped fix) makes it a new copy of the pipeline,
        fed the waiting samples. The copies cost CPU (docs/diagnose.md, "Round trip")."""
        batch = self._pending
        if len(batch) > 1:
            batch.sort(key=_sample_time)  # stable: arrival order breaks ties
        held: list[Sample] | None = None
        fresh: list[Sample] = []
        refork = False
        t_step = t
        if self.hold_s > 0.0:
            t_step = t - self.hold_s
            cut = bisect.bisect_right(batch, t_step, key=_sample_time)
            held = batch[cut:]
            self._pending = list(held)
            batch = batch[:cut]
            if not self.fresh_estimates:
                held = None
        else:
            self._pending = []
        if held is not None:
            fresh = self._fresh
            self._fresh = []
            fresh.sort(key=_sample_time)
            refork = (self._shadows is None or len(self._shadows) != len(self.pipelines)
                      or (bool(fresh) and fresh[0].t < self._shadow_t))
            if refork:
                self._shadows = list(self.pipelines)
        t_sensor = batch[-1].t if batch else None
        vehicle = self.cfg.vehicle.id
        sources = self.selector.active  # replaced, never mutated, on a switch
        records = []
        refork_next = False
        for i, p in enumerate(self.pipelines):
            try:
                values = p.step(t_step, batch)
                if held is not None:
                    shadows = self._shadows
                    if refork:
                        shadows[i] = copy.deepcopy(p)  # type: ignore[index]
                    values = shadows[i].step(t, held if refork else fresh)  # type: ignore
            except Exception as err:  # a pipeline bug must not stop the others
                values = self._recover(i, p, err)
                refork_next = True
            pev = getattr(p, "events", None)
            if pev:  # a pipeline's own events (e.g. restored state discarded)
                self.events.extend(f"{p.name}: {e}" for e in pev)
                pev.clear()
            if not values:
                continue
            for v in values.values():
                if v - v != 0.0:  # NaN or +-inf: drop every such entry (rare path)
                    values = self._finite(p.name, values)
                    break
            entry = self._std_names.get(id(p))
            std_names = entry[1] if entry is not None else self._std_columns(p)
            # the std_ entries in the order of values ({} for a pipeline without std_
            # columns: values only holds its columns)
            std = {std_names[k]: v for k, v in values.items() if k in std_names} \
                if std_names else {}
            rec = EstimateRecord(vehicle=vehicle, pipeline=p.name, t=t,
                                 values=dict(values), std=std, t_sensor=t_sensor,
                                 sources=sources)
            self.latest[p.name] = rec
            records.append(rec)
        if held is not None:
            newest = held[-1].t if (refork and held) else fresh[-1].t if fresh else None
            if refork:
                self._shadow_t = t_step if newest is None else max(newest, t_step)
            elif newest is not None:
                self._shadow_t = max(self._shadow_t, newest)
            if refork_next:  # a restarted pipeline: its shadow is copied again
                self._shadows = None
        self._ticks += 1
        return records

    def _finite(self, name: str, values: Mapping[str, float]) -> dict[str, float]:
        """``values`` without its non-finite entries, each counted in :attr:`nonfinite`.
        A record must not carry NaN or infinity: JSON has neither (msgspec writes
        ``null``, which a subscriber decoding ``EstimateRecord`` rejects whole, losing
        the finite estimates beside it), and architecture.md §5 publishes an unknown
        quantity as absent."""
        out = {}
        for k, v in values.items():
            if v - v == 0.0:
                out[k] = v
            else:
                self.nonfinite[name] += 1
        return out

    def _std_columns(self, p: Pipeline) -> dict[str, str]:
        """``std_<q>`` -> ``<q>`` for the columns of ``p`` (fixed at its construction),
        cached for the pipelines in use (a restarted one gets a fresh entry)."""
        if len(self._std_names) > 4 * len(self.pipelines):
            self._std_names.clear()
        names = {c: c[4:] for c in p.columns if c.startswith("std_")}
        self._std_names[id(p)] = (p, names)
        return names

    def _recover(self, i: int, p: Pipeline, err: Exception) -> None:
        """Count a pipeline's failure, report it, and restart it from its configuration
        (its adaptive state is lost; the other pipelines carry on)."""
        self.pipeline_errors[p.name] += 1
        self.events.append(f"{p.name}: {type(err).__name__}: {err}; restarted")
        fresh = build(self.cfg, only={p.name})
        if fresh:
            self.pipelines[i] = fresh[0]
        return None

    def health(self, t: float, rates_hz: dict[str, float] | None = None,
               events: list[str] | None = None) -> HealthRecord:
        """Innovations and NIS of every pipeline plus rejection counts; the events since
        the previous call (``events`` first), stale streams among them."""
        self._check_stale(t)
        innovations: dict[str, float] = {}
        nis: dict[str, float] = {}
        for p in self.pipelines:
            for k, v in p.health().items():
                target = nis if k.endswith("nis") else innovations
                target[f"{p.name}.{k}"] = float(v)
        rejected = dict(self.rejected)
        rejected.update({f"pipeline:{k}:error": n for k, n in self.pipeline_errors.items()})
        rejected.update({f"pipeline:{k}:nonfinite": n for k, n in self.nonfinite.items()})
        return HealthRecord(vehicle=self.cfg.vehicle.id, t=t, rates_hz=rates_hz or {},
                            rejected=rejected, innovations=innovations, nis=nis,
                            events=(events or []) + self._new_events(), mode=self.mode,
                            sources=self.selector.active)

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

    def set_state(self, state: dict) -> None:
        """Restore what :meth:`get_state` returned, pipeline by pipeline (a pipeline
        missing from ``state`` keeps its fresh state)."""
        self._shadows = None
        for p in self.pipelines:
            if isinstance(state.get(p.name), dict):
                p.set_state(state[p.name])


_sample_time: Callable[[Sample], float] = attrgetter("t")
"""The sort key of a tick's batch: the sample time (s)."""


def run(engine: Engine, samples: Iterable[Sample], on_tick: TickCallback,
        *, gap_s: float = 10.0, tick_times: Iterable[float] | None = None) -> int:
    """Replay ``samples`` (time-ordered) through ``engine``; return the number of ticks.

    Ticks fall on the grid ``t0 + k / rate_hz`` from the first sample's time ``t0``; each
    tick at time ``T`` sees exactly the samples with ``t <= T``. Across a gap in the log
    longer than ``gap_s`` seconds the grid jumps forward instead of ticking through empty
    time. With ``tick_times`` (a recording of live ticks) those times are used instead of
    the grid, which reproduces a live run exactly.
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
    for s in samples:
        if t0 is None:
            t0 = s.t
            next_t = t0
        if s.t > next_t:
            if s.t - next_t > gap_s:
                on_tick(next_t, engine.tick(next_t))
                ticks += 1
                k = math.floor((s.t - t0) / period)
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
