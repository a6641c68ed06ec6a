"""Each sensor's white noise, identified from the log itself.

Method: second differences (the "variate difference" method; Tintner 1940). For a
signal sampled every ``dt`` whose third derivative is small, the second difference
``x[k+1] - 2 x[k] + x[k-1]`` removes the signal up to ``x''' dt^3`` and leaves white noise
of one-sigma ``s`` with the variance ``6 s^2``; a slowly wandering error (a receiver's
drift, a bias) cancels too. So ``s`` is the second differences' robust spread (1.4826
times their median absolute deviation, which a few outliers or manoeuvres do not move)
over ``sqrt(6)``.

Why differencing and not the Allan deviation: the Allan deviation separates white noise
from slower processes on a *still* sensor; on a moving vehicle the motion dominates every
averaging time longer than a sample, and its white-noise floor at the shortest one is the
same second difference. The drift, where the fixes report their own accuracy, is what
that accuracy holds beyond the white part: ``drift_share = 1 - s^2 / h_acc^2``.

Two checks decide whether a figure is usable:

* **whiteness**: the lag-1 autocorrelation of the second differences of white noise is
  ``-4 / 6 = -2/3``. An autopilot's filtered output (smooth, correlated) gives near 0 or
  positive values, a resampled one values near -1; its second-difference spread then
  says nothing about the error the filter should expect, and the figure is reported but
  not written (outside :data:`WHITE_LAG1_MIN` - :data:`WHITE_LAG1_MAX`).
* **the signal's share**: the same statistic on the third differences (variance ``20
  s^2``, lag-1 ``-15/20``) must agree with the second's within :data:`SIGNAL_RATIO_MAX`;
  a larger third-difference figure means motion leaks in (too coarse a sampling).

Only triples of samples evenly spaced (their two intervals within
:data:`EVEN_SPACING` of each other) and closer than :data:`MAX_GAP_S` are used.

**The receiver's drift** (:func:`receiver_drift`), where the fixes carry a velocity over
ground: the fixes less their own velocity integrated (trapezoids between fixes) leave the
fixes' error, white ``w`` plus a wandering ``b``, and the integrated velocity noise. The
variance of that residual's change over a lag ``T``, per axis (its structure function),
is then::

    D(T) = A + 2 s_b^2 (1 - exp(-T / tau)) + s_v^2 dt T

``A`` the white part (``2 s_w^2``), ``s_b`` and ``tau`` the drift's size and correlation
time (a first-order Gauss-Markov error), ``s_v`` the velocity's white noise (identified
above) and ``dt`` the fixes' interval. ``A``, ``s_b`` and ``tau`` are fitted on lags from
one fix to a quarter of the log, in logarithms, each lag weighted by the square root of
the independent spans it holds. What the increment filters need is the drift's rate of
change ``2 s_b^2 / tau`` (m^2/s: algorithms.md §2.2), better determined by a short log
than ``s_b`` and ``tau`` apart; with the fixes' reported accuracy ``h`` and the
``drift_share`` it gives, the config's ``drift_tau_s = 2 drift_share h^2 / rate`` makes
the filter's rate the measured one.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.optimize import least_squares

MIN_TRIPLES = 50
"""Least evenly spaced triples of samples for a figure."""
EVEN_SPACING = 0.1
"""Largest relative difference of the two intervals of a usable triple."""
MAX_GAP_S = 2.0
"""Samples further apart (s) are not differenced across."""
WHITE_LAG1 = -2.0 / 3.0
"""The lag-1 autocorrelation of the second differences of white noise."""
WHITE_LAG1_MAX = -0.55
"""Above this lag-1 autocorrelation of the second differences the noise is not white
(a filtered output): the figure is not written to a config. Even a 5-point moving
average of white noise reads -0.5 (second-difference coefficients ``[1, -1, 0, 0, 0, -1,
1] / 5``) while its spread understates the noise per sample threefold; white noise reads
-0.67 within about ``1 / sqrt(n)``."""
WHITE_LAG1_MIN = -0.8
"""Below this lag-1 autocorrelation the second differences alternate more than white
noise's do: a resampled or interpolated channel (the BlueBoat's 10 Hz positions read
-0.97), whose spread is no noise either."""
SIGNAL_RATIO_MAX = 1.3
"""Largest ratio of the third-difference to the second-difference estimate before the
motion is taken to leak into them."""
MAD_TO_STD = 1.4826
"""Normal one-sigma per median absolute deviation."""
DRIFT_MIN_S = 300.0
"""Shortest stretch of fixes with a velocity (s) whose drift is fitted."""
DRIFT_LAGS = 24
"""Lags of the structure function, on a geometric grid from one fix to a quarter of the
log."""
UNDERSTATES = 1.25
"""A receiver whose fixes' white noise alone exceeds this many times the accuracy they
report understates it: its reported accuracy is no basis for the fixes' noise (the
overlay sets it aside and writes the noise measured, white and drift)."""
DRIFT_TAU_RANGE_S = (10.0, 3600.0)
"""The drift's correlation time is fitted from the first (a faster wander is the white
noise's business), and the ``drift_tau_s`` written is kept within both (s)."""


def _robust_std(x: np.ndarray) -> float:
    return float(MAD_TO_STD * np.median(np.abs(x - np.median(x))))


def _lag1(x: np.ndarray) -> float:
    d = x - np.mean(x)
    den = float(np.dot(d, d))
    return float(np.dot(d[1:], d[:-1]) / den) if den > 0 else 0.0


def _even_runs(t: np.ndarray) -> np.ndarray:
    """Indices ``k`` whose samples ``k-1, k, k+1`` are evenly spaced and close."""
    dt = np.diff(t)
    a, b = dt[:-1], dt[1:]
    ok = ((a > 0) & (b > 0) & (a < MAX_GAP_S) & (b < MAX_GAP_S)
          & (np.abs(a - b) <= EVEN_SPACING * np.maximum(a, b)))
    return np.flatnonzero(ok) + 1


def white_noise(t: np.ndarray, x: np.ndarray) -> dict | None:
    """The white noise of one channel: ``std`` (the channel's unit), ``lag1`` of its
    second differences, ``third_ratio`` (third-difference over second-difference
    estimate), ``samples``, ``white`` (usable); None with too few evenly spaced
    triples."""
    t, x = np.asarray(t, float), np.asarray(x, float)
    keep = np.isfinite(t) & np.isfinite(x)
    t, x = t[keep], x[keep]
    if len(t) < MIN_TRIPLES + 2:
        return None
    k = _even_runs(t)
    if len(k) < MIN_TRIPLES:
        return None
    d2 = x[k + 1] - 2.0 * x[k] + x[k - 1]
    s2 = _robust_std(d2) / math.sqrt(6.0)
    third = _third(t, x)
    ratio = third / s2 if third is not None and s2 > 0 else math.nan
    lag1 = _lag1(d2[np.r_[True, np.diff(k) == 1]]) if len(k) > 2 else math.nan
    white = (s2 > 0 and WHITE_LAG1_MIN <= lag1 <= WHITE_LAG1_MAX
             and (not math.isfinite(ratio) or ratio <= SIGNAL_RATIO_MAX))
    return {"std": s2, "lag1": lag1, "third_ratio": ratio, "samples": int(len(k)),
            "white": bool(white)}


def _third(t: np.ndarray, x: np.ndarray) -> float | None:
    """The white-noise estimate from third differences (variance ``20 s^2``)."""
    dt = np.diff(t)
    if len(dt) < 3:
        return None
    a, b, c = dt[:-2], dt[1:-1], dt[2:]
    hi = np.maximum(np.maximum(a, b), c)
    ok = ((np.minimum(np.minimum(a, b), c) > 0) & (hi < MAX_GAP_S)
          & (hi - np.minimum(np.minimum(a, b), c) <= EVEN_SPACING * hi))
    k = np.flatnonzero(ok)
    if len(k) < MIN_TRIPLES:
        return None
    d3 = x[k + 3] - 3.0 * x[k + 2] + 3.0 * x[k + 1] - x[k]
    return _robust_std(d3) / math.sqrt(20.0)


def _axes(rows, cols: tuple[int, ...]) -> dict | None:
    """The per-axis figures of ``rows`` (time first) over the columns ``cols``, pooled:
    the root mean square of the axes' ``std``, white only if every axis is."""
    if not rows:
        return None
    a = np.asarray(rows, float)
    per = [white_noise(a[:, 0], a[:, c]) for c in cols]
    if any(p is None for p in per):
        return None
    std = math.sqrt(sum(p["std"] ** 2 for p in per) / len(per))
    return {"std": std, "per_axis": [p["std"] for p in per],
            "lag1": max(p["lag1"] for p in per),
            "third_ratio": max(p["third_ratio"] for p in per),
            "samples": min(p["samples"] for p in per), "white": all(p["white"] for p in per)}


def _segments(t: np.ndarray) -> list[np.ndarray]:
    """Index runs of samples closer than :data:`MAX_GAP_S`, each longer than
    :data:`DRIFT_MIN_S`."""
    cut = np.flatnonzero((np.diff(t) <= 0) | (np.diff(t) >= MAX_GAP_S)) + 1
    return [k for k in np.split(np.arange(len(t)), cut)
            if len(k) > 2 and t[k[-1]] - t[k[0]] >= DRIFT_MIN_S]


def receiver_drift(fixes, velocity, velocity_std: float) -> dict | None:
    """The wandering part of the fixes' error (module docstring): ``rate_m2_per_s`` (``2
    s_b^2 / tau`` per axis), ``std`` (``s_b``, m), ``tau_s``, ``white_std`` (``sqrt(A /
    2)``, m), ``span_s`` (the stretches fitted); None without :data:`DRIFT_MIN_S` of
    fixes with a velocity, or when the fit fails. ``fixes`` are ``(t, north, east)``,
    ``velocity`` ``(t, v_north, v_east)`` rows at the same times."""
    at = {float(r[0]): r for r in fixes}
    rows = [(t, at[float(t)][1], at[float(t)][2], vn, ve) for t, vn, ve in velocity
            if float(t) in at]
    if len(rows) < MIN_TRIPLES:
        return None
    a = np.asarray(rows, float)
    a = a[np.all(np.isfinite(a), axis=1)]
    t = a[:, 0]
    segs = _segments(t)
    if not segs:
        return None
    dt = float(np.median(np.diff(t)))
    longest = max(len(k) for k in segs)
    lags = np.unique(np.round(np.geomspace(1, max(longest // 4, 2), DRIFT_LAGS)).astype(int))
    res = [a[k, 1:3] - cumulative_trapezoid(a[k, 3:5], t[k], axis=0, initial=0.0)
           for k in segs]
    D, w, T = [], [], []
    n_all = sum(len(k) for k in segs)
    for m in lags:
        d = [r[m:] - r[:-m] for r in res if len(r) > m]
        if not d:
            continue
        d = np.vstack(d)
        D.append(float(np.mean([_robust_std(d[:, i]) ** 2 for i in (0, 1)])))
        w.append(math.sqrt(n_all / m))
        T.append(m * dt)
    if len(T) < 4:
        return None
    D_, w_, T_ = np.array(D), np.array(w), np.array(T)
    c_v = velocity_std ** 2 * dt

    def residual(p: np.ndarray) -> np.ndarray:
        model = math.exp(p[0]) + math.exp(p[1]) * -np.expm1(-T_ / math.exp(p[2])) + c_v * T_
        return w_ * (np.log(model) - np.log(D_))

    lo = [math.log(1e-8), math.log(1e-8), math.log(DRIFT_TAU_RANGE_S[0])]
    hi = [math.log(1e4), math.log(1e4), math.log(1e6)]
    start = np.clip([math.log(max(D_[0], 1e-8)), math.log(max(D_[-1] - D_[0], 1e-6)),
                     math.log(T_[len(T_) // 2])], lo, hi)
    try:
        fit = least_squares(residual, start, bounds=(lo, hi))
    except (ValueError, FloatingPointError):
        return None
    A, two_sb2, tau = (math.exp(x) for x in fit.x)
    if not (fit.success and all(math.isfinite(x) for x in (A, two_sb2, tau))):
        return None
    return {"rate_m2_per_s": two_sb2 / tau, "std": math.sqrt(0.5 * two_sb2), "tau_s": tau,
            "white_std": math.sqrt(0.5 * A), "span_s": float(sum(t[k[-1]] - t[k[0]]
                                                                   for k in segs))}


def identify(raw: dict) -> dict:
    """Every channel's white noise from the log's measurements (``Dataset.raw``):
    ``gnss_position`` (m per axis), ``gnss_velocity`` (m/s per axis), ``compass`` (rad),
    ``dvl`` (m/s per axis), each with its method and checks; the position's
    ``drift_share`` where the fixes report their accuracy (and ``reported_understates``
    where their white noise alone is :data:`UNDERSTATES` times it), its ``drift`` where
    they carry a velocity (:func:`receiver_drift`) and, with both, the ``drift_tau_s`` that gives the
    filter the measured rate. Channels the log lacks are left out."""
    out: dict = {}
    pos = _axes(raw.get("fixes") or [], (1, 2))
    if pos is not None:
        out["gnss_position"] = {**pos, "unit": "m"}
    vel = _axes(raw.get("gnss_velocity") or [], (1, 2))
    if vel is not None:
        out["gnss_velocity"] = {**vel, "unit": "m/s"}
    # one heading source, never mixed: the most frequent (the finest sampling leaves the
    # least motion in the differences)
    for source in sorted(("heading", "attitude_yaw"), key=lambda k: -len(raw.get(k) or [])):
        head = raw.get(source) or []
        fig = None
        if len(head) > 2:
            h = np.asarray(head, float)
            fig = white_noise(h[:, 0], np.unwrap(h[:, 1]))
        if fig is not None:
            out["compass"] = {**fig, "unit": "rad", "source": source}
            break
    dvl = _axes(raw.get("dvl") or [], (1, 2))
    if dvl is not None:
        out["dvl"] = {**dvl, "unit": "m/s"}
    acc = [a for _, a in raw.get("gnss_accuracy") or [] if a > 0]
    if pos is not None and acc:
        h_acc = float(np.median(acc))
        out["gnss_position"]["reported_std"] = h_acc
        out["gnss_position"]["drift_share"] = max(0.0, 1.0 - pos["std"] ** 2 / h_acc ** 2)
        out["gnss_position"]["reported_understates"] = pos["std"] > UNDERSTATES * h_acc
    if pos is not None and vel is not None:
        drift = receiver_drift(raw.get("fixes") or [], raw.get("gnss_velocity") or [],
                               vel["std"])
        if drift is not None:
            out["gnss_position"]["drift"] = drift
            share = out["gnss_position"].get("drift_share", 0.0)
            if share > 0.0 and drift["rate_m2_per_s"] > 0.0:
                lo, hi = DRIFT_TAU_RANGE_S
                tau = 2.0 * share * out["gnss_position"]["reported_std"] ** 2 \
                    / drift["rate_m2_per_s"]
                out["gnss_position"]["drift_tau_s"] = min(max(tau, lo), hi)
    for v in out.values():
        v["method"] = "second differences (robust), white-noise checked"
    return out


CONFIG_KEYS = {
    "gnss_position": ("sensors.gnss", "position_std_m"),
    "gnss_velocity": ("sensors.gnss", "velocity_std_mps"),
    "compass": ("sensors.compass", "heading_std_rad"),
    "dvl": ("sensors.dvl", "velocity_std_mps"),
}
"""Where each identified channel's one-sigma goes in a config."""
