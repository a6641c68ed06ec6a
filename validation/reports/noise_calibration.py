"""Calibration in a world whose noise the configuration does not know: docs/integrity.md,
"Learned noise".

Run ``python -m validation.reports.noise_calibration [--seeds 2 3] [--duration 600]``:
each noise-scale scenario (``sitl.scenarios.noise_scaled``: every sensor's true noise
0.3, 1 or 3 times what the bundled config declares) flown on held-out seeds through the
``aie``, ``kf`` and ``current`` pipelines of that unchanged config; per scenario, pooled
over the seeds after :data:`AFTER_S`, the 1- and 2-sigma coverage of speed, heading and
current (with how precisely the seeds measure it: validation/coverage.py), each
channel's mean NIS and the learned noise against the true and the declared, and the
``nis_out_of_band`` warnings; printed as the page's Markdown tables. With
``--summaries DIR/*/replay/summary.json`` (replays of the real logs): the real-log table,
what each log's channels learned and whether the NIS check still warns.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from validation.coverage import Coverage, interval

AFTER_S = 120.0
"""Coverage is pooled over the ticks after this (s): the filters' start is not judged."""
HELD_OUT_SEEDS = (2, 3)
"""Seeds not used while the noise learning was designed (seed 1 was)."""
SCENARIO_CONFIG = {"noise-boat": "rudder-boat", "noise-auv": "torpedo-auv"}
"""The bundled config each family is flown with, unchanged."""
TICK_S = 0.1


@dataclass
class Pooled:
    """Normalized errors ``|error| / sigma`` per quantity, pooled over the runs."""

    z: dict[str, list[np.ndarray]] = field(default_factory=dict)
    nis: dict[str, list[float]] = field(default_factory=dict)
    learned: dict[str, list[float]] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def add(self, q: str, err: np.ndarray, sd: np.ndarray) -> None:
        ok = np.isfinite(err) & np.isfinite(sd) & (sd > 0)
        self.z.setdefault(q, []).append(np.abs(err[ok]) / sd[ok])

    def coverage(self, q: str) -> tuple[Coverage, Coverage]:
        """The 1- and 2-sigma coverage of quantity ``q``, each with its effective sample
        count and 95 % interval over the runs (validation/coverage.py)."""
        runs = self.z.get(q, [])
        return interval([z < 1.0 for z in runs]), interval([z < 2.0 for z in runs])


def family(name: str) -> str:
    """``noise-boat`` of ``noise-boat-3x``."""
    return name.rsplit("-", 1)[0]


def fly(scenario: str, seed: int, duration: float | None, pooled: Pooled) -> None:
    """One run of ``scenario`` through its family's config; its coverage, NIS, learned
    noise and warnings into ``pooled``."""
    from onboard.core import config as config_mod
    from onboard.core.geo import wrap_pi_array
    from onboard.engine import Engine
    from onboard.pipelines import aie as aie_mod
    from onboard.pipelines import current as current_mod
    from onboard.pipelines import kf as kf_mod
    from onboard.sitl.runner import engine_ticks, simulate

    cfg = config_mod.load(SCENARIO_CONFIG[family(scenario)])
    pipes = [p for p in (aie_mod.create(cfg), kf_mod.create(cfg), current_mod.create(cfg))
             if p is not None]
    eng = Engine(cfg, pipelines=pipes)
    rows: list[tuple[float, dict[str, dict[str, float]], Any]] = [
        (t, {r.pipeline: r.values for r in recs}, truth) for t, recs, truth in
        engine_ticks(eng, simulate(scenario, duration=duration, seed=seed), TICK_S)]
    t = np.array([r[0] for r in rows])
    m = t >= t[0] + AFTER_S

    def col(p: str, q: str) -> np.ndarray:
        return np.array([r[1].get(p, {}).get(q, math.nan) for r in rows])[m]

    def tru(q: str) -> np.ndarray:
        return np.array([getattr(r[2], q) for r in rows])[m]
    speed = np.copysign(np.hypot(tru("u"), tru("v")), tru("u"))
    for p in ("aie", "kf"):
        if p not in {x.name for x in pipes}:
            continue
        pooled.add(f"{p}.speed", col(p, "speed") - speed, col(p, "std_speed"))
        pooled.add(f"{p}.heading", wrap_pi_array(col(p, "heading") - tru("yaw")),
                   col(p, "std_heading"))
    for ax in ("north", "east"):
        pooled.add(f"current.{ax}", col("current", ax) - tru(f"current_{ax}"),
                   col("current", f"std_{ax}"))
    _channels(eng, pipes, pooled)


def _channels(eng: Any, pipes: list[Any], pooled: Pooled) -> None:
    """Each channel's mean NIS per dof and learned noise (one-sigma), and the run's
    ``nis_out_of_band`` warnings and ``nis_unpublished``/``nis_corrected`` notes, into
    ``pooled``."""
    summary = eng.monitor.snapshot()
    for p in pipes:
        noise = getattr(p, "noise", None)
        if noise is None:
            continue
        for ch, s in noise.scales.items():
            if s.n:
                pooled.learned.setdefault(f"{p.name} {ch}", []).append(math.sqrt(s.scale))
    if summary:
        for p, chans in summary.items():
            for ch, h in chans.items():
                if h.nis_mean is not None:
                    pooled.nis.setdefault(f"{p} {ch}", []).append(h.nis_mean / h.dof)
    for a in eng.alerts:
        if a.code == "nis_out_of_band":
            pooled.warnings.append(f"{a.pipeline}: {a.message}")
        elif a.code in ("nis_unpublished", "nis_corrected"):
            pooled.notes.append(f"{a.pipeline}: {a.message}")


def true_ratio(scenario: str) -> float:
    """The scenario's true noise over the declared (``k`` of ``noise-boat-3x``)."""
    return float(scenario.rsplit("-", 1)[1].rstrip("x"))


def run_family(seeds: Sequence[int], duration: float | None,
               scenarios_: Sequence[str]) -> dict[str, Pooled]:
    """Every scenario of ``scenarios_`` on ``seeds``, pooled per scenario."""
    out: dict[str, Pooled] = {}
    for sc in scenarios_:
        pooled = out[sc] = Pooled()
        for seed in seeds:
            fly(sc, seed, duration, pooled)
    return out


def coverage_rows(results: dict[str, Pooled]) -> list[str]:
    """The coverage table: per scenario and quantity, 1- and 2-sigma coverage."""
    lines = ["| scenario | quantity | 1σ coverage (95 % interval) | 2σ coverage (95 % "
             "interval) | samples (effective, 1σ / 2σ) |", "|---|---|---|---|---|"]
    for sc, pooled in results.items():
        for q in sorted(pooled.z):
            c1, c2 = pooled.coverage(q)
            lines.append(f"| {sc} | {q} | {c1.text()} | {c2.fraction:.3f} ({c2.low:.3f}-"
                         f"{c2.high:.3f}) | {c1.n} ({c1.n_eff:.0f} / {c2.n_eff:.0f}) |")
    return lines


def noise_rows(results: dict[str, Pooled]) -> list[str]:
    """The learned-noise table: per scenario and channel the learned one-sigma over the
    declared (mean over seeds) against the true over the declared, the mean NIS per
    dof, the runs that warned ``nis_out_of_band`` about the channel and those that noted
    ``nis_unpublished`` about it (algorithms.md §9.2)."""
    lines = ["| scenario | channel | learned / declared σ | true / declared σ | "
             "mean NIS / dof | warned | noted |", "|---|---|---|---|---|---|---|"]
    for sc, pooled in results.items():
        k = true_ratio(sc)
        for key in sorted(set(pooled.learned) | set(pooled.nis)):
            ch = key.split(" ", 1)[1]
            learned = pooled.learned.get(key)
            nis = pooled.nis.get(key)
            warned, noted = (sum(1 for w in said if w.startswith(key.split(" ")[0] + ":")
                                 and f" {ch}:" in w)
                             for said in (pooled.warnings, pooled.notes))
            lines.append(
                f"| {sc} | {key} | {np.mean(learned):.2f} | {k:g} | " if learned else
                f"| {sc} | {key} | - | - | ")
            lines[-1] += (f"{np.mean(nis):.2f} | " if nis else "- | ") + f"{warned} | "
            lines[-1] += f"{noted} |"
    return lines


def log_rows(summaries: Sequence[str]) -> list[str]:
    """The real-log table from replays' ``summary.json`` (``onboard replay`` of each log
    with its config): per log and learning channel of ``aie``/``kf``/``current`` the
    learned one-sigma over the declared, the mean NIS per dof, and whether
    ``nis_out_of_band`` was raised about the channel (its message's remedy)."""
    import json
    from pathlib import Path

    lines = ["| log | channel | learned / declared σ | mean NIS / dof | warned |",
             "|---|---|---|---|---|"]
    for path in summaries:
        doc = json.loads(Path(path).read_text())
        name = Path(path).parent.parent.name if Path(path).parent.name == "replay" \
            else Path(path).parent.name
        health, inn = doc.get("pipeline_health", {}), doc.get("innovations", {})
        warned = {(w.get("pipeline", ""), w["message"].split(":")[0].split(" ", 1)[-1])
                  for w in doc.get("warnings", []) if w["code"] == "nis_out_of_band"}
        for p in ("aie", "kf", "current"):
            for key, scale in sorted(health.get(p, {}).items()):
                if not (key.startswith("noise.") and key.endswith(".scale")):
                    continue
                ch = key[len("noise."):-len(".scale")]
                h = inn.get(p, {}).get(ch, {})
                nis = h.get("nis_mean")
                nis_s = f"{nis / h.get('dof', 1):.2f}" if nis is not None else "-"
                lines.append(f"| {name} | {p} {ch} | {math.sqrt(scale):.2f} | {nis_s} | "
                             f"{'yes' if (p, ch) in warned else 'no'} |")
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    """Print both tables. Returns 0."""
    from onboard.sitl import scenarios

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(HELD_OUT_SEEDS))
    ap.add_argument("--duration", type=float, default=None)
    ap.add_argument("--only", default="noise-", help="scenario name prefix")
    ap.add_argument("--summaries", nargs="+", metavar="SUMMARY_JSON",
                    help="print the real-log table of these replays' summary.json instead")
    a = ap.parse_args(argv)
    if a.summaries:
        print("\n".join(log_rows(a.summaries)))
        return 0
    names = [n for n in scenarios.names() if n.startswith(a.only)]
    results = run_family(a.seeds, a.duration, names)
    print("\n".join(coverage_rows(results)))
    print()
    print("\n".join(noise_rows(results)))
    for sc, pooled in results.items():
        for w in pooled.warnings + pooled.notes:
            print(f"{sc}: {w}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
