"""The current pipeline on real data: Slocum glider, Kolumbo (DVL-measured current).

What the observers give there and why (docs/current.md, "Real data"): the log is at 8 s
steps, the glider is driven by buoyancy (pump volume, battery position), which the torpedo
regression model lacks, and the over-ground velocity comes from differenced, corrected
navigation, not DVL bottom track. The test pins down honest behaviour, not accuracy.
"""

from __future__ import annotations

import numpy as np
import pytest

import onboard.tools.reports.current_validation as cv

pytestmark = [pytest.mark.data, pytest.mark.slow]


def test_glider_log_runs_and_reports_its_ignorance(shared_data):
    path = shared_data / "slocum_glider_kolumbo_dvl" / "glider_data.csv"
    if not path.exists():
        pytest.skip(f"{path} not present")
    r = cv.run_glider(path)
    assert len(r["t"]) > 1000
    assert np.all(np.isfinite(r["est"])) and np.all(np.isfinite(r["std"]))
    m = r["t"] > 1200.0
    e = r["est"][m] - r["truth"][m]
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    cover = np.mean(np.abs(e) <= 2 * r["std"][m], axis=0)
    # measured: rms N/E 0.678 / 0.074 m/s against the DVL water-profile current (whose own
    # rms is 0.265 / 0.059: estimating zero would do better in north); 2-sigma coverage
    # 0.20 / 1.00; correlation 0.27 / 0.09. The north estimate carries a +0.5 m/s bias from
    # a surge model identified on a buoyancy-driven vehicle the regression cannot describe;
    # its sigma is NOT honest there (docs/current.md, "Real data"). Bounds pin the figures.
    assert rms[0] < 1.0
    assert rms[1] < 0.15
    assert cover[1] > 0.9
