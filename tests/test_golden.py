"""Golden files: ``onboard replay`` of committed logs gives the committed estimates.csv.

The inputs and the expected outputs live in ``tests/data/replay`` (regenerated only by
``tests/data/make_golden.py``, when a change of the estimates is intended). A refactoring
must leave every byte of every estimate unchanged.
"""

from __future__ import annotations

import csv
import importlib.util
import io
import math
from pathlib import Path

import pytest

from onboard.cli import main as cli_main

DATA = Path(__file__).resolve().parent / "data"
_spec = importlib.util.spec_from_file_location("make_golden", DATA / "make_golden.py")
make_golden = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_golden)


def _largest_difference(got: str, want: str) -> str:
    """Where two estimates.csv texts differ: the column and the largest numeric gap."""
    rows_got = list(csv.reader(io.StringIO(got)))
    rows_want = list(csv.reader(io.StringIO(want)))
    if rows_got[:1] != rows_want[:1]:
        return f"header differs: {rows_got[:1]} != {rows_want[:1]}"
    if len(rows_got) != len(rows_want):
        return f"{len(rows_got) - 1} rows instead of {len(rows_want) - 1}"
    worst = (0.0, "", 0)
    for i, (a, b) in enumerate(zip(rows_got[1:], rows_want[1:]), start=1):
        for name, x, y in zip(rows_want[0], a, b):
            if x == y:
                continue
            if not x or not y:
                return f"row {i} column {name}: {x!r} != {y!r}"
            gap = abs(float(x) - float(y)) / max(abs(float(y)), 1e-12)
            if gap > worst[0] or math.isnan(gap):
                worst = (gap, name, i)
    return f"largest relative difference {worst[0]:.3g} in column {worst[1]} at row {worst[2]}"


@pytest.mark.parametrize("case", sorted(make_golden.CASES))
def test_replay_of_a_committed_log_gives_the_committed_estimates(case: str, tmp_path: Path,
                                                                 capsys) -> None:
    log = DATA / "replay" / f"{case}.tlog"
    expected = (DATA / "replay" / f"{case}.estimates.csv").read_text()
    assert cli_main(["replay", str(log), "--out", str(tmp_path), "--no-plot"]) == 0
    got = (tmp_path / "estimates.csv").read_text()
    assert got == expected, _largest_difference(got, expected)
