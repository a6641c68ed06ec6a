"""The accelerometer's path acceleration (onboard/estimators/path_accel.py)."""

from __future__ import annotations

import math

import pytest

from onboard.estimators.path_accel import GRAVITY, PathAccelerometer


def _feed(pa: PathAccelerometer, accel, pitch, roll=lambda t: 0.0, crab=0.0, fy=0.0,
          t_end=2.0, rate=50.0, att_rate=10.0) -> None:
    """Specific force of a body with path acceleration ``accel(t)``, pitched by
    ``pitch(t)`` (attitude at ``att_rate``, gyro pitch rate exact)."""
    pa.crab(crab)
    n = int(t_end * rate)
    next_att = 0.0
    for i in range(n + 1):
        t = i / rate
        if t >= next_att - 1e-9:
            pa.attitude(t, roll(t), pitch(t))
            next_att += 1.0 / att_rate
        th = pitch(t)
        q = (pitch(t + 1e-4) - pitch(t - 1e-4)) / 2e-4
        fx = accel(t) * math.cos(crab) + GRAVITY * math.sin(th)
        pa.add(t, fx, fy, 0.0, q, 0.0)


def test_constant_acceleration_integrates_exactly() -> None:
    pa = PathAccelerometer()
    _feed(pa, lambda t: 0.5, lambda t: 0.0)
    d = pa.delta(0.3, 1.3)
    assert d is not None
    assert d[0] == pytest.approx(0.5, rel=1e-9)         # dv = a tau
    assert d[1] == pytest.approx(0.25, rel=1e-9)        # a tau^2 / 2


def test_gravity_of_a_wave_pitch_is_removed_between_attitude_samples() -> None:
    """A 2.5 s wave pitching the hull 0.1 rad and accelerating it 0.95 m/s^2: the
    speed change over 0.15 s windows follows the true acceleration; with the pitch held
    between 10 Hz attitudes (no gyro) it would miss by g times the pitch change."""
    w = 2.0 * math.pi / 2.5

    def acc(t):
        return 0.95 * math.cos(w * t)

    pa = PathAccelerometer()
    _feed(pa, acc, lambda t: 0.1 * math.sin(w * t), t_end=5.0)
    worst = 0.0
    for i in range(20):
        t0 = 1.0 + 0.17 * i
        d = pa.delta(t0, t0 + 0.15)
        assert d is not None
        true_dv = 0.95 / w * (math.sin(w * (t0 + 0.15)) - math.sin(w * t0))
        worst = max(worst, abs(d[0] - true_dv))
    # measured 0.0028 m/s (ZOH of 50 Hz samples); g * 0.1 rad * w * 0.1 s * 0.15 s
    # = 0.037 m/s with the pitch held
    assert worst < 0.006


def test_crab_projects_and_bias_is_learned_and_removed() -> None:
    pa = PathAccelerometer(bias_gain=0.05)
    # the body x axis 0.2 rad off the track: the path acceleration is a_x cos + a_y sin
    _feed(pa, lambda t: 0.0, lambda t: 0.0, crab=0.2, fy=0.3, t_end=4.0)
    d = pa.delta(1.0, 2.0)
    assert d is not None and d[0] == pytest.approx(0.3 * math.sin(0.2), rel=1e-6)
    for i in range(100):   # the filtered speed says the boat did not accelerate
        pa.update_bias(1.0, 2.0, 0.0)
    assert pa.bias == pytest.approx(0.3 * math.sin(0.2), rel=1e-3)
    d = pa.delta(1.0, 2.0)
    assert d is not None and abs(d[0]) < 1e-3


def test_missing_attitude_or_a_silence_breaks_the_integral() -> None:
    pa = PathAccelerometer()
    assert not pa.add(0.0, 0.1, 0.0, 0.0, 0.0, 0.0)     # no attitude yet
    assert pa.delta(0.0, 0.1) is None
    pa.attitude(0.0, 0.0, 0.0)
    for i in range(10):
        pa.add(0.02 * i, 0.1, 0.0, 0.0, 0.0, 0.0)
    assert pa.delta(0.0, 0.18) is not None
    pa.attitude(1.0, 0.0, 0.0)
    pa.add(1.0, 0.1, 0.0, 0.0, 0.0, 0.0)                # 0.82 s of silence
    assert pa.n_breaks == 1
    assert pa.delta(0.1, 1.0) is None
    assert not pa.add(1.02, math.nan, 0.0, 0.0, 0.0, 0.0)


def test_forecast_blend_finds_the_optimal_weight_under_a_common_error() -> None:
    """Misses sharing a large common error (the measurement's noise, the starting
    estimate's error): the weight is that of the forecasts' own errors, 0.5^2 / (0.5^2 +
    0.25^2) = 0.8 for the second, and 0 / 1 when one forecast is exact."""
    import numpy as np

    from onboard.estimators.path_accel import ForecastBlend

    rng = np.random.default_rng(3)
    b, exact = ForecastBlend(gain=1e-5), ForecastBlend(gain=1e-5)
    assert b.w == 1.0   # before min_n misses: w0
    for _ in range(20000):
        common = rng.standard_normal()
        em, ei = 0.5 * rng.standard_normal(), 0.25 * rng.standard_normal()
        b.add(common + em, common + ei)
        exact.add(common, common + ei)
    # measured 0.773 (other seeds 0.78-0.80: the plain mean of 20000 misses)
    assert b.w == pytest.approx(0.8, abs=0.04)
    assert exact.w < 0.02
    b.add(math.nan, 1.0)   # ignored
    assert b.n == 20000
