"""The README's figures against docs/figures.json, and docs/figures.json against a rerun.

* The README's "What it estimates" table is the one ``python -m validation figures --readme``
  renders from docs/figures.json (so every number in it is the file's), and the file holds
  every registered figure with the registry's unit, seeds and tolerance.
* Likewise every generated table of the docs pages (``python -m validation figures --docs
  docs``): each block between its markers is its template (``validation/templates/``)
  filled from the file by ``validation/render.py`` (no simulation: cheap).
* Each figure is recomputed (``validation/figures.py``, runs shared with the other SITL
  tests through ``validation/reports/runs.py``) and compared with the file within its
  stated tolerance: the figures' ``default_suite_seeds`` here, every other seed and figure
  with ``-m slow`` (real-log figures also skip without ../shared/data).

After an intended change of an estimator's figures: ``make figures`` (or ``python -m
validation figures --only 'aie.*' --write docs/figures.json --readme README.md --docs docs``
for the figures it moved) and commit docs/figures.json, README.md and docs/ with the change.
"""

from __future__ import annotations

import copy
import math
import re

import pytest

from onboard.core.errors import UsageError
from validation import figures as F
from validation import render as R
from validation.reports import runs

REGISTRY = F.registry()
(README_BLOCK,) = R.template_blocks(R.README_TEMPLATE)
DOCS_BLOCKS = [(t, b) for t in sorted(R.DOCS_TEMPLATES.glob("*.md"))
               for b in R.template_blocks(t, "figures")]
"""Every figures block of the docs pages' templates, with its template."""


def _docs_block(key: str) -> tuple:
    return next((t, b) for t, b in DOCS_BLOCKS if b.key == key)


def _copy_pages(tmp_path) -> None:
    for template, _ in DOCS_BLOCKS:
        (tmp_path / template.name).write_text(
            (F.REPO / R.page_of(template)).read_text(encoding="utf-8"), encoding="utf-8")


@pytest.fixture(scope="module")
def committed() -> dict:
    return F.load(F.FIGURES_FILE)


def test_the_readme_table_is_rendered_from_the_figures_file(committed) -> None:
    block = README_BLOCK.find(F.README.read_text(encoding="utf-8"))
    assert block == README_BLOCK.render(committed["figures"]), (
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
    assert README_BLOCK.names() <= set(REGISTRY), sorted(README_BLOCK.names() - set(REGISTRY))
    rows = [line.split(" | ") for line in README_BLOCK.body()[2:]]
    assert rows
    for row in rows:
        ours, ref = row[3], row[4]
        # every row names at least one figure, its "ours" cell holds figures and
        # separators only (no prose template, no hand-copied number), and it says what
        # the figure is measured against
        assert R.PLACEHOLDER.search(ours), row
        assert re.fullmatch(r"[\s/;,\->]*(of \d+)?", R.PLACEHOLDER.sub("", ours)), row
        assert ref.strip(), row


def test_a_stale_readme_number_is_caught(committed) -> None:
    """Negative control: one figure moved in the file changes the rendered table."""
    doc = copy.deepcopy(committed)
    rec = doc["figures"]["aie.jaiabot_turns.speed_rmse.aie"]
    rec["values"] = {k: v + 0.01 for k, v in rec["values"].items()}
    assert README_BLOCK.render(doc["figures"]) != README_BLOCK.render(committed["figures"])
    del doc["figures"]["aie.jaiabot_turns.speed_rmse.aie"]
    with pytest.raises(UsageError):
        README_BLOCK.render(doc["figures"])


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


@pytest.mark.parametrize("template, block", [pytest.param(t, b, id=b.key) for t, b in DOCS_BLOCKS])
def test_every_docs_table_is_rendered_from_the_figures_file(template, block, committed) -> None:
    page = F.REPO / R.page_of(template)
    assert block.find(page.read_text(encoding="utf-8")) == block.render(committed["figures"]), (
        f"{R.page_of(template)}'s generated table {block.key} differs from docs/figures.json: "
        "run `python -m validation figures --docs docs` (or `make figures` to recompute)")


def test_every_docs_table_names_registered_figures_only() -> None:
    idents = [(R.page_of(t), b.ident) for t in R.templates() for b in R.template_blocks(t)]
    assert len({i for _, i in idents}) == len(idents), idents
    for _, block in DOCS_BLOCKS:
        assert block.names() <= set(REGISTRY), (block.key,
                                                sorted(block.names() - set(REGISTRY)))


def test_every_generated_block_of_the_pages_has_a_template() -> None:
    """A page's ``figures:begin`` / ``tuning:begin`` marker without a template block would
    be a table nobody fills or checks."""
    begin = re.compile(r"^<!-- (figures|tuning):begin(?: ([\w.-]+))?:", re.M)
    have = {(R.page_of(t), b.ident) for t in R.templates() for b in R.template_blocks(t)}
    pages = [F.README, *sorted((F.REPO / "docs").glob("*.md"))]
    found = {(p.relative_to(F.REPO).as_posix(), f"{m[1]} {m[2] or ''}".strip())
             for p in pages for m in begin.finditer(p.read_text(encoding="utf-8"))}
    assert found == have, sorted(found ^ have)


def test_the_tables_that_list_a_family_of_figures_list_all_of_it() -> None:
    """The effect scenarios, the model variants, the current runs and the NIS channels of
    the registry each have their row (a template does not grow with the registry)."""
    _, effects = _docs_block("aie.effects")
    assert {f"aie.{sc.replace('-', '_')}.speed_rmse.aie"
            for sc in runs.AIE_EFFECT_SCENARIOS} <= effects.names()
    _, sens = _docs_block("aie.sensitivity")
    assert {f"aie.{sc}.model_{v}.speed_rmse.aie" for v in runs.AIE_MODEL_VARIANTS
            for sc in ("jaiabot_turns", "twin_thruster_turns")} <= sens.names()
    _, cur = _docs_block("current.validation")
    for key, obs, model, _ in F.CURRENT_TABLE:
        tok = F.current_token(key, obs, model)
        (row,) = [line for line in cur.body() if f"{{current.{tok}.peak}}" in line]
        # the label states the run's duration (runs.CURRENT_RUNS)
        assert f", {runs.CURRENT_RUNS[key][3]:.0f} s, " in row.split(" | ")[0], row
    _, nis = _docs_block("eseso.nis")
    assert {f"eseso.nis.{ch}" for ch in F.NIS_TABLE_CHANNELS} <= nis.names()


def test_a_stale_docs_table_is_caught_and_rewritten(committed, tmp_path) -> None:
    """Negative control: a figure moved in the file changes its table; ``update_docs``
    rewrites exactly the stale block, keeps the text around it, and a page without the
    markers is a UsageError."""
    template, block = _docs_block("aie.effects")
    doc = copy.deepcopy(committed)
    rec = doc["figures"]["aie.effect_waves.speed_rmse.aie"]
    rec["values"] = {k: v + 0.01 for k, v in rec["values"].items()}
    assert block.render(doc["figures"]) != block.render(committed["figures"])
    _copy_pages(tmp_path)
    assert R.update_docs(tmp_path, "figures", committed["figures"]) == []
    before = (tmp_path / template.name).read_text(encoding="utf-8")
    assert R.update_docs(tmp_path, "figures", doc["figures"]) == ["figures aie.effects"]
    after = (tmp_path / template.name).read_text(encoding="utf-8")
    assert after.replace(block.render(doc["figures"]),
                         block.render(committed["figures"])) == before
    (tmp_path / template.name).write_text("no markers here\n", encoding="utf-8")
    with pytest.raises(UsageError):
        R.update_docs(tmp_path, "figures", committed["figures"])
    del doc["figures"]["aie.effect_waves.speed_rmse.aie"]
    with pytest.raises(UsageError):
        block.render(doc["figures"])


FIGS = {"a": {"values": {"1": 0.05, "2": 0.09}, "digits": 3},
        "b": {"values": {"1": 0.06, "2": 0.06}, "digits": 3},
        "r": {"values": {"1": 0.07, "2": 0.08}, "digits": 3},
        "n": {"values": {"1": None}, "digits": 3},
        "one": {"values": {"3": 1.23456}, "digits": 2},
        "p.aie": {"values": {"1": 0.05, "2": 0.09}, "digits": 3},
        "p.kf": {"values": {"1": 0.06, "2": 0.06}, "digits": 3},
        "count": {"values": {"1": 100.0, "2": 300.0}, "digits": 0}}


def test_the_placeholder_language() -> None:
    """Each placeholder of validation/render.py's docstring, as the tables print it."""
    assert R.fill("{a@1} {a} {a@2:1} {one} {n} {one:2g} {a:1}", FIGS) == (
        "0.050 0.050-0.090 0.1 1.23 n/a 1.2 0.1")
    assert R.fill("{seeds(a)} / {seeds(one)}", FIGS) == "1-2 / 3"
    assert R.fill("{below_raw(p.aie, p.kf, r)}", FIGS) == "KF only"  # above r on seed 2
    assert R.fill("{below_raw(b, b, r)}", FIGS) == "both"
    assert R.fill("{below_raw(r, n, b)}", FIGS) == "**neither**"
    assert R.fill("{ratio(b, a)} {ratio(b, a):1}", FIGS) == "0.67-1.20 0.7-1.2"
    # the band of the mean of 100 (seed 1) or 400 (both seeds) chi-square(2) values;
    # scipy.stats.chi2.ppf([0.025, 0.975], 2 n) / n gives 1.627 / 2.411 and 1.809 / 2.201
    assert R.fill("{chi2_band(count@1, 2)}", FIGS) == "[1.627, 2.411]"
    assert R.fill("{chi2_band(count, 2)}", FIGS) == "[1.809, 2.201]"
    assert R.names("{a@1} {ratio(b, one)} {chi2_band(count@1, 2)}") == {"a", "b", "one",
                                                                          "count"}


@pytest.mark.parametrize("text", ["{a@7}", "{nope}", "{sum(a, b)}", "{ratio(a)}",
                                  "{seeds(a):2}", "{A}", "{a:x}", "a } b", "{chi2_band(a, b)}"])
def test_a_wrong_placeholder_is_a_usage_error(text: str) -> None:
    """Negative control: a seed the figure lacks, an unknown figure or function, a wrong
    argument count or kind, a format where no number is printed, a brace that is not a
    placeholder."""
    with pytest.raises(UsageError):
        R.fill(text, FIGS)


def test_a_template_holds_tables_of_figures_only() -> None:
    """Negative control: text outside a block, a row of other than the header's cells, an
    unknown family, a block without its end, and a row without a figure (unless it is a
    quoted paper row) are refused."""
    head = "<!-- figures:begin k: x -->\n| a | b |\n|---|---|\n"
    ok = head + "| x | {a} |\n| paper | 0.1 | <!-- quoted -->\n<!-- figures:end k -->\n"
    (block,) = R.parse(ok)
    assert block.render(FIGS).splitlines()[3:5] == ["| x | 0.050-0.090 |", "| paper | 0.1 |"]
    for bad in ("prose\n" + ok, head + "| x | {a} | 3 |\n<!-- figures:end k -->",
                ok.replace("figures:", "other:"), head + "| x | {a} |\n",
                head + "| x | 0.1 |\n<!-- figures:end k -->"):
        with pytest.raises(UsageError):
            R.parse(bad)


def test_compare_applies_the_tolerance(committed) -> None:
    """Negative control: a value just outside the tolerance fails, just inside passes."""
    fig = REGISTRY["aie.jaiabot_turns.speed_rmse.aie"]
    ref = committed["figures"][fig.name]["values"]["1"]
    allowed = fig.tolerance.allowed(ref)
    assert F.compare(fig, "1", ref + 0.99 * allowed, committed)[0]
    assert not F.compare(fig, "1", ref + 1.01 * allowed, committed)[0]
    assert not F.compare(fig, "9", ref, committed)[0]  # a seed the file lacks


def test_format_gives_a_range_over_seeds_only_when_they_differ() -> None:
    assert R.format_value({"values": {"1": 0.0521, "2": 0.0524}, "digits": 3}) == "0.052"
    assert R.format_value({"values": {"1": 0.0521, "2": 0.0536}, "digits": 3}) == "0.052-0.054"
    assert R.format_value({"values": {"-": 10.0}, "digits": 0}) == "10"
    assert R.format_value({"values": {"-": 2.3389e-05}, "digits": "2g"}) == "2.3e-05"


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
    """``python -m validation figures --only ... --check ... --write ...`` on one cheap figure
    (its run is the default suite's 30 s closed loop, shared): against the committed file it passes;
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
    """``python -m validation figures --docs DIR`` alone re-renders the pages from
    docs/figures.json (a stale block is rewritten, nothing is recomputed); with ``--check``
    and no ``--write`` it is a usage error."""
    import argparse

    template, block = DOCS_BLOCKS[0]
    _copy_pages(tmp_path)
    path = tmp_path / template.name
    stale = path.read_text(encoding="utf-8").replace(
        block.render(committed["figures"]), f"{block.begin()}\n| old |\n{block.end()}")
    path.write_text(stale, encoding="utf-8")
    args = argparse.Namespace(only=None, write=None, check=None, readme=None,
                              docs=str(tmp_path), results=None)
    assert F.main(args) == 0
    assert block.find(path.read_text(encoding="utf-8")) == block.render(committed["figures"])
    assert block.key in capsys.readouterr().out
    args.check = str(F.FIGURES_FILE)
    with pytest.raises(UsageError):
        F.main(args)
