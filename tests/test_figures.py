"""The README's figures against docs/figures.json, and docs/figures.json against a rerun.

* The README's "What it estimates" table is the one ``python -m validation figures --readme`` renders
  from docs/figures.json (so every number in it is the file's), and the file holds every
  registered figure with the registry's unit, seeds and tolerance.
* Likewise every generated table of the docs pages (``validation/doc_tables.py``,
  ``python -m validation figures --docs docs``): each block between its markers is the rendering of
  the file (no simulation: cheap).
* Each figure is recomputed (``validation/figures.py``, runs shared with the other SITL
  tests through ``validation/reports/runs.py``) and compared with the file within its
  stated tolerance: the figures' ``default_suite_seeds`` here, every other seed and figure
  with ``-m slow`` (real-log figures also skip without ../shared/data).

After an intended change of an estimator's figures: ``make figures`` (or ``python -m validation figures
--only 'aie.*' --write docs/figures.json --readme README.md --docs docs`` for the figures
it moved) and commit docs/figures.json, README.md and docs/ with the change.
"""

from __future__ import annotations

import copy
import math
import re

import pytest

from onboard.core.errors import UsageError
from validation import doc_tables as D
from validation import figures as F
from validation.reports import runs

REGISTRY = F.registry()


@pytest.fixture(scope="module")
def committed() -> dict:
    return F.load(F.FIGURES_FILE)


def test_the_readme_table_is_rendered_from_the_figures_file(committed) -> None:
    block = F.readme_block(F.README.read_text(encoding="utf-8"))
    assert block == F.render_table(committed), (
        "README.md's figures block differs from docs/figures.json: run "
        "`python -m validation figures --readme README.md` (or `make figures` to recompute)")


def test_the_figures_file_holds_every_figure_as_the_registry_states_it(committed) -> None:
    figs = committed["figures"]
    assert set(figs) == set(REGISTRY), ("file and registry differ: "
                                        f"{sorted(set(figs) ^ set(REGISTRY))}")
    for name, fig in REGISTRY.items():
        rec = figs[name]
        assert rec["unit"] == fig.unit, name
        assert rec["seeds"] == list(fig.seeds), name
        assert set(rec["values"]) == set(fig.keys()), name
        assert rec["digits"] == fig.digits, name
        assert rec["tolerance"] == {"rel": fig.tolerance.rel, "abs": fig.tolerance.abs}, name
        # null: an estimate never published in the run (a current component unknown)
        assert all(v is None or isinstance(v, float) for v in rec["values"].values()), name
    for key in ("versions", "written_utc", "command"):
        assert key in committed


def test_every_readme_placeholder_names_a_registered_figure() -> None:
    used = {m for row in F.README_ROWS for m in F.PLACEHOLDER.findall(row[3])}
    assert used <= set(REGISTRY), sorted(used - set(REGISTRY))
    for row in F.README_ROWS:
        # every row names at least one figure, its "ours" cell holds figures and
        # separators only (no prose template, no hand-copied number), and it says what
        # the figure is measured against
        assert F.PLACEHOLDER.search(row[3]), row
        assert re.fullmatch(r"[\s/;,\->]*(of \d+)?", F.PLACEHOLDER.sub("", row[3])), row
        assert row[4], row


def test_a_stale_readme_number_is_caught(committed) -> None:
    """Negative control: one figure moved in the file changes the rendered table."""
    doc = copy.deepcopy(committed)
    rec = doc["figures"]["aie.jaiabot_turns.speed_rmse.aie"]
    rec["values"] = {k: v + 0.01 for k, v in rec["values"].items()}
    assert F.render_table(doc) != F.render_table(committed)
    del doc["figures"]["aie.jaiabot_turns.speed_rmse.aie"]
    with pytest.raises(UsageError):
        F.render_table(doc)


def test_the_results_file_is_rendered_from_the_figures_file(committed) -> None:
    """docs/results.csv: one row per figure and seed, with its scenario and what it is
    measured against (``python -m validation figures --results docs/results.csv``)."""
    from validation import results as R

    path = F.REPO / "docs" / "results.csv"
    assert path.read_text(encoding="utf-8") == R.render(committed), (
        "docs/results.csv differs from docs/figures.json: run "
        "`python -m validation figures --results docs/results.csv`")
    assert R.reference("aie.jaiabot_turns.speed_rmse.aie") == "simulator truth"
    assert R.reference("aie.blueboat.speed_rmse.aie").startswith("field log")
    assert R.scenario("aie.twin_thruster_turns.speed_rmse.kf") == "twin-thruster-turns"
    n = sum(len(rec["values"]) for rec in committed["figures"].values())
    assert len(R.rows(committed)) == n


@pytest.mark.parametrize("table", D.tables(), ids=lambda t: t.key)
def test_every_docs_table_is_rendered_from_the_figures_file(table, committed) -> None:
    page = F.REPO / "docs" / table.page
    assert table.block(page.read_text(encoding="utf-8")) == table.render(committed), (
        f"docs/{table.page}'s generated table {table.key} differs from docs/figures.json: "
        "run `python -m validation figures --docs docs` (or `make figures` to recompute)")


def test_every_docs_table_names_registered_figures_only() -> None:
    keys = [t.key for t in D.tables()]
    assert len(keys) == len(set(keys))
    for table in D.tables():
        assert table.names() <= set(REGISTRY), (table.key, sorted(table.names() - set(REGISTRY)))
        for row in table.rows:
            # a row without a figure of ours must be a quoted paper row
            if not isinstance(row, D.Quoted):
                sub = D.DocTable("x", table.page, table.header, (row,))
                assert sub.names(), (table.key, row)


def test_a_stale_docs_table_is_caught_and_rewritten(committed, tmp_path) -> None:
    """Negative control: a figure moved in the file changes its table; ``update_docs``
    rewrites exactly the stale block, keeps the text around it, and a page without the
    markers is a UsageError."""
    table = next(t for t in D.tables() if t.key == "aie.effects")
    doc = copy.deepcopy(committed)
    rec = doc["figures"]["aie.effect_waves.speed_rmse.aie"]
    rec["values"] = {k: v + 0.01 for k, v in rec["values"].items()}
    assert table.render(doc) != table.render(committed)
    for page in {t.page for t in D.tables()}:
        (tmp_path / page).write_text((F.REPO / "docs" / page).read_text(encoding="utf-8"),
                                     encoding="utf-8")
    assert D.update_docs(tmp_path, committed) == []
    before = (tmp_path / table.page).read_text(encoding="utf-8")
    assert D.update_docs(tmp_path, doc) == ["aie.effects"]
    after = (tmp_path / table.page).read_text(encoding="utf-8")
    assert after.replace(table.render(doc), table.render(committed)) == before
    (tmp_path / table.page).write_text("no markers here\n", encoding="utf-8")
    with pytest.raises(UsageError):
        D.update_docs(tmp_path, committed)
    del doc["figures"]["aie.effect_waves.speed_rmse.aie"]
    with pytest.raises(UsageError):
        table.render(doc)


def test_docs_cells() -> None:
    figs = {"a": {"values": {"1": 0.05, "2": 0.09}, "digits": 3},
            "b": {"values": {"1": 0.06, "2": 0.06}, "digits": 3},
            "r": {"values": {"1": 0.07, "2": 0.08}, "digits": 3},
            "n": {"values": {"1": None}, "digits": 3},
            "one": {"values": {"3": 1.23456}, "digits": 2}}
    assert D.fill("{a@1} {a} {a@2:1} {one} {n}", figs) == "0.050 0.050-0.090 0.1 1.23 n/a"
    assert D.Seeds("a").render(figs) == "1-2" and D.Seeds("one").render(figs) == "3"
    assert D.BelowRaw("a", "b", "r").render(figs) == "KF only"  # a is above r on seed 2
    assert D.BelowRaw("b", "b", "r").render(figs) == "both"
    assert D.BelowRaw("r", "n", "b").render(figs) == "**neither**"
    assert D.Ratio("b", "a").render(figs) == "0.67-1.20"
    assert D.Axes("x", "rms", ("north", "east"), bold=("east",)).render(
        {"x.north_rms": figs["a"], "x.east_rms": figs["b"]}) == "0.050-0.090 / **0.060**"
    with pytest.raises(UsageError):
        D.fill("{a@7}", figs)


def test_compare_applies_the_tolerance(committed) -> None:
    """Negative control: a value just outside the tolerance fails, just inside passes."""
    fig = REGISTRY["aie.jaiabot_turns.speed_rmse.aie"]
    ref = committed["figures"][fig.name]["values"]["1"]
    allowed = fig.tolerance.allowed(ref)
    assert F.compare(fig, "1", ref + 0.99 * allowed, committed)[0]
    assert not F.compare(fig, "1", ref + 1.01 * allowed, committed)[0]
    assert not F.compare(fig, "9", ref, committed)[0]  # a seed the file lacks


def test_format_gives_a_range_over_seeds_only_when_they_differ() -> None:
    assert F.format_entry({"values": {"1": 0.0521, "2": 0.0524}}, 3) == "0.052"
    assert F.format_entry({"values": {"1": 0.0521, "2": 0.0536}}, 3) == "0.052-0.054"
    assert F.format_entry({"values": {"-": 10.0}}, 0) == "10"


def test_select_matches_globs_and_prefixes() -> None:
    names = ["aie.a.x", "aie.b.x", "current.a.y"]
    assert F.select(names, ["aie.*"]) == ["aie.a.x", "aie.b.x"]
    assert F.select(names, ["current"]) == ["current.a.y"]
    assert F.select(names, ["*.a.*"]) == ["aie.a.x", "current.a.y"]
    assert F.select(names, None) == names


def _cases(default: bool) -> list:
    out = []
    for name, fig in REGISTRY.items():
        dk = fig.default_keys()
        for key in fig.keys():
            if (key in dk) != default:
                continue
            marks = [] if default else [pytest.mark.slow]
            if fig.data:
                marks.append(pytest.mark.data)
            out.append(pytest.param(name, key, marks=marks, id=f"{name}[{key}]"))
    return out


def _check(name: str, key: str, committed: dict) -> None:
    fig = REGISTRY[name]
    try:
        value = fig.value(key)
    except runs.MissingData as err:
        pytest.skip(str(err))
    except ModuleNotFoundError as err:
        if err.name != "casadi":
            raise
        pytest.skip("the MPCs need the 'mpc' extra (casadi)")
    ok, why = F.compare(fig, key, None if math.isnan(value) else value, committed)
    assert ok, f"{name} [{key}] = {value:.6g} {fig.unit}: {why} ({fig.what})"


@pytest.mark.parametrize("name, key", _cases(default=True))
def test_figure_reproduces(name: str, key: str, committed: dict) -> None:
    """The default suite's subset: recomputed, within tolerance of docs/figures.json."""
    _check(name, key, committed)


@pytest.mark.parametrize("name, key", _cases(default=False))
def test_figure_reproduces_slow(name: str, key: str, committed: dict) -> None:
    """Every other figure and seed (``-m slow``)."""
    _check(name, key, committed)


def test_validate_checks_writes_and_exits_1_on_a_figure_outside_its_tolerance(
        committed, tmp_path, capsys) -> None:
    """``python -m validation figures --only ... --check ... --write ...`` on one cheap figure (its run
    is the default suite's 30 s closed loop, shared): against the committed file it passes;
    against a file whose value is moved by twice the tolerance it exits 1 and says which;
    the written file holds the figure with its unit, tolerance and versions."""
    import argparse
    import json

    pytest.importorskip("casadi", reason="the MPCs need the 'mpc' extra (casadi)")
    name = "eseso.circle_30s.disturbance_rms.ampc"
    good = tmp_path / "good.json"
    good.write_text(json.dumps(committed))
    args = argparse.Namespace(only=[name], write=str(tmp_path / "out.json"), check=str(good),
                              readme=None, docs=None, results=None)
    assert F.main(args) == 0
    written = json.loads((tmp_path / "out.json").read_text())
    assert set(written["figures"]) == {name}
    assert written["figures"][name]["unit"] == "N" and "numpy" in written["versions"]
    bad_doc = copy.deepcopy(committed)
    rec = bad_doc["figures"][name]
    rec["values"]["0"] += 2 * REGISTRY[name].tolerance.allowed(rec["values"]["0"])
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(bad_doc))
    args.check, args.write = str(bad), None
    assert F.main(args) == 1
    assert name in capsys.readouterr().err


def test_validate_docs_alone_rerenders_without_recomputing(committed, tmp_path, capsys) -> None:
    """``python -m validation figures --docs DIR`` alone re-renders the pages from docs/figures.json
    (a stale block is rewritten, nothing is recomputed); with ``--check`` and no
    ``--write`` it is a usage error."""
    import argparse

    table = D.tables()[0]
    for page in {t.page for t in D.tables()}:
        (tmp_path / page).write_text((F.REPO / "docs" / page).read_text(encoding="utf-8"),
                                     encoding="utf-8")
    path = tmp_path / table.page
    stale = path.read_text(encoding="utf-8").replace(table.render(committed),
                                                     f"{table.begin()}\n| old |\n{table.end()}")
    path.write_text(stale, encoding="utf-8")
    args = argparse.Namespace(only=None, write=None, check=None, readme=None,
                              docs=str(tmp_path), results=None)
    assert F.main(args) == 0
    assert table.block(path.read_text(encoding="utf-8")) == table.render(committed)
    assert table.key in capsys.readouterr().out
    args.check = str(F.FIGURES_FILE)
    with pytest.raises(UsageError):
        F.main(args)
