"""The docs pages' results tables, generated from ``docs/figures.json``.

Each :class:`DocTable` is one Markdown table of a page under ``docs/``, written between
two markers::

    <!-- figures:begin KEY: generated from docs/figures.json by `python -m validation figures --docs docs` ... -->
    | ... |
    <!-- figures:end KEY -->

``python -m validation figures --docs docs`` rewrites every block from the file (``--write`` first
when figures are recomputed); ``tests/test_figures.py`` checks that every block equals its
rendering, so a number in these tables is the file's, and the file's is what the code
gives (within each figure's tolerance, ``validation/figures.py``).

A cell is a string in which ``{name}`` prints figure ``name`` at its own digits (its range
``lo-hi`` over its seeds when they differ), ``{name@2}`` its value on seed 2 and
``{name:4}`` / ``{name@2:4}`` with 4 decimals; or a computed cell (:class:`Seeds`,
:class:`BelowRaw`, :class:`Ratio`, :class:`Axes`, :class:`ChiSquareBand`). A value the file
holds as ``null`` (an estimate never published) prints ``n/a``. Rows of numbers quoted
from a paper are :class:`Quoted`, the only rows allowed without a figure.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence, Union

from onboard.core.errors import UsageError
from validation.reports import runs

PLACEHOLDER = re.compile(r"\{([a-z0-9_.]+)(?:@(\d+))?(?::(\d+))?\}")
"""``{name}``, ``{name@seed}``, ``{name:digits}``, ``{name@seed:digits}``."""


def _record(figs: dict[str, Any], name: str) -> dict[str, Any]:
    """The file's record of ``name``; a :class:`UsageError` when it lacks it."""
    if name not in figs:
        raise UsageError(f"a docs table names {name}, which the figures file lacks "
                         "(run python -m validation figures --only NAME --write docs/figures.json)")
    return figs[name]


def _values(rec: dict[str, Any], seed: str | None) -> list[float]:
    if seed is None:
        return [v for v in rec["values"].values() if v is not None]
    if seed not in rec["values"]:
        raise UsageError(f"a docs table asks for seed {seed} of a figure measured on "
                         f"{', '.join(rec['values'])}")
    v = rec["values"][seed]
    return [] if v is None else [v]


def format_value(rec: dict[str, Any], seed: str | None = None, digits: int | None = None
                 ) -> str:
    """A figure's value as the tables print it: on ``seed``, or its range ``lo-hi`` over
    the seeds when they differ at ``digits`` decimals (default the figure's); ``n/a``
    when never published."""
    d = int(rec["digits"]) if digits is None else digits
    vals = _values(rec, seed)
    if not vals:
        return "n/a"
    lo, hi = f"{min(vals):.{d}f}", f"{max(vals):.{d}f}"
    return lo if lo == hi else f"{lo}-{hi}"


def fill(text: str, figs: dict[str, Any]) -> str:
    """``text`` with every placeholder replaced by the file's value."""
    def sub(m: re.Match[str]) -> str:
        name, seed, digits = m.group(1), m.group(2), m.group(3)
        return format_value(_record(figs, name), seed, None if digits is None else int(digits))

    return PLACEHOLDER.sub(sub, text)


# ----------------------------------------------------------------------------- cells


@dataclass(frozen=True)
class Seeds:
    """The seeds figure ``name`` is measured on, as ``1`` or ``1-3`` or ``1, 4``."""

    name: str

    def names(self) -> tuple[str, ...]:
        """The figures the cell reads."""
        return (self.name,)

    def render(self, figs: dict[str, Any]) -> str:
        """The cell's text from the figures file's ``figures`` object."""
        seeds = sorted(int(s) for s in _record(figs, self.name)["values"] if s != "-")
        if not seeds:
            return "-"
        if seeds == list(range(seeds[0], seeds[-1] + 1)) and len(seeds) > 1:
            return f"{seeds[0]}-{seeds[-1]}"
        return ", ".join(str(s) for s in seeds)


@dataclass(frozen=True)
class BelowRaw:
    """Which of two filters' errors are below the raw measurement's on every seed:
    ``both``, ``AIE only`` (the first), ``KF only`` (the second) or ``**neither**``."""

    first: str
    second: str
    raw: str
    labels: tuple[str, str] = ("AIE", "KF")

    def names(self) -> tuple[str, ...]:
        """The figures the cell reads."""
        return (self.first, self.second, self.raw)

    def render(self, figs: dict[str, Any]) -> str:
        """The cell's text from the figures file's ``figures`` object."""
        raw = _record(figs, self.raw)["values"]

        def below(name: str) -> bool:
            vals = _record(figs, name)["values"]
            return all(v is not None and raw.get(k) is not None and v < raw[k]
                       for k, v in vals.items())

        a, b = below(self.first), below(self.second)
        if a and b:
            return "both"
        if a or b:
            return f"{self.labels[0] if a else self.labels[1]} only"
        return "**neither**"


@dataclass(frozen=True)
class Ratio:
    """Figure ``num`` over figure ``den`` on their common seeds (range when it differs),
    at ``digits`` decimals."""

    num: str
    den: str
    digits: int = 2

    def names(self) -> tuple[str, ...]:
        """The figures the cell reads."""
        return (self.num, self.den)

    def render(self, figs: dict[str, Any]) -> str:
        """The cell's text from the figures file's ``figures`` object."""
        a, b = _record(figs, self.num)["values"], _record(figs, self.den)["values"]
        r = [a[k] / b[k] for k in a if k in b and a[k] is not None and b[k]]
        return format_value({"values": dict(enumerate(r)), "digits": self.digits})


@dataclass(frozen=True)
class Axes:
    """Figures ``<prefix>.<axis>_<stat>`` over ``axes`` joined by `` / ``, bold where
    ``bold`` names the axis."""

    prefix: str
    stat: str
    axes: tuple[str, ...]
    digits: int | None = None
    bold: tuple[str, ...] = ()

    def names(self) -> tuple[str, ...]:
        """The figures the cell reads."""
        return tuple(f"{self.prefix}.{ax}_{self.stat}" for ax in self.axes)

    def render(self, figs: dict[str, Any]) -> str:
        """The cell's text from the figures file's ``figures`` object."""
        out = []
        for ax, name in zip(self.axes, self.names()):
            v = format_value(_record(figs, name), None, self.digits)
            out.append(f"**{v}**" if ax in self.bold else v)
        return " / ".join(out)


@dataclass(frozen=True)
class ChiSquareBand:
    """The two-sided 95 % band of the mean of ``n`` chi-square(``dim``) values, ``n`` the
    sum of the count figures ``counts`` over ``seeds`` (``runs.chi2_mean_band``), as
    ``[lo, hi]``."""

    counts: str
    dim: int
    seeds: tuple[str, ...]

    def names(self) -> tuple[str, ...]:
        """The figures the cell reads."""
        return (self.counts,)

    def render(self, figs: dict[str, Any]) -> str:
        """The cell's text from the figures file's ``figures`` object."""
        vals = _record(figs, self.counts)["values"]
        missing = [s for s in self.seeds if vals.get(s) is None]
        if missing:
            raise UsageError(f"{self.counts} lacks seed(s) {', '.join(missing)}")
        lo, hi = runs.chi2_mean_band(int(sum(vals[s] for s in self.seeds)), self.dim)
        return f"[{lo:.3f}, {hi:.3f}]"


Cell = Union[str, Seeds, BelowRaw, Ratio, Axes, ChiSquareBand]


@dataclass(frozen=True)
class Quoted:
    """A row of numbers quoted from a paper (no figure of ours in it)."""

    cells: tuple[str, ...]


Row = Union[tuple[Cell, ...], Quoted]


@dataclass(frozen=True)
class DocTable:
    """One generated table: its block key, the page under ``docs/`` it lives in, the
    header and the rows."""

    key: str
    page: str
    header: tuple[str, ...]
    rows: tuple[Row, ...]

    def names(self) -> set[str]:
        """Every figure the table reads."""
        out: set[str] = set()
        for row in self.rows:
            if isinstance(row, Quoted):
                continue
            for cell in row:
                if isinstance(cell, str):
                    out |= {m.group(1) for m in PLACEHOLDER.finditer(cell)}
                else:
                    out |= set(cell.names())
        return out

    def begin(self) -> str:
        """The opening marker."""
        return (f"<!-- figures:begin {self.key}: generated from docs/figures.json by "
                f"`python -m validation figures --docs docs`; the rows are tables() in "
                f"validation/doc_tables.py -->")

    def end(self) -> str:
        """The closing marker."""
        return f"<!-- figures:end {self.key} -->"

    def render(self, doc: dict[str, Any]) -> str:
        """The block (markers included) from a figures file's contents."""
        figs = doc["figures"]
        lines = [self.begin(), "| " + " | ".join(self.header) + " |",
                 "|" + "---|" * len(self.header)]
        for row in self.rows:
            if isinstance(row, Quoted):
                cells = list(row.cells)
            else:
                cells = [fill(c, figs) if isinstance(c, str) else c.render(figs) for c in row]
            if len(cells) != len(self.header):
                raise UsageError(f"docs table {self.key}: a row of {len(cells)} cells under "
                                 f"{len(self.header)} columns")
            lines.append("| " + " | ".join(cells) + " |")
        lines.append(self.end())
        return "\n".join(lines)

    def block(self, text: str) -> str:
        """The table's block in a page's text (markers included); a
        :class:`UsageError` when its markers are missing or repeated."""
        opening = f"<!-- figures:begin {self.key}:"
        i, j = text.find(opening), text.find(self.end())
        if i < 0 or j < i or text.count(opening) != 1 or text.count(self.end()) != 1:
            raise UsageError(f"docs/{self.page} has no single generated block {self.key} "
                             f"(the figures:begin {self.key} / figures:end {self.key} "
                             "markers)")
        return text[i:j + len(self.end())]


# ----------------------------------------------------------------------------- the tables


def _aie_sitl() -> DocTable:
    rows = []
    for sc in ("jaiabot-turns", "twin-thruster-turns"):
        k = sc.replace("-", "_")
        for seed in (1, 2, 3):
            rows.append((
                sc, str(seed),
                *(f"{{aie.{k}.speed_rmse.{w}@{seed}}}" for w in ("aie", "kf", "gnss")),
                *(f"{{aie.{k}.heading_rmse.{w}@{seed}:4}}" for w in ("aie", "kf")),
                *(f"{{aie.{k}.position_rmse.{w}@{seed}}}" for w in ("aie", "kf"))))
    return DocTable("aie.sitl", "aie.md",
                    ("scenario", "seed", "AIE speed", "KF speed", "GNSS speed", "AIE heading",
                     "KF heading", "AIE pos", "KF pos"), tuple(rows))


def _aie_effects() -> DocTable:
    rows = []
    for sc in runs.AIE_EFFECT_SCENARIOS:
        k = f"aie.{sc.replace('-', '_')}.speed_rmse"
        rows.append((sc, Seeds(f"{k}.aie"), f"{{{k}.aie}}", f"{{{k}.kf}}", f"{{{k}.gnss}}",
                     BelowRaw(f"{k}.aie", f"{k}.kf", f"{k}.gnss")))
    return DocTable("aie.effects", "aie.md",
                    ("scenario", "seeds", "AIE speed", "KF speed", "raw (ticks)",
                     "below raw on every seed?"), tuple(rows))


def _aie_coverage() -> DocTable:
    rows: list[Row] = []
    for seed in (1, 2, 3):
        k = "aie.jaiabot_turns"
        rows.append(("jaiabot-turns", str(seed),
                     *(f"{{{k}.cover1.{w}@{seed}}} / {{{k}.cover2.{w}@{seed}}}"
                       for w in ("aie", "kf")), "", "", "", ""))
    for seed in (1, 2, 3):
        k = "aie.gnss_outage"
        rows.append((
            "fault-gnss-outage", str(seed),
            *(f"{{{k}.run_cover1.{w}@{seed}}} / {{{k}.run_cover2.{w}@{seed}}}"
              for w in ("aie", "kf")),
            *(f"{{{k}.cover1.{w}@{seed}}} / {{{k}.cover2.{w}@{seed}}}" for w in ("aie", "kf")),
            f"{{{k}.max_error.aie@{seed}}} / {{{k}.max_error.kf@{seed}}} m",
            f"{{{k}.max_sigma.aie@{seed}}} / {{{k}.max_sigma.kf@{seed}}} m"))
    return DocTable("aie.coverage", "aie.md",
                    ("scenario", "seed", "AIE 1 / 2 sigma", "KF 1 / 2 sigma", "AIE outage",
                     "KF outage", "max error in the outage AIE / KF",
                     "max sigma in the outage AIE / KF"), tuple(rows))


def _aie_models() -> tuple[DocTable, DocTable]:
    sens: list[Row] = []
    ident: list[Row] = []
    for sc in ("jaiabot-turns", "twin-thruster-turns"):
        k = f"aie.{sc.replace('-', '_')}"
        for v, (what, f) in runs.AIE_MODEL_VARIANTS.items():
            m = f"{k}.model_{v}"
            sens.append((sc, f"{what} x {f}", f"{{{m}.speed_rmse.aie}}",
                         f"{{{m}.speed_rmse.kf}}", f"{{{m}.heading_rmse.aie}}",
                         f"{{{m}.heading_rmse.kf}}"))
        m = f"{k}.model_identified"
        ident.append((sc, f"a={{{k}.identified.surge_a}} g={{{k}.identified.surge_gain}} / "
                          f"a={{{k}.identified.heading_a}} g={{{k}.identified.heading_gain}}",
                      *(f"{{{m}.{q}_rmse.{w}}}" for q in ("speed", "heading", "position")
                        for w in ("aie", "kf"))))
    return (DocTable("aie.sensitivity", "aie.md",
                     ("scenario", "model", "AIE speed", "KF speed", "AIE heading",
                      "KF heading"), tuple(sens)),
            DocTable("aie.identified", "aie.md",
                     ("scenario", "model (surge / heading)", "AIE speed", "KF speed",
                      "AIE heading", "KF heading", "AIE pos", "KF pos"), tuple(ident)))


_OBSERVER = {"kf": "KF", "hgo": "HGO (γ = γ*)", "flow": "flow observer (Fan)"}
_SCENARIO_LABEL = {"effect-current": "effect-current (rudder boat, 0.29 m/s)",
                   "boat-tidal": "boat-tidal (0.1 + 0.3 cos(2πt/600) m/s)",
                   "jaiabot-turns": "jaiabot-turns (no current)",
                   "twin-thruster-turns": "twin-thruster-turns (no current)"}


def _current_validation() -> DocTable:
    from validation.figures import CURRENT_TABLE, current_token

    rows: list[Row] = []
    for key, obs, model, axes in CURRENT_TABLE:
        scenario, _, _, duration, _ = runs.CURRENT_RUNS[key]
        p = f"current.{current_token(key, obs, model)}"
        label = (f"{_SCENARIO_LABEL.get(scenario, scenario)}, {duration:.0f} s, "
                 f"{_OBSERVER[obs]}, {'(a)' if model else '(b)'}")
        rows.append((label, Axes(p, "rms", axes), Axes(p, "std", axes),
                     Axes(p, "cover2", axes), Axes(p, "published", axes),
                     f"{{{p}.peak}} / {{{p}.peaking}}", f"{{{p}.settle}}"))
        if key == "gavia-tidal" and obs == "hgo":
            rows.append(Quoted(("**Kim et al. 2018, field: HGO vs an ADCP (not simulator truth)**", "",
                                "**0.094 / 0.066 / 0.032**", "", "", "peaking ~10 s", "")))
    return DocTable("current.validation", "current.md",
                    ("run (seed 1)", "rms N / E / D (m/s)", "std N / E / D (m/s)",
                     "2σ cover N / E / D", "published N / E / D",
                     "transient peak / peaking (m/s)", "settle < 0.1 m/s (s)"), tuple(rows))


_CONTROLLER = {"pid": "PID", "nmpc": "NMPC", "nmpc_of": "offset-free NMPC", "ampc": "AMPC"}


def _eseso_results(key: str, controllers: Sequence[str]) -> DocTable:
    rows: list[Row] = []
    for c in controllers:
        p = f"eseso.{key}"
        rows.append((_CONTROLLER[c], f"{{{p}.tracking_rmse.{c}}}", f"{{{p}.control_rmse.{c}}}",
                     f"{{{p}.disturbance_rms.{c}}} / {{{p}.disturbance_max.{c}}}"))
    for base in [c for c in ("nmpc", "nmpc_of") if c in controllers]:
        rows.append((f"AMPC / {_CONTROLLER[base]}",
                     Ratio(f"eseso.{key}.tracking_rmse.ampc", f"eseso.{key}.tracking_rmse.{base}"),
                     Ratio(f"eseso.{key}.control_rmse.ampc", f"eseso.{key}.control_rmse.{base}"),
                     ""))
    return DocTable(f"eseso.{key}", "eseso-mpc.md",
                    ("controller", "tracking RMSE (true, m)", "control RMSE (estimate, m)",
                     "disturbance error RMS / max after 5 s (N)"), tuple(rows))


def _eseso_nis() -> DocTable:
    from validation.figures import NIS_TABLE_CHANNELS

    rows: list[Row] = []
    for ch, dim in NIS_TABLE_CHANNELS.items():
        rows.append((f"{ch} ({dim})",
                     " / ".join(f"{{eseso.nis_seed.{ch}@{s}}}" for s in (1, 2, 3)),
                     f"{{eseso.nis.{ch}}}",
                     ChiSquareBand(f"eseso.nis_count.{ch}", dim, ("1",)),
                     ChiSquareBand(f"eseso.nis_count.{ch}", dim, ("1", "2", "3"))))
    return DocTable("eseso.nis", "eseso-mpc.md",
                    ("channel (dim)", "seeds 1 / 2 / 3", "pooled", "95 % band, one seed (1)",
                     "95 % band, pooled"), tuple(rows))


def tables() -> tuple[DocTable, ...]:
    """Every generated docs table."""
    return (_aie_coverage(), _aie_sitl(), _aie_effects(), *_aie_models(),
            _current_validation(),
            _eseso_results("circle", ("pid", "nmpc", "nmpc_of", "ampc")),
            _eseso_results("circle_1p5", ("pid", "nmpc", "ampc")), _eseso_nis())


# ----------------------------------------------------------------------------- pages


def update_docs(docs_dir: Path, doc: dict[str, Any]) -> list[str]:
    """Rewrite every generated block of the pages in ``docs_dir`` from ``doc``; returns
    the keys of the blocks that changed."""
    changed = []
    by_page: dict[str, list[DocTable]] = {}
    for t in tables():
        by_page.setdefault(t.page, []).append(t)
    for page, ts in by_page.items():
        path = docs_dir / page
        if not path.is_file():
            raise UsageError(f"{path}: no such page (--docs takes the docs directory)")
        text = path.read_text(encoding="utf-8")
        new = text
        for t in ts:
            block = t.render(doc)
            old = t.block(new)
            if old != block:
                changed.append(t.key)
                new = new.replace(old, block)
        if new != text:
            path.write_text(new, encoding="utf-8")
    return changed
