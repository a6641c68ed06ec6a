"""The one chi-square of the package (onboard.core.stats) against scipy.stats, its oracle,
and the band of a mean NIS against simulated chi-square values."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

from onboard.core.stats import chi2_mean_band, chi2_quantile, chi2_sf
from tests.helpers.imports import REPO

DOFS = (1, 2, 3, 6, 23, 0.7, 5.5, 137.25, 300.0)
"""Degrees of freedom: the gates' (1-3), a whole state's (23), the effective, fractional
counts of the integrity monitor's blocks (0.7 to 300)."""


@pytest.mark.parametrize("dof", DOFS)
def test_the_quantile_is_scipys(dof: float) -> None:
    for q in (1e-6, 0.005, 0.025, 0.5, 0.95, 0.975, 0.995, 0.999, 1 - 1e-6):
        assert chi2_quantile(q, dof) == pytest.approx(stats.chi2.ppf(q, dof), rel=1e-14)


@pytest.mark.parametrize("dof", DOFS)
def test_the_survival_function_is_scipys(dof: float) -> None:
    for x in (0.0, 1e-3, 0.5, 1.0, 3.84, 10.83, 50.0, 400.0):
        assert chi2_sf(x, dof) == pytest.approx(stats.chi2.sf(x, dof), rel=1e-13, abs=1e-300)


def test_the_survival_function_inverts_the_quantile() -> None:
    for dof in (1, 2, 3):
        assert chi2_sf(chi2_quantile(0.999, dof), dof) == pytest.approx(1e-3, rel=1e-12)


def test_the_gates_are_the_exact_quantiles_not_a_rounded_table() -> None:
    # the ESESO's table was 10.83, 13.82, 16.27: within 0.04 %, but not the quantile
    exact = [chi2_quantile(0.999, k) for k in (1, 2, 3)]
    assert exact == pytest.approx([10.827566, 13.815511, 16.266236], abs=1e-6)
    assert all(abs(t - e) > 1e-3 for t, e in zip((10.83, 13.82, 16.27), exact))


def test_a_gate_asked_again_comes_from_the_cache() -> None:
    chi2_quantile(0.999, 2)
    hits = chi2_quantile.cache_info().hits
    for _ in range(100):
        chi2_quantile(0.999, 2)
    assert chi2_quantile.cache_info().hits == hits + 100


@pytest.mark.parametrize("n, dof", [(1, 1), (5, 2), (100, 3), (2460, 3), (7.3, 1)])
def test_the_band_of_a_mean_is_scipys(n: float, dof: int) -> None:
    k = n * dof
    lo, hi = chi2_mean_band(n, dof)
    assert (lo, hi) == pytest.approx((stats.chi2.ppf(0.025, k) / n,
                                      stats.chi2.ppf(0.975, k) / n), rel=1e-14)
    lo99, hi99 = chi2_mean_band(n, dof, 0.99)
    assert lo99 < lo < dof < hi < hi99


def test_the_band_holds_the_mean_of_simulated_nis_values_at_its_probability() -> None:
    """5000 means of 5 chi-square(2) values: 95 % inside the 95 % band (measured 0.9494;
    the binomial one-sigma is 0.003)."""
    rng = np.random.default_rng(31)
    means = rng.chisquare(2, size=(5000, 5)).mean(axis=1)
    lo, hi = chi2_mean_band(5, 2)
    inside = float(np.mean((means >= lo) & (means <= hi)))
    assert abs(inside - 0.95) < 0.01
    # negative control: the band of a 4-dimensional NIS does not hold them (measured 0.47)
    lo4, hi4 = chi2_mean_band(5, 4)
    assert float(np.mean((means >= lo4) & (means <= hi4))) < 0.6


def test_no_values_have_no_band() -> None:
    assert all(math.isnan(v) for v in chi2_mean_band(0, 3))


def test_importing_the_module_and_its_users_does_not_import_scipy() -> None:
    """scipy.special is imported at the first quantile (0.4 s of a vehicle's start), not
    by importing the module or the filters and the monitor that use it."""
    code = ("import sys, onboard.core.stats, onboard.estimators.eseso_filter, "
            "onboard.estimators.restored_current, onboard.monitor.integrity; "
            "assert not [m for m in sys.modules if m.startswith('scipy')], "
            "sorted(m for m in sys.modules if 'scipy' in m)[:5]")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)
