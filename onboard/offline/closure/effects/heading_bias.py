"""``heading_bias``: a constant heading error (rad): a misaligned compass, an uncorrected
magnetic declination, a dual-antenna GNSS baseline not along the bow.

The vehicle moves along its true heading, so at every heading and speed the velocity over
ground makes the same angle ``-bias`` with the measured heading. The bias need not be
small (a GNSS compass can be off by tens of degrees), so it is not fitted as a linearized
regressor but measured as that angle (:meth:`HeadingBias.search`: the circular mean of the
crab angle while moving, the hull's sway in turns taken out) and taken out of the data
(:meth:`HeadingBias.transform`); the heading channel is unaffected, as a constant cancels
in heading changes.
"""

from __future__ import annotations

import math

import numpy as np

from onboard.offline.closure.dataset import Dataset, lateral_base_columns, remeasured
from onboard.offline.closure.effects.base import Effect


def rotate_heading(ds: Dataset, bias: float) -> Dataset:
    """``ds`` with ``bias`` (rad) removed from the measured heading."""
    return remeasured(ds, psi=ds.psi - bias)


class HeadingBias(Effect):
    """The constant heading error, measured as the crab angle and applied to the data
    (module docstring)."""

    name = "heading_bias"
    params = ("bias",)
    transforms_data = True

    def columns(self, ds, ctx):
        return {}

    def transform(self, ds: Dataset, bias: float) -> Dataset:
        """The data with the measured heading corrected by ``bias`` (rad)."""
        return rotate_heading(ds, bias)

    def search(self, ds: Dataset, min_speed: float = 0.3) -> tuple[float, float] | None:
        """(bias, one-sigma): minus the circular mean of the crab angle where the vehicle
        moves (> ``min_speed`` m/s), after the hull's sway in turns (the base model's lateral
        terms, :func:`onboard.offline.closure.dataset.lateral_base_columns`, fitted with the speed
        term by least squares) is taken out of the lateral velocity."""
        speed = np.hypot(ds.v_n, ds.v_e)
        m = (speed > min_speed) & np.isfinite(ds.lateral) & np.isfinite(ds.r)
        if m.sum() < 50:
            return None
        sway = lateral_base_columns(ds)[m]
        X = np.column_stack([sway, ds.along[m]])
        coef, *_ = np.linalg.lstsq(X, ds.lateral[m], rcond=None)
        crab = np.arctan2(ds.lateral[m] - sway @ coef[:-1], ds.along[m])
        c, s = float(np.mean(np.cos(crab))), float(np.mean(np.sin(crab)))
        bias = -math.atan2(s, c)
        spread = math.sqrt(max(0.0, -2.0 * math.log(max(1e-12, math.hypot(c, s)))))
        n_eff = max(4.0, float(m.sum()) * ds.dt / 2.0)
        return bias, spread / math.sqrt(n_eff)


EFFECT = HeadingBias()
