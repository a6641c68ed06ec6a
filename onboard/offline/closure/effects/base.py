"""What every effect module provides: regressors per residual channel, and its physics.

The base model (see :mod:`onboard.offline.closure.model`) predicts three residual channels:

* ``lateral``: velocity over ground across the measured heading (m/s); the base model
  says 0 (the vehicle moves where it points);
* ``heading``: measured heading change minus the integrated gyro yaw rate since the start
  of each segment (rad); base 0;
* ``along``: the surge dynamics ``U' = -a U + b c + c0`` of the through-water speed ``U``
  from the command ``c``, fitted in derivative form (m/s^2) and evaluated open loop.

An effect adds columns (one per linear parameter) to some channels, and may add a term to
the surge dynamics (``dynamics``) or to the predicted along-track speed (``along_output``)
for open-loop prediction. Effects are told apart by where they appear: a current changes
the along-track speed with heading, a compass deviation does not; a compass deviation
changes the heading rate against the gyro, a current does not; a GPS latency lags the
along-track speed during accelerations, a sideslip does not.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from onboard.offline.closure.dataset import Dataset


@dataclass
class Context:
    """Quantities the regressors need from the base fit: surge pole ``a`` (1/s), input
    gain ``b`` (m/s^2 per unit command), and the wave period (s) found in the residual."""

    a: float = 0.5
    b: float = 0.5
    wave_period_s: float | None = None
    extra: dict = field(default_factory=dict)


class Effect:
    """Base class of the effects in the vocabulary (architecture.md §4.3)."""

    name: str = ""
    params: tuple[str, ...] = ()
    needs_gyro: bool = False
    needs_commands: bool = False

    def applies(self, ds: Dataset, ctx: Context) -> bool:
        """Whether the data can show the effect at all (a gyro, commands where needed)."""
        if self.needs_gyro and not ds.has_gyro:
            return False
        if self.needs_commands and not ds.has_commands:
            return False
        return True

    def columns(self, ds: Dataset, ctx: Context) -> dict[str, np.ndarray]:
        """Regressor columns, channel -> array (n, len(params))."""
        raise NotImplementedError

    transforms_data: bool = False
    """True if the effect is applied to the data (a delay) rather than as regressors."""
    dynamic: bool = False
    """True if the effect changes the surge dynamics (see :meth:`surge_terms`)."""

    def surge_terms(self, theta: np.ndarray, ds: Dataset) -> tuple:
        """The effect's terms in ``U' = -(a + k(t)) U - d U|U| + b c + c0 + f(t)``:
        ``(f, k, d)`` with ``f`` and ``k`` arrays over ticks (or None) and ``d`` a float."""
        return None, None, 0.0

    def along_output(self, theta: np.ndarray, ds: Dataset, ctx: Context) -> np.ndarray:
        """Additive term of the predicted along-track speed over ground (m/s)."""
        return np.zeros(len(ds))

    def physical(self, theta: np.ndarray) -> bool:
        """False if the fitted parameters are physically impossible (a negative latency,
        a negative drag): such a fit is evidence of something else, not of this effect."""
        return True

    def output_delay_s(self, theta: np.ndarray) -> float:
        """Delay (s) of the measured along-track speed behind the simulated one."""
        return 0.0

    def lateral_output(self, theta: np.ndarray, ds: Dataset, ctx: Context) -> np.ndarray:
        """Additive term of the lateral channel (m/s) for parameters ``theta``."""
        cols = self.columns(ds, ctx).get("lateral")
        return np.zeros(len(ds)) if cols is None else cols @ theta

    def heading_output(self, theta: np.ndarray, ds: Dataset, ctx: Context) -> np.ndarray:
        """Additive term of the heading channel (rad) for parameters ``theta``."""
        cols = self.columns(ds, ctx).get("heading")
        return np.zeros(len(ds)) if cols is None else cols @ theta

    def describe(self, theta: np.ndarray, std: np.ndarray) -> tuple[dict, dict]:
        """Parameters in the vocabulary's units, and their one-sigma uncertainties."""
        return ({k: float(v) for k, v in zip(self.params, theta)},
                {k: float(s) for k, s in zip(self.params, std)})


def speed(ds: Dataset) -> np.ndarray:
    """Along-track speed (m/s), the multiplier of angle errors in the lateral channel."""
    return ds.along
