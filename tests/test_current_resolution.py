"""Issue 32, deliverable 6: a current the data do not tell from zero is flagged
(``current_unresolved``) and withheld, per component (docs/integrity.md, "The current not
resolved").

A scalar random-walk Kalman filter stands for the current pipeline's axis: the Kolumbo
glider's east (a 0.06 m/s current, velocities of 0.43 m/s noise every 8 s, a walk of 0.03
m/s/sqrt(s)) is worse than estimating zero, and the check says so; a strong current under
the same noise (the glider's north) and a well-measured zero current (a boat's Doppler)
are resolved.
"""

from __future__ import annotations

import math
import random

import pytest

from onboard.monitor.alerts import Alerts
from onboard.monitor.current_resolution import (
    RESOLVE_MIN_STD_MPS,
    RESOLVE_WINDOW_S,
    AxisResolution,
)
from onboard.monitor.integrity import IntegrityMonitor


def _walk_filter(current, noise_mps: float, walk: float, dt: float, seconds: float,
                 seed: int = 7):
    """(t, estimate, one-sigma, truth) of a random-walk Kalman filter of one current
    component ``current(t)`` (m/s) measured every ``dt`` (s) with ``noise_mps`` of noise,
    its walk ``walk`` (m/s/sqrt(s)) and its noise as declared."""
    rng = random.Random(seed)
    x, p = 0.0, 1.0
    q, r = walk * walk * dt, noise_mps * noise_mps
    t = 0.0
    while t < seconds:
        t += dt
        p += q
        truth = current(t)
        k = p / (p + r)
        x += k * (truth + rng.gauss(0.0, noise_mps) - x)
        p *= 1.0 - k
        yield t, x, math.sqrt(p), truth


def _judge(rows) -> tuple[float, float, float]:
    """Share of the ticks after the first window judged unresolved, and the RMS error of
    the estimate and of zero there (m/s)."""
    ax = AxisResolution()
    flags, err, zero = [], [], []
    for t, x, s, truth in rows:
        flag = ax.add(t, x, s)
        if t > RESOLVE_WINDOW_S:
            flags.append(flag)
            err.append((x - truth) ** 2)
            zero.append(truth * truth)
    return (sum(flags) / len(flags), math.sqrt(sum(err) / len(err)),
            math.sqrt(sum(zero) / len(zero)))


def _glider_east(t: float) -> float:
    """A 0.06 m/s current turning with a 15-minute period (the Kolumbo east: +-0.06)."""
    return 0.06 * math.sqrt(2.0) * math.sin(2.0 * math.pi * t / 900.0)


def test_a_noise_following_estimate_worse_than_zero_is_unresolved() -> None:
    share, err, zero = _judge(_walk_filter(_glider_east, 0.43, 0.03, 8.0, 9600.0))
    # measured: the estimate errs by 0.136 m/s against zero's 0.060, with a one-sigma
    # of 0.19; unresolved on every judged tick
    assert err > zero
    assert share > 0.95


def test_a_strong_current_under_the_same_noise_is_resolved() -> None:
    """Negative control: the same filter and noise, a 0.4 m/s current."""
    share, err, zero = _judge(_walk_filter(lambda t: 0.4, 0.43, 0.03, 8.0, 9600.0))
    # measured: resolved on every judged tick (error 0.138 against zero's 0.400)
    assert err < zero
    assert share == 0.0


def test_a_well_measured_zero_current_is_resolved() -> None:
    """Negative control: no current, measured at 5 Hz with 0.1 m/s of noise (a boat's
    Doppler): inside its one-sigma of zero, but that one-sigma is immaterial."""
    rows = list(_walk_filter(lambda t: 0.0, 0.1, 0.01, 0.2, 1200.0))
    # measured: one-sigma 0.021 m/s, error 0.014
    assert max(s for _, _, s, _ in rows[100:]) < RESOLVE_MIN_STD_MPS
    share, _, _ = _judge(rows)
    assert share == 0.0


class _Current:
    name = "current"
    position: tuple[str, ...] = ()
    speed: tuple[str, ...] = ()
    heading_dependent = ("north", "east")
    heading_estimate: tuple[str, ...] = ()
    current_estimate = ("north", "east")
    frame = None
    frame_offset = None


def test_the_unresolved_component_is_withheld_and_its_sigma_kept() -> None:
    """The monitor judges the current's components at every tick (before anything is
    withheld): east (the glider's) unresolved, north (0.4 m/s) not."""
    monitor = IntegrityMonitor(Alerts())
    monitor.watch([_Current()])
    assert monitor.amends
    east = _walk_filter(_glider_east, 0.43, 0.03, 8.0, 1200.0)
    north = _walk_filter(lambda t: 0.4, 0.43, 0.03, 8.0, 1200.0, seed=8)
    for (t, xe, se, _), (_, xn, sn, _) in zip(east, north):
        values = {"north": xn, "east": xe, "std_north": sn, "std_east": se}
        monitor.amend("current", t, values)
    assert monitor.withheld("current") == ("east",)
    assert monitor.active() == {"current": ["current_unresolved"]}
    warning = next(a for a in monitor.alerts if a.code == "current_unresolved")
    assert "east" in warning.message and "north" not in warning.message
    assert warning.t_start == pytest.approx(RESOLVE_WINDOW_S * 0.8, abs=8.0)
