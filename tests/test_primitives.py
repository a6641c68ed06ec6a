"""One implementation per primitive, and every fast path against its reference.

Angle wrapping (:mod:`onboard.core.geo`): the scalar functions and their numpy twin agree
bit for bit, and the closed ends are the documented ones. ZYX rotation
(:mod:`onboard.core.so3`): the plain-float fast paths against the numpy reference.
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


# --------------------------------------------------------------------------- ZYX rotation


def _random_attitudes(n: int = 500, seed: int = 2) -> list[tuple[float, float, float]]:
    rng = random.Random(seed)
    out = [(0.0, 0.0, 0.0), (_PI, 0.0, -_PI), (0.3, 1.5, 2.0), (-0.3, -1.5, -2.0)]
    out += [(rng.uniform(-_PI, _PI), rng.uniform(-1.5, 1.5), rng.uniform(-4.0, 4.0))
            for _ in range(n)]
    return out


def test_plain_float_rotations_are_the_reference_matrix_products() -> None:
    from onboard.core.so3 import body_to_ned, euler_to_matrix, ned_to_body

    rng = np.random.default_rng(3)
    for roll, pitch, yaw in _random_attitudes():
        R = euler_to_matrix(roll, pitch, yaw)
        v = rng.normal(size=3) * 10.0 ** rng.integers(-3, 4)
        scale = float(np.abs(v).sum())
        assert np.allclose(body_to_ned(roll, pitch, yaw, v.tolist()), R @ v, rtol=0.0,
                           atol=1e-15 * scale)
        assert np.allclose(ned_to_body(roll, pitch, yaw, v.tolist()), R.T @ v, rtol=0.0,
                           atol=1e-15 * scale)
        # each component is the reference row times v, term by term: bit for bit
        e = R.tolist()
        x, y, z = v.tolist()
        assert body_to_ned(roll, pitch, yaw, (x, y, z)) == tuple(
            r[0] * x + r[1] * y + r[2] * z for r in e)
        assert ned_to_body(roll, pitch, yaw, (x, y, z)) == tuple(
            e[0][j] * x + e[1][j] * y + e[2][j] * z for j in range(3))


def test_euler_kinematics_is_the_rotation_and_the_euler_rate_matrix() -> None:
    from onboard.core.so3 import euler_kinematics, euler_rate_matrix, euler_to_matrix

    rng = np.random.default_rng(4)
    for roll, pitch, yaw in _random_attitudes():
        nu = rng.normal(size=6)
        got = np.array(euler_kinematics(roll, pitch, yaw, nu.tolist()))
        want = np.concatenate([euler_to_matrix(roll, pitch, yaw) @ nu[:3],
                               euler_rate_matrix(roll, pitch) @ nu[3:]])
        # T(Theta) grows like 1/cos(pitch): compare relative to the largest term
        scale = float(np.abs(nu).sum()) / math.cos(pitch)
        assert np.allclose(got, want, rtol=0.0, atol=4e-15 * scale), (roll, pitch, yaw)


def test_euler_to_matrix_is_a_rotation_that_points_the_nose() -> None:
    from onboard.core.so3 import euler_to_matrix, matrix_to_euler

    for roll, pitch, yaw in _random_attitudes(100):
        R = euler_to_matrix(roll, pitch, yaw)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-15 * 8)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)
        if abs(pitch) < 1.5:
            assert np.allclose(euler_to_matrix(*matrix_to_euler(R)), R, atol=1e-12)
    assert np.allclose(euler_to_matrix(0.0, 0.0, _PI / 2) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    assert (euler_to_matrix(0.0, 0.3, 0.0) @ [1.0, 0.0, 0.0])[2] < 0.0  # nose up: -down


def test_skew_is_the_cross_product() -> None:
    from onboard.core.so3 import cross, skew

    rng = np.random.default_rng(5)
    for _ in range(100):
        a, b = rng.normal(size=3), rng.normal(size=3)
        assert np.allclose(skew(a) @ b, np.cross(a, b), rtol=0.0, atol=1e-15 * 8)
        assert np.allclose(cross(a, b), np.cross(a, b), rtol=0.0, atol=1e-15 * 8)
        assert np.array_equal(skew(a), -skew(a).T)
