"""The current pipeline with the glider model on the Kolumbo Slocum log, against the DVL
water-profiling current (docs/current.md, "Glider model on the Kolumbo log").

``onboard replay glider_data.csv --config config/slocum-glider-kolumbo.toml``: published
Slocum flight coefficients (nothing fitted); the velocity one-sigma and the current's random
walk chosen on the first 20 minutes, which the figures leave out. "Estimating zero" is
the reference's own rms: 0.265 m/s north, 0.059 east.
"""

from __future__ import annotations

import pytest

import validation.reports.current_validation as cv

pytestmark = pytest.mark.data

LOG = ("slocum_glider_kolumbo_dvl", "glider_data.csv")


@pytest.fixture(scope="module")
def figures(shared_data, tmp_path_factory):
    path = shared_data.joinpath(*LOG)
    if not path.exists():
        pytest.skip(f"{path} not present (the Kolumbo glider log, shared/data; see "
                    "tests/conftest.py shared_data)")
    r = cv.run_glider_model(path, tmp_path_factory.mktemp("kolumbo"))
    return cv.glider_figures(r)


def test_north_beats_estimating_zero_with_covering_sigma(figures):
    n = figures["north"]
    # measured: rms 0.215 m/s against zero's 0.293 on the same ticks (0.265 on all; the
    # torpedo regression: 0.68); 2-sigma coverage 0.92, 1-sigma 0.62. Published on 38.8 %
    # of the ticks (99.8 % before issue 32): north's RMS over 600 s is within its own
    # one-sigma (0.19) on the others, and it is withheld there as `current_unresolved`
    # although it beat zero there too (0.212 against 0.245): the criterion cannot tell a
    # lagging estimate of a large current from a noise-following one of a small current
    # (docs/integrity.md, "The current not resolved")
    assert n["zero_rms"] == pytest.approx(0.265, abs=0.001)
    assert n["rms"] < 0.24
    assert n["rms"] < n["zero_rms_published"]
    assert 0.3 < n["published"] < 0.5
    assert n["cover2"] > 0.85
    assert 0.5 < n["cover1"] < 0.8


def test_east_worse_than_zero_is_withheld(figures):
    """Issue 32: the east current, worse than estimating zero (0.097 m/s against 0.059
    before), is flagged and withheld after the first 600 s window (`current_unresolved`:
    its RMS over the window 0.05-0.17 m/s against its one-sigma of 0.18-0.19)."""
    e = figures["east"]
    # measured: published on none of the ticks after the first 20 minutes (on 37.7 % of
    # the first 20, before the first window is judged)
    assert e["zero_rms"] == pytest.approx(0.059, abs=0.001)
    assert e["published"] == 0.0
