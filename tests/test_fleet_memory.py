"""The fleet field's account of a current estimate's memory (docs/algorithms.md §8.9): a
vehicle's estimate is the water it crossed over its estimator's memory, so a window's
place is as uncertain as the distance its vehicle covers in that memory. A synthetic
fleet whose estimates remember 20 s of their track (an exponential filter of the truth
along it) is covered with the term and overconfident without it (the negative control)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.fleet.field import (
    ESTIMATE_MEMORY_S, PRIOR, THIN_S, CurrentField, Hyper, Observation, Plane,
    memory_place, one_blas_thread)
from tests.helpers.fleet_scenarios import UTC0, fleet

COVERAGE = (0.90, 0.99)


def covered(f, vehicles: list[int], memory_s: float, calibrate: bool = True
            ) -> tuple[np.ndarray, float]:
    """RMS (north, east) and the share within 1.96 sigma along each of ``vehicles``'
    tracks (every 30 s), each left out of a field whose estimates' memory is
    ``memory_s`` (its sigma calibrated on the fleet's data or not)."""
    err, z = [], []
    for v in vehicles:
        field = CurrentField(hyper=Hyper(), prior=PRIOR, memory_s=memory_s,
                             calibrate=calibrate)
        for o in f.observations(skip=v):
            field.add(o)
        field.fit()
        sel = np.flatnonzero((f.vehicle == v) & (np.mod(f.t, 30.0) < 1e-6))
        lat, lon = f.plane.to_latlon(f.north_m[sel], f.east_m[sel])
        with one_blas_thread():
            for j, i in enumerate(sel):
                p = field.predict(float(lat[j]), float(lon[j]), UTC0 + float(f.t[i]))
                e = np.array([p.north, p.east]) - f.truth[i]
                err.append(e)
                z.append(np.abs(e) / np.array([p.std_north, p.std_east]))
    return np.sqrt((np.array(err) ** 2).mean(axis=0)), float((np.array(z) < 1.96).mean())


def test_estimates_that_remember_their_track_are_covered_with_the_memory_term():
    """Six vehicles for 20 minutes in a 600-m square across the meandering front, their
    estimates the truth along their track through a 20-s exponential filter plus an AR(1)
    of 5 mm/s; three left out in turn. Measured: with the memory term coverage 0.96 (RMS
    0.004/0.012 m/s); without it (the negative control) 0.88, the windows taken as
    observations of the water where they are."""
    f = fleet("front", seed=1, vehicles=6, duration_s=1200.0, rate_hz=1.0,
              half_width_m=300.0, sigma=0.005, white=0.005 / 3, memory_s=ESTIMATE_MEMORY_S)
    rms, cov = covered(f, [0, 1, 2], ESTIMATE_MEMORY_S)
    assert np.all(rms <= 0.03), rms
    assert COVERAGE[0] <= cov <= COVERAGE[1], cov
    # without the calibration too, which covers 0.97 of these misses by itself
    _, cov_without = covered(f, [0, 1, 2], 0.0, calibrate=False)
    assert cov_without < COVERAGE[0], cov_without


def test_a_windows_place_sigma_is_its_speed_times_the_memory():
    """A vehicle at 1.5 m/s north-east on a straight line: its window's place sigma is
    ``1.5 m/s x memory`` per axis (in quadrature with its fix's), whatever the order its
    records arrive in; a vehicle holding station adds nothing."""
    def window(speed: float, order: list[int]) -> float:
        field = CurrentField(memory_s=ESTIMATE_MEMORY_S)
        heading = math.radians(45.0)
        t = np.arange(0.0, 29.95, 0.1)
        lat, lon = Plane(43.1, 5.9).to_latlon(speed * t * math.cos(heading),
                                              speed * t * math.sin(heading))
        start = math.ceil(UTC0 / THIN_S) * THIN_S   # one window
        for i in order:
            field.add(Observation("v", start + t[i], float(lat[i]), float(lon[i]), 0.1, 0.2,
                                  0.03, 0.03, position_std_m=3.0))
        return float(field.gather().place[0])

    order = list(range(300))
    assert window(1.5, order) == pytest.approx(
        math.hypot(3.0, float(memory_place(np.array(1.5)))), rel=2e-3)
    assert float(memory_place(np.array(1.5))) == pytest.approx(1.5 * ESTIMATE_MEMORY_S)
    rng = np.random.default_rng(3)
    assert window(1.5, list(rng.permutation(300))) == pytest.approx(window(1.5, order),
                                                                     rel=1e-5)
    assert window(0.0, order) == pytest.approx(3.0)
