"""The simulator's link delay (sitl/link.py) against what it says it reproduces."""

from __future__ import annotations

import numpy as np

from onboard.sitl.link import ARDUSUB_TETHER, DelayedClock, LinkDelay


def test_the_tether_delay_has_the_tlogs_percentiles_memory_and_keeps_the_frames_in_order():
    """20 Hz frames for an hour: the delay's 50th / 95th percentiles near the ArduSub
    tlog's ATTITUDE (7 / 20 ms; the clipped normal gives 8 / 19.5), consecutive delays
    correlated 0.82 (the tlog's), never negative, and no frame overtaking another."""
    clock = DelayedClock(ARDUSUB_TETHER, np.random.default_rng(7))
    t = np.arange(0.0, 3600.0, 0.05)
    arrival = np.array([clock.arrival(x) for x in t])
    d = (arrival - t) * 1000.0
    assert np.all(d >= 0.0) and np.all(np.diff(arrival) >= 0.0)
    p50, p95 = np.percentile(d, [50, 95])
    assert 6.5 < p50 < 9.5 and 17.0 < p95 < 23.0, (p50, p95)
    assert 0.75 < np.corrcoef(d[:-1], d[1:])[0, 1] < 0.88


def test_a_link_without_spread_delays_every_frame_by_its_mean():
    """The control: no wandering part, every frame exactly ``mean`` late."""
    clock = DelayedClock(LinkDelay(mean_s=0.004, std_s=0.0, tau_s=1.0),
                         np.random.default_rng(0))
    assert [round(clock.arrival(x) - x, 12) for x in (0.0, 0.02, 0.04, 1.0)] == [0.004] * 4
