"""Known sensor errors taken out of each validated sample (``[corrections]``).

The errors are measured once (by ``onboard diagnose`` or by hand) and written to the
configuration (:class:`onboard.core.config.Corrections`, docs/service.md "corrections"):

* :class:`HeadingErrorModel`: the heading error as a function of the true heading (a
  constant offset plus the compass deviation as harmonics, or a deviation card) and its
  inversion, the true heading whose reading is the measured one;
* :class:`SampleCorrector`: the corrections applied to one sample (GNSS fixes re-stamped
  by their latency, headings through the inverted error model, gyro rates minus their
  bias). The engine applies it to every validated sample, live and in replay alike.
"""

from __future__ import annotations

import bisect
import math

import msgspec

from onboard.core.config import Corrections
from onboard.core.geo import wrap_2pi, wrap_pi
from onboard.core.messages import Attitude, GnssFix, Heading, Imu, Sample
from onboard.engine.sources import pattern_matches

TWO_PI = 2 * math.pi


class HeadingErrorModel:
    """The heading error ``e(psi)`` (rad) at the true heading ``psi`` (rad).

    ``e(psi) = offset + sum_k (s_k sin k psi + c_k cos k psi)``, ``k = 1, 2, ...``, plus
    the deviation card (``[heading_deg, error_deg]`` pairs) interpolated linearly and
    periodically over the true heading. A sensor reads ``m = psi + e(psi)``.

    Attributes:
        offset: the constant error (rad).
        sin, cos: the harmonic coefficients ``s_k``, ``c_k`` (rad), ``k = 1, 2, ...``.
        table: the deviation card as ``(heading, error)`` (rad) sorted by heading in
            ``[0, 2 pi)``, its first point repeated one turn on (empty: no card).
        active: False when the error is zero at every heading.
    """

    ITERATIONS = 3
    """Fixed-point rounds of :meth:`true_heading`: the error left after ``n`` rounds
    shrinks as ``A^(n+1)`` for a deviation of amplitude ``A`` (rad), below 1e-5 rad for
    ``A`` = 0.1 rad after three."""

    def __init__(self, c: Corrections) -> None:
        """The heading error of ``c`` (``heading_offset_rad``, ``heading_harmonics_*``,
        ``heading_deviation_table``)."""
        self.offset = float(c.heading_offset_rad)
        self.sin = tuple(float(x) for x in c.heading_harmonics_sin)
        self.cos = tuple(float(x) for x in c.heading_harmonics_cos)
        table = sorted((math.radians(h) % TWO_PI, math.radians(e))
                       for h, e in c.heading_deviation_table)
        if table:  # periodic: the first point again one turn on
            table.append((table[0][0] + TWO_PI, table[0][1]))
        self.table = table
        self.active = bool(self.offset != 0.0 or any(self.sin) or any(self.cos) or table)

    def error(self, psi: float) -> float:
        """``e(psi)`` (rad) at the true heading ``psi`` (rad)."""
        e = self.offset
        for k, a in enumerate(self.sin, 1):
            e += a * math.sin(k * psi)
        for k, b in enumerate(self.cos, 1):
            e += b * math.cos(k * psi)
        if self.table:
            e += self._card(psi)
        return e

    def _card(self, psi: float) -> float:
        """The deviation card (rad) interpolated at ``psi`` (rad), periodic."""
        x = psi % TWO_PI
        xs = [h for h, _ in self.table]
        i = bisect.bisect_right(xs, x)
        if i == 0:  # before the first point: between the last and the first
            (h0, e0), (h1, e1) = self.table[-2], self.table[-1]
            x += TWO_PI
        elif i >= len(self.table):
            (h0, e0), (h1, e1) = self.table[-2], self.table[-1]
        else:
            (h0, e0), (h1, e1) = self.table[i - 1], self.table[i]
        return e0 + (e1 - e0) * (x - h0) / (h1 - h0) if h1 > h0 else e0

    def true_heading(self, measured: float) -> float:
        """The true heading ``psi`` (rad, unwrapped) whose reading is ``measured`` (rad):
        ``m = psi + e(psi)`` inverted by the fixed-point iteration ``psi <- m - e(psi)``
        from ``psi = m`` (:attr:`ITERATIONS` rounds)."""
        psi = measured
        for _ in range(self.ITERATIONS):
            psi = measured - self.error(psi)
        return psi


class SampleCorrector:
    """The ``[corrections]`` of a configuration applied to one validated sample.

    * ``GnssFix``: time stamp minus ``gnss_latency_s`` (the instant it measured);
    * ``Heading`` and ``Attitude`` yaw (of the ``heading_sources``, default all): the
      true heading of the reading (:meth:`HeadingErrorModel.true_heading`);
    * ``Imu`` gyro rates and ``Attitude`` body rates: minus ``gyro_bias_rps``.

    Other samples pass unchanged.

    Attributes:
        latency_s: the GNSS latency (s) taken off each fix's time stamp.
        gyro: the gyro bias (rad/s, body x, y, z).
        heading: the heading error model.
        sources: the glob patterns of the heading sources corrected (empty: all).
        active: False when ``c`` corrects nothing (the engine then skips the corrector).
    """

    def __init__(self, c: Corrections) -> None:
        """Precompute what ``c`` asks for."""
        self.latency_s = float(c.gnss_latency_s)
        self.gyro = tuple(float(x) for x in c.gyro_bias_rps)
        self.heading = HeadingErrorModel(c)
        self.sources = list(c.heading_sources)
        self.has_gyro = any(g != 0.0 for g in self.gyro)
        self.has_heading = self.heading.active
        self.active = self.latency_s > 0.0 or self.has_gyro or self.has_heading
        self._for_source: dict[str, bool] = {}

    def heading_error(self, psi: float) -> float:
        """The heading error (rad) this corrector removes at true heading ``psi`` (rad)."""
        return self.heading.error(psi)

    def _heading_source(self, source: str) -> bool:
        """Whether the heading corrections apply to ``source`` (cached per source)."""
        ok = self._for_source.get(source)
        if ok is None:
            ok = self._for_source[source] = not self.sources or any(
                pattern_matches(p, source) for p in self.sources)
        return ok

    def __call__(self, sample: Sample) -> Sample:
        """``sample`` with the corrections applied (a new sample, or itself)."""
        if type(sample) is GnssFix:
            if self.latency_s > 0.0:
                return msgspec.structs.replace(sample, t=sample.t - self.latency_s)
        elif type(sample) is Heading:
            if self.has_heading and self._heading_source(sample.source):
                return msgspec.structs.replace(
                    sample, heading_rad=wrap_2pi(self.heading.true_heading(sample.heading_rad)))
        elif type(sample) is Imu:
            if self.has_gyro:
                gx, gy, gz = self.gyro
                return msgspec.structs.replace(sample, gyro_x=sample.gyro_x - gx,
                                               gyro_y=sample.gyro_y - gy,
                                               gyro_z=sample.gyro_z - gz)
        elif type(sample) is Attitude:
            return self._attitude(sample)
        return sample

    def _attitude(self, sample: Attitude) -> Attitude:
        """``sample`` with its yaw (a heading source) and body rates corrected."""
        changes: dict[str, float] = {}
        if self.has_heading and self._heading_source(sample.source):
            changes["yaw_rad"] = wrap_pi(self.heading.true_heading(sample.yaw_rad))
        if self.has_gyro:
            for name, g in zip(("roll_rate_rps", "pitch_rate_rps", "yaw_rate_rps"), self.gyro):
                v = getattr(sample, name)
                if v is not None and g != 0.0:
                    changes[name] = v - g
        return msgspec.structs.replace(sample, **changes) if changes else sample
