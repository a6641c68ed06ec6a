"""The results file: every figure of ``docs/figures.json`` as one row per seed.

``python -m validation figures --results docs/results.csv`` writes it (alone: from
docs/figures.json, nothing recomputed; with ``--write``: from the file written). Columns::

    name, scenario, seed, value, unit, reference

``reference`` says what the figure is measured against: simulator truth, a field log's
own channel, a chi-square distribution, or nothing (an identified coefficient, a count
of named effects). A figure measured against simulator truth is never a field figure:
docs/aie.md and docs/current.md keep the two apart where they set ours beside a paper's.
"""

from __future__ import annotations

import csv
import fnmatch
import io
from pathlib import Path
from typing import Any

SIM = "simulator truth"
"""The reference of a figure computed against the simulator's hidden state."""

REFERENCES: tuple[tuple[str, str], ...] = (
    ("aie.blueboat.*", "field log: the logged surge speed (the autopilot's estimate)"),
    ("aie.*.identified.*", "none: a model coefficient identified on seed 10"),
    ("aie.*.cover*", SIM + " (fraction of errors within the published sigma)"),
    ("current.*.cover*", SIM + " (fraction of errors within the published sigma)"),
    ("current.*.published", "none: fraction of ticks with a published estimate"),
    ("eseso.nis*", "chi-square: mean normalized innovation squared (expected: dimension)"),
    ("eseso.*_over_*", SIM + " (a ratio of two tracking errors)"),
    ("current.*.lipschitz", "none: a bound of the model the observer runs"),
    ("current.*.gamma_star", "none: the gain of the model the observer runs"),
    ("diagnose.blueboat.*", "field log: the logged surge speed"),
    ("diagnose.blueboat_literal.*", "field log: the logged surge speed"),
    ("diagnose.usv_shenzhen.*", "none: an offset found on a field log (no truth)"),
    ("diagnose.*", "the simulator's injected effects"),
    ("*", SIM),
)
"""What each figure is measured against: the first pattern its name matches."""

SCENARIOS: tuple[tuple[str, str], ...] = (
    ("aie.blueboat.*", "blueboat_sysid_ntnu (field, 8 held-out runs)"),
    ("aie.gnss_outage.*", "fault-gnss-outage"),
    ("eseso.*", "bluerov2-circle"),
    ("diagnose.blueboat.*", "blueboat_sysid_ntnu (field)"),
    ("diagnose.blueboat_literal.*", "blueboat_sysid_ntnu (field)"),
    ("diagnose.usv_shenzhen.*", "usv_shenzhen (field)"),
    ("diagnose.effects_named", "the 11 effect scenarios"),
)
"""Scenarios not spelled in the figure's name; otherwise its second part, with hyphens."""

HEADER = ("name", "scenario", "seed", "value", "unit", "reference")


def _first(name: str, rules: tuple[tuple[str, str], ...]) -> str | None:
    return next((v for pat, v in rules if fnmatch.fnmatchcase(name, pat)), None)


def reference(name: str) -> str:
    """What figure ``name`` is measured against (:data:`REFERENCES`)."""
    return _first(name, REFERENCES) or SIM


def scenario(name: str) -> str:
    """The scenario (or field log) of figure ``name``."""
    return _first(name, SCENARIOS) or name.split(".")[1].replace("_", "-")


def rows(doc: dict[str, Any]) -> list[tuple[str, ...]]:
    """The results rows of a figures file's contents, one per figure and seed (seed
    empty for a figure without seeds), the value at two digits beyond the printed ones
    (``n/a``: never published)."""
    out = []
    for name, rec in doc["figures"].items():
        d = int(rec["digits"]) + 2
        for seed, v in rec["values"].items():
            out.append((name, scenario(name), "" if seed == "-" else seed,
                        "n/a" if v is None else f"{v:.{d}f}", rec["unit"], reference(name)))
    return out


def render(doc: dict[str, Any]) -> str:
    """The CSV text of :func:`rows` with its header."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(HEADER)
    w.writerows(rows(doc))
    return buf.getvalue()


def write(path: Path, doc: dict[str, Any]) -> bool:
    """Write the results file; True when it changed."""
    text = render(doc)
    old = path.read_text(encoding="utf-8") if path.exists() else None
    if old != text:
        path.write_text(text, encoding="utf-8")
    return old != text
