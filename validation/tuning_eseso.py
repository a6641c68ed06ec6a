"""The common tuning protocol (:mod:`validation.tuning`) applied to the ESESO's thrust noise.

The ESESO's thrust update runs at the actuator's rate (once per thruster command, issue
29), so the two noises that set its gain on the lumped disturbance ``xi`` are tuned
again, by the protocol every other filter is tuned by (same optimizer, budget, simplex,
tuning seed and held-out seeds; :mod:`validation.tuning`):

* **Parameters** (:data:`PARAMS`, ``log10`` inside fixed bounds): ``noise.thrust_std_n``,
  the thrusters' own force error in the thrust update's noise, and
  ``process.disturbance_walk_n_rts``, the random walk of ``xi`` between updates.
  ``process.thrust_rel_std`` stays 0.05: it is set by the closed loop (docs/eseso-mpc.md),
  and the published sigma's calibration no longer depends on it (the excess the thrust
  innovations show, ``EsesoFilter.disturbance_excess``).
* **Tuning runs**: ``bluerov2-circle`` through ``sitl.runner`` (its PID) in the mismatch
  cases :data:`TUNING_CASES` (the nominal plant, thrust -25 %, a 0.15 s thruster lag: a
  filter tuned where its model is exact trusts the model), seed
  :data:`validation.tuning.TUNING_SEEDS`, the first
  :data:`validation.tuning.TUNING_DURATION_S` s, each simulated once.
* **Objective** (dimensionless, lower is better): over the tuning runs, the mean of the
  disturbance's RMSE against the true lumped disturbance
  (:func:`validation.reports.eseso_calibration.lumped_truth`, mean of the three body axes)
  over :data:`DIST_SCALE`, plus ``COVERAGE_WEIGHT`` times how far the published
  disturbance sigma's 2-sigma coverage (mean of the axes) falls below ``COVERAGE_FLOOR``.
* **Evaluation**: the held-out seeds :data:`validation.tuning.HELD_OUT_SEEDS` of the
  tuning cases and the cases :data:`UNSEEN_CASES` the tuning never saw, whole runs
  (:data:`validation.reports.eseso_calibration.SECONDS`).

``python -m validation tune eseso [--budget N] [--out docs/tuning.json]`` runs it; the
results go under the file's ``eseso`` key.
"""

from __future__ import annotations

import functools
import json
import math
import sys
import time
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from validation import tuning
from validation.tuning import Param

PARAMS = (Param("noise.thrust_std_n", -2.0, 1.5),
          Param("process.disturbance_walk_n_rts", -2.0, 1.0))
"""The tuned keys of ``[pipelines.eseso]`` and the bounds of their ``log10``."""
THRUST_STD_OFF = 0.01
"""The start of ``noise.thrust_std_n`` (N) where its default, 0, has no log."""
TUNING_CASES = ("nominal", "thrust-25", "lag0.15")
"""The mismatch cases (:func:`validation.reports.eseso_calibration.cases`) tuned on."""
UNSEEN_CASES: dict[str, tuple[int, ...]] = {"off-design": (1,), "noise2x": (1,),
                                            "damping-30": (1,)}
"""Cases the tuning never saw, and their seeds."""
DIST_SCALE = 1.0
"""The objective's disturbance unit (N): about the thrust model's noise on one axis."""
DIST_COLUMNS = ("dist_x", "dist_y", "dist_z")


def start_point() -> list[float]:
    """``log10`` of the shipped defaults, clipped to the bounds."""
    from onboard.core.pipeline_config import EsesoConfig

    cfg = EsesoConfig()
    out = []
    for p in PARAMS:
        table, key = p.key.split(".")
        v = float(getattr(getattr(cfg, table), key)) or THRUST_STD_OFF
        out.append(min(max(math.log10(v), p.lo), p.hi))
    return out


@functools.cache
def simulated(case: str, seed: int, seconds: float) -> tuple[Any, ...]:
    """The simulator's steps of ``case``, flown once per process."""
    from validation.reports.eseso_calibration import simulate_case

    return tuple(simulate_case(case, seed, seconds))


def run(values: Mapping[str, float], case: str, seed: int, seconds: float) -> dict[str, Any]:
    """The ESESO of ``config/bluerov2.toml`` with ``values`` (dotted keys of its table)
    over ``case`` (:func:`validation.reports.eseso_calibration.fly`)."""
    import msgspec

    from onboard.core import config as config_mod
    from validation.reports.eseso_calibration import fly

    data = msgspec.to_builtins(config_mod.load("bluerov2"))
    over: dict[str, Any] = {}
    for k, v in values.items():
        table, key = k.split(".")
        over.setdefault(table, {})[key] = float(v)
    data["pipelines"]["eseso"] = tuning.merged(data["pipelines"].get("eseso", {}), over)
    return fly(config_mod.from_dict(data), case, simulated(case, seed, seconds))


def metrics(r: Mapping[str, Any]) -> dict[str, float]:
    """Disturbance RMSE (N, mean of the axes) and the 1-/2-sigma coverage of its published
    sigma (mean of the axes) of one :func:`run`."""
    out = {"dist": 0.0, "dist_cover1": 0.0, "dist_cover2": 0.0}
    for col in DIST_COLUMNS:
        e, s = r["errors"][col], r["sigma"][col]
        z = np.abs(e) / np.maximum(s, 1e-12)
        out["dist"] += float(np.sqrt(np.mean(e * e))) / len(DIST_COLUMNS)
        out["dist_cover1"] += float(np.mean(z <= 1.0)) / len(DIST_COLUMNS)
        out["dist_cover2"] += float(np.mean(z <= 2.0)) / len(DIST_COLUMNS)
    return out


def score(m: Mapping[str, float]) -> float:
    """The objective of one run's :func:`metrics` (module docstring)."""
    pen = max(0.0, tuning.COVERAGE_FLOOR - m["dist_cover2"])
    return m["dist"] / DIST_SCALE + tuning.COVERAGE_WEIGHT * pen


def objective(values: Mapping[str, float]) -> float:
    """The mean :func:`score` over the tuning runs (non-finite: ``inf``)."""
    scores = [score(metrics(run(values, case, seed, tuning.TUNING_DURATION_S)))
              for case in TUNING_CASES for seed in tuning.TUNING_SEEDS]
    v = float(np.mean(scores))
    return v if math.isfinite(v) else math.inf


def _values(x: Any) -> dict[str, float]:
    return {p.key: float(10.0 ** v) for p, v in zip(PARAMS, x)}


def tune(budget: int = tuning.BUDGET, log: Any = sys.stderr) -> dict[str, Any]:
    """Nelder-Mead on the ``log10`` parameters from the shipped defaults, at most
    ``budget`` evaluations (:func:`validation.tuning.tune`'s settings)."""
    from scipy.optimize import minimize

    x0 = np.asarray(start_point())
    n = len(x0)
    simplex = np.vstack([x0] + [x0 + tuning.SIMPLEX_STEP * np.eye(n)[i] for i in range(n)])
    for i, p in enumerate(PARAMS):
        if simplex[i + 1, i] > p.hi:
            simplex[i + 1, i] = x0[i] - tuning.SIMPLEX_STEP
    t0, calls = time.monotonic(), [0]

    def f(x: np.ndarray) -> float:
        calls[0] += 1
        v = objective(_values(x))
        print(f"  eseso [{calls[0]}] {np.round(x, 2).tolist()} -> {v:.4f}", file=log,
              flush=True)
        return v

    f0 = f(x0)
    res = minimize(f, x0, method="Nelder-Mead", bounds=[(p.lo, p.hi) for p in PARAMS],
                   options={"maxfev": budget - 1, "initial_simplex": simplex,
                            "xatol": 0.02, "fatol": 1e-4})
    best = res.x if res.fun <= f0 else x0
    return {"params": _values(best), "tuned": True, "start": _values(x0),
            "objective_start": f0, "objective": float(min(res.fun, f0)),
            "evaluations": calls[0], "wall_s": round(time.monotonic() - t0, 1)}


def evaluate(values: Mapping[str, float]) -> dict[str, dict[str, float]]:
    """:func:`metrics` per ``<case>@<seed>`` on the held-out runs (module docstring)."""
    from validation.reports.eseso_calibration import SECONDS

    plan = [(c, s) for c in TUNING_CASES for s in tuning.HELD_OUT_SEEDS]
    plan += [(c, s) for c, seeds in UNSEEN_CASES.items() for s in seeds]
    return {f"{c}@{s}": metrics(run(values, c, s, SECONDS)) for c, s in plan}


def held_out_objective(ev: Mapping[str, Mapping[str, float]]) -> float:
    """The mean :func:`score` over the held-out runs: the figure by which tuned
    parameters replace the shipped defaults (lower wins)."""
    return float(np.mean([score(m) for m in ev.values()]))


def main(budget: int | None, out: Path | None, no_tune: bool) -> int:
    """Tune (unless ``no_tune``), evaluate the result and the shipped defaults on the
    held-out runs, print both, merge them under ``out``'s ``eseso`` key."""
    rec = {"params": {}, "tuned": False} if no_tune else tune(budget or tuning.BUDGET)
    rec["held_out"] = evaluate(rec["params"])
    rec["held_out_objective"] = held_out_objective(rec["held_out"])
    rec["protocol"] = {"cases": list(TUNING_CASES), "seeds": list(tuning.TUNING_SEEDS),
                       "duration_s": tuning.TUNING_DURATION_S, "budget": tuning.BUDGET,
                       "held_out_seeds": list(tuning.HELD_OUT_SEEDS),
                       "unseen": {k: list(v) for k, v in UNSEEN_CASES.items()},
                       "dist_scale": DIST_SCALE, "coverage_floor": tuning.COVERAGE_FLOOR,
                       "coverage_weight": tuning.COVERAGE_WEIGHT}
    if rec["params"]:
        rec["defaults_held_out"] = evaluate({})
        rec["defaults_held_out_objective"] = held_out_objective(rec["defaults_held_out"])
    print(json.dumps(rec, indent=1))
    if out:
        doc = json.loads(out.read_text(encoding="utf-8")) if out.exists() else {}
        doc["eseso"] = rec
        out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    return 0


ESESO = "eseso"
"""The name that runs the protocol on the ESESO's thrust noise (alone on the command line;
its results under the results file's ``eseso`` key)."""


def tune_command(args: Any) -> int:
    """``python -m validation tune``: ``eseso`` alone runs :func:`main`, every other
    variant :func:`validation.tuning.main` (``--list`` names both)."""
    if args.variants == [ESESO]:
        return main(args.budget, Path(args.out) if args.out else None, args.no_tune)
    status = tuning.main(args)
    if args.list or not args.variants:
        print(f"{ESESO:16s} the ESESO's thrust noise (validation/tuning_eseso.py)")
    return status
