"""Receiver accuracy as noise: a GNSS fix's own speed accuracy, else its horizontal
accuracy, sets the velocity one-sigma the current pipeline fuses it with
(``gnss_nominal_accuracy_m``, docs/current.md, "Receiver accuracy as noise")."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from onboard.core.messages import GnssFix
from tests.helpers.current_plants import current_errors, current_pipeline, simulate_boat

BAD = (120.0, 200.0)
"""s: the window in which the receiver is degraded (multipath, few satellites)."""


def degraded_boat(report_accuracy: bool, seed: int = 0, duration: float = 240.0,
                  speed_accuracy: bool = False):
    """simulate_boat (GNSS velocity noise 0.05 m/s per axis, 2.5 Hz) whose fixes carry
    ``h_acc_m = 1.5`` m, except in :data:`BAD`, where their velocity has 0.5 m/s of extra
    noise per axis and the receiver says so (``h_acc_m = 15`` m; with ``speed_accuracy``
    also ``speed_acc_mps`` 0.05 outside, 0.5 inside). Without ``report_accuracy`` no fix
    carries an accuracy (the configured noise throughout)."""
    rng = np.random.default_rng(100 + seed)
    for t, samples, c in simulate_boat(duration, seed=seed):
        out = []
        for s in samples:
            if isinstance(s, GnssFix):
                bad = BAD[0] <= t < BAD[1]
                vn, ve = s.sog_mps * math.cos(s.cog_rad), s.sog_mps * math.sin(s.cog_rad)
                if bad:
                    vn, ve = vn + rng.normal(0, 0.5), ve + rng.normal(0, 0.5)
                s = msgspec.structs.replace(
                    s, sog_mps=math.hypot(vn, ve), cog_rad=math.atan2(ve, vn),
                    h_acc_m=(15.0 if bad else 1.5) if report_accuracy else None,
                    speed_acc_mps=(0.5 if bad else 0.05)
                    if report_accuracy and speed_accuracy else None)
            out.append(s)
        yield t, out, c


def _run(report_accuracy: bool, seed: int = 0, speed_accuracy: bool = False):
    pipe = current_pipeline("rudder-boat", gnss_velocity_std_mps=0.05,
                            gnss_nominal_accuracy_m=1.5)
    errs = []
    nis = []  # of every velocity update in the window, gated ones included
    for t, samples, c in degraded_boat(report_accuracy, seed, speed_accuracy=speed_accuracy):
        out = pipe.step(t, samples)
        if BAD[0] <= t and "north" in out and "east" in out:
            errs.append([out["north"] - c[0], out["east"] - c[1]])
        nis += [r.nis for r in pipe.innovations()
                if r.channel == "velocity" and BAD[0] <= r.t < BAD[1]]
    return pipe, np.sqrt(np.mean(np.array(errs) ** 2, axis=0)), float(np.mean(nis))


@pytest.mark.parametrize("speed_accuracy", [False, True], ids=["h_acc", "speed_acc"])
def test_fixes_reporting_a_poor_accuracy_are_down_weighted(speed_accuracy):
    """80 s of fixes ten times noisier than configured, reported as such by the receiver:
    with the accuracy as noise the current error from the degradation on is smaller than
    with the fixed configured noise, and the velocity NIS in the window stays in its band
    (about 2 for two components) instead of blowing up; the same whether the receiver
    reports its speed accuracy or only its position accuracy."""
    aware, rms_aware, nis_aware = _run(True, speed_accuracy=speed_accuracy)
    fixed, rms_fixed, nis_fixed = _run(False)
    # measured (seed 0, rms N/E from 120 s to 240 s): accuracy as noise 0.022 / 0.017 m/s,
    # fixed noise 0.058 / 0.045 (176 fixes gated out, q_scale raised to 1.47); mean NIS of
    # the window's velocity updates (gated ones included) 1.9 vs 35
    assert np.all(rms_aware < 0.6 * rms_fixed)
    assert np.all(rms_aware < 0.04)
    assert 0.5 < nis_aware < 4.0
    assert nis_fixed > 6.0
    assert fixed.kf.counters.rejected_gate > 0 and aware.kf.counters.rejected_gate == 0
    assert aware.health().gnss_velocity_std == 0.05  # back to nominal after the window


def test_accuracy_scaling_never_tightens_and_falls_back_to_the_configured_noise():
    pipe = current_pipeline("rudder-boat", gnss_velocity_std_mps=0.1,
                            gnss_nominal_accuracy_m=1.5)
    meas: list = []
    for acc, expect in ((0.02, 0.1), (3.0, 0.2), (None, 0.1), (math.nan, 0.1), (-1.0, 0.1)):
        pipe.samples._on_gnss(GnssFix(t=0.0, lat_deg=0.0, lon_deg=0.0, sog_mps=1.0, cog_rad=0.0,
                              h_acc_m=acc), meas)
        assert meas[-1][3] == expect
    for sacc, expect in ((0.02, 0.1), (0.4, 0.4), (math.nan, 0.2)):  # NaN: h_acc_m instead
        pipe.samples._on_gnss(GnssFix(t=0.0, lat_deg=0.0, lon_deg=0.0, sog_mps=1.0, cog_rad=0.0,
                              h_acc_m=3.0, speed_acc_mps=sacc), meas)
        assert meas[-1][3] == pytest.approx(expect)
    off = current_pipeline("rudder-boat", gnss_velocity_std_mps=0.1, gnss_nominal_accuracy_m=0.0)
    off.samples._on_gnss(GnssFix(t=0.0, lat_deg=0.0, lon_deg=0.0, sog_mps=1.0, cog_rad=0.0,
                         h_acc_m=30.0), meas)
    assert meas[-1][3] == 0.1
