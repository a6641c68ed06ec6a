"""``actuator_mapping``: a skid-steered boat's thruster channels swapped or reversed.

The logged ``left`` and ``right`` commands (the config's ``[inputs]``) may not be the port
and starboard thrusters pushing ahead: the ESC cables swapped on the autopilot, a
propeller of the other hand, a column label that does not mean what it says. Eight
mappings are possible (swap or not, each side reversed or not). Physics fixes the right
one: the surge speed follows the mean of the two forward thrusts with a positive gain, and
the yaw rate (clockwise positive) follows half their difference, port minus starboard,
with a positive gain. Each mapping is scored by how much of the speed and yaw-rate
variance a first-order lag of its surge and yaw commands explains with positive gains
(:func:`explained`); the search keeps the best (:meth:`ActuatorMapping.search`) and the
data are re-mapped (:meth:`ActuatorMapping.transform`). Selection takes a mapping only
when it explains the selection part better than the logged one by its minimum gain
(:func:`held_out_gain`), which also sees a pure swap (it flips only the yaw command, which
the surge model does not use).

Reported: ``swapped`` (the ``left`` command drives the starboard thruster), and
``reversed_left`` / ``reversed_right`` (that logged command pushes astern when positive).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from onboard.offline.closure.dataset import Dataset, from_arrays
from onboard.offline.closure.effects.base import Effect

LAG_S = 1.5
"""Time constant (s) of the lag the commands are filtered with: a small boat's surge and
yaw time constants are of this order (the BlueBoat's surge pole 0.62 1/s)."""


def mapping(code: int) -> tuple[bool, bool, bool]:
    """(swapped, reversed_left, reversed_right) of mapping ``code`` in 0..7 (0: as logged)."""
    return bool(code & 1), bool(code & 2), bool(code & 4)


def remap(left: np.ndarray, right: np.ndarray, code: int) -> tuple[np.ndarray, np.ndarray]:
    """Port and starboard forward commands from the logged ``left`` and ``right``."""
    swapped, rev_l, rev_r = mapping(code)
    lft = -left if rev_l else left
    rgt = -right if rev_r else right
    return (rgt, lft) if swapped else (lft, rgt)


def _lagged(ds: Dataset, x: np.ndarray) -> np.ndarray:
    """``x`` through a first-order lag of ``LAG_S``, restarted at each segment."""
    alpha = ds.dt / (LAG_S + ds.dt)
    out = np.empty(len(ds))
    change = np.flatnonzero(np.r_[True, ds.run[1:] != ds.run[:-1], True])
    for a, b in zip(change[:-1], change[1:]):
        seg = np.nan_to_num(x[a:b])
        out[a:b] = lfilter([alpha], [1.0, alpha - 1.0], seg, zi=[seg[0] * (1.0 - alpha)])[0]
    return out


def _design(ds: Dataset, code: int) -> tuple[np.ndarray, np.ndarray]:
    port, stbd = remap(ds.cmd_left, ds.cmd_right, code)
    return _lagged(ds, 0.5 * (port + stbd)), _lagged(ds, 0.5 * (port - stbd))


def fit_gains(ds: Dataset, code: int) -> np.ndarray:
    """Least-squares [gain, offset] of speed on the lagged surge command and of yaw rate
    on the lagged yaw command (rows: surge, yaw)."""
    su, sy = _design(ds, code)
    out = []
    for x, y in ((su, ds.along), (sy, ds.r)):
        ok = np.isfinite(x) & np.isfinite(y)
        X = np.column_stack([x[ok], np.ones(ok.sum())])
        out.append(np.linalg.lstsq(X, y[ok], rcond=None)[0])
    return np.array(out)


def explained(ds: Dataset, code: int, gains: np.ndarray) -> float:
    """Share of the speed variance plus share of the yaw-rate variance left unexplained
    (0 perfect, 2 nothing) by mapping ``code`` with ``gains``; inf when a gain is not
    positive (a thruster pushing ahead must speed the boat up, port ahead must turn it to
    starboard)."""
    if not (gains[:, 0] > 0).all():
        return float("inf")
    su, sy = _design(ds, code)
    total = 0.0
    for (k, c), x, y in zip(gains, (su, sy), (ds.along, ds.r)):
        ok = np.isfinite(x) & np.isfinite(y)
        var = float(np.var(y[ok]))
        total += float(np.mean((y[ok] - k * x[ok] - c) ** 2)) / var if var > 0 else 1.0
    return total


def held_out_gain(fit: Dataset, hold: Dataset, code: int) -> float:
    """1 - (unexplained share of mapping ``code``) / (that of the logged mapping) on
    ``hold``, both with gains fitted on ``fit``. Physics holds for the logged mapping too:
    where its fitted gain is not positive, the best physical gain is zero (the command
    explains nothing of that channel), which is how a pure swap shows."""
    g0 = fit_gains(fit, 0)
    su, sy = _design(hold, 0)
    base = 0.0
    for (k, c), x, y, y_fit in zip(g0, (su, sy), (hold.along, hold.r), (fit.along, fit.r)):
        if k <= 0:
            k, c = 0.0, float(np.nanmean(y_fit))
        ok = np.isfinite(x) & np.isfinite(y)
        var = float(np.var(y[ok]))
        base += float(np.mean((y[ok] - k * x[ok] - c) ** 2)) / var if var > 0 else 1.0
    new = explained(hold, code, fit_gains(fit, code))
    return 1.0 - new / base if base > 0 else 0.0


class ActuatorMapping(Effect):
    """Swapped or reversed thruster channels, found by a search over the eight mappings
    and applied to the data (module docstring)."""

    name = "actuator_mapping"
    params = ("swapped", "reversed_left", "reversed_right")
    transforms_data = True
    needs_commands = True

    def applies(self, ds, ctx):
        """Only with two thruster commands (the yaw rate may come from the heading)."""
        return (ds.cmd_left is not None and ds.cmd_right is not None
                and bool(np.isfinite(ds.cmd_left).any()))

    def columns(self, ds, ctx):
        return {}

    def search(self, ds: Dataset) -> tuple[float, float] | None:
        """(mapping code, 0) of the best-explaining physical mapping; None when the
        logged one is best."""
        scores = {code: explained(ds, code, fit_gains(ds, code)) for code in range(8)}
        best = min(scores, key=scores.get)
        if best == 0 or not np.isfinite(scores[best]):
            return None
        return float(best), 0.0

    def transform(self, ds: Dataset, code: float) -> Dataset:
        """The data with the thruster commands re-mapped (and their derived commands)."""
        port, stbd = remap(ds.cmd_left, ds.cmd_right, int(code))
        out = from_arrays(
            ds.t, ds.psi, ds.v_n, ds.v_e, r=ds.r if ds.has_gyro else None,
            cmd_surge=0.5 * (port + stbd), cmd_yaw=0.5 * (port - stbd),
            thrust_quadratic=0.5 * (port * np.abs(port) + stbd * np.abs(stbd)),
            thrust_reverse=0.5 * (np.minimum(port, 0.0) + np.minimum(stbd, 0.0)),
            run=ds.run, north=ds.north, east=ds.east, source=ds.source,
            cmd_left=port, cmd_right=stbd)
        # from_arrays re-derives psi_dot, along... from the same measurements: identical;
        # keep the measured derived channels exactly as they were.
        for k in ("psi", "psi_dot", "along", "lateral", "speed_dot", "along_s", "r",
                  "actuator_lag_s", "base_terms", "acc_x", "acc_y"):
            setattr(out, k, getattr(ds, k))
        return out

    def describe_value(self, code: float) -> dict:
        """The mapping of ``code`` as booleans by parameter name."""
        return dict(zip(self.params, mapping(int(code))))


EFFECT = ActuatorMapping()
