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

from onboard.offline.closure import drift
from onboard.offline.closure import model as M
from onboard.offline.closure.dataset import (MIN_DATA_S, Dataset, NotEnoughData, concat, lag_commands,
                                     segment_starts, too_short)
from onboard.offline.closure.effects import ALL, Context
from onboard.offline.closure.effects import actuator_mapping as am


@dataclass
class Split:
    """The three parts of the data: ``fit`` (parameters are estimated on it), ``holdout``
    (the selection part: effects are chosen by their error on it) and ``test`` (the final
    score only: never used to fit or to choose), with ``how`` in words and ``parts``, which
    runs or time ranges went where (for diagnosis.json)."""

    fit: Dataset
    holdout: Dataset
    how: str
    test: Dataset | None = None
    parts: dict = field(default_factory=dict)


def _time_ranges(ds: Dataset) -> list[list[float]]:
    """[start, end] (s since the log's first tick) of each contiguous segment of ``ds``."""
    out = []
    if len(ds) == 0:
        return out
    change = np.flatnonzero(ds.run[1:] != ds.run[:-1]) + 1
    for a, b in zip(np.r_[0, change], np.r_[change, len(ds)]):
        out.append([float(ds.t[a]), float(ds.t[b - 1])])
    return out


def _part_summary(ds: Dataset, t0: float, runs: list[str] | None = None) -> dict:
    ranges = [[round(a - t0, 2), round(b - t0, 2)] for a, b in _time_ranges(ds)]
    merged: list[list[float]] = []
    for a, b in ranges:  # adjacent blocks of one part read as one range
        if merged and a - merged[-1][1] <= 2.5 * ds.dt:
            merged[-1][1] = b
        else:
            merged.append([a, b])
    out = {"samples": len(ds), "seconds": round(len(ds) * ds.dt, 1), "time_ranges_s": merged}
    if runs is not None:
        out["runs"] = runs
    return out


MIN_PART_S = 10.0
"""Least data (s, ticks times the tick interval) in each of the fit, selection and test
parts: at the default 10 Hz, 100 ticks. A shorter part is no test of anything:
:func:`split` shrinks its blocks to reach it, and refuses the log when it cannot."""


def split(ds: Dataset, block_s: float = 60.0, test_share: float = 0.2) -> Split:
    """Fit, selection and test parts.

    * At least three runs (a directory of runs): every third run, from the third, is the
      test part; of the others every third, from the second, the selection part; the rest
      are fitted on.
    * One run: the last ``test_share`` of the time span is the test part (forward in time:
      the model is scored on what came after everything it saw); before it, interleaved
      ``block_s`` blocks, every third for selection, the others fitted on. When that
      leaves the selection part shorter than :data:`MIN_PART_S` (a log of less than
      about 160 s at 60 s blocks) the blocks shrink to a third of the time before the
      test part.

    Blocks get their own run labels, so open-loop predictions restart at each. A log
    with less than :data:`onboard.offline.closure.dataset.MIN_DATA_S` of data, or too gappy to
    give every part :data:`MIN_PART_S`, is a :class:`onboard.offline.closure.dataset.NotEnoughData`.
    """
    if _seconds(ds) < MIN_DATA_S:
        raise NotEnoughData(too_short(ds.source or "log", _seconds(ds)))
    sp = _split(ds, block_s, test_share)
    if sp.parts["method"] == "forward_in_time" and _seconds(sp.holdout) < MIN_PART_S:
        before_test = (1.0 - test_share) * float(ds.t[-1] - ds.t[0])
        sp = _split(ds, before_test / 3.0, test_share)
    _require_parts(ds, sp)
    return sp


def _seconds(ds: Dataset) -> float:
    """Data in ``ds`` (s): its ticks times the tick interval, gaps not counted."""
    return len(ds) * ds.dt


def _require_parts(ds: Dataset, sp: Split) -> None:
    """A :class:`NotEnoughData` naming the log and the shortest part unless every part
    of ``sp`` holds :data:`MIN_PART_S` of data."""
    parts = {"fit": sp.fit, "selection": sp.holdout, "test": sp.test}
    name, part = min(parts.items(), key=lambda kv: _seconds(kv[1]))
    if _seconds(part) < MIN_PART_S:
        short = math.floor(10.0 * _seconds(part)) / 10.0  # 9.98 s reads 9.9, not 10.0
        raise NotEnoughData(
            f"{ds.source or 'log'}: too short: {_seconds(ds):.0f} s with both heading and "
            f"velocity over ground leave the {name} part {short:.1f} s "
            f"({sp.parts['method'].replace('_', ' ')}); each part needs at least "
            f"{MIN_PART_S:.0f} s")


def _split(ds: Dataset, block_s: float, test_share: float) -> Split:
    """:func:`split` with blocks of ``block_s`` seconds, the parts' lengths unchecked."""
    runs = [r.split("#")[0] for r in ds.run]
    names = sorted(set(runs))
    t0 = float(ds.t[0]) if len(ds) else 0.0
    if len(names) >= 3:
        test_runs = names[2::3]
        rest = [n for n in names if n not in test_runs]
        sel_runs = rest[1::3]
        fit_runs = [n for n in rest if n not in sel_runs]
        where = np.array(runs, dtype=object)
        parts = {"fit": ds.subset(np.isin(where, fit_runs)),
                 "select": ds.subset(np.isin(where, sel_runs)),
                 "test": ds.subset(np.isin(where, test_runs))}
        summary = {k: _part_summary(v, t0, r) for (k, v), r in zip(
            parts.items(), (fit_runs, sel_runs, test_runs))}
        return Split(parts["fit"], parts["select"],
                     f"by run: {len(fit_runs)} fit, {len(sel_runs)} select "
                     f"({', '.join(sel_runs)}), {len(test_runs)} test ({', '.join(test_runs)})",
                     parts["test"], {"method": "by_run", **summary})
    t_rel = ds.t - t0
    span = float(t_rel[-1]) if len(ds) else 0.0
    t_test = (1.0 - test_share) * span
    block = np.floor(t_rel / block_s).astype(int)
    is_test = t_rel >= t_test
    block = np.where(is_test, block.max(initial=0) + 1 + np.floor((t_rel - t_test) / block_s).astype(int), block)
    labels = np.array([f"{r}@{b}" for r, b in zip(ds.run, block)], dtype=object)
    ds2 = Dataset(**{**vars(ds), "run": labels})
    is_sel = ~is_test & (block % 3 == 2)
    fit, sel, test = ds2.subset(~is_test & ~is_sel), ds2.subset(is_sel), ds2.subset(is_test)
    return Split(fit, sel,
                 f"forward in time: the last {100 * test_share:.0f} % (from {t_test:.0f} s) is "
                 f"the test part; before it, interleaved {block_s:.0f} s blocks, every third "
                 "for selection, the others fitted on",
                 test, {"method": "forward_in_time", "fit": _part_summary(fit, t0),
                        "select": _part_summary(sel, t0), "test": _part_summary(test, t0)})


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
    effects, the base and final fits (refitted on the fit and selection parts together)
    with their scores on the test part (``before``, ``after``) and on the selection part
    (``select_before``, ``select_after``), every round's candidates, an ``unexplained``
    residual structure, the wave found in the residual, and the values of the effects
    applied to the data (``transformed``)."""

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
    """The parts the final model was fitted and scored on (re-aligned by a latency)."""
    transformed: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Data-transforming effects chosen: name -> (value, one-sigma)."""
    select_before: M.Score | None = None
    select_after: M.Score | None = None
    selection_fit: M.Fit | None = None
    """The final effects fitted on the fit part alone (the fit the selection scored)."""
    base_test: Dataset | None = None
    """The test part as the base model sees it (no transform applied)."""
    actuator_lag_s: float = 0.0
    """The base model's shaft lag (s), estimated on the fit part and applied to every
    part's commands (:func:`onboard.offline.closure.model.estimate_actuator_lag`)."""
    drift: dict = field(default_factory=dict)
    """Per-window re-estimates of the chosen effects and the surge gain (:mod:`.drift`)."""
    rejected_on_test: list[dict] = field(default_factory=list)
    """Effects chosen on the selection part whose model scored worse on the test part
    than the model without them (``_worse_on_test``), last chosen first: each ``name``,
    ``test_error_without`` and ``test_error_with`` (the headline metric)."""


def _worse_on_test(after: M.Score, before: M.Score) -> bool:
    """Whether the model with the chosen effects is worse on the test part than the base
    model: a higher headline error."""
    a, b = after.headline, before.headline
    return (a is not None and b is not None and math.isfinite(a) and math.isfinite(b)
            and a > b)


def _sigma(ds: Dataset, f: M.Fit) -> dict[str, float]:
    """Robust noise scale per channel (derivative-form for the along channel)."""
    targets = M.channel_targets(ds)
    out = {}
    for ch, y in targets.items():
        pred = np.zeros(len(ds))
        if ch == "along":
            pred = M.along_base_output(ds, f)
        elif ch == "lateral":
            pred = M.lateral_base_output(ds, f)
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

    Effects are fitted on the fit part and chosen by their error on the selection part;
    the chosen model and the base model are then refitted on both parts and scored on the
    test part, which neither step saw. ``declared`` effects are fitted as part of the
    model from the start; ``known`` effects are part of it with fixed parameters (a
    calm-water calibration) and may still be found again as candidates, for the part the
    calibration does not cover.
    """
    sp = split(ds)
    # The base model's shaft lag, from the fit part, applied to every part's commands.
    lag = M.estimate_actuator_lag(sp.fit)
    if lag > 0.0:
        sp = Split(lag_commands(sp.fit, lag), lag_commands(sp.holdout, lag), sp.how,
                   None if sp.test is None else lag_commands(sp.test, lag), sp.parts)
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
    sel_before = M.score(sp.holdout, base, metric)
    n_eff = max(10.0, len(sp.holdout) * ds.dt / 2.0)

    pool = [n for n in (candidates or tuple(ALL)) if n not in declared
            and ALL[n].applies(sp.fit, ctx)]
    chosen: list[str] = []
    transformed: dict[str, tuple[float, float]] = {}
    fit_data, hold_data = sp.fit, sp.holdout
    current_fit, current_rel = base, 1.0
    rounds: list[list[Candidate]] = []

    if "actuator_mapping" in pool:
        # First: every surge and yaw effect depends on which command drives which thruster.
        pool.remove("actuator_mapping")
        e = ALL["actuator_mapping"]
        found = e.search(fit_data)
        if found is not None:
            code = found[0]
            fd, hd = e.transform(fit_data, code), e.transform(hold_data, code)
            f = M.fit(fd, _model_effects(declared), sigma, ctx, known=known)
            s = M.score(hd, f, metric)
            gain = am.held_out_gain(fit_data, hold_data, int(code))
            cand = Candidate("actuator_mapping", _relative(s, sel_before), gain, math.inf,
                             s.headline, value=(code, 0.0))
            rounds.append([cand])
            if gain >= min_gain:
                cand.accepted = True
                chosen.append(cand.name)
                transformed[cand.name] = cand.value
                fit_data, hold_data = fd, hd
                current_fit, current_rel = f, cand.score

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
                f = M.fit(fd, _model_effects((*declared, *chosen)), sigma, ctx, known=known)
            else:
                f = M.fit(fd, _model_effects((*declared, *chosen, name)), sigma, ctx, known=known)
                theta, std = f.theta[name], f.std[name]
            s = M.score(hd, f, metric)
            k = sum(len(ALL[x].params) for x in (*chosen, name))
            rel = _relative(s, sel_before) * math.exp(penalty * k / n_eff)
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
            current_fit = M.fit(fit_data, _model_effects((*declared, *chosen)), sigma, ctx,
                                known=known)
            current_rel = top.score
        else:
            break
    # The final score: both models refitted on fit + selection, scored on the test part;
    # an effect that makes the test part worse than the model without it is rejected, and
    # so is one whose parameters, physical as fitted on the fit part, are not once refitted.
    test = sp.test if sp.test is not None and len(sp.test) else sp.holdout
    base_final = M.fit(concat([sp.fit, sp.holdout]), declared, sigma, ctx, known=known)
    before = M.score(test, base_final, metric)
    rejected: list[dict] = []
    while True:
        fit_data, hold_data, test_data = sp.fit, sp.holdout, test
        for name, (value, _) in transformed.items():
            fit_data, hold_data, test_data = (ALL[name].transform(d, value)
                                              for d in (fit_data, hold_data, test_data))
        both = concat([fit_data, hold_data])
        final = M.fit(both, _model_effects((*declared, *chosen)), sigma, ctx, known=known)
        after = M.score(test_data, final, metric)
        unphysical = [n for n in _model_effects(chosen) if not ALL[n].physical(final.theta[n])]
        entry: dict = {}
        if unphysical:
            name = unphysical[-1]
            entry = {"unphysical": True,
                     "params": ALL[name].describe(final.theta[name], final.std[name])[0]}
        elif not chosen or not _worse_on_test(after, before):
            break
        else:
            name = chosen[-1]
        chosen.remove(name)
        transformed.pop(name, None)
        rejected.append({"name": name, "test_error_without": before.headline,
                         "test_error_with": after.headline, **entry})
    if rejected:
        current_fit = M.fit(fit_data, _model_effects((*declared, *chosen)), sigma, ctx,
                            known=known)
    sel_after = M.score(hold_data, current_fit, metric)
    final_split = Split(fit_data, hold_data, sp.how, test_data, sp.parts)
    sel = Selection(split=sp, metric=metric, declared=tuple(declared), chosen=tuple(chosen),
                    base_fit=base_final, final_fit=final, before=before, after=after,
                    rounds=rounds, wave=wave, final_split=final_split, transformed=transformed,
                    select_before=sel_before, select_after=sel_after,
                    selection_fit=current_fit, base_test=test, actuator_lag_s=lag,
                    rejected_on_test=rejected)
    sel.unexplained = structure_left(final_split, current_fit)
    sel.drift = drift.per_window(both, current_fit)
    return sel


def _model_effects(names) -> tuple[str, ...]:
    """The effects among ``names`` that are model terms (not data transforms)."""
    return tuple(n for n in names if not ALL[n].transforms_data)


def _blocks(t: np.ndarray, run: np.ndarray, block_s: float) -> np.ndarray:
    """First index of each block of at most ``block_s`` seconds, blocks never spanning a
    change of run label or a gap in time."""
    new_seg = np.r_[True, run[1:] != run[:-1]] | np.r_[True, np.diff(t) > 1.0]
    seg = np.cumsum(new_seg)
    since = t - t[np.flatnonzero(new_seg)][seg - 1]
    blk = np.floor(since / block_s)
    return np.flatnonzero(np.r_[True, (seg[1:] != seg[:-1]) | (blk[1:] != blk[:-1])])


def find_wave(ds: Dataset, residual: np.ndarray, min_period_s: float = 2.0,
              max_period_s: float = 15.0, max_p: float = 1e-6,
              block_s: float = 30.0) -> dict | None:
    """The regular wave (period, direction) that best explains a lateral residual, or
    None if no wave is significant.

    A moving boat meets the crests at the encounter frequency ``w - k V . d``, which
    changes with its velocity over ground ``V``; over the whole record the phase
    ``w t - k (N cos d + E sin d)`` winds through hundreds of radians, so the coherent fit
    of :mod:`.effects.wave_oscillation` peaks in a cell far narrower than any grid over
    2-15 s and all directions. The search therefore runs in two stages:

    1. **Encounter frequency, block by block.** On ``block_s`` blocks (within each
       contiguous part) the wave regressors get their own amplitude and phase per block
       (:func:`.effects.wave_oscillation.lateral_shares` with blocks), so a cell scores
       when its encounter frequency matches every block's at that block's speed and
       heading. This score is smooth in period and direction: a grid of 60 log-spaced
       periods and 24 directions finds the peak, refined on a 9 x 9 grid around it.
    2. **Coherent phase.** Around that estimate (periods within 1.5 %, directions within
       0.12 rad, 31 x 25 cells) one wave of fixed amplitude and phase is fitted to the
       whole residual, as the effect's regressors will be.

    Samples are taken at 5 Hz at most (encounter periods stay above a second). The
    false-alarm probability counts one independent sample per second of data and every
    cell of both stages; the coherent share must also stand 20 times above the median
    coherent share over the first stage's grid, so a coloured residual is not taken for
    a wave. (The median of the block-wise shares is no guard: with a few cycles of a long
    period per block its lobes are broad, and a strong 6 s wave with no positions raises
    it to a fifth of its peak.)
    """
    from onboard.offline.closure.effects.wave_oscillation import lateral_shares
    from onboard.offline.closure.effects.wave_oscillation import track as wave_track

    y = np.asarray(residual, float)
    ok = np.isfinite(y)
    if ok.sum() < 200 or np.ptp(ds.t) < 10 * max_period_s:
        return None
    has_pos = bool(np.isfinite(ds.north).any())
    step = max(1, int(0.2 / ds.dt + 1e-9))
    idx = np.flatnonzero(ok)[::step]
    if len(idx) < 100:
        return None
    y = y[idx] - y[idx].mean()
    if float(y @ y) <= 0:
        return None
    t = ds.t[idx]
    north, east = wave_track(ds)
    north, east = north[idx], east[idx]
    psi = ds.psi[idx]
    v_n = np.nan_to_num(ds.v_n[idx]) if has_pos else None
    v_e = np.nan_to_num(ds.v_e[idx]) if has_pos else None
    starts = _blocks(t, ds.run[idx], block_s)

    def scores(periods, directions, blocks):
        pp, dd = np.meshgrid(periods, directions, indexing="ij")
        return lateral_shares(t, north, east, psi, y, pp.ravel(), dd.ravel(), blocks,
                              v_north=v_n, v_east=v_e).reshape(pp.shape)

    periods = np.geomspace(min_period_s, max_period_s, 60)
    directions = np.linspace(0.0, 2 * np.pi, 24, endpoint=False) if has_pos else np.zeros(1)
    coarse = scores(periods, directions, starts)
    coarse_coherent = scores(periods, directions, None)
    i, j = np.unravel_index(int(np.argmax(coarse)), coarse.shape)
    ratio = float(periods[1] / periods[0])
    fine_p = periods[i] * ratio ** np.linspace(-1.0, 1.0, 9)
    fine_d = directions[j] + (np.linspace(-0.13, 0.13, 9) if has_pos else np.zeros(1))
    fine = scores(fine_p, fine_d, starts)
    i, j = np.unravel_index(int(np.argmax(fine)), fine.shape)
    coh_p = fine_p[i] * np.linspace(0.985, 1.015, 31)
    coh_d = fine_d[j] + (np.linspace(-0.12, 0.12, 25) if has_pos else np.zeros(1))
    coh = scores(coh_p, coh_d, None)
    k, m = np.unravel_index(int(np.argmax(coh)), coh.shape)
    sh = float(coh[k, m])
    n_eff = max(8.0, len(idx) * step * ds.dt)
    cells = coarse.size * coh.size
    fap = min(1.0, cells * (1.0 - sh) ** ((n_eff - 5) / 2))
    if sh < 20.0 * float(np.median(coarse_coherent)) or fap > max_p:
        return None
    return {"period": float(coh_p[k]), "direction": float(coh_d[m] % (2 * np.pi)),
            "share": sh, "false_alarm_p": fap,
            "encounter_share": float(np.max(fine))}


def _harmonics(psi: np.ndarray, orders=(1, 2, 3)) -> list[tuple[str, np.ndarray]]:
    return [(f"heading harmonic {k}", np.column_stack([np.cos(k * psi), np.sin(k * psi)]))
            for k in orders]


def generic_basis(ds: Dataset, channel: str) -> list[tuple[str, np.ndarray]]:
    """Groups of generic regressors for ``channel``'s residual, by name: what a missing
    effect of any kind would correlate with (heading harmonics, speed, turn rate,
    commands, time and their products), in the channel's own form (the heading channel
    is integrated from each segment's start, so its regressors are too). The speed is a
    glider's glide speed where it has one: the measured along-track speed is in the along
    channel's residual, and a regressor made of it explains its noise."""
    tau = (ds.t - ds.t.mean()) / max(1.0, float(np.ptp(ds.t)))
    u = np.nan_to_num(ds.along if ds.u_model is None else ds.u_model)
    groups: list[tuple[str, np.ndarray]] = []
    if channel == "heading":
        s0 = segment_starts(ds)
        since = ds.t - ds.t[s0]
        for name, h in _harmonics(ds.psi):
            groups.append((name, h - h[s0]))
        # a rate bias that changes over the log: its drift grows as since * (time of day)
        groups.append(("time", np.column_stack([since * tau])))
        groups.append(("time x heading harmonic 1",
                       np.column_stack([tau * np.cos(ds.psi) - (tau * np.cos(ds.psi))[s0],
                                        tau * np.sin(ds.psi) - (tau * np.sin(ds.psi))[s0]])))
        return groups
    groups += _harmonics(ds.psi)
    groups.append(("speed x heading harmonic 1", u[:, None] * _harmonics(ds.psi, (1,))[0][1]))
    groups.append(("speed x heading harmonic 2", u[:, None] * _harmonics(ds.psi, (2,))[0][1]))
    if channel != "along":
        # in the along channel speed and command are the surge model's own terms (and
        # those of its catalog effects): a correction there is a refit, not a new effect
        groups.append(("speed", np.column_stack([u, u * np.abs(u)])))
    groups.append(("yaw rate", np.column_stack([ds.r, ds.r**2])))
    groups.append(("time", np.column_stack([tau, tau**2])))
    groups.append(("time x heading harmonic 1", tau[:, None] * _harmonics(ds.psi, (1,))[0][1]))
    if ds.has_commands:
        c = np.nan_to_num(ds.cmd_surge)
        if channel != "along":
            groups.append(("surge command", np.column_stack([c, c * np.abs(c)])))
        groups.append(("time x surge command", np.column_stack([tau * c])))
        groups.append(("yaw command", np.column_stack([np.nan_to_num(ds.cmd_yaw)])))
    return groups


def _increments(ds: Dataset, x: np.ndarray, seconds: float = 5.0) -> np.ndarray:
    """Non-overlapping increments of ``x`` over ``seconds`` within each segment."""
    k = max(1, int(round(seconds / ds.dt)))
    i = np.arange(0, len(ds) - k, k)
    i = i[ds.run[i] == ds.run[i + k]]
    return np.asarray(x)[i + k] - np.asarray(x)[i]


def _held_out_gain(Xf, yf, Xh, yh) -> float:
    """Share of the held-out mean square that a least-squares fit of ``Xf`` (plus a
    constant) to ``yf`` removes from ``yh``."""
    Xf = np.column_stack([Xf, np.ones(len(Xf))])
    Xh = np.column_stack([Xh, np.ones(len(Xh))])
    coef, *_ = np.linalg.lstsq(Xf, yf, rcond=None)
    before = float(np.mean(yh**2))
    after = float(np.mean((yh - Xh @ coef) ** 2))
    return 1.0 - after / before if before > 0 else 0.0


def structure_left(sp: Split, f: M.Fit, min_gain: float = 0.15,
                   min_step: float = 0.03) -> dict | None:
    """Evidence of structure the chosen effects do not explain, or None.

    In every residual channel (lateral, heading, along), groups of a generic basis
    (:func:`generic_basis`) are fitted to the fit part's residual and added one at a time,
    each time the group that most lowers the selection part's residual mean square, while
    a group lowers it by ``min_step`` more (so many weak regressors cannot add up to a
    false alarm by overfitting); the channel counts when the groups kept lower it by
    ``min_gain``. For each channel that counts: its ``held_out_gain``, the group that
    carries the structure (the first kept, ``regressor``, with its gain alone,
    ``regressor_gain``) and the groups kept (``correlates_with``). The top-level
    ``channel``, ``regressor`` and ``held_out_gain`` name the strongest channel.
    """
    res_fit = M.residuals(sp.fit, f)
    res_hold = M.residuals(sp.holdout, f)
    found = {}
    for ch in res_fit:
        gf, gh = generic_basis(sp.fit, ch), generic_basis(sp.holdout, ch)
        yf, yh = res_fit[ch], res_hold[ch]
        if ch == "heading":
            # The integrated channel is a random walk of the gyro noise: compare its
            # increments over 5 s (rate errors, independent) instead of its values.
            gf = [(n, _increments(sp.fit, g)) for n, g in gf]
            gh = [(n, _increments(sp.holdout, g)) for n, g in gh]
            yf, yh = _increments(sp.fit, yf), _increments(sp.holdout, yh)
        Xf = np.column_stack([g for _, g in gf])
        Xh = np.column_stack([g for _, g in gh])
        okf = np.isfinite(yf) & np.isfinite(Xf).all(1)
        okh = np.isfinite(yh) & np.isfinite(Xh).all(1)
        if okf.sum() < 20 or okh.sum() < 20:
            continue
        kept: list[int] = []
        gain = 0.0
        first_gain = 0.0
        while len(kept) < len(gf):
            best = (gain, -1)
            for i in range(len(gf)):
                if i in kept:
                    continue
                cols = kept + [i]
                g = _held_out_gain(np.column_stack([gf[j][1] for j in cols])[okf], yf[okf],
                                   np.column_stack([gh[j][1] for j in cols])[okh], yh[okh])
                if g > best[0]:
                    best = (g, i)
            if best[1] < 0 or best[0] - gain < min_step:
                break
            kept.append(best[1])
            if len(kept) == 1:
                first_gain = best[0]
            gain = best[0]
        if gain < min_gain:
            continue
        found[ch] = {"held_out_gain": round(gain, 3), "regressor": gf[kept[0]][0],
                     "regressor_gain": round(first_gain, 3),
                     "correlates_with": [gf[i][0] for i in kept]}
    if not found:
        return None
    top = max(found, key=lambda c: found[c]["held_out_gain"])
    return {**found, "channel": top, "regressor": found[top]["regressor"],
            "held_out_gain": found[top]["held_out_gain"]}
