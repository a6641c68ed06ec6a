"""GNSS latency: fusion at a delayed horizon, published estimates forecast to the tick.

A GNSS receiver reports a fix ``tau`` seconds (``[corrections] gnss_latency_s``) after
the instant it measured; the corrector (:mod:`onboard.engine.corrections`) stamps it back to that
instant. By then the compass, the IMU and the commands of the last ``tau`` seconds have
arrived, so a pipeline fed each sample as it comes would get the fix out of time order.
:class:`FixedLagQueue` keeps the order with two copies of each pipeline's state:

* **the fusion horizon.** At a tick at time ``t`` each pipeline (the *delayed* pipeline,
  the one the engine owns) is stepped to ``t - tau`` with the samples stamped at or
  before ``t - tau``, in time order; the newer samples wait for a later tick. A fix
  that arrives at most ``tau`` late is therefore always fused in order. The delayed
  pipeline is the filter of record: its state is what persists and what is restarted.
* **the forecast.** Estimates ``tau`` old are too old to steer by, so the estimates
  published at ``t`` come from a *fork* of each delayed pipeline that is also fed the
  waiting samples, in time order, and stepped to ``t``: as fresh as without the
  correction, and every measurement in them fused in time order. A fork takes the new
  samples of each tick as long as they are not older than the newest sample it has;
  a sample older than that (a re-stamped fix, typically each fix) makes a new fork, a
  copy of the delayed pipeline (just stepped to the horizon) fed the waiting samples.

The cost is the copies: one ``copy.deepcopy`` of every pipeline per re-stamped fix, the
fork's ``step`` on top of the delayed one each tick, and the samples of the last ``tau``
seconds stepped once more by each new fork (docs/diagnose.md "Round trip" gives the
measured CPU). The copy is needed because a fix re-stamped into the past must not be
fused out of order, and the pipeline contract (:class:`onboard.pipelines.base.Pipeline`:
``step`` and the adaptive ``get_state``/``set_state``) has no other way to branch a
pipeline's full state: no snapshot, no prediction without an update. A copy-free design
(the delayed filter plus an output predictor, as in PX4's EKF2) needs a pipeline method
that predicts its estimates to ``t`` from the delayed state without changing it; the
published estimates would then carry the inputs of the last ``tau`` seconds but none of
their measurement updates (docs/architecture.md §3).

Without ``forecast`` (model closure's collector, which records what was fused) only the
delayed pipelines are stepped and the estimates are those at the horizon.
"""

from __future__ import annotations

import copy
import math
from typing import TYPE_CHECKING, Mapping

from onboard.core.messages import Sample
from onboard.pipelines.base import sample_time, split_at

if TYPE_CHECKING:
    from onboard.pipelines.base import Pipeline


class FixedLagQueue:
    """The samples for the pipelines, fused at the horizon ``tick - lag_s`` and
    forecast to the tick (module docstring). One tick is :meth:`open_tick`, then
    :meth:`step` for each pipeline in order, then :meth:`close_tick`.

    Attributes:
        lag_s: the lag ``tau`` (s) of the fusion horizon behind the tick.
        forecast: publish the forks' estimates at the tick (True) or the delayed
            pipelines' at the horizon (False: no forks, no copies).
        pending: the samples not yet fused by the delayed pipelines, in arrival order
            until the next tick sorts them.
        copies: the forks made so far (one per pipeline per re-fork).
        t_sensor: the newest sample time (s) fused at the last tick, None if none.
    """

    def __init__(self, lag_s: float, forecast: bool = True) -> None:
        """A queue with the fusion horizon ``lag_s`` (s, > 0) behind the tick."""
        self.lag_s = lag_s
        self.forecast = forecast
        self.pending: list[Sample] = []
        self.copies = 0
        self.t_sensor: float | None = None
        self._new: list[Sample] = []
        """The samples queued since the previous tick (the forks' next input)."""
        self._forks: list[Pipeline | None] | None = None
        """Per pipeline its fork, fed every sample up to :attr:`_fork_t`; None: fork
        again at the next tick."""
        self._fork_t = -math.inf
        self._t = 0.0
        self._horizon = 0.0
        self._fused: list[Sample] = []
        self._held: list[Sample] = []
        self._fork_input: list[Sample] = []
        self._refork = False
        self._restarted = False

    def put(self, sample: Sample) -> None:
        """Queue ``sample`` (accepted, corrected, selected) for the pipelines."""
        self.pending.append(sample)
        if self.forecast:
            self._new.append(sample)

    def open_tick(self, t: float, n_pipelines: int) -> None:
        """Split the queue at the horizon ``t - lag_s``: the samples up to it are fused
        this tick, the newer ones wait; decide whether the forks are made again."""
        self._t = t
        self._horizon = t - self.lag_s
        self._fused, self._held = split_at(self.pending, self._horizon)
        self.pending = list(self._held)
        self.t_sensor = self._fused[-1].t if self._fused else None
        self._restarted = False
        if not self.forecast:
            return
        new = self._new
        self._new = []
        new.sort(key=sample_time)
        forks = self._forks
        self._refork = (forks is None or len(forks) != n_pipelines
                        or (bool(new) and new[0].t < self._fork_t))
        if self._refork:
            self._forks = [None] * n_pipelines
            self._fork_input = self._held  # everything newer than the horizon
        else:
            self._fork_input = new  # what the forks have not seen yet

    def step(self, i: int, pipeline: Pipeline) -> Mapping[str, float]:
        """Step the delayed ``pipeline`` (the ``i``-th) to the horizon and its fork to
        the tick; return the estimates to publish. Raises what the pipeline raises."""
        values = pipeline.step(self._horizon, self._fused)
        if not self.forecast:
            return values
        forks = self._forks
        assert forks is not None
        if self._refork:
            forks[i] = copy.deepcopy(pipeline)
            self.copies += 1
        fork = forks[i]
        assert fork is not None
        values = fork.step(self._t, self._fork_input)
        fork.innovations()  # the delayed pipeline's updates are the ones of record
        return values

    def restarted(self, i: int) -> None:
        """The ``i``-th pipeline was replaced: every fork is made again next tick."""
        self._restarted = True

    def close_tick(self) -> None:
        """Note how far the forks have been fed."""
        if not self.forecast:
            return
        held, new = self._held, self._fork_input
        if self._refork:
            newest = held[-1].t if held else None
            self._fork_t = self._horizon if newest is None else max(newest, self._horizon)
        elif new:
            self._fork_t = max(self._fork_t, new[-1].t)
        if self._restarted:
            self._forks = None
        self._fork_input = []

    def reset(self) -> None:
        """The delayed pipelines' state was replaced: fork them again at the next tick."""
        self._forks = None
