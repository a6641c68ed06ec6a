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
from onboard.closure import stats
from onboard.closure.dataset import Dataset
from onboard.closure.effects import ALL, Context


@dataclass
class Split:
    fit: Dataset
    holdout: Dataset
    how: str


def split(ds: Dataset, block_s: float = 60.0) -> Split:
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
    name: str
    score: float
    gain: float
    t_max: float
    headline: float
    physical: bool = True
    accepted: bool = False


@dataclass
class Selection:
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
           min_gain: float = 0.03, min_t: float = 4.0, penalty: float = 2.0,
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
    # A wave period from the residual spectrum, for the wave effect's regressors.
    res_fit = M.residuals(sp.fit, base)
    wave = None
    best = (None, 1.0, 0.0)
    for ch in ("lateral", "along"):
        if ch in res_fit:
            period, p, g = stats.spectral_peak(sp.fit.t, res_fit[ch])
            if period is not None and p < best[1]:
                best = (period, p, g)
    if best[0] is not None and best[1] < 1e-6:
        ctx.wave_period_s = _refine_period(sp.fit, best[0])
        wave = {"period": ctx.wave_period_s, "periodogram_period": best[0],
                "false_alarm_p": best[1], "power_share": best[2]}
    base = M.fit(sp.fit, declared, sigma, ctx, known=known)
    before = M.score(sp.holdout, base, metric)
    n_eff = max(10.0, len(sp.holdout) * ds.dt / 2.0)

    pool = [n for n in (candidates or tuple(ALL)) if n not in declared
            and ALL[n].applies(sp.fit, ctx)]
    chosen: list[str] = []
    current_fit, current_rel = base, 1.0
    rounds: list[list[Candidate]] = []
    while pool:
        round_: list[Candidate] = []
        for name in pool:
            f = M.fit(sp.fit, (*declared, *chosen, name), sigma, ctx, known=known)
            s = M.score(sp.holdout, f, metric)
            k = sum(len(ALL[e].params) for e in (*chosen, name))
            rel = _relative(s, before) * math.exp(penalty * k / n_eff)
            t = f.theta[name] / np.where(f.std[name] > 0, f.std[name], np.inf)
            cand = Candidate(name, rel, 1.0 - rel / current_rel, float(np.max(np.abs(t))),
                             s.headline, physical=ALL[name].physical(f.theta[name]))
            round_.append(cand)
        round_.sort(key=lambda c: c.score)
        rounds.append(round_)
        usable = [c for c in round_ if c.physical]
        if not usable:
            break
        top = usable[0]
        if top.gain >= min_gain and top.t_max >= min_t:
            top.accepted = True
            chosen.append(top.name)
            pool.remove(top.name)
            current_fit = M.fit(sp.fit, (*declared, *chosen), sigma, ctx, known=known)
            current_rel = top.score
        else:
            break
    after = M.score(sp.holdout, current_fit, metric)
    sel = Selection(split=sp, metric=metric, declared=tuple(declared), chosen=tuple(chosen),
                    base_fit=base, final_fit=current_fit, before=before, after=after,
                    rounds=rounds, wave=wave)
    sel.unexplained = structure_left(sp, current_fit)
    return sel


def _refine_period(ds: Dataset, period: float) -> float:
    """The period near the periodogram's peak that best fits the earth-frame wave model
    in the lateral channel (the heading modulates the projected oscillation, which biases
    the raw peak)."""
    wave = ALL["wave_oscillation"]
    y = ds.lateral - np.nanmean(ds.lateral)
    ok = np.isfinite(y)
    best, best_cost = period, math.inf
    for p in period * np.linspace(0.9, 1.1, 161):
        X = wave.columns(ds, Context(wave_period_s=float(p)))["lateral"][ok]
        coef, *_ = np.linalg.lstsq(X, y[ok], rcond=None)
        cost = float(np.mean((y[ok] - X @ coef) ** 2))
        if cost < best_cost:
            best, best_cost = float(p), cost
    return best


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
