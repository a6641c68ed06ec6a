"""RLS with forgetting and bounded covariance (onboard.estimators.rls)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from onboard.estimators.rls import RecursiveLeastSquares, dot, reference_rls_update, rls_update


def test_converges_to_true_parameters_with_noise():
    rng = np.random.default_rng(0)
    theta = np.array([-0.8, 0.3, 1.5])
    rls = RecursiveLeastSquares(3, forgetting=0.999, p0=100.0)
    for _ in range(3000):
        phi = rng.normal(size=3)
        rls.update(phi, float(phi @ theta + rng.normal(0, 0.05)))
    # measured: max error 0.004 and sigma 0.050 (noise 0.05)
    assert np.max(np.abs(rls.theta - theta)) < 0.02
    assert abs(np.sqrt(rls.sigma2) - 0.05) < 0.01


def test_tracks_a_parameter_step_with_forgetting():
    rng = np.random.default_rng(1)
    rls = RecursiveLeastSquares(2, forgetting=0.98, p0=10.0)
    for k in range(2000):
        theta = np.array([1.0, -1.0]) if k < 1000 else np.array([2.0, -1.0])
        phi = rng.normal(size=2)
        rls.update(phi, float(phi @ theta + rng.normal(0, 0.01)))
    # memory 1/(1-0.98) = 50 samples: after 1000 more samples the step is long tracked
    assert abs(rls.theta[0] - 2.0) < 0.01


def test_covariance_stays_bounded_without_excitation():
    """Covariance wind-up: a constant regressor leaves one direction unexcited; with plain
    forgetting its variance grows as lambda^-k (1e43 after 20000 steps at 0.995)."""
    rls = RecursiveLeastSquares(2, forgetting=0.995, p0=10.0)
    phi = np.array([1.0, 0.0])
    for _ in range(20000):
        rls.update(phi, 1.0)
    # measured: trace 10.0 (the bound tr_max = n * p0 = 20 is never exceeded)
    assert np.trace(rls.P) <= 20.0 + 1e-6
    assert np.all(np.isfinite(rls.P))
    assert abs(rls.theta[0] - 1.0) < 1e-6


def test_state_round_trip_and_mismatch_ignored():
    rls = RecursiveLeastSquares(2, names=("a", "b"))
    rls.update(np.array([1.0, 2.0]), 3.0)
    st = rls.get_state()
    other = RecursiveLeastSquares(2, names=("a", "b"))
    other.set_state(st)
    assert np.allclose(other.theta, rls.theta)
    wrong = RecursiveLeastSquares(2, names=("x", "y"))
    wrong.set_state(st)
    assert np.allclose(wrong.theta, 0.0)
    wrong.set_state({"names": ["x", "y"], "theta": [float("nan"), 0.0], "P": [[1, 0], [0, 1]]})
    assert np.all(np.isfinite(wrong.theta))


def _spd(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    M = rng.standard_normal((n, n))
    return scale * (M @ M.T / n + 0.5 * np.eye(n))


def _close(fast, ref, *inputs, rel: float = 1e-12) -> bool:
    """Equal to ``rel`` relative to the largest magnitude of the reference and of the
    ``inputs`` it was computed from (a covariance update subtracts nearly equal numbers
    when the data is informative: both forms then lose the same digits)."""
    fast, ref = np.asarray(fast, dtype=float), np.asarray(ref, dtype=float)
    scale = max([np.max(np.abs(ref))] + [np.max(np.abs(np.asarray(x))) for x in inputs])
    return bool(np.max(np.abs(fast - ref)) <= rel * scale)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(n=st.integers(1, 9), seed=st.integers(0, 2**32 - 1))
def test_float_update_is_the_numpy_reference(n: int, seed: int) -> None:
    """rls_update (floats, what RecursiveLeastSquares runs) against
    reference_rls_update (numpy, algorithms.md §3.4) on random covariances, regressors,
    weights, forgetting and EFRA terms: P, theta, e, lambda_k and s_k to 1e-12."""
    rng = np.random.default_rng(seed)
    P = _spd(rng, n, 10.0 ** rng.uniform(-2, 3))
    th, phi = rng.standard_normal(n), rng.standard_normal(n) * 10.0 ** rng.uniform(-2, 1)
    a, weight = float(rng.standard_normal()), float(rng.uniform(0.05, 1.0))
    forgetting, tr_max = float(rng.uniform(0.95, 1.0)), float(np.trace(P) * rng.uniform(0.5, 3))
    beta, delta = float(rng.uniform(0, 1e-3)), float(rng.uniform(0, 1e-3)) / np.trace(P)
    args = (a, weight, forgetting, tr_max, beta, delta)
    got = rls_update(P.tolist(), th.tolist(), phi.tolist(), *args)
    want = reference_rls_update(P, th, phi, *args)
    assert _close(got[0], want[0], P / want[3])
    assert np.array_equal(np.array(got[0]), np.array(got[0]).T)    # symmetric, bit for bit
    assert _close(got[1], want[1], th)
    for g, w in zip(got[2:], want[2:]):
        assert g == pytest.approx(w, rel=1e-12, abs=1e-300)


def test_estimator_runs_the_float_update() -> None:
    """RecursiveLeastSquares.update is rls_update on its state, bit for bit."""
    rng = np.random.default_rng(3)
    rls = RecursiveLeastSquares(4, forgetting=0.99, p0=10.0)
    for _ in range(50):
        phi, a = rng.standard_normal(4), float(rng.standard_normal())
        P, th, e, _, _ = rls_update(rls.P.tolist(), rls.theta.tolist(), phi.tolist(), a,
                                    1.0, rls.forgetting, rls.tr_max, rls.beta, rls.delta)
        assert rls.update(phi, a) == e
        assert np.array_equal(rls.P, P) and np.array_equal(rls.theta, th)


def test_dot_sums_left_to_right_from_the_first_product() -> None:
    """Not compensated, and a -0.0 product stays -0.0: the order the goldens record."""
    assert dot([1e16, 1.0, -1e16], [1.0, 1.0, 1.0]) == 0.0
    assert math.copysign(1.0, dot([-0.0], [1.0])) == -1.0
