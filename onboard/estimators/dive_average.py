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

Its error, per axis, is what each source leaves over the dive (the covariance of
``V_dac``, ``C / T^2``, ``T = t_1 - t_0``)::

    C = 2 sigma_p^2 I                                  the two fixes
      + sigma_L^2 S_a S_a^T                            the lift (angle of attack), per dive
      + sigma_b^2 S_b S_b^T                            the pitch sensor's bias, per dive
      + sigma_psi^2 / 2 (D_perp D_perp^T               the compass's error, per dive:
                         + P_c P_c^T + P_s P_s^T)      constant, and one cycle in heading
      + sum (sigma_w / tan|gamma|)^2 min(2 tau_w, dt) dt e e^T    the vertical water
      + S_c S_c^T                                      where the last speed was carried

with ``e = (cos psi, sin psi)``, ``g = |gamma|`` and ``k = u_h / (sin g cos g)`` the
horizontal speed's change per radian of the flight-path angle. An error that is the
same all dive adds linearly, as a sum of its effects: the lift's relative error
``sigma_L`` scales every angle of attack alike, ``S_a = sum |alpha| k e dt``; a pitch
sensor's bias steepens the glide on one cast and flattens it on the other, so its
effects cancel over the yos, ``S_b = sum sign(pitch) k e dt``; a compass's error
``delta(psi) = c + a cos psi + b sin psi`` (a constant bias and the one-cycle deviation
of iron that moves with the glider, ``c``, ``a``, ``b`` each of variance ``sigma_psi^2 /
2``: ``sigma_psi`` the compass's one-sigma at a heading) turns each step's displacement
``u_h dt e`` by ``delta``: ``D_perp = sum u_h e_perp dt`` (the whole displacement turned,
``(-D_e, D_n)``), ``P_c = sum cos(psi) u_h e_perp dt`` and ``P_s`` with ``sin``, ``e_perp =
(-sin psi, cos psi)``. A constant bias cancels where the glider turns back; a deviation
does not, the reciprocal legs' errors add. The vertical water
velocity (internal waves, ``sigma_w``) is random, correlated over ``tau_w``: its
variance adds over the dive. Where the model gives no speed (an inflection, a pitch
below its least glide angle, a pitch or heading not measured within
:data:`MAX_DEPTH_INTERVAL_S`) the last speed is carried, with a one-sigma of the speed
itself, ``S_c = sum u_h e dt`` over those steps; a dive unmodelled for more than
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
LIFT_REL_STD = 0.25
"""Relative one-sigma of the glide model's lift per angle of attack, one value for a dive
(a hull, its fouling and trim against the published coefficients)."""
PITCH_BIAS_STD_RAD = math.radians(0.5)
"""One-sigma (rad) of the pitch sensor's bias: its calibration and its mounting in the
hull."""
VERTICAL_WATER_TIME_S = 300.0
"""Correlation time (s) of the vertical water velocity a glider meets: internal waves
near the buoyancy frequency, periods of minutes to tens of minutes."""
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
    std_north: float
    """One-sigma of the north component (m/s)."""
    std_east: float
    """One-sigma of the east component (m/s)."""
    unmodelled_s: float
    """Time (s) under water where the model gave no speed (the last one carried)."""
    place: tuple[float, float]
    """Where it applies: the midpoint of the two fixes (north, east; m, their frame)."""


class DiveAverage:
    """The depth-averaged current of each dive (module docstring): feed it the fixes in
    a local frame and the depth samples with the pitch, heading and pump volume of their
    time; :attr:`latest` is the newest dive's current.

    ``heading_std`` (rad): the compass's error at a heading; ``lift_rel_std``,
    ``pitch_bias_std`` (rad), ``vertical_water_time_s`` (s): the other error sources'
    (module docstring; the vertical water's one-sigma is the model's)."""

    def __init__(self, model: GliderModel, surface_depth_m: float,
                 position_std_m: float, min_dive_s: float = MIN_DIVE_S,
                 heading_std: float = 0.0, lift_rel_std: float = LIFT_REL_STD,
                 pitch_bias_std: float = PITCH_BIAS_STD_RAD,
                 vertical_water_time_s: float = VERTICAL_WATER_TIME_S) -> None:
        self.model = model
        self.surface_depth_m = surface_depth_m
        self.position_std_m = position_std_m
        self.min_dive_s = min_dive_s
        self.heading_std = heading_std
        self.lift_rel_std = lift_rel_std
        self.pitch_bias_std = pitch_bias_std
        self.vertical_water_time_s = vertical_water_time_s
        self.latest: DiveCurrent | None = None
        self.dives = 0
        self.unfollowed = 0   # dives left without a current (MAX_UNMODELLED_SHARE)
        self._anchor: tuple[float, float, float] | None = None  # (t, north, east)
        self._dived = False
        self._depth: tuple[float, float] | None = None  # (t, depth) of the last sample
        self._u_last = self._psi_last = 0.0
        self._restart()

    def _restart(self) -> None:
        """A new dive's sums (module docstring), all zero."""
        self._disp = [0.0, 0.0]       # through-water displacement D (m) since the anchor
        self._lift = [0.0, 0.0]       # S_a (m/rad)
        self._pitch_bias = [0.0, 0.0]  # S_b (m/rad)
        self._carried = [0.0, 0.0]    # S_c (m)
        self._dev_cos = [0.0, 0.0]    # P_c (m)
        self._dev_sin = [0.0, 0.0]    # P_s (m)
        self._random = 0.0            # the vertical water's variance (m^2), along e e^T ...
        self._random_nn = self._random_ne = 0.0   # ... its north-north, north-east parts
        self._under = 0.0             # time (s) under water since the anchor
        self._unmodelled = 0.0

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
            self._restart()
        return out

    def depth(self, t: float, depth_m: float, pitch: float, heading: float,
              pump_cc: float) -> None:
        """A depth sample at ``t`` (s) with the pitch and heading (rad) and pump volume
        (cm^3) of its time: the flight since the previous sample into the displacement
        and its error sums."""
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
        if glide is not None:
            u = glide.u_h
            self._u_last, self._psi_last = u, heading
        else:  # the last speed along the last heading, its one-sigma the speed itself
            u, heading = self._u_last, self._psi_last
            self._unmodelled += dt
        c, s = math.cos(heading), math.sin(heading)
        self._disp[0] += u * c * dt
        self._disp[1] += u * s * dt
        for p, f in ((self._dev_cos, c * u * dt), (self._dev_sin, s * u * dt)):
            p[0] -= f * s
            p[1] += f * c
        if glide is None:
            self._carried[0] += u * c * dt
            self._carried[1] += u * s * dt
            return
        g = abs(glide.gamma)
        k = u / (math.sin(g) * math.cos(g)) * dt   # metres per radian of |gamma|
        a = abs(glide.alpha) * k
        self._lift[0] += a * c
        self._lift[1] += a * s
        b = math.copysign(k, pitch)
        self._pitch_bias[0] += b * c
        self._pitch_bias[1] += b * s
        w = self.model.vertical_water_std / math.tan(g)
        v = w * w * min(2.0 * self.vertical_water_time_s, dt) * dt
        self._random += v
        self._random_nn += v * c * c
        self._random_ne += v * c * s

    def _at_surface(self) -> bool:
        return self._depth is not None and self._depth[1] <= self.surface_depth_m

    def covariance(self) -> tuple[float, float, float]:
        """``C`` of the module docstring so far (m^2): north-north, east-east,
        north-east."""
        cov = [2.0 * self.position_std_m ** 2, 2.0 * self.position_std_m ** 2, 0.0]
        d_perp = (-self._disp[1], self._disp[0])
        half = self.heading_std / math.sqrt(2.0)
        for scale, v in ((self.lift_rel_std, self._lift),
                         (self.pitch_bias_std, self._pitch_bias), (half, d_perp),
                         (half, self._dev_cos), (half, self._dev_sin),
                         (1.0, self._carried)):
            x, y = scale * v[0], scale * v[1]
            cov[0] += x * x
            cov[1] += y * y
            cov[2] += x * y
        cov[0] += self._random_nn
        cov[1] += self._random - self._random_nn
        cov[2] += self._random_ne
        return cov[0], cov[1], cov[2]

    def _close(self, t: float, north: float, east: float, duration: float) -> DiveCurrent:
        a = self._anchor
        assert a is not None
        vn = (north - a[1] - self._disp[0]) / duration
        ve = (east - a[2] - self._disp[1]) / duration
        c_nn, c_ee, _ = self.covariance()
        self.dives += 1
        self.latest = DiveCurrent(a[0], t, vn, ve, math.sqrt(c_nn) / duration,
                                  math.sqrt(c_ee) / duration, self._unmodelled,
                                  (0.5 * (a[1] + north), 0.5 * (a[2] + east)))
        return self.latest
