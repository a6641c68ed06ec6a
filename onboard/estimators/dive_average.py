"""Depth-averaged current of a glider's dive (algorithms.md §3.7).

A glider has GPS only at the surface. Over a dive from the last fix before it,
``(t_0, p_0)``, to the first fix after it, ``(t_1, p_1)``, the water carried the glider by
the difference between where it surfaced and where its own flight would have taken it::

    V_dac = (p_1 - p_0 - D) / (t_1 - t_0),     D = sum of u_h (cos psi, sin psi) dt

``D`` is the through-water displacement (north, east): the horizontal speed ``u_h`` of
the steady glide that descends at the measured depth rate at the measured pitch
(:meth:`.vehicle_models.GliderModel.glide_from_depth_rate`, Merckelbach et al. 2010),
along the measured heading, between consecutive depth samples below the surface. This is
the depth-averaged current of the OceanGliders DAC standard operating procedure, with the
glider model in place of the glider's own dead reckoning.

Its one-sigma per axis: the two fixes' position errors over the dive's duration, and the
model's speed error, which is one error for the whole dive (a coefficient or a trim
wrong for every yo alike), so its one-sigmas add linearly over the dive::

    sigma^2 = 2 sigma_p^2 / T^2 + (sum of sigma_u dt / T)^2

Where the model gives no speed (an inflection, a pitch below its least glide angle, a
pitch or heading not measured within :data:`MAX_DEPTH_INTERVAL_S`) the last speed is
carried, with a one-sigma of the speed itself; a dive unmodelled for more than
:data:`MAX_UNMODELLED_SHARE` of its time under water gives none.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from onboard.estimators.vehicle_models import GliderModel

MIN_DIVE_S = 600.0
"""A dive shorter than this (s) between its two fixes gives no current: the fixes'
errors over a few minutes outweigh the water's displacement."""
MAX_DEPTH_INTERVAL_S = 30.0
"""Depth samples further apart than this (s) give no depth rate, and a pitch or heading
older than this is none: the time between them is counted unmodelled."""
MAX_UNMODELLED_SHARE = 0.25
"""A dive whose time under water was unmodelled for more than this share gives no
current (a log too sparse to follow the flight: a Slocum's ``.sbd``)."""


class DiveCurrent(NamedTuple):
    """One dive's depth-averaged current."""

    t_start: float
    """Time (s) of the last fix before the dive."""
    t_end: float
    """Time (s) of the first fix after it."""
    north: float
    """North component (m/s)."""
    east: float
    """East component (m/s)."""
    std: float
    """One-sigma of each component (m/s)."""
    unmodelled_s: float
    """Time (s) under water where the model gave no speed (the last one carried)."""
    place: tuple[float, float]
    """Where it applies: the midpoint of the two fixes (north, east; m, their frame)."""


class DiveAverage:
    """The depth-averaged current of each dive (module docstring): feed it the fixes in
    a local frame and the depth samples with the pitch, heading and pump volume of their
    time; :attr:`latest` is the newest dive's current."""

    def __init__(self, model: GliderModel, surface_depth_m: float,
                 position_std_m: float, min_dive_s: float = MIN_DIVE_S) -> None:
        self.model = model
        self.surface_depth_m = surface_depth_m
        self.position_std_m = position_std_m
        self.min_dive_s = min_dive_s
        self.latest: DiveCurrent | None = None
        self.dives = 0
        self.unfollowed = 0   # dives left without a current (MAX_UNMODELLED_SHARE)
        self._anchor: tuple[float, float, float] | None = None  # (t, north, east)
        self._dived = False
        self._depth: tuple[float, float] | None = None  # (t, depth) of the last sample
        self._disp = [0.0, 0.0]       # through-water displacement (m) since the anchor
        self._disp_std = 0.0          # its one-sigma (m), added linearly
        self._under = 0.0             # time (s) under water since the anchor
        self._unmodelled = 0.0
        self._u_last = self._psi_last = 0.0

    def fix(self, t: float, north: float, east: float) -> DiveCurrent | None:
        """A GNSS fix at ``t`` (s), ``north``/``east`` (m): it ends a dive (returning its
        current) or becomes the start of the next."""
        out = None
        a = self._anchor
        ended = a is not None and self._dived and self._at_surface()
        if ended and t - a[0] >= self.min_dive_s:
            if self._unmodelled > MAX_UNMODELLED_SHARE * self._under:
                self.unfollowed += 1
            else:
                out = self._close(t, north, east, t - a[0])
        if out is not None or not self._dived or self._at_surface():
            self._anchor = (t, north, east)
            self._dived = False
            self._disp = [0.0, 0.0]
            self._disp_std = self._unmodelled = self._under = 0.0
        return out

    def depth(self, t: float, depth_m: float, pitch: float, heading: float,
              pump_cc: float) -> None:
        """A depth sample at ``t`` (s) with the pitch and heading (rad) and pump volume
        (cm^3) of its time: the flight since the previous sample into the displacement."""
        prev, self._depth = self._depth, (t, depth_m)
        if self._anchor is None or prev is None or t <= prev[0]:
            return
        below = depth_m > self.surface_depth_m or prev[1] > self.surface_depth_m
        if not below:
            return
        self._dived = True
        dt = t - prev[0]
        self._under += dt
        glide = None
        if dt <= MAX_DEPTH_INTERVAL_S and math.isfinite(heading):
            glide = self.model.glide_from_depth_rate(pitch, (depth_m - prev[1]) / dt,
                                                     pump_cc)
        if glide is not None and math.isfinite(glide.std_u_h):
            u, sd = glide.u_h, glide.std_u_h
            self._u_last, self._psi_last = u, heading
        else:  # the last speed along the last heading, its one-sigma the speed itself
            u, sd, heading = self._u_last, self._u_last, self._psi_last
            self._unmodelled += dt
        self._disp[0] += u * math.cos(heading) * dt
        self._disp[1] += u * math.sin(heading) * dt
        self._disp_std += sd * dt

    def _at_surface(self) -> bool:
        return self._depth is not None and self._depth[1] <= self.surface_depth_m

    def _close(self, t: float, north: float, east: float, duration: float) -> DiveCurrent:
        a = self._anchor
        assert a is not None
        vn = (north - a[1] - self._disp[0]) / duration
        ve = (east - a[2] - self._disp[1]) / duration
        std = math.hypot(math.sqrt(2.0) * self.position_std_m, self._disp_std) / duration
        self.dives += 1
        self.latest = DiveCurrent(a[0], t, vn, ve, std, self._unmodelled,
                                  (0.5 * (a[1] + north), 0.5 * (a[2] + east)))
        return self.latest
