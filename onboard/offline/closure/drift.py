"""Nonstationarity: the chosen model re-estimated per time window, and its drift.

A current that turns with the tide, a propeller fouled half-way through a survey, a gyro
warming up: one parameter value for the whole log hides them. After selection the model
(base surge parameters and the chosen effects) is refitted on consecutive windows of the
data it was selected on (never the test part); for each parameter the per-window values,
a weighted straight line through them (slope per hour, with its one sigma) and a
chi-square test of "the same value in every window" are reported. A parameter is
``changing`` when that test rejects constancy at ``p < 1e-3`` or the slope is three of its
standard errors from zero, and the values spread by more than ``min_spread`` of their mean
magnitude.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats as sps

from onboard.offline.closure import model as M
from onboard.offline.closure.dataset import Dataset
from onboard.offline.closure.effects import ALL

SURGE = ("a", "b")
"""Base surge parameters followed per window (``surge.a``, pole, 1/s; ``surge.b``, command
gain, m/s^2) when no chosen effect shares the surge equation."""


def _window_params(ds: Dataset, f: M.Fit) -> tuple[dict[str, float], dict[str, float]]:
    """One window's parameters (describe() units) and one sigma, by ``effect.param``."""
    wf = M.fit(ds, f.effects, f.sigma, f.ctx, output_error=False, known=f.known)
    vals: dict[str, float] = {}
    sds: dict[str, float] = {}
    if ds.has_commands and not any(ALL[n].dynamic for n in f.effects):
        # with a dynamic effect in the surge equation (a thrust curve, drag) the base gain
        # trades off against it window by window: followed only in the base model
        vals["surge.a"], vals["surge.b"] = float(wf.base[0]), float(wf.base[1])
        sds["surge.a"] = sds["surge.b"] = math.nan
    for name in f.effects:
        p, s = ALL[name].describe(wf.theta[name], wf.std[name])
        for k, v in p.items():
            if k in s and math.isfinite(v):
                vals[f"{name}.{k}"] = v
                sds[f"{name}.{k}"] = s[k]
    return vals, sds


def _surge_sigma(ds: Dataset, f: M.Fit) -> tuple[float, float]:
    """One sigma of the surge pole and gain in a window: bootstrap-free, from the
    derivative-form regression of that window alone (inflated for correlated noise)."""
    X = M._base_columns(ds)
    y = ds.speed_dot
    ok = np.isfinite(y) & np.isfinite(X).all(1)
    if ok.sum() < 20:
        return math.inf, math.inf
    coef, *_ = np.linalg.lstsq(X[ok], y[ok], rcond=None)
    r = y[ok] - X[ok] @ coef
    s2 = float(r @ r) / max(1, ok.sum() - 3)
    cov = np.linalg.pinv(X[ok].T @ X[ok]) * s2 * max(1.0, 2.0 / ds.dt)
    return float(math.sqrt(max(cov[0, 0], 0.0))), float(math.sqrt(max(cov[1, 1], 0.0)))


def per_window(ds: Dataset, f: M.Fit, window_s: float | None = None,
               min_spread: float = 0.2) -> dict:
    """Per-window re-estimates of ``f``'s parameters on ``ds`` (in time order) and their
    drift (module docstring). Windows are ``window_s`` long (default: a fifth of the
    span, at least 90 s); with fewer than three windows the result has no drift."""
    order = np.argsort(ds.t, kind="stable")
    ds = ds.subset(order)
    span = float(np.ptp(ds.t)) if len(ds) else 0.0
    window_s = window_s or max(90.0, span / 5.0)
    edges = np.arange(ds.t[0], ds.t[-1] + 1e-9, window_s) if len(ds) else np.zeros(0)
    windows = []
    for lo in edges:
        m = (ds.t >= lo) & (ds.t < lo + window_s)
        if m.sum() * ds.dt < 0.5 * window_s:
            continue
        w = ds.subset(m)
        try:
            vals, sds = _window_params(w, f)
        except (np.linalg.LinAlgError, ValueError):
            continue
        if "surge.a" in vals:
            sds["surge.a"], sds["surge.b"] = _surge_sigma(w, f)
        windows.append({"t0": float(lo - ds.t[0]), "t1": float(lo - ds.t[0] + window_s),
                        "params": vals, "std": sds})
    out: dict = {"window_s": window_s, "windows": windows, "params": {}}
    if len(windows) < 3:
        return out
    for key in windows[0]["params"]:
        tm = np.array([0.5 * (w["t0"] + w["t1"]) for w in windows if key in w["params"]])
        v = np.array([w["params"][key] for w in windows if key in w["params"]])
        s = np.array([w["std"].get(key, math.inf) for w in windows if key in w["params"]])
        ok = np.isfinite(v) & np.isfinite(s) & (s > 0)
        if ok.sum() < 3:
            continue
        tm, v, s = tm[ok], v[ok], s[ok]
        wts = 1.0 / s**2
        mean = float(np.sum(wts * v) / np.sum(wts))
        chi2 = float(np.sum(wts * (v - mean) ** 2))
        p = float(sps.chi2.sf(chi2, len(v) - 1))
        X = np.column_stack([np.ones_like(tm), tm / 3600.0])
        cov = np.linalg.pinv(X.T @ (X * wts[:, None]))
        coef = cov @ (X.T @ (wts * v))
        spread = float(np.ptp(v)) / max(abs(mean), float(np.median(s)), 1e-9)
        out["params"][key] = {
            "mean": mean, "slope_per_hour": float(coef[1]),
            "slope_std": float(math.sqrt(max(cov[1, 1], 0.0))),
            "first": float(v[0]), "last": float(v[-1]),
            "constancy_p": p,
            "changing": bool((p < 1e-3 or abs(coef[1]) >= 3.0 * math.sqrt(max(cov[1, 1], 0.0)))
                             and spread > min_spread)}
    return out
