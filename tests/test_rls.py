"""RLS with forgetting and bounded covariance (onboard.estimators.rls)."""

from __future__ import annotations

import numpy as np

from onboard.estimators.rls import RecursiveLeastSquares


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
