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
      + sigma_t^2 S_t S_t^T                            the ballast's trim, per dive
      + sigma_psi^2 / 2 (D_perp D_perp^T               the compass's error, per dive:
                         + P_c P_c^T + P_s P_s^T)      constant, and one cycle in heading
      + sigma_z^2 sum_jk rho_jk c_j c_k^T              the water's vertical displacement
      + S_c S_c^T                                      where the last speed was carried

with ``e = (cos psi, sin psi)``, ``g = |gamma|`` and ``k = u_h / (sin g cos g)`` the
horizontal speed's change per radian of the flight-path angle. An error that is the
same all dive adds linearly, as a sum of its effects: the lift's relative error
``sigma_L`` scales every angle of attack alike, ``S_a = sum |alpha| k e dt``; a pitch
sensor's bias steepens the glide on one cast and flattens it on the other, so its
effects cancel over the yos, ``S_b = sum sign(pitch) k e dt``; so does a trim error
``sigma_t`` (cm^3: the neutral pump volume off the config's, a ballast error or water
of another density than the ballasting's), which adds buoyancy on one cast and takes it
on the other, the angle of attack in proportion, ``S_t = sum sign(pitch) |alpha| /
|V_pump - V_neutral| k e dt``; a compass's error
``delta(psi) = c + a cos psi + b sin psi`` (a constant bias and the one-cycle deviation
of iron that moves with the glider, ``c``, ``a``, ``b`` each of variance ``sigma_psi^2 /
2``: ``sigma_psi`` the compass's one-sigma at a heading) turns each step's displacement
``u_h dt e`` by ``delta``: ``D_perp = sum u_h e_perp dt`` (the whole displacement turned,
``(-D_e, D_n)``), ``P_c = sum cos(psi) u_h e_perp dt`` and ``P_s`` with ``sin``, ``e_perp =
(-sin psi, cos psi)``. A constant bias cancels where the glider turns back; a deviation
does not, the reciprocal legs' errors add. Internal waves lift and lower the water the
glider flies through: the depth rate counts the water's vertical displacement ``eta`` as
the glider's own, a cast from ``eta_a`` to ``eta_b`` travels ``(eta_b - eta_a) /
tan|gamma|`` too far or too short. The displacement is bounded (a few metres, 0 at the
surface), so its error does not grow with the dive: it is the displacement at each
inflection, ``eta_j`` of one-sigma ``sigma_z``, correlated ``rho_jk = exp(-|t_j - t_k| /
tau_z)`` between inflections, weighted ``c_j = v_k - v_(k+1)`` by the two casts it joins,
``v = s e / tan|gamma|`` averaged over a cast, ``s`` +1 down, -1 up (a descent then a
climb on one heading: ``2 e / tan|gamma|``, the next turn ``-2 e / tan|gamma|``: where the
water heaves slowly against the yos their errors cancel). Where the
model gives no speed (an inflection, a pitch
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
VERTICAL_DISPLACEMENT_STD_M = 5.0
"""One-sigma (m) of the water's vertical displacement by internal waves where a glider
turns: the Garrett-Munk spectrum's is about 7 m in the deep ocean's thermocline (Munk
1981), less in a shelf sea's."""
VERTICAL_DISPLACEMENT_TIME_S = 600.0
"""Correlation time (s) of that displacement: internal waves' periods, from the buoyancy
period's minutes to hours. The inflections of a shallow glider's yos, minutes apart, see
nearly the same displacement, whose errors then cancel (a descent's against the climb's);
a deep glider's, half an hour apart, independent ones."""
TRIM_STD_CC = 30.0
"""One-sigma (cm^3) of the neutral pump volume against the config's: the ballasting's
error, and the water's density against the ballasting's (0.5 kg/m^3 on a 60-L hull)."""
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
    ``pitch_bias_std`` (rad), ``trim_std`` (cm^3), ``vertical_displacement_std`` (m) and
    ``vertical_displacement_time_s`` (s): the other error sources' (module docstring)."""

    def __init__(self, model: GliderModel, surface_depth_m: float,
                 position_std_m: float, min_dive_s: float = MIN_DIVE_S,
                 heading_std: float = 0.0, lift_rel_std: float = LIFT_REL_STD,
                 pitch_bias_std: float = PITCH_BIAS_STD_RAD, trim_std: float = TRIM_STD_CC,
                 vertical_displacement_std: float = VERTICAL_DISPLACEMENT_STD_M,
                 vertical_displacement_time_s: float = VERTICAL_DISPLACEMENT_TIME_S) -> None:
        self.model = model
        self.surface_depth_m = surface_depth_m
        self.position_std_m = position_std_m
        self.min_dive_s = min_dive_s
        self.heading_std = heading_std
        self.lift_rel_std = lift_rel_std
        self.pitch_bias_std = pitch_bias_std
        self.trim_std = trim_std
        self.vertical_displacement_std = vertical_displacement_std
        self.vertical_displacement_time_s = vertical_displacement_time_s
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
        self._trim = [0.0, 0.0]       # S_t (m/cm^3)
        self._carried = [0.0, 0.0]    # S_c (m)
        self._dev_cos = [0.0, 0.0]    # P_c (m)
        self._dev_sin = [0.0, 0.0]    # P_s (m)
        self._inflections: list[tuple[float, float, float]] = []   # (t_j, c_j north, east)
        self._cast = [0.0, 0.0, 0.0]  # this cast's sum of s e / tan|gamma| dt, and of dt
        self._cast_sign = 0.0         # s of this cast (0: none yet)
        self._cast_t0 = 0.0           # when it began (s)
        self._cast_prev: tuple[float, float] | None = None   # v of the previous cast
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
        excess = abs(pump_cc - self.model.neutral_pump_cc)
        if excess > 0.0:
            trim = b * abs(glide.alpha) / excess
            self._trim[0] += trim * c
            self._trim[1] += trim * s
        down = -math.copysign(1.0, pitch)   # s: nose down, sinking
        if down != self._cast_sign:
            self._end_cast()
            self._cast_sign, self._cast_t0 = down, prev[0]
        f = down / math.tan(g) * dt
        self._cast[0] += f * c
        self._cast[1] += f * s
        self._cast[2] += dt

    def _end_cast(self) -> None:
        """The cast so far ends at an inflection: the inflection where it began, and its
        ``v`` for the next one's."""
        n, e, dt = self._cast
        if dt <= 0.0:
            return
        joint = self._inflection()
        if joint is not None:
            self._inflections.append(joint)
        self._cast_prev = (n / dt, e / dt)
        self._cast = [0.0, 0.0, 0.0]

    def _inflection(self) -> tuple[float, float, float] | None:
        """The inflection where the cast under way began: ``(t_j, c_j)``; None before the
        cast has a sample, or where no cast came before it (the dive began at the
        surface, where the water's heave is nil)."""
        n, e, dt = self._cast
        if dt <= 0.0 or self._cast_prev is None:
            return None
        prev = self._cast_prev
        return (self._cast_t0, prev[0] - n / dt, prev[1] - e / dt)

    def _at_surface(self) -> bool:
        return self._depth is not None and self._depth[1] <= self.surface_depth_m

    def covariance(self) -> tuple[float, float, float]:
        """``C`` of the module docstring so far (m^2): north-north, east-east,
        north-east."""
        cov = [2.0 * self.position_std_m ** 2, 2.0 * self.position_std_m ** 2, 0.0]
        d_perp = (-self._disp[1], self._disp[0])
        half = self.heading_std / math.sqrt(2.0)
        for scale, v in ((self.lift_rel_std, self._lift),
                         (self.pitch_bias_std, self._pitch_bias),
                         (self.trim_std, self._trim), (half, d_perp),
                         (half, self._dev_cos), (half, self._dev_sin),
                         (1.0, self._carried)):
            x, y = scale * v[0], scale * v[1]
            cov[0] += x * x
            cov[1] += y * y
            cov[2] += x * y
        pending = self._inflection()   # the cast under way joins the previous one
        joints = self._inflections + ([pending] if pending else [])
        z2, tau = self.vertical_displacement_std ** 2, self.vertical_displacement_time_s
        for tj, nj, ej in joints:
            for tk, nk, ek in joints:
                r = z2 * math.exp(-abs(tj - tk) / tau)
                cov[0] += r * nj * nk
                cov[1] += r * ej * ek
                cov[2] += r * nj * ek
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
