"""The coverage interval of validation/coverage.py: effective sample counts of time
series of hits, and Wilson's interval."""

import numpy as np
import pytest

from validation.coverage import integrated_time, interval, wilson


def test_wilson_interval_matches_its_formula_at_a_known_point():
    # p = 0.5 of 100: 0.5 -+ 1.96 * sqrt(0.25 / 100 + 1.96^2 / 4e4) / (1 + 1.96^2 / 100)
    low, high = wilson(0.5, 100)
    assert low == pytest.approx(0.4038, abs=1e-4) and high == pytest.approx(0.5962, abs=1e-4)


def test_independent_hits_count_as_themselves():
    rng = np.random.default_rng(1)
    c = interval([rng.random(5000) < 0.68 for _ in range(4)])
    assert c.n == 20000
    assert 0.8 * c.n < c.n_eff <= c.n
    assert c.low < 0.68 < c.high


def test_persistent_hits_count_as_their_correlation_time():
    # A two-state chain that switches with probability q a step: lag-k correlation
    # (1 - 2q)^k, integrated time (1 + rho) / (1 - rho) = (1 - q) / q = 49 for q = 0.02.
    rng = np.random.default_rng(2)
    q, n = 0.02, 200_000
    flips = rng.random(n) < q
    hits = (np.cumsum(flips) % 2) == 0
    c = interval([hits])
    assert c.n / c.n_eff == pytest.approx(49.0, rel=0.25)


def test_runs_that_differ_as_wholes_count_as_about_one_sample_each():
    # four runs each wholly covered or not: four samples, not 4,000
    runs = [np.ones(1000, bool), np.ones(1000, bool), np.zeros(1000, bool), np.ones(1000, bool)]
    c = interval(runs)
    assert c.fraction == 0.75
    assert 2.0 <= c.n_eff <= 8.0
    assert c.low < 0.5 and c.high > 0.9


def test_every_hit_the_same_counts_each_run_once():
    c = interval([np.ones(3000, bool)] * 4)
    assert (c.fraction, c.n_eff) == (1.0, 4.0)
    assert c.low < 0.6 and c.high == 1.0


def test_negative_correlation_never_counts_for_more_than_the_samples():
    hits = np.arange(1000) % 2 == 0  # alternating: lag-1 correlation -1
    assert integrated_time(np.array([1.0, -1.0, 1.0, -1.0])) == 1.0
    assert interval([hits]).n_eff == 1000


def test_no_samples_is_not_a_figure():
    c = interval([np.zeros(0, bool)])
    assert c.n == 0 and c.text() == "-"
