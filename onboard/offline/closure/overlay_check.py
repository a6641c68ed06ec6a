"""An overlay never makes things worse: each section of ``diagnose --write-config`` is
checked before it is written.

Two checks, in this order, per section (:class:`onboard.offline.closure.overlay.Section`):

1. **Plausibility**: a first-order model ``x' = -a x + gain c + offset`` written into
   ``[pipelines.aie.*]``/``[pipelines.kf.*]`` must have a time constant ``1/a`` within
   :data:`TIME_CONSTANT_BOUNDS_S` and reach at most :data:`MAX_TOP_SPEED_MPS` (surge) or
   :data:`MAX_TOP_YAW_RATE_RPS` (heading) at full command (``c = 1``): the steady state
   ``(gain + |offset|) / a``. A section outside is refused, naming the parameter.
2. **Replay** (every section but those in :data:`JUDGED_BY_DIAGNOSIS`): the log's test part (the diagnosis's held-out part, never fitted, never
   used to choose; :func:`onboard.offline.closure.select.split`) is replayed through the onboard
   engine with the configuration so far and with that plus the section; each time the
   RMS error of ``aie.speed`` and ``kf.speed`` as each filter predicted it for every GNSS
   fix of the test part, before the fix reached it, against the fix's measured speed over
   ground (:func:`prediction_errors`: a filter's speed after a fix has taken part of the
   fix's noise, so the fix cannot score it). The section is written when it raises
   neither error by more than :data:`TIE_MPS`; a tie is kept (a section no filter reads,
   such as the current's prior, leaves both unchanged).

Sections are checked in the overlay's order, each on top of those already accepted. A
section is judged together with the sections fitted on it (the surge model, fitted on the
re-mapped ``[inputs]``, with the re-mapping: the new mapping under the old model, or the
new model under the old mapping, is a configuration nobody fitted); both are written or
neither, and a surge model whose re-mapping was refused is refused too.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator, Sequence

import numpy as np

from onboard.core.config import Config, from_dict, merge, to_dict
from onboard.core.messages import Sample
from onboard.drivers.logs import open_log
from onboard.engine import Engine, run
from onboard.engine.inputs import column_names
from onboard.offline.closure import model as M

TIME_CONSTANT_BOUNDS_S: dict[str, tuple[float, float]] = {
    "surge": (0.2, 30.0), "heading": (0.05, 30.0)}
"""Plausible time constant ``1/a`` (s) of each axis of a small marine vehicle (1-5 m
hull: surge 1-15 s and yaw 0.1-10 s in Fossen 2021, Handbook of Marine Craft
Hydrodynamics, ch. 7, first-order Nomoto models; widened by a factor of ~3 on each side)."""

MAX_TOP_SPEED_MPS = 10.0
"""Highest plausible steady surge speed at full command (m/s): the vehicles this tool
targets (BlueBoat ~3 m/s, ASVs and AUVs below 5 m/s) with a factor two of margin."""

MAX_TOP_YAW_RATE_RPS = 3.0
"""Highest plausible steady yaw rate at full command (rad/s, ~170 deg/s)."""

TIE_MPS = 0.001
"""A change of a filter's speed error below this (m/s) is a tie (numerical noise)."""

WARMUP_S = 30.0
"""Data replayed (not scored) before each test range, so the filters have converged."""

JUDGED_BY_DIAGNOSIS = {
    "corrections": "judged by the diagnosis's own held-out test (the test-part error "
                   "before and after, in diagnosis.json); the speed against the GNSS speed "
                   "cannot judge a heading offset or a latency, since aie and kf fuse that "
                   "same speed"}
"""Sections not replayed: what they correct is measured by the diagnosis itself, and the
filters' speed against the GNSS Doppler speed (which they fuse) does not see it (on the
Shenzhen USV a right -73.5 deg heading offset and 1.23 s latency, which lower the
diagnosis's lateral velocity error 0.326 -> 0.063 m/s, raise that speed error 0.028 ->
0.065 m/s; predicted for each fix, :func:`prediction_errors`, 0.055 -> 0.095 m/s)."""

FILTERS = ("aie", "kf")
"""The filters whose speed error decides."""


@dataclass
class Verdict:
    """The decision on one overlay section: written or not, why, and the test-part speed
    RMS errors (m/s) of each filter without (``before``) and with it (``after``)."""

    section: str
    written: bool
    reason: str
    before: dict[str, float | None] = field(default_factory=dict)
    after: dict[str, float | None] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """The diagnosis.json entry (architecture.md §4.3, ``overlay_check``)."""
        return {"section": self.section, "written": self.written, "reason": self.reason,
                "speed_rmse_before_mps": self.before, "speed_rmse_after_mps": self.after}

    def line(self) -> str:
        """One printed line: ``written``/``refused``, the section, the figures, why."""
        figs = ", ".join(f"{k} {_f(self.before.get(k))} -> {_f(self.after.get(k))} m/s"
                         for k in FILTERS if k in self.before)
        word = "written" if self.written else "refused"
        return f"overlay {self.section}: {word}" + (f" ({figs})" if figs else "") + \
            f": {self.reason}"


def _f(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.3f}"


def implausible(table: str, values: dict[str, Any]) -> str | None:
    """Why the first-order model ``values`` (``a`` 1/s, ``gain``, ``offset``) of the TOML
    table ``table`` (``pipelines.<filter>.<axis>``) is not physical, or None."""
    axis = table.rsplit(".", 1)[-1]
    if axis not in TIME_CONSTANT_BOUNDS_S or "a" not in values:
        return None
    a = float(values["a"])
    lo, hi = TIME_CONSTANT_BOUNDS_S[axis]
    if not (a > 0 and lo <= 1.0 / a <= hi):
        tau = f"{1.0 / a:.3g} s" if a > 0 else "none (a <= 0)"
        return (f"{table}.a = {a:.4g} 1/s: time constant {tau} outside "
                f"[{lo:g}, {hi:g}] s")
    top = (abs(float(values.get("gain", 0.0))) + abs(float(values.get("offset", 0.0)))) / a
    bound, unit = ((MAX_TOP_SPEED_MPS, "m/s") if axis == "surge"
                   else (MAX_TOP_YAW_RATE_RPS, "rad/s"))
    if top > bound:
        return (f"{table}: (gain + |offset|) / a = {top:.3g} {unit} at full command, "
                f"above the plausible {bound:g} {unit}")
    return None


def held_out_ranges(sel: Any) -> list[tuple[float, float]]:
    """The test part's contiguous time ranges (s, the log's own time), merged across
    adjacent blocks."""
    ds = sel.split.test
    if ds is None or len(ds) == 0:
        return []
    cut = np.flatnonzero((ds.run[1:] != ds.run[:-1]) | (np.diff(ds.t) > 2.5 * ds.dt)) + 1
    out: list[tuple[float, float]] = []
    for i, j in zip(np.r_[0, cut], np.r_[cut, len(ds)]):
        a, b = float(ds.t[i]), float(ds.t[j - 1])
        if out and a - out[-1][1] <= 2.5 * ds.dt:
            out[-1] = (out[-1][0], b)
        else:
            out.append((a, b))
    return out


def _within(samples: Iterable[Sample], ranges: Sequence[tuple[float, float]]
            ) -> Iterator[Sample]:
    for s in samples:
        if any(a - WARMUP_S <= s.t <= b for a, b in ranges):
            yield s


def signed_ground_speed(nav: dict[str, float]) -> float | None:
    """The measured speed over ground (m/s, ``nav.speed``), negative when the track runs
    more than 90 deg from the heading (going astern), so that it compares with the
    filters' signed surge speed; unsigned without a heading or a direction of travel;
    None without a speed."""
    speed = nav.get("speed")
    if speed is None or not math.isfinite(speed):
        return None
    if "v_north" in nav and "v_east" in nav:
        track = math.atan2(nav["v_east"], nav["v_north"])
    else:
        track = nav.get("course", math.nan)
    heading = nav.get("heading", math.nan)
    if not (math.isfinite(track) and math.isfinite(heading)):
        return speed
    return speed if math.cos(heading - track) >= 0.0 else -speed


def prediction_errors(log: str, cfg: Config, ranges: Sequence[tuple[float, float]]
                      ) -> dict[str, np.ndarray]:
    """Per GNSS fix within ``ranges``, in time order: ``aie.speed`` and ``kf.speed`` as
    each filter predicted it before the fix reached it, minus the fix's measured speed
    over ground (:func:`signed_ground_speed` of the same replay's ``nav``; NaN where a
    filter gave no speed), replaying only those ranges (plus :data:`WARMUP_S` before
    each) through the onboard engine under ``cfg``.

    The prediction, not the estimate after the fix: a filter's speed after it fused a
    fix has taken part of that fix's own noise, so scoring it against the fix rewards
    the configuration that trusts the receiver most (on ``noise-boat-3x`` the measured
    noise section, right to 2 %, was refused by that score); the speed predicted before
    it is independent of the fix's noise, and its mean square error against the fix is
    the filter's own plus the receiver's, which is the same for every configuration. A
    fix is a tick at which ``nav``'s position or speed changes; with a GNSS latency ``L``
    in ``cfg`` it reports the instant ``L`` before it arrived, and the prediction is the
    filter's speed at the last tick at or before that instant (and before the arrival)."""
    _, reader = open_log(log, cfg.csv, column_names(cfg.inputs))
    engine = Engine(cfg)
    lag = cfg.corrections.gnss_latency_s
    ts: list[float] = []
    fixes: list[tuple[float, float, float]] = []
    est: dict[str, list[float]] = {k: [] for k in FILTERS}

    def on_tick(t: float, records: Sequence[Any]) -> None:
        vals = {r.pipeline: r.values for r in records}
        nav = vals.get("nav", {})
        ref = signed_ground_speed(nav)
        ts.append(t)
        fixes.append((nav.get("north", math.nan), nav.get("east", math.nan),
                      math.nan if ref is None else ref))
        for k in FILTERS:
            est[k].append(vals.get(k, {}).get("speed", math.nan))

    run(engine, _within(reader, [(a, b + lag) for a, b in ranges]), on_tick)
    t_arr = np.asarray(ts)
    fix = np.asarray(fixes).reshape(-1, 3)
    ref = fix[:, 2]
    same = (fix[1:] == fix[:-1]) | (np.isnan(fix[1:]) & np.isnan(fix[:-1]))
    new = np.zeros(len(ts), dtype=bool)
    new[1:] = ~np.all(same, axis=1) & np.isfinite(ref[1:])
    arrival = np.flatnonzero(new)
    instant = t_arr[arrival] - lag
    before = np.minimum(arrival - 1, np.searchsorted(t_arr, instant, side="right") - 1)
    keep = np.array([any(a <= t <= b for a, b in ranges) for t in instant], dtype=bool)
    keep &= before >= 0
    return {k: np.asarray(est[k])[before[keep]] - ref[arrival[keep]] for k in FILTERS}


def speed_errors(log: str, cfg: Config, ranges: Sequence[tuple[float, float]]
                 ) -> dict[str, float | None]:
    """The RMS (m/s) of each filter's :func:`prediction_errors` (None where it predicted
    none)."""
    rms = {k: M.rms(d) for k, d in prediction_errors(log, cfg, ranges).items()}
    return {k: v if math.isfinite(v) else None for k, v in rms.items()}


def with_layer(cfg: Config, layer: dict[str, Any]) -> Config:
    """``cfg`` with the TOML tables ``layer`` applied on top."""
    return from_dict(merge(to_dict(cfg), layer), "<overlay section>")


def _worse(before: dict[str, float | None], after: dict[str, float | None]) -> list[str]:
    """The filters whose :func:`speed_errors` ``after`` is more than :data:`TIE_MPS` above
    ``before``, or that stopped predicting."""
    out = []
    for k in FILTERS:
        b, a = before[k], after[k]
        if b is not None and (a is None or a > b + TIE_MPS):
            out.append(f"{k} {_f(b)} -> {_f(a)} m/s")
    return out


def _refusal(sec: Any, written: set[str]) -> str | None:
    """Why ``sec`` cannot be judged on the log: an implausible model, or a section it
    was fitted with refused; None when it can."""
    why = next((w for t, v in sec.tables.items() if (w := implausible(t, v))), None)
    if why is not None:
        return "implausible: " + why
    missing = [n for n in sec.needs if n not in written]
    if missing:
        return f"fitted with the {', '.join(missing)} section, which was not written"
    return None


def check(sections: Sequence[Any], log: str, cfg: Config, sel: Any) -> list[Verdict]:
    """A :class:`Verdict` per section with tables (see the module docstring)."""
    ranges = held_out_ranges(sel)
    todo = [s for s in sections if s.tables]
    current = cfg
    base_err: dict[str, float | None] | None = None
    written: set[str] = set()
    judged: set[str] = set()
    out = []
    for i, sec in enumerate(todo):
        if sec.name in judged:
            continue  # judged with the section it was fitted on
        why = _refusal(sec, written)
        if why is not None:
            out.append(Verdict(sec.name, False, why))
            continue
        # the section with those fitted on it (the surge model on the re-mapped inputs):
        # either alone is a configuration nobody fitted
        group = [sec]
        for dep in todo[i + 1:]:
            if sec.name in dep.needs:
                why = _refusal(dep, written | {sec.name})
                if why is None:
                    group.append(dep)
                else:
                    out.append(Verdict(dep.name, False, why))
                judged.add(dep.name)
        names = [g.name for g in group]
        together = (f" ({' and '.join(names)} judged together, the one fitted on the "
                    "other)" if len(group) > 1 else "")
        try:
            cand = current
            for g in group:
                cand = with_layer(cand, g.layer())
        except ValueError as err:
            out.extend(Verdict(n, False, f"invalid configuration: {err}") for n in names)
            continue
        if sec.name in JUDGED_BY_DIAGNOSIS:
            out.extend(Verdict(n, True, JUDGED_BY_DIAGNOSIS[sec.name]) for n in names)
            written.update(names)
            current = cand
            base_err = None
            continue
        if not ranges:
            out.extend(Verdict(n, False, "no test part to replay") for n in names)
            continue
        if base_err is None:
            base_err = speed_errors(log, current, ranges)
        err = speed_errors(log, cand, ranges)
        worse = _worse(base_err, err)
        if worse:
            out.extend(Verdict(n, False, "raises the test-part speed error: "
                               + "; ".join(worse) + together, dict(base_err), err)
                       for n in names)
            continue
        out.extend(Verdict(n, True, "does not raise the test-part speed error of aie or "
                           "kf" + together, dict(base_err), err) for n in names)
        written.update(names)
        current, base_err = cand, err
    order = {s.name: k for k, s in enumerate(todo)}
    return sorted(out, key=lambda v: order[v.section])


def record(doc: dict, verdicts: Sequence[Verdict], out_dir: Path) -> dict:
    """``doc`` with ``overlay_check`` (a :meth:`Verdict.as_dict` per section), written
    again as ``out_dir/diagnosis.json`` (architecture.md §4.3); returned."""
    clean = [{**v.as_dict(), **{k: {f: (None if x is None or not math.isfinite(x) else x)
                                    for f, x in v.as_dict()[k].items()}
                                for k in ("speed_rmse_before_mps", "speed_rmse_after_mps")}}
             for v in verdicts]
    doc = {**doc, "overlay_check": clean}
    (Path(out_dir) / "diagnosis.json").write_text(json.dumps(doc, indent=2) + "\n")
    return doc
