"""How precisely a coverage fraction is measured when its samples are time series.

A coverage figure (the share of a run's errors within k published sigmas) is a mean of
hits along a track: an estimate that is off at one tick is off at the next, so 9,600
samples of a run may hold a few dozen independent ones, and runs of different seeds
differ as wholes. :func:`interval` pools the runs and takes their hits as one stationary
sequence about the pooled mean: the autocovariance at each lag is summed over the runs
(never across two), and the integrated autocorrelation time is Geyer's initial positive
sequence estimator (Geyer 1992, Statistical Science 7(4), 473-483, §3.3: the sums of
adjacent autocorrelations, cut at the first that is not positive). The pooled hits then
count as ``n / tau`` independent ones, and the interval is Wilson's score interval
(Wilson 1927, JASA 22(158), 209-212) for that count. A run whose hits all lie on one side
of the pooled mean (a seed covered 1.00 where the others are 0.90) is correlated over its
whole length and counts as about one sample: what differs between seeds is measured by
the number of seeds. Where every hit is the same (all runs covered 1.00) nothing says how
they vary, and each run counts as one sample.

The interval says how far the same method, measured again on other seeds of the same
scenario, could land; it is not a tolerance, and a band is judged on the figure itself.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import numpy as np

Z_95 = 1.959963984540054
"""The standard normal's 97.5 % quantile: a two-sided 95 % interval."""


class Coverage(NamedTuple):
    """A pooled coverage fraction with its effective sample count and 95 % interval."""

    fraction: float
    n: int
    n_eff: float
    low: float
    high: float

    def text(self) -> str:
        """``0.86 (0.81-0.90)``: the figure and its interval."""
        if not self.n:
            return "-"
        return f"{self.fraction:.2f} ({self.low:.2f}-{self.high:.2f})"


def integrated_time(rho: np.ndarray) -> float:
    """Geyer's initial positive sequence estimate of ``1 + 2 sum_k rho_k`` from the
    autocorrelations ``rho`` (``rho[0] = 1``): pairs ``rho_2m + rho_2m+1`` summed while
    positive. At least 1 (a negative correlation never counts for more samples)."""
    total = 0.0
    for m in range(len(rho) // 2):
        pair = rho[2 * m] + rho[2 * m + 1]
        if pair <= 0.0:
            break
        total += pair
    return max(1.0, 2.0 * total - 1.0)


def _autocovariance(d: np.ndarray, max_lag: int) -> np.ndarray:
    """``sum_t d_t d_t+k`` for ``k = 0..max_lag`` (by FFT, zero-padded: no wrap)."""
    n = len(d)
    size = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(d, size)
    acov = np.fft.irfft(f * np.conj(f), size)[:n]
    out = np.zeros(max_lag + 1)
    out[:min(n, max_lag + 1)] = acov[:max_lag + 1]
    return out


def wilson(p: float, n: float, z: float = Z_95) -> tuple[float, float]:
    """Wilson's score interval for a fraction ``p`` of ``n`` independent trials."""
    if n <= 0:
        return 0.0, 1.0
    z2n = z * z / n
    centre = (p + z2n / 2.0) / (1.0 + z2n)
    half = z * math.sqrt(p * (1.0 - p) / n + z2n / (4.0 * n)) / (1.0 + z2n)
    return max(0.0, centre - half), min(1.0, centre + half)


def interval(hits: Sequence[np.ndarray]) -> Coverage:
    """The pooled coverage of ``hits`` (one boolean array per run, in time order) with
    its effective sample count (module docstring) and 95 % interval."""
    runs = [np.asarray(h, dtype=float) for h in hits if len(h)]
    n = sum(len(h) for h in runs)
    if not n:
        return Coverage(math.nan, 0, 0.0, math.nan, math.nan)
    p = float(sum(h.sum() for h in runs) / n)
    longest = max(len(h) for h in runs)
    acov = sum((_autocovariance(h - p, longest - 1) for h in runs), np.zeros(longest))
    if acov[0] <= 0.0:  # every hit the same: each run counts as one sample
        n_eff = float(len(runs))
    else:
        n_eff = n / integrated_time(acov / acov[0])
    low, high = wilson(p, n_eff)
    return Coverage(p, n, n_eff, low, high)
