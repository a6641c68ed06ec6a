"""Selection of effects by held-out error with a complexity penalty.

1. Split the data: by run when the log has several runs (a directory of CSV runs), else in
   interleaved blocks of ``block_s`` seconds, every third one held out.
2. Fit the base model (plus declared effects) on the fit part; its residual noise scale per
   channel fixes the channel weights for every later fit, so scores are comparable.
3. Greedy forward selection: try each remaining effect, score it on the held-out part
   (geometric mean over channels of held-out MSE relative to the base model's, times
   ``exp(penalty * k / n_eff)`` for k parameters and n_eff independent samples), keep the
   best if it lowers the score by at least ``min_gain`` and one of its parameters is at
   least ``min_t`` standard errors from zero and its parameters are physical (no negative
   latency or drag). Repeat until nothing is kept.
4. ``unexplained``: if a held-out residual is still structured (a generic basis of heading
   harmonics, speed, turn rate, commands and time predicts it on held-out data) the
   residual is reported as unexplained rather than forced onto the nearest name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from onboard.closure import model as M
from onboard.closure.dataset import Dataset
from onboard.closure.effects import ALL, Context


@dataclass
class Split:
    """Data to fit on, data to score on (held out), and how they were split."""

    fit: Dataset
    holdout: Dataset
    how: str


def split(ds: Dataset, block_s: float = 60.0) -> Split:
    """Fit and held-out data: by run when there are at least three runs (every third
    held out), else interleaved blocks of ``block_s`` seconds (every third held out)."""
    runs = [r.split("#")[0] for r in ds.run]
    names = sorted(set(runs))
    if len(names) >= 3:
        held = set(names[1::3])
        mask = np.array([r in held for r in runs])
        return Split(ds.subset(~mask), ds.subset(mask),
                     f"by run: {len(names) - len(held)} fit, {len(held)} held out ({', '.join(sorted(held))})")
    block = np.floor((ds.t - ds.t[0]) / block_s).astype(int)
    mask = block % 3 == 2
    labels = np.array([f"{r}@{b}" for r, b in zip(ds.run, block)], dtype=object)
    ds2 = Dataset(**{**vars(ds), "run": labels})
    return Split(ds2.subset(~mask), ds2.subset(mask),
                 f"interleaved {block_s:.0f} s blocks, every third held out")


@dataclass
class Candidate:
    """One effect tried in one selection round: its relative held-out ``score`` (lower is
    better), ``gain`` over the model before the round, largest parameter ``t_max`` in
    standard errors, held-out ``headline`` error, whether its fit is ``physical`` and was
    ``accepted``, and for a data transform its ``value`` and one sigma."""

    name: str
    score: float
    gain: float
    t_max: float
    headline: float
    physical: bool = True
    accepted: bool = False
    value: tuple[float, float] | None = None
    alternatives: tuple[str, ...] = ()
    """Other candidates of the same round whose held-out score is within 25 % of the
    chosen one's (about 12 % in RMS error): effects these data cannot tell apart."""


@dataclass
class Selection:
    """The outcome of :func:`select`: the split, the metric, the declared and chosen
    effects, the base and final fits with their held-out scores, every round's
    candidates, an ``unexplained`` residual structure, the wave found in the residual,
    and the values of the effects applied to the data (``transformed``)."""

    split: Split
    metric: str
    declared: tuple[str, ...]
    chosen: tuple[str, ...]
    base_fit: M.Fit
    final_fit: M.Fit
    before: M.Score
    after: M.Score
    rounds: list[list[Candidate]] = field(default_factory=list)
    unexplained: dict | None = None
    wave: dict | None = None
    final_split: Split | None = None
    """The data the final model was fitted and scored on (re-aligned by a latency)."""
    transformed: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Data-transforming effects chosen: name -> (value, one-sigma)."""


def _sigma(ds: Dataset, f: M.Fit) -> dict[str, float]:
    """Robust noise scale per channel (derivative-form for the along channel)."""
    targets = M.channel_targets(ds)
    out = {}
    for ch, y in targets.items():
        pred = np.zeros(len(ds))
        if ch == "along":
            pred = M._base_columns(ds) @ f.base
        elif ch == "lateral":
            pred = f.x_p * ds.r
        r = y - pred
        r = r[np.isfinite(r)]
        mad = float(np.median(np.abs(r - np.median(r)))) * 1.4826 if len(r) else 1.0
        out[ch] = mad if mad > 1e-9 else 1.0
    return out


def _relative(s: M.Score, ref: M.Score) -> float:
    """Geometric mean over channels of held-out MSE relative to the base model's: a large
    relative gain in one channel counts even where another channel is noise-dominated
    (the log-likelihood of independent Gaussian channels)."""
    vals = [2.0 * math.log(s.channels[c] / ref.channels[c]) for c in ref.channels
            if c in s.channels and ref.channels[c] > 0 and s.channels[c] > 0
            and math.isfinite(s.channels[c])]
    return float(math.exp(np.mean(vals))) if vals else math.inf


def select(ds: Dataset, *, declared: tuple[str, ...] = (), metric: str | None = None,
           min_gain: float = 0.05, min_t: float = 4.0, penalty: float = 2.0,
           candidates: tuple[str, ...] | None = None,
           known: dict[str, np.ndarray] | None = None) -> Selection:
    """Choose the effects that explain the base model's held-out residuals (module doc).

    ``declared`` effects are fitted as part of the model from the start; ``known`` effects
    are part of it with fixed parameters (a calm-water calibration) and may still be found
    again as candidates, for the part the calibration does not cover.
    """
    sp = split(ds)
    known = {k: np.asarray(v, float) for k, v in (known or {}).items()}
    metric = M.metric_name(ds, metric)
    ctx = Context()
    base0 = M.fit(sp.fit, declared, {}, ctx, output_error=False, known=known)
    sigma = _sigma(sp.fit, base0)
    base = M.fit(sp.fit, declared, sigma, base0.ctx, known=known)
    ctx = base.ctx
    # A wave (period, direction) from the residual, for the wave effect's regressors.
    res_fit = M.residuals(sp.fit, base)
    wave = find_wave(sp.fit, res_fit["lateral"])
    if wave is not None:
        ctx.wave_period_s = wave["period"]
        ctx.extra["wave_direction"] = wave["direction"]
    base = M.fit(sp.fit, declared, sigma, ctx, known=known)
    before = M.score(sp.holdout, base, metric)
    n_eff = max(10.0, len(sp.holdout) * ds.dt / 2.0)

    pool = [n for n in (candidates or tuple(ALL)) if n not in declared
            and ALL[n].applies(sp.fit, ctx)]
    chosen: list[str] = []
    transformed: dict[str, tuple[float, float]] = {}
    fit_data, hold_data = sp.fit, sp.holdout
    current_fit, current_rel = base, 1.0
    rounds: list[list[Candidate]] = []

    def model_effects(names):
        return tuple(n for n in names if not ALL[n].transforms_data)

    while pool:
        round_: list[Candidate] = []
        trials: dict[str, tuple[Dataset, Dataset]] = {}
        for name in pool:
            e = ALL[name]
            fd, hd = fit_data, hold_data
            if e.transforms_data:
                found = e.search(fit_data)
                if found is None:
                    continue
                value, value_std = found
                fd, hd = e.transform(fit_data, value), e.transform(hold_data, value)
                trials[name] = (fd, hd)
                theta, std = np.array([value]), np.array([value_std])
                f = M.fit(fd, model_effects((*declared, *chosen)), sigma, ctx, known=known)
            else:
                f = M.fit(fd, model_effects((*declared, *chosen, name)), sigma, ctx, known=known)
                theta, std = f.theta[name], f.std[name]
            s = M.score(hd, f, metric)
            k = sum(len(ALL[x].params) for x in (*chosen, name))
            rel = _relative(s, before) * math.exp(penalty * k / n_eff)
            t = theta / np.where(std > 0, std, np.inf)
            cand = Candidate(name, rel, 1.0 - rel / current_rel, float(np.max(np.abs(t))),
                             s.headline, physical=e.physical(theta))
            if e.transforms_data:
                cand.value = (float(theta[0]), float(std[0]))
            round_.append(cand)
        round_.sort(key=lambda c: c.score)
        rounds.append(round_)
        usable = [c for c in round_ if c.physical]
        if not usable:
            break
        top = usable[0]
        if top.gain >= min_gain and top.t_max >= min_t:
            top.accepted = True
            top.alternatives = tuple(c.name for c in usable[1:] if c.score <= 1.25 * top.score)
            chosen.append(top.name)
            pool.remove(top.name)
            if top.name in trials:
                fit_data, hold_data = trials[top.name]
                transformed[top.name] = top.value
            current_fit = M.fit(fit_data, model_effects((*declared, *chosen)), sigma, ctx,
                                known=known)
            current_rel = top.score
        else:
            break
    final_split = Split(fit_data, hold_data, sp.how)
    after = M.score(hold_data, current_fit, metric)
    sel = Selection(split=sp, metric=metric, declared=tuple(declared), chosen=tuple(chosen),
                    base_fit=base, final_fit=current_fit, before=before, after=after,
                    rounds=rounds, wave=wave, final_split=final_split, transformed=transformed)
    sel.unexplained = structure_left(final_split, current_fit)
    return sel


def find_wave(ds: Dataset, residual: np.ndarray, min_period_s: float = 2.0,
              max_period_s: float = 15.0, max_p: float = 1e-6) -> dict | None:
    """The regular wave (period, direction) that best explains a lateral residual, or
    None if no wave is significant.

    A grid search: for each period (log-spaced) and direction, the earth-frame wave
    regressors of :mod:`.effects.wave_oscillation` are fitted to the residual and the
    explained share of variance kept; the best cell is refined on a finer grid. The
    false-alarm probability uses one effective sample per second and the number of
    cells searched, and the share must be 20 times the median share, so a coloured
    residual is not taken for a wave.
    """
    wave = ALL["wave_oscillation"]
    y = np.asarray(residual, float)
    ok = np.isfinite(y)
    if ok.sum() < 200 or np.ptp(ds.t) < 10 * max_period_s:
        return None
    y = y[ok] - y[ok].mean()
    total = float(y @ y)
    if total <= 0:
        return None
    has_pos = bool(np.isfinite(ds.north).any())
    directions = np.linspace(0.0, 2 * np.pi, 24, endpoint=False) if has_pos else [0.0]

    def share(period: float, direction: float) -> float:
        ctx = Context(wave_period_s=float(period), extra={"wave_direction": float(direction)})
        X = wave.columns(ds, ctx)["lateral"][ok]
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        return 1.0 - float(np.sum((y - X @ coef) ** 2)) / total

    periods = np.geomspace(min_period_s, max_period_s, 120)
    grid = np.array([[share(p, d) for d in directions] for p in periods])
    i, j = np.unravel_index(int(np.argmax(grid)), grid.shape)
    best = (float(grid[i, j]), float(periods[i]), float(directions[j]))
    for p in periods[i] * np.linspace(0.97, 1.03, 25):
        for d in directions[j] + np.linspace(-0.15, 0.15, 7 if has_pos else 1):
            sh = share(p, d)
            if sh > best[0]:
                best = (sh, float(p), float(d % (2 * np.pi)))
    sh, period, direction = best
    n_eff = max(8.0, float(np.ptp(ds.t)))
    fap = min(1.0, grid.size * (1.0 - sh) ** ((n_eff - 5) / 2))
    if sh < 20.0 * float(np.median(grid)) or fap > max_p:
        return None
    return {"period": period, "direction": direction, "share": sh, "false_alarm_p": fap}


def _generic_basis(ds: Dataset) -> tuple[np.ndarray, list[str]]:
    cols, names = [], []
    for k in (1, 2, 3):
        cols += [np.cos(k * ds.psi), np.sin(k * ds.psi)]
        names += [f"cos({k} heading)", f"sin({k} heading)"]
    cols += [ds.along, ds.r, ds.r**2, (ds.t - ds.t.mean()) / max(1.0, np.ptp(ds.t))]
    names += ["speed", "yaw rate", "yaw rate^2", "time"]
    if ds.has_commands:
        cols += [np.nan_to_num(ds.cmd_surge), np.nan_to_num(ds.cmd_yaw)]
        names += ["surge command", "yaw command"]
    cols.append(np.ones(len(ds)))
    names.append("constant")
    return np.column_stack(cols), names


def structure_left(sp: Split, f: M.Fit, min_gain: float = 0.15) -> dict | None:
    """Evidence of structure the chosen effects do not explain, or None.

    A generic basis fitted to the fit-part residual must lower the held-out residual's
    mean square by ``min_gain`` in some channel to count.
    """
    res_fit = M.residuals(sp.fit, f)
    res_hold = M.residuals(sp.holdout, f)
    Xf, names = _generic_basis(sp.fit)
    Xh, _ = _generic_basis(sp.holdout)
    found = {}
    for ch in res_fit:
        if ch != "lateral":
            continue  # along: open-loop drift, judged by the metric; heading: integrated
        yf, yh = res_fit[ch], res_hold[ch]
        okf = np.isfinite(yf) & np.isfinite(Xf).all(1)
        okh = np.isfinite(yh) & np.isfinite(Xh).all(1)
        if okf.sum() < 50 or okh.sum() < 50:
            continue
        coef, *_ = np.linalg.lstsq(Xf[okf], yf[okf], rcond=None)
        before = float(np.mean(yh[okh] ** 2))
        after = float(np.mean((yh[okh] - Xh[okh] @ coef) ** 2))
        gain = 1.0 - after / before if before > 0 else 0.0
        if gain >= min_gain:
            scale = np.std(Xf[okf], axis=0) * np.abs(coef)
            top = [names[i] for i in np.argsort(scale)[::-1][:3] if names[i] != "constant"]
            found[ch] = {"held_out_gain": round(gain, 3), "correlates_with": top}
    return found or None
