"""The numbers the prose of README.md and docs/*.md quotes, and where each comes from.

The generated tables are the figures file's by construction (:mod:`validation.render`,
checked by tests/test_figures.py). Prose quotes numbers too ("the calm-water Gavia fit has
`L_f` = 5.91"), and those drift when a change moves a figure and nobody rereads the
sentence. Every quote registered here says where its numbers come from;
tests/test_docs_numbers.py checks that each is on its page (outside the generated blocks
and code) and agrees with its source:

* :class:`FromFigures`: the quote as a template of :mod:`validation.render`, with
  placeholders where the numbers go (``{current.gavia_tidal.hgo.lipschitz:2}``, a
  ``tuning.*`` record too); the page must hold it filled from docs/figures.json and
  docs/tuning.json.
* :class:`FromTest`: the quote with its numbers in braces (``{0.325} -> {0.066}``) and
  the test that checks them: the test must exist and state each number (the measured
  figure beside its bound, the house rule), so a number changed on one side only fails.
* :class:`Measured`: the quote with its numbers in braces and, for each, what measures
  it, cheaply and here: a gain file's gamma*, a configuration default, a scenario's
  current, the runs of a data set (:data:`MissingData` without ../shared/data: skipped).

:data:`SCANS` are the prose patterns of numbers that drifted before (issue 30: gamma*,
`L_f`, a count of BlueBoat runs, a before -> after pair of a BlueBoat diagnosis). Every
match on a page must lie inside a registered quote or a :class:`Record` (a number of the
past kept as such, with why), so a new sentence of that kind cannot go unregistered.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any, Callable

REPO = Path(__file__).resolve().parents[1]
PAGES = ("README.md", "docs/*.md")
"""The pages whose prose is checked (globs under the repository)."""

_NUMBER = r"-?\d+(?:\.\d+)?"
_MARKED = re.compile(r"\{(" + _NUMBER + r")\}")
"""A number in braces in a :class:`FromTest` or :class:`Measured` quote."""


@dataclass(frozen=True)
class FromFigures:
    """A quote whose numbers are figures: ``template`` in :mod:`validation.render`'s
    placeholder syntax, filled from docs/figures.json and docs/tuning.json."""

    page: str
    template: str


@dataclass(frozen=True)
class FromTest:
    """A quote whose braced numbers ``test`` (``tests/FILE.py::NAME``) checks and states."""

    page: str
    text: str
    test: str


@dataclass(frozen=True)
class Measured:
    """A quote whose braced numbers are measured here, in order, by ``measures``."""

    page: str
    text: str
    measures: tuple[Callable[[], float], ...]


@dataclass(frozen=True)
class Record:
    """Text on ``page`` whose numbers are a record of the past (a before/after, a
    campaign on a date, a former model), kept as what it says it is; ``why`` says so."""

    page: str
    text: str
    why: str


Quote = FromFigures | FromTest | Measured


def marked(text: str) -> tuple[str, list[str]]:
    """``text`` without the braces of its marked numbers, and those numbers in order."""
    return _MARKED.sub(r"\1", text), _MARKED.findall(text)


def agrees(quoted: str, value: float) -> bool:
    """Whether ``value`` printed with the decimals of ``quoted`` reads ``quoted``."""
    decimals = len(quoted.partition(".")[2])
    return math.isfinite(value) and f"{value:.{decimals}f}" == quoted


# ----------------------------------------------------------------------------- measures


@cache
def _gain_file(vehicle_class: str) -> dict[str, Any]:
    return json.loads((REPO / "config" / "gains" / f"{vehicle_class}.json").read_text())


def gain(vehicle_class: str, key: str) -> Callable[[], float]:
    """A value of ``config/gains/<vehicle_class>.json``: ``gamma_star``, ``lipschitz``,
    ``k1``/``k2`` (the first axis's gains), ``P_norm`` (the 2-norm of ``P``)."""
    def measure() -> float:
        g = _gain_file(vehicle_class)
        if key in ("k1", "k2"):
            return float(g["K"][0 if key == "k1" else 1][0])
        if key == "P_norm":
            import numpy as np

            return float(np.linalg.norm(np.asarray(g["P"]), 2))
        return float(g[key])
    return measure


def current_default(field: str) -> Callable[[], float]:
    """The default of ``[pipelines.current] field``."""
    def measure() -> float:
        from onboard.core.pipeline_config import CurrentConfig

        return float(getattr(CurrentConfig(), field))
    return measure


def demo(name: str) -> Callable[[], float]:
    """A constant of the demo (``onboard.apps.demo`` or ``demo_truth``)."""
    def measure() -> float:
        from onboard.apps import demo as d, demo_truth as dt

        return float(getattr(d, name) if hasattr(d, name) else getattr(dt, name))
    return measure


def scenario_current(name: str) -> Callable[[], float]:
    """The speed (m/s) of the water current a scenario injects."""
    def measure() -> float:
        from onboard.sitl.scenarios import get

        p = next(e.params for e in get(name).injected if e.name == "water_current")
        return math.hypot(p["north"], p["east"])
    return measure


def data_runs(folder: str) -> Callable[[], float]:
    """The runs (CSV files) of a data set in ../shared/data (raises
    ``validation.reports.runs.MissingData`` without it)."""
    def measure() -> float:
        from validation.reports.runs import MissingData, data_dir

        path = data_dir() / folder
        if not path.is_dir():
            raise MissingData(f"{path} not in the shared data")
        return float(len(list(path.glob("*.csv"))))
    return measure


BLUEBOAT_RUNS = data_runs("blueboat_sysid_ntnu")


def _blueboat_test_runs() -> float:
    """The BlueBoat runs docs/aie.md 3.3 tests on: every other run in name order
    (``validation.reports.runs.blueboat_heldout``'s split)."""
    from validation.reports.runs import MissingData, data_dir

    path = data_dir() / "blueboat_sysid_ntnu"
    if not path.is_dir():
        raise MissingData(f"{path} not in the shared data")
    return float(len(sorted(path.glob("fixed_*.csv"))[1::2]))


BLUEBOAT_TEST_RUNS = _blueboat_test_runs

# ----------------------------------------------------------------------------- the registry

_HGO = "current.gavia_tidal.hgo"
_BB = "diagnose.blueboat"
_BBL = "diagnose.blueboat_literal"

QUOTES: tuple[Quote, ...] = (
    # README.md
    FromFigures("README.md", "the second command reports the test runs' open-loop surge "
                f"error {{{_BB}.holdout_before}} -> {{{_BB}.holdout_after}} m/s"),
    FromFigures("README.md", "with the thruster columns taken literally the diagnosis "
                f"finds the mapping itself first: {{{_BBL}.holdout_before}} -> "
                f"{{{_BBL}.holdout_after}} m/s"),
    Measured("README.md", "A component whose sigma is above {0.3} m/s is published as "
             "unknown", (current_default("unknown_above_std_mps"),)),
    Measured("README.md", "(by default {150} s of a boat flying turns in a {0.29} m/s "
             "current it is not told about", (demo("DEFAULT_DURATION_S"),
                                              scenario_current("effect-current"))),
    # docs/current.md: the HGO
    Measured("docs/current.md", "K = [{1.04}, {1.35}] per axis ([{1.07}, {1.36}] for the "
             "boats), ||P|| = {2}, γ* = {6.4} (torpedo, spheroid), {4.0} (boats), {1.2} "
             "(BlueROV2). Those γ* are of the *default* model (`L_f` = {1.60} for the "
             "torpedo)", (gain("torpedo-auv", "k1"), gain("torpedo-auv", "k2"),
                          gain("rudder-boat", "k1"), gain("rudder-boat", "k2"),
                          gain("torpedo-auv", "P_norm"), gain("torpedo-auv", "gamma_star"),
                          gain("rudder-boat", "gamma_star"), gain("bluerov2", "gamma_star"),
                          gain("torpedo-auv", "lipschitz"))),
    FromFigures("docs/current.md", f"the calm-water Gavia fit has `L_f` = {{{_HGO}.lipschitz}}, "
                f"γ* = {{{_HGO}.gamma_star}}"),
    FromFigures("docs/current.md", f"the observer then runs at {{{_HGO}.gamma_star}} "
                "instead of 6.4: RMS "
                f"{{{_HGO}.north_rms}} / {{{_HGO}.east_rms}} / {{{_HGO}.down_rms}} m/s"),
    Measured("docs/current.md", "the HGO at γ* = {6.4} loses the split",
             (gain("torpedo-auv", "gamma_star"),)),
    Measured("docs/current.md", "HGO at γ = γ* = {4.0} (and", (gain("rudder-boat", "gamma_star"),)),
    FromFigures("docs/current.md", f"| gavia-tidal (γ* = {{{_HGO}.gamma_star}}; its own "
                "model's coefficients"),
    FromFigures("docs/current.md", "| spheroid-sawtooth (γ* = "
                "{current.spheroid_sawtooth.hgo.gamma_star}; consider parameters"),
    FromFigures("docs/current.md", "by the HGO at γ* of the model it runs "
                "({current.spheroid_sawtooth.hgo.north_rms} / "
                "{current.spheroid_sawtooth.hgo.east_rms} m/s;"),
    Measured("docs/current.md", "The real BlueBoat log (NTNU, {16} runs", (BLUEBOAT_RUNS,)),
    # docs/algorithms.md
    Measured("docs/algorithms.md", "`K = [{1.04}, {1.35}]` per axis (`[{1.07}, {1.36}]` for the "
             "boats), `||P|| = {2}`, `gamma* = {6.4}` (torpedo, spheroid), {4.0} (boats), "
             "{1.2} (BlueROV2)",
             (gain("torpedo-auv", "k1"), gain("torpedo-auv", "k2"), gain("rudder-boat", "k1"),
              gain("rudder-boat", "k2"), gain("torpedo-auv", "P_norm"),
              gain("torpedo-auv", "gamma_star"), gain("rudder-boat", "gamma_star"),
              gain("bluerov2", "gamma_star"))),
    # docs/aie.md
    FromFigures("docs/aie.md", "on `jaiabot-turns` the KF is ahead "
                "({aie.jaiabot_turns.speed_rmse.kf} against the AIE's "
                "{aie.jaiabot_turns.speed_rmse.aie} m/s), on `twin-thruster-turns` they are "
                "level ({aie.twin_thruster_turns.speed_rmse.kf} against "
                "{aie.twin_thruster_turns.speed_rmse.aie}); both are well below the raw GNSS "
                "speed's {aie.jaiabot_turns.speed_rmse.gnss} / "
                "{aie.twin_thruster_turns.speed_rmse.gnss} m/s. The "
                "AIE is ahead on heading on both boats ({aie.jaiabot_turns.heading_rmse.aie} "
                "against {aie.jaiabot_turns.heading_rmse.kf} rad, "
                "{aie.twin_thruster_turns.heading_rmse.aie} against "
                "{aie.twin_thruster_turns.heading_rmse.kf})"),
    FromFigures("docs/aie.md", "With the identified models the AIE is slightly ahead on "
                "`jaiabot-turns` ({aie.jaiabot_turns.model_identified.speed_rmse.aie} against "
                "{aie.jaiabot_turns.model_identified.speed_rmse.kf}) and the KF on "
                "`twin-thruster-turns` ({aie.twin_thruster_turns.model_identified.speed_rmse.kf}"
                " against {aie.twin_thruster_turns.model_identified.speed_rmse.aie})"),
    FromFigures("docs/aie.md", "random-walk bias state (`kf`, {tuning.kf.speed.jaiabot_turns}) "
                "or by RCIE on top of the map (`aie`, {tuning.aie.speed.jaiabot_turns}), "
                "halves it"),
    FromFigures("docs/aie.md", "The KF is ahead on `jaiabot-turns` "
                "({tuning.kf.speed.jaiabot_turns} against {tuning.aie.speed.jaiabot_turns}), "
                "level on `twin-thruster-turns` ({tuning.kf.speed.twin_thruster_turns} against "
                "{tuning.aie.speed.twin_thruster_turns}), behind on `effect-waves` "
                "({tuning.kf.speed.effect_waves} against {tuning.aie.speed.effect_waves})"),
    FromFigures("docs/aie.md", "AIE {aie.blueboat.speed_rmse.aie}, KF "
                "{aie.blueboat.speed_rmse.kf}, speed from consecutive fixes "
                "{aie.blueboat.speed_rmse.gps} m/s"),
    Measured("docs/aie.md", "### 3.3 BlueBoat field data (`blueboat_sysid_ntnu`, {16} runs)",
             (BLUEBOAT_RUNS,)),
    Measured("docs/aie.md", "1 s later on 14 of {16} runs", (BLUEBOAT_RUNS,)),
    Measured("docs/aie.md", "Held-out mean ({8} runs)", (BLUEBOAT_TEST_RUNS,)),
    # docs/diagnose.md
    Measured("docs/diagnose.md", "{16} runs of a BlueBoat (ArduRover, two T200 thrusters)",
             (BLUEBOAT_RUNS,)),
    FromFigures("docs/diagnose.md", "| linear model, thruster columns taken literally "
                f"(`thr_left` = left, both ahead) | {{{_BBL}.holdout_before}} |"),
    FromFigures("docs/diagnose.md", "`thr_left` is the starboard thruster, reversed), + "
                "`thrust_nonlinearity` + `quadratic_drag` | "
                f"**{{{_BBL}.holdout_after}}** |"),
    FromFigures("docs/diagnose.md", "| the config's hand-made mapping "
                f"(`config/blueboat-ntnu-csv.toml`), linear | {{{_BB}.holdout_before}} |"),
    FromFigures("docs/diagnose.md", "+ `quadratic_drag` (d = 0.39 1/m) | "
                f"**{{{_BB}.holdout_after}}** |"),
    FromTest("docs/diagnose.md", "lateral velocity {0.325} -> {0.066} m/s",
             "tests/test_diagnose_real.py::test_shenzhen_dual_antenna_heading_offset"),
    Measured("docs/diagnose.md", "of the {16} single BlueBoat runs", (BLUEBOAT_RUNS,)),
    # docs/formats-text.md, docs/real-logs.md, docs/integrity.md
    Measured("docs/formats-text.md", "`shared/data/blueboat_sysid_ntnu` ({16} runs at 10 Hz",
             (BLUEBOAT_RUNS,)),
    Measured("docs/formats-text.md", "| blueboat_sysid_ntnu ({16} runs) |", (BLUEBOAT_RUNS,)),
    Measured("docs/real-logs.md", "aie/kf/current over the {16} runs", (BLUEBOAT_RUNS,)),
    Measured("docs/integrity.md", "| blueboat ({16} runs) |", (BLUEBOAT_RUNS,)),
    # docs/reproducing.md
    FromFigures("docs/reproducing.md", f"(\"the calm-water Gavia fit has `L_f` = "
                f"{{{_HGO}.lipschitz}}, γ* = {{{_HGO}.gamma_star}}\")"),
    FromFigures("docs/reproducing.md", f"**quoted** from `{_BBL}.*` ({{{_BBL}.holdout_before}} "
                f"-> {{{_BBL}.holdout_after}}) and `{_BB}.*` ({{{_BB}.holdout_before}} -> "
                f"{{{_BB}.holdout_after}};"),
    # docs/service.md: the demo
    Measured("docs/service.md", "By default it flies `effect-current` for {150} s",
             (demo("DEFAULT_DURATION_S"),)),
    Measured("docs/service.md", "in a {0.29} m/s current it is not told about",
             (scenario_current("effect-current"),)),
    Measured("docs/service.md", "has stayed at or below {0.1} m/s for {10} s",
             (demo("CURRENT_KNOWN_STD"), demo("CURRENT_SETTLE_S"))),
    Measured("docs/service.md", "A simulator that fell more than {1} s (simulated) behind",
             (demo("LATE_WARN_S"),)),
)
"""Every registered quote."""

RECORDS: tuple[Record, ...] = (
    Record("docs/current.md", "| γ = γ* = 6.4, held output (default) |",
           "the HGO gain table: a measurement at the gain file's 6.4 before the gain "
           "followed the model it runs (the page says so)"),
    Record("docs/current.md", "| γ = 2γ* = 12.8, held output |",
           "the same table's variant at twice the gain file's gamma*"),
    Record("docs/current.md", "a high-gain observer at γ* ≈ 55 too stiff to run",
           "a former model's gamma*, the reason it was dropped"),
    Record("docs/current.md", "the published current's 95th percentile 0.48 → 0.36 m/s and "
           "its largest 0.80 → 0.67 m/s", "the BlueBoat before and after the surge "
           "turn-loss regressor (r26, the page says so)"),
    Record("docs/current.md", "`gamma` follows gamma* of the model it runs: L_f 4.24 for the "
           "one-rpm", "the one-rpm Gavia HGO run of issue 32 (gavia-rpm, 1500 rpm, seed 1; "
           "the page says so), measured once: the pipeline's health lipschitz"),
    Record("docs/current.md", "model with L_f 8.09 (heave `uw` -4.05, surge `u|u|` -0.249)",
           "the same run on the code before the noise learning (67ff9d3^), measured once"),
    Record("docs/diagnose.md", "surge 0.047 -> 0.049 m/s",
           "single-run robustness table: measured once, dated; tests check bounds"),
    Record("docs/diagnose.md", "surge 0.124 -> 0.121 m/",
           "single-run robustness table: measured once, dated; tests check bounds"),
)
"""Text whose numbers the scans may find and that no source re-measures."""

_BLUEBOAT = re.compile(r"blueboat", re.I)
SCANS: dict[str, tuple[re.Pattern[str], re.Pattern[str] | None]] = {
    "gamma*": (re.compile(rf"(?:γ\*|gamma\*`?)\s*(?:=|≈|of)?\s*{_NUMBER}"), None),
    "L_f": (re.compile(rf"L_f`?\s*(?:=|≈|of)?\s*{_NUMBER}"), None),
    "BlueBoat runs": (re.compile(rf"\b{_NUMBER} (?:[\w-]+ ){{0,2}}runs\b"), _BLUEBOAT),
    "BlueBoat before -> after": (re.compile(rf"{_NUMBER}\s*(?:->|→)\s*{_NUMBER}"), _BLUEBOAT),
}
"""Each scan: the pattern of a quoted number, and what its sentence (or table cell,
:func:`sentence`) must mention for a match to count (None: always)."""


# ----------------------------------------------------------------------------- pages

_GENERATED = re.compile(r"<!-- ([a-z-]+):begin.*?<!-- \1:end[^>]*-->", re.S)
_FENCED = re.compile(r"^```.*?^```", re.S | re.M)


PARAGRAPH = "¶"
"""Where :func:`prose` marks a paragraph's end (a blank line, a heading, a block)."""


def prose(text: str) -> str:
    """A page's prose: generated blocks and fenced code replaced by a paragraph mark,
    headings and blank lines too, every other run of whitespace one space (a quote may
    wrap across lines)."""
    text = _GENERATED.sub(f"\n\n{PARAGRAPH}\n\n", text)
    text = _FENCED.sub(f"\n\n{PARAGRAPH}\n\n", text)
    text = re.sub(r"^(#+ .*)$", rf"\1 {PARAGRAPH}", text, flags=re.M)
    text = re.sub(r"\n\s*\n", f" {PARAGRAPH} ", text)
    return re.sub(r"\s+", " ", text)


def normal(text: str) -> str:
    """``text`` with every run of whitespace one space, as :func:`prose` has it."""
    return re.sub(r"\s+", " ", text).strip()


def pages() -> dict[str, str]:
    """The prose of every checked page by its path relative to the repository."""
    out = {}
    for pattern in PAGES:
        for path in sorted(REPO.glob(pattern)):
            out[path.relative_to(REPO).as_posix()] = prose(path.read_text(encoding="utf-8"))
    return out


def records_of_files() -> dict[str, Any]:
    """docs/figures.json's figures and docs/tuning.json's records, by name."""
    from validation import figures, tuning

    recs = dict(figures.load(figures.FIGURES_FILE)["figures"])
    recs.update(tuning.records(json.loads(tuning.TUNING_FILE.read_text(encoding="utf-8"))))
    return recs


def expected(quote: Quote, records: dict[str, Any]) -> str:
    """The text ``quote`` must have on its page (its placeholders filled, its braces
    removed), whitespace normalized."""
    if isinstance(quote, FromFigures):
        from validation import render

        return normal(render.fill(quote.template, records))
    return normal(marked(quote.text)[0])


def spans(page_text: str, text: str) -> list[tuple[int, int]]:
    """Every (start, end) of ``text`` in ``page_text``."""
    return [(m.start(), m.start() + len(text))
            for m in re.finditer(re.escape(text), page_text)]


_BOUNDARY = re.compile(rf"\. |\||{PARAGRAPH}")
"""Where a sentence, a table cell or a paragraph ends."""


def sentence(page_text: str, start: int, end: int) -> str:
    """The sentence, or table cell, of ``page_text`` around ``start:end``."""
    left = max((m.end() for m in _BOUNDARY.finditer(page_text, 0, start)), default=0)
    right = _BOUNDARY.search(page_text, end)
    return page_text[left:right.start() if right else len(page_text)]


def scan(page_text: str) -> list[tuple[str, int, int]]:
    """Every (scan name, start, end) of :data:`SCANS` in a page's prose."""
    hits = []
    for name, (pattern, near) in SCANS.items():
        for m in pattern.finditer(page_text):
            if near is None or near.search(sentence(page_text, m.start(), m.end())):
                hits.append((name, m.start(), m.end()))
    return hits
