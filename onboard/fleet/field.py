"""One current field from every vehicle's estimates: Gaussian-process regression in space
and time with a per-vehicle correlated error (docs/algorithms.md, "The fleet's current
field").

The water current ``c(x, t)`` (north and east, m/s) at position ``x`` (m on a local plane)
and time ``t`` (UTC, s) is a Gaussian process about a constant mean, each component
independent with the same covariance (the signal)::

    k_c((x, t), (x', t')) = sigma_f^2 exp(-|x - x'|^2 / (2 l_s^2) - (t - t')^2 / (2 l_t^2))

A vehicle's estimate is the field plus the vehicle's own error, which is not white: a
current estimator's error wanders slowly (a compass offset, a model error, the filter's
memory), so ten records a second are not ten measurements. Each vehicle's error is an
Ornstein-Uhlenbeck process along its own time line, scaled by the sigma the vehicle
reports (``std``), plus a small white floor::

    k_e(i, j) = a^2 s_i s_j exp(-|t_i - t_j| / tau)   for records i, j of one vehicle
              + sigma_w^2 [i = j]

The records are first thinned into super-observations: the records of one vehicle within
one window of :data:`THIN_S` seconds averaged (position, time, current; ``s`` their RMS
sigma), so the cost follows the fleet's hours, not its record rate. The hyperparameters
``theta = (sigma_f north, sigma_f east, l_s, l_t, a, tau, sigma_w)`` maximize the marginal likelihood of a
sample of at most :data:`FIT_MAX` super-observations (runs of consecutive ones, so that
``tau`` is seen; both components share them), with its analytic gradient (Rasmussen and
Williams 2006, eq. 5.9) and scipy's L-BFGS-B; with a :class:`Prior` (the default,
:data:`PRIOR`: log-normal, from the physical scales of coastal currents) they are the
posterior's mode instead. A fleet too sparse to fit (windows of fewer than
:data:`MIN_FIT_VEHICLES` vehicles) is averaged over the prior's length scales
(:class:`Averaged`), so its sigma carries the hyperparameters' own uncertainty.

A prediction at ``(x*, t*)`` uses the :data:`NEIGHBOURS` super-observations nearest in the
scaled distance ``sqrt(|x - x*|^2 / l_s^2 + (t - t*)^2 / l_t^2)`` (a k-d tree), within
:data:`KNOWN_WITHIN`: with ``K = k_c + k_e`` over them and ``k*`` the signal covariance
with the point::

    mean = m + k*' K^-1 (y - m),   var = sigma_f^2 - k*' K^-1 k*

per component (``sigma_f``, the error term and the sigmas differ by component: a tidal
stream along a channel varies far more along it than across). With no
super-observation within :data:`KNOWN_WITHIN` the field knows nothing there (``None``).
The vertical current ``down``, where a record gives one (an underwater vehicle's; a
boat's has none, which is not a down of 0), is the same process with its own mean and
spread ``sigma_down`` (fitted by its own marginal likelihood, :func:`fit_sigma_down`), the
scales and the error model of north and east and one error common to every window that
gives a down (:func:`down_bias_variance`), predicted from the super-observations that
have one (None where none is near); depth is not a coordinate.

A vehicle's estimate is a memory of the water along its track, not the water where it is:
a window's place is as uncertain as the distance its vehicle covers in the estimator's
memory :data:`ESTIMATE_MEMORY_S` (:func:`memory_place`, added to its position's sigma).

The predictive sigma is scaled by what the fleet's own windows show: each predicted from
the other vehicles misses by more or less than the process says (:func:`calibration`,
learned with the hyperparameters; it only widens).

A record without time or position, or without either component of the current with a
converged sigma (withheld by an integrity check, not yet converged, not finite), is not
an observation; one that gives one component is an observation of that component, and a
super-observation's other component is NaN, as a boat's down is. A super-observation
further than :data:`OUTLIER_SIGMA` predictive sigmas from what the other vehicles say at
its place is an outlier and left out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from onboard.core.geo import radii_of_curvature
from onboard.core.messages import EstimateRecord
from onboard.core.stamps import UTC_MIN_S

THIN_S = 30.0
"""Length (s) of the windows a vehicle's records are averaged in (one super-observation
per vehicle and window)."""
HISTORY_S = 6 * 3600.0
"""Super-observations older than this (s) before the newest are forgotten."""
PLANE_RECENTRE_M = 10_000.0
"""The local plane moves to the kept windows' middle when that lies further than this (m)
from its origin: the equirectangular :class:`Plane` keeps distances within about 0.1 %
over 10 km of its origin, and a service that runs for weeks from one survey site to the
next, or whose first record came from far off, would otherwise fit its field on a plane
stretched by several per cent."""
NEIGHBOURS = 64
"""Super-observations a prediction uses (the nearest in scaled distance)."""
KNOWN_WITHIN = 3.0
"""Scaled distance (length scales) beyond which a super-observation says nothing."""
FIT_MAX = 240
"""Super-observations the marginal likelihood is computed over."""
FIT_RUN = 6
"""Consecutive super-observations of one vehicle per run of the fitting sample."""
MIN_FIT = 24
"""Fewer super-observations than this keep the hyperparameters as they are."""
OUTLIER_SIGMA = 5.0
"""A super-observation this many predictive sigmas from the others' field is an outlier."""
JUDGES = 2
"""Other vehicles whose windows must be near a window for it to be judged an outlier."""
SCREEN_WITHIN_S = 600.0
"""Only windows this recent (s before the newest record) are judged for outliers: a live
fleet's windows are judged as they close; a history that arrives in bulk (a service
restarted onto stored records) is taken as it is, so a fit's cost stays bounded."""
CALIBRATION_SAMPLE = 120
"""Super-observations (evenly spread over the history) each fit predicts from the other
vehicles to calibrate the field's sigma (:func:`calibration`)."""
CALIBRATION_MIN = 20
"""Fewer leave-one-vehicle-out predictions than this leave the field's sigma as the
Gaussian process gives it."""
VARIANCE_SCALE_BOUNDS = (1.0, 25.0)
"""Bounds of the learned scale of the field's predictive variance (:func:`calibration`):
its sigma never narrowed, at most five times wider."""
FLOOR_STD_BOUNDS = (1e-4, 0.1)
"""Bounds (m/s) of the learned floor of the field's predictive sigma (:func:`calibration`:
what a stationary field misses where its windows are dense)."""
OWN_SCALE_BOUNDS = (0.05, 20.0)
"""Bounds of the learned scale of a window's own variance, from the crossings
(:func:`own_scale`)."""
FLOOR_STD_START = 1e-3
"""Where the floor's fit starts (m/s)."""
CROSSING_RADIUS = 0.15
"""Two windows of different vehicles nearer than this in the scaled space and time (the
length and time scales as units: about 30 m and 5 minutes on fleet-survey) are a
crossing: the water differs little between them, so their difference measures their own
errors (:func:`own_scale`)."""
MAX_STD_MPS = 0.5
"""A component whose sigma exceeds this (m/s) is not converged: not observed."""
MAX_SPEED_MPS = 6.0
"""A current faster than this (m/s) is not water: not an observation."""
SIGMA_DOWN = 0.02
"""The down component's spread about its mean (m/s) before it is fitted: vertical
currents are a few cm/s at most outside convection and internal waves."""
SIGMA_DOWN_BOUNDS = (1e-3, 1.0)
"""Bounds (m/s) of the down component's spread in its fit."""
MIN_FIT_DOWN = 12
"""Fewer super-observations with a down than this keep its spread as it is."""
MIN_FIT_VEHICLES = 3
"""Super-observations of fewer vehicles than this are not fitted: with two, every
difference between them may be one vehicle's slowly wandering error, and the likelihood
says so (on the simulator's fleet-channel, two vehicles fitted a 76 m length scale, a
0.016 m/s spread and a 530 s error correlation by maximum likelihood, sigmas a third of
the misses; with the prior, the posterior's mode was as small: 0.017 m/s, 73 m). With a
prior the field is then averaged over it (:meth:`Prior.quadrature`); without, the
hyperparameters are kept as they are."""
MAX_POSITION_STD_M = 200.0
"""A record whose position sigma exceeds this (m per axis; an AUV dead reckoned for
hours) is not placed: not an observation."""
ESTIMATE_MEMORY_S = 20.0
"""How far back along its own track (s) a vehicle's current estimate reaches: a current
estimator's estimate is a memory of the water it crossed, not of the water where it is
(docs/algorithms.md §8.9). Measured on the simulator's ``fleet-survey`` (seeds 1-2,
``python -m validation.fleet_shared``): each vehicle's error against the true water
where it was earlier is least 5-30 s back (the boats on north-south lines 5 s, the AUVs
and the boat on east-west lines 10-20 s, the station-keeper 30 s). A window's place is
as uncertain as the distance its vehicle covers in that memory: ``speed x
ESTIMATE_MEMORY_S`` per axis (:func:`memory_place`)."""


NORTH, EAST, DOWN = 0, 1, 2
"""The current's components, the columns of :attr:`SuperObs.y` and :attr:`SuperObs.s`."""


class Hyper(NamedTuple):
    """The hyperparameters ``theta`` (module docstring), in SI units."""

    sigma_north: float = 0.2  # m/s, the field's spread about its mean, north
    sigma_east: float = 0.2   # m/s, and east
    length_m: float = 1000.0  # m, its length scale
    length_s: float = 3600.0  # s, its time scale
    scale: float = 1.0        # the reported sigmas' factor, a
    tau_s: float = 60.0       # s, the correlation time of a vehicle's error
    white: float = 0.005      # m/s, the white floor sigma_w

    def spread(self, c: int) -> float:
        """The field's spread (m/s) of horizontal component ``c`` (:data:`NORTH` or
        :data:`EAST`)."""
        return self.sigma_north if c == NORTH else self.sigma_east

    @staticmethod
    def bounds() -> list[tuple[float, float]]:
        """Bounds of each hyperparameter (SI), for the fit (in logarithms)."""
        return [(1e-3, 5.0), (1e-3, 5.0), (30.0, 1e5), (60.0, 2e5), (0.1, 10.0), (1.0, 7200.0),
                (1e-4, 0.5)]


class Prior(NamedTuple):
    """A log-normal prior on each hyperparameter (docs/algorithms.md §8.3): ``log theta_j``
    normal about ``log median_j`` with standard deviation ``log_sd_j``."""

    median: Hyper
    log_sd: Hyper

    def penalty(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """``-log p(theta)`` (up to a constant) at ``theta`` (the logarithms of
        :class:`Hyper`'s fields) and its gradient in ``theta``."""
        sd = np.array(self.log_sd)
        dev = (theta - np.log(np.array(self.median))) / sd
        return 0.5 * float(dev @ dev), dev / sd

    def quadrature(self) -> list[tuple[float, Hyper]]:
        """The prior's length scale at the three points of a Gauss-Hermite rule for its
        normal logarithm (``log median +- sqrt(3) log_sd`` and the median, weights 1/6,
        2/3, 1/6), every other hyperparameter at its median: the hyperparameters a field
        is averaged over when the fleet is too sparse to fit them."""
        step = math.sqrt(3.0) * self.log_sd.length_m
        return [(w, self.median._replace(length_m=self.median.length_m * math.exp(k * step)))
                for w, k in ((1.0 / 6.0, -1), (2.0 / 3.0, 0), (1.0 / 6.0, 1))]


PRIOR = Prior(
    median=Hyper(sigma_north=0.1, sigma_east=0.1, length_m=300.0, length_s=3600.0,
                 scale=1.0, tau_s=60.0, white=0.005),
    log_sd=Hyper(sigma_north=1.0, sigma_east=1.0, length_m=1.0, length_s=1.0,
                 scale=0.5, tau_s=1.0, white=2.0))
"""The field's prior from the physical scales of coastal currents and of a current
estimator's error (docs/algorithms.md §8.3 gives the sources): a spread of 0.1 m/s (0.04-0.27
within one log-sd) over a survey area, a length scale of 300 m (110-820 m: the
submesoscale's fronts and eddies), a time scale of 1 h (a tide turns in hours), the
reported sigmas trusted within a factor 1.6, a vehicle's error correlated over 60 s
(22-160 s: a current filter's memory), a white floor of 5 mm/s (loose)."""

@dataclass(frozen=True)
class Observation:
    """One vehicle's current estimate at one instant: where (deg), when (UTC s), the
    current (north, east; m/s) and its one-sigma (m/s); a component the vehicle does not
    know (withheld as unknown, e.g. along its track before it has turned) is None with
    its sigma, and at least one is known."""

    vehicle: str
    utc: float
    lat_deg: float
    lon_deg: float
    north: float | None
    east: float | None
    std_north: float | None
    std_east: float | None
    down: float | None = None
    std_down: float | None = None
    position_std_m: float | None = None


def observation(rec: EstimateRecord) -> tuple[Observation | None, str]:
    """The observation a ``current`` record makes, or None and why not (``no_time``,
    ``bad_time`` (not finite, or before 2000, ``core.stamps.UTC_MIN_S``: a clock never set,
    a simulator's seconds since its start), ``no_position``,
    ``bad_position`` (not finite, outside +-90 deg of latitude or +-180 of longitude, or
    exactly 0, 0: a fix never made), ``position_uncertain`` (its ``position_std_m`` above
    :data:`MAX_POSITION_STD_M`), ``no_current``, ``no_std``, ``not_converged``,
    ``too_fast``). A horizontal component is observed where the record gives a finite
    value with a sigma in (0, :data:`MAX_STD_MPS`]; a record observes at least one (a
    vehicle publishes the component across its track before the one along it, which
    needs its turns; docs/current.md), else it is no observation, for the first of
    these reasons its components have: no value (withheld), no sigma, a sigma not
    converged. Its ``down`` (and ``std_down``) only where the record gives a finite one
    with a converged sigma (a boat's record has none: it is absent, never 0)."""
    v, sd = rec.values, rec.std
    if rec.utc is None:
        return None, "no_time"
    if not (math.isfinite(rec.utc) and rec.utc >= UTC_MIN_S):
        return None, "bad_time"
    lat, lon = rec.lat_deg, rec.lon_deg
    if lat is None or lon is None:
        return None, "no_position"
    if not (abs(lat) <= 90.0 and abs(lon) <= 180.0) or lat == lon == 0.0:
        return None, "bad_position"
    p = rec.position_std_m
    if p is not None and not p <= MAX_POSITION_STD_M:
        return None, "position_uncertain"
    known, why = [], []
    for ax in ("north", "east"):
        x, s_x = v.get(ax), sd.get(ax)
        if x is None or not math.isfinite(x):
            known.append((None, None)), why.append("no_current")
        elif s_x is None or not s_x > 0.0:
            known.append((None, None)), why.append("no_std")
        elif s_x > MAX_STD_MPS:
            known.append((None, None)), why.append("not_converged")
        else:
            known.append((x, s_x))
    (n, s_n), (e, s_e) = known
    if n is None and e is None:
        return None, min(why, key=("no_current", "no_std", "not_converged").index)
    if math.hypot(n or 0.0, e or 0.0) > MAX_SPEED_MPS:
        return None, "too_fast"
    d, s_d = v.get("down"), sd.get("down")
    if d is None or s_d is None or not (math.isfinite(d) and 0.0 < s_d <= MAX_STD_MPS):
        d = s_d = None
    return Observation(rec.vehicle, rec.utc, rec.lat_deg, rec.lon_deg, n, e, s_n, s_e,
                       d, s_d, p), ""


class Prediction(NamedTuple):
    """The field at one place and time: the current (m/s; None where unknown), its
    one-sigma (m/s; None where unknown) and how many super-observations it rests on;
    ``down`` and ``std_down`` from the super-observations that have one (None where none
    is near)."""

    north: float | None
    east: float | None
    std_north: float | None
    std_east: float | None
    n_obs: int
    down: float | None = None
    std_down: float | None = None


UNKNOWN = Prediction(None, None, None, None, 0)


class Plane:
    """Latitude and longitude on a local plane (m) about a reference point: the WGS-84
    meridional and prime-vertical radii at the reference (an equirectangular projection,
    within 0.1 % over tens of km)."""

    def __init__(self, lat0_deg: float, lon0_deg: float) -> None:
        m, n = radii_of_curvature(lat0_deg)
        self.lat0, self.lon0 = lat0_deg, lon0_deg
        self.m_per_rad_lat = m
        self.m_per_rad_lon = n * math.cos(math.radians(lat0_deg))

    def to_ne(self, lat_deg, lon_deg):
        """(north, east) in m of latitude and longitude (deg; scalars or arrays); east
        the shorter way round (a place across the antimeridian is a few metres east, not
        40 000 km west)."""
        return (np.radians(np.asarray(lat_deg) - self.lat0) * self.m_per_rad_lat,
                np.radians(wrap_lon(np.asarray(lon_deg) - self.lon0)) * self.m_per_rad_lon)

    def to_latlon(self, north_m, east_m):
        """(lat, lon) in deg of a position on the plane (m; scalars or arrays), the
        longitude within [-180, 180]."""
        return (self.lat0 + np.degrees(np.asarray(north_m) / self.m_per_rad_lat),
                wrap_lon(self.lon0 + np.degrees(np.asarray(east_m) / self.m_per_rad_lon)))


def wrap_lon(lon_deg):
    """A longitude (or a difference of two; deg, scalar or array) within [-180, 180]:
    360 added or taken where it is beyond, a value within left exactly as it is."""
    lon = np.asarray(lon_deg)
    return np.where(lon > 180.0, lon - 360.0, np.where(lon < -180.0, lon + 360.0, lon))[()]


class SuperObs(NamedTuple):
    """The super-observations as arrays: ``x`` (n, 3) north m, east m, UTC s less
    ``t_ref``; ``y`` (n, 3) current north, east, down (m/s; NaN in a window without the
    component); ``s`` (n, 3) their sigmas;
    ``vehicle`` (n,) an integer per vehicle; ``utc`` (n,) the UTC (s); ``keys`` (vehicle
    id, window number) of each; ``place`` (n,) how far the water it observed may be
    from its place (m per axis): the RMS of its records' position sigmas (0 where they
    gave none) and its estimate's memory along the track (:func:`memory_place`) in
    quadrature; ``plane`` the :class:`Plane` ``x`` is on."""

    x: np.ndarray
    y: np.ndarray
    s: np.ndarray
    vehicle: np.ndarray
    utc: np.ndarray
    keys: list[tuple[str, int]]
    place: np.ndarray
    plane: Plane | None = None

    def take(self, pick: np.ndarray) -> "SuperObs":
        """The super-observations ``pick`` selects (a boolean mask or indices)."""
        idx = np.flatnonzero(pick) if pick.dtype == bool else pick
        return SuperObs(self.x[idx], self.y[idx], self.s[idx], self.vehicle[idx],
                        self.utc[idx], [self.keys[i] for i in idx], self.place[idx],
                        self.plane)


def signal_corr(h: Hyper, xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """``k_c / sigma_f^2`` between the rows of ``xa`` and ``xb`` (north m, east m, time
    s)."""
    d2 = ((xa[:, None, :2] - xb[None, :, :2]) ** 2).sum(-1) / h.length_m ** 2 + \
        (xa[:, None, 2] - xb[None, :, 2]) ** 2 / h.length_s ** 2
    return np.exp(-0.5 * d2)


def error_cov(h: Hyper, t: np.ndarray, vehicle: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``k_e`` among observations at times ``t`` (s) of ``vehicle`` with sigmas ``s``."""
    same = vehicle[:, None] == vehicle[None, :]
    corr = np.exp(-np.abs(t[:, None] - t[None, :]) / h.tau_s)
    return (h.scale ** 2) * np.outer(s, s) * corr * same + h.white ** 2 * np.eye(len(t))


def down_bias_variance(h: Hyper, s: np.ndarray) -> float:
    """The variance (m^2/s^2) of one error common to every window that gives a down, of
    any vehicle and at any time: ``(max(a, 1) median(s))^2`` for the windows' sigmas ``s``
    (docs/algorithms.md §8.7: a diving vehicle's down is biased for a whole run by its
    model's through-water heave, alike on vehicles of one kind, and no other vehicle checks
    it, so neither time nor a second vehicle averages it away; a constant, it is one with
    the unknown mean and adds to the prediction's variance whole)."""
    return (max(h.scale, 1.0) * float(np.median(s))) ** 2


def place_variance(sigma_f: float, length_m: float, place: np.ndarray) -> np.ndarray:
    """The variance (m^2/s^2) a position sigma ``place`` (m per axis) adds to an
    observation of a component of spread ``sigma_f`` (m/s) and length scale ``length_m``:
    the mean square of the field's difference between the true and the reported place,
    ``E[(c(x + d) - c(x))^2] = 2 sigma_f^2 place^2 / (l_s^2 + place^2)`` for ``d`` normal
    of ``place`` per axis (0 for a fix-placed window; up to ``2 sigma_f^2``, an
    observation that says nothing, for one lost far beyond the length scale)."""
    p2 = place ** 2
    return 2.0 * sigma_f ** 2 * p2 / (length_m ** 2 + p2)


def memory_place(speed_mps: np.ndarray, memory_s: float = ESTIMATE_MEMORY_S) -> np.ndarray:
    """The place sigma (m per axis) of an estimate that remembers the water along its
    track: an exponential memory of ``memory_s`` (s) at ``speed_mps`` (m/s over ground)
    puts the water it observed ``d = speed u`` back, ``u`` exponential of mean
    ``memory_s``, ``E|d|^2 = 2 (speed memory_s)^2``: as a place error of the same mean
    square spread over both axes, ``speed x memory_s`` per axis (docs/algorithms.md
    §8.9)."""
    return speed_mps * memory_s


def window_speed(acc: np.ndarray, plane: "Plane") -> np.ndarray:
    """Each window's speed over ground (m/s) from its sums (:meth:`CurrentField.add`):
    the least-squares slope of its records' latitude and longitude against their time in
    the window; 0 for a window whose records share one time."""
    n = acc[:, 0]
    t_mean = acc[:, 12] / n
    var_t = acc[:, 13] / n - t_mean ** 2
    slope = (acc[:, 14:16] / n[:, None] - acc[:, 2:4] / n[:, None] * t_mean[:, None])
    with np.errstate(invalid="ignore", divide="ignore"):
        slope = np.where(var_t[:, None] > 1e-9, slope / var_t[:, None], 0.0)   # deg/s
    return np.hypot(np.radians(slope[:, 0]) * plane.m_per_rad_lat,
                    np.radians(slope[:, 1]) * plane.m_per_rad_lon)


class CurrentField:
    """The fleet's current field (module docstring): :meth:`add` observations in any
    order, :meth:`fit` (the super-observations, and the hyperparameters by marginal
    likelihood), :meth:`predict` at a place and time.

    Attributes:
        hyper: the hyperparameters (:class:`Hyper`).
        sigma_down: the down component's own spread (m/s), fitted on the
            super-observations that have a down (:func:`fit_sigma_down`).
        fitted: the field of the last fit (:class:`Fitted`: its super-observations,
            hyperparameters and mean; None before).
        added: observations added; rejected: observations and super-observations left
            out, by reason (:func:`observation`'s, ``outlier``, ``too_old``).
        log_likelihood: the marginal log-likelihood of the last hyperparameter fit.
        memory_s: how far back along its track a vehicle's estimate reaches (s;
            :data:`ESTIMATE_MEMORY_S`; 0: the water where the vehicle is).
        calibrate: whether the field's sigma is calibrated on the fleet's own data.
        sigma_calibration: the calibration of the predictive variance (north, east:
            :class:`SigmaCalibration`), learned with the hyperparameters and at the first
            fit (:func:`calibration`; none when not calibrated).
    """

    def __init__(self, hyper: Hyper = Hyper(), thin_s: float = THIN_S,
                 history_s: float = HISTORY_S, neighbours: int = NEIGHBOURS,
                 seed: int = 0, prior: Prior | None = PRIOR,
                 memory_s: float = ESTIMATE_MEMORY_S, calibrate: bool = True) -> None:
        self.hyper, self.thin_s, self.history_s = hyper, thin_s, history_s
        self.prior, self.memory_s, self.calibrate = prior, memory_s, calibrate
        self.sigma_down = SIGMA_DOWN
        self.neighbours = neighbours
        self.plane: Plane | None = None
        self.t_ref: float | None = None
        self.fitted: Fitted | None = None
        self.added = 0
        self.rejected: dict[str, int] = {}
        self.log_likelihood: float | None = None
        self.averaged = False
        """Whether the last fit of the hyperparameters found the fleet too sparse to fit
        and averaged the field over the prior instead; a refresh without a fit
        (``hyperparameters=False``) makes the same kind of field."""
        self.sigma_calibration = (SigmaCalibration(), SigmaCalibration())
        self.newest_utc = -math.inf
        self._bins: dict[tuple[str, int], list[float]] = {}
        self._vehicles: dict[str, int] = {}
        self._outliers: set[tuple[str, int]] = set()
        self._screened_keys: set[tuple[str, int]] = set()
        self._rng = np.random.default_rng(seed)

    # ------------------------------------------------------------------ observations
    def add(self, obs: Observation) -> bool:
        """Take one observation (late and out of order as well); False when it is older
        than the history kept (counted ``too_old``)."""
        if obs.utc < self.newest_utc - self.history_s:
            self.reject("too_old")
            return False
        if self.plane is None:
            self.plane, self.t_ref = Plane(obs.lat_deg, obs.lon_deg), obs.utc
        self.newest_utc = max(self.newest_utc, obs.utc)
        # within 180 deg of the plane's longitude: a window across the antimeridian
        # averages places a few metres apart, not 360 deg apart
        lon = obs.lon_deg + 360.0 * round((self.plane.lon0 - obs.lon_deg) / 360.0)
        key = (obs.vehicle, math.floor(obs.utc / self.thin_s))
        acc = self._bins.get(key)
        if acc is None:
            acc = self._bins[key] = [0.0] * 18
            self._vehicles.setdefault(obs.vehicle, len(self._vehicles))
        acc[0] += 1.0
        acc[1] += obs.utc
        acc[2] += obs.lat_deg
        acc[3] += lon
        if obs.north is not None:
            acc[16] += 1.0
            acc[4] += obs.north
            acc[6] += obs.std_north ** 2
        if obs.east is not None:
            acc[17] += 1.0
            acc[5] += obs.east
            acc[7] += obs.std_east ** 2
        if obs.down is not None and obs.std_down is not None:
            acc[8] += 1.0
            acc[9] += obs.down
            acc[10] += obs.std_down ** 2
        if obs.position_std_m is not None:
            acc[11] += obs.position_std_m ** 2
        u = obs.utc - key[1] * self.thin_s   # s into its window: the track's slope
        acc[12] += u
        acc[13] += u * u
        acc[14] += obs.lat_deg * u
        acc[15] += lon * u
        self.added += 1
        return True

    def add_record(self, rec: EstimateRecord) -> bool:
        """:meth:`add` the observation of a ``current`` record; False (the reason counted
        in :attr:`rejected`) when it makes none."""
        return not self.take(rec)

    def take(self, rec: EstimateRecord) -> str:
        """:meth:`add_record`, returning ``""`` when the record was added, else why not
        (the reason counted in :attr:`rejected`: :func:`observation`'s, ``too_old``)."""
        obs, why = observation(rec)
        if obs is None:
            self.reject(why)
            return why
        return "" if self.add(obs) else "too_old"

    def reject(self, why: str, n: int = 1) -> None:
        """Count ``n`` observations left out for ``why`` (:attr:`rejected`)."""
        self.rejected[why] = self.rejected.get(why, 0) + n

    # ------------------------------------------------------------------ fit
    def fit(self, hyperparameters: bool = True) -> None:
        """:meth:`gather` the super-observations and :meth:`update` the field with them."""
        self.update(self.gather(), hyperparameters)

    def gather(self) -> SuperObs | None:
        """The super-observations (outliers left out), after forgetting the windows beyond
        the history; None without any. The only step that reads what :meth:`add` writes
        (a service holds its lock for this alone)."""
        if self.plane is None:   # nothing added yet
            return None
        oldest = math.floor((self.newest_utc - self.history_s) / self.thin_s)
        for key in [k for k in self._bins if k[1] < oldest]:
            del self._bins[key]
            self._outliers.discard(key)
            self._screened_keys.discard(key)
        keys = [k for k in self._bins if k not in self._outliers]
        if not keys:
            return None
        acc = np.array([self._bins[k] for k in keys])
        n = acc[:, :1]
        mean = acc[:, 1:4] / n
        plane = self._plane_about(mean[:, 1], mean[:, 2])
        north, east = plane.to_ne(mean[:, 1], mean[:, 2])
        x = np.column_stack([north, east, mean[:, 0] - self.t_ref])
        n_horizontal, n_down = acc[:, 16:18], acc[:, 8:9]
        with np.errstate(invalid="ignore", divide="ignore"):   # NaN: none in the window
            n_each = np.tile(n_horizontal, 2)   # the values' and the variances' counts
            horizontal = np.where(n_each > 0, acc[:, 4:8] / n_each, np.nan)
            down = np.where(n_down > 0, acc[:, 9:11] / n_down, np.nan)
        y = np.column_stack([horizontal[:, :2], down[:, 0]])
        s = np.column_stack([np.sqrt(horizontal[:, 2:]), np.sqrt(down[:, 1])])
        place = np.hypot(np.sqrt(acc[:, 11] / n[:, 0]),
                         memory_place(window_speed(acc, plane), self.memory_s))
        return SuperObs(x, y, s, np.array([self._vehicles[k[0]] for k in keys]), mean[:, 0],
                        keys, place, plane)

    def _plane_about(self, lat_deg: np.ndarray, lon_deg: np.ndarray) -> Plane:
        """The plane the windows at ``lat_deg``, ``lon_deg`` are fitted on: the one in use,
        or one about their median place when that is more than :data:`PLANE_RECENTRE_M`
        from its origin (then :attr:`plane` from now on)."""
        lat, lon = float(np.median(lat_deg)), float(np.median(lon_deg))
        if math.hypot(*self.plane.to_ne(lat, lon)) > PLANE_RECENTRE_M:
            self.plane = Plane(lat, lon)
        return self.plane

    def update(self, obs: SuperObs | None, hyperparameters: bool = True) -> None:
        """Fit the hyperparameters to ``obs`` by marginal likelihood when asked and there
        are enough, leave the outliers out, and index the rest for :meth:`predict` (the
        field :meth:`predict` reads is replaced at once, when it is ready)."""
        if obs is None:
            self.fitted = None
            return
        with one_blas_thread():
            self._update(obs, hyperparameters)

    def _update(self, obs: SuperObs, hyperparameters: bool) -> None:
        mean = np.array([obs.y[np.isfinite(obs.y[:, c]), c].mean()
                         if np.isfinite(obs.y[:, c]).any() else 0.0 for c in (NORTH, EAST, DOWN)])
        has_down = np.isfinite(obs.y[:, DOWN])
        sparse = _vehicles(obs) < MIN_FIT_VEHICLES
        if hyperparameters and len(obs.y) >= MIN_FIT and not sparse:
            self.hyper, self.log_likelihood = fit_hyper(
                self.hyper, _fitting_sample(obs, self._rng), mean, self.prior)
        if hyperparameters and has_down.sum() >= MIN_FIT_DOWN and \
                _vehicles(obs.take(has_down)) >= MIN_FIT_VEHICLES:
            self.sigma_down = fit_sigma_down(
                self.hyper, _fitting_sample(obs.take(has_down), self._rng), mean[2],
                self.sigma_down)
        if hyperparameters:
            self.averaged = sparse and self.prior is not None
        averaged = self.averaged
        fitted = self._fitted(obs, mean, averaged)
        out = self._outliers_in(fitted)
        if out.size:
            keep = np.ones(len(obs.y), bool)
            keep[out] = False
            fitted = self._fitted(obs.take(keep), mean, averaged)
        if self.calibrate and (hyperparameters or self.fitted is None):
            self.sigma_calibration = calibration(fitted)   # learned with the hyperparameters
        self.fitted = fitted

    def _fitted(self, obs: SuperObs, mean: np.ndarray, averaged: bool
                ) -> "Fitted | Averaged":
        """The field of ``obs`` with the hyperparameters in hand, or (``averaged``) over
        the prior's :meth:`Prior.quadrature`."""
        if not averaged:
            return Fitted(obs, self.hyper, mean, self.neighbours, self.sigma_down)
        return Averaged([(w, Fitted(obs, h, mean, self.neighbours, self.sigma_down))
                         for w, h in self.prior.quadrature()])

    def _outliers_in(self, fitted: "Fitted") -> np.ndarray:
        """The super-observations of ``fitted`` further than :data:`OUTLIER_SIGMA`
        predictive sigmas from what the other vehicles say at their place, each window
        judged once, when its vehicle has moved on to the next, if within
        :data:`SCREEN_WITHIN_S` of the newest record (their indices; they are left out from
        now on, counted ``outlier``)."""
        obs = fitted.obs
        newest: dict[str, int] = {}
        for v, k in obs.keys:
            newest[v] = max(newest.get(v, k), k)
        recent = math.floor((self.newest_utc - SCREEN_WITHIN_S) / self.thin_s)
        out = []
        for i, key in enumerate(obs.keys):
            if recent <= key[1] < newest[key[0]] and key not in self._screened_keys:
                self._screened_keys.add(key)
                if fitted.is_outlier(i):
                    out.append(i)
                    self._outliers.add(key)
        if out:
            self.reject("outlier", len(out))
        return np.array(out, dtype=int)

    # ------------------------------------------------------------------ predict
    def learned(self) -> str:
        """What the last fit learned, in a few words: the length and time scales and how
        the sigma is calibrated per component (its factor and its floor); empty before
        the first fit."""
        if self.fitted is None:
            return ""
        h = self.fitted.hyper
        cal = ", ".join(f"x{math.sqrt(c.scale):.2f} + {100 * math.sqrt(c.floor):.1f} cm/s "
                        f"{name}" for name, c in zip(("north", "east"), self.sigma_calibration))
        return f"{h.length_m:.0f} m, {h.length_s / 60:.0f} min; sigma {cal}"

    def predict(self, lat_deg: float, lon_deg: float, utc: float) -> Prediction:
        """The field at ``lat_deg``, ``lon_deg`` (deg) and ``utc`` (POSIX s) as of the
        last :meth:`fit` (:data:`UNKNOWN` where no super-observation is near)."""
        fitted = self.fitted
        if fitted is None or self.plane is None:
            return UNKNOWN
        n, e = (fitted.obs.plane or self.plane).to_ne(lat_deg, lon_deg)
        p = fitted.predict(np.array([float(n), float(e), utc - self.t_ref]))
        if p.north is None:
            return p
        north, east = self.sigma_calibration
        return p._replace(std_north=north.std(p.std_north), std_east=east.std(p.std_east))


class SigmaCalibration(NamedTuple):
    """How one component's predictive variance is calibrated on the fleet's own misses
    (docs/algorithms.md §8.10): the published variance is ``scale v_f + floor``."""

    scale: float = 1.0   # k (with the windows' spread, :func:`noise_spread`), v_f's factor
    floor: float = 0.0   # b, (m/s)^2 added to it
    own: float = 1.0     # c, the windows' own variance's factor, from the crossings

    def std(self, std_f: float) -> float:
        """The published sigma (m/s) of a prediction whose process sigma is ``std_f``."""
        return math.sqrt(self.scale * std_f ** 2 + self.floor)


def calibration(fitted: "Fitted | Averaged") -> tuple[SigmaCalibration, SigmaCalibration]:
    """The calibration of the field's predictive variance (north, east) learned from the
    fleet's own data (docs/algorithms.md §8.10). At :data:`CALIBRATION_SAMPLE`
    super-observations spread evenly over the history, the field predicted from the other
    vehicles (``exclude``, as :meth:`Fitted.is_outlier` does) misses the window by ``r``,
    whose variance is the field's ``k g v_f + b`` (its predictive variance, scaled, and a
    floor) plus the window's own ``c v_o`` (its estimate's scaled sigma, the white error
    and its place term; ``c`` measured on the crossings, :func:`own_scale`; ``g`` what
    windows worse than the model says add to the field's variance, :func:`noise_spread`).
    ``k`` and ``b`` are the maximum-likelihood values within :data:`VARIANCE_SCALE_BOUNDS`
    and :data:`FLOOR_STD_BOUNDS`, and the published scale is ``k g``; none with fewer than
    :data:`CALIBRATION_MIN` predictions."""
    obs, h = fitted.obs, fitted.hyper
    central = fitted.central if isinstance(fitted, Averaged) else fitted
    pick = np.unique(np.linspace(0, len(obs.y) - 1, CALIBRATION_SAMPLE).astype(int))
    rows: list[tuple[float, float, float, float, float, float]] = []
    judged: list[tuple[int, np.ndarray]] = []
    for i in pick:
        others = central.neighbourhood(obs.x[i], exclude=int(obs.vehicle[i]))
        if len(set(obs.vehicle[others].tolist())) < JUDGES:
            continue   # one vehicle against another cannot tell which is wrong
        p = fitted.predict(obs.x[i], exclude=int(obs.vehicle[i]))
        if p.north is None:
            continue
        judged.append((int(i), others))
        rows.append((obs.y[i, NORTH] - p.north, p.std_north ** 2,
                     _own_variance(h, obs, i, NORTH),
                     obs.y[i, EAST] - p.east, p.std_east ** 2,
                     _own_variance(h, obs, i, EAST)))
    a = np.array(rows).reshape(-1, 6)
    out = []
    for c, part in ((NORTH, a[:, 0:3]), (EAST, a[:, 3:6])):
        given = np.isfinite(part[:, 0])   # a window without the component: NaN
        if given.sum() < CALIBRATION_MIN:
            out.append(SigmaCalibration())
            continue
        own = own_scale(central, [i for i, _ in judged], c)
        spread = noise_spread(central, [w for w, g in zip(judged, given) if g], c, own)
        r, v_f, v_o = part[given].T
        k, b = _ml_scale(r, spread * v_f, own * v_o)
        out.append(SigmaCalibration(k * spread, b, own))
    return out[0], out[1]


def noise_spread(fitted: "Fitted", judged: list[tuple[int, np.ndarray]], c: int,
                 own: float) -> float:
    """How much more the field's predictive variance of component ``c`` is when the
    windows' own covariance is ``own`` times the model's (``own`` > 1: windows worse than
    the model says; 1 otherwise, the variance never narrowed by it): the median, over the
    ``judged`` windows (index, the other vehicles' windows near it), of the variance
    kriged with that covariance over the variance kriged with the model's."""
    if own <= 1.0:
        return 1.0
    obs, h = fitted.obs, fitted.hyper
    sigma_f = h.spread(c)
    ratios = []
    for i, others in judged:
        idx = others[np.isfinite(obs.y[others, c])]
        if not idx.size:
            continue
        _, s1 = fitted.krige_component(obs.x[i], idx, c, sigma_f)
        _, s_own = fitted.krige_component(obs.x[i], idx, c, sigma_f, noise_scale=own)
        if s1 > 0.0:
            ratios.append((s_own / s1) ** 2)
    return float(np.median(ratios)) if ratios else own


def own_scale(fitted: "Fitted", windows: list[int], c: int) -> float:
    """How far the windows' own variance ``v_o`` of component ``c`` is to be taken (the
    ``c`` of docs/algorithms.md §8.10), measured on the crossings of ``windows`` with the
    other vehicles' windows (:data:`CROSSING_RADIUS`): the difference of two windows at
    nearly one place and time is their two errors, of variance ``c (v_o,i + v_o,j)``,
    plus the little the water differs between them, ``2 sigma_c^2 (1 - rho_ij)``. The
    maximum-likelihood ``c`` within :data:`OWN_SCALE_BOUNDS`; 1 with fewer than
    :data:`CALIBRATION_MIN` crossings."""
    from scipy.optimize import minimize_scalar

    obs, h = fitted.obs, fitted.hyper
    sigma_f = h.spread(c)
    d2, v_o, v_w = [], [], []
    for i in windows:
        if not np.isfinite(obs.y[i, c]):
            continue
        near = np.array([j for j in fitted.tree.query_ball_point(obs.x[i] / fitted.scale,
                                                                CROSSING_RADIUS)
                         if obs.vehicle[j] != obs.vehicle[i] and np.isfinite(obs.y[j, c])],
                        dtype=int)
        if not near.size:
            continue
        own_i = _own_variance(h, obs, i, c)
        d2.extend((obs.y[i, c] - obs.y[near, c]) ** 2)
        v_o.extend(own_i + _own_variance(h, obs, j, c) for j in near)
        v_w.extend(2.0 * sigma_f ** 2 * (1.0 - signal_corr(h, obs.x[[i]], obs.x[near])[0]))
    if len(d2) < CALIBRATION_MIN:
        return 1.0
    d2a, v_oa, v_wa = np.array(d2), np.array(v_o), np.array(v_w)

    def nll(log_c: float) -> float:
        v = math.exp(log_c) * v_oa + v_wa
        return float(np.sum(np.log(v) + d2a / v))

    lo, hi = np.log(OWN_SCALE_BOUNDS)
    return math.exp(minimize_scalar(nll, bounds=(lo, hi), method="bounded").x)


def _ml_scale(r: np.ndarray, v_f: np.ndarray, v_o: np.ndarray) -> tuple[float, float]:
    """The ``k`` within :data:`VARIANCE_SCALE_BOUNDS` and the ``b`` within
    :data:`FLOOR_STD_BOUNDS` (squared) that maximize the likelihood of the misses ``r``,
    normal of variance ``k v_f + b + v_o``."""
    from scipy.optimize import minimize

    def nll(theta: np.ndarray) -> float:
        v = math.exp(theta[0]) * v_f + math.exp(2.0 * theta[1]) + v_o
        return float(np.sum(np.log(v) + r * r / v))

    bounds = [tuple(np.log(VARIANCE_SCALE_BOUNDS)), tuple(np.log(FLOOR_STD_BOUNDS))]
    start = np.array([bounds[0][0], math.log(FLOOR_STD_START)])
    res = minimize(nll, start, bounds=bounds, method="L-BFGS-B")
    k, floor_std = np.exp(res.x)
    return float(k), float(floor_std) ** 2


def _own_variance(h: Hyper, obs: SuperObs, i: int, c: int) -> float:
    """The variance of super-observation ``i``'s component ``c`` about the water at its
    place (its estimate's sigma scaled, the white error, its place term)."""
    sigma_f = h.spread(c)
    return (h.scale * obs.s[i, c]) ** 2 + h.white ** 2 + \
        float(place_variance(sigma_f, h.length_m, obs.place[i]))


class Fitted:
    """The field as one :meth:`CurrentField.update` left it, never changed afterwards (a
    query reads it while the next is fitted): the super-observations, the
    hyperparameters, the mean (north, east, down), the down component's spread and the
    k-d trees of the scaled coordinates (all super-observations; those with a down)."""

    def __init__(self, obs: SuperObs, hyper: Hyper, mean: np.ndarray,
                 neighbours: int = NEIGHBOURS, sigma_down: float = SIGMA_DOWN) -> None:
        from scipy.spatial import cKDTree

        self.obs, self.hyper, self.mean, self.neighbours = obs, hyper, mean, neighbours
        self.sigma_down = sigma_down
        self.scale = np.array([hyper.length_m, hyper.length_m, hyper.length_s])
        self.tree = cKDTree(obs.x / self.scale)
        self.down_rows = np.flatnonzero(np.isfinite(obs.y[:, 2]))
        self.down_tree = cKDTree(obs.x[self.down_rows] / self.scale) \
            if self.down_rows.size else None

    def predict(self, x: np.ndarray, exclude: int = -1) -> Prediction:
        """The field at plane coordinates ``x`` (north m, east m, time s less ``t_ref``),
        leaving out the super-observations of vehicle ``exclude``."""
        idx = self.neighbourhood(x, exclude)
        if not idx.size:
            return UNKNOWN
        p = self.krige(x, idx)
        idx_down = self.neighbourhood(x, exclude, down=True)
        if p.north is None or not idx_down.size:
            return p
        down, std_down = self.krige_component(x, idx_down, DOWN, self.sigma_down)
        return p._replace(down=down, std_down=std_down)

    def neighbourhood(self, x: np.ndarray, exclude: int = -1, down: bool = False
                      ) -> np.ndarray:
        """The indices of the super-observations a prediction at ``x`` uses: the
        ``neighbours`` nearest in scaled distance within :data:`KNOWN_WITHIN`, none of
        vehicle ``exclude``; with ``down`` only those that have a down."""
        tree, rows = (self.down_tree, self.down_rows) if down else (self.tree, None)
        if tree is None:
            return np.zeros(0, dtype=int)
        n = tree.n
        k = min(self.neighbours * (2 if exclude >= 0 else 1), n)
        dist, idx = tree.query(x / self.scale, k=k, distance_upper_bound=KNOWN_WITHIN)
        idx = np.atleast_1d(idx)[np.isfinite(np.atleast_1d(dist))]
        if rows is not None:
            idx = rows[idx]
        if exclude >= 0:
            idx = idx[self.obs.vehicle[idx] != exclude][:self.neighbours]
        return idx

    def krige(self, x: np.ndarray, idx: np.ndarray) -> Prediction:
        """The Gaussian-process mean and sigma of north and east at ``x`` from the
        super-observations ``idx`` (module docstring), per component from those that give
        it (:data:`UNKNOWN` where one has none)."""
        h, xs = self.hyper, self.obs.x[idx]
        corr = (signal_corr(h, xs, xs), signal_corr(h, x[None, :], xs)[0])
        parts = []
        for c, sigma_f in ((NORTH, h.sigma_north), (EAST, h.sigma_east)):
            gives = np.isfinite(self.obs.y[idx, c])
            if not gives.any():
                return UNKNOWN
            own = corr if gives.all() else (corr[0][np.ix_(gives, gives)], corr[1][gives])
            parts.append(self.krige_component(x, idx[gives], c, sigma_f, own))
        (n, s_n), (e, s_e) = parts
        return Prediction(n, e, s_n, s_e, int(idx.size))

    def krige_component(self, x: np.ndarray, idx: np.ndarray, c: int, sigma_f: float,
                        corr: tuple[np.ndarray, np.ndarray] | None = None,
                        noise_scale: float = 1.0) -> tuple[float, float]:
        """Component ``c`` (:data:`NORTH`, :data:`EAST`, :data:`DOWN`) of spread
        ``sigma_f`` at ``x`` from the super-observations ``idx``: its mean and sigma
        (down's mean unknown: :func:`gls_mean`); ``corr``: the signal correlations among
        them and with ``x`` when already computed; ``noise_scale``: the windows' own
        covariance scaled (:func:`calibration`)."""
        from scipy.linalg import cho_factor, cho_solve

        obs, h = self.obs, self.hyper
        if c == DOWN:   # one vehicle's down is checked against no other's: never narrowed
            h = h._replace(scale=max(h.scale, 1.0))
        xs = obs.x[idx]
        if corr is None:
            corr = (signal_corr(h, xs, xs), signal_corr(h, x[None, :], xs)[0])
        kc, ks = sigma_f ** 2 * corr[0], sigma_f ** 2 * corr[1]
        ke = error_cov(h, xs[:, 2], obs.vehicle[idx], obs.s[idx, c]) + \
            np.diag(place_variance(sigma_f, h.length_m, obs.place[idx]))
        factor = cho_factor(kc + noise_scale * ke, lower=True)
        y, mean, var_mean = obs.y[idx, c], self.mean[c], 0.0
        if c == DOWN:
            mean, var_mean = gls_mean(factor, ks, y)
            var_mean += down_bias_variance(h, obs.s[idx, c])
        alpha = cho_solve(factor, y - mean)
        var = max(sigma_f ** 2 - float(ks @ cho_solve(factor, ks)), 0.0) + var_mean
        return float(mean + ks @ alpha), math.sqrt(var)

    def is_outlier(self, i: int) -> bool:
        """Whether super-observation ``i`` is further than :data:`OUTLIER_SIGMA` sigmas
        (the prediction's and its own) from the other vehicles' field at its place; a
        place fewer than :data:`JUDGES` other vehicles saw has no outliers (one vehicle
        against another cannot tell which is wrong)."""
        obs, h = self.obs, self.hyper
        idx = self.neighbourhood(obs.x[i], exclude=obs.vehicle[i])
        if len(set(obs.vehicle[idx].tolist())) < JUDGES:
            return False
        p = self.krige(obs.x[i], idx)
        if p.north is None:
            return False
        for c, m, sd in ((NORTH, p.north, p.std_north), (EAST, p.east, p.std_east)):
            if not np.isfinite(obs.y[i, c]):
                continue
            var = sd ** 2 + _own_variance(h, obs, i, c)
            if abs(obs.y[i, c] - m) > OUTLIER_SIGMA * math.sqrt(var):
                return True
        return False


class Averaged:
    """The field averaged over hyperparameters the fleet cannot fit (docs/algorithms.md
    §8.3): a weighted mixture of :class:`Fitted` fields, one per hyperparameter value.
    A member that knows nothing at a place gives its prior there (the mean, ``sigma_c``);
    the mixture knows nothing where no member knows anything. Its mean is the weighted
    mean of the members', its variance theirs plus the spread of their means (the law
    of total variance). Outliers are judged by the heaviest member."""

    def __init__(self, members: list[tuple[float, Fitted]]) -> None:
        self.members = members
        self.central = max(members, key=lambda m: m[0])[1]
        self.obs, self.hyper, self.mean = self.central.obs, self.central.hyper, self.central.mean
        self.down_rows = self.central.down_rows

    def predict(self, x: np.ndarray, exclude: int = -1) -> Prediction:
        """The mixture's prediction at ``x`` (:meth:`Fitted.predict`'s arguments)."""
        preds = [(w, f, f.predict(x, exclude)) for w, f in self.members]
        if all(p.north is None for _, _, p in preds):
            return UNKNOWN
        parts = [mixture([(w, *_or_prior(p, f, c)) for w, f, p in preds])
                 for c in (NORTH, EAST)]
        down = [(w, p.down, p.std_down) for w, _, p in preds if p.down is not None]
        d = mixture(down) if down else (None, None)
        return Prediction(parts[0][0], parts[1][0], parts[0][1], parts[1][1],
                          max(p.n_obs for _, _, p in preds), *d)

    def is_outlier(self, i: int) -> bool:
        """:meth:`Fitted.is_outlier` of the heaviest member."""
        return self.central.is_outlier(i)


def _or_prior(p: Prediction, f: Fitted, c: int) -> tuple[float, float]:
    """Component ``c`` (:data:`NORTH`, :data:`EAST`) of ``p``: its mean and sigma, or
    where ``f`` knows nothing its prior, the mean and spread ``sigma_c``."""
    if p.north is None:
        return float(f.mean[c]), (f.hyper.sigma_north, f.hyper.sigma_east)[c]
    return (p.north, p.std_north) if c == NORTH else (p.east, p.std_east)


def mixture(parts: list[tuple[float, float, float]]) -> tuple[float, float]:
    """The mean and sigma of a mixture of normals given as (weight, mean, sigma): the
    weighted mean, and the square root of the weighted mean variance plus the weighted
    spread of the means (weights normalized)."""
    w = np.array([p[0] for p in parts])
    m = np.array([p[1] for p in parts])
    sd = np.array([p[2] for p in parts])
    w = w / w.sum()
    mean = float(w @ m)
    return mean, math.sqrt(float(w @ (sd ** 2 + (m - mean) ** 2)))


def gls_mean(factor, ks: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """The constant mean of ``y`` unknown (a vague prior): its generalized-least-squares
    estimate ``beta = 1' K^-1 y / 1' K^-1 1`` from the neighbourhood (``factor``: the
    Cholesky factor of ``K``) and the variance its uncertainty adds to a prediction with
    signal covariance ``ks``, ``(1 - 1' K^-1 ks)^2 / 1' K^-1 1`` (Rasmussen and Williams
    2006, eq. 2.42): a component few vehicles give (down, often from one vehicle) cannot
    take its mean as known."""
    from scipy.linalg import cho_solve

    k1 = cho_solve(factor, np.ones(len(y)))
    w = float(k1.sum())
    return float(k1 @ y) / w, (1.0 - float(ks @ k1)) ** 2 / w


def one_blas_thread():
    """A context in which BLAS runs on one thread (threadpoolctl, the ``fleet`` extra): a
    64 x 64 or 240 x 240 Cholesky gains nothing from more, and on a busy machine the
    threads spin on each other's cores (a 64 x 64 Cholesky took 9 ms instead of 0.1 ms,
    measured under a load of 20); a no-op without threadpoolctl. Also the limit itself:
    ``one_blas_thread()`` keeps it for as long as the returned object lives."""
    import scipy.linalg  # noqa: F401 - its own BLAS must be loaded to be limited

    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        import contextlib

        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def _vehicles(obs: SuperObs) -> int:
    """How many vehicles ``obs`` come from."""
    return len(np.unique(obs.vehicle))


def _fitting_sample(obs: SuperObs, rng: np.random.Generator) -> SuperObs:
    """At most :data:`FIT_MAX` super-observations: runs of :data:`FIT_RUN` consecutive
    ones of one vehicle from random starts (all of them when they are few)."""
    n = len(obs.y)
    if n <= FIT_MAX:
        return obs
    order = np.lexsort((obs.x[:, 2], obs.vehicle))   # by vehicle, then time
    starts = rng.choice(n, size=FIT_MAX // FIT_RUN, replace=False)
    pos = (starts[:, None] + np.arange(FIT_RUN)[None, :]).ravel()
    return obs.take(np.unique(order[pos[pos < n]]))


def log_likelihood(theta: np.ndarray, obs: SuperObs, mean: np.ndarray,
                   placed: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """The negative marginal log-likelihood of ``obs`` (both components) at
    ``theta`` (the logarithms of :class:`Hyper`'s fields) and its gradient in ``theta``
    (Rasmussen and Williams 2006, eq. 5.9: ``1/2 tr((alpha alpha' - K^-1) dK)``);
    ``placed`` (n, 2): each observation's :func:`place_variance` per component, held
    fixed (None: none)."""
    from scipy.linalg import cho_factor, cho_solve

    h = Hyper(*np.exp(theta))
    x = obs.x
    d2s = ((x[:, None, :2] - x[None, :, :2]) ** 2).sum(-1) / h.length_m ** 2
    d2t = (x[:, None, 2] - x[None, :, 2]) ** 2 / h.length_s ** 2
    corr = np.exp(-0.5 * (d2s + d2t))
    dt = np.abs(x[:, None, 2] - x[None, :, 2])
    same = (obs.vehicle[:, None] == obs.vehicle[None, :]) * np.exp(-dt / h.tau_s)
    nll, grad = 0.0, np.zeros(7)
    for c, sigma_f in enumerate((h.sigma_north, h.sigma_east)):
        m = np.isfinite(obs.y[:, c])   # the windows that give the component
        if not m.any():
            continue
        sub = np.ix_(m, m)
        n_c, eye = int(m.sum()), np.eye(int(m.sum()))
        kc = sigma_f ** 2 * corr[sub]
        ve = np.outer(obs.s[m, c], obs.s[m, c]) * same[sub] * h.scale ** 2
        k = kc + ve + h.white ** 2 * eye
        if placed is not None:
            k = k + np.diag(placed[m, c])
        try:
            factor = cho_factor(k, lower=True)
        except np.linalg.LinAlgError:
            return 1e10, np.zeros(7)
        r = obs.y[m, c] - mean[c]
        alpha = cho_solve(factor, r)
        nll += 0.5 * r @ alpha + np.log(np.diag(factor[0])).sum() + \
            0.5 * n_c * math.log(2 * math.pi)
        w = cho_solve(factor, eye) - np.outer(alpha, alpha)
        dks = (2.0 * kc, kc * d2s[sub], kc * d2t[sub], 2.0 * ve, ve * dt[sub] / h.tau_s,
               2.0 * h.white ** 2 * eye)
        g = [(w * dk).sum() for dk in dks]
        grad += 0.5 * np.array([g[0] * (c == 0), g[0] * (c == 1), *g[1:]])
    return float(nll), grad


def log_posterior(theta: np.ndarray, obs: SuperObs, mean: np.ndarray,
                  placed: np.ndarray | None, prior: Prior) -> tuple[float, np.ndarray]:
    """The negative log-posterior of ``theta`` (up to a constant): :func:`log_likelihood`'s
    negative marginal log-likelihood plus ``prior``'s :meth:`Prior.penalty`, and its
    gradient."""
    nll, grad = log_likelihood(theta, obs, mean, placed)
    pen, dpen = prior.penalty(theta)
    return nll + pen, grad + dpen


def fit_hyper(start: Hyper, obs: SuperObs, mean: np.ndarray,
              prior: Prior | None = None) -> tuple[Hyper, float]:
    """The hyperparameters that maximize the marginal likelihood of ``obs`` (with
    ``prior``: its posterior, the maximum a posteriori), from ``start`` (scipy's
    L-BFGS-B in the logarithms, within :meth:`Hyper.bounds`), and the log-likelihood (or
    log-posterior) reached; ``start`` kept when the fit fails. The variance a window's
    position sigma adds (:func:`place_variance`) is computed at ``start`` and held fixed
    through the fit (the next fit, a minute later, starts from this one's result)."""
    from scipy.optimize import minimize

    bounds = [(math.log(lo), math.log(hi)) for lo, hi in Hyper.bounds()]
    theta0 = np.clip(np.log(np.array(start)), [b[0] for b in bounds], [b[1] for b in bounds])
    placed = None
    if np.any(obs.place > 0):
        placed = np.column_stack([place_variance(sf, start.length_m, obs.place)
                                  for sf in (start.sigma_north, start.sigma_east)])
    objective, args = (log_likelihood, (obs, mean, placed)) if prior is None else \
        (log_posterior, (obs, mean, placed, prior))
    res = minimize(objective, theta0, args=args, jac=True,
                   method="L-BFGS-B", bounds=bounds, options={"maxiter": 50})
    if not np.all(np.isfinite(res.x)) or res.fun >= 1e10:
        return start, float("nan")
    return Hyper(*map(float, np.exp(res.x))), -float(res.fun)


def down_nll(log_sigma: float, h: Hyper, obs: SuperObs, mean_down: float) -> float:
    """The negative marginal log-likelihood of the down component of ``obs`` (all with a
    down) with spread ``exp(log_sigma)`` (m/s) and the rest of ``h``."""
    from scipy.linalg import cho_factor, cho_solve

    sigma_f = math.exp(log_sigma)
    k = sigma_f ** 2 * signal_corr(h, obs.x, obs.x) + \
        error_cov(h, obs.x[:, 2], obs.vehicle, obs.s[:, DOWN]) + \
        np.diag(place_variance(sigma_f, h.length_m, obs.place))
    try:
        factor = cho_factor(k, lower=True)
    except np.linalg.LinAlgError:
        return 1e10
    r = obs.y[:, DOWN] - mean_down
    return float(0.5 * r @ cho_solve(factor, r) + np.log(np.diag(factor[0])).sum())


def fit_sigma_down(h: Hyper, obs: SuperObs, mean_down: float, start: float) -> float:
    """The down component's spread (m/s) that maximizes the marginal likelihood of the
    super-observations ``obs`` that have a down, the length and time scales and the error
    model being ``h``'s (fitted on north and east, which every vehicle gives); bounded by
    :data:`SIGMA_DOWN_BOUNDS`; ``start`` kept when the fit fails."""
    from scipy.optimize import minimize_scalar

    lo, hi = (math.log(b) for b in SIGMA_DOWN_BOUNDS)
    res = minimize_scalar(down_nll, bounds=(lo, hi), args=(h, obs, mean_down),
                          method="bounded", options={"xatol": 0.01})
    if not res.success or not math.isfinite(res.x) or res.fun >= 1e10:
        return start
    return float(math.exp(res.x))
