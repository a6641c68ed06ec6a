"""Golden files for the text formats: reading each committed capture gives the committed
samples and counters, byte for byte.

The inputs and expected outputs live in ``tests/data/<format>/`` (NMEA, Water Linked
DVL JSON, PD6, a survey-boat Arduino+GPS capture, a BlueBoat-style CSV); the expected
outputs are regenerated only by ``tests/data/make_format_golden.py``, when a change of a
reader's output is intended.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parent / "data"
_spec = importlib.util.spec_from_file_location("make_format_golden",
                                               DATA / "make_format_golden.py")
make_format_golden = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_format_golden)


def _first_difference(got: str, want: str) -> str:
    """The first line where two texts differ, both versions."""
    a, b = got.splitlines(), want.splitlines()
    for i, (x, y) in enumerate(zip(a, b), start=1):
        if x != y:
            return f"line {i}:\n  got  {x}\n  want {y}"
    return f"{len(a)} lines instead of {len(b)}"


@pytest.mark.parametrize("name", sorted(make_format_golden.CASES))
def test_reading_a_capture_gives_the_committed_samples_and_counts(name):
    capture = DATA / name
    samples, counts = make_format_golden.render(capture, make_format_golden.CASES[name])
    samples_path, counts_path = make_format_golden.expected_paths(capture)
    want_samples, want_counts = samples_path.read_text(), counts_path.read_text()
    assert counts == want_counts, f"{counts_path.name}: {_first_difference(counts, want_counts)}"
    assert samples == want_samples, (
        f"{samples_path.name}: {_first_difference(samples, want_samples)}")


def test_every_capture_has_valid_records_and_counted_damage():
    """The inputs are not vacuous: each yields samples and rejects something, so a reader
    that silently drops or accepts everything fails the comparison."""
    for name in make_format_golden.CASES:
        _, counts_path = make_format_golden.expected_paths(DATA / name)
        counts = counts_path.read_text()
        assert '"samples": 0' not in counts and '"rejected": {}' not in counts, name
