"""The model-mismatch campaign: every estimator and controller against a perturbed plant.

Run ``python -m validation.reports.mismatch --seeds 1 2 3 --out docs/mismatch.md``: for
each :mod:`sitl.mismatch` case (the plant perturbed, the estimators and controllers told
the nominal vehicle and the nominal sensor noise) and each seed it runs

* ``bluerov2-circle`` in closed loop (:func:`sitl.closed_loop.simulate`, the ESESO in the
  onboard engine) with the PID, the plain NMPC, the offset-free NMPC (``nmpc-of``) and the
  AMPC: tracking RMSE (true position against the circle), the ESESO's disturbance error
  against the push and velocity error, and the mean NIS of every ESESO update channel
  (from the AMPC run);
* ``gavia-tidal`` through the engine with the ``current`` pipeline (KF, model (a): the
  model identified by the pipeline on the *nominal* plant in calm water, as
  :mod:`validation.reports.current_validation` does): horizontal current RMS error and
  the mean NIS of the velocity updates (channels ``velocity`` and ``dvl``);
* ``jaiabot-turns`` through the engine with the ``aie`` and ``kf`` pipelines: speed RMSE
  against the true speed, and the mean NIS of the surge and heading increment updates.

Mean NIS is compared with the two-sided 95 % band of the mean of ``n`` chi-square(dim)
values (``n * mean ~ chi2(n dim)``). Every pipeline's NIS is taken from its innovation
records (the engine's :meth:`~onboard.monitor.innovations.InnovationMonitor.keep`), one value per
update, gated updates included, keyed ``<pipeline>.<channel>``.

The tables are written between the markers ``<!-- mismatch:begin -->`` and
``<!-- mismatch:end -->`` of ``--out`` (the rest of the file is kept), with the seeds, the
durations and the date. ``--json`` also dumps every run's figures.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import sys
from functools import cache
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from onboard.core.geo import wrap_pi_array
from onboard.core.messages import EstimateRecord
from onboard.core.stats import chi2_mean_band

CONTROLLERS = ("pid", "nmpc", "nmpc-of", "ampc")
BEGIN = "<!-- mismatch:begin -->"
END = "<!-- mismatch:end -->"


def _rms(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if x.size else math.nan


# --------------------------------------------------------------------------- BlueROV2


def rov_run(controller: str, case: str, seed: int, duration: float) -> dict[str, Any]:
    """One closed-loop circle under the push: tracking RMSE (m), disturbance error RMS
    against the push (N), ESESO velocity RMSE (m/s) and the ESESO's NIS per channel.

    Args:
        controller: ``pid``, ``nmpc``, ``nmpc-of`` or ``ampc``.
        case: a :mod:`sitl.mismatch` case name.
        seed: sensor noise seed.
        duration: simulated seconds (metrics after 10 s).
    """
    from onboard.sitl.closed_loop import simulate

    rep, _ = simulate(controller, duration=duration, seed=seed, mismatch=case,
                      collect_nis=True)
    return {"tracking_rmse_m": rep["tracking_rmse_m"],
            "disturbance_error_n": rep["disturbance_error_n"],
            "velocity_rmse_mps": rep["eseso"]["velocity_rmse_mps"],
            "nis": rep.get("nis", {})}


# --------------------------------------------------------------------------- engine runs


def _keep_innovations(engine: Any, pipes: Sequence[Any]) -> Callable[[], dict[str, Any]]:
    """Keep every innovation record of ``pipes`` in ``engine``; returns the function that
    gives their mean NIS per ``<pipeline>.<channel>`` (:func:`sitl.closed_loop.mean_nis`)."""
    from onboard.sitl.closed_loop import mean_nis

    kept = {p.name: engine.monitor.keep(p.name) for p in pipes}
    return lambda: {f"{name}.{ch}": v for name, records in kept.items()
                    for ch, v in mean_nis(records).items()}


@cache
def gavia_model() -> tuple[tuple[str, tuple[tuple[str, float], ...]], ...]:
    """The current pipeline's model (a) for gavia-tidal, identified on the nominal plant in
    calm water (:func:`validation.reports.current_validation.calm_model`), as a
    hashable tuple."""
    from validation.reports.current_validation import calm_model

    m = calm_model("gavia-tidal", "torpedo-auv")
    return tuple((k, tuple(sorted(v.items()))) for k, v in m.items())


def gavia_run(case: str, seed: int, duration: float, after: float = 60.0) -> dict[str, Any]:
    """gavia-tidal with the plant perturbed by ``case``; the current KF with the nominal
    model (a). Horizontal current RMS error (m/s) after ``after`` s and the velocity NIS.

    Args:
        case: a :mod:`sitl.mismatch` case name.
        seed: sensor noise seed.
        duration: simulated seconds.
        after: start of the error window (s).
    """
    from onboard.engine import Engine
    from onboard.pipelines import current as current_mod
    from validation.reports.current_validation import make_config
    from onboard.sitl.mismatch import perturb_scenario
    from onboard.sitl.runner import simulate

    model = {k: dict(v) for k, v in gavia_model()}
    cfg = make_config("torpedo-auv", {"model": model})
    pipe = current_mod.create(cfg)
    eng = Engine(cfg, pipelines=[pipe])
    nis = _keep_innovations(eng, [pipe])
    rate = cfg.engine.rate_hz
    next_tick: float | None = None
    truth_now = None
    err: list[float] = []
    for t, samples, truth in simulate(perturb_scenario("gavia-tidal", case),
                                      duration=duration, seed=seed):
        if truth is not None:
            truth_now = truth
        if next_tick is None:
            next_tick = t
        while t >= next_tick - 1e-9:
            recs = eng.tick(next_tick)
            if recs and truth_now is not None and next_tick >= after:
                v = recs[0].values
                e = math.hypot(v.get("north", math.nan) - truth_now.current_north,
                               v.get("east", math.nan) - truth_now.current_east)
                err.append(e)
            next_tick += 1.0 / rate
        for s in samples:
            eng.push(s)
    return {"current_rms_mps": _rms(np.asarray(err)),
            "published": float(np.mean(np.isfinite(err))) if err else 0.0,
            "nis": nis()}


def boat_run(case: str, seed: int, duration: float, after: float = 30.0) -> dict[str, Any]:
    """jaiabot-turns with the plant perturbed by ``case``; the AIE and KF pipelines with the
    bundled ``rudder-boat`` config. Speed RMSE (m/s) and heading RMSE (rad) after
    ``after`` s, and the surge and heading NIS of both.

    Args:
        case: a :mod:`sitl.mismatch` case name.
        seed: sensor noise seed.
        duration: simulated seconds.
        after: start of the error window (s).
    """
    from onboard.core import config as config_mod
    from onboard.engine import Engine
    from onboard.pipelines import aie as aie_mod
    from onboard.pipelines import kf as kf_mod
    from onboard.sitl.mismatch import perturb_scenario
    from onboard.sitl.runner import engine_ticks, simulate

    cfg = config_mod.load("rudder-boat")
    pa, pk = aie_mod.create(cfg), kf_mod.create(cfg)
    if pa is None or pk is None:
        raise RuntimeError("the aie and kf pipelines do not apply to config/rudder-boat.toml")
    eng = Engine(cfg, pipelines=[pa, pk])
    nis = _keep_innovations(eng, [pa, pk])
    speed: dict[str, list[float]] = {"aie": [], "kf": []}
    heading: dict[str, list[float]] = {"aie": [], "kf": []}
    steps = simulate(perturb_scenario("jaiabot-turns", case), duration=duration, seed=seed)
    for t, records, truth in engine_ticks(eng, steps):
        recs: dict[str, EstimateRecord] = {r.pipeline: r for r in records}
        if t < after:
            continue
        true_speed = math.copysign(math.hypot(truth.u, truth.v), truth.u)
        for p in ("aie", "kf"):
            v = recs[p].values if p in recs else {}
            speed[p].append(v.get("speed", math.nan) - true_speed)
            heading[p].append(float(wrap_pi_array(np.array([v.get("heading", math.nan)
                                                            - truth.yaw]))[0]))
    return {"speed_rmse_mps": {p: _rms(np.asarray(v)) for p, v in speed.items()},
            "heading_rmse_rad": {p: _rms(np.asarray(v)) for p, v in heading.items()},
            "nis": nis(),
            "noise_std": {p.name: {k.removeprefix("noise.").removesuffix(".std"): v
                                   for k, v in p.health().flat().items()
                                   if k.startswith("noise.") and k.endswith(".std")}
                          for p in (pa, pk)}}


# --------------------------------------------------------------------------- campaign


def pooled_nis(runs: Sequence[dict[str, Any]], channel: str) -> dict[str, float] | None:
    """Mean NIS of ``channel`` pooled over runs (weighted by their update counts), its
    count, dimension and 95 % band; None when no run has the channel.

    Args:
        runs: per-seed results with a ``nis`` mapping.
        channel: the channel's key in ``nis``.
    """
    items = [r["nis"][channel] for r in runs if channel in r.get("nis", {})]
    if not items:
        return None
    n = sum(int(i["n"]) for i in items)
    mean = sum(i["mean"] * i["n"] for i in items) / max(n, 1)
    dim = int(items[0]["dim"])
    lo, hi = chi2_mean_band(n, dim)
    return {"mean": mean, "n": n, "dim": dim, "lo": lo, "hi": hi}


def run_campaign(cases: Sequence[str], seeds: Sequence[int], rov_s: float, gavia_s: float,
                 boat_s: float, parts: Sequence[str] = ("rov", "gavia", "boat"),
                 log: Callable[[str], None] = lambda s: None) -> dict[str, Any]:
    """Every run of the campaign: ``{part: {case: [per-seed result, ...]}}`` (the BlueROV2
    part per controller: ``{"rov": {case: {controller: [...]}}}``).

    Args:
        cases: :mod:`sitl.mismatch` case names.
        seeds: sensor noise seeds.
        rov_s: BlueROV2 circle duration (s).
        gavia_s: gavia-tidal duration (s).
        boat_s: jaiabot-turns duration (s).
        parts: which of ``rov``, ``gavia``, ``boat`` to run.
        log: progress sink (one line per run).
    """
    out: dict[str, Any] = {p: {} for p in parts}
    for case in cases:
        for seed in seeds:
            if "rov" in parts:
                for c in CONTROLLERS:
                    r = rov_run(c, case, seed, rov_s)
                    out["rov"].setdefault(case, {}).setdefault(c, []).append(r)
                    log(f"rov {case} {c} seed {seed}: tracking {r['tracking_rmse_m']:.3f} m,"
                        f" disturbance {r['disturbance_error_n']:.2f} N")
            if "gavia" in parts:
                r = gavia_run(case, seed, gavia_s)
                out["gavia"].setdefault(case, []).append(r)
                log(f"gavia {case} seed {seed}: current {r['current_rms_mps']:.3f} m/s")
            if "boat" in parts:
                r = boat_run(case, seed, boat_s)
                out["boat"].setdefault(case, []).append(r)
                log(f"boat {case} seed {seed}: speed aie {r['speed_rmse_mps']['aie']:.3f} "
                    f"kf {r['speed_rmse_mps']['kf']:.3f} m/s")
    return out


def ampc_against_offset_free(per: dict[str, list[dict[str, Any]]],
                             margin: float = 0.02) -> tuple[int, int]:
    """Seeds where the AMPC's tracking RMSE is below / above the offset-free NMPC's by more
    than ``margin`` (relative); the others are ties.

    Args:
        per: one case's BlueROV2 runs, ``{controller: [per-seed result, ...]}``.
        margin: relative difference that counts.
    """
    pairs = [(a["tracking_rmse_m"], b["tracking_rmse_m"])
             for a, b in zip(per["ampc"], per["nmpc-of"])]
    better = sum(a < (1.0 - margin) * b for a, b in pairs)
    worse = sum(a > (1.0 + margin) * b for a, b in pairs)
    return better, worse


def _mean(xs: Sequence[float]) -> float:
    v = [x for x in xs if math.isfinite(x)]
    return float(np.mean(v)) if v else math.nan


def _f(x: float, nd: int = 3) -> str:
    return f"{x:.{nd}f}" if math.isfinite(x) else "-"


def _nis_cell(p: dict[str, float] | None) -> str:
    if p is None:
        return "-"
    mark = "" if p["lo"] <= p["mean"] <= p["hi"] else (" ↑" if p["mean"] > p["hi"] else " ↓")
    return f"{p['mean']:.2f}{mark}"


def tables(res: dict[str, Any], seeds: Sequence[int], durations: dict[str, float]) -> str:
    """The markdown tables of a campaign (means over the seeds; NIS pooled)."""
    from onboard.sitl.mismatch import get

    date = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d")
    lines = [f"Generated by `python -m validation.reports.mismatch` on {date}, seeds "
             f"{', '.join(str(s) for s in seeds)}; figures are means over the seeds, NIS is "
             "pooled over them (↑ above, ↓ below the 95 % band of its mean; no mark: "
             "inside).", ""]
    rov = res.get("rov")
    if rov:
        lines += [f"### BlueROV2 circle under the push ({durations['rov']:.0f} s, metrics "
                  "after 10 s)", "",
                  "Tracking RMSE (m) per controller, the AMPC's ratio to the offset-free "
                  "NMPC, and the ESESO (AMPC run): disturbance error against the push (N), "
                  "velocity RMSE (m/s), mean NIS per channel (dimension).", "",
                  "| case | plant | PID | NMPC | NMPC-OF | AMPC | AMPC / NMPC-OF | seeds AMPC "
                  "better / worse | xi error (N) | velocity (m/s) | thrust (3) | dvl (3) | attitude (3) "
                  "| depth (1) |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for case, per in rov.items():
            tr = {c: [r["tracking_rmse_m"] for r in per[c]] for c in CONTROLLERS}
            m = {c: _mean(v) for c, v in tr.items()}
            better, worse = ampc_against_offset_free(per)
            a = per["ampc"]
            lines.append("| " + " | ".join([
                case, get(case).describe(), *(_f(m[c]) for c in CONTROLLERS),
                _f(m["ampc"] / m["nmpc-of"], 2), f"{better} / {worse}",
                _f(_mean([r["disturbance_error_n"] for r in a]), 2),
                _f(_mean([r["velocity_rmse_mps"] for r in a]), 4),
                *(_nis_cell(pooled_nis(a, ch)) for ch in ("thrust", "dvl", "attitude",
                                                          "depth"))]) + " |")
        lines.append("")
        ch_band = {ch: pooled_nis(rov[next(iter(rov))]["ampc"], ch)
                   for ch in ("thrust", "dvl", "attitude", "depth")}
        lines.append("95 % bands of the mean NIS (nominal case, pooled): " + ", ".join(
            f"{ch} [{b['lo']:.2f}, {b['hi']:.2f}]" for ch, b in ch_band.items() if b) + ".")
        lines.append("")
    gav = res.get("gavia")
    if gav:
        lines += [f"### Torpedo AUV current estimate (gavia-tidal, {durations['gavia']:.0f} s, "
                  "error after 60 s)", "",
                  "The current KF with model (a), identified on the nominal plant in calm "
                  "water.", "",
                  "| case | plant | current RMS error (m/s) | per seed | velocity NIS (3) | "
                  "band |", "|---|---|---|---|---|---|"]
        for case, runs in gav.items():
            p = pooled_nis(runs, "current.velocity")
            lines.append("| " + " | ".join([
                case, get(case).describe(), _f(_mean([r["current_rms_mps"] for r in runs])),
                " / ".join(_f(r["current_rms_mps"]) for r in runs), _nis_cell(p),
                f"[{p['lo']:.2f}, {p['hi']:.2f}]" if p else "-"]) + " |")
        lines.append("")
    boat = res.get("boat")
    if boat:
        lines += [f"### Rudder boat speed and heading (jaiabot-turns, {durations['boat']:.0f} s,"
                  " error after 30 s)", "",
                  "| case | plant | speed RMSE AIE (m/s) | speed RMSE KF (m/s) | heading RMSE "
                  "AIE / KF (rad) | NIS AIE surge / heading (1) | NIS KF surge / heading (1) |",
                  "|---|---|---|---|---|---|---|"]
        for case, runs in boat.items():
            cells = []
            for p in ("aie", "kf"):
                cells.append(_nis_cell(pooled_nis(runs, f"{p}.surge.increment")) + " / "
                             + _nis_cell(pooled_nis(runs, f"{p}.heading.increment")))
            lines.append("| " + " | ".join([
                case, get(case).describe(),
                _f(_mean([r["speed_rmse_mps"]["aie"] for r in runs])),
                _f(_mean([r["speed_rmse_mps"]["kf"] for r in runs])),
                _f(_mean([r["heading_rmse_rad"]["aie"] for r in runs]), 4) + " / "
                + _f(_mean([r["heading_rmse_rad"]["kf"] for r in runs]), 4),
                *cells]) + " |")
        first = next(iter(boat.values()))
        b = pooled_nis(first, "aie.surge.increment")
        if b:
            lines.append("")
            lines.append(f"95 % band of a mean NIS of dimension 1 over ~{b['n']} values: "
                         f"[{b['lo']:.2f}, {b['hi']:.2f}].")
        lines.append("")
    return "\n".join(lines)


def write_tables(path: Path, text: str) -> None:
    """Put ``text`` between the campaign markers of ``path`` (created if missing; the rest
    of the file kept).

    Args:
        path: the markdown file.
        text: the generated tables.
    """
    block = f"{BEGIN}\n{text}\n{END}"
    if path.exists():
        old = path.read_text(encoding="utf-8")
        if BEGIN in old and END in old:
            head, rest = old.split(BEGIN, 1)
            tail = rest.split(END, 1)[1]
            path.write_text(head + block + tail, encoding="utf-8")
            return
        path.write_text(old.rstrip("\n") + "\n\n" + block + "\n", encoding="utf-8")
        return
    path.write_text(block + "\n", encoding="utf-8")


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (module docstring). Returns 0."""
    from onboard.sitl.mismatch import CASES

    ap = argparse.ArgumentParser(prog="python -m validation.reports.mismatch",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--parts", nargs="+", default=["rov", "gavia", "boat"],
                    choices=["rov", "gavia", "boat"])
    ap.add_argument("--rov-duration", type=float, default=60.0)
    ap.add_argument("--gavia-duration", type=float, default=300.0)
    ap.add_argument("--boat-duration", type=float, default=300.0)
    ap.add_argument("--out", help="markdown file to write the tables into")
    ap.add_argument("--json", help="dump every run's figures here")
    ap.add_argument("--load", nargs="+", metavar="JSON",
                    help="do not run: tabulate these --json dumps (parts merged)")
    args = ap.parse_args(argv)
    if args.load:
        res: dict[str, Any] = {}
        for f in args.load:
            for part, cases in json.loads(Path(f).read_text(encoding="utf-8")).items():
                res.setdefault(part, {}).update(cases)
    else:
        res = run_campaign(args.cases, args.seeds, args.rov_duration, args.gavia_duration,
                           args.boat_duration, args.parts,
                           log=lambda s: print(s, file=sys.stderr, flush=True))
    text = tables(res, args.seeds, {"rov": args.rov_duration, "gavia": args.gavia_duration,
                                    "boat": args.boat_duration})
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1), encoding="utf-8")
    if args.out:
        write_tables(Path(args.out), text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
