"""The chi-square distribution of a normalized innovation squared (NIS): its survival
function, its quantiles, and the band of the mean of ``n`` NIS values.

Every gate and every consistency band of the package takes its numbers from here
(Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
Navigation*, 2001, section 5.4: the NIS of a consistent filter's ``m``-dimensional innovation is
chi-square with ``m`` degrees of freedom, and ``n`` times the mean of ``n`` independent
ones is chi-square with ``n m``). The values are those of ``scipy.stats.chi2``
(tests/test_stats.py compares them): its ``sf`` and ``ppf`` evaluate
``scipy.special.chdtrc`` and ``2 gammaincinv(dof / 2, q)``, which are called here
directly. ``scipy.special`` is imported at the first quantile or survival value, not
with this module: it takes 0.4 s to import (``scipy.stats`` 1.2 s), which a vehicle's
start does not pay unless a filter uses a chi-square. The service calls :func:`preload`
before READY, so that the import is not paid inside its first measurement updates (a
0.4 s stall of its tick loop, and 1.3 % of a core over the 30 s the service benchmark
measures).

A quantile is cached per ``(q, dof)`` (:data:`QUANTILE_CACHE_SIZE` entries): a gate asked
at every update costs a dictionary look-up, not a scipy call.
"""

from __future__ import annotations

import functools
import math

QUANTILE_CACHE_SIZE = 4096
"""Quantiles kept per ``(q, dof)``, least recently used dropped: the gates use a handful,
the integrity monitor's bands one per block of a channel with a new effective count."""


def preload() -> None:
    """Import what the chi-square functions need now rather than at their first call."""
    import scipy.special  # noqa: F401


def chi2_sf(x: float, dof: float) -> float:
    """``P(X > x)`` for ``X`` chi-square with ``dof`` (real, > 0) degrees of freedom."""
    from scipy.special import chdtrc

    return float(chdtrc(dof, x))


@functools.lru_cache(maxsize=QUANTILE_CACHE_SIZE)
def chi2_quantile(q: float, dof: float) -> float:
    """The ``x`` with ``P(X <= x) = q`` for ``X`` chi-square with ``dof`` (real, > 0)
    degrees of freedom (``scipy.stats.chi2.ppf``); e.g. the 99.9 % gate of a 1-dimensional
    innovation, ``chi2_quantile(0.999, 1)`` = 10.8276."""
    from scipy.special import gammaincinv

    return float(2.0 * gammaincinv(0.5 * dof, q))


def chi2_mean_band(n: float, dof: float, p: float = 0.95) -> tuple[float, float]:
    """The two-sided ``p`` band ``(lo, hi)`` of the mean of ``n`` independent chi-square
    values of ``dof`` degrees of freedom (``n`` may be an effective, fractional count): the
    ``(1 -+ p) / 2`` quantiles of chi-square with ``n dof`` degrees of freedom, divided by
    ``n``. NaN for ``n dof <= 0`` (no values)."""
    k = n * dof
    if not k > 0.0:
        return math.nan, math.nan
    a = 0.5 * (1.0 - p)
    return chi2_quantile(a, k) / n, chi2_quantile(1.0 - a, k) / n
