"""The GNSS latency: the pipelines fuse at the horizon ``tick - gnss_latency_s`` in time
order, and the published estimates are forecast to the tick (onboard.engine.latency); a
pipeline's own hold of late samples (onboard.pipelines.base.LateSampleHold).

The replay with a latency overlay is byte-compared with the reference in the harness
(case ``jaiabot-latency``) and in tests/test_diagnose_roundtrip.py.
"""

from __future__ import annotations

import math

import pytest

from onboard.core import config
from onboard.core.messages import GnssFix, Heading, Sample
from onboard.engine import Engine, TickQueue
from onboard.engine.latency import FixedLagQueue
from onboard.pipelines.base import LateSampleHold, NoHealth, PipelineDefaults


class _Recorder(PipelineDefaults):
    """A pipeline that records what it is fed and answers the newest sample time."""

    name = "rec"
    columns = ("newest",)

    def __init__(self) -> None:
        self.fed: list[tuple[float, list[Sample]]] = []
        self.newest = -math.inf

    def step(self, t, samples):
        self.fed.append((t, list(samples)))
        for s in samples:
            assert s.t <= t
            self.newest = max(self.newest, s.t)
        return {"newest": self.newest}

    def __deepcopy__(self, memo):
        twin = _Recorder()
        twin.newest = self.newest
        return twin

    def innovations(self):
        return []

    def health(self):
        return NoHealth()

    def get_state(self):
        return {}

    def set_state(self, state):
        pass


def _live_stream(latency: float, seconds: float = 20.0, gnss: bool = True):
    """(receive time, sample) as a service receives them: compass at 10 Hz on time, GNSS
    at 5 Hz measured ``latency`` s before it arrives and stamped on arrival."""
    out = []
    for k in range(int(seconds * 10)):
        t = 0.1 * k + 0.003
        out.append((t, Heading(t=t, source="compass", heading_rad=0.01 * k)))
        if gnss and k % 2 == 0:
            out.append((t + latency, GnssFix(t=t + latency, source="gnss", lat_deg=60.0,
                                             lon_deg=10.0)))
    out.sort(key=lambda x: x[0])
    return out


def _run_live(eng: Engine, stream, ticks: int = 200) -> list[float]:
    """Push ``stream`` with its receive clock and tick at 10 Hz; the published
    ``newest`` of each tick (-inf when the record leaves it out)."""
    out = []
    i = 0
    for k in range(1, ticks + 1):
        tick = 0.1 * k
        while i < len(stream) and stream[i][0] <= tick:
            eng.push(stream[i][1], now=stream[i][0])
            i += 1
        recs = eng.tick(tick)
        out.append(recs[0].values.get("newest", -math.inf) if recs else -math.inf)
    return out


def _latency_engine(rec, **kw) -> Engine:
    return Engine(config.from_dict({"corrections": {"gnss_latency_s": 0.6}}),
                  pipelines=[rec], **kw)


def test_a_latency_makes_the_queue_fixed_lag():
    eng = _latency_engine(_Recorder())
    assert isinstance(eng.queue, FixedLagQueue) and eng.queue.lag_s == 0.6
    assert isinstance(Engine(config.from_dict({}), pipelines=[]).queue, TickQueue)


def test_live_engine_fuses_restamped_fixes_in_time_order():
    """The engine fed like the service (push with the receive clock, ticks on a fixed
    grid): every sample reaches the pipeline once, in global time order, the fixes at
    the instant they measured; the estimate at each tick still has the newest compass."""
    rec = _Recorder()
    eng = _latency_engine(rec)
    outputs = _run_live(eng, _live_stream(0.6))
    fed = [s for _, batch in rec.fed for s in batch]
    times = [s.t for s in fed]
    assert times == sorted(times)
    fixes = [s for s in fed if isinstance(s, GnssFix)]
    assert len(fixes) >= 95
    # each fix at the instant it measured (the even compass instants), not its arrival
    for s in fixes:
        k = (s.t - 0.003) / 0.2
        assert k == pytest.approx(round(k), abs=1e-6)
    # the pipeline's own state is fed up to the fusion horizon only
    assert [t for t, _ in rec.fed] == pytest.approx([0.1 * k - 0.6 for k in range(1, 201)])
    for t, batch in rec.fed:
        assert all(s.t <= t + 1e-9 for s in batch)
    # published estimate: the newest compass sample before the tick (from the fork)
    for k, newest in enumerate(outputs[10:], 11):
        assert 0.1 * k - 0.1 < newest <= 0.1 * k
    assert not eng.rejected


def test_a_fork_is_made_for_each_restamped_fix_and_only_then():
    """The forks follow the samples in order without a copy; a fix stamped before the
    fork's newest sample makes them again: about one fork per pipeline per fix (100
    fixes arrive in 20 s), and one in all without GNSS."""
    with_fixes = _latency_engine(_Recorder())
    _run_live(with_fixes, _live_stream(0.6))
    # 98: the first fork, then one per fix (97 arrive by 20 s)
    assert 95 <= with_fixes.queue.copies <= 101
    compass_only = _latency_engine(_Recorder())
    _run_live(compass_only, _live_stream(0.6, gnss=False))
    assert compass_only.queue.copies == 1


class _FailsOnce(_Recorder):
    """A recorder whose fork raises at its first step after ``fail`` is set."""

    fail = False

    def step(self, t, samples):
        if _FailsOnce.fail:
            _FailsOnce.fail = False
            raise ValueError("boom")
        return super().step(t, samples)

    def __deepcopy__(self, memo):
        return _FailsOnce()


def test_set_state_and_a_restart_fork_again(monkeypatch):
    """A fork must not outlive the state it was copied from: after set_state, and after
    a pipeline restart (the next tick forks the new pipeline)."""
    import onboard.engine.engine as engine_mod

    monkeypatch.setattr(engine_mod, "build", lambda cfg, only=None: [_FailsOnce()])
    eng = _latency_engine(_FailsOnce())
    _run_live(eng, _live_stream(0.6, seconds=2.0, gnss=False), ticks=20)
    assert eng.queue.copies == 1
    eng.set_state({})
    eng.tick(2.1)
    assert eng.queue.copies == 2
    _FailsOnce.fail = True
    assert eng.tick(2.2) == [] and eng.pipeline_errors["rec"] == 1
    eng.tick(2.3)
    assert eng.queue.copies == 3


def test_collector_engine_without_fresh_estimates_keeps_order_and_copies_nothing():
    """Model closure's collector: fed at the fusion horizon, no forks."""
    rec = _Recorder()
    eng = _latency_engine(rec, fresh_estimates=False)
    outputs = _run_live(eng, _live_stream(0.6))
    # nothing fed yet at the horizon: -inf, which a record leaves out
    assert outputs[0] == -math.inf and math.isfinite(outputs[10])
    times = [s.t for _, batch in rec.fed for s in batch]
    assert times == sorted(times) and len(times) > 290
    assert eng.queue.copies == 0
    assert outputs[-1] <= 20.0 - 0.6 + 1e-9


def test_without_the_fixed_lag_a_late_fix_would_break_the_order():
    """What the fusion horizon prevents: the same stream re-stamped, fed at once."""
    rec = _Recorder()
    eng = _latency_engine(rec)
    eng.queue = TickQueue()  # re-stamp, but feed at once
    _run_live(eng, _live_stream(0.6), ticks=100)
    times = [s.t for _, batch in rec.fed for s in batch]
    assert times != sorted(times)


# ------------------------------------------------------------------ LateSampleHold


def _h(t: float) -> Heading:
    return Heading(t=t, heading_rad=0.0)


def test_hold_passes_in_order_samples_through_at_the_tick():
    hold = LateSampleHold(0.5)
    for k in range(1, 6):
        batch = [_h(0.1 * k - 0.05), _h(0.1 * k)]
        horizon, due = hold.release(0.1 * k, batch)
        assert horizon == 0.1 * k and due == batch
    assert hold.hold_s == 0.0 and hold.late == 0


def test_hold_grows_to_the_lateness_seen_and_then_releases_in_time_order():
    hold = LateSampleHold(0.5, memory_s=10.0)
    hold.release(1.0, [_h(1.0)])
    # a report stamped 0.8 arrives at the tick of 1.1, behind the horizon 1.0
    horizon, due = hold.release(1.1, [_h(0.8), _h(1.1)])
    assert hold.late == 1 and hold.hold_s == pytest.approx(0.3)
    assert horizon == 1.0  # the horizon never goes back: it waits for the ticks
    assert [s.t for s in due] == [0.8]  # the late one, handed on (behind the horizon)
    # the next late report (0.18 s) arrives ahead of the horizon: held, then in order
    horizon, due = hold.release(1.2, [_h(1.02), _h(1.2)])
    assert horizon == 1.0 and due == [] and hold.late == 1
    horizon, due = hold.release(1.45, [_h(1.45)])
    assert horizon == pytest.approx(1.15) and [s.t for s in due] == [1.02, 1.1]
    horizon, due = hold.release(1.6, [])
    assert [s.t for s in due] == [1.2] and horizon == pytest.approx(1.3)
    # no lateness for longer than the memory: the hold is back to 0, everything due
    horizon, due = hold.release(12.0, [_h(12.0)])
    assert hold.hold_s == 0.0 and horizon == 12.0 and [s.t for s in due] == [1.45, 12.0]


def test_hold_counts_samples_later_than_its_ceiling():
    hold = LateSampleHold(0.5)
    hold.release(5.0, [_h(5.0)])
    hold.release(5.05, [_h(4.2), _h(5.05)])  # a stall: 0.85 s late
    assert hold.too_late == 1 and hold.hold_s == 0.5


def test_hold_off_is_the_identity():
    hold = LateSampleHold(0.0)
    batch = [_h(0.2)]
    assert hold.release(1.0, batch) == (1.0, batch)
    assert hold.release(1.1, [_h(0.1)])[1][0].t == 0.1 and hold.late == 0
