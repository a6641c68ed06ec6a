"""The simulator and field-log runs behind the README's figures, each computed once per
process.

Every function here is memoised (``functools.cache``): ``python -m validation figures`` and the test
suite ask for the same run under several figures (the AIE and the KF of one
``jaiabot-turns`` seed, the three axes of one current run), and the run is flown once.
The runs themselves are the validation reports' (``aie_validation``,
``current_validation``), ``sitl.closed_loop`` and ``onboard.offline.diagnose``; this module only
picks their settings (scenario, seed, duration, the window the metrics skip) and reduces
them to numbers.

A run that needs the real field logs raises :class:`MissingData` when
``$ONBOARD_DATA`` / ``../shared/data`` is absent.
"""

from __future__ import annotations

import functools
import inspect
import math
import os
import re
import tempfile
from pathlib import Path
from typing import Any, Callable, TypeVar

import numpy as np

from onboard.core.stats import chi2_mean_band

REPO = Path(__file__).resolve().parents[2]
SITL_DIAGNOSE_CONFIG = REPO / "config" / "sitl-rudder-boat.toml"

DIAGNOSE_SCENARIOS: dict[str, tuple[str, ...]] = {
    "effect-current": ("water_current",),
    "effect-compass-deviation": ("compass_deviation",),
    "effect-heading-bias": ("heading_bias",),
    "effect-gyro-bias": ("gyro_bias",),
    "effect-gps-latency": ("gps_latency",),
    "effect-thrust-nonlinearity": ("thrust_nonlinearity",),
    "effect-quadratic-drag": ("quadratic_drag",),
    "effect-surge-yaw-coupling": ("surge_yaw_coupling",),
    "effect-sideslip": ("sideslip",),
    "effect-waves": ("wave_oscillation",),
    "effect-two": ("water_current", "compass_deviation"),
}
"""The catalog-effect scenarios of ``sitl/scenarios.py`` and the effects injected in each
(12 in all): the material of the README's "names N of 12"."""


F = TypeVar("F", bound=Callable[..., Any])


def cache(fn: F) -> F:
    """Memoise ``fn`` on its arguments as bound to its signature, defaults applied, so
    ``f("x", 1)`` and ``f("x", seed=1)`` share one run."""
    sig = inspect.signature(fn)
    memo: dict[tuple[Any, ...], Any] = {}

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        b = sig.bind(*args, **kwargs)
        b.apply_defaults()
        key = tuple(b.arguments.values())
        if key not in memo:
            memo[key] = fn(*args, **kwargs)
        return memo[key]

    wrapper.cache_clear = memo.clear  # type: ignore[attr-defined]
    return wrapper  # type: ignore[return-value]


class MissingData(RuntimeError):
    """A figure needs the real field logs and they are not on this machine."""


def data_dir() -> Path:
    """``$ONBOARD_DATA`` or ``../shared/data``; raises :class:`MissingData` when neither
    is a directory."""
    env = os.environ.get("ONBOARD_DATA")
    for cand in ([Path(env)] if env else []) + [REPO.parent / "shared" / "data"]:
        if cand.is_dir():
            return cand
    raise MissingData("real field logs not found: set ONBOARD_DATA or place shared/data "
                      "beside the repository")


# ----------------------------------------------------------------------------- AIE / KF

AIE_EFFECT_SCENARIOS: dict[str, tuple[int, ...]] = {
    "clean": (1,),
    "effect-current": (1,),
    "effect-sideslip": (1,),
    "effect-waves": (1, 2, 3),
    "effect-gps-latency": (1,),
    "effect-thrust-nonlinearity": (1, 2, 3),
    "effect-quadratic-drag": (1, 2, 3),
    "effect-surge-yaw-coupling": (1, 2, 3),
    "effect-compass-deviation": (1,),
    "effect-heading-bias": (1,),
    "effect-gyro-bias": (1,),
    "effect-two": (1,),
    "fault-compass-step": (1,),
}
"""The surface-boat scenarios beyond ``jaiabot-turns`` / ``twin-thruster-turns`` the AIE
and KF are measured on (docs/aie.md 3.1.1; ``rudder-boat`` config, the scenario's own
duration) and their seeds: 1-3 where seed 1 is, or was, a miss or near one, 1 elsewhere."""


@cache
def aie_run(scenario: str, seed: int, identified: bool = False) -> Any:
    """``aie_validation.run_sitl`` over the whole scenario (the AIE and KF pipelines
    through the engine); ``identified``: both with the surge/heading models of
    ``config/sitl-jaiabot.toml`` (identified on ``jaiabot-turns`` seed 10) instead of the
    vehicle config's defaults."""
    import msgspec

    from onboard.core import config as config_mod
    from validation.reports.aie_validation import run_sitl

    table = msgspec.to_builtins(config_mod.load("sitl-jaiabot").pipelines.aie) \
        if identified else None
    return run_sitl(scenario, seed=seed, aie_table=table)


@cache
def aie_metrics(scenario: str, seed: int, identified: bool = False
                ) -> dict[str, dict[str, float]]:
    """``sitl_metrics`` of :func:`aie_run`: RMSE after 30 s per pipeline (speed m/s,
    heading rad, position m, ...; ``nav``: the raw GNSS speed over ground)."""
    from validation.reports.aie_validation import sitl_metrics

    return sitl_metrics(aie_run(scenario, seed, identified))


AIE_MODEL_VARIANTS: dict[str, tuple[str, float]] = {
    "a_0p7": ("a", 0.7), "a_1p3": ("a", 1.3), "gain_0p7": ("gain", 0.7),
    "gain_1p3": ("gain", 1.3),
}
"""docs/aie.md 3.2's sensitivity: the default model's ``a`` or ``gain`` (surge 1 / 3,
heading 2 / 2) scaled on both axes, for both filters."""


@cache
def aie_identified_models(scenario: str) -> dict[str, dict[str, float]]:
    """``aie_validation.identify_sitl`` on ``scenario`` seed 10 (GNSS speed over ground and
    compass against the mapped commands, output-error fit), as a ``[pipelines.aie]``
    table: ``{"surge": {a, gain, offset}, "heading": {a, gain, offset}}``."""
    from validation.reports.aie_validation import identify_sitl

    ms, mh = identify_sitl(scenario, seed=10)
    return {"surge": {"a": ms.a, "gain": ms.gain, "offset": ms.offset},
            "heading": {"a": mh.a, "gain": mh.gain, "offset": mh.offset}}


@cache
def aie_model_metrics(scenario: str, seed: int, variant: str
                      ) -> dict[str, dict[str, float]]:
    """:func:`aie_metrics` of ``scenario`` with both filters' model replaced:
    ``variant`` a key of :data:`AIE_MODEL_VARIANTS` or ``identified``
    (:func:`aie_identified_models`)."""
    from validation.reports.aie_validation import run_sitl, sitl_metrics

    if variant == "identified":
        table: dict[str, Any] = aie_identified_models(scenario)
    else:
        what, f = AIE_MODEL_VARIANTS[variant]
        table = {"surge": {what: f * (1.0 if what == "a" else 3.0)},
                 "heading": {what: f * 2.0}}
    return sitl_metrics(run_sitl(scenario, seed=seed, aie_table=table))


def position_coverage(run: Any, p: str, t_from: float = 10.0, t_to: float = 1e9
                      ) -> tuple[float, float]:
    """Fraction of the per-axis position errors of pipeline ``p`` (north and east pooled,
    ticks in [t_from, t_to) s) within one and two published sigmas
    (``std_north``, ``std_east``)."""
    t, e, tr = run.t, run.est, run.truth
    z = []
    for ax in ("north", "east"):
        err, sd = e[f"{p}.{ax}"] - tr[ax], e[f"{p}.std_{ax}"]
        ok = (t >= t_from) & (t < t_to) & np.isfinite(err) & np.isfinite(sd)
        z.append(np.abs(err[ok]) / sd[ok])
    zz = np.concatenate(z)
    return float(np.mean(zz < 1.0)), float(np.mean(zz < 2.0))


OUTAGE = (30.0, 150.0)
"""``fault-gnss-outage``: no GNSS fix from 30 s to 150 s (s)."""


@cache
def outage_metrics(seed: int) -> dict[str, float]:
    """``fault-gnss-outage``: per pipeline (``aie``, ``kf``) in the outage the maximum
    horizontal position error (``max_error``, m), the largest published per-axis position
    sigma (``max_sigma``, m), the 1- and 2-sigma coverage of the position (``cover1``,
    ``cover2``); over the whole run after 10 s the coverage (``run_cover1``,
    ``run_cover2``)."""
    run = aie_run("fault-gnss-outage", seed)
    out: dict[str, float] = {}
    inside = (run.t >= OUTAGE[0]) & (run.t < OUTAGE[1])
    for p in ("aie", "kf"):
        err = np.hypot(run.est[f"{p}.north"] - run.truth["north"],
                       run.est[f"{p}.east"] - run.truth["east"])
        out[f"{p}.max_error"] = float(np.nanmax(err[inside]))
        out[f"{p}.max_sigma"] = float(np.nanmax(np.maximum(run.est[f"{p}.std_north"][inside],
                                                           run.est[f"{p}.std_east"][inside])))
        out[f"{p}.cover1"], out[f"{p}.cover2"] = position_coverage(run, p, *OUTAGE)
        out[f"{p}.run_cover1"], out[f"{p}.run_cover2"] = position_coverage(run, p)
    return out


@cache
def blueboat_heldout() -> dict[str, float]:
    """The NTNU BlueBoat runs: models identified on the even runs, AIE / KF / the speed
    from consecutive fixes on the odd (held-out) runs; the mean over those runs of the
    speed RMSE against the logged surge speed (m/s). The logs carry no Doppler speed:
    both filters run at their shipped defaults, which take the noise parameters the
    common tuning found without one (``"auto"``, docs/aie.md section 2.2)."""
    from validation.reports.aie_validation import (blueboat_metrics, blueboat_runs,
                                                      identify_blueboat, run_blueboat)

    d = data_dir()
    if not (d / "blueboat_sysid_ntnu").is_dir():
        raise MissingData(f"{d / 'blueboat_sysid_ntnu'} not in the shared data")
    runs = blueboat_runs(d)
    train, test = runs[::2], runs[1::2]
    ms, my = identify_blueboat(train)
    acc: dict[str, list[float]] = {}
    for r in test:
        met = blueboat_metrics(r, run_blueboat(r, ms, my), ms, my)
        for k in ("aie.speed", "kf.speed", "gps.speed"):
            acc.setdefault(k, []).append(met[k])
    return {k: float(np.nanmean(v)) for k, v in acc.items()} | {"runs": float(len(test))}


# ----------------------------------------------------------------------------- current


@cache
def calm_model(scenario: str, config_name: str) -> dict[str, dict[str, float]]:
    """The current pipeline's model identified in a 300 s calm-water run of the same
    vehicle and mission (seed 7; mode (a), docs/current.md)."""
    from validation.reports import current_validation as cv

    return cv.calm_model(scenario, config_name, duration=300.0)


@cache
def calm_state(scenario: str, config_name: str) -> dict[str, Any]:
    """The persistent state of that calm-water identification (its coefficients and their
    covariance, :func:`.current_validation.identified_state`): what mode (a) runs carry, so
    that the model's uncertainty reaches the current's sigma."""
    from validation.reports import current_validation as cv

    return cv.calm_state(scenario, config_name, duration=300.0)


CURRENT_RUNS: dict[str, tuple[str, str, bool, float, float]] = {
    # key: (scenario, config, configured model by default, duration s, metrics after s)
    "gavia-tidal": ("gavia-tidal", "torpedo-auv", True, 200.0, 60.0),
    "spheroid-sawtooth": ("spheroid-sawtooth", "spheroid", True, 600.0, 100.0),
    "effect-current": ("effect-current", "rudder-boat", False, 600.0, 120.0),
    "boat-tidal": ("boat-tidal", "rudder-boat", False, 900.0, 120.0),
    "jaiabot-turns": ("jaiabot-turns", "rudder-boat", False, 300.0, 120.0),
    "twin-thruster-turns": ("twin-thruster-turns", "twin-thruster-boat", False, 300.0, 120.0),
}
"""The current pipeline's figure runs: a configured model identified in calm water
(mode (a)) or none (mode (b), the surface boat identifies its own online). The two
current-free boat runs measure what the pipeline makes of no current at all."""


def current_run(key: str, observer: str, seed: int, model: bool | None = None
                ) -> dict[str, Any]:
    """``current_validation.run`` of ``CURRENT_RUNS[key]`` with ``observer`` (``kf``,
    ``hgo`` at its configured gamma*, ``flow``); ``model``: with the calm-water identified
    model (mode (a)) or without (mode (b)), ``None`` the run's default."""
    return _current_run(key, observer, seed,
                        CURRENT_RUNS[key][2] if model is None else bool(model))


@cache
def _current_run(key: str, observer: str, seed: int, model: bool) -> dict[str, Any]:
    from validation.reports import current_validation as cv

    scenario, cfg, _, duration, _ = CURRENT_RUNS[key]
    state = calm_state(scenario, cfg) if model else None
    section: dict[str, Any] = {"model": state["thetas"]} if state else {}
    if observer != "kf":
        section["observer"] = observer
    sc = cv.boat_tidal_scenario() if scenario == "boat-tidal" else scenario
    return cv.run(sc, section, cfg, duration=duration, seed=seed, state=state)


def current_metrics(key: str, observer: str, seed: int, model: bool | None = None
                    ) -> dict[str, Any]:
    """``current_validation.metrics`` of :func:`current_run` after the run's window:
    per axis rms, std, 2-sigma coverage, published fraction; and ``transient``: the
    start-up peak (m/s), peaking (m/s) and the time the error takes to stay below
    0.1 m/s (s; NaN when the horizontal current is never published)."""
    return _current_metrics(key, observer, seed,
                            CURRENT_RUNS[key][2] if model is None else bool(model))


@cache
def _current_metrics(key: str, observer: str, seed: int, model: bool) -> dict[str, Any]:
    from validation.reports import current_validation as cv

    r = _current_run(key, observer, seed, model)
    peak, peaking, settle = cv.transient(r)
    return cv.metrics(r, after=CURRENT_RUNS[key][4]) | {
        "transient": {"peak": peak, "peaking": peaking, "settle": settle}}


# ----------------------------------------------------------------------------- ESESO


@cache
def closed_loop(controller: str, seed: int = 0, duration: float = 240.0,
                speed: float | None = None) -> dict[str, Any]:
    """``sitl.closed_loop.simulate``: the ``bluerov2-circle`` closed loop with the ESESO
    in it; the report (tracking RMSE m, disturbance error N, ESESO state errors)."""
    from onboard.sitl import closed_loop as cl

    sc = cl.CircleScenario() if speed is None else cl.CircleScenario(speed=speed)
    return cl.simulate(controller, duration=duration, seed=seed, scenario=sc)[0]


@cache
def eseso_nis(seed: int, seconds: float = 120.0) -> dict[str, tuple[float, int]]:
    """Mean NIS per ESESO channel over every update (its innovation records, gated ones
    included) on ``bluerov2-circle`` through ``sitl.runner`` (its PID), and the number of
    updates: ``{channel: (mean, n)}``."""
    from onboard.core import config as config_mod
    from onboard.engine import Engine, run
    from onboard.pipelines import eseso as eseso_mod
    from onboard.sitl.runner import simulate

    cfg = config_mod.load("bluerov2")
    p = eseso_mod.create(cfg)
    if p is None:
        raise RuntimeError("config/bluerov2.toml does not enable the eseso pipeline")
    eng = Engine(cfg, pipelines=[p])
    records = eng.monitor.keep(p.name)
    stream = (s for _, samples, _ in simulate("bluerov2-circle", seconds, seed=seed)
              for s in samples)
    run(eng, stream, lambda t, recs: None)
    nis: dict[str, list[float]] = {}
    for r in records:  # a sample rejected before any update has no NIS
        if math.isfinite(r.nis):
            nis.setdefault(r.channel, []).append(r.nis)
    return {ch: (float(np.mean(v)), len(v)) for ch, v in nis.items()}


# ----------------------------------------------------------------------------- diagnose


@cache
def diagnose_sitl(scenario: str, seed: int = 1,
                  config_path: Path = SITL_DIAGNOSE_CONFIG) -> dict[str, Any]:
    """``onboard diagnose`` of a ``scenario`` log (``sitl.runner.run_to_tlog``) with
    ``config_path`` (default ``config/sitl-rudder-boat.toml``) and nothing declared:
    ``diagnosis.json`` plus ``report_bytes``, the size of ``report.html``."""
    from onboard.core import config as config_mod
    from onboard.offline.diagnose import diagnose
    from onboard.sitl.runner import run_to_tlog

    with tempfile.TemporaryDirectory(prefix="onboard-figures-") as tmp:
        d = Path(tmp)
        run_to_tlog(scenario, d / "log.tlog", d / "truth.jsonl", seed=seed)
        doc = diagnose(str(d / "log.tlog"), config_mod.load(config_path), d / "out")
        doc = {**doc, "report_bytes": (d / "out" / "report.html").stat().st_size}
    return doc


def named(doc: dict[str, Any]) -> set[str]:
    """The effects a diagnosis names (``detected``)."""
    return {e["name"] for e in doc["effects"] if e["detected"]}


def effects_named(scenario: str, seed: int = 1) -> int:
    """How many of the effects injected in ``scenario`` its diagnosis names. A sideslip
    counts when it is named or listed ``ambiguous_with`` the heading bias named instead
    (one compass and GNSS cannot separate them, docs/diagnose.md)."""
    doc = diagnose_sitl(scenario, seed)
    f = {e["name"]: e for e in doc["effects"] if e["detected"]}
    n = 0
    for eff in DIAGNOSE_SCENARIOS[scenario]:
        if eff in f or (eff == "sideslip" and "sideslip" in
                        f.get("heading_bias", {}).get("evidence", {}).get("ambiguous_with", [])):
            n += 1
    return n


@cache
def diagnose_blueboat() -> dict[str, Any]:
    """``onboard diagnose`` of the NTNU BlueBoat runs with ``config/blueboat-ntnu-csv.toml``
    as shipped (its thruster mapping): the README's command."""
    from onboard.core import config as config_mod
    from onboard.offline.diagnose import diagnose

    runs = data_dir() / "blueboat_sysid_ntnu"
    if not runs.is_dir():
        raise MissingData(f"{runs} not in the shared data")
    with tempfile.TemporaryDirectory(prefix="onboard-figures-") as tmp:
        return diagnose(str(runs), config_mod.load(REPO / "config" / "blueboat-ntnu-csv.toml"),
                        Path(tmp) / "out")


@cache
def diagnose_blueboat_literal() -> dict[str, Any]:
    """``onboard diagnose`` of the NTNU BlueBoat runs with the thruster columns taken
    literally (``thr_left`` = left, both ahead above neutral): the mapping must be found."""
    from onboard.core import config as config_mod
    from onboard.offline.diagnose import diagnose

    runs = data_dir() / "blueboat_sysid_ntnu"
    if not runs.is_dir():
        raise MissingData(f"{runs} not in the shared data")
    text = (REPO / "config" / "blueboat-ntnu-csv.toml").read_text()
    for role, ch in (("left", 1), ("right", 2)):
        text = re.sub(rf"^{role} = .*$", f'{role} = {{ source = "servo", channel = {ch}, '
                      'neutral_us = 1510, half_range_us = 390, deadband_us = 25 }',
                      text, flags=re.M)
    with tempfile.TemporaryDirectory(prefix="onboard-figures-") as tmp:
        cfg_path = Path(tmp) / "literal.toml"
        cfg_path.write_text(text)
        return diagnose(str(runs), config_mod.load(cfg_path), Path(tmp) / "out")


@cache
def diagnose_usv_heading() -> dict[str, Any]:
    """``onboard diagnose`` of the Shenzhen USV's RTK/dual-antenna NMEA log (its config
    detected from the log)."""
    from onboard.offline.diagnose import diagnose
    from onboard.offline.replay import choose_config

    log = data_dir() / "usv_rtk_gnss_heading_nmea_shenzhen" / "202412051751.txt"
    if not log.exists():
        raise MissingData(f"{log} not in the shared data")
    cfg, _ = choose_config(str(log), None)
    with tempfile.TemporaryDirectory(prefix="onboard-figures-") as tmp:
        return diagnose(str(log), cfg, Path(tmp))


def usv_heading_offset_deg() -> float:
    """The magnitude of the ``heading_bias`` :func:`diagnose_usv_heading` names (deg)."""
    found = {e["name"]: e for e in diagnose_usv_heading()["effects"] if e["detected"]}
    if "heading_bias" not in found:
        return float("nan")
    return abs(math.degrees(found["heading_bias"]["params"]["bias"]))


# ----------------------------------------------------------------------------- gliders

GLIDER_DEV_SEEDS = tuple(range(1, 9))
"""Seeds of ``onboard sitl --glider`` the dive current's error model was written on."""
GLIDER_HELD_OUT_SEEDS = tuple(range(9, 25))
"""Seeds held out from it (docs/current.md, "A glider's depth-averaged current")."""
GRAVER_LIFT = {"lift_kl": 132.5, "drag_kd0": 2.15, "drag_kd": 25.0}
"""Graver's (2005) Slocum coefficients, the glide model's defaults before Merckelbach et
al.'s (2019)."""


def graver_overlay(folder: Path) -> Path:
    """``folder/graver.toml``: a config overlay of Graver's lift (:data:`GRAVER_LIFT`)."""
    path = folder / "graver.toml"
    path.write_text("[pipelines.current.glider]\n" + "".join(
        f"{k} = {v}\n" for k, v in GRAVER_LIFT.items()))
    return path


def dive_errors(log: Path, truth: list[dict], out: Path,
                configs: list[str] | None = None) -> np.ndarray:
    """Each dive's ``dac`` current of a simulated glider's log, replayed into ``out`` with
    its own config (or ``configs``, applied in order), against ``truth`` (its dives,
    :func:`sitl.glider.fly`): a row per dive, the error north and east and the sigma
    north and east (m/s). ValueError where the replay's dives are not the truth's."""
    import csv

    from onboard.offline.replay import choose_config, replay

    cfg, _ = choose_config(str(log), configs)
    replay(str(log), cfg, out, plot=False)
    with open(out / "estimates.csv") as f:
        est = {r["dac.dive_end"]: r for r in csv.DictReader(f) if r["dac.north"]}
    if len(est) != len(truth):
        raise ValueError(f"{log}: {len(est)} dive currents for {len(truth)} true dives")
    return np.array([[float(d["dac.north"]) - tr["north"], float(d["dac.east"]) - tr["east"],
                      float(d["dac.std_north"]), float(d["dac.std_east"])]
                     for d, tr in zip(est.values(), truth)])


@cache
def glider_dac(first: int, last: int, graver: bool = False) -> dict[str, float]:
    """Each dive's ``dac`` current of the simulated gliders of seeds ``first``-``last``
    (four dives each, :func:`sitl.glider.fly`, replayed with config/slocum-glider.toml;
    with ``graver`` Graver's lift instead) against its truth, pooled over north and east
    (:func:`dive_errors`): ``rms`` (m/s), ``cover1``, ``cover2`` (within 1 and 1.96
    sigma), ``z_median`` (median |error| / sigma), ``dives``."""
    from onboard.core import config as config_mod
    from onboard.sitl.glider import fly

    rows = []
    with tempfile.TemporaryDirectory(prefix="onboard-figures-") as tmp:
        configs = [str(config_mod.resolve("slocum-glider")),
                   str(graver_overlay(Path(tmp)))] if graver else None
        for seed in range(first, last + 1):
            run = fly(Path(tmp) / f"glider-{seed}", seed)
            rows.append(dive_errors(run.path, run.dives, Path(tmp) / f"replay-{seed}",
                                    configs))
    a = np.concatenate(rows)
    e_arr, z_arr = a[:, :2].ravel(), (np.abs(a[:, :2]) / a[:, 2:]).ravel()
    return {"rms": float(np.sqrt(np.mean(e_arr ** 2))), "cover1": float(np.mean(z_arr < 1.0)),
            "cover2": float(np.mean(z_arr < 1.96)), "z_median": float(np.median(z_arr)),
            "dives": float(len(a))}
