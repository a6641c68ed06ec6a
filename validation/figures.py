"""``python -m validation figures``: the README's figures, recomputed from the simulator and
the field logs, written to and checked against ``docs/figures.json``.

Each figure has a name (``aie.jaiabot_turns.speed_rmse.aie``: estimator, scenario,
quantity, which filter), the function computing it from a run
(``validation/reports/runs.py``, each run flown once per process), its unit, the seeds it
is measured on and a tolerance. The README's "What it estimates" table is generated from
the file (between the ``figures:begin`` / ``figures:end`` markers), and so are the docs
pages' results tables (``--docs docs``): Markdown templates under
``validation/templates/`` filled by :mod:`validation.render`, so their numbers are the
file's; ``tests/test_figures.py`` checks every generated block against the file and
recomputes the figures (a subset in the default suite, every one with ``-m slow``)
against it within each figure's tolerance. docs/reproducing.md says how to
re-measure after a change.

Tolerances. A run is deterministic per seed on one machine (same seed, same bytes), so a
tolerance only has to absorb what differs between machines: numpy/scipy/BLAS rounding,
which a filter can carry along a run, and for the closed loop the MPC solver's iteration
path (casadi/IPOPT versions). The seed-to-seed spread bounds what that noise can look like
from above: the AIE speed RMSE is 0.051-0.053 m/s over seeds 1-3 (4 %), the KF's on
``twin-thruster-turns`` 0.077-0.079 (3 %). Hence:

* RMS errors on the simulator: 3 % of the value, with an absolute floor of a few units of
  the last printed digit (:data:`SITL`);
* closed-loop (MPC) figures: 10 % (:data:`CLOSED_LOOP`; seed 0 vs seed 2 tracking differ
  by 70 %, docs/eseso-mpc.md);
* fractions (coverage): 0.02 absolute (one tick in fifty);
* counts (effects named): exact;
* real-log figures: 2 % (:data:`DATA`; no simulator randomness, only rounding).

A figure that moves by more than its tolerance is a change of the estimator, to be
re-measured with ``python -m validation figures --only 'PREFIX.*' --write docs/figures.json
--readme README.md --docs docs`` (all of them: ``make figures``) and committed with the change that
moved it.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import fnmatch
import json
import math
import platform
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from onboard.core.errors import UsageError
from validation import render
from validation.reports import runs

REPO = Path(__file__).resolve().parents[1]
FIGURES_FILE = REPO / "docs" / "figures.json"
README = REPO / "README.md"


@dataclass(frozen=True)
class Tolerance:
    """Allowed difference from the committed value: ``max(abs, rel * |value|)``."""

    rel: float = 0.0
    abs: float = 0.0

    def allowed(self, ref: float) -> float:
        """The allowed absolute difference around ``ref`` (the figure's unit)."""
        return max(self.abs, self.rel * abs(ref))


SITL = Tolerance(rel=0.03, abs=0.001)
"""Simulator RMS errors (m/s, m, rad; the floor 0.001 is below the printed digits)."""
SITL_DEG = Tolerance(rel=0.03, abs=0.1)
"""Simulator errors in metres where the README prints one decimal."""
CLOSED_LOOP = Tolerance(rel=0.10, abs=0.002)
"""The MPC closed loop: the solver's iteration path differs between library versions."""
FRACTION = Tolerance(abs=0.02)
"""Coverage fractions."""
MODEL = Tolerance(rel=0.01)
"""A property of a model identified on the simulator (a Lipschitz bound, gamma*): the
identification is deterministic per seed, only rounding differs."""
COUNT = Tolerance(abs=0.0)
"""Counts: exact."""
DATA = Tolerance(rel=0.02, abs=0.001)
"""Real field logs (no simulator randomness)."""
NIS = Tolerance(rel=0.01)
"""Mean NIS pooled over thousands of updates."""


@dataclass(frozen=True)
class Figure:
    """One figure: ``compute(seed)`` gives its value on ``seed`` (``None`` for a figure
    without seeds: real logs, or a figure pooled over its own seeds)."""

    name: str
    unit: str
    what: str
    compute: Callable[[int | None], float]
    seeds: tuple[int, ...]
    tolerance: Tolerance
    default_seeds: tuple[int, ...] = ()
    digits: int = 3
    data: bool = False

    def keys(self) -> tuple[str, ...]:
        """The keys of its values in the figures file: the seeds, or ``"-"``."""
        return tuple(str(s) for s in self.seeds) or ("-",)

    def value(self, key: str) -> float:
        """Compute the value for one key of :meth:`keys`."""
        return float(self.compute(None if key == "-" else int(key)))

    def default_keys(self) -> tuple[str, ...]:
        """The keys the default test suite recomputes (the rest run with ``-m slow``)."""
        if not self.seeds:
            return ("-",) if self.default_seeds == (0,) else ()
        return tuple(str(s) for s in self.default_seeds)


# ----------------------------------------------------------------------------- registry

SEEDS_1_3 = (1, 2, 3)


def _aie_figures() -> list[Figure]:
    out: list[Figure] = []
    for key, sc in (("jaiabot_turns", "jaiabot-turns"),
                    ("twin_thruster_turns", "twin-thruster-turns")):
        for who, (p, q) in (("aie", ("aie", "speed")), ("kf", ("kf", "speed")),
                            ("gnss", ("nav", "speed"))):
            out.append(Figure(
                f"aie.{key}.speed_rmse.{who}", "m/s",
                f"{sc}, 300 s, speed RMSE against truth after 30 s: "
                + {"aie": "the AIE pipeline", "kf": "the KF pipeline (default thrust map)",
                   "gnss": "the raw GNSS speed over ground (newest fix)"}[who],
                lambda s, sc=sc, p=p, q=q: runs.aie_metrics(sc, s)[p][q],
                SEEDS_1_3, SITL, default_seeds=(1,)))
        for who in ("aie", "kf"):
            out.append(Figure(
                f"aie.{key}.heading_rmse.{who}", "rad",
                f"{sc}, 300 s, heading RMSE against truth after 30 s, the {who.upper()} "
                "pipeline",
                lambda s, sc=sc, who=who: runs.aie_metrics(sc, s)[who]["heading"],
                SEEDS_1_3, Tolerance(rel=0.03, abs=0.0005), default_seeds=(1,)))
            out.append(Figure(
                f"aie.{key}.position_rmse.{who}", "m",
                f"{sc}, 300 s, horizontal position RMSE against truth after 30 s, the "
                f"{who.upper()} pipeline",
                lambda s, sc=sc, who=who: runs.aie_metrics(sc, s)[who]["position"],
                SEEDS_1_3, Tolerance(rel=0.03, abs=0.01), default_seeds=(1,), digits=2))
    out.append(Figure(
        "aie.jaiabot_turns.speed_rmse.kf_identified", "m/s",
        "jaiabot-turns, 300 s, speed RMSE after 30 s, the KF pipeline with the surge/heading "
        "models of config/sitl-jaiabot.toml (identified on seed 10)",
        lambda s: runs.aie_metrics("jaiabot-turns", s, True)["kf"]["speed"],
        SEEDS_1_3, SITL))
    for who, label in (("aie", "the AIE"), ("kf", "the KF"),
                       ("gps", "the speed from consecutive fixes")):
        out.append(Figure(
            f"aie.blueboat.speed_rmse.{who}", "m/s",
            "NTNU BlueBoat field runs (no Doppler): models identified on the even runs, the "
            "shipped defaults (their \"auto\" noise takes the no-Doppler tuned set, docs/aie.md "
            "section 2.2), "
            f"mean over the 8 held-out runs of {label}'s speed RMSE against the logged surge",
            lambda s, who=who: runs.blueboat_heldout()[f"{who}.speed"],
            (), DATA, data=True))
    for who in ("aie", "kf"):
        out.append(Figure(
            f"aie.gnss_outage.max_error.{who}", "m",
            "fault-gnss-outage (jaiabot-turns, no fix 30-150 s): maximum horizontal "
            f"position error of the {who.upper()} pipeline in the outage (dead reckoning)",
            lambda s, who=who: runs.outage_metrics(s)[f"{who}.max_error"],
            SEEDS_1_3, SITL_DEG, default_seeds=(1,), digits=1))
    out.append(Figure(
        "aie.gnss_outage.cover2.aie", "1",
        "fault-gnss-outage: fraction of the AIE's per-axis position errors within its "
        "published 2 sigma during the outage",
        lambda s: runs.outage_metrics(s)["aie.cover2"],
        SEEDS_1_3, FRACTION, default_seeds=(1,), digits=2))
    for who in ("aie", "kf"):
        out.append(Figure(
            f"aie.gnss_outage.max_sigma.{who}", "m",
            f"fault-gnss-outage: the largest per-axis position sigma the {who.upper()} "
            "pipeline publishes in the outage",
            lambda s, who=who: runs.outage_metrics(s)[f"{who}.max_sigma"],
            SEEDS_1_3, SITL_DEG, default_seeds=(1,), digits=1))
        for k in ("1",) if who == "aie" else ("1", "2"):  # aie's 2-sigma: cover2.aie above
            out.append(Figure(
                f"aie.gnss_outage.cover{k}.{who}", "1",
                f"fault-gnss-outage: fraction of the {who.upper()}'s per-axis position "
                f"errors within its published {k} sigma during the outage",
                lambda s, who=who, k=k: runs.outage_metrics(s)[f"{who}.cover{k}"],
                SEEDS_1_3, FRACTION, default_seeds=(1,), digits=2))
        for k in ("1", "2"):
            out.append(Figure(
                f"aie.gnss_outage.run_cover{k}.{who}", "1",
                f"fault-gnss-outage, the whole run after 10 s: fraction of the "
                f"{who.upper()}'s per-axis position errors within its published {k} sigma",
                lambda s, who=who, k=k: runs.outage_metrics(s)[f"{who}.run_cover{k}"],
                SEEDS_1_3, FRACTION, default_seeds=(1,), digits=2))
            out.append(Figure(
                f"aie.jaiabot_turns.cover{k}.{who}", "1",
                f"jaiabot-turns, 300 s, after 10 s: fraction of the {who.upper()}'s per-axis "
                f"position errors within its published {k} sigma",
                lambda s, who=who, k=int(k): runs.position_coverage(
                    runs.aie_run("jaiabot-turns", s), who)[k - 1],
                SEEDS_1_3, FRACTION, default_seeds=(1,), digits=2))
    for sc in ("jaiabot-turns", "twin-thruster-turns"):
        k = sc.replace("-", "_")
        for ax in ("surge", "heading"):
            for par in ("a", "gain"):
                out.append(Figure(
                    f"aie.{k}.identified.{ax}_{par}", "1/s" if par == "a" else
                    ("m/s^2" if ax == "surge" else "rad/s^2"),
                    f"{sc} seed 10: the {ax} model's {par} identified by identify_sitl "
                    "(GNSS speed over ground and compass against the commands)",
                    lambda s, sc=sc, ax=ax, par=par: runs.aie_identified_models(sc)[ax][par],
                    (), Tolerance(rel=0.02, abs=0.01), digits=2))
        for variant, seeds in (("identified", SEEDS_1_3),
                               *((v, (1,)) for v in runs.AIE_MODEL_VARIANTS)):
            label = ("the models identified on seed 10" if variant == "identified" else
                     "the default model's {} x {}".format(*runs.AIE_MODEL_VARIANTS[variant]))
            for q, unit, tol, digits in (("speed", "m/s", SITL, 3),
                                         ("heading", "rad", Tolerance(rel=0.03, abs=0.0005), 4),
                                         ("position", "m", Tolerance(rel=0.03, abs=0.01), 2)):
                for who in ("aie", "kf"):
                    out.append(Figure(
                        f"aie.{k}.model_{variant}.{q}_rmse.{who}", unit,
                        f"{sc}, 300 s, both filters with {label}: {q} RMSE after 30 s, the "
                        f"{who.upper()} pipeline",
                        lambda s, sc=sc, variant=variant, q=q, who=who:
                            runs.aie_model_metrics(sc, s, variant)[who][q],
                        seeds, tol, digits=digits))
    for sc, seeds in runs.AIE_EFFECT_SCENARIOS.items():
        for who, (p, label) in (("aie", ("aie", "the AIE pipeline")),
                                ("kf", ("kf", "the KF pipeline (default thrust map)")),
                                ("gnss", ("nav", "the raw GNSS speed over ground at the "
                                                 "ticks (newest fix)"))):
            out.append(Figure(
                f"aie.{sc.replace('-', '_')}.speed_rmse.{who}", "m/s",
                f"{sc} (rudder-boat config, the scenario's duration), speed RMSE against "
                f"truth after 30 s: {label}",
                lambda s, sc=sc, p=p: runs.aie_metrics(sc, s)[p]["speed"],
                seeds, SITL))
    return out


CURRENT_TABLE: tuple[tuple[str, str, bool, tuple[str, ...]], ...] = (
    # (run key, observer, calm-water model, axes): docs/current.md's validation table
    ("gavia-tidal", "kf", True, ("north", "east", "down")),
    ("gavia-tidal", "kf", False, ("north", "east", "down")),
    ("gavia-tidal", "hgo", True, ("north", "east", "down")),
    ("spheroid-sawtooth", "kf", True, ("north", "east", "down")),
    ("spheroid-sawtooth", "kf", False, ("north", "east", "down")),
    ("spheroid-sawtooth", "hgo", True, ("north", "east", "down")),
    ("spheroid-sawtooth", "flow", True, ("north", "east", "down")),
    ("effect-current", "kf", False, ("north", "east")),
    ("effect-current", "kf", True, ("north", "east")),
    ("boat-tidal", "kf", False, ("north", "east")),
    ("jaiabot-turns", "kf", False, ("north", "east")),
    ("twin-thruster-turns", "kf", False, ("north", "east")),
)
"""The runs of docs/current.md's validation table. A run with its key's default mode
(``runs.CURRENT_RUNS``) is named ``current.<key>.<observer>.*`` (the README's names); the
other mode adds ``_model`` (mode (a)) or ``_nomodel`` (mode (b)) to the observer."""


def current_token(key: str, observer: str, model: bool) -> str:
    """``<key>.<observer>[_model|_nomodel]`` of a :data:`CURRENT_TABLE` run in its
    figure names."""
    k = key.replace("-", "_")
    if model == runs.CURRENT_RUNS[key][2]:
        return f"{k}.{observer}"
    return f"{k}.{observer}_{'model' if model else 'nomodel'}"


def _current_table_figures(have: set[str]) -> list[Figure]:
    out: list[Figure] = []
    stats = (("rms", "RMS", SITL, 3), ("std", "standard deviation of the", SITL, 3),
             ("cover2", "fraction within the published 2 sigma of the", FRACTION, 2),
             ("published", "fraction of ticks with a published (not unknown)", FRACTION, 2))
    for key, obs, model, axes in CURRENT_TABLE:
        scenario, cfg, _, duration, after = runs.CURRENT_RUNS[key]
        tok = current_token(key, obs, model)
        what = (f"{scenario} ({cfg}, {duration:.0f} s, seed 1), "
                + ("model identified in calm water (mode (a))" if model
                   else "no model (mode (b))") + f", the {obs} observer")
        for ax in axes:
            for stat, label, tol, digits in stats:
                name = f"current.{tok}.{ax}_{stat}"
                if name in have:
                    continue
                out.append(Figure(
                    name, "1" if tol is FRACTION else "m/s",
                    f"{what}: {label} {ax} current error after {after:.0f} s"
                    + (" (over the published ticks)" if stat != "published" else ""),
                    lambda s, key=key, obs=obs, model=model, ax=ax, stat=stat:
                        runs.current_metrics(key, obs, s, model)[ax][stat],
                    (1,), tol, digits=digits))
        for stat, unit, label, tol, digits in (
                ("peak", "m/s", "largest horizontal error in the first 60 s it is "
                 "published", SITL, 2),
                ("peaking", "m/s", "that peak less the first published error (> 0: "
                 "overshoot)", SITL, 2),
                ("settle", "s", "time after which the horizontal error stays below "
                 "0.1 m/s", Tolerance(rel=0.1, abs=2.0), 0)):
            out.append(Figure(
                f"current.{tok}.{stat}", unit, f"{what}: {label}",
                lambda s, key=key, obs=obs, model=model, stat=stat:
                    runs.current_metrics(key, obs, s, model)["transient"][stat],
                (1,), tol, digits=digits))
    return out


def _current_figures() -> list[Figure]:
    out: list[Figure] = []
    plan = (
        # (run key, observer, axes, seeds checked by default, what)
        ("gavia-tidal", "kf", ("north", "east", "down"), (),
         "gavia-tidal, 200 s, calm-water identified model (mode (a)), the joint KF"),
        ("gavia-tidal", "hgo", ("north", "east", "down"), (1,),
         "gavia-tidal, 200 s, calm-water identified model (mode (a)), the high-gain "
         "observer at the LMI's gamma* (config/gains/torpedo-auv.json)"),
        ("spheroid-sawtooth", "flow", ("north", "east"), (),
         "spheroid-sawtooth, 600 s, calm-water identified model, the flow observer"),
        ("spheroid-sawtooth", "kf", ("north", "east"), (),
         "spheroid-sawtooth, 600 s, calm-water identified model, the joint KF"),
        ("effect-current", "kf", ("north", "east"), (),
         "effect-current (rudder boat, constant 0.29 m/s current), 600 s, no model: "
         "identified online by the joint KF"),
        ("boat-tidal", "kf", ("north", "east"), (),
         "effect-current's boat and mission in a 0.1 + 0.3 cos(2 pi t / 600 s) m/s stream, "
         "900 s, no model, the joint KF"),
    )
    for key, obs, axes, dflt, what in plan:
        after = runs.CURRENT_RUNS[key][4]
        k = key.replace("-", "_")
        for ax in axes:
            out.append(Figure(
                f"current.{k}.{obs}.{ax}_rms", "m/s",
                f"{what}: RMS {ax} current error against truth after {after:.0f} s",
                lambda s, key=key, obs=obs, ax=ax: runs.current_metrics(key, obs, s)[ax]["rms"],
                (1,), SITL, default_seeds=dflt))
        out.append(Figure(
            f"current.{k}.{obs}.cover2_min", "1",
            f"{what}: the smallest over the axes of the fraction of errors within the "
            "published 2 sigma",
            lambda s, key=key, obs=obs, axes=axes: min(
                runs.current_metrics(key, obs, s)[a]["cover2"] for a in axes),
            (1,), FRACTION, default_seeds=dflt, digits=2))
    return out + _hgo_model_figures() + _current_table_figures({f.name for f in out})


def _hgo_model_figures() -> list[Figure]:
    """The Lipschitz bound and gamma* of the model the high-gain observer runs at the end
    of its mode (a) runs (docs/current.md, "HGO"): properties of an identified model."""
    out: list[Figure] = []
    for key, dflt in (("gavia-tidal", (1,)), ("spheroid-sawtooth", ())):
        k = key.replace("-", "_")
        what = (f"{key}, {runs.CURRENT_RUNS[key][3]:.0f} s, seed 1, model identified in calm "
                "water (mode (a)), the high-gain observer: ")
        out.append(Figure(
            f"current.{k}.hgo.lipschitz", "1/s",
            what + "the Lipschitz bound L_f of the model it runs (its own RLS's "
            "coefficients, at the speeds and rates of design-gain)",
            lambda s, key=key: runs.current_run(key, "hgo", s)["pipe"].lipschitz,
            (1,), MODEL, default_seeds=dflt, digits=2))
        out.append(Figure(
            f"current.{k}.hgo.gamma_star", "1",
            what + "gamma* = max(1, 2 ||P|| L_f / lambda) of that model, the gain it runs at",
            lambda s, key=key: runs.current_run(key, "hgo", s)["pipe"].gamma_star,
            (1,), MODEL, default_seeds=dflt, digits=1))
    return out


def _nis_pooled(channel: str) -> float:
    means = [runs.eseso_nis(s)[channel] for s in SEEDS_1_3]
    n = sum(m[1] for m in means)
    return sum(m[0] * m[1] for m in means) / n


NIS_CHANNELS = {"vog": 2, "attitude": 3, "dvl": 3}
NIS_TABLE_CHANNELS = {"vog": 2, "attitude": 3, "dvl": 3, "depth": 1, "thrust": 3}
"""The ESESO's update channels of docs/eseso-mpc.md's NIS table and their dimensions."""
NIS_BAND_CHANNELS = {"vog": 2, "attitude": 3, "dvl": 3, "thrust": 3}
"""The channels ``eseso.nis.channels_in_band`` counts: the sensor channels and the thrust
channel, which carries the disturbance (depth is the simulator's dice, docs/eseso-mpc.md)."""


def _nis_in_band(_: int | None) -> float:
    k = 0
    for ch, dim in NIS_BAND_CHANNELS.items():
        n = sum(runs.eseso_nis(s)[ch][1] for s in SEEDS_1_3)
        lo, hi = runs.chi2_mean_band(n, dim)
        k += lo <= _nis_pooled(ch) <= hi
    return float(k)


def _eseso_figures() -> list[Figure]:
    out: list[Figure] = []
    for dur, key, dflt in ((240.0, "circle", ()), (30.0, "circle_30s", (0,))):
        for c in ("ampc", "nmpc", "pid"):
            out.append(Figure(
                f"eseso.{key}.tracking_rmse.{c}", "m",
                f"bluerov2-circle closed loop (sitl.closed_loop, 0.5 m/s, [40, 40, 10] N), "
                f"{dur:.0f} s, true tracking RMSE after 10 s, {c.upper()} with the ESESO in "
                "the loop",
                lambda s, c=c, dur=dur: runs.closed_loop(c, s, dur)["tracking_rmse_m"],
                (0,), CLOSED_LOOP, default_seeds=dflt))
        out.append(Figure(
            f"eseso.{key}.disturbance_rms.ampc", "N",
            f"bluerov2-circle, {dur:.0f} s, AMPC run: RMS error of the ESESO's disturbance "
            "estimate after 10 s",
            lambda s, dur=dur: runs.closed_loop("ampc", s, dur)["disturbance_error_n"],
            (0,), CLOSED_LOOP, default_seeds=dflt, digits=2))
    for c in ("pid", "nmpc", "nmpc-of", "ampc"):
        tok = c.replace("-", "_")
        for speed, key in ((None, "circle"), (1.5, "circle_1p5")):
            if speed is not None and c == "nmpc-of":
                continue
            where = ("bluerov2-circle closed loop, 240 s" if speed is None else
                     "bluerov2-circle at the paper's 1.5 m/s (thrusters saturate), 240 s")
            stats = (("tracking_rmse", "tracking_rmse_m", "m", "true tracking RMSE after 10 s",
                      3),
                     ("control_rmse", "control_rmse_m", "m", "RMS distance of the ESESO's "
                      "estimated position from the reference after 10 s (what the "
                      "controller sees)", 3),
                     ("disturbance_rms", "disturbance_error_n", "N", "RMS error of the "
                      "ESESO's disturbance estimate after 10 s", 2),
                     ("disturbance_max", "disturbance_error_max_after_5s_n", "N", "largest "
                      "error of the ESESO's disturbance estimate after 5 s", 2))
            for stat, rkey, unit, label, digits in stats:
                name = f"eseso.{key}.{stat}.{tok}"
                if any(f.name == name for f in out):
                    continue
                out.append(Figure(
                    name, unit, f"{where}, seed 0, {c.upper()} with the ESESO in the "
                    f"loop: {label}",
                    lambda s, c=c, speed=speed, rkey=rkey:
                        runs.closed_loop(c, s, 240.0, speed)[rkey],
                    (0,), CLOSED_LOOP, digits=digits))
    out.append(Figure(
        "eseso.circle_1p5.ampc_over_nmpc", "1",
        "bluerov2-circle at the paper's 1.5 m/s (thrusters saturate), 240 s: tracking RMSE "
        "of the AMPC over the NMPC's",
        lambda s: (runs.closed_loop("ampc", s, 240.0, 1.5)["tracking_rmse_m"]
                   / runs.closed_loop("nmpc", s, 240.0, 1.5)["tracking_rmse_m"]),
        (0,), CLOSED_LOOP, digits=2))
    for ch in NIS_CHANNELS:
        out.append(Figure(
            f"eseso.nis.{ch}", "1",
            f"bluerov2-circle through sitl.runner (its PID), 120 s, seeds 1-3 pooled: mean "
            f"NIS of the ESESO's {ch} updates (every update, gated ones included; "
            f"dimension {NIS_CHANNELS[ch]})",
            lambda s, ch=ch: _nis_pooled(ch), (), NIS))
    for ch, dim in NIS_TABLE_CHANNELS.items():
        if ch not in NIS_CHANNELS:
            out.append(Figure(
                f"eseso.nis.{ch}", "1",
                f"bluerov2-circle through sitl.runner (its PID), 120 s, seeds 1-3 pooled: mean "
                f"NIS of the ESESO's {ch} updates (every update, gated ones included; "
                f"dimension {dim})",
                lambda s, ch=ch: _nis_pooled(ch), (), NIS))
        out.append(Figure(
            f"eseso.nis_seed.{ch}", "1",
            f"bluerov2-circle through sitl.runner (its PID), 120 s: mean NIS of the ESESO's "
            f"{ch} updates on one seed (dimension {dim})",
            lambda s, ch=ch: runs.eseso_nis(s)[ch][0], SEEDS_1_3, NIS))
        out.append(Figure(
            f"eseso.nis_count.{ch}", "count",
            f"bluerov2-circle through sitl.runner, 120 s: the number of the ESESO's {ch} "
            "updates on one seed (the n of the chi-square band of the mean)",
            lambda s, ch=ch: float(runs.eseso_nis(s)[ch][1]), SEEDS_1_3, COUNT, digits=0))
    out.append(Figure(
        "eseso.nis.channels_in_band", "count",
        "of the vog, attitude, DVL and thrust channels, how many have their pooled mean NIS "
        "inside the 95 % chi-square band of a mean",
        _nis_in_band, (), COUNT, digits=0))
    return out


DIAGNOSE_DEFAULT = ("effect-current",)
"""The scenarios whose diagnose figure the default suite recomputes; the others' run with
``-m slow`` (each is a 600 s diagnose, 12-17 s of CPU; in the default suite
tests/test_diagnose_sitl.py names the current, tests/test_closure_synthetic.py a compass
deviation and two effects at once)."""


def _diagnose_figures() -> list[Figure]:
    out: list[Figure] = []
    for sc, effs in runs.DIAGNOSE_SCENARIOS.items():
        out.append(Figure(
            f"diagnose.{sc.replace('-', '_')}.effects_named", "count",
            f"onboard diagnose on {sc} (seed 1, 600 s, config/sitl-rudder-boat.toml, nothing "
            f"declared): how many of the {len(effs)} injected effect(s) it names",
            lambda s, sc=sc: float(runs.effects_named(sc, s)),
            (1,), COUNT, default_seeds=(1,) if sc in DIAGNOSE_DEFAULT else (), digits=0))
    out.append(Figure(
        "diagnose.effects_named", "count",
        f"the sum of the above over the {len(runs.DIAGNOSE_SCENARIOS)} scenarios "
        f"({sum(len(e) for e in runs.DIAGNOSE_SCENARIOS.values())} injected effects)",
        lambda s: float(sum(runs.effects_named(sc, s) for sc in runs.DIAGNOSE_SCENARIOS)),
        (1,), COUNT, digits=0))
    out.append(Figure(
        "diagnose.clean.effects_named", "count",
        "onboard diagnose on clean (no effect, seed 1): how many effects it names "
        "(false alarms)",
        lambda s: float(len(runs.named(runs.diagnose_sitl("clean", s)))),
        (1,), COUNT, default_seeds=(1,), digits=0))
    for which in ("before", "after"):
        out.append(Figure(
            f"diagnose.blueboat.holdout_{which}", "m/s",
            "NTNU BlueBoat with config/blueboat-ntnu-csv.toml as shipped (its thruster "
            "mapping; the README's `onboard diagnose` command): open-loop surge speed RMSE "
            f"on the 5 test runs {which} the effects the diagnosis found",
            lambda s, which=which: runs.diagnose_blueboat()[f"holdout_error_{which}"],
            (), DATA, data=True))
    for which in ("before", "after"):
        out.append(Figure(
            f"diagnose.blueboat_literal.holdout_{which}", "m/s",
            "NTNU BlueBoat, thruster columns taken literally: open-loop surge speed RMSE on "
            f"the 5 test runs {which} the effects the diagnosis found (the thruster mapping "
            "among them)",
            lambda s, which=which: runs.diagnose_blueboat_literal()[f"holdout_error_{which}"],
            (), DATA, data=True))
    out.append(Figure(
        "diagnose.usv_shenzhen.heading_offset_deg", "deg",
        "Shenzhen USV, RTK GNSS + dual-antenna heading (NMEA): |heading_bias| the diagnosis "
        "names (the antenna baseline is not along the bow)",
        lambda s: runs.usv_heading_offset_deg(),
        (), DATA, data=True, digits=1))
    return out


def _dac_figures() -> list[Figure]:
    """A simulated glider's dive currents against their truth (docs/current.md, "A
    glider's depth-averaged current"), pooled over each set's seeds."""
    out: list[Figure] = []
    sets = (("dev", runs.GLIDER_DEV_SEEDS, False,
             "the seeds the error model was written on"),
            ("held_out", runs.GLIDER_HELD_OUT_SEEDS, False, "held-out seeds"),
            ("graver", runs.GLIDER_HELD_OUT_SEEDS, True,
             "held-out seeds, Graver's (2005) lift, the default before"))
    quantities = (("rms", "m/s", "RMS error", SITL, 3),
                  ("cover1", "1", "the share within 1 sigma", FRACTION, 2),
                  ("cover2", "1", "the share within 1.96 sigma", FRACTION, 3),
                  ("z_median", "1", "the median |error| / sigma", Tolerance(rel=0.05), 2),
                  ("dives", "count", "dives", COUNT, 0))
    for key, seeds, graver, what in sets:
        for q, unit, text, tol, digits in quantities:
            out.append(Figure(
                f"dac.sim_glider.{key}.{q}", unit,
                f"onboard sitl --glider, seeds {seeds[0]}-{seeds[-1]} ({what}), four dives "
                f"each, pipeline dac against the truth, north and east pooled: {text}",
                lambda s, seeds=seeds, graver=graver, q=q:
                    runs.glider_dac(seeds[0], seeds[-1], graver)[q],
                (), tol, digits=digits))
    return out


def registry() -> dict[str, Figure]:
    """Every figure, by name, in the order ``python -m validation figures`` runs them."""
    figs = _aie_figures() + _current_figures() + _eseso_figures() + _diagnose_figures() + \
        _dac_figures()
    return {f.name: f for f in figs}


# ----------------------------------------------------------------------------- file


def versions() -> dict[str, str]:
    """Python, numpy, scipy, casadi, onboard and the git commit the figures came from."""
    from importlib import metadata

    try:
        own = metadata.version("onboard")
    except metadata.PackageNotFoundError:
        own = "not installed"
    out = {"python": platform.python_version(), "onboard": own,
           "platform": f"{platform.system()} {platform.machine()}"}
    for mod in ("numpy", "scipy", "casadi"):
        try:
            out[mod] = __import__(mod).__version__
        except ImportError:
            out[mod] = "absent"
    try:
        out["git"] = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=REPO,
                                    capture_output=True, text=True, timeout=10,
                                    check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        out["git"] = "unknown"
    return out


def entry(fig: Figure, values: dict[str, float | None], measured: str) -> dict[str, Any]:
    """A figure's record in the figures file."""
    return {"value": _summary(values), "values": values, "unit": fig.unit, "what": fig.what,
            "seeds": list(fig.seeds), "default_suite_seeds": list(fig.default_keys()),
            "tolerance": {"rel": fig.tolerance.rel, "abs": fig.tolerance.abs},
            "digits": fig.digits, "measured_utc": measured}


def _summary(values: dict[str, float | None]) -> float | list[float] | None:
    v = [x for x in values.values() if x is not None]
    if not v:
        return None
    return v[0] if len(v) == 1 else [min(v), max(v)]


def load(path: Path) -> dict[str, Any]:
    """A figures file's contents; a :class:`UsageError` when it is unreadable."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise UsageError(f"{path}: {err}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("figures"), dict):
        raise UsageError(f"{path}: not a figures file (no 'figures' object)")
    return doc


def compare(fig: Figure, key: str, value: float | None, ref_doc: dict[str, Any]
            ) -> tuple[bool, str]:
    """``(ok, reason)``: ``value`` of ``fig`` on ``key`` against the file's, within the
    figure's tolerance (of the registry, the code's current statement)."""
    rec = ref_doc["figures"].get(fig.name)
    if rec is None or key not in rec["values"]:
        return False, "not in the figures file"
    ref = rec["values"][key]
    if value is None or ref is None:
        return value is None and ref is None, f"file {ref}, now {value}"
    allowed = fig.tolerance.allowed(ref)
    diff = value - ref
    ok = abs(diff) <= allowed + 1e-12
    return ok, f"file {ref:.6g}, diff {diff:+.3g}, allowed {allowed:.3g}"


# ----------------------------------------------------------------------------- command


def select(names: Iterable[str], patterns: Sequence[str] | None) -> list[str]:
    """Names matching any of the glob ``patterns`` (a pattern without a wildcard matches
    as a prefix); all when ``patterns`` is empty."""
    names = list(names)
    if not patterns:
        return names
    out = []
    for n in names:
        for p in patterns:
            if fnmatch.fnmatchcase(n, p) or (not any(c in p for c in "*?[") and n.startswith(p)):
                out.append(n)
                break
    return out


def run_figures(names: Sequence[str], figs: dict[str, Figure], log: Any = sys.stderr
                ) -> tuple[dict[str, dict[str, float | None]], list[str]]:
    """Compute the named figures on all their seeds, with a progress line each on
    ``log``; returns (values by name and key, names skipped for missing field logs)."""
    out: dict[str, dict[str, float | None]] = {}
    skipped: list[str] = []
    total = sum(len(figs[n].keys()) for n in names)
    i = 0
    for n in names:
        fig = figs[n]
        vals: dict[str, float | None] = {}
        for key in fig.keys():
            i += 1
            t0 = time.monotonic()
            print(f"[{i}/{total}] {n}" + ("" if key == "-" else f" seed {key}"),
                  end=" ... ", file=log, flush=True)
            try:
                v = fig.value(key)
            except runs.MissingData as err:
                print(f"skipped: {err}", file=log, flush=True)
                skipped.append(n)
                break
            vals[key] = None if math.isnan(v) else v
            print(f"{v:.{fig.digits + 2}f} {fig.unit} ({time.monotonic() - t0:.1f} s)",
                  file=log, flush=True)
        else:
            out[n] = vals
    return out, skipped


def render_pages(readme: str | None, docs: str | None, doc: dict[str, Any],
                 results: str | None = None) -> None:
    """Rewrite the README's figures block (``readme``), the figures blocks of the pages
    in ``docs`` (their templates, :mod:`validation.render`) and the results file
    (``results``, :mod:`validation.results`) from ``doc``, saying what changed."""
    from validation import results as results_mod

    if results:
        changed = results_mod.write(Path(results), doc)
        print(f"{results}: {'rewritten' if changed else 'unchanged'}")
    figs = doc["figures"]
    if readme:
        keys = render.update_page(Path(readme), render.README_TEMPLATE, "figures", figs)
        print(f"{readme}: figures block {'rewritten' if keys else 'unchanged'}")
    if docs:
        keys = render.update_docs(Path(docs), "figures", figs)
        n = sum(len(render.template_blocks(t, "figures"))
                for t in render.DOCS_TEMPLATES.glob("*.md"))
        print(f"{docs}: {n} generated tables, "
              + (f"rewritten: {', '.join(keys)}" if keys else "all unchanged"))


def main(args: argparse.Namespace) -> int:
    """``python -m validation figures [--only PATTERN]... [--write FILE] [--check FILE]
    [--readme FILE] [--docs DIR] [--results FILE]``: compute the figures, print them as
    a table, write them, check them against a file (exit 1 when one is outside its
    tolerance), rewrite the README's figures block, the docs pages' generated tables and
    the results file. ``--readme`` / ``--docs`` / ``--results`` without
    ``--write``/``--check`` only re-render from docs/figures.json."""
    figs = registry()
    names = select(figs, args.only)
    docs = getattr(args, "docs", None)
    res = getattr(args, "results", None)
    if args.only and not names:
        raise UsageError(f"no figure matches {' '.join(args.only)} (see docs/figures.json)")
    if (args.readme or docs or res) and not args.write and not args.check:
        render_pages(args.readme, docs, load(FIGURES_FILE), res)
        return 0
    if (args.readme or docs or res) and not args.write:
        raise UsageError("--readme/--docs/--results with --check needs --write (the pages "
                         "are rendered from the file written)")
    ref = load(Path(args.check)) if args.check else None
    values, skipped = run_figures(names, figs)
    bad: list[str] = []
    rows = []
    for n, vals in values.items():
        fig = figs[n]
        for key, v in vals.items():
            status = ""
            if ref is not None:
                ok, why = compare(fig, key, v, ref)
                status = ("ok " if ok else "OUT ") + why
                if not ok:
                    bad.append(f"{n} [{key}]")
            rows.append((n, key, "n/a" if v is None else f"{v:.{fig.digits + 2}f}", fig.unit,
                         status))
    w = max((len(r[0]) for r in rows), default=10)
    print(f"{'figure':{w}s}  seed  {'value':>10s}  unit   check")
    for r in rows:
        print(f"{r[0]:{w}s}  {r[1]:>4s}  {r[2]:>10s}  {r[3]:5s}  {r[4]}")
    for n in skipped:
        print(f"{n:{w}s}  skipped: real field logs absent")
    if args.write:
        path = Path(args.write)
        doc = load(path) if path.exists() else {"figures": {}}
        now = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        doc["about"] = ("The README's and the docs tables' figures (python -m validation figures; "
                        "validation/figures.py says how each is computed and why its "
                        "tolerance; docs/reproducing.md how to re-measure).")
        doc["command"] = ("python -m validation figures --write docs/figures.json "
                          "--readme README.md --docs docs")
        doc["written_utc"] = now
        doc["versions"] = versions()
        for n, vals in values.items():
            doc["figures"][n] = entry(figs[n], vals, now)
        order = list(figs)
        doc["figures"] = dict(sorted(doc["figures"].items(),
                                     key=lambda kv: order.index(kv[0]) if kv[0] in order
                                     else len(order)))
        path.write_text(json.dumps(doc, indent=1, sort_keys=False) + "\n", encoding="utf-8")
        print(f"wrote {len(values)} figures to {path}")
        render_pages(args.readme, docs, doc, res)
    if bad:
        print(f"{len(bad)} figure(s) outside their tolerance: {', '.join(bad)}",
              file=sys.stderr)
        return 1
    return 0
