"""``gps_latency``: GNSS position and velocity arrive ``seconds`` late.

The measured velocity over ground is the true one ``tau`` seconds ago, while the compass
and gyro are prompt. In a turn that rotates the measured velocity back by ``r tau``
against the heading (``-tau U r`` across it, which alone looks like the hull's sway in
turns or like sideslip); during speed changes the measured speed answers the command
``tau`` late, which neither does. Because the linearized form is collinear with the hull's
own sway at steady speed, the latency is found as what it is, a delay
(:meth:`GpsLatency.search`): with an accelerometer, the delay that aligns the GNSS
acceleration over ground with the IMU's, rotated by the compass (no hull model: a hull
that drifts out of its turns by ``-k U r``, a catamaran, cannot pose as a latency ``k``);
without one, the GNSS velocity advanced by each candidate ``tau`` and the one that best
aligns it with the heading. The data are then re-aligned (:meth:`transform`) and the rest
of the model fitted on them.
"""

from __future__ import annotations

import math

import numpy as np

from onboard.offline.closure.dataset import (
    Dataset,
    acceleration_delay_cost,
    lateral_base_columns,
    lateral_base_names,
    remeasured,
)
from onboard.offline.closure.effects.base import Effect


def advance_velocity(ds: Dataset, tau: float) -> Dataset:
    """``ds`` with the velocity over ground taken ``tau`` seconds later, within each
    segment (the last ``tau`` seconds of each segment, which have none, are dropped)."""
    k = int(round(tau / ds.dt))
    if k <= 0:
        return ds
    vn = np.full(len(ds), np.nan)
    ve = np.full(len(ds), np.nan)
    change = np.flatnonzero(np.r_[True, ds.run[1:] != ds.run[:-1], True])
    for a, b in zip(change[:-1], change[1:]):
        if b - a > k:
            vn[a:b - k] = ds.v_n[a + k:b]
            ve[a:b - k] = ds.v_e[a + k:b]
    return remeasured(ds, v_n=vn, v_e=ve, keep=np.isfinite(vn))


class GpsLatency(Effect):
    """The GNSS latency, found by a delay search and applied to the data (module docstring)."""

    name = "gps_latency"
    params = ("seconds",)
    transforms_data = True

    def columns(self, ds, ctx):
        return {}

    def physical(self, theta):
        return bool(theta[0] > 0.0)

    def transform(self, ds: Dataset, tau: float) -> Dataset:
        """The data with the GNSS position and velocity advanced by ``tau`` seconds."""
        return advance_velocity(ds, tau)

    def lateral_cost(self, ds: Dataset, taus: np.ndarray) -> np.ndarray:
        """For each delay in ``taus`` (s), the mean square (m^2/s^2) of the lateral
        velocity advanced by it, after the hull's sway per yaw rate and its course lag
        (``x_p r + x_pd r'``), a constant crab and a current are fitted out. The base
        model's speed drift ``k_ur U r`` is left out: to first order it is what a delay
        does in turns (``-tau U r``), so with it no delay could be told from the lateral
        channel alone."""
        cost = []
        for tau in taus:
            d = self.transform(ds, float(tau))
            if len(d) < 100:
                cost.append(np.inf)
                continue
            turn = [i for i, n in enumerate(lateral_base_names(d)) if n in ("x_p", "x_pd")]
            X = np.column_stack([lateral_base_columns(d)[:, turn], d.along, -np.sin(d.psi),
                                 np.cos(d.psi)])
            coef, *_ = np.linalg.lstsq(X, d.lateral, rcond=None)
            cost.append(float(np.mean((d.lateral - X @ coef) ** 2)))
        return np.asarray(cost)

    def search(self, ds: Dataset, max_s: float = 2.0) -> tuple[float, float] | None:
        """(tau, one-sigma) of the GNSS delay; None when the data cannot say.

        With an accelerometer, the delay that best aligns the GNSS acceleration over
        ground with the IMU's, rotated by the compass
        (:func:`onboard.offline.closure.dataset.acceleration_delay_cost`): no hull model enters,
        so a hull's drift in turns cannot pose as a delay. Without one, the delay that
        minimises the lateral velocity left after the hull's sway in turns (the base
        model's turn terms, :meth:`lateral_cost`), a constant crab and a current: there a
        hull whose drift out of a turn grows with speed times yaw rate (speed-independent
        sway damping, a catamaran) shows a delay about its ``k_ur``."""
        taus = np.arange(0.0, max_s + 1e-9, max(ds.dt, 0.05))
        cost = acceleration_delay_cost(ds, taus)
        if cost is None:
            cost = self.lateral_cost(ds, taus)
        i = int(np.argmin(cost))
        if not np.isfinite(cost[i]) or i == 0:
            return None
        lo, hi = max(0, i - 2), min(len(taus), i + 3)
        tau = float(taus[i])
        c2 = 0.0
        if hi - lo >= 3 and np.isfinite(cost[lo:hi]).all():
            c2, c1, _ = np.polyfit(taus[lo:hi], cost[lo:hi], 2)
            if c2 > 0:  # the parabola's vertex, between grid points
                tau = float(np.clip(-c1 / (2 * c2), taus[lo], taus[hi - 1]))
        n_eff = max(8.0, float(np.ptp(ds.t)) / 2.0)
        std = math.sqrt(cost[i] / (n_eff * c2)) if c2 > 0 else float("inf")
        return tau, std


EFFECT = GpsLatency()
