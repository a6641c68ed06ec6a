"""One tuning protocol for the surge/heading filters (``aie``, ``kf`` and their ablations).

Every filter is tuned the same way, so that a comparison between them credits the
method, not the care spent on its noise settings (issue 23, item 1):

* **Parameters**: each variant's noise and adaptation parameters (:data:`VARIANTS`:
  ``v_d`` of both axes, and the AIE's RCIE penalty ``r_d`` or the KF's input-bias walk
  ``bias_q``), searched as ``log10`` values inside fixed bounds (:class:`Param`).
* **Optimizer**: ``scipy.optimize.minimize(method="Nelder-Mead")`` from the shipped
  defaults, with a fixed budget of :data:`BUDGET` objective evaluations per variant
  (each evaluation is :data:`TUNING_RUNS` simulator runs; a few minutes per variant on
  one core).
* **Tuning runs**: :data:`TUNING_SCENARIOS` on seeds :data:`TUNING_SEEDS`, the first
  :data:`TUNING_DURATION_S` s, each simulated once and replayed through the engine
  with the candidate pipeline alone.
* **Objective** (dimensionless, lower is better): over the tuning runs, the mean of the
  speed RMSE against simulator truth over the Doppler noise :data:`SPEED_SCALE` plus
  the heading RMSE over the compass noise :data:`HEADING_SCALE` (ticks after
  :data:`METRIC_AFTER_S` s), plus :data:`COVERAGE_WEIGHT` times how far the published
  speed and heading sigmas' 2-sigma coverage falls below :data:`COVERAGE_FLOOR` (a
  tuning that buys RMSE with an overconfident sigma pays for it).
* **Evaluation**: the tuned parameters on held-out seeds :data:`HELD_OUT_SEEDS` of the
  tuning scenarios (whole runs) and on :data:`UNSEEN_SCENARIOS`, which the tuning never
  saw: RMSE and 1-/2-sigma coverage of speed and heading (:func:`evaluate`).

``python -m validation tune VARIANT... [--budget N] [--out FILE]`` runs it (``python -m
validation tune --list``); docs/aie.md section 2.1 holds the ablation table it produced
(its template ``validation/templates/docs/aie.md`` filled from :func:`records`) and says
which defaults came from it.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from onboard.core.errors import UsageError
from validation import render

TUNING_SCENARIOS = ("jaiabot-turns", "twin-thruster-turns", "effect-waves")
"""The scenarios the parameters are tuned on: the AIE paper's boat, a skid-steered one,
and a rudder boat in undeclared waves (without a disturbance the model lacks, the search
trusts the model to the point of failing in one: tuned on the first two alone, the speed
RMSE on effect-waves rose from 0.063 to 0.075 m/s for the AIE, 0.049 to 0.071 for the
KF, above the raw speed's 0.073)."""
TUNING_SEEDS = (10,)
"""Their sensor-noise seeds in the tuning (the figures are measured on 1-3)."""
TUNING_DURATION_S = 150.0
"""Simulated seconds of each tuning run."""
TUNING_RUNS = len(TUNING_SCENARIOS) * len(TUNING_SEEDS)
"""Simulator runs per objective evaluation."""
BUDGET = 60
"""Objective evaluations per variant (the same for every variant)."""
HELD_OUT_SEEDS = (1, 2, 3)
"""Seeds of the tuning scenarios the evaluation uses (whole runs)."""
UNSEEN_SCENARIOS: dict[str, tuple[int, ...]] = {
    "effect-thrust-nonlinearity": (1,), "effect-surge-yaw-coupling": (1,),
    "effect-current": (1,)}
"""Scenarios the tuning never saw (rudder-boat config, the scenario's duration) and
their seeds."""
METRIC_AFTER_S = 30.0
"""RMSE and coverage are taken over the ticks after this many seconds (s)."""
SPEED_SCALE = 0.1
"""The objective's speed unit (m/s): the simulated Doppler speed's noise."""
HEADING_SCALE = 0.03
"""The objective's heading unit (rad): the simulated compass noise."""
COVERAGE_FLOOR = 0.90
"""Least 2-sigma coverage of the published speed and heading sigmas without penalty."""
COVERAGE_WEIGHT = 10.0
"""Penalty per unit of 2-sigma coverage below :data:`COVERAGE_FLOOR`."""
SIMPLEX_STEP = 0.5
"""Initial simplex of Nelder-Mead: each parameter moved by this many decades."""

TUNING_FILE = Path(__file__).resolve().parents[1] / "docs" / "tuning.json"
"""The committed results of the protocol (docs/aie.md section 2.1 is rendered from it)."""

SCENARIO_CONFIG = {"jaiabot-turns": "rudder-boat", "twin-thruster-turns": "twin-thruster-boat"}
"""The bundled vehicle config of each scenario (else ``rudder-boat``)."""


# ----------------------------------------------------------------------------- variants


@dataclass(frozen=True)
class Param:
    """One tuned parameter: its dotted key in the pipeline's table (``surge.v_d``) and
    the bounds of its ``log10``."""

    key: str
    lo: float
    hi: float


V_D = (Param("surge.v_d", -4.0, 1.0), Param("heading.v_d", -4.0, 1.0))
R_D = (Param("surge.r_d", -2.0, 3.0), Param("heading.r_d", -2.0, 3.0))
BIAS_Q = (Param("surge.bias_q", -6.0, 0.0), Param("heading.bias_q", -6.0, 0.0))
BIAS_OFF = 1e-6
"""The start of ``bias_q`` where the default has no bias state (``0`` has no log)."""
FROZEN_R_D = 1e9
"""``r_d`` that freezes RCIE: its input estimate stays at zero."""


@dataclass(frozen=True)
class Variant:
    """A filter under test: its pipeline, what it credits, the settings that make it
    (``fixed``, merged into the pipeline's table) and the parameters tuned."""

    pipeline: str
    cause: str
    params: tuple[Param, ...]
    fixed: Mapping[str, Any] = field(default_factory=dict)


VARIANTS: dict[str, Variant] = {
    "kf-no-doppler": Variant(
        "kf", "KF on the position increments alone (the paper's filter; no Doppler row, "
        "so the bias state is never updated)", V_D, {"gnss_velocity": False}),
    "kf-no-bias": Variant(
        "kf", "KF with the Doppler row, nominal thrust map, no input-bias state", V_D,
        {"surge": {"bias_q": 0.0}, "heading": {"bias_q": 0.0}}),
    "kf-no-imu": Variant(
        "kf", "KF with the Doppler row and the bias state, no accelerometer between fixes",
        V_D + BIAS_Q, {"imu_aiding": False}),
    "kf": Variant("kf", "KF as shipped: Doppler row, bias state, accelerometer",
                  V_D + BIAS_Q),
    "aie-no-doppler": Variant(
        "aie", "AIE on the position increments alone (no Doppler row)", V_D + R_D,
        {"gnss_velocity": False}),
    "aie-pure": Variant(
        "aie", "the paper's AIE: no commands (known_input = false), RCIE learns the "
        "whole input", V_D + R_D,
        {"surge": {"known_input": False}, "heading": {"known_input": False}}),
    "aie-frozen": Variant(
        "aie", "nominal thrust map, RCIE frozen (r_d = 1e9): the KF without its bias "
        "state, in the AIE's code", V_D,
        {"surge": {"r_d": FROZEN_R_D}, "heading": {"r_d": FROZEN_R_D}}),
    "aie-no-imu": Variant(
        "aie", "AIE (nominal map + RCIE, Doppler row), no accelerometer between fixes",
        V_D + R_D, {"imu_aiding": False}),
    "aie": Variant("aie", "AIE as shipped: nominal map + RCIE, Doppler row, accelerometer",
                   V_D + R_D),
}
"""Every variant of docs/aie.md's ablation table, in its order."""


def merged(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` with ``over`` merged in, key by key, tables recursively."""
    out = dict(base)
    for k, v in over.items():
        out[k] = merged(out.get(k, {}), v) if isinstance(v, Mapping) else v
    return out


def table_of(params: Sequence[Param], x: Sequence[float]) -> dict[str, Any]:
    """The pipeline-table overrides of ``log10`` values ``x`` of ``params``."""
    out: dict[str, Any] = {}
    for p, v in zip(params, x):
        axis, key = p.key.split(".")
        out.setdefault(axis, {})[key] = float(10.0 ** v)
    return out


def start_point(variant: Variant) -> list[float]:
    """``log10`` of the shipped defaults of the variant's parameters (``bias_q = 0``
    starts at :data:`BIAS_OFF`; ``"auto"`` is the tuned value of the variant's
    measurement set: without a Doppler speed where it fixes ``gnss_velocity = false``),
    clipped to the bounds."""
    from onboard.core.pipeline_config import AieConfig, KfConfig

    cfg = AieConfig() if variant.pipeline == "aie" else KfConfig()
    doppler = bool(variant.fixed.get("gnss_velocity", True))
    out = []
    for p in variant.params:
        axis, key = p.key.split(".")
        v = getattr(cfg, axis).tuned(key, doppler)
        out.append(min(max(math.log10(v if v > 0 else BIAS_OFF), p.lo), p.hi))
    return out


# ----------------------------------------------------------------------------- runs


@functools.cache
def simulated(scenario: str, seed: int, duration: float | None) -> tuple[Any, ...]:
    """The simulator's ``(t, samples, truth)`` steps, flown once per process."""
    from onboard.sitl.runner import simulate

    return tuple(simulate(scenario, duration=duration, seed=seed))


def run(variant: Variant, table: Mapping[str, Any], scenario: str, seed: int,
        duration: float | None = None) -> Any:
    """The variant's pipeline with ``table`` merged into its settings, alone through the
    engine over a simulated run (``aie_validation.SitlRun``)."""
    import msgspec

    from onboard.core import config as config_mod
    from onboard.pipelines import aie as aie_mod
    from onboard.pipelines import kf as kf_mod
    from validation.reports.aie_validation import fly

    cfg = config_mod.load(SCENARIO_CONFIG.get(scenario, "rudder-boat"))
    data = msgspec.to_builtins(cfg)
    pipes = data["pipelines"]
    pipes[variant.pipeline] = merged(merged(pipes.get(variant.pipeline, {}),
                                            variant.fixed), table)
    cfg = config_mod.from_dict(data)
    pipe = (aie_mod if variant.pipeline == "aie" else kf_mod).create(cfg)
    assert pipe is not None
    return fly(scenario, cfg, [pipe], simulated(scenario, seed, duration))


def metrics(run_: Any, name: str, after_s: float = METRIC_AFTER_S) -> dict[str, float]:
    """Speed (m/s) and heading (rad) RMSE against truth of pipeline ``name`` after
    ``after_s``, the 1- and 2-sigma coverage of their published sigmas
    (``std_speed``, ``std_heading``), and the raw GNSS speed's RMSE (``raw_speed``)."""
    from onboard.core.geo import wrap_pi_array

    m = run_.t >= run_.t[0] + after_s
    e, tr = run_.est, run_.truth
    out: dict[str, float] = {}
    for q, err in (("speed", e[f"{name}.speed"] - tr["speed"]),
                   ("heading", wrap_pi_array(e[f"{name}.heading"] - tr["heading"]))):
        sd = e[f"{name}.std_{q}"]
        ok = m & np.isfinite(err) & np.isfinite(sd)
        out[q] = float(np.sqrt(np.mean(err[ok] ** 2)))
        z = np.abs(err[ok]) / sd[ok]
        out[f"{q}_cover1"], out[f"{q}_cover2"] = float(np.mean(z < 1)), float(np.mean(z < 2))
    raw = (e["nav.speed"] - tr["speed"])[m]
    raw = raw[np.isfinite(raw)]
    out["raw_speed"] = float(np.sqrt(np.mean(raw ** 2)))
    return out


def score(m: Mapping[str, float]) -> float:
    """The objective of one run's :func:`metrics` (module docstring)."""
    pen = sum(max(0.0, COVERAGE_FLOOR - m[f"{q}_cover2"]) for q in ("speed", "heading"))
    return m["speed"] / SPEED_SCALE + m["heading"] / HEADING_SCALE + COVERAGE_WEIGHT * pen


def objective(variant: Variant, table: Mapping[str, Any]) -> float:
    """The mean :func:`score` over the tuning runs (a non-finite result is ``inf``)."""
    total = 0.0
    for sc in TUNING_SCENARIOS:
        for seed in TUNING_SEEDS:
            r = run(variant, table, sc, seed, TUNING_DURATION_S)
            total += score(metrics(r, variant.pipeline))
    v = total / TUNING_RUNS
    return v if math.isfinite(v) else math.inf


# ----------------------------------------------------------------------------- tuning


@dataclass
class Tuned:
    """A tuning's outcome: the parameters (values, not logs), the objective at the
    start and at the end, the evaluations spent and the wall time (s)."""

    variant: str
    params: dict[str, float]
    start: dict[str, float]
    objective_start: float
    objective: float
    evaluations: int
    wall_s: float


def tune(name: str, budget: int = BUDGET, log: Any = sys.stderr) -> Tuned:
    """Nelder-Mead on the ``log10`` parameters of variant ``name`` from the shipped
    defaults, at most ``budget`` objective evaluations, inside the parameters' bounds."""
    from scipy.optimize import minimize

    variant = VARIANTS[name]
    x0 = np.asarray(start_point(variant))
    n = len(x0)
    simplex = np.vstack([x0] + [x0 + SIMPLEX_STEP * np.eye(n)[i] for i in range(n)])
    for i, p in enumerate(variant.params):   # step down where up leaves the bounds
        if simplex[i + 1, i] > p.hi:
            simplex[i + 1, i] = x0[i] - SIMPLEX_STEP
    t0, calls = time.monotonic(), [0]

    def f(x: np.ndarray) -> float:
        calls[0] += 1
        v = objective(variant, table_of(variant.params, x))
        print(f"  {name} [{calls[0]}] {np.round(x, 2).tolist()} -> {v:.4f}", file=log,
              flush=True)
        return v

    f0 = f(x0)
    res = minimize(f, x0, method="Nelder-Mead",
                   bounds=[(p.lo, p.hi) for p in variant.params],
                   options={"maxfev": budget - 1, "initial_simplex": simplex,
                            "xatol": 0.02, "fatol": 1e-4})
    best = res.x if res.fun <= f0 else x0
    return Tuned(name, _values(variant, best), _values(variant, x0), f0,
                 float(min(res.fun, f0)), calls[0], time.monotonic() - t0)


def _values(variant: Variant, x: Iterable[float]) -> dict[str, float]:
    return {p.key: float(10.0 ** v) for p, v in zip(variant.params, x)}


def _table(params: Mapping[str, float]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in params.items():
        axis, key = k.split(".")
        out.setdefault(axis, {})[key] = v
    return out


def evaluate(name: str, params: Mapping[str, float]) -> dict[str, dict[str, float]]:
    """Variant ``name`` with ``params`` on the held-out runs: :func:`metrics` per
    ``<scenario>@<seed>`` (whole runs of the tuning scenarios on
    :data:`HELD_OUT_SEEDS`, and :data:`UNSEEN_SCENARIOS`)."""
    variant, table = VARIANTS[name], _table(params)
    plan = [(sc, s) for sc in TUNING_SCENARIOS for s in HELD_OUT_SEEDS]
    plan += [(sc, s) for sc, seeds in UNSEEN_SCENARIOS.items() for s in seeds]
    return {f"{sc}@{s}": metrics(run(variant, table, sc, s), variant.pipeline)
            for sc, s in plan}


# ----------------------------------------------------------------------------- the table


TOKEN = re.compile(r"[^a-z0-9]+")


def token(name: str) -> str:
    """A variant's name as it appears in record names: ``aie (before)`` is
    ``aie_before``."""
    return TOKEN.sub("_", name.lower()).strip("_")


def _record(values: Mapping[str, float | None], digits: int | str) -> dict[str, Any]:
    return {"values": dict(values), "digits": digits}


def held_out_objective(ev: Mapping[str, Mapping[str, float]]) -> float:
    """The mean :func:`score` over the held-out runs of :func:`evaluate`: the figure by
    which tuned parameters replace the shipped defaults (lower wins)."""
    return float(np.mean([score(m) for m in ev.values()]))


def _groups(ev: Mapping[str, Any]) -> dict[str, list[str]]:
    """The held-out runs (``<scenario>@<seed>``) by tuning scenario (its name with
    underscores) and ``unseen``: the runs of :data:`UNSEEN_SCENARIOS`."""
    by = {sc: [k for k in ev if k.split("@")[0] == sc]
          for sc in (*TUNING_SCENARIOS, *UNSEEN_SCENARIOS)}
    out = {sc.replace("-", "_"): by[sc] for sc in TUNING_SCENARIOS}
    out["unseen"] = [k for sc in UNSEEN_SCENARIOS for k in by[sc]]
    return out


def variant_records(prefix: str, rec: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """The records of one variant's results (:func:`records`), named ``prefix.*``."""
    ev = rec["held_out"]
    groups = _groups(ev)
    out = {f"{prefix}.speed.{g}": _record({k: ev[k]["speed"] for k in keys}, 3)
           for g, keys in groups.items()}
    for sc in TUNING_SCENARIOS:
        keys = groups[sc.replace("-", "_")]
        mean = float(np.mean([ev[k]["heading"] for k in keys])) if keys else None
        out[f"{prefix}.heading_mean.{sc.replace('-', '_')}"] = _record({"mean": mean}, 4)
    for q in ("speed_cover1", "speed_cover2", "heading_cover1", "heading_cover2"):
        out[f"{prefix}.{q}"] = _record({k: m[q] for k, m in ev.items()}, 2)
    out[f"{prefix}.held_out_objective"] = _record({"-": held_out_objective(ev)}, 3)
    out |= {f"{prefix}.param.{k}": _record({"-": v}, "2g") for k, v in rec["params"].items()}
    return out


def records(doc: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """The ablation table's figures of a results file, as the records the template of
    docs/aie.md reads (``validation/render.py``). Per variant ``V`` (:func:`token`):

    * ``tuning.V.speed.S``: speed RMSE (m/s) on each held-out run of tuning scenario
      ``S`` (``jaiabot_turns``, ...), ``tuning.V.speed.unseen`` on the unseen ones;
    * ``tuning.V.heading_mean.S``: heading RMSE (rad), mean over the held-out runs of ``S``
      (``null`` without one);
    * ``tuning.V.speed_cover1`` (``_cover2``, ``heading_cover1``, ``heading_cover2``):
      the coverage of the published sigma on each held-out run;
    * ``tuning.V.held_out_objective``: :func:`held_out_objective`;
    * ``tuning.V.param.KEY``: the tuned parameter ``KEY`` (``surge.v_d``; 2 significant
      digits);

    and ``tuning.raw_speed.S`` / ``.unseen``: the raw GNSS speed's RMSE on the held-out
    runs (every variant flies the same runs; taken from the first variant in
    :data:`VARIANTS` order)."""
    res = doc["variants"]
    names = [n for n in VARIANTS if n in res] + [n for n in res if n not in VARIANTS]
    out: dict[str, dict[str, Any]] = {}
    for name in names:
        prefix = f"tuning.{token(name)}"
        if f"{prefix}.held_out_objective" in out:
            raise UsageError(f"variants {name} and another share the record names {prefix}")
        out |= variant_records(prefix, res[name])
    if names:
        ev = res[names[0]]["held_out"]
        out |= {f"tuning.raw_speed.{g}": _record({k: ev[k]["raw_speed"] for k in keys}, 3)
                for g, keys in _groups(ev).items()}
    return out


def update_page(path: Path, doc: Mapping[str, Any]) -> bool:
    """Rewrite the page's ablation block (the template's ``tuning`` block of the page of
    the same name, ``validation/templates/docs/aie.md``) from ``doc``; True when it
    changed."""
    template = render.DOCS_TEMPLATES / path.name
    return bool(render.update_page(path, template, "tuning", records(doc)))


def summary(doc: Mapping[str, Any]) -> list[str]:
    """One line per record of ``doc`` (:func:`records`): its name and value, printed as
    the table prints it."""
    recs = records(doc)
    w = max((len(n) for n in recs), default=0)
    return [f"{n:{w}s}  {render.format_value(r)}" for n, r in recs.items()]


# ----------------------------------------------------------------------------- command


def main(args: argparse.Namespace) -> int:
    """``python -m validation tune [--list] [--budget N] [--out FILE] [--no-tune]
    [--page FILE] VARIANT...``: tune each variant (:func:`tune`), evaluate it
    (:func:`evaluate`), print its table figures (:func:`summary`), merge the results into
    ``--out`` (JSON) and rewrite the ablation table of ``--page`` from it (``--page``
    alone: from docs/tuning.json)."""
    if args.page and not args.variants:
        update_page(Path(args.page), json.loads(Path(args.out or TUNING_FILE).read_text(
            encoding="utf-8")))
        return 0
    if args.list or not args.variants:
        for n, v in VARIANTS.items():
            print(f"{n:16s} {v.pipeline:4s} {', '.join(p.key for p in v.params):40s} "
                  f"{v.cause}")
        return 0
    bad = [v for v in args.variants if v not in VARIANTS]
    if bad:
        raise UsageError(f"unknown variant(s) {', '.join(bad)} (python -m validation tune --list)")
    out = Path(args.out) if args.out else None
    doc: dict[str, Any] = (json.loads(out.read_text(encoding="utf-8"))
                           if out and out.exists() else {})
    doc["protocol"] = protocol()
    results = doc.setdefault("variants", {})
    for name in args.variants:
        if args.no_tune:
            rec: dict[str, Any] = {"params": {}, "tuned": False}   # the shipped defaults
        else:
            t = tune(name, args.budget or BUDGET)
            rec = {"params": t.params, "tuned": True, "start": t.start,
                   "objective_start": t.objective_start, "objective": t.objective,
                   "evaluations": t.evaluations, "wall_s": round(t.wall_s, 1)}
        rec["held_out"] = evaluate(name, rec["params"])
        results[name] = rec
        print(f"{name}: {json.dumps({k: v for k, v in rec.items() if k != 'held_out'})}")
        if out:
            out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    print("\n".join(summary({"variants": {n: results[n] for n in args.variants}})))
    if args.page:
        if not out:
            raise UsageError("--page needs --out (the table is rendered from that file)")
        changed = update_page(Path(args.page), doc)
        print(f"{args.page}: ablation table {'rewritten' if changed else 'unchanged'}")
    return 0


def protocol() -> dict[str, Any]:
    """The protocol's settings, as written beside the results."""
    return {"scenarios": list(TUNING_SCENARIOS), "seeds": list(TUNING_SEEDS),
            "duration_s": TUNING_DURATION_S, "budget": BUDGET,
            "held_out_seeds": list(HELD_OUT_SEEDS),
            "unseen": {k: list(v) for k, v in UNSEEN_SCENARIOS.items()},
            "after_s": METRIC_AFTER_S, "speed_scale": SPEED_SCALE,
            "heading_scale": HEADING_SCALE, "coverage_floor": COVERAGE_FLOOR,
            "coverage_weight": COVERAGE_WEIGHT}

