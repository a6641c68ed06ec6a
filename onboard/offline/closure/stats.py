"""Residual statistics: bias, RMS, whiteness (Ljung-Box) and spectral peaks."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats as sps


def ljung_box_p(x: np.ndarray, lags: int = 10) -> float:
    """p-value of the Ljung-Box test that ``x`` is white (small p: structured)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    n = len(x)
    if n < 3 * lags:
        return float("nan")
    x = x - x.mean()
    denom = float(x @ x)
    if denom <= 0:
        return 1.0
    q = 0.0
    for k in range(1, lags + 1):
        rho = float(x[k:] @ x[:-k]) / denom
        q += rho * rho / (n - k)
    q *= n * (n + 2)
    return float(sps.chi2.sf(q, lags))


def decimate_for_whiteness(x: np.ndarray, dt: float, every_s: float = 1.0) -> np.ndarray:
    """Subsample to ~1 Hz: the smoothing of derived channels makes neighbouring ticks
    correlated by construction, which is not the structure we look for."""
    step = max(1, int(round(every_s / dt)))
    return np.asarray(x)[::step]


def summary(res: np.ndarray, dt: float) -> dict[str, float]:
    """``rmse``, ``bias`` and ``whiteness_p`` of a residual."""
    res = np.asarray(res, float)
    res = res[np.isfinite(res)]
    if len(res) == 0:
        return {"rmse": float("nan"), "bias": float("nan"), "whiteness_p": float("nan")}
    return {
        "rmse": float(math.sqrt(np.mean(res**2))),
        "bias": float(np.mean(res)),
        "whiteness_p": ljung_box_p(decimate_for_whiteness(res, dt)),
    }


def spectral_peak(t: np.ndarray, x: np.ndarray, min_period_s: float = 2.0,
                  max_period_s: float = 15.0) -> tuple[float | None, float, float]:
    """(period s, false-alarm probability, variance share) of the strongest sinusoid in
    ``x(t)`` between ``min_period_s`` and ``max_period_s``.

    A periodogram of the series on its full time grid with the gaps (the held-out blocks
    of a split) set to zero, which approximates the Lomb-Scargle periodogram at FFT speed. The false-alarm probability uses an effective sample
    count of one per second (residuals of smoothed channels are correlated over ~1 s) and
    the number of independent frequencies in the band; a peak must also stand 20 times
    above the band's median power, so a coloured background is not taken for a wave.
    """
    t = np.asarray(t, float)
    x = np.asarray(x, float)
    ok = np.isfinite(x) & np.isfinite(t)
    t, x = t[ok], x[ok] - np.mean(x[ok])
    if len(x) < 64 or np.ptp(t) < 4 * max_period_s:
        return None, 1.0, 0.0
    span = float(np.ptp(t))
    dt = float(np.median(np.diff(t)))
    # The gapped series on its full grid, zero where there is no data, zero-padded 4x.
    idx = np.round((t - t[0]) / dt).astype(int)
    grid = np.zeros(idx[-1] + 1)
    grid[idx] = x
    nfft = 4 * len(grid)
    spec = np.abs(np.fft.rfft(grid, nfft)) ** 2
    freqs = np.fft.rfftfreq(nfft, dt)
    band = (freqs >= 1.0 / max_period_s) & (freqs <= 1.0 / min_period_s)
    if band.sum() < 8:
        return None, 1.0, 0.0
    power = spec[band] * 2.0 / (len(x) * float(x @ x))  # share of variance of a sinusoid
    k = int(np.argmax(power))
    share = float(min(1.0, power[k]))
    f_lo, f_hi = 1.0 / max_period_s, 1.0 / min_period_s
    n_eff = max(8.0, span)
    m_indep = max(1.0, (f_hi - f_lo) * span)
    fap = float(min(1.0, m_indep * (1.0 - share) ** ((n_eff - 3) / 2)))
    if share < 20.0 * float(np.median(power)):
        fap = 1.0
    return float(1.0 / freqs[band][k]), fap, share
