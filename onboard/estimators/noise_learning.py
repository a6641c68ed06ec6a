"""Measurement noise learned from a channel's own innovations, both ways (algorithms.md §9).

Windowed covariance matching (Mehra 1972; Mohamed & Schwarz 1999, eq. 21): for a filter
whose forecast covariance is right, the innovation ``z = y - H x_f`` of a measurement of
noise covariance ``R`` has ``E[z z^T] = H P_f H^T + R``. With ``R = s R_0`` (``R_0`` the
declared noise, ``s`` the channel's variance scale) each accepted update gives one sample
of the scale::

    s_k = (min(z^T z, CAP tr(S)) - tr(H P_f H^T)) / tr(R_0)      (one sample)
    f_k = tr(H P_f H^T) / tr(R_0)                                  (the forecast's share)
    m_k = m_{k-1} + (s_k - m_{k-1}) / min(n_k, WINDOW)     (their means over the last
    f_k = f_{k-1} + (f_k - f_{k-1}) / min(n_k, WINDOW)      WINDOW updates)
    s   = clip(1 into [m_k - TRUST f_k, m_k + TRUST f_k], FLOOR, CEILING)
          once n_k >= MIN_UPDATES, else the start value

The matching takes the forecast covariance as right, and an error ``e`` of it moves
straight into ``R`` (``E[s_k] = s + e f``): with the forecast a large share of ``S`` (the
Doppler row of a boat, the current's velocity rows) a forecast 20 % too timid would halve
the learned noise. So the declared noise is kept unless the innovations contradict it by
more than a forecast error of ``TRUST`` (25 %) explains: the scale is the value nearest its
start value (1, or the scale a previous run ended with) within ``m_k +- TRUST f_k``. ``tr(H P_f H^T)`` is ``tr(S) - tr(R)`` of the
update as made, and ``CAP`` clips an
innovation at 3 sigma (Huber-like: a manoeuvre's model error, an outlier inside the gate,
must not carry the scale; for Gaussian innovations the clip takes 1.5 % off the mean of
``z^2``, and a noise far above ``S`` is still approached, by a factor up to ``CAP`` per
window), so the filter's own ``S``
and ``R`` are all a channel needs to hand over. A sample is taken only while the
forecast's share is at most ``FORECAST_SHARE_MAX`` times the declared noise's: the
sample's variance is ``2 tr(S)^2 / tr(R_0)^2`` for Gaussian innovations, so a filter still
converging (``P_f`` many times ``R_0``: its first updates, a restart) says next to nothing
about ``R`` and would swamp the mean. (Against the declared, not the learned noise: a
scale at its floor must still see the samples that lift it.) The mean moves both ways: a declared noise
three times too large is narrowed as a too small one is widened, within ``[FLOOR,
CEILING]`` times the declared variance (``FLOOR``: a sigma 0.2 times the declared;
``CEILING``: 5 times). Before ``MIN_UPDATES`` samples the scale keeps its start value (1,
or the value a previous run ended with, :meth:`NoiseScale.set_state`).

What the update takes. The learned scale is reported (health, the integrity monitor's
advice on the key) and persisted whatever it is; the filter's update takes it
(:attr:`NoiseScale.applied`)

* where it widens the declared noise, while the innovations are white (lag-1
  autocorrelation at most ``WHITE_LAG1_MAX``): a sensor louder than declared is weighted as
  loud as it is; innovations correlated in time carry a model's error (waves, a
  manoeuvre), not the sensor's, and widening for it cost the KF's speed on effect-waves
  0.0700 -> 0.0955 m/s (the Doppler row, lag-1 0.66);
* where it narrows it only on a channel that ``narrows`` (the heading increments): the
  process noise is a tuning of the model's error against the declared sensor noise, and
  a narrowed ``R`` hands that margin to the measurements. Measured: narrowing the
  heading increments' noise calibrates the heading of a boat whose compass is 0.3x the
  declared (1-sigma coverage 0.985 -> 0.71) at no cost found; narrowing the Doppler
  speed's cost the latency-corrected AIE speed 0.041 -> 0.069 m/s
  (tests/test_diagnose_roundtrip.py), narrowing the current's velocity rows its error
  0.0037 -> 0.0063 m/s (tests/test_current_sample_time.py, whose innovations came out
  below even the forecast's share: the forecast too timid, ``R`` not identified).

What is published (:class:`Consistency`, algorithms.md §9.1): where the filter keeps the
declared noise and its innovations are white and smaller than their ``S``, a sigma
published from the filter is scaled by their windowed mean ratio ``z^T z / tr(S)``
(:attr:`NoiseScale.published_factor`, at most 1, never below what the learned noise
supports), or, where the measurement noise is taken as the filter's, by the factor of the
forecast's part of ``S`` alone (:meth:`Consistency.forecast_factor`: the current's),
apart from the gain: the estimates, the gain and ``P`` are unchanged.

The process noise (:class:`ProcessScale`, algorithms.md §9.3): where a channel's
innovations are smaller than the forecast's share alone (the noise not identified), a
measurement-noise scale cannot fix them; on the heading axis the forecast's input error
``V_u`` takes a learned scale ``q``, shrinking while the innovations' windowed ``z^2 / S``
is below :data:`PROCESS_NIS_BAND` and their lag-1 autocorrelation is below
:data:`PUBLISHED_LAG1_MIN` (a gain above the optimal one), growing back to at most 1
above the band or with positively correlated innovations.

Why this and not the variational-Bayes filter (Sarkka & Nummenmaa 2009): every filter here
already has its innovation and ``S`` in closed form at each update, and the matching reads
them without changing the update itself, where the VB step iterates the posterior
update a few times per measurement; with a forgetting window both estimate the same
second moment. The matching needs the forecast covariance to be right: a forecast too
confident puts its excess into ``R`` (which still makes ``S``, and so the NIS, right).
"""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping

from mypy_extensions import mypyc_attr
import numpy as np

WINDOW = 200
"""Effective number of updates the mean spans (an exponential window of gain
``1 / WINDOW`` once that many have come; before, the plain mean of all of them)."""
MIN_UPDATES = 50
"""Samples before the scale moves from its start value: the sample variance of the mean
of 50 chi-square(1) values is 0.04, a sigma known to 10 %."""
FLOOR = 0.04
"""Smallest variance scale: a noise learned at most 5 times smaller (sigma) than
declared."""
CEILING = 25.0
"""Largest variance scale: a noise learned at most 5 times larger (sigma) than declared."""
FORECAST_SHARE_MAX = 3.0
"""A sample is taken only while ``tr(H P_f H^T) <= FORECAST_SHARE_MAX tr(R_0)``."""
TRUST = 0.25
"""Relative error of the forecast covariance taken as possible: the learned scale moves
from its start value (the declared noise, or the one restored) only as far as the
innovations contradict it beyond that."""
WHITE_LAG1_MAX = 0.4
"""A widened noise is applied only while the innovations' lag-1 autocorrelation is at most
this: sensor noise is white, a model's error (waves, a manoeuvre) is not. Measured at 5-10
Hz: 0.64-0.72 on the Doppler and velocity rows of effect-waves (2.5 s waves the model
lacks), -0.14 to +0.28 with every sensor three times louder than declared."""
PUBLISHED_LAG1_MIN = -0.25
"""A sigma is narrowed by its consistency factor only while the normalized innovations'
lag-1 autocorrelation is at least this (and at most :data:`WHITE_LAG1_MAX`). Innovations
correlated negatively say the gain is above the optimal one for the true noise: the
forecast's noise is too large against the measurement's (Mehra 1970), so ``S`` is inflated
by the forecast while the updated ``P`` is held near ``R``; their ratio would narrow a
``P`` that does not share the excess. (Positive correlation, a gain below the optimal one,
is what a sensor quieter than declared gives, the case the factor serves.) -0.25 is 3.5
standard errors of a :data:`WINDOW`-update mean of white innovations (``1 / sqrt(WINDOW)``
= 0.07). Measured: the boats' velocity rows settle within -0.07..+0.10 (-0.2..-0.3 in
their first minute); the BlueROV2's INS velocity rows stay at -0.26..-0.42, where the
current's error is an external push that no innovation sees (fault-dvl-lock-loss-rov,
live: 0.19 m/s at 2.7 published sigmas with the factor, 1.3 without)."""
SHARE_MIN = 0.1
"""A forecast's factor is taken only while the forecast is at least this share of ``S``:
below it the innovations hardly see the forecast (the factor's error is the ratio's over
the share: 0.07 / 0.1, for 200 white updates of 2 degrees of freedom)."""
CAP = 9.0
"""An innovation enters a sample at most as ``z^T z = CAP tr(S)``: 3 sigma."""


def _dot(a: float | np.ndarray, b: float | np.ndarray) -> float:
    """``a . b`` of two innovations (numbers or vectors): two floats multiplied without
    numpy (the same product as ``np.dot``, at a fraction of its call's cost)."""
    if isinstance(a, float) and isinstance(b, float):
        return float(a * b)
    return float(np.dot(a, b))


@mypyc_attr(allow_interpreted_subclasses=True)
class Consistency:
    """The consistency factor of a channel's published sigma (algorithms.md §9.1): the
    windowed mean of ``r_k = min(z^T z, CAP tr(S)) / tr(S)`` over every accepted update
    (whatever the forecast's share), and the lag-1 autocorrelation of the normalized
    innovations ``z / sqrt(tr(S))``.

    For a linear filter whose process and measurement noise are both ``c`` times the true
    ones, the actual error covariance is ``c P`` and ``E[r_k] = c``; white innovations
    are what says the gain is the optimal one for the true noise up to that scale
    (Mehra 1970), so the factor is taken only while they are white.

    Its lag-1 is not :attr:`NoiseScale.lag1`: that one whitens by the declared noise and
    takes only the updates whose forecast share lets them measure the sensor, this one
    whitens by ``S`` and takes every accepted update, as the published sigma does.

    Attributes (read them to debug):
        n: updates taken (capped at :data:`WINDOW`).
        ratio: the windowed mean of ``r_k``.
        lag: the windowed mean of ``z_k . z_{k-1} / sqrt(tr(S_k) tr(S_{k-1}))``.
        share: the windowed mean of the forecast's share of ``S``,
            ``s_k = tr(S_k - R_k) / tr(S_k)``.
    """

    __slots__ = ("n", "ratio", "lag", "share", "_prev")

    def __init__(self) -> None:
        self.n = 0
        self.ratio = 1.0
        self.lag = 0.0
        self.share = 1.0
        self._prev: np.ndarray | float | None = None

    def observe(self, z: float | np.ndarray, S_trace: float, R_trace: float = 0.0) -> None:
        """One accepted update: innovation ``z``, ``tr(S)`` and ``tr(R)`` as made (``R``
        not given: the forecast's share taken as 1, its factor the common scale's)."""
        power = _dot(z, z)
        if not (S_trace > 0.0 and math.isfinite(power)):
            self._prev = None
            return
        w = (z if isinstance(z, float) else np.asarray(z, dtype=float)) / math.sqrt(S_trace)
        lag = 0.0 if self._prev is None else _dot(w, self._prev)
        self._prev = w
        if self.n < WINDOW:
            self.n += 1
        gain = 1.0 / self.n
        self.ratio += gain * (min(power / S_trace, CAP) - self.ratio)
        self.lag += gain * (max(-CAP, min(lag, CAP)) - self.lag)
        self.share += gain * (max(S_trace - R_trace, 0.0) / S_trace - self.share)

    @property
    def lag1(self) -> float:
        """The normalized innovations' lag-1 autocorrelation over the window."""
        return self.lag / self.ratio if self.ratio > 0.0 else 0.0

    def factor(self, floor: float) -> float:
        """The variance factor of the published sigma: ``ratio`` within ``[floor, 1]``
        once :data:`MIN_UPDATES` updates are in and the innovations are white (lag-1
        between :data:`PUBLISHED_LAG1_MIN` and :data:`WHITE_LAG1_MAX`); else 1."""
        if not self.white:
            return 1.0
        return min(max(self.ratio, floor), 1.0)

    def forecast_factor(self, floor: float) -> float:
        """The variance factor of the forecast's part of ``S`` (``H P_f H^T``), the
        measurement noise taken as the filter's: ``E[r_k] = (1 - s) + a s`` gives
        ``a = 1 - (1 - ratio) / share``, within ``[floor, 1]``, under the conditions of
        :meth:`factor` and while the forecast is at least :data:`SHARE_MIN` of ``S``;
        else 1."""
        if not self.white or self.share < SHARE_MIN:
            return 1.0
        return min(max(1.0 - (1.0 - self.ratio) / self.share, floor), 1.0)

    @property
    def full(self) -> bool:
        """Whether its window holds :data:`WINDOW` updates."""
        return self.n >= WINDOW

    @property
    def white(self) -> bool:
        """Whether :data:`MIN_UPDATES` updates are in and the innovations are white (lag-1
        between :data:`PUBLISHED_LAG1_MIN` and :data:`WHITE_LAG1_MAX`)."""
        return self.n >= MIN_UPDATES and PUBLISHED_LAG1_MIN <= self.lag1 <= WHITE_LAG1_MAX


@mypyc_attr(allow_interpreted_subclasses=True)
class NoiseScale:
    """The learned variance scale of one measurement channel (module docstring).

    Attributes (read them to debug):
        channel: the innovation channel (``surge.increment``, ``velocity``, ...).
        key: the configuration key that declares the channel's noise.
        declared: the declared one-sigma (unit of ``unit``).
        unit: its unit.
        scale: the variance scale in use (``R = scale R_0``).
        n: samples taken (capped at :data:`WINDOW`).
        mean: their windowed mean (unclipped).
        forecast: the windowed mean of the forecast's share ``f_k``.
    """

    __slots__ = ("channel", "key", "declared", "basis", "unit", "narrows", "scale", "n",
                 "mean", "forecast", "power", "lag", "_start", "_prev", "consistency")

    def __init__(self, channel: str, key: str, declared: float, unit: str, *,
                 narrows: bool = False) -> None:
        self.channel = channel
        self.key = key
        self.declared = declared
        self.basis = "declared"
        """What :attr:`declared` is: the configuration's value (``declared``), or the
        sensor's own reported accuracy that the update takes instead (``reported``: a GNSS
        receiver's, the root mean square of its fixes' over the window)."""
        self.unit = unit
        self.narrows = narrows
        self.scale = self._start = 1.0
        self.n = 0
        self.mean = 1.0
        self.forecast = 0.0
        self._prev: float | np.ndarray | None = None
        self.power = self.lag = 0.0
        self.consistency = Consistency()

    def observe(self, z: float | np.ndarray, S_trace: float, R_trace: float) -> None:
        """One accepted update: the innovation ``z`` (a number or a vector), ``S_trace =
        tr(S)`` and ``R_trace = tr(R)`` of the update as made (``R`` already scaled by
        :attr:`applied`)."""
        self.consistency.observe(z, S_trace, R_trace)
        R0 = R_trace / self.applied
        power = _dot(z, z)
        forecast = S_trace - R_trace
        if not (R0 > 0.0 and math.isfinite(power) and forecast <= FORECAST_SHARE_MAX * R0):
            self._prev = None
            return
        cap = CAP * S_trace
        sample = ((power if power < cap else cap) - forecast) / R0
        lag = 0.0 if self._prev is None else _dot(z, self._prev)
        self._prev = z
        if self.n < WINDOW:
            self.n += 1
        gain = 1.0 / self.n
        self.mean += gain * (sample - self.mean)
        self.forecast += gain * (forecast / R0 - self.forecast)
        self.power += gain * (min(power, cap) / R0 - self.power)
        self.lag += gain * (max(-cap, min(lag, cap)) / R0 - self.lag)
        if self.n >= MIN_UPDATES:
            slack = TRUST * self.forecast
            m = min(max(self._start, self.mean - slack), self.mean + slack)
            self.scale = FLOOR if m < FLOOR else CEILING if m > CEILING else m

    @property
    def lag1(self) -> float:
        """The innovations' lag-1 autocorrelation over the window (0 before a sample)."""
        return self.lag / self.power if self.power > 0.0 else 0.0

    @property
    def std(self) -> float:
        """The learned one-sigma (unit of :attr:`unit`): ``declared sqrt(scale)``."""
        return self.declared * math.sqrt(self.scale)

    @property
    def applied(self) -> float:
        """The variance scale the filter's update takes (``R = applied R_0``): the learned
        scale where it widens the declared noise and the innovations are white, or narrows
        it on a channel that :attr:`narrows`; else 1 (module docstring, "What the update
        takes")."""
        if self.scale > 1.0:
            return self.scale if self.lag1 <= WHITE_LAG1_MAX else 1.0
        return self.scale if self.narrows else 1.0

    @property
    def identified(self) -> bool:
        """Whether the innovations identify the noise: the windowed mean of the samples
        (the noise's share of the innovation power) exceeds what a ``TRUST`` error of the
        forecast could make of it. A mean below says the forecast alone is larger than the
        innovations (its process noise set too high), not that the sensor is quiet."""
        return self.learned and self.mean > TRUST * self.forecast

    @property
    def supported_floor(self) -> float:
        """The smallest variance factor of a published sigma the learned noise supports
        (algorithms.md §9.1): where the innovations identify the noise, the smallest scale
        its samples are consistent with (``m_k - TRUST f_k``, a forecast ``TRUST`` too
        timid) over the applied one, at least :data:`FLOOR`; else :data:`FLOOR`."""
        if self.identified:
            return max((self.mean - TRUST * self.forecast) / self.applied, FLOOR)
        return FLOOR

    @property
    def published_factor(self) -> float:
        """The variance factor (at most 1) of a sigma published from this channel's
        filter: :meth:`Consistency.factor` floored at :attr:`supported_floor`."""
        return self.consistency.factor(self.supported_floor)

    @property
    def learned(self) -> bool:
        """Whether the scale has had its :data:`MIN_UPDATES` samples (or was restored)."""
        return self.n >= MIN_UPDATES

    @property
    def at_bound(self) -> int:
        """+1 at the ceiling, -1 at the floor, 0 between (or not moved yet)."""
        if self.n < MIN_UPDATES:
            return 0
        return 1 if self.scale >= CEILING else -1 if self.scale <= FLOOR else 0

    def get_state(self) -> dict[str, float]:
        """What to persist: the scale and the samples behind it."""
        return {"scale": self.scale, "n": self.n, "forecast": self.forecast}

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`get_state`: a finite scale within ``[FLOOR, CEILING]`` becomes
        the start value and the mean, with its sample count (at most :data:`WINDOW`);
        anything else is ignored."""
        try:
            s, n = float(state["scale"]), int(state.get("n", MIN_UPDATES))
        except (KeyError, TypeError, ValueError):
            return
        if math.isfinite(s) and FLOOR <= s <= CEILING and n >= 0:
            self.scale = self.mean = self._start = s
            self.n = min(n, WINDOW)
            f = state.get("forecast", 0.0)
            self.forecast = float(f) if isinstance(f, (int, float)) and f >= 0.0 else 0.0


PROCESS_NIS_BAND = (0.61, 1.41)
"""The windowed mean ``z^2 / S`` (:attr:`Consistency.ratio`) outside which a channel's
process-noise scale moves (algorithms.md §9.3): the NIS per degree of freedom of sigmas
whose 1-sigma coverage is 0.6-0.8 (docs/integrity.md, "The band"); inside it the scale
holds."""
PROCESS_STEP = 0.02
"""Gain of the process-noise scale's log per accepted update: ``q <- q exp(PROCESS_STEP
(r - 1))``; at ``r = 0.2``, 10 Hz, an e-fold in 6 s (the window of ``r``, 200 updates,
lags by about half of it: an overshoot of at most ``exp(-0.8)``, which the band's other
side brings back)."""
PROCESS_FLOOR = 1e-3
"""Smallest process-noise scale: an input error learned at most 30 times smaller (sigma)
than the configured ``v_d``."""


@mypyc_attr(allow_interpreted_subclasses=True)
class ProcessScale:
    """The learned scale ``q`` of an axis filter's process noise (its input-error variance
    ``V_u``, algorithms.md §9.3): the forecast takes ``q V_u``.

    Covariance matching on the forecast's side (Mehra 1972; the adaptive ``V_d`` of the
    AIE papers, §2.8): where the channel's measurement noise is learned and its
    innovations are smaller than the forecast's share alone (:attr:`NoiseScale.identified`
    false: what no measurement-noise scale can fix) and their windowed ``z^2 / S`` is
    below :data:`PROCESS_NIS_BAND`, ``q`` shrinks; above the band it grows back, never
    above 1 (widening the process noise is the rate row's matching of ``V_u``, §2.7) nor
    below :data:`PROCESS_FLOOR`; inside the band, or while the innovations identify the
    measurement noise, it holds.

    Attributes (read them to debug):
        scale: ``q``, 1 until it moves.
    """

    __slots__ = ("scale",)

    def __init__(self) -> None:
        self.scale = 1.0

    def observe(self, noise: NoiseScale) -> None:
        """After the channel's accepted update (``noise`` has observed it): one step of
        ``q`` from its windowed ``z^2 / S`` (:attr:`Consistency.ratio`)."""
        c = noise.consistency
        if not noise.learned or c.n < WINDOW:
            return
        r, lag1 = c.ratio, c.lag1
        lo, hi = PROCESS_NIS_BAND
        if (r < lo and lag1 < PUBLISHED_LAG1_MIN and not noise.identified) or (
                (r > hi or lag1 > WHITE_LAG1_MAX) and self.scale < 1.0):
            q = self.scale * math.exp(PROCESS_STEP * (min(r, CAP) - 1.0))
            self.scale = PROCESS_FLOOR if q < PROCESS_FLOOR else 1.0 if q > 1.0 else q


@mypyc_attr(allow_interpreted_subclasses=True)
class ChannelNoise:
    """The learned noise of a pipeline's channels, by channel name: reported, persisted
    and read by the integrity monitor (:meth:`report`)."""

    def __init__(self, scales: list[NoiseScale],
                 published: Mapping[str, Callable[[], float]] | None = None,
                 processes: Mapping[str, ProcessScale] | None = None) -> None:
        self.scales = {s.channel: s for s in scales}
        self.published = dict(published or {})
        """Per channel, the variance factor of its ``S`` that its pipeline's published
        sigma implies (algorithms.md §9.1: the common scale itself, or for the current
        ``(1 - s) + s a`` of its forecast's factor ``a``), for the channels whose factor a
        published sigma takes."""
        self.slow: dict[str, Callable[[], bool]] = {}
        """Per channel, whether the published sigma is held up by errors slower than the
        channel's innovations show (§9.1: the current's block-mean NIS above the factor
        its innovations give), for the channels whose published sigma has such a floor."""
        self.processes = dict(processes or {})
        """Per channel, the learned scale of the process noise of the filter it updates
        (algorithms.md §9.3), for the channels that learn one."""

    def health(self) -> dict[str, float]:
        """``noise.<channel>.scale`` and ``noise.<channel>.std`` (the learned one-sigma in
        the declared key's unit) per channel that had a sample."""
        out: dict[str, float] = {}
        for ch, s in self.scales.items():
            if not s.n:
                continue
            out[f"noise.{ch}.scale"] = s.scale
            out[f"noise.{ch}.std"] = s.std
            q = self.processes.get(ch)
            if q is not None and q.scale != 1.0:
                out[f"noise.{ch}.process_scale"] = q.scale
        return out

    def summary(self) -> dict[str, dict[str, object]]:
        """Per channel, for a reader (summary.json's ``noise``): the configuration
        ``key`` that declares its noise, its ``unit``, the ``declared`` one-sigma (its
        ``basis``: the config's, or the sensor's reported accuracy the update takes), the
        ``learned`` one (null before a sample), the ``samples`` taken, the variance
        scale the filter ``applied`` (the learned one only where it is applied: module
        docstring) and whether the innovations ``identified`` the sensor's noise (the
        forecast small enough to tell it apart)."""
        return {ch: {"key": s.key, "unit": s.unit, "declared": s.declared, "basis": s.basis,
                     "learned": s.std if s.n else None, "samples": s.n,
                     "applied": s.applied, "identified": s.identified}
                for ch, s in self.scales.items()}

    def get_state(self) -> dict[str, dict[str, float]]:
        """Per channel its :meth:`NoiseScale.get_state`, with ``process_scale`` where the
        channel learns its filter's process noise."""
        out = {ch: s.get_state() for ch, s in self.scales.items()}
        for ch, q in self.processes.items():
            if ch in out:
                out[ch]["process_scale"] = q.scale
        return out

    def set_state(self, state: object) -> None:
        """Restore :meth:`get_state`; unknown channels and malformed entries are
        ignored (a ``process_scale`` outside ``[PROCESS_FLOOR, 1]`` too)."""
        if not isinstance(state, dict):
            return
        for ch, sub in state.items():
            s = self.scales.get(ch)
            if s is not None and isinstance(sub, dict):
                s.set_state(sub)
                q, v = self.processes.get(ch), sub.get("process_scale")
                if (q is not None and isinstance(v, (int, float))
                        and PROCESS_FLOOR <= v <= 1.0):
                    q.scale = float(v)

    def report(self, channel: str) -> NoiseScale | None:
        """The channel's learned noise (None if it learns none)."""
        return self.scales.get(channel)

    def published_factor(self, channel: str) -> float:
        """The variance factor (at most 1) the pipeline's published sigma applies to what
        this channel measures: its innovations are consistent with that sigma when their
        NIS over the factor is (algorithms.md §9.1); 1 for a channel no published sigma
        is scaled by."""
        factor = self.published.get(channel)
        return 1.0 if factor is None else factor()

    def slow_error_holds(self, channel: str) -> bool:
        """Whether the published sigma of what ``channel`` measures is held up by errors
        slower than its innovations show: they are then small against that sigma without
        the sigma being larger than the errors (the integrity monitor does not judge them
        below their band, docs/integrity.md)."""
        holds = self.slow.get(channel)
        return holds is not None and holds()
