"""One implementation per primitive, and every fast path against its reference.

Angle wrapping (:mod:`onboard.core.geo`): the scalar functions and their numpy twin agree
bit for bit, and the closed ends are the documented ones.
"""

from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest

from onboard.core.geo import TWO_PI, wrap_2pi, wrap_pi, wrap_pi_array

# --------------------------------------------------------------------------- angle wrapping

_PI = math.pi
_EDGES = [0.0, -0.0, _PI, -_PI, 3 * _PI, -3 * _PI, TWO_PI, -TWO_PI, 4 * _PI, -4 * _PI,
          math.nextafter(_PI, 0.0), math.nextafter(-_PI, 0.0), math.nextafter(_PI, 4.0),
          math.nextafter(-_PI, -4.0), 1e-300, -1e-300, 5e-324, -5e-324, 1e-17, -1e-17,
          1e16, -1e16, 1e300, -1e300, 1.7976931348623157e308, -1.7976931348623157e308]
_SPECIAL = [math.nan, math.inf, -math.inf]


def _angles() -> list[float]:
    rng = random.Random(13)
    out = list(_EDGES)
    out += [rng.uniform(-20.0, 20.0) for _ in range(2000)]
    out += [k * _PI + rng.choice((-1, 0, 1)) * 1e-15 for k in range(-40, 41)]
    out += [rng.uniform(-1.0, 1.0) * 10.0 ** rng.randint(-30, 300) for _ in range(2000)]
    return out


def _bits(x: float) -> bytes:
    return struct.pack("<d", x)


def _same_angle(a: float, b: float) -> bool:
    """``a`` and ``b`` are the same direction, to the rounding of ``a``'s size."""
    tol = 8.0 * math.ulp(max(abs(a), 8.0))
    d = math.fmod(a - b, TWO_PI)
    return min(abs(d), TWO_PI - abs(d)) <= tol


def test_wrap_pi_is_in_minus_pi_exclusive_to_pi_inclusive() -> None:
    for x in _angles():
        w = wrap_pi(x)
        assert -_PI < w <= _PI, x
        assert _same_angle(x, w), x
    assert wrap_pi(_PI) == _PI
    assert wrap_pi(-_PI) == _PI
    assert wrap_pi(3 * _PI) == _PI
    assert wrap_pi(-3 * _PI) == pytest.approx(_PI)
    assert wrap_pi(3 * _PI / 2) == pytest.approx(-_PI / 2)
    assert wrap_pi(-3 * _PI / 2) == pytest.approx(_PI / 2)
    assert _bits(wrap_pi(0.0)) == _bits(0.0) and _bits(wrap_pi(-0.0)) == _bits(0.0)


def test_wrap_2pi_is_in_zero_inclusive_to_two_pi_exclusive() -> None:
    for x in _angles():
        w = wrap_2pi(x)
        assert 0.0 <= w < TWO_PI, x
        assert _same_angle(x, w), x
        assert _bits(w) != _bits(-0.0), x
    assert wrap_2pi(-0.5) == pytest.approx(TWO_PI - 0.5)
    assert wrap_2pi(TWO_PI) == 0.0 and wrap_2pi(-TWO_PI) == 0.0
    # a rounding error below a multiple of 2 pi: 0, never 2 pi (Python's % gives 2 pi)
    assert (-1e-17) % TWO_PI == TWO_PI
    assert wrap_2pi(-1e-17) == 0.0
    assert _bits(wrap_2pi(-0.0)) == _bits(0.0)


@pytest.mark.parametrize("fn", [wrap_pi, wrap_2pi])
def test_wrapping_nan_and_infinities_gives_nan(fn) -> None:
    for x in _SPECIAL:
        assert math.isnan(fn(x))


def test_wrap_pi_array_is_bit_for_bit_the_scalar_wrap() -> None:
    xs = _angles() + _SPECIAL
    got = wrap_pi_array(xs)
    assert got.dtype == np.float64 and got.shape == (len(xs),)
    for x, g in zip(xs, got.tolist()):
        w = wrap_pi(x)
        assert (math.isnan(w) and math.isnan(g)) or _bits(w) == _bits(g), x
    assert wrap_pi_array(-_PI).shape == ()
    assert float(wrap_pi_array(-_PI)) == _PI
    block = np.array(xs[:100]).reshape(10, 10)
    assert np.array_equal(wrap_pi_array(block), wrap_pi_array(xs[:100]).reshape(10, 10))
