"""The base vehicle model, its augmentation by effects, fitting and open-loop prediction.

Base model (what the AIE and current pipelines assume, plus what every hull does): the
vehicle moves along its measured heading but for the hull's sway in turns, which builds up
behind the turn rate (lateral velocity ``x_p r + x_pd r' + k_ur U r + k_urd (U r)'``:
``x_p`` the sway per yaw rate, ``x_pd = -x_p T_v`` the course lag of a sway that follows
``x_p r`` with time constant ``T_v``, and, switched on where wanted, ``k_ur`` the drift
out of a turn that scales with speed times yaw rate on a hull whose sway damping does
not grow with speed and ``k_urd`` its lag;
:func:`onboard.offline.closure.dataset.lateral_base_columns`); the measured heading turns with
the gyro (heading change minus integrated gyro 0); and its through-water speed follows the first-order surge model of algorithms.md §1.1, ``U' = -a U + b c +
c0``, from the normalized command ``c`` as the propeller applies it: through the shaft's
first-order lag, whose time constant is found once per log (:func:`estimate_actuator_lag`,
applied to the data by :func:`onboard.offline.closure.dataset.lag_commands`). The shaft lag, the
course lag and the speed drift are switched by
:func:`onboard.offline.closure.dataset.with_base_terms` (default: shaft lag and course lag).
Effects add linear regressors to those channels (:mod:`.effects`). All parameters enter
linearly once ``a`` and ``b`` are fixed, so a fit is a weighted least-squares problem over
the stacked channels, iterated to refresh ``a`` and ``b``.

A glider's base model (:mod:`onboard.offline.closure.base_models`) keeps the lateral and
heading channels and replaces the surge model: its along-track velocity over ground is
the through-water speed of the steady glide (``Dataset.u_model``) plus the effects' terms,
algebraic (no open-loop simulation, no commands).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from onboard.offline.closure.dataset import (
    Dataset,
    heading_drift,
    lag_commands,
    lateral_base_columns,
    lateral_base_names,
)
from onboard.offline.closure.effects import ALL, Context, Effect

CHANNELS = ("lateral", "heading", "along")
BASE_PARAMS = ("a", "b", "c0")


def channel_targets(ds: Dataset) -> dict[str, np.ndarray]:
    """The measured quantity each channel's regression explains (a glider's along-track
    channel: the velocity over ground along the heading minus the glide's speed, m/s)."""
    out = {"lateral": ds.lateral}
    if ds.has_gyro:
        out["heading"] = heading_drift(ds)
    if ds.has_commands:
        out["along"] = ds.speed_dot
    elif ds.u_model is not None:
        out["along"] = ds.along - ds.u_model
    return out


def along_base_output(ds: Dataset, f: "Fit") -> np.ndarray:
    """The base model's term of the along-track channel as :func:`channel_targets` states
    it: the surge model's acceleration (m/s^2) with commands; 0 for a glider, whose
    glide speed the target already holds."""
    if ds.has_commands:
        return _base_columns(ds) @ f.base
    return np.zeros(len(ds))


def lateral_base_output(ds: Dataset, f: "Fit") -> np.ndarray:
    """The base model's lateral velocity (m/s) on ``ds`` for the fit ``f``: the hull's
    sway in turns (:func:`onboard.offline.closure.dataset.lateral_base_columns`)."""
    names = lateral_base_names(ds)
    return lateral_base_columns(ds) @ np.array([f.lateral_params.get(n, 0.0) for n in names])


def estimate_actuator_lag(ds: Dataset, max_s: float = 1.5) -> float:
    """The shaft lag (s) that best explains the surge channel: for each candidate time
    constant on a grid of the tick interval up to ``max_s``, the commands are lagged
    (:func:`lag_commands`) and the along-track acceleration regressed on
    ``[-U, -U|U|, c, c|c|, min(c, 0), 1]`` (the surge model with the catalog's drag and
    thrust-law terms, so that an unmodelled nonlinearity does not pose as a lag); the
    least residual wins, refined by a parabola through its neighbours. 0 without
    commands, or when ``ds`` is to be fitted without the ``actuator_lag`` term.

    The speed is measured by the GNSS, so a GNSS latency would pose as shaft lag: where
    the log has an accelerometer, the GNSS delay it shows (:meth:`GpsLatency.search
    <onboard.offline.closure.effects.gps_latency.GpsLatency.search>`, no hull model) is taken out
    of the velocity first."""
    if not ds.has_commands or len(ds) < 100 or "actuator_lag" not in ds.base_terms:
        return 0.0
    if ds.acc_x is not None:
        late = ALL["gps_latency"].search(ds)
        if late is not None:
            ds = ALL["gps_latency"].transform(ds, late[0])
    taus = np.arange(0.0, max_s + 1e-9, max(ds.dt, 0.05))
    u = ds.along_s
    y = ds.speed_dot
    cost = []
    for tau in taus:
        d = lag_commands(ds, float(tau))
        c = np.nan_to_num(d.cmd_surge)
        X = np.column_stack([-u, -u * np.abs(u), c, np.nan_to_num(d.thrust_quadratic),
                             np.nan_to_num(d.thrust_reverse), np.ones(len(ds))])
        ok = np.isfinite(y) & np.isfinite(X).all(axis=1)
        coef, *_ = np.linalg.lstsq(X[ok], y[ok], rcond=None)
        cost.append(float(np.mean((y[ok] - X[ok] @ coef) ** 2)))
    cost = np.asarray(cost)
    i = int(np.argmin(cost))
    tau = float(taus[i])
    if 0 < i < len(taus) - 1:
        c2, c1, _ = np.polyfit(taus[i - 1:i + 2], cost[i - 1:i + 2], 2)
        if c2 > 0:
            tau = float(np.clip(-c1 / (2 * c2), taus[i - 1], taus[i + 1]))
    return tau


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
    lateral_params: dict[str, float] = field(default_factory=dict)
    """The base model's lateral coefficients by name
    (:func:`onboard.offline.closure.dataset.lateral_base_names`: ``x_p`` m, ``x_pd`` m s, ``k_ur``
    s, ``k_urd`` s^2); the terms switched off are absent."""
    known: dict[str, np.ndarray] = field(default_factory=dict)
    """Effects with known, fixed parameters (from a calm-water calibration, say)."""

    @property
    def x_p(self) -> float:
        """Hull sway per yaw rate (m): the base model's lateral velocity ``x_p r`` in turns."""
        return self.lateral_params.get("x_p", 0.0)

    @property
    def x_pd(self) -> float:
        """Course lag of the sway (m s): the base model's lateral term ``x_pd r'``."""
        return self.lateral_params.get("x_pd", 0.0)

    def all_effects(self) -> list[tuple[Effect, np.ndarray]]:
        """Known and fitted effects with their parameters."""
        return [(ALL[n], th) for n, th in self.known.items()] + [
            (ALL[n], self.theta[n]) for n in self.effects]

    def effect(self, name: str) -> Effect:
        """The effect of the vocabulary called ``name``."""
        return ALL[name]


def _decorrelation(ds: Dataset, seconds: float = 2.0) -> float:
    """Variance inflation for correlated residuals: ticks per independent sample."""
    return max(1.0, seconds / ds.dt)


def fit(ds: Dataset, effects: tuple[str, ...], sigma: dict[str, float],
        ctx: Context | None = None, output_error: bool = True,
        known: dict[str, np.ndarray] | None = None) -> Fit:
    """Weighted least squares of the base model plus ``effects`` on ``ds``.

    ``sigma`` gives each channel's noise scale (its rows are divided by it), so channels
    in different units weigh alike. With ``output_error`` the surge parameters are then
    refined to minimise the open-loop speed error (:func:`refine_output_error`).
    """
    ctx = Context(**vars(ctx)) if ctx is not None else Context()
    known = dict(known or {})
    targets = channel_targets(ds)
    n = len(ds)
    base = np.array([ctx.a, ctx.b, 0.0])
    lat_names = lateral_base_names(ds)
    lat_params: dict[str, float] = {}
    theta: dict[str, np.ndarray] = {}
    std: dict[str, np.ndarray] = {}
    for _ in range(8 if ds.has_commands else 1):
        a_prev = ctx.a
        blocks, ys = [], []
        layout: list[tuple[str, int]] = []
        if ds.has_commands:
            layout.append(("__base__", 3))
        layout.append(("__pivot__", len(lat_names)))
        for name in effects:
            layout.append((name, len(ALL[name].params)))
        n_par = sum(k for _, k in layout)
        cols_cache = {name: ALL[name].columns(ds, ctx) for name in effects}
        known_cols = {name: ALL[name].columns(ds, ctx) for name in known}
        pivot = lateral_base_columns(ds)
        for ch, y in targets.items():
            for name, th in known.items():
                c = known_cols[name].get(ch)
                if c is not None:
                    y = y - c @ th
            X = np.zeros((n, n_par))
            j = 0
            for name, k in layout:
                if name == "__base__":
                    if ch == "along":
                        X[:, j:j + k] = _base_columns(ds)
                elif name == "__pivot__":
                    if ch == "lateral":
                        X[:, j:j + k] = pivot
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
            elif name == "__pivot__":
                lat_params = {nm: float(v) for nm, v in zip(lat_names, sol[j:j + k])}
            else:
                theta[name] = sol[j:j + k].copy()
                std[name] = sd[j:j + k].copy()
            j += k
        if abs(ctx.a - a_prev) < 1e-4 * max(1.0, abs(ctx.a)):
            break
    f = Fit(effects=tuple(effects), base=base, theta=theta, std=std, ctx=ctx,
            sigma=dict(sigma), n=n, lateral_params=lat_params, known=known)
    if output_error and ds.has_commands:
        f = refine_output_error(ds, f)
    return f


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


def _surge_inputs(ds: Dataset, base: np.ndarray, dyn: list[tuple[Effect, np.ndarray]]):
    """Per-tick forcing ``f`` (m/s^2), linear damping ``k`` (1/s) and quadratic drag ``d``
    (1/m) of ``U' = -k U - d U|U| + f`` for the base model plus dynamic effects."""
    a, b, c0 = (float(x) for x in base)
    f = b * np.nan_to_num(ds.cmd_surge) + c0
    k = np.full(len(ds), a)
    d = 0.0
    for e, th in dyn:
        fe, ke, de = e.surge_terms(th, ds)
        if fe is not None:
            f = f + fe
        if ke is not None:
            k = k + ke
        d += de
    return f, k, d


def simulate_speed(ds: Dataset, base: np.ndarray, dyn: list[tuple[Effect, np.ndarray]],
                   u0_offset: np.ndarray | None = None) -> np.ndarray:
    """Open-loop through-water speed (m/s) from the commands, restarted from the measured
    along-track speed (minus ``u0_offset``, the kinematic effects' part) at the start of
    each contiguous segment. Forward Euler at the tick rate (dt <= 0.1 s against time
    constants of seconds)."""
    f, k, d = _surge_inputs(ds, base, dyn)
    f, k = f.tolist(), k.tolist()
    dt = ds.dt
    out = [0.0] * len(ds)
    along = ds.along
    for seg in _segments(ds):
        i0, i1 = int(seg[0]), int(seg[-1]) + 1
        u = float(along[i0] - (u0_offset[i0] if u0_offset is not None else 0.0))
        for i in range(i0, i1):
            out[i] = u
            u += dt * (f[i] - k[i] * u - d * u * abs(u))
            if not -50.0 < u < 50.0:
                u = math.nan
    return np.asarray(out)


def predict(ds: Dataset, f: Fit) -> dict[str, np.ndarray]:
    """Model predictions of each channel on ``ds``; the along-track speed open loop.

    ``along`` is the predicted along-track speed over ground (m/s), simulated from the
    commands from the measured speed at the start of each contiguous segment (a glider's:
    its glide speed plus the effects' terms); the other channels are algebraic.
    """
    n = len(ds)
    ctx = f.ctx
    lat = lateral_base_output(ds, f)
    hr = np.zeros(n)
    out_along = np.zeros(n)
    dyn = []
    delay = 0.0
    for e, th in f.all_effects():
        lat = lat + e.lateral_output(th, ds, ctx)
        hr += e.heading_output(th, ds, ctx)
        out_along += e.along_output(th, ds, ctx)
        delay += e.output_delay_s(th)
        if e.dynamic:
            dyn.append((e, th))
    preds = {"lateral": lat}
    if ds.has_gyro:
        preds["heading"] = hr
    if ds.has_commands:
        along = simulate_speed(ds, f.base, dyn, out_along)
        if delay > 0.0:
            for seg in _segments(ds):
                ts = ds.t[seg]
                along[seg] = np.interp(ts - delay, ts, along[seg])
        preds["along"] = along + out_along
    elif ds.u_model is not None:
        preds["along"] = ds.u_model + out_along
    return preds


def refine_output_error(ds: Dataset, f: Fit, max_nfev: int = 30) -> Fit:
    """Refit the surge parameters (base and dynamic effects) to minimise the open-loop
    along-track speed error, the quantity the held-out metric measures; the equation-error
    solution is the starting point. Kinematic effects stay as fitted."""
    from scipy.optimize import least_squares

    dyn_names = [n for n in f.effects if ALL[n].dynamic]
    sizes = [len(f.theta[n]) for n in dyn_names]
    p0 = np.concatenate([f.base, *[f.theta[n] for n in dyn_names]])
    out_along = np.zeros(len(ds))
    delay = 0.0
    fixed_dyn = [(ALL[n], th) for n, th in f.known.items() if ALL[n].dynamic]
    for e, th in f.all_effects():
        out_along += e.along_output(th, ds, f.ctx)
        delay += e.output_delay_s(th)
    target = ds.along - out_along
    segs = _segments(ds) if delay > 0 else []

    def unpack(p):
        dyn, j = list(fixed_dyn), 3
        for n, k in zip(dyn_names, sizes):
            dyn.append((ALL[n], p[j:j + k]))
            j += k
        return p[:3], dyn

    def resid(p):
        base, dyn = unpack(p)
        u = simulate_speed(ds, base, dyn, out_along)
        for seg in segs:
            ts = ds.t[seg]
            u[seg] = np.interp(ts - delay, ts, u[seg])
        r = u - target
        return np.where(np.isfinite(r), r, 10.0)

    try:
        sol = least_squares(resid, p0, x_scale="jac", max_nfev=max_nfev)
    except ValueError:
        return f
    if not np.all(np.isfinite(sol.x)) or sol.cost > 0.5 * float(resid(p0) @ resid(p0)):
        return f
    base, dyn = unpack(sol.x)
    theta, std = dict(f.theta), dict(f.std)
    try:
        s2 = 2.0 * sol.cost / max(1, len(ds) - len(p0))
        cov = np.linalg.pinv(sol.jac.T @ sol.jac) * s2 * _decorrelation(ds)
        sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        sd = np.full(len(p0), np.inf)
    j = 3
    for n, k in zip(dyn_names, sizes):
        theta[n] = sol.x[j:j + k].copy()
        std[n] = sd[j:j + k].copy()
        j += k
    ctx = Context(**vars(f.ctx))
    return Fit(effects=f.effects, base=np.asarray(base, float).copy(), theta=theta, std=std,
               ctx=ctx, sigma=f.sigma, n=f.n, lateral_params=dict(f.lateral_params),
               known=f.known)


def residuals(ds: Dataset, f: Fit) -> dict[str, np.ndarray]:
    """Measured minus predicted, per channel (along: open-loop speed error, m/s)."""
    p = predict(ds, f)
    out = {"lateral": ds.lateral - p["lateral"]}
    if "heading" in p:
        out["heading"] = heading_drift(ds) - p["heading"]
    if "along" in p:
        out["along"] = ds.along - p["along"]
    return out


def rms(x: np.ndarray) -> float:
    """Root mean square of the finite entries of ``x``; NaN when there are none."""
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
    plus lateral velocity over ground; a glider's along-track speed is its glide's) or,
    without commands or a glide, ``lateral_velocity_rmse_mps``."""
    if requested:
        return requested
    has_along = ds.has_commands or ds.u_model is not None
    return "ground_velocity_rmse_mps" if has_along else "lateral_velocity_rmse_mps"
