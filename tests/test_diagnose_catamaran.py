"""``onboard diagnose`` on the Otter-class catamaran: its drift in turns is not a latency.

The catamaran (sitl/plants/catamaran.py) has a sway damping that does not grow with
speed, so it drifts out of its turns by about ``-0.5 s x U r``, which is in steady turns
exactly what a GNSS latency of 0.5 s does to the lateral velocity (issue 16: a latency of
~0.5 s named on every log of such a boat, a true 0.6 s one sized 1.1 s). The delay search
that explains the lateral velocity with the hull's sway per yaw rate and its course lag
finds that false latency; aligning the GNSS acceleration with the accelerometer's,
rotated by the compass, needs no hull model and does not.

The default suite flies one short clean run (240 s, seed 1) and derives from it both
cases: the run as flown, and the same run with its GNSS velocity made 0.6 s late. The
ten-seed campaigns of the real scenarios (`cat-clean`, `cat-gps-latency`) are slow
(``pytest -m slow``, ~40 s of CPU per log). Bounds carry the measured figures.
"""

from __future__ import annotations

import dataclasses
import functools
import tempfile
from pathlib import Path

import numpy as np
import pytest

from onboard.offline.closure import dataset as D
from onboard.offline.closure.effects import ALL
from onboard.offline.closure.select import split
from onboard.core import config
from validation import diagnose_campaign as campaign

CFG = Path(__file__).resolve().parent.parent / "config" / "sitl-catamaran.toml"
LATENCY = ALL["gps_latency"]


@functools.cache
def short_clean_run() -> D.Dataset:
    """The fit part of `cat-clean`, seed 1, flown for 240 s (one mission loop of 215 s),
    read as `onboard diagnose` reads it."""
    from onboard.sitl.runner import run_to_tlog

    with tempfile.TemporaryDirectory(prefix="onboard-cat-") as tmp:
        log = Path(tmp) / "log.tlog"
        run_to_tlog("cat-clean", log, Path(tmp) / "truth.jsonl", duration=240.0, seed=1)
        ds = D.from_log(str(log), config.load(CFG))
    return split(ds).fit


def late(ds: D.Dataset, seconds: float) -> D.Dataset:
    """``ds`` with its GNSS velocity ``seconds`` late (whole ticks, within each segment;
    the first ticks of each segment, which have none, are dropped)."""
    k = round(seconds / ds.dt)
    vn, ve = np.full(len(ds), np.nan), np.full(len(ds), np.nan)
    starts = np.flatnonzero(D.segment_starts(ds) == np.arange(len(ds)))
    for a, b in zip(starts, np.r_[starts[1:], len(ds)]):
        vn[a + k:b], ve[a + k:b] = ds.v_n[a:b - k], ds.v_e[a:b - k]
    return D.remeasured(ds, v_n=vn, v_e=ve, keep=np.isfinite(vn))


def without_accelerometer(ds: D.Dataset) -> D.Dataset:
    """``ds`` as a log without accelerometer data (the lateral delay search)."""
    return dataclasses.replace(ds, acc_x=None, acc_y=None)


def test_the_catamaran_s_drift_is_a_latency_only_to_the_lateral_search_without_base_terms():
    ds = short_clean_run()
    off = D.with_base_terms(ds, D.NO_BASE_TERMS)
    # Base terms off (no shaft lag, no course lag), no accelerometer: the lateral delay
    # search takes the drift for a latency (measured 0.263 s +- 0.14; 0.276 s on the fit
    # part of the full 600 s log). With the base model's terms on, the course lag x_pd r'
    # takes most of it (measured 0.039 s).
    tau_off, _ = LATENCY.search(without_accelerometer(off))
    assert tau_off > 0.15
    on = LATENCY.search(without_accelerometer(ds))
    assert on is None or on[0] < 0.1
    # Aligning the accelerations needs no hull model: no delay to speak of (measured
    # 0.055 s +- 0.056 on this short run; None, the best delay 0, on the full log)
    found = LATENCY.search(off)
    assert found is None or found[0] < 0.1
    # The same run with the GNSS 0.6 s late: the alignment measures it (0.631 +- 0.061 s
    # with the terms off or on); the lateral search adds the drift on with the terms
    # off (0.932 s) and sizes it 0.556 s with them on.
    lat = late(ds, 0.6)
    tau_imu, _ = LATENCY.search(D.with_base_terms(lat, D.NO_BASE_TERMS))
    assert tau_imu == pytest.approx(0.6, abs=0.1)
    lat_off = without_accelerometer(D.with_base_terms(lat, D.NO_BASE_TERMS))
    tau_lat_off, _ = LATENCY.search(lat_off)
    assert tau_lat_off > 0.75


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("cat-campaign")


@pytest.mark.slow
def test_cat_clean_false_alarm_rate_over_ten_seeds(work):
    outs = [campaign.diagnose_seed("cat-clean", s, CFG, work) for s in range(1, 11)]
    alarms = [o for o in outs if campaign.is_false_alarm(o)]
    # measured 2026-11-25: 0/10 (nothing named, nothing unexplained); limit 10 %
    assert len(alarms) <= 1


@pytest.mark.slow
def test_cat_gps_latency_over_ten_seeds(work):
    outs = [campaign.diagnose_seed("cat-gps-latency", s, CFG, work) for s in range(1, 11)]
    found = [o.params["gps_latency"]["seconds"] for o in outs if "gps_latency" in o.named]
    # measured 2026-11-25: 10/10, 0.576-0.606 s (mean 0.593); seeds 5 and 6 also report
    # the heading channel unexplained, seed 6 a gyro_bias of 0.0007 rad/s (extras, not
    # counted here: docs/diagnose.md)
    assert len(found) >= 9
    assert all(abs(tau - 0.6) <= 0.15 for tau in found)


@pytest.mark.slow
def test_cat_seed_1_with_the_base_terms_off(work):
    # The base model's shaft lag and course lag switched off: the accelerometer still
    # finds no latency on the clean log and the true one on the latency log (measured:
    # nothing named; 0.586 s, as with the terms on)
    off = D.NO_BASE_TERMS
    clean = campaign.diagnose_seed("cat-clean", 1, CFG, work, off)
    assert not campaign.is_false_alarm(clean)
    late_log = campaign.diagnose_seed("cat-gps-latency", 1, CFG, work, off)
    assert late_log.params["gps_latency"]["seconds"] == pytest.approx(0.6, abs=0.15)
