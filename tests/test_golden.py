"""Golden files: ``onboard replay`` of committed logs gives the committed estimates.csv.

The inputs and the expected outputs live in ``tests/data/replay`` (regenerated only by
``tests/data/make_golden.py``, when a change of the estimates is intended). A refactoring
must leave every estimate unchanged: the same header, rows and empty cells, and every
number the same to :data:`RTOL`. That tolerance is the last printed digit and no more:
estimates.csv prints 10 significant digits, and OpenBLAS chooses its matrix kernels by
CPU, so the last bit of a product in the current and ESESO filters, and with it sometimes
the last printed digit, differs between machines (the committed files match byte for byte
where OpenBLAS runs its Haswell kernels; on an AMD EPYC with AVX-512, up to 7.4e-10
relative in bluerov2-circle and gavia-tidal). A value far below its column's scale is the
remainder of a cancellation (a vertical velocity of 5e-6 m/s in a column of tenths): it is
compared at :data:`SMALL` of the column's largest value, where its rounding is (the
ESESO's compiled kernels, ``onboard[fast]``, move such a value's 9th digit, 1e-14 m/s).
On one machine a refactoring is compared byte for byte, before against after.
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


RTOL = 2e-9
"""Largest relative difference of one number from the committed one (the last of 10
printed significant digits; see the module docstring)."""
SMALL = 1e-3
"""A value below this share of its column's largest is compared at that share (module
docstring)."""


def _largest_difference(got: str, want: str) -> tuple[float, str]:
    """The largest relative difference between two estimates.csv texts and where it is
    (infinite when the header, the row count or an empty cell differs)."""
    rows_got = list(csv.reader(io.StringIO(got)))
    rows_want = list(csv.reader(io.StringIO(want)))
    if rows_got[:1] != rows_want[:1]:
        return math.inf, f"header differs: {rows_got[:1]} != {rows_want[:1]}"
    if len(rows_got) != len(rows_want):
        return math.inf, f"{len(rows_got) - 1} rows instead of {len(rows_want) - 1}"
    scale = [SMALL * max((abs(float(v)) for v in col if v), default=0.0)
             for col in zip(*rows_want[1:])]
    worst = (0.0, "", 0)
    for i, (a, b) in enumerate(zip(rows_got[1:], rows_want[1:]), start=1):
        for name, x, y, small in zip(rows_want[0], a, b, scale):
            if x == y:
                continue
            if not x or not y:
                return math.inf, f"row {i} column {name}: {x!r} != {y!r}"
            gap = abs(float(x) - float(y)) / max(abs(float(y)), small, 1e-12)
            if gap > worst[0] or math.isnan(gap):
                worst = (gap, name, i)
    return worst[0], (f"largest relative difference {worst[0]:.3g} in column {worst[1]} "
                      f"at row {worst[2]}")


@pytest.mark.parametrize("case", sorted(make_golden.CASES))
def test_replay_of_a_committed_log_gives_the_committed_estimates(case: str, tmp_path: Path,
                                                                 capsys) -> None:
    log = DATA / "replay" / f"{case}.tlog"
    expected = (DATA / "replay" / f"{case}.estimates.csv").read_text()
    assert cli_main(["replay", str(log), "--out", str(tmp_path), "--no-plot"]) == 0
    got = (tmp_path / "estimates.csv").read_text()
    if got != expected:
        gap, where = _largest_difference(got, expected)
        assert gap <= RTOL, where


def test_the_comparison_sees_a_change_beyond_the_last_digit() -> None:
    """A negative control: a changed digit before the last, a missing cell and a missing
    row are each caught; a change of the last digit alone is within the tolerance."""
    want = "t,a.x\n0.000000,1.234567891\n0.100000,2.5\n"
    assert _largest_difference(want.replace("1.234567891", "1.234567892"), want)[0] <= RTOL
    assert _largest_difference(want.replace("1.234567891", "1.234567991"), want)[0] > RTOL
    assert _largest_difference(want.replace("1.234567891", ""), want)[0] == math.inf
    assert _largest_difference(want.rsplit("0.1", 1)[0], want)[0] == math.inf
    # a value a millionth of its column's largest: its 9th digit is within, its 3rd is not
    tiny = "t,a.x\n0.000000,5.236973817e-06\n0.100000,0.25\n"
    assert _largest_difference(tiny.replace("817e", "806e"), tiny)[0] <= RTOL
    assert _largest_difference(tiny.replace("5.23697", "5.33697"), tiny)[0] > RTOL
