"""``onboard replay --pipelines``: only the pipelines asked for run, each one's estimates
those of a replay with every pipeline (the pipelines share no state)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from onboard.cli import main as cli_main

pytestmark = pytest.mark.integration

LOG = Path(__file__).parent / "data" / "replay" / "jaiabot-turns.tlog"


def _replay(out: Path, *extra: str) -> tuple[list[str], list[list[str]], dict]:
    assert cli_main(["replay", str(LOG), "--out", str(out), "--no-plot", *extra]) == 0
    with open(out / "estimates.csv", newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:], json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="module")
def full(tmp_path_factory):
    return _replay(tmp_path_factory.mktemp("full"))


@pytest.mark.parametrize("names", ["current", "nav,kf", "aie"])
def test_the_pipelines_asked_for_give_the_estimates_of_a_full_replay(full, tmp_path, names):
    header, rows, summary = _replay(tmp_path, "--pipelines", names)
    wanted = names.split(",")
    assert summary["pipelines"] == [p for p in full[2]["pipelines"] if p in wanted]
    assert {c.split(".")[0] for c in header[2:]} == set(wanted)
    assert header[:2] == full[0][:2]
    index = [full[0].index(c) for c in header]
    assert len(rows) == len(full[1])
    for row, whole in zip(rows, full[1]):
        assert row == [whole[i] for i in index]
    # the warnings of those pipelines are the full replay's
    mine = [w for w in summary["warnings"] if w.get("pipeline") in wanted]
    assert mine == [w for w in full[2]["warnings"] if w.get("pipeline") in wanted]


@pytest.mark.parametrize("names, says", [("foo", "foo is not a pipeline"),
                                         ("eseso", "none of them runs on")])
def test_a_pipeline_that_is_not_one_or_does_not_run_is_a_usage_error(tmp_path, capsys,
                                                                     names, says):
    assert cli_main(["replay", str(LOG), "--out", str(tmp_path), "--no-plot",
                     "--pipelines", names]) == 2
    assert says in capsys.readouterr().err
