"""``gps_latency``: GNSS position and velocity arrive ``seconds`` late.

The measured velocity over ground is the true one ``tau`` seconds ago, while the compass
and gyro are prompt. In a turn that rotates the measured velocity back by ``r tau``
against the heading (``-tau U r`` across it, which alone looks like the hull's sway in
turns or like sideslip); during speed changes the measured speed answers the command
``tau`` late, which neither does. Because the linearized form is collinear with the hull's
own sway at steady speed, the latency is found as what it is, a delay: the GNSS velocity
is advanced by each candidate ``tau`` and the one that best aligns it with the heading
wins (:meth:`GpsLatency.search`); the data are then re-aligned (:meth:`transform`) and
the rest of the model fitted on them.
"""

from __future__ import annotations

import math

import numpy as np

from onboard.closure.dataset import Dataset, remeasured, yaw_accel
from onboard.closure.effects.base import Effect


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

    def search(self, ds: Dataset, max_s: float = 2.0) -> tuple[float, float] | None:
        """(tau, one-sigma) minimising the lateral velocity left after the hull's sway and
        its course lag (the base model's ``x_p r + x_pd r'``), a constant crab and a
        current; None when the data cannot say."""
        taus = np.arange(0.0, max_s + 1e-9, max(ds.dt, 0.05))
        cost = []
        for tau in taus:
            d = self.transform(ds, float(tau))
            if len(d) < 100:
                cost.append(np.inf)
                continue
            X = np.column_stack([d.r, yaw_accel(d), d.along, -np.sin(d.psi), np.cos(d.psi)])
            coef, *_ = np.linalg.lstsq(X, d.lateral, rcond=None)
            cost.append(float(np.mean((d.lateral - X @ coef) ** 2)))
        cost = np.asarray(cost)
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
