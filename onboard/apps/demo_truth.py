"""The demo's comparison with the simulator's hidden truth: what each estimate is measured
against, how far off it is, and what a figure that looks bad means.

:func:`score` matches every estimate received over Zenoh to the truth record of the same
instant and gives one :class:`ScoreRow` per quantity: its RMSE, the mean one-sigma the
estimator published for it, the raw measurement it improves on (``aie.speed`` beside the
GNSS ``nav.speed``) and the spread of the true value over the run. :func:`format_scores`
prints them as a table, :func:`notes` says in words what the rows that look bad mean (an
input estimate whose RMSE exceeds the truth's spread, an estimate behind its raw
measurement, a sigma smaller than the error), and :func:`current_story` tells how the
water current went from unknown to known, against the simulated current.

The water current is scored only where it is *known* (:func:`current_known`): its published
one-sigma has stayed at most :data:`CURRENT_KNOWN_STD` for :data:`CURRENT_SETTLE_S`. Before
that a row reads ``unknown`` with the largest sigma published, never a number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

from onboard.core.geo import wrap_pi
from onboard.core.messages import EstimateRecord

CURRENT_KNOWN_STD = 0.1
"""A current estimate is shown as known when its published one-sigma (the larger of
``std_north`` and ``std_east``, m/s) has been at most this for ``CURRENT_SETTLE_S``."""
CURRENT_SETTLE_S = 10.0
"""How long (simulated s) the current's sigma must stay small before it counts as known."""
MATCH_S = 0.06
"""An estimate is matched to the truth record within this many seconds of its time."""
OVERCONFIDENT_RATIO = 2.0
"""A row whose RMSE exceeds this many times its mean published sigma gets a note: the
estimator claims more than it knows."""

_TRUTH: dict[str, Callable[[Any], float | None]] = {
    "heading": lambda tr: tr.yaw, "yaw": lambda tr: tr.yaw,
    "roll": lambda tr: tr.roll, "pitch": lambda tr: tr.pitch,
    "speed": lambda tr: math.hypot(tr.u, tr.v), "yaw_rate": lambda tr: tr.r,
    "u": lambda tr: tr.u, "v": lambda tr: tr.v, "w": lambda tr: tr.w,
    "u_r": lambda tr: tr.u_r, "v_r": lambda tr: tr.v_r, "w_r": lambda tr: tr.w_r,
    "rate_p": lambda tr: tr.p, "rate_q": lambda tr: tr.q, "rate_r": lambda tr: tr.r,
    "surge_input": lambda tr: tr.surge_input, "yaw_input": lambda tr: tr.yaw_input,
    "dist_x": lambda tr: tr.disturbance_x, "dist_y": lambda tr: tr.disturbance_y,
    "dist_z": lambda tr: tr.disturbance_z, "depth": lambda tr: tr.down,
}
_ANGLES = {"heading", "yaw", "roll", "pitch"}
_RATES = {"yaw_rate", "rate_p", "rate_q", "rate_r"}
_INPUTS = {"surge_input", "yaw_input"}
_POSITIONS = {"north": "north", "east": "east", "down": "down"}
_CURRENT = {"north": "current_north", "east": "current_east", "down": "current_down"}
_RAW = {"speed": "nav.speed", "north": "nav.north", "east": "nav.east",
        "heading": "nav.heading"}
"""The raw measurement each estimated quantity improves on (pipelines other than nav)."""
_AGAINST = {
    "north": "position north", "east": "position east", "down": "depth",
    "heading": "heading", "yaw": "heading", "roll": "roll", "pitch": "pitch",
    "speed": "speed over ground", "yaw_rate": "yaw rate",
    "u": "surge over ground", "v": "sway over ground", "w": "heave over ground",
    "u_r": "surge through water", "v_r": "sway through water", "w_r": "heave through water",
    "rate_p": "roll rate", "rate_q": "pitch rate", "rate_r": "yaw rate",
    "surge_input": "thrust / surge mass", "yaw_input": "yaw moment / inertia",
    "dist_x": "disturbance x", "dist_y": "disturbance y", "dist_z": "disturbance z",
    "depth": "depth",
}
"""What the truth of each quantity is (the table's last column), in the table's order."""
_PIPELINE_ORDER = ("nav", "aie", "kf", "current", "eseso")
"""The table's order: the raw measurements first, then each estimator."""


@dataclass
class ScoreRow:
    """RMSE of one estimated quantity against the truth.

    ``n`` counts the samples scored; ``total`` the samples received. For the current
    pipeline only the samples it knows (:func:`current_known`) are scored, so ``n``
    may be below ``total`` and zero (``rmse`` NaN: printed as unknown). ``raw`` names the
    raw measurement the quantity improves on, ``raw_rmse`` is that one's RMSE.
    """

    column: str
    n: int
    rmse: float
    truth_std: float
    unit: str
    total: int = 0
    raw: str | None = None
    raw_rmse: float = math.nan
    max_std: float = math.nan
    """The largest published sigma among the unscored samples (current only)."""
    sigma: float = math.nan
    """The mean one-sigma the estimator published over the scored samples (NaN: none)."""
    against: str = ""
    """What the truth of this quantity is (``thrust / surge mass``, ``water current`` ...)."""


def current_known(history: list[EstimateRecord]) -> dict[float, bool]:
    """For each ``current`` record time (s): whether its estimate is known, i.e. its
    horizontal one-sigma (``max(std_north, std_east)``, m/s) has stayed at most
    ``CURRENT_KNOWN_STD`` for ``CURRENT_SETTLE_S`` seconds. A record without sigmas is
    unknown."""
    out: dict[float, bool] = {}
    since: float | None = None
    for rec in history:
        if rec.pipeline != "current":
            continue
        sd = _horizontal_std(rec)
        if math.isfinite(sd) and sd <= CURRENT_KNOWN_STD:
            if since is None:
                since = rec.t
            out[rec.t] = rec.t - since >= CURRENT_SETTLE_S
        else:
            since = None
            out[rec.t] = False
    return out


def _horizontal_std(rec: EstimateRecord) -> float:
    """The larger of a current record's north and east one-sigma (m/s; inf: none)."""
    return max(rec.std.get("north", math.inf), rec.std.get("east", math.inf))


def _unit(pipeline: str, q: str) -> str:
    if pipeline == "current" and q in _CURRENT:
        return "m/s"
    if q in _ANGLES:
        return "deg"
    if q in _RATES:
        return "deg/s"
    if q == "surge_input":
        return "m/s^2"
    if q == "yaw_input":
        return "rad/s^2"
    if q.startswith("dist_"):
        return "N"
    if q in _POSITIONS or q == "depth":
        return "m"
    return "m/s"


class _TruthIndex:
    """The truth record nearest in time (within :data:`MATCH_S`) of an evenly sampled
    truth series."""

    def __init__(self, truth: list[Any]) -> None:
        self.truth = truth
        self.ts = [tr.t for tr in truth]
        n = len(self.ts)
        self.dt = (self.ts[-1] - self.ts[0]) / (n - 1) if n > 1 else 0.1

    def at(self, t: float) -> Any | None:
        """The truth record at ``t`` (None: none within :data:`MATCH_S`)."""
        ts = self.ts
        i = int(round((t - ts[0]) / self.dt)) if self.dt > 0 else 0
        for j in (i, i - 1, i + 1):
            if 0 <= j < len(ts) and abs(ts[j] - t) <= MATCH_S:
                return self.truth[j]
        return None


class _Tally:
    """Errors, true values and published sigmas per column while scoring."""

    def __init__(self) -> None:
        self.errs: dict[str, list[float]] = {}
        self.refs: dict[str, list[float]] = {}
        self.sigmas: dict[str, list[float]] = {}
        self.totals: dict[str, int] = {}
        self.max_std: dict[str, float] = {}

    def unknown(self, col: str, sd: float) -> None:
        """A current sample not scored (unknown) with its horizontal sigma ``sd``."""
        self.max_std[col] = max(self.max_std.get(col, 0.0), sd)
        self.errs.setdefault(col, [])
        self.refs.setdefault(col, [])

    def add(self, col: str, err: float, ref: float, sigma: float | None) -> None:
        """One scored sample: its error, the true value and its published sigma."""
        self.errs.setdefault(col, []).append(err)
        self.refs.setdefault(col, []).append(ref)
        if sigma is not None and math.isfinite(sigma):
            self.sigmas.setdefault(col, []).append(sigma)


def _reference(rec: EstimateRecord, q: str, v: float, tr: Any,
               first: dict[tuple[str, str], tuple[float, float]]) -> float | None:
    """The true value that ``rec``'s ``q`` = ``v`` is measured against (None: none)."""
    if rec.pipeline == "current" and q in _CURRENT:
        return getattr(tr, _CURRENT[q])
    if q in _POSITIONS:
        base = first.setdefault((rec.pipeline, q), (v, getattr(tr, _POSITIONS[q])))
        return base[0] + getattr(tr, _POSITIONS[q]) - base[1]
    if q in _TRUTH:
        return _TRUTH[q](tr)
    return None


def _tally(history: list[EstimateRecord], truth: list[Any]) -> _Tally:
    """Every estimate of ``history`` against the truth of its instant."""
    index = _TruthIndex(truth)
    tally = _Tally()
    first: dict[tuple[str, str], tuple[float, float]] = {}
    known = current_known(history)
    for rec in history:
        tr = index.at(rec.t)
        if tr is None:
            continue
        for q, v in rec.values.items():
            if q.startswith("std_") or not math.isfinite(v):
                continue
            col = f"{rec.pipeline}.{q}"
            tally.totals[col] = tally.totals.get(col, 0) + 1
            if rec.pipeline == "current" and not known.get(rec.t, False):
                tally.unknown(col, _horizontal_std(rec))
                continue
            ref = _reference(rec, q, v, tr, first)
            if ref is None or not math.isfinite(ref):
                continue
            e = wrap_pi(v - ref) if q in _ANGLES else v - ref
            tally.add(col, e, ref, rec.std.get(q))
    return tally


def score(history: list[EstimateRecord], truth: list[Any]) -> list[ScoreRow]:
    """RMSE of every estimated quantity that has a truth counterpart.

    Estimates are matched to the truth record nearest in time (within :data:`MATCH_S`).
    Positions (``north``/``east``/``down`` of pipelines other than ``current``) are
    compared as displacements from the pipeline's first estimate, as the estimators report
    them from their first fix. Current samples are scored only where
    :func:`current_known`; each row names the raw measurement it improves on (``_RAW``)
    with that one's RMSE, and the mean sigma the estimator published for it.
    """
    if not truth:
        return []
    tally = _tally(history, truth)
    rows = [_row(col, es, tally) for col, es in tally.errs.items()]
    by_col = {row.column: row for row in rows}
    for row in rows:
        if row.raw in by_col:
            row.raw_rmse = by_col[row.raw].rmse
    return sorted(rows, key=_order)


def _order(row: ScoreRow) -> tuple[int, int, str]:
    """A row's place in the table: by pipeline (:data:`_PIPELINE_ORDER`), then quantity
    (:data:`_AGAINST`)."""
    pipe, q = row.column.split(".", 1)
    quantities = list(_AGAINST)
    return (_PIPELINE_ORDER.index(pipe) if pipe in _PIPELINE_ORDER else len(_PIPELINE_ORDER),
            quantities.index(q) if q in quantities else len(quantities), row.column)


def _row(col: str, es: list[float], tally: _Tally) -> ScoreRow:
    """The :class:`ScoreRow` of one column from its tallied errors."""
    pipe, q = col.split(".", 1)
    r = tally.refs[col]
    sig = tally.sigmas.get(col, [])
    rmse = math.sqrt(sum(e * e for e in es) / len(es)) if es else math.nan
    mean = sum(r) / len(r) if r else math.nan
    std = math.sqrt(sum((x - mean) ** 2 for x in r) / len(r)) if r else math.nan
    sigma = sum(sig) / len(sig) if sig else math.nan
    if q in _ANGLES or q in _RATES:
        rmse, std, sigma = math.degrees(rmse), math.degrees(std), math.degrees(sigma)
    against = "water current" if pipe == "current" and q in _CURRENT else _AGAINST.get(q, q)
    return ScoreRow(col, len(es), rmse, std, _unit(pipe, q),
                    total=tally.totals.get(col, len(es)),
                    raw=_RAW.get(q) if pipe not in ("nav", "current") else None,
                    max_std=tally.max_std.get(col, math.nan), sigma=sigma, against=against)


def _num(x: float, width: int = 9) -> str:
    return f"{x:{width}.3f}" if math.isfinite(x) else f"{'-':>{width}}"


def format_scores(rows: list[ScoreRow]) -> str:
    """The truth comparison as a text table: estimate, samples, RMSE, the mean published
    sigma, the raw measurement it improves on and that one's RMSE, the truth's spread,
    unit, and what the truth is. An estimate with no known sample reads ``unknown`` with
    the largest sigma it published."""
    if not rows:
        return "no estimates matched the truth (nothing to score)"
    w = max(len(r.column) for r in rows)
    out = [f"{'estimate':<{w}}  {'n':>5}  {'RMSE':>9}  {'sigma':>9}  {'raw':<{w}}  "
           f"{'raw RMSE':>9}  {'truth std':>9}  {'unit':<7}  against"]
    for r in rows:
        raw = r.raw if r.raw is not None and math.isfinite(r.raw_rmse) else "-"
        raw_rmse = _num(r.raw_rmse) if raw != "-" else f"{'':9}"
        if r.n == 0:
            note = (f"unknown: sigma up to {r.max_std:.2f} {r.unit}"
                    if math.isfinite(r.max_std) else "unknown")
            out.append(f"{r.column:<{w}}  {0:>5}  {'unknown':>9}  {'':9}  {'-':<{w}}  "
                       f"{'':9}  {'':9}  {r.unit:<7}  {r.against} ({note}, {r.total} "
                       "samples)")
            continue
        line = (f"{r.column:<{w}}  {r.n:>5}  {r.rmse:9.3f}  {_num(r.sigma)}  {raw:<{w}}  "
                f"{raw_rmse}  {r.truth_std:9.3f}  {r.unit:<7}  {r.against}")
        if r.total > r.n:
            line += f" (known in {r.n} of {r.total} samples)"
        out.append(line)
    return "\n".join(out)


LEGEND = (
    "RMSE: the estimate against the simulator's hidden truth at the same instant (positions\n"
    "as displacements from each pipeline's first estimate); sigma: the mean one-sigma the\n"
    "estimator published for it (an honest sigma is near its RMSE); raw: the raw measurement\n"
    "it improves on, scored against the same truth; truth std: the spread of the true value\n"
    "over the run (an RMSE near it says little); against: what the truth is.")
"""How to read :func:`format_scores`' table (printed above it)."""


def notes(rows: list[ScoreRow], models: dict[str, float] | None = None) -> list[str]:
    """What the rows that look bad mean, one paragraph each: an input estimate whose RMSE
    is at least the truth's spread (:func:`_input_note`), an estimate behind the raw
    measurement it improves on, and a sigma much smaller than the error
    (:data:`OVERCONFIDENT_RATIO`). ``models``: the AIE's damping rates ``a`` (1/s) by
    axis (``surge``, ``heading``), quoted in the input notes."""
    out: list[str] = []
    by_col = {r.column: r for r in rows}
    for r in rows:
        if r.n == 0 or not math.isfinite(r.rmse):
            continue
        q = r.column.split(".", 1)[1]
        if q in _INPUTS and r.rmse >= r.truth_std:
            out.append(_input_note(r, q, (models or {}).get(
                "surge" if q == "surge_input" else "heading")))
        raw = by_col.get(r.raw or "")
        if raw is not None and raw.n and r.rmse > raw.rmse:
            out.append(f"{r.column}: RMSE {r.rmse:.3f} {r.unit}, above the raw {raw.column}'s "
                       f"{raw.rmse:.3f}: here the filter did not improve on the measurement "
                       f"(its published sigma {r.sigma:.3f} {r.unit} says how far it trusts "
                       "itself; the live comparison also counts how late the estimate "
                       "reached the service)")
        if math.isfinite(r.sigma) and r.sigma > 0 and r.rmse > OVERCONFIDENT_RATIO * r.sigma:
            out.append(f"{r.column}: RMSE {r.rmse:.3f} {r.unit} against a mean published "
                       f"sigma of {r.sigma:.3f}: the estimator claimed to know it "
                       f"{r.rmse / r.sigma:.1f} times better than it did")
    return out


def _input_note(r: ScoreRow, q: str, a: float | None) -> str:
    """Why an AIE input estimate's RMSE can exceed the spread of its truth."""
    axis, x, truth = (("surge", "v", "the thrust over the surge mass alone")
                      if q == "surge_input" else
                      ("heading", "r", "the actuators' yaw moment over the yaw inertia alone"))
    model = f"{x}' = -a {x} + u" + (f", a = {a:.2f} 1/s" if a is not None else "")
    return (f"{r.column}: RMSE {r.rmse:.3f} {r.unit} against a truth spread of "
            f"{r.truth_std:.3f}. The truth is {truth}; the estimate is the input u of the "
            f"AIE's first-order {axis} model ({model}), which also carries the drag and "
            "damping that model leaves out, and is inferred from the measured increments, "
            "so it is noisy sample by sample. It is what the forecast needs, not a "
            f"measurement of the actuator: judge the filter by its {axis} rows.")


def current_story(history: list[EstimateRecord], truth: list[Any],
                  unknown_above_std: float) -> list[str]:
    """The water current in words: the simulated one, the last estimate with its sigma,
    how long it was unknown (its sigma above ``unknown_above_std``, m/s, the pipeline's
    publication threshold: no number), and from when it was known
    (:func:`current_known`). Empty without a ``current`` pipeline."""
    recs = [r for r in history if r.pipeline == "current"]
    if not recs:
        return []
    out = []
    if truth:
        tn, te = truth[-1].current_north, truth[-1].current_east
        out.append(f"water current in the simulator: {_flow(tn, te)} "
                   f"(N {tn:+.3f}, E {te:+.3f} m/s)")
    published = [r for r in recs if "north" in r.values and "east" in r.values]
    if not published:
        sd = min(_horizontal_std(r) for r in recs)
        arc = headings_held([tr.yaw for tr in truth])
        why = ("the vehicle did not turn enough for the current along its track to be told "
               "from its own speed; run longer (--duration) or a scenario with turns"
               if arc < TURNED_DEG else
               f"the vehicle turned through {arc:.0f}° of heading, so turning is not what "
               "it lacked: its model, as configured, does not tell the current from its "
               "own motion through the water (the current's health: observable.*, "
               "theta.std_max)")
        out.append(f"estimated: unknown for all {recs[-1].t - recs[0].t:.0f} s (its sigma "
                   f"never below {sd:.2f} m/s together on both axes): {why}")
        return out
    last = published[-1]
    n, e = last.values["north"], last.values["east"]
    sn, se = last.std.get("north", math.nan), last.std.get("east", math.nan)
    out.append(f"estimated at t={last.t:.0f} s: {_flow(n, e)} (N {n:+.3f} ± {sn:.3f}, "
               f"E {e:+.3f} ± {se:.3f} m/s, one sigma)")
    t_known = next((t for t, k in current_known(history).items() if k), None)
    known = (f"known (sigma at most {CURRENT_KNOWN_STD} m/s for {CURRENT_SETTLE_S:.0f} s) "
             f"from t={t_known:.0f} s" if t_known is not None else
             f"never at most {CURRENT_KNOWN_STD} m/s for {CURRENT_SETTLE_S:.0f} s")
    out.append(f"unknown (its sigma above {unknown_above_std:g} m/s: no number published) "
               f"until t={published[0].t:.0f} s: the current along the boat's track cannot "
               "be told from the boat's own speed through the water until it has turned "
               f"enough (heading diversity); {known}")
    return out


TURNED_DEG = 90.0
"""Headings held over an arc at least this wide (deg) are a turn: the current along one
leg is then told from the other legs, where the model and the speed allow it."""


def headings_held(yaws: list[float]) -> float:
    """The arc of headings (deg) that ``yaws`` (rad) cover: 360 less the widest gap between
    them around the circle (0 for one heading; 355 for a circle sampled every 5 deg)."""
    if not yaws:
        return 0.0
    deg = sorted(math.degrees(y) % 360.0 for y in yaws)
    gaps = [b - a for a, b in zip(deg, deg[1:])] + [deg[0] + 360.0 - deg[-1]]
    return 360.0 - max(gaps)


def _flow(north: float, east: float) -> str:
    """``0.29 m/s toward 149°``: a current's speed and the direction it flows to."""
    return (f"{math.hypot(north, east):.2f} m/s toward "
            f"{math.degrees(math.atan2(east, north)) % 360.0:.0f}°")
