"""The base vehicle model, its augmentation by effects, fitting and open-loop prediction.

Base model (what the AIE and current pipelines assume): the vehicle moves along its
measured heading (lateral velocity over ground 0), the measured heading turns with the
gyro (heading rate minus gyro 0), and its through-water speed follows the first-order
surge model of algorithms.md §1.1, ``U' = -a U + b c + c0``, from the normalized command
``c``. Effects add linear regressors to those channels (:mod:`.effects`). All parameters
enter linearly once ``a`` and ``b`` are fixed, so a fit is a weighted least-squares problem
over the stacked channels, iterated twice to refresh ``a`` and ``b``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from onboard.closure.dataset import Dataset
from onboard.closure.effects import ALL, Context, Effect

CHANNELS = ("lateral", "heading_rate", "along")
BASE_PARAMS = ("a", "b", "c0")


def channel_targets(ds: Dataset) -> dict[str, np.ndarray]:
    """The measured quantity each channel's regression explains."""
    out = {"lateral": ds.lateral}
    if ds.has_gyro:
        out["heading_rate"] = ds.psi_dot - ds.r
    if ds.has_commands:
        out["along"] = ds.speed_dot
    return out


def _base_columns(ds: Dataset) -> np.ndarray:
    cmd = np.nan_to_num(ds.cmd_surge)
    return np.column_stack([-ds.along_s, cmd, np.ones(len(ds))])


@dataclass
class Fit:
    """A fitted model: base surge parameters, effect parameters and their one-sigma."""

    effects: tuple[str, ...]
    base: np.ndarray
    theta: dict[str, np.ndarray]
    std: dict[str, np.ndarray]
    ctx: Context
    sigma: dict[str, float]
    n: int = 0

    def effect(self, name: str) -> Effect:
        return ALL[name]


def _decorrelation(ds: Dataset, seconds: float = 2.0) -> float:
    """Variance inflation for correlated residuals: ticks per independent sample."""
    return max(1.0, seconds / ds.dt)


def fit(ds: Dataset, effects: tuple[str, ...], sigma: dict[str, float],
        ctx: Context | None = None) -> Fit:
    """Weighted least squares of the base model plus ``effects`` on ``ds``.

    ``sigma`` gives each channel's noise scale (its rows are divided by it), so channels
    in different units weigh alike.
    """
    ctx = Context(**vars(ctx)) if ctx is not None else Context()
    targets = channel_targets(ds)
    n = len(ds)
    base = np.array([ctx.a, ctx.b, 0.0])
    theta: dict[str, np.ndarray] = {}
    std: dict[str, np.ndarray] = {}
    for _ in range(8 if ds.has_commands else 1):
        a_prev = ctx.a
        blocks, ys = [], []
        layout: list[tuple[str, int]] = []
        if ds.has_commands:
            layout.append(("__base__", 3))
        for name in effects:
            layout.append((name, len(ALL[name].params)))
        n_par = sum(k for _, k in layout)
        cols_cache = {name: ALL[name].columns(ds, ctx) for name in effects}
        for ch, y in targets.items():
            X = np.zeros((n, n_par))
            j = 0
            for name, k in layout:
                if name == "__base__":
                    if ch == "along":
                        X[:, j:j + k] = _base_columns(ds)
                else:
                    c = cols_cache[name].get(ch)
                    if c is not None:
                        X[:, j:j + k] = c
                j += k
            ok = np.isfinite(y) & np.isfinite(X).all(axis=1)
            w = 1.0 / sigma.get(ch, 1.0)
            blocks.append(X[ok] * w)
            ys.append(y[ok] * w)
        X = np.vstack(blocks)
        y = np.concatenate(ys)
        if n_par == 0:
            break
        xtx = X.T @ X
        try:
            sol = np.linalg.solve(xtx, X.T @ y)
        except np.linalg.LinAlgError:
            sol, *_ = np.linalg.lstsq(X, y, rcond=None)
        resid = y - X @ sol
        dof = max(1, len(y) - n_par)
        s2 = float(resid @ resid) / dof
        try:
            cov = np.linalg.pinv(xtx) * s2 * _decorrelation(ds)
        except np.linalg.LinAlgError:
            cov = np.full((n_par, n_par), np.inf)
        sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
        j = 0
        for name, k in layout:
            if name == "__base__":
                base = sol[j:j + k].copy()
                a = float(base[0])
                ctx.a = a if 0.01 < a < 20.0 else ctx.a
                ctx.b = float(base[1])
            else:
                theta[name] = sol[j:j + k].copy()
                std[name] = sd[j:j + k].copy()
            j += k
        if abs(ctx.a - a_prev) < 1e-4 * max(1.0, abs(ctx.a)):
            break
    return Fit(effects=tuple(effects), base=base, theta=theta, std=std, ctx=ctx,
               sigma=dict(sigma), n=n)


def _segments(ds: Dataset) -> list[np.ndarray]:
    """Index ranges of contiguous stretches (per run label)."""
    out = []
    if len(ds) == 0:
        return out
    change = np.flatnonzero(ds.run[1:] != ds.run[:-1]) + 1
    bounds = np.r_[0, change, len(ds)]
    for a, b in zip(bounds[:-1], bounds[1:]):
        out.append(np.arange(a, b))
    return out


def predict(ds: Dataset, f: Fit) -> dict[str, np.ndarray]:
    """Model predictions of each channel on ``ds``; the along-track speed open loop.

    ``along`` is the predicted along-track speed over ground (m/s), simulated from the
    commands from the measured speed at the start of each contiguous segment; the other
    channels are algebraic.
    """
    n = len(ds)
    ctx = f.ctx
    lat = np.zeros(n)
    hr = np.zeros(n)
    out_along = np.zeros(n)
    dyn_effects = []
    delay = sum(ALL[name].output_delay_s(f.theta[name]) for name in f.effects)
    for name in f.effects:
        e, th = ALL[name], f.theta[name]
        lat += e.lateral_output(th, ds, ctx)
        hr += e.heading_rate_output(th, ds, ctx)
        out_along += e.along_output(th, ds, ctx)
        if type(e).dynamics is not Effect.dynamics:
            dyn_effects.append((e, th))
    preds = {"lateral": lat}
    if ds.has_gyro:
        preds["heading_rate"] = hr
    if ds.has_commands:
        a, b, c0 = (float(x) for x in f.base)
        cmd = np.nan_to_num(ds.cmd_surge)
        along = np.full(n, np.nan)
        dt = ds.dt
        for seg in _segments(ds):
            i0 = seg[0]
            u = float(ds.along[i0] - out_along[i0])
            for i in seg:
                along[i] = u
                du = -a * u + b * cmd[i] + c0
                for e, th in dyn_effects:
                    du += e.dynamics(th, u, i, ds)
                u += dt * du
                if not math.isfinite(u) or abs(u) > 50.0:
                    u = float("nan")
            if delay > 0.0:
                ts = ds.t[seg]
                along[seg] = np.interp(ts - delay, ts, along[seg])
            along[seg] += out_along[seg]
        preds["along"] = along
    return preds


def residuals(ds: Dataset, f: Fit) -> dict[str, np.ndarray]:
    """Measured minus predicted, per channel (along: open-loop speed error, m/s)."""
    p = predict(ds, f)
    out = {"lateral": ds.lateral - p["lateral"]}
    if "heading_rate" in p:
        out["heading_rate"] = (ds.psi_dot - ds.r) - p["heading_rate"]
    if "along" in p:
        out["along"] = ds.along - p["along"]
    return out


def rms(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(math.sqrt(np.mean(x**2))) if len(x) else float("nan")


@dataclass
class Score:
    """Held-out errors: per channel RMS and the headline metric."""

    channels: dict[str, float]
    headline: float
    metric: str
    extra: dict = field(default_factory=dict)


def score(ds: Dataset, f: Fit, metric: str) -> Score:
    """Held-out error of ``f`` on ``ds`` under ``metric`` (see :func:`metric_name`)."""
    res = residuals(ds, f)
    ch = {k: rms(v) for k, v in res.items()}
    if metric == "surge_speed_open_loop_rmse_mps":
        head = ch.get("along", float("nan"))
    elif metric == "ground_velocity_rmse_mps":
        e2 = res["lateral"] ** 2 + res["along"] ** 2
        head = float(math.sqrt(np.nanmean(e2)))
    else:
        head = ch["lateral"]
    return Score(channels=ch, headline=head, metric=metric)


def metric_name(ds: Dataset, requested: str | None = None) -> str:
    """The held-out metric: ``surge_speed_open_loop_rmse_mps`` (open-loop prediction of the
    surge speed from the commands), ``ground_velocity_rmse_mps`` (open-loop along-track
    plus lateral velocity over ground) or, without commands, ``lateral_velocity_rmse_mps``."""
    if requested:
        return requested
    return "ground_velocity_rmse_mps" if ds.has_commands else "lateral_velocity_rmse_mps"
