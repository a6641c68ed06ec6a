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
    # measured: rms 0.213 m/s against zero's 0.265 (the torpedo regression: 0.68),
    # published on 99.8 % of the ticks, 2-sigma coverage 0.92, 1-sigma 0.64; mean error
    # +0.080 (the model's through-water speed 0.04 m/s below the DVL's, and the filter's
    # lag behind the current's change with depth)
    assert n["zero_rms"] == pytest.approx(0.265, abs=0.001)
    assert n["rms"] < 0.24
    assert n["published"] > 0.95
    assert n["cover2"] > 0.85
    assert 0.5 < n["cover1"] < 0.8


def test_east_is_covered_but_no_better_than_zero(figures):
    e = figures["east"]
    # measured: rms 0.097 m/s against zero's 0.059 (an honest miss: the east current is
    # +-0.06 m/s, under the 0.18 m/s one-sigma the 8 s navigation allows); 2-sigma
    # coverage 1.00, 1-sigma 0.93 (too timid); mean error +0.035 (a 2.5 deg crab of the
    # course through water against the logged heading the model has no term for)
    assert e["zero_rms"] == pytest.approx(0.059, abs=0.001)
    assert e["rms"] < 0.12
    assert e["published"] > 0.95
    assert e["cover2"] > 0.95
