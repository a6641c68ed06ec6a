"""Integrity monitoring: each estimate checked against an independent measurement.

The pipelines fuse what they are given; nothing inside a filter can see that a sensor is
misaligned or that its own covariance has stopped meaning anything. This module watches
from beside the engine, fed at every tick with the samples handed to the pipelines, the
published records and the innovation records, and runs these checks:

* **heading against course over ground** (:class:`HeadingCourseCheck`): while the vehicle
  moves (GNSS speed above :data:`HEADING_MIN_SPEED_MPS`), the circular mean of
  ``heading - course`` over :data:`HEADING_WINDOW_S` must stay within
  :func:`crab_bound` (for fixes that carry no course, the course of their track:
  :class:`onboard.monitor.track_course.TrackCourse`). Beyond it
  ``heading_course_mismatch`` is raised naming the angle, and
  the estimates that turn a velocity with the heading (each pipeline's
  ``heading_dependent`` outputs: the ``current`` pipeline's current and through-water
  velocity) are published as unknown while it lasts. Courses behind the heading (beyond
  :data:`HEADING_GROSS_RAD` at more than :data:`HEADING_GROSS_MIN_SPEED_MPS`) are judged
  early, from two fixes in a row over :data:`HEADING_GROSS_RUN_S`, and withhold the path
  speeds signed along that heading, from the first such fix. Vehicles that move sideways
  by design (:attr:`onboard.core.vehicles.VehicleTraits.holonomic`) are not checked.
* **position against GNSS** (:class:`PositionCheck`): at the first tick after each fix,
  each pipeline's published ``position`` against the fix (in the frame about the first
  fix, as documented; a pipeline with a ``frame_offset``, the ESESO, in its own frame),
  normalized by the published one-sigma and the fix's own; ``position_residual`` when more than
  :data:`POSITION_FRACTION` of the comparisons of the last :data:`POSITION_WINDOW_S` are
  beyond :data:`POSITION_SIGMA_BOUND`. The pipeline is flagged, its values kept.
* **NIS against its chi-square band** (:class:`NisCheck`): per channel the mean NIS of
  each block of :data:`NIS_BLOCK_UPDATES` accepted updates against the :data:`NIS_BAND`
  band of such a mean for a consistent filter, ``chi2(dof n) / n``, with ``n`` the
  block's effective number of independent updates from the measured lag-1
  autocorrelation of its NIS (:func:`effective_count`; 100 for white innovations), never
  narrower than the NIS of sigmas within the 1-sigma coverage target
  (:data:`NIS_COVERAGE_TARGET`);
  ``nis_out_of_band`` after :data:`NIS_SUSTAIN_BLOCKS` blocks in a row outside it on the
  same side (too large: sigmas too small; too small: sigmas too large); below the band,
  not judged within :data:`NIS_SETTLE_S` of the channel's filter's start or restart (a
  filter converging from a wide prior; above it is judged from the start), nor while the
  published sigma of what the channel measures is held up by errors slower than its
  innovations show (``ChannelNoise.slow_error_holds``: the current's block-mean NIS above
  the factor its velocity rows' innovations give, algorithms.md §9.1). A channel whose
  pipeline learns its measurement noise (the pipeline's ``noise``,
  :class:`onboard.estimators.noise_learning.ChannelNoise`) is judged only once the noise
  is learned (or has given no sample in a full window of updates: nothing to learn from),
  and from then on: the blocks judged before are dropped. An NIS out of band first drives
  the adaptation, and the warning says what is still inconsistent after it (the learned
  noise at its bound: the configuration key to change and the learned value, a limit; a noise learned below the declared that the update
  does not take, the same; else the process-noise key the pipeline names for the
  channel's forecast, ``forecast_noise``, with the value that brings the NIS to 1 from
  its mean and the forecast's share of ``S``). A channel whose factor a
  published sigma takes (``ChannelNoise.published_factor``, algorithms.md §9.1) is judged
  against that sigma: its NIS over the factor. The pipeline is flagged. Below its band
  on one of the pipeline's ``unpublished_channels`` (a forecast of what it publishes
  without a sigma, algorithms.md §9.2) the NIS is information, ``nis_unpublished`` once
  per channel, not flagged; on one of its ``calibrating_channels`` (whose innovations
  correct the published sigma both ways, the filter's gain keeping its tuning) the same,
  ``nis_corrected``; on one of its ``regression_channels`` (a regression's residual, whose
  ``S`` no gain uses) ``nis_unpublished`` on either side.
* **position consistency** (:class:`PositionNeesCheck`): where a fix is better than the
  estimate (the published variance :data:`POSITION_NEES_FIX_RATIO` times the fix's), the NEES of the published position
  against it, ``d^T (P + R_fix)^-1 d`` (2 dof), by blocks as the NIS;
  ``position_inconsistent`` when it stays outside its band.
* **speed against Doppler or DVL** (:class:`SpeedCheck`): at the first tick after each
  GNSS fix with a speed over ground, or each valid DVL bottom-track report, each
  pipeline's published ``speed`` against it: its horizontal speed (the magnitude of its
  forward speed and, where it declares one, its sideways speed: ``aie``/``kf`` the path
  speed over ground, no current enters it; ``eseso`` ``hypot(u, v)``) against the Doppler
  speed over ground, its signed forward speed against the DVL's forward ``vx``. Normalized
  by the published one-sigma and the measurement's own; ``speed_mismatch`` when more than
  :data:`SPEED_FRACTION` of the comparisons of the last :data:`SPEED_WINDOW_S` are beyond
  :data:`SPEED_SIGMA_BOUND` and :data:`SPEED_FLOOR_MPS`, or at once when the same holds
  over the last :data:`SPEED_GROSS_WINDOW_S` with an RMS normalized residual beyond
  :data:`SPEED_GROSS_RMS_SIGMA` (a gross miss). The pipeline is flagged, its speed
  withheld while it lasts.

Issue 32 adds, each its own class (docs/integrity.md, "Heading honesty", "Current
honesty"):

* **compass deviation** (:class:`CompassDeviationCheck`): a heading-dependent compass
  error learned against the course over ground on straight legs, beside the current's
  crab; while significant, each published heading's sigma is widened by the deviation at
  that heading when the deviation exceeds it (``compass_deviation`` on the pipeline:
  :meth:`IntegrityMonitor.amend`), and the heading-dependent outputs are withheld when
  it exceeds :data:`DEVIATION_MIN_RAD`. Under ``heading_course_mismatch`` the aie/kf
  heading and positions (``heading_estimate``, ``position``) are withheld too, and the
  warning quotes the worst window's angle beside the fastest's.
* **heading against the navigation solution's own** (:class:`HeadingSourceCheck`): the
  selected heading against the heading of the solution that gives the velocity over
  ground (``VelocityOverGround.heading_rad``, a DVL-aided INS's), interpolated to its
  time, averaged over :data:`HEADING_WINDOW_S`; beyond :data:`HEADING_SOURCE_BOUND_RAD`
  ``heading_source_mismatch`` withholds the aie/kf heading and positions; below it the
  heading sigma is widened to the offset where it exceeds it (:meth:`IntegrityMonitor.amend`).
* **idle drift** (:class:`IdleDriftCheck`): with every thruster idle, the published
  current (``current_estimate``) against the slope of the fixes; ``current_idle_drift``
  withholds it while they disagree.
* **current resolution** (:class:`onboard.monitor.current_resolution.CurrentResolution`):
  per component, the published current's RMS over a window against its RMS one-sigma;
  ``current_unresolved`` withholds a component inside its own one-sigma of zero (an
  estimate then worse than zero) where that one-sigma is material.
* **run mean NIS** (:class:`NisRunMean`): ``nis_far_above`` when a channel's mean NIS
  over the run exceeds :data:`NIS_FAR_FACTOR` per degree of freedom.
* **divergence storms** (:class:`DivergenceCheck`): ``input_model_divergence`` when an
  input model restarts :data:`DIVERGENCE_STORM` times or more in
  :data:`DIVERGENCE_WINDOW_S`.

Why withhold rather than inflate the current's sigma under a heading mismatch: a heading
offset ``d`` at speed ``s`` adds a bias of ``2 s sin(d/2)`` to the current (1.8 m/s for
the Shenzhen log's 73.5 deg at 1.8 m/s), not noise; a wider sigma around that mean would
still publish the wrong number as the best guess, and the pipeline already publishes a
component it cannot determine as absent (``[pipelines.current] unknown_above_std_mps``),
which every consumer handles. The flag, the count ``pipeline:<name>:flagged`` and the
warning say why.

Which outputs are a position, a speed or heading-dependent, and in which frame, each
pipeline declares (its roles, :class:`Declared`; ``onboard.pipelines.base.Pipeline``):
the monitor reads the declarations of the pipelines it watches (:meth:`IntegrityMonitor.watch`),
never their names.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from itertools import islice
from typing import Iterable, Mapping, Protocol, Sequence

from onboard.monitor.alerts import Alerts
from onboard.monitor.compass_deviation import CompassDeviation
from onboard.monitor.current_resolution import (RESOLVE_MIN_STD_MPS, RESOLVE_WINDOW_S,
                                                CurrentResolution)
from onboard.monitor.track_course import TrackCourse
from onboard.core.geo import LocalFrame, circular_stats, wrap_pi
from onboard.core.stats import chi2_mean_band
from onboard.core.messages import (
    ActuatorCommand,
    Attitude,
    DvlVelocity,
    GnssFix,
    Heading,
    Innovation,
    Sample,
    VelocityOverGround,
)

HEADING_MIN_SPEED_MPS = 0.5
"""Below this GNSS speed (m/s) the course over ground is too noisy to check a heading."""
HEADING_WINDOW_S = 10.0
"""The heading/course difference is averaged (circular mean) over this long (s): a turn's
lag between heading and course averages out, a fixed offset does not."""
HEADING_MIN_FIXES = 5
"""Moving fixes needed in a window before it is judged."""
HEADING_FRESH_S = 1.0
"""A heading older than this (s) at a fix is not compared with its course."""
HEADING_SOURCE_BOUND_RAD = math.radians(2.0)
"""The least mean difference (rad) between the heading the pipelines use and the heading
of the navigation solution that resolved the velocity over ground (a DVL-aided INS's, in
GLOBAL_POSITION_INT's ``hdg``) that is a mismatch: two headings of one vehicle 2 deg apart
on average over :data:`HEADING_WINDOW_S` put one of them at least 1 deg off, more than a
calibrated compass's error (one autopilot's EKF gives both: 0.02 deg apart at most on the
ArduSub log of ../shared/data)."""
HEADING_SOURCE_WIDEN_MIN_RAD = math.radians(0.1)
"""A mean offset between the two headings below this (rad) widens nothing: their
resolution (GLOBAL_POSITION_INT's ``hdg`` is in 0.01 deg) and interpolation, not an
error; the records are then not amended for it."""
HEADING_BOUND_RAD = math.radians(25.0)
"""The least heading/course difference (rad) that is a mismatch: a boat's crab angle in a
turn or a cross wind is a few degrees."""
PLAUSIBLE_CURRENT_MPS = 0.5
"""A current this strong (m/s) across the track makes a crab angle of ``asin(c / sog)``
at speed over ground ``sog``: the bound widens with it at low speed."""
HEADING_GROSS_RAD = math.radians(90.0)
"""A heading/course difference beyond this (rad) at :data:`HEADING_GROSS_MIN_SPEED_MPS`
is judged before the window has filled: the vehicle would be going backwards through the
water, or its heading is wrong."""
HEADING_GROSS_MIN_SPEED_MPS = 2.0 * PLAUSIBLE_CURRENT_MPS
"""Mean speed over ground (m/s) of a window judged early: with a current of at most
:data:`PLAUSIBLE_CURRENT_MPS` the course is then within 30 deg of the velocity through
the water."""
HEADING_GROSS_MIN_S = 3.0
"""The least span (s) of moving fixes of a window judged early."""
HEADING_GROSS_RUN_S = 1.0
"""The newest fixes of a window, at least two spanning this long (s), each with its
course beyond :data:`HEADING_GROSS_RAD` off the heading at more than
:data:`HEADING_GROSS_MIN_SPEED_MPS`, judge the heading behind at once: for a heading
within its sigma of the water's direction (a crab of at most 30 deg at that speed) each
such fix is a miss of 60 deg or more, beyond 3 sigma of a compass as loud as 20 deg, and
two of them in a row rarer than one in 10^5."""

HEADING_OFFSET_HINT = ("a constant offset is measured by onboard diagnose LOG --write-config "
                       "FILE ([corrections] heading_offset_rad)")
"""How ``heading_course_mismatch`` ends: where the offset is measured. ``onboard
diagnose`` replaces it in its own output with what its diagnosis found."""

LEG_S = 5.0
"""A straight leg of the compass-deviation fit lasts this long (s)."""
LEG_GAP_S = 2.0
"""A gap between moving fixes longer than this (s) ends the leg being gathered."""
LEG_STRAIGHT_RAD = math.radians(5.0)
"""Largest circular standard deviation (rad) of a straight leg's headings and courses."""
DEVIATION_WALD = 18.47
"""The compass deviation is significant when the Wald statistic of its four harmonic
terms exceeds this: the chi-square(4) 0.999 quantile."""
DEVIATION_MIN_RAD = math.radians(2.0)
"""A significant deviation this large (rad, RMS over a turn) withholds the heading-
dependent outputs (the current): at 1.5 m/s it puts ``2 s sin(d / 2)`` = 0.05 m/s into
the current, the size of its sigma."""

IDLE_COMMAND = 0.05
"""A normalized thruster command within this of zero pushes nothing (an ESC's
deadband)."""
IDLE_SETTLE_S = 10.0
"""After this long (s) of idle commands a small vehicle moves with the water (a boat's
surge time constant is a few seconds)."""
IDLE_WINDOW_S = 30.0
"""The idle drift is fitted over at most the last this long (s)."""
IDLE_MIN_SPAN_S = 5.0
"""Least span (s) of idle fixes that measures a drift."""
IDLE_GAP_S = 2.0
"""A gap in the fixes longer than this (s) restarts the idle span (a new run)."""
IDLE_DRIFT_BOUND = 3.44
"""Mahalanobis distance (2 dof) of current minus drift beyond which the current fails:
the chi-square(2) 0.9973 quantile's square root (a 3-sigma event)."""

NIS_FAR_FACTOR = 10.0
"""A channel whose mean NIS over the run exceeds this many times its degrees of freedom
is far above any band: ``nis_far_above`` names it (a consistent filter's is 1 per dof;
the block check's band tops out near 1.5-5 per dof)."""
NIS_FAR_MIN_UPDATES = 500
"""Accepted updates of a channel before its run mean is judged."""
DIVERGENCE_WINDOW_S = 60.0
"""Input-model divergences are counted over windows this long (s)."""
DIVERGENCE_STORM = 5
"""Divergences of one input model in one window that make a storm: its input estimate
restarts every 12 s or more often, and the sigmas published between restarts do not
count the restarts."""

POSITION_SIGMA_BOUND = 3.0
"""Mahalanobis distance (2 dof) of the position residual beyond which a comparison fails:
a consistent estimate exceeds it 1.1 % of the time."""
POSITION_WINDOW_S = 30.0
"""Comparisons judged together (s)."""
POSITION_MIN_CHECKS = 5
"""Comparisons needed in a window before it is judged."""
POSITION_FRACTION = 0.5
"""Share of failed comparisons in a window that raises ``position_residual``."""
FIX_MAX_AGE_S = 1.0
"""A fix that arrived longer ago than this (s) at the tick is not compared (its time
stamp, the instant it measured, is ``[corrections] gnss_latency_s`` before its
arrival)."""
DEFAULT_FIX_STD_M = 2.0
"""One-sigma (m) of a fix that reports no accuracy and has no configured one."""

SPEED_SIGMA_BOUND = 3.0
"""Normalized speed residual beyond which a comparison fails: a consistent estimate
exceeds it 0.27 % of the time."""
SPEED_FLOOR_MPS = 0.25
"""A speed residual (m/s) below this never fails: the Doppler speed over ground of a
vehicle at rest is biased up by its noise (a magnitude; 0.13 m/s for a 0.1 m/s sigma)."""
SPEED_WINDOW_S = 30.0
"""Speed comparisons judged together (s)."""
SPEED_MIN_CHECKS = 5
"""Speed comparisons needed in a window before it is judged."""
SPEED_FRACTION = 0.5
"""Share of failed speed comparisons in a window that raises ``speed_mismatch``."""
SPEED_GROSS_WINDOW_S = 10.0
"""The shorter window of the gross-miss rule (s): an estimate that swings through many
sigmas for seconds (an input estimator oscillating at rest) fails there before the
:data:`SPEED_WINDOW_S` window has half its comparisons failed."""
SPEED_GROSS_RMS_SIGMA = 5.0
"""RMS normalized residual over :data:`SPEED_GROSS_WINDOW_S` beyond which a window with
more than :data:`SPEED_FRACTION` of its comparisons failed fails at once. A consistent
estimate's normalized residuals, however correlated in time, have a mean square above 25
about as rarely as a single draw does (P(chi2_1 > 25) = 6e-7); a comparison below
:data:`SPEED_FLOOR_MPS` counts as zero, and a single wild measurement cannot move the
rule, which needs most of the window failed."""
GNSS_DOPPLER = "GNSS Doppler"
"""The speed reference of a fix's speed over ground (the other: ``"DVL"``)."""
DEFAULT_SPEED_STD_MPS = 0.1
"""One-sigma (m/s) of a Doppler speed over ground that reports no accuracy."""
DEFAULT_DVL_STD_MPS = 0.01
"""One-sigma (m/s) of a DVL velocity that reports no figure of merit."""

NIS_BLOCK_UPDATES = 100
"""Accepted updates per block: the check judges each block's mean NIS (10 s of a 10 Hz
channel, 20 s of a 5 Hz one)."""
NIS_BAND = 0.99
"""Probability of the two-sided band a consistent filter's block mean stays in."""
NIS_SUSTAIN_BLOCKS = 3
"""Blocks in a row outside the band, on the same side, that raise ``nis_out_of_band``
(30 s of a 10 Hz channel, 60 s of a 5 Hz one): longer than a manoeuvre's model error (a
hard turn with a speed change puts a calibrated boat's surge increments 20-40 s above the
band), so that a calibrated log is quiet; a consistent filter stays quiet in one-hour
10 Hz channels (tests/test_integrity.py)."""
NIS_EXEMPT_CHANNELS = frozenset({"zupt"})
"""Pseudo-measurements whose sigma is a bound, not a noise: their NIS is not chi-square."""
NIS_COVERAGE_TARGET = (0.6, 0.8)
"""The 1-sigma coverage a calibrated sigma gives (issue 23's target on the simulator's
scenarios; 0.68 exact). It is a tolerance on the sigma's scale: the band is never
narrower than the mean NIS per degree of freedom such a sigma gives
(:func:`calibrated_nis`), 0.61-1.41, so a significant but immaterial miscalibration
(the simulator's heading increments at 0.79) is not flagged."""
NIS_RHO_MAX = 0.9
"""Largest lag-1 autocorrelation of the NIS taken into the effective sample count: a
block keeps at least ``(1 - 0.9) / (1 + 0.9)`` of its updates (5 of 100), so a channel
whose NIS wanders slowly is still judged."""
NIS_RHO_MEMORY = 0.5
"""Weight of the earlier blocks' sums in the lag-1 autocorrelation (per block)."""
NIS_SETTLE_S = 120.0
"""A channel's NIS *below* its band is not judged within this long (s) of its filter's
start (the channel's first accepted update, or its first after the pipeline restarted the
filter: :data:`RESTART_REASONS`). A filter converging from a prior that is wide on purpose
has a forecast larger than its errors until the prior is forgotten, so its innovations are
smaller than their ``S`` whatever its steady state will be; issue 32's calibration bands
pool after 120 s for that reason. Measured on the harness's clean boat logs: the current's
velocity rows below their band only before 80-120 s (their innovations' lag-1
autocorrelation -0.3 to -0.45 there, the gain above the optimal one; the current's
covariance still shrinking 2-100 fold), in band after it. *Above* the band is judged from
the start: a filter more confident than its errors while it converges is a real miss
(docs/integrity.md, "The clean simulator logs")."""
RESTART_REASONS = frozenset({"restart", "diverged"})
"""Reasons of a rejected innovation record that say the pipeline restarted the channel's
filter from its prior (``onboard.pipelines.current.REASONS``): its settling starts again."""


def circular_mean(angles: Iterable[float]) -> float:
    """The circular mean (rad, in ``(-pi, pi]``) of ``angles`` (rad): the direction of
    the sum of their unit vectors, each sum taken with ``sum`` in the angles' order."""
    a = tuple(angles)
    return math.atan2(sum(map(math.sin, a)), sum(map(math.cos, a)))


def crab_bound(sog_mps: float) -> float:
    """The largest heading/course difference (rad) that is not a mismatch at speed over
    ground ``sog_mps``: :data:`HEADING_BOUND_RAD`, or the crab angle a
    :data:`PLAUSIBLE_CURRENT_MPS` current across the track can make, if larger."""
    ratio = min(1.0, PLAUSIBLE_CURRENT_MPS / max(sog_mps, 1e-9))
    return max(HEADING_BOUND_RAD, math.asin(ratio))


@functools.cache
def _normal_quantile(p: float) -> float:
    """The standard normal ``p`` quantile (bisection on ``erf``; p in (0, 1))."""
    lo, hi = -10.0, 10.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if 0.5 * (1.0 + math.erf(mid / math.sqrt(2.0))) < p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def effective_count(n: int, rho: float) -> float:
    """The number of independent values whose mean has the variance of the mean of ``n``
    values of lag-1 autocorrelation ``rho`` (AR(1), large ``n``): ``n (1 - r) / (1 +
    r)``, ``r`` clipped to [0, :data:`NIS_RHO_MAX`] (a negative correlation is not taken
    to narrow the band)."""
    r = min(max(rho, 0.0), NIS_RHO_MAX)
    return n * (1.0 - r) / (1.0 + r)


def calibrated_nis(coverage: tuple[float, float] = NIS_COVERAGE_TARGET
                   ) -> tuple[float, float]:
    """The mean NIS per degree of freedom (lo, hi) of sigmas whose 1-sigma coverage is
    ``coverage`` (hi, lo): a sigma ``k`` times the true one covers ``2 Phi(k) - 1``, and
    its NIS is ``1 / k^2``."""
    k_lo = _normal_quantile(0.5 + coverage[0] / 2.0)
    k_hi = _normal_quantile(0.5 + coverage[1] / 2.0)
    return 1.0 / (k_hi * k_hi), 1.0 / (k_lo * k_lo)


def nis_band(dof: int, n: float = NIS_BLOCK_UPDATES, p: float = NIS_BAND
             ) -> tuple[float, float]:
    """The band of the mean of ``n`` (effective, possibly fractional) NIS values of
    ``dof`` degrees of freedom: the two-sided ``p`` band of a consistent filter's,
    ``chi2_q(dof n) / n`` at ``(1 -+ p) / 2`` (Bar-Shalom, Li & Kirubarajan 2001,
    section 5.4.2, the time-average NIS; :func:`onboard.core.stats.chi2_mean_band`), widened
    to at least ``dof`` times :func:`calibrated_nis`."""
    lo, hi = chi2_mean_band(n, dof, p)
    c_lo, c_hi = calibrated_nis()
    return min(lo, dof * c_lo), max(hi, dof * c_hi)


FORECAST_FACTOR_MIN = 0.01
"""The smallest factor on a forecast's variance a remedy names (:meth:`IntegrityMonitor.
_forecast_remedy`): innovations smaller than the measurement noise alone explains give no
factor from the data, and the remedy says so."""
FORECAST_FACTOR_MAX = 10.0
"""The largest factor on a forecast's variance a remedy names for innovations above their
band: a forecast that would have to be more than this many times wider (3.2 times its
sigma) is not mistuned; the innovations carry an error the filter does not model (a
manoeuvre, a heading source off the course, outliers), and the remedy says so instead of
naming a key (a survey boat's compass 69-124 deg off its course asked for its heading's
process noise times 110)."""
NIS_DIGITS = (2, 6)
"""Decimals of a printed NIS and band: the fewest from the first at which the mean and
both edges read apart, at most the second (a mean 3.2746 outside [0.09, 3.2743] never
reads "3.27 outside [0.09, 3.27]")."""


def _nis_vs_band(check: NisCheck, word: str = "outside") -> str:
    """``"<mean> <word> [lo, hi]"`` with :data:`NIS_DIGITS` decimals."""
    lo, hi = check.band
    m = check.mean
    d = NIS_DIGITS[0]
    while d < NIS_DIGITS[1] and f"{m:.{d}f}" in (f"{lo:.{d}f}", f"{hi:.{d}f}"):
        d += 1
    return f"{m:.{d}f} {word} [{lo:.{d}f}, {hi:.{d}f}]"


def _learned_key(n: object, bound: str = "=", value: float | None = None) -> str:
    """``<key> = <value> (declared <value> <unit>)`` of a learned noise ``n``, the value
    its learned one-sigma unless given (``reported`` for ``declared`` where the sensor's
    own accuracy is the noise the update takes); ``bound`` ``<=`` for a noise learned at
    its floor, ``>=`` at its ceiling: the truth lies beyond the learning's range, the
    value is a limit."""
    v = n.std if value is None else value  # type: ignore[attr-defined]
    basis = getattr(n, "basis", "declared")
    return (f"{n.key} {bound} {v:.3g} ({basis} {n.declared:.3g} "  # type: ignore[attr-defined]
            f"{n.unit})")  # type: ignore[attr-defined]


def _forecast_share(n: object | None) -> float:
    """The forecast's share of ``S`` (``tr(H P_f H^T) / tr(S)``) from a channel's learned
    noise: its windowed forecast ``f_k`` over ``f_k`` plus the noise applied (both over
    the declared); 1 where it has no sample (its forecast always above
    ``FORECAST_SHARE_MAX`` times the noise) or learns none."""
    f = getattr(n, "forecast", 0.0)
    if n is None or not getattr(n, "n", 0) or f <= 0.0:
        return 1.0
    return f / (f + n.applied)  # type: ignore[attr-defined]


class HeadingCourseCheck:
    """Heading against course over ground while moving (module docstring).

    Attributes:
        offset_rad: the circular mean of ``heading - course`` (rad) of the newest judged
            window, None before one.
        mismatch: whether the newest judged window was beyond its bound; a window that
            cannot be judged (the vehicle stopped) leaves it as it was: a misaligned
            sensor stays misaligned when the vehicle stops.
    """

    def __init__(self) -> None:
        self._heading: tuple[float, float] | None = None  # (t, heading rad)
        # the window, one deque per column, oldest first: the sums are taken in C over
        # whole columns, and each difference's sine and cosine once, as it arrives
        self._t: deque[float] = deque()  # s
        self._sin: deque[float] = deque()  # sin(heading - course)
        self._cos: deque[float] = deque()  # cos(heading - course)
        self._sog: deque[float] = deque()  # m/s
        self.offset_rad: float | None = None
        self.mismatch = False
        self.behind = False
        """Whether the newest judged window's course was more than
        :data:`HEADING_GROSS_RAD` off the heading at more than
        :data:`HEADING_GROSS_MIN_SPEED_MPS`: a path speed signed along that heading has
        the wrong sign, or the vehicle goes astern."""
        self.suspect = False
        """Whether the newest fix alone has its course beyond :data:`HEADING_GROSS_RAD`
        off the heading at more than :data:`HEADING_GROSS_MIN_SPEED_MPS`: not a verdict
        (one fix), but the path speed's sign is in doubt until the next fix."""
        self.worst: tuple[float, float] | None = None
        """(offset rad, mean speed m/s) of the window of the present mismatch whose
        offset is the largest: the angle an operator must allow for."""
        self.fastest: tuple[float, float] | None = None
        """(offset rad, mean speed m/s) of its fastest window: the course is the most
        precise there."""

    def heading(self, t: float, heading_rad: float) -> None:
        """The newest heading (rad, true) at ``t`` (s)."""
        self._heading = (t, heading_rad)

    def fix(self, s: GnssFix) -> bool | None:
        """Compare the fix's course with the newest heading; return the window's verdict
        (True: mismatch), or None when the window cannot be judged."""
        h = self._heading
        if h is None or s.t - h[0] > HEADING_FRESH_S:
            self._drop_before(s.t - HEADING_WINDOW_S)
            self.suspect = False
            return None
        return self.course(s.t, h[1], s.sog_mps, s.cog_rad)

    def course(self, t: float, heading_rad: float, sog: float | None, cog: float | None
               ) -> bool | None:
        """Compare a course ``cog`` (rad) at speed over ground ``sog`` (m/s) at ``t`` (s)
        with the heading (rad) it was made under (a fix's with the newest heading, or one
        derived from the track with the mean heading over it,
        :class:`onboard.monitor.track_course.TrackCourse`); return the window's verdict
        (True: mismatch), or None when the window cannot be judged."""
        self._drop_before(t - HEADING_WINDOW_S)
        self.suspect = False
        if (sog is None or cog is None or not sog > HEADING_MIN_SPEED_MPS
                or not math.isfinite(cog)):
            return None
        self._append(t, heading_rad - cog, sog)
        self.suspect = (self._cos[-1] < math.cos(HEADING_GROSS_RAD)
                        and sog > HEADING_GROSS_MIN_SPEED_MPS)
        n = len(self._t)
        span = t - self._t[0]
        run = self._newest_fixes_behind()
        if run:  # judged on those fixes alone: the window's older ones may predate it
            offset = math.atan2(sum(islice(reversed(self._sin), run)),
                                sum(islice(reversed(self._cos), run)))
            sog_mean = sum(islice(reversed(self._sog), run)) / run
            behind = True
        elif n < HEADING_MIN_FIXES or span < HEADING_GROSS_MIN_S:
            return None
        else:
            # the circular mean of the window's differences, from the sines and cosines
            # kept (tests/test_integrity.py)
            offset = math.atan2(sum(self._sin), sum(self._cos))
            sog_mean = sum(self._sog) / n
            behind = abs(offset) > HEADING_GROSS_RAD and sog_mean > HEADING_GROSS_MIN_SPEED_MPS
        if span < 0.8 * HEADING_WINDOW_S and not behind:
            return None   # not judged before the window has filled, unless gross
        self.offset_rad = offset
        self.mismatch = abs(offset) > crab_bound(sog_mean)
        self.behind = behind
        if not self.mismatch:
            self.worst = self.fastest = None
            return False
        if self.worst is None or abs(self.offset_rad) > abs(self.worst[0]):
            self.worst = (self.offset_rad, sog_mean)
        if self.fastest is None or sog_mean > self.fastest[1]:
            self.fastest = (self.offset_rad, sog_mean)
        return True

    def _newest_fixes_behind(self) -> int:
        """How many of the window's newest fixes in a row have their course beyond
        :data:`HEADING_GROSS_RAD` off the heading at more than
        :data:`HEADING_GROSS_MIN_SPEED_MPS` over ground, when they span at least
        :data:`HEADING_GROSS_RUN_S`; else 0."""
        run, first = 0, math.nan
        cos_gross = math.cos(HEADING_GROSS_RAD)
        for t, c, sog in zip(reversed(self._t), reversed(self._cos), reversed(self._sog)):
            if not (c < cos_gross and sog > HEADING_GROSS_MIN_SPEED_MPS):
                break
            run, first = run + 1, t
        return run if self._t[-1] - first >= HEADING_GROSS_RUN_S else 0

    def speed(self) -> float:
        """Mean speed over ground (m/s) of the window."""
        win = self._sog
        return sum(win) / len(win) if win else math.nan

    def _append(self, t: float, diff: float, sog: float) -> None:
        """One moving fix into the window: its time (s), heading - course (rad) and
        speed over ground (m/s)."""
        self._t.append(t)
        self._sin.append(math.sin(diff))
        self._cos.append(math.cos(diff))
        self._sog.append(sog)

    def _drop_before(self, t: float) -> None:
        """Drop the window's fixes older than ``t`` (s)."""
        times = self._t
        while times and times[0] < t:
            for column in (times, self._sin, self._cos, self._sog):
                column.popleft()


class HeadingSourceCheck:
    """The heading the pipelines use against the heading of the navigation solution that
    resolved the velocity over ground (module docstring), both of one vehicle at one
    instant: the selected heading interpolated (or held) to the time of each velocity
    that carries its own heading, the circular mean of their difference over
    :data:`HEADING_WINDOW_S`.

    Attributes:
        offset_rad: the newest judged window's mean ``selected - solution`` (rad).
        mismatch: whether it was beyond :data:`HEADING_SOURCE_BOUND_RAD`.
        worst: the largest offset (rad) of the present mismatch.
    """

    def __init__(self) -> None:
        self._selected: deque[tuple[float, float]] = deque(maxlen=2)  # (t, rad unwrapped)
        self._t: deque[float] = deque()
        self._sin: deque[float] = deque()
        self._cos: deque[float] = deque()
        self.offset_rad: float | None = None
        self.mismatch = False
        self.worst: float | None = None
        self.t_judged = -math.inf
        """When (s) the newest window was judged."""

    @property
    def widens(self) -> bool:
        """Whether the newest offset may widen a heading sigma (beyond
        :data:`HEADING_SOURCE_WIDEN_MIN_RAD`)."""
        return self.offset_rad is not None and abs(self.offset_rad) > HEADING_SOURCE_WIDEN_MIN_RAD

    def widening_at(self, t: float) -> float | None:
        """The newest judged offset (rad) while it :attr:`widens` and is recent at ``t``
        (s): judged within :data:`HEADING_WINDOW_S`; else None (the two agree, or the
        solution's heading stopped)."""
        return self.offset_rad if self.widens and t - self.t_judged <= HEADING_WINDOW_S \
            else None

    def selected(self, t: float, heading_rad: float) -> None:
        """The heading the pipelines are given (rad, true) at ``t`` (s)."""
        sel = self._selected
        if sel and t <= sel[-1][0]:
            sel.clear()   # out of order or repeated: start the pair again
        if sel:
            heading_rad = sel[-1][1] + wrap_pi(heading_rad - sel[-1][1])
        sel.append((t, heading_rad))

    def solution(self, t: float, heading_rad: float) -> bool | None:
        """Compare the solution's heading (rad) at ``t`` (s) with the selected one
        there; return the window's verdict (True: mismatch), or None when it cannot be
        judged (no selected heading within :data:`HEADING_FRESH_S`, too few samples)."""
        self._drop_before(t - HEADING_WINDOW_S)
        sel = self._selected
        if not sel or abs(t - sel[-1][0]) > HEADING_FRESH_S:
            return None
        if len(sel) == 2 and sel[1][0] - sel[0][0] <= HEADING_FRESH_S:
            (ta, a), (tb, b) = sel
            psi = a + (b - a) * (t - ta) / (tb - ta)   # the turn between them, not a lag
        else:
            psi = sel[-1][1]
        diff = wrap_pi(psi - heading_rad)
        self._t.append(t)
        self._sin.append(math.sin(diff))
        self._cos.append(math.cos(diff))
        if len(self._t) < HEADING_MIN_FIXES or t - self._t[0] < 0.8 * HEADING_WINDOW_S:
            return None
        self.offset_rad = math.atan2(sum(self._sin), sum(self._cos))
        self.t_judged = t
        self.mismatch = abs(self.offset_rad) > HEADING_SOURCE_BOUND_RAD
        if not self.mismatch:
            self.worst = None
        elif self.worst is None or abs(self.offset_rad) > abs(self.worst):
            self.worst = self.offset_rad
        return self.mismatch

    def _drop_before(self, t: float) -> None:
        times = self._t
        while times and times[0] < t:
            for column in (times, self._sin, self._cos):
                column.popleft()


class CompassDeviationCheck:
    """The compass's heading-dependent error, learned against course over ground on
    straight legs (:class:`onboard.monitor.compass_deviation.CompassDeviation`).

    The fixes of a moving vehicle with a fresh heading are gathered into legs of
    :data:`LEG_S`; a leg whose headings and courses each stay within
    :data:`LEG_STRAIGHT_RAD` (circular standard deviation) of their mean is one equation
    of the fit, a turning one is dropped (a turn's lag between heading and course is not
    a deviation).

    Attributes:
        fit: the least-squares fit.
        deviated: whether the fit's harmonic terms are significant (Wald statistic above
            :data:`DEVIATION_WALD`); the monitor then compares their size with each
            pipeline's heading sigma.
    """

    def __init__(self) -> None:
        self.fit = CompassDeviation()
        self.deviated = False
        self._leg: list[tuple[float, float, float, float]] = []  # (t, psi, chi, sog)

    def fix(self, t: float, psi: float, chi: float, sog: float) -> bool:
        """One moving fix with its fresh heading ``psi`` and course ``chi`` (rad), speed
        over ground ``sog`` (m/s); returns whether a leg was closed (the fit may have
        moved)."""
        leg = self._leg
        if leg and t - leg[-1][0] > LEG_GAP_S:
            leg.clear()
        leg.append((t, psi, chi, sog))
        if t - leg[0][0] < LEG_S:
            return False
        mean_psi, straight_psi = circular_stats([p for _, p, _, _ in leg])
        mean_chi, straight_chi = circular_stats([c for _, _, c, _ in leg])
        sog_mean = sum(v for _, _, _, v in leg) / len(leg)
        leg.clear()
        if max(straight_psi, straight_chi) > LEG_STRAIGHT_RAD:
            return False
        self.fit.leg(mean_psi, mean_chi, sog_mean, t)
        self.deviated = self.fit.significance() > DEVIATION_WALD
        return True

    def rms(self) -> float:
        """The deviation's RMS over a turn (rad) when it is significant, else 0."""
        return self.fit.rms() if self.deviated else 0.0


class IdleDriftCheck:
    """The published current against the vehicle's drift while its thrusters idle.

    A vehicle with no thrust settles to the water's velocity: after
    :data:`IDLE_SETTLE_S` of idle commands its velocity over ground is the current (and
    what wind pushes). The drift is the least-squares slope of the fixes' north and east
    against time over the idle span (at most :data:`IDLE_WINDOW_S`; a slope of ``n``
    fixes of one-sigma ``s`` over a span of time-spread ``sd_t`` has the one-sigma ``s /
    (sqrt(n) sd_t)``). At each fix of a span of at least :data:`IDLE_MIN_SPAN_S` the
    published current is compared with it: the Mahalanobis distance of their difference
    with both covariances (2 dof) beyond :data:`IDLE_DRIFT_BOUND` fails.

    Attributes:
        idle_since: when (s) the commands last became idle, None while thrusting.
        failing: the newest verdict (kept while no idle span can judge).
        last: (drift north, east, current north, east (m/s), distance) of the newest
            comparison.
    """

    def __init__(self) -> None:
        self.idle_since: float | None = None
        self.failing = False
        self.last: tuple[float, float, float, float, float] | None = None
        self._fixes: deque[tuple[float, float, float, float]] = deque()  # t, n, e, var
        self._last_fix_t: float | None = None

    def command(self, t: float, idle: bool) -> None:
        """A normalized command at ``t`` (s): ``idle`` when no thruster pushes."""
        if not idle:
            self.idle_since = None
            self._fixes.clear()
        elif self.idle_since is None:
            self.idle_since = t

    def fix(self, t: float, north: float, east: float, var_m2: float) -> None:
        """A fix (m in the monitor's frame, its variance m^2 per axis) during idle; after
        a gap in the fixes longer than :data:`IDLE_GAP_S` the vehicle settles anew."""
        since = self.idle_since
        if since is None:
            return
        last = self._last_fix_t
        self._last_fix_t = t
        if last is not None and t - last > IDLE_GAP_S:
            self.idle_since = since = t
            self._fixes.clear()
        if t - since < IDLE_SETTLE_S:
            return
        fixes = self._fixes
        fixes.append((t, north, east, var_m2))
        while fixes and fixes[0][0] < t - IDLE_WINDOW_S:
            fixes.popleft()

    def drift(self) -> tuple[float, float, float] | None:
        """The drift (north, east, m/s) and its variance per axis (m^2/s^2), None when
        the idle span is shorter than :data:`IDLE_MIN_SPAN_S`."""
        fixes = self._fixes
        if len(fixes) < 3 or fixes[-1][0] - fixes[0][0] < IDLE_MIN_SPAN_S:
            return None
        n = len(fixes)
        tm = sum(f[0] for f in fixes) / n
        stt = sum((f[0] - tm) ** 2 for f in fixes)
        nm = sum(f[1] for f in fixes) / n
        em = sum(f[2] for f in fixes) / n
        vn = sum((f[0] - tm) * (f[1] - nm) for f in fixes) / stt
        ve = sum((f[0] - tm) * (f[2] - em) for f in fixes) / stt
        var = sum(f[3] for f in fixes) / n / stt
        return vn, ve, var

    def judge(self, current: tuple[float, float], var: tuple[float, float]) -> bool | None:
        """The published current (north, east, m/s) and its variance per axis against
        the drift; the verdict (True: failing), None when no idle span can judge."""
        d = self.drift()
        if d is None:
            return None
        dn, de = d[0] - current[0], d[1] - current[1]
        m = math.sqrt(dn * dn / (d[2] + var[0]) + de * de / (d[2] + var[1]))
        self.last = (d[0], d[1], current[0], current[1], m)
        self.failing = m > IDLE_DRIFT_BOUND
        return self.failing


def _idle(c: ActuatorCommand) -> bool:
    """Whether command ``c`` pushes nothing: every thruster within
    :data:`IDLE_COMMAND` of zero (a rudder alone does not push); a command without a
    thruster is not idle."""
    some = False
    for x in (c.throttle, c.left, c.right, *(c.thrusters or ())):
        if x is not None:
            if not -IDLE_COMMAND <= x <= IDLE_COMMAND:
                return False
            some = True
    return some


def _astern(c: ActuatorCommand) -> bool:
    """Whether command ``c`` pushes backwards: its throttle, or the mean of its
    thrusters, below -:data:`IDLE_COMMAND`."""
    pushes = [x for x in (c.throttle, c.left, c.right, *(c.thrusters or ()))
              if x is not None]
    return bool(pushes) and sum(pushes) / len(pushes) < -IDLE_COMMAND


class PositionCheck:
    """One pipeline's published position against the GNSS fixes (module docstring)."""

    def __init__(self) -> None:
        self._window: deque[tuple[float, float, float]] = deque()  # (t, distance, metres)
        self.beyond = 0
        """Comparisons in the window beyond :data:`POSITION_SIGMA_BOUND` (a count kept as
        they come and go: an integer, exact)."""
        self.failing = False

    def add(self, t: float, residual_ne: tuple[float, float], var_ne: tuple[float, float]
            ) -> bool | None:
        """One comparison at ``t`` (s): the residual (m) and its variance per axis (m^2,
        published plus fix). Returns the window's verdict (True: failing), None when it
        cannot be judged yet."""
        dn, de = residual_ne
        d = math.sqrt(dn * dn / var_ne[0] + de * de / var_ne[1])
        win = self._window
        win.append((t, d, math.hypot(dn, de)))
        self.beyond += d > POSITION_SIGMA_BOUND
        while win[0][0] < t - POSITION_WINDOW_S:
            self.beyond -= win.popleft()[1] > POSITION_SIGMA_BOUND
        if len(win) < POSITION_MIN_CHECKS:
            return None
        self.failing = self.beyond > POSITION_FRACTION * len(win)
        return self.failing

    def median_m(self) -> float:
        """Median distance (m) to the fixes in the window."""
        xs = sorted(m for _, _, m in self._window)
        return xs[len(xs) // 2] if xs else math.nan

    def median_sigma(self) -> float:
        """Median normalized distance in the window."""
        xs = sorted(x for _, x, _ in self._window)
        return xs[len(xs) // 2] if xs else math.nan


class SpeedCheck:
    """One pipeline's published speed against Doppler or DVL (module docstring).

    Attributes:
        failing: whether the newest judged window failed.
    """

    def __init__(self) -> None:
        self._window: deque[tuple[float, float, bool]] = deque()  # (t, |residual|, failed)
        self.failed = 0
        """Failed comparisons in the window (a count kept as they come and go: an
        integer, exact)."""
        self._gross: deque[tuple[float, float, float, bool]] = deque()  # (t, |r|, z^2, failed)
        self._gross_failed = 0
        self.failing = False
        self.gross_rms: float | None = None
        """The RMS normalized residual over :data:`SPEED_GROSS_WINDOW_S` when the newest
        judged window failed by the gross-miss rule alone, else None."""

    def add(self, t: float, residual_mps: float, var: float) -> bool | None:
        """One comparison at ``t`` (s): the residual (m/s) and its variance (m^2/s^2,
        published plus measured). Returns the window's verdict (True: failing), None when
        it cannot be judged yet."""
        r = abs(residual_mps)
        failed = r > SPEED_FLOOR_MPS and r > SPEED_SIGMA_BOUND * math.sqrt(var)
        win = self._window
        win.append((t, r, failed))
        self.failed += failed
        while win[0][0] < t - SPEED_WINDOW_S:
            self.failed -= win.popleft()[2]
        gross = self._gross
        gross.append((t, r, r * r / var if r > SPEED_FLOOR_MPS and var > 0.0 else 0.0,
                      failed))
        self._gross_failed += failed
        while gross[0][0] < t - SPEED_GROSS_WINDOW_S:
            self._gross_failed -= gross.popleft()[3]
        if len(win) < SPEED_MIN_CHECKS:
            return None
        self.failing = self.failed > SPEED_FRACTION * len(win)
        self.gross_rms = None
        if not self.failing and len(gross) >= SPEED_MIN_CHECKS \
                and self._gross_failed > SPEED_FRACTION * len(gross):
            rms = math.sqrt(sum([z2 for _, _, z2, _ in gross]) / len(gross))
            if rms > SPEED_GROSS_RMS_SIGMA:
                self.failing, self.gross_rms = True, rms
        return self.failing

    def median_mps(self) -> float:
        """Median speed difference (m/s) in the window."""
        xs = sorted(r for _, r, _ in self._window)
        return xs[len(xs) // 2] if xs else math.nan

    def gross_rms_mps(self) -> float:
        """RMS speed difference (m/s) over :data:`SPEED_GROSS_WINDOW_S`."""
        g = self._gross
        return math.sqrt(sum([r * r for _, r, _, _ in g]) / len(g)) if g else math.nan


def _computed_speed(qs: tuple[str, ...], values: Mapping[str, float], forward_only: bool
                    ) -> tuple[float, float] | None:
    """A pipeline's speed (m/s) and its variance (m^2/s^2) as compared with a measurement,
    from its ``values`` of a tick (each quantity ``q`` with its ``std_q``), ``qs`` its
    forward speed and maybe its sideways speed: the forward speed (signed,
    ``forward_only``) or the horizontal speed (a magnitude); None when it has no finite
    one with its sigma."""
    qs = qs[:1] if forward_only else qs
    got = [(values.get(q, math.nan), values.get("std_" + q, math.nan)) for q in qs]
    if not all(math.isfinite(v) and math.isfinite(sd) for v, sd in got):
        return None
    if forward_only:
        return got[0][0], got[0][1] ** 2
    return math.hypot(*[v for v, _ in got]), sum([sd * sd for _, sd in got])


class NisCheck:
    """One channel's block-mean NIS against its band (module docstring).

    Each block of :data:`NIS_BLOCK_UPDATES` accepted updates is judged at its end: its
    mean against :func:`nis_band` for ``dof`` and the block's effective sample count
    (:func:`effective_count`) from the lag-1 autocorrelation of the NIS, measured on the
    blocks so far (each block's deviations from its own mean; earlier blocks weighted by
    :data:`NIS_RHO_MEMORY` per block).

    Attributes:
        dof: degrees of freedom of one NIS.
        mean: the newest judged block's mean NIS (nan before one).
        rho: the lag-1 autocorrelation of the NIS used for it.
        band: its band (lo, hi).
        outside: judged blocks in a row outside the band on the same side: positive
            above, negative below.
        first_failed: when (s) the check first failed: one warning per pipeline spans
            the run's failures, not one per excursion.
    """

    __slots__ = ("dof", "mean", "rho", "band", "outside", "first_failed", "t_start",
                 "adapted", "_n", "_sx", "_sxx", "_sxy", "_first", "_prev", "_sv", "_sc")

    def __init__(self, dof: int) -> None:
        self.dof = dof
        self.mean = math.nan
        self.rho = 0.0
        self.band = nis_band(dof)
        self.outside = 0
        self.first_failed: float | None = None
        self.t_start: float | None = None
        """When (s) the channel's filter started (or restarted): the monitor's settling
        clock (:data:`NIS_SETTLE_S`); None before its first accepted update."""
        self.adapted = False
        """Whether the channel's noise had adapted when the newest update came
        (:meth:`IntegrityMonitor._adapted`)."""
        self._sv = self._sc = 0.0   # pooled deviation power and lag-1 product
        self._reset()

    def _reset(self) -> None:
        self._n = 0
        self._sx = self._sxx = self._sxy = 0.0
        self._first = self._prev = 0.0

    def restart(self) -> None:
        """Judge from the next update on as from the start: the block in progress and
        the run of blocks outside the band are dropped (they measured a filter whose
        noise was still adapting); the NIS's autocorrelation is kept."""
        self._reset()
        self.outside = 0

    @property
    def failing(self) -> bool:
        """Whether the newest :data:`NIS_SUSTAIN_BLOCKS` blocks were outside the band on
        the same side."""
        return abs(self.outside) >= NIS_SUSTAIN_BLOCKS

    @property
    def judges_next(self) -> bool:
        """Whether the next :meth:`add` ends a block (and so judges it)."""
        return self._n + 1 >= NIS_BLOCK_UPDATES

    def add(self, nis: float, unjudged_below: bool = False) -> bool:
        """One accepted update's NIS; ``unjudged_below``: a block that ends with it is not
        judged below its band (the filter still settles from its prior, or slow errors
        hold its published sigma: module docstring). Returns :attr:`failing`."""
        if self._n:
            self._sxy += nis * self._prev
        else:
            self._first = nis
        self._n += 1
        self._sx += nis
        self._sxx += nis * nis
        self._prev = nis
        if self._n >= NIS_BLOCK_UPDATES:
            self._judge(unjudged_below)
        return abs(self.outside) >= NIS_SUSTAIN_BLOCKS

    def _judge(self, unjudged_below: bool = False) -> None:
        """The block's mean against its band (below it not judged with ``unjudged_below``:
        such a block neither counts towards :data:`NIS_SUSTAIN_BLOCKS` nor extends a run
        below); the next block starts."""
        n, sx = self._n, self._sx
        m = sx / n
        dev = self._sxx - n * m * m
        lag = self._sxy - m * (2.0 * sx - self._first - self._prev) + (n - 1) * m * m
        self._sv = NIS_RHO_MEMORY * self._sv + dev
        self._sc = NIS_RHO_MEMORY * self._sc + lag
        self.rho = self._sc / self._sv if self._sv > 0.0 else 0.0
        self.band = lo, hi = nis_band(self.dof, effective_count(n, self.rho))
        self.mean = m
        side = 1 if m > hi else -1 if m < lo and not unjudged_below else 0
        self.outside = (self.outside + side if side and self.outside * side >= 0
                        else side)
        self._reset()


class NisRunMean:
    """One channel's mean NIS over the whole run against :data:`NIS_FAR_FACTOR` times
    its degrees of freedom: the block check (:class:`NisCheck`) widens its band for
    correlated innovations and judges blocks, so a channel whose mean is carried by rare
    huge innovations can stay inside every block's band while its run mean is 100."""

    __slots__ = ("dof", "n", "total", "far")

    def __init__(self, dof: int) -> None:
        self.dof = dof
        self.n = 0
        self.total = 0.0
        self.far = False

    @property
    def mean(self) -> float:
        """The mean NIS of the accepted updates so far (nan before one)."""
        return self.total / self.n if self.n else math.nan

    def add_block(self, mean: float, n: int) -> bool:
        """A block of ``n`` accepted updates of mean NIS ``mean``; returns True when the
        channel has just become far above."""
        self.n += n
        self.total += mean * n
        if self.far or self.n < NIS_FAR_MIN_UPDATES:
            return False
        self.far = self.mean > NIS_FAR_FACTOR * self.dof
        return self.far


class DivergenceCheck:
    """Input-model divergences per pipeline counter (``<axis>.diverged`` in its health)
    over windows of :data:`DIVERGENCE_WINDOW_S`: :data:`DIVERGENCE_STORM` or more in
    one window is a storm.

    Attributes:
        storms: counter key (``<pipeline>:<axis>.diverged``) -> (divergences in the
            newest stormy window, its length s).
    """

    def __init__(self) -> None:
        self._start: float | None = None
        self._counts: dict[str, float] = {}
        self.storms: dict[str, tuple[float, float]] = {}
        self.first: dict[str, float] = {}
        """counter key -> when (s) its first stormy window began."""

    def due(self, t: float) -> bool:
        """Whether a window ends at ``t`` (s) (the first call starts one)."""
        if self._start is None:
            self._start = t
            return False
        return t - self._start >= DIVERGENCE_WINDOW_S

    def window(self, t: float, counters: dict[str, float]) -> list[str]:
        """The counters at the end of a window; returns the keys that stormed in it."""
        span = t - (self._start if self._start is not None else t)
        stormed = []
        for key, n in counters.items():
            before = self._counts.get(key)
            self._counts[key] = n
            if before is not None and n - before >= DIVERGENCE_STORM:
                self.storms[key] = (n - before, span)
                self.first.setdefault(key, t - span)
                stormed.append(key)
        self._start = t
        return stormed


REORIGINED = ("; its own local frame is no longer about the first fix (a restart "
              "re-origins it at the next fix), so its published positions jumped")
"""Added to ``position_residual`` when the pipeline's frame moved."""
WARN_EVERY_S = 1.0
"""A condition that lasts is re-raised at most this often (s) (one warning spans it)."""
WATCHED = frozenset({GnssFix, Heading, Attitude, DvlVelocity, ActuatorCommand,
                     VelocityOverGround})
"""The sample types the monitor reads (the engine hands it only these)."""


POSITION_NEES_FIX_RATIO = 4.0
"""A fix is better than the estimate when the published variance is at least this many
times the fix's (its sigma half the estimate's): the fix's own error (and the drift the
estimate shares with it) is then a small part of the residual."""


class PositionNeesCheck(NisCheck):
    """One pipeline's position NEES against the fixes better than its estimate (module
    docstring): a :class:`NisCheck` of 2 degrees of freedom fed with
    ``d^T (P + R_fix)^-1 d`` where ``R_fix < P``."""

    __slots__ = ()

    def __init__(self) -> None:
        super().__init__(2)


class Declared(Protocol):
    """A pipeline as the monitor sees it: its name and the roles it declares
    (``onboard.pipelines.base.Pipeline`` documents them). It may also name, per innovation
    channel, the configuration key whose process noise sets that channel's forecast:
    ``forecast_noise(channel) -> (key, value, unit, power) | None`` (the forecast's
    variance taken as proportional to the value to that power; read where present, for
    the NIS warning's remedy)."""

    name: str
    position: tuple[str, ...]
    """The columns that are a position (north, east; m), each with its ``std_<q>``."""
    speed: tuple[str, ...]
    """Its forward speed over ground (m/s) and maybe its sideways speed."""
    heading_dependent: tuple[str, ...]
    """The columns withheld while the heading disagrees with the course."""
    heading_estimate: tuple[str, ...]
    """Its published heading (rad), with its ``std_<q>``: widened by a detected compass
    deviation, withheld with ``position`` while the heading disagrees with the course."""
    current_estimate: tuple[str, ...]
    """Its water current (north, east; m/s), each with its ``std_<q>``: judged against
    the idle drift."""
    unpublished_channels: tuple[str, ...]
    """Its innovation channels whose forecast is of a quantity published without a sigma:
    below their band, information (``nis_unpublished``), not ``nis_out_of_band``."""
    calibrating_channels: tuple[str, ...]
    """Its innovation channels whose innovations correct a published sigma both ways:
    below their band, information (``nis_corrected``), not ``nis_out_of_band``."""
    regression_channels: tuple[str, ...]
    """Its innovation channels that are a regression's a-priori residuals: out of their
    band on either side, information (``nis_unpublished``), not ``nis_out_of_band``."""
    frame: LocalFrame | None
    """The local frame about its first fix (None before it)."""
    frame_offset: tuple[float, float] | None
    """Where ``frame``'s origin lies in its published position (None: its positions are
    about the first fix handed to the pipelines)."""


class IntegrityMonitor:
    """The five checks of one run and their flags (module docstring).

    Attributes:
        flags: pipeline -> the codes of the checks it fails now.
        flagged: per pipeline, the values withheld from its records (the health record's
            ``withheld``: ``pipeline:<name>:flagged``).
        withheld_rows: per pipeline, the records (ticks) it had values withheld from.
        heading: the heading/course check, None for a holonomic vehicle.
        positions: pipeline -> its position check.
        speeds: pipeline -> reference (``GNSS Doppler``, ``DVL``) -> its speed check.
        nis: pipeline -> channel -> its NIS check.
    """

    def __init__(self, alerts: Alerts, holonomic: bool = False,
                 fix_std_m: float = DEFAULT_FIX_STD_M,
                 speed_std_mps: float = DEFAULT_SPEED_STD_MPS,
                 dvl_std_mps: float = DEFAULT_DVL_STD_MPS,
                 gnss_latency_s: float = 0.0) -> None:
        """Raise warnings into ``alerts``; ``holonomic``: the vehicle moves sideways by
        design (:attr:`onboard.core.vehicles.VehicleTraits.holonomic`: no heading/course
        check); ``fix_std_m`` is the one-sigma (m) of a fix that
        reports no accuracy (``[sensors.gnss] position_std_m``), ``speed_std_mps`` of its
        speed over ground (``[sensors.gnss] velocity_std_mps``), ``dvl_std_mps`` of a DVL
        velocity with no figure of merit (``[sensors.dvl] velocity_std_mps``);
        ``gnss_latency_s`` (``[corrections] gnss_latency_s``) how long before its arrival
        a fix's time stamp is: a fix is compared while it arrived at most
        :data:`FIX_MAX_AGE_S` before the tick."""
        self.alerts = alerts
        self.fix_max_age_s = FIX_MAX_AGE_S + gnss_latency_s
        self.fix_std_m = fix_std_m
        self.speed_std_mps = speed_std_mps
        self.dvl_std_mps = dvl_std_mps
        self.speeds: dict[str, dict[str, SpeedCheck]] = {}
        self._speed_refs: list[tuple[float, float, float, str]] = []
        """Measured speeds since the previous tick: (t, m/s, variance, reference)."""
        self.heading = None if holonomic else HeadingCourseCheck()
        self.sources = HeadingSourceCheck()
        """The selected heading against the navigation solution's own."""
        self.deviation = None if holonomic else CompassDeviationCheck()
        self.idle = IdleDriftCheck()
        self.track = TrackCourse()
        """The course of the track of fixes that carry none (for the heading check)."""
        self.run_means: dict[str, dict[str, NisRunMean]] = {}
        self.divergences = DivergenceCheck()
        self.watched: dict[str, Declared] = {}
        """The pipelines whose roles it reads, by name (:meth:`watch`)."""
        self._resolving = False
        """Whether a watched pipeline publishes a current (judged at every tick by
        :meth:`amend`)."""
        self.resolution: dict[str, CurrentResolution] = {}
        """pipeline -> whether the data resolve its current, per component."""
        self.positions: dict[str, PositionCheck] = {}
        self.nis: dict[str, dict[str, NisCheck]] = {}
        self.position_nees: dict[str, PositionNeesCheck] = {}
        self.flags: dict[str, set[str]] = {}
        self.flagged: dict[str, int] = {}
        self.withheld_rows: dict[str, int] = {}
        self._fix: GnssFix | None = None
        self.frame: LocalFrame | None = None
        """The local frame about the first fix handed to the pipelines: the frame of the
        published ``aie``/``kf`` positions ("m from the first fix")."""
        self._fix_new = False
        self._last_warn: dict[tuple[str, str], float] = {}
        self._noted_below: dict[str, list[str]] = {}
        """pipeline -> its channels already noted below their band as information
        (``nis_unpublished``, ``nis_corrected``)."""

    def watch(self, pipelines: Iterable[Declared]) -> None:
        """Read the roles (and frames) of ``pipelines`` from now on, replacing those
        watched so far (the engine calls it whenever its pipelines change)."""
        self.watched = {p.name: p for p in pipelines}
        self._resolving = any(getattr(p, "current_estimate", ())
                              for p in self.watched.values())

    # ------------------------------------------------------------------ samples
    def observe(self, s: Sample) -> None:
        """A sample handed to the pipelines (one of :data:`WATCHED`)."""
        cls = type(s)
        hc = self.heading
        if cls is GnssFix:
            if s.fix_quality > 0:  # type: ignore[attr-defined]
                self._fix, self._fix_new = s, True  # type: ignore[assignment]
                self._doppler(s)  # type: ignore[arg-type]
                if self.frame is None:
                    self.frame = LocalFrame(s.lat_deg, s.lon_deg)  # type: ignore
                self._idle_fix(s)  # type: ignore[arg-type]
                if hc is not None:
                    self._heading_verdict(self._course(s), s.t)  # type: ignore[arg-type]
                    self._deviation_fix(s)  # type: ignore[arg-type]
        elif cls is DvlVelocity:
            self._dvl(s)  # type: ignore[arg-type]
        elif cls is ActuatorCommand:
            self.idle.command(s.t, _idle(s))  # type: ignore[arg-type]
            if _astern(s):  # type: ignore[arg-type]
                self.track.astern(s.t)
        elif cls is VelocityOverGround:
            psi = s.heading_rad  # type: ignore[attr-defined]
            if psi is not None and math.isfinite(psi):
                self._source_verdict(self.sources.solution(s.t, psi), s.t)
        elif cls is Heading:
            self._heading_sample(s.t, s.heading_rad)  # type: ignore[attr-defined]
        elif cls is Attitude and s.yaw_selected:  # type: ignore[attr-defined]
            self._heading_sample(s.t, s.yaw_rad)  # type: ignore[attr-defined]

    def _heading_sample(self, t: float, psi: float) -> None:
        """The heading the pipelines are given (rad) at ``t`` (s), into the checks."""
        self.sources.selected(t, psi)
        hc = self.heading
        if hc is None:
            return
        hc.heading(t, psi)
        if self.track.active:
            self.track.heading(t, psi)

    def _source_verdict(self, verdict: bool | None, t: float) -> None:
        """Set or clear ``heading_source_mismatch`` on the pipelines that publish a
        heading, and warn while it holds."""
        if verdict is None:
            return
        code = "heading_source_mismatch"
        own = [n for n, p in self.watched.items() if getattr(p, "heading_estimate", ())]
        for name in own:
            self._flag(name, code, verdict)
        if verdict and own:
            worst = self.sources.worst
            assert worst is not None
            self._warn(code, "", t, (
                f"the heading the estimators use disagrees with the heading of the "
                f"navigation solution that gives the velocity over ground by up to "
                f"{math.degrees(worst):.1f} deg (bound "
                f"{math.degrees(HEADING_SOURCE_BOUND_RAD):.0f} deg): "
                + ", ".join(f"{n} heading and position" for n in own)
                + " withheld until they agree again; [sources] heading chooses the source"),
                details=(f"the circular mean over {HEADING_WINDOW_S:.0f} s of the selected "
                         "heading, interpolated to each velocity's time, minus the "
                         "velocity's own heading (GLOBAL_POSITION_INT hdg); an AHRS's "
                         "magnetic yaw beside a DVL-aided INS, or a misaligned compass; "
                         "the current turns the velocity with the solution's own heading"))

    def _course(self, s: GnssFix) -> bool | None:
        """The heading/course verdict at fix ``s``: against its own course, or, when it
        carries none, against the course of the track of the fixes
        (:class:`TrackCourse`) with the mean heading over it."""
        hc = self.heading
        assert hc is not None and self.frame is not None
        if s.cog_rad is not None:
            return hc.fix(s)
        n, e = self.frame.to_ne(s.lat_deg, s.lon_deg)
        derived = self.track.fix(s.t, n, e, self._fix_var(s))
        h = hc._heading
        if derived is None or h is None or s.t - h[0] > HEADING_FRESH_S:
            return hc.course(s.t, 0.0, None, None)
        sog, cog, mean_heading = derived
        return hc.course(s.t, mean_heading, sog, cog)

    def _fix_var(self, s: GnssFix) -> float:
        """A fix's variance (m^2) per axis: its reported accuracy squared, else
        ``fix_std_m`` squared."""
        acc = s.h_acc_m
        return (acc * acc if acc is not None and acc > 0 and math.isfinite(acc)
                else self.fix_std_m ** 2)

    def _heading_verdict(self, verdict: bool | None, t: float) -> None:
        """Set or clear the heading/course flag of the pipelines with heading-dependent
        outputs."""
        if verdict is None:
            return
        code = "heading_course_mismatch"
        for name, p in self.watched.items():
            if p.heading_dependent or getattr(p, "heading_estimate", ()):
                self._flag(name, code, verdict)
        if verdict:
            hc = self.heading
            assert hc is not None and hc.worst is not None and hc.fastest is not None
            offset, sog = hc.worst
            held = ", ".join(n for n, p in self.watched.items() if p.heading_dependent)
            held += "".join(f", {n} heading and position" for n, p in self.watched.items()
                            if getattr(p, "heading_estimate", ()))
            self._warn(code, "", t, (
                f"heading disagrees with course over ground by up to "
                f"{math.degrees(offset):.1f} deg at {sog:.1f} m/s (bound "
                f"{math.degrees(crab_bound(sog)):.0f} deg; "
                f"{math.degrees(hc.fastest[0]):.1f} deg at its fastest, "
                f"{hc.fastest[1]:.1f} m/s): "
                + (f"{held.lstrip(', ')} withheld until they agree again; " if held else "")
                + HEADING_OFFSET_HINT), details=(
                f"the median over {HEADING_WINDOW_S:.0f} s; a misaligned compass or antenna "
                "baseline, or a heading from another vehicle; the rows withheld: "
                "summary.json withheld_rows"))

    def _deviation_fix(self, s: GnssFix) -> None:
        """A fix's course against the newest heading, into the compass-deviation fit;
        the pipelines with heading-dependent outputs flagged while the deviation is
        significant and above :data:`DEVIATION_MIN_RAD`."""
        hc, dc = self.heading, self.deviation
        assert hc is not None and dc is not None
        h = hc._heading
        sog, cog = s.sog_mps, s.cog_rad
        if (h is None or sog is None or cog is None or s.t - h[0] > HEADING_FRESH_S
                or not sog > HEADING_MIN_SPEED_MPS or not math.isfinite(cog)):
            return
        if not dc.fix(s.t, h[1], cog, sog):
            return
        on = dc.rms() > DEVIATION_MIN_RAD
        dependent = [n for n, p in self.watched.items() if p.heading_dependent]
        was = any("compass_deviation" in self.flags.get(n, ()) for n in dependent)
        for name in dependent:
            self._flag(name, "compass_deviation", on)
        if on and not was:
            self._deviation_warning("", s.t, ", ".join(dependent))

    def _deviation_warning(self, pipeline: str, t: float, held: str = "") -> None:
        dc = self.deviation
        assert dc is not None and dc.fit.residual_std is not None
        what = (f"{pipeline} heading sigma widened by it at each heading"
                if pipeline else f"{held} withheld while it lasts" if held
                else "the heading sigmas widened by it")
        self._warn("compass_deviation", pipeline, t, (
            f"the compass errs with the heading by {math.degrees(dc.rms()):.1f} deg RMS "
            f"(learned against course over ground on {dc.fit.legs} straight legs): "
            f"{what}; onboard diagnose LOG names and sizes the deviation"), details=(
            f"Wald statistic {dc.fit.significance():.0f} on 4 dof (bound "
            f"{DEVIATION_WALD}); legs' residual {dc.fit.residual_std:.3f} m/s across the "
            "heading; "
            "the constant term and a uniform current are fitted beside it "
            "(docs/integrity.md)"))

    def _idle_fix(self, s: GnssFix) -> None:
        """A fix into the idle-drift fit, in the monitor's frame."""
        idle = self.idle
        if idle.idle_since is None or self.frame is None:
            return
        n, e = self.frame.to_ne(s.lat_deg, s.lon_deg)
        idle.fix(s.t, n, e, self._fix_var(s))

    def _resolution(self, pipeline: str, t: float, values: dict[str, float],
                    qs: tuple[str, ...]) -> None:
        """The current ``qs`` (north, east) in ``values`` (before anything is withheld)
        into its :class:`CurrentResolution`; ``current_unresolved`` while a component is
        not told from zero (withheld, its ``std_`` kept)."""
        res = self.resolution.get(pipeline)
        if res is None:
            res = self.resolution[pipeline] = CurrentResolution()
        res.add(t, values, qs)
        axes = res.unresolved()
        self._flag(pipeline, "current_unresolved", bool(axes))
        if axes and self._due("current_unresolved", pipeline, t):
            self._unresolved_warning(pipeline, t, res, axes)

    def _unresolved_warning(self, pipeline: str, t: float, res: CurrentResolution,
                            axes: tuple[str, ...]) -> None:
        said = "; ".join(f"{q} {res.axes[q].rms:.3f} m/s RMS against its one-sigma "
                         f"{res.axes[q].sigma:.3f}" for q in axes)
        self._warn("current_unresolved", pipeline, t, (
            f"{pipeline}: the current is not told from zero over {RESOLVE_WINDOW_S:.0f} s "
            f"({said}): "
            "the current it claims is inside its own one-sigma, an estimate that is then "
            f"worse than zero; {', '.join(axes)} withheld (std_ kept) until it is "
            "resolved; a velocity source of lower noise ([sensors.gnss] "
            "velocity_std_mps, a DVL) resolves it (docs/integrity.md)"), details=(
            f"judged where the one-sigma exceeds {RESOLVE_MIN_STD_MPS} m/s: the filter "
            "follows its measurements' noise, whose variance is about half its claimed "
            "one's"))

    def _idle_current(self, pipeline: str, qs: tuple[str, ...], t: float,
                      values: dict[str, float]) -> None:
        """At a tick after a fix during an idle span, the current ``qs`` (north, east) in
        ``values`` (before anything is withheld) against the idle drift
        (:class:`IdleDriftCheck`)."""
        sq = ["std_" + q for q in qs]
        if len(qs) != 2 or not all(q in values for q in (*qs, *sq)):
            return
        idle = self.idle
        verdict = idle.judge((values[qs[0]], values[qs[1]]),
                             (values[sq[0]] ** 2, values[sq[1]] ** 2))
        if verdict is None:
            return
        self._flag(pipeline, "current_idle_drift", verdict)
        if verdict and idle.last is not None:
            self._idle_warning(pipeline, t, idle.last)

    def _idle_warning(self, pipeline: str, t: float,
                      last: tuple[float, float, float, float, float]) -> None:
        dn, de, cn, ce, m = last
        self._warn("current_idle_drift", pipeline, t, (
            f"{pipeline} current {math.hypot(cn, ce):.2f} m/s is {m:.1f} sigma from the "
            f"drift over ground {math.hypot(dn, de):.2f} m/s with the thrusters idle: "
            "withheld until an idle drift agrees with it; its noise is set in "
            f"[pipelines.{pipeline}] (docs/integrity.md)"), details=(
            f"drift north/east {dn:.3f}/{de:.3f} m/s, current {cn:.3f}/{ce:.3f} m/s; the "
            f"drift is the slope of the fixes after {IDLE_SETTLE_S:.0f} s of idle commands "
            "(wind pushes a drifting boat too)"))

    # ------------------------------------------------------------------ records
    def withheld(self, pipeline: str) -> tuple[str, ...]:
        """The quantities of ``pipeline`` to publish as unknown now: its heading-
        dependent outputs while the heading disagrees with the course or the compass
        deviates (and its heading and position, each with its ``std_``, while the
        heading disagrees with the course); its speed with its ``std_`` while it
        disagrees with the measured speed or the course is behind the heading at speed
        (:attr:`HeadingCourseCheck.behind`, or the newest fix's alone,
        :attr:`HeadingCourseCheck.suspect`); its current while it disagrees with the idle
        drift, and the components of its current the data do not resolve."""
        flags = self.flags.get(pipeline) or set()
        p = self.watched.get(pipeline)
        hc = self.heading
        suspect = hc is not None and hc.suspect
        if (not flags and not suspect) or p is None:
            return ()
        out: tuple[str, ...] = ()
        own = tuple(getattr(p, "heading_estimate", ())) + tuple(p.position)
        own += tuple("std_" + q for q in own)   # its heading and position, with sigmas
        if "heading_course_mismatch" in flags:
            out = p.heading_dependent + own
        elif "compass_deviation" in flags:
            out = p.heading_dependent
        if "heading_source_mismatch" in flags:
            out += tuple(q for q in own if q not in out)
        if "speed_mismatch" in flags or suspect or (
                "heading_course_mismatch" in flags and hc is not None and hc.behind):
            out += tuple(q for q in (*p.speed, *("std_" + q for q in p.speed))
                         if q not in out)
        if "current_idle_drift" in flags:
            out += tuple(q for q in getattr(p, "current_estimate", ()) if q not in out)
        if "current_unresolved" in flags:
            out += tuple(q for q in self.resolution[pipeline].unresolved() if q not in out)
        return out

    @property
    def amends(self) -> bool:
        """Whether :meth:`amend` may judge or change a record now: while a watched
        pipeline publishes a current (its resolution is judged at every tick), during an
        idle span or while the compass deviation is significant."""
        dc = self.deviation
        return (self._resolving or self.idle.idle_since is not None
                or (dc is not None and dc.deviated) or self.sources.widens)

    def amend(self, pipeline: str, t: float, values: dict[str, float]) -> None:
        """A pipeline's values at ``t`` (s) before its record is made: its current (the
        ``current_estimate`` role) judged for its resolution (:class:`CurrentResolution`)
        and against the idle drift at a tick after a fix of an idle span, and the sigma of its heading (``heading_estimate``) widened in
        ``values`` by the compass deviation at that heading while the deviation exceeds
        the sigma (``compass_deviation`` on the pipeline): ``std <- hypot(std, d(psi))``;
        likewise by the mean difference between the selected heading and the navigation
        solution's own (:class:`HeadingSourceCheck`) while it exceeds the sigma (below
        :data:`HEADING_SOURCE_BOUND_RAD`, where ``heading_source_mismatch`` withholds the
        heading)."""
        p = self.watched.get(pipeline)
        if p is None:
            return
        currents = tuple(getattr(p, "current_estimate", ()))
        if currents:
            self._resolution(pipeline, t, values, currents)
        if self._fix_new and self.idle.idle_since is not None:
            self._idle_current(pipeline, tuple(getattr(p, "current_estimate", ())), t,
                               values)
        qs = getattr(p, "heading_estimate", ())
        if not qs:
            return
        q, sq = qs[0], "std_" + qs[0]
        offset = self.sources.widening_at(t)
        if offset is not None and sq in values and abs(offset) > values[sq]:
            values[sq] = math.hypot(values[sq], offset)
        dc = self.deviation
        if dc is None or not dc.deviated or q not in values or sq not in values:
            return
        rms = dc.rms()
        on = rms > values[sq]
        was = "compass_deviation" in self.flags.get(pipeline, ())
        self._flag(pipeline, "compass_deviation", on)
        if on:
            values[sq] = math.hypot(values[sq], dc.fit.deviation(values[q]))
            if not was:
                self._deviation_warning(pipeline, t)

    def count_withheld(self, pipeline: str, n: int) -> None:
        """``n`` values of ``pipeline`` were left out of its record."""
        self.flagged[pipeline] = self.flagged.get(pipeline, 0) + n
        if n:
            self.withheld_rows[pipeline] = self.withheld_rows.get(pipeline, 0) + 1

    def positions_at(self, t: float, computed: Sequence[tuple[str, Mapping[str, float]]]
                     ) -> None:
        """At the first tick (at ``t``) after a fix, compare each watched pipeline's
        ``position`` (in its frame, with its ``std_`` columns) with it; ``computed``: each
        pipeline's name and values as it stepped, before any is withheld, so that a
        position withheld while the heading is contradicted is still judged."""
        fix = self._fix
        if not self._fix_new or fix is None or self.frame is None:
            return
        self._fix_new = False
        dt = t - fix.t
        if dt > self.fix_max_age_s:
            return
        dn = de = 0.0
        if fix.sog_mps is not None and fix.cog_rad is not None:
            dn = fix.sog_mps * math.cos(fix.cog_rad) * dt
            de = fix.sog_mps * math.sin(fix.cog_rad) * dt
        acc = fix.h_acc_m
        var_fix = (acc * acc if acc is not None and acc > 0 and math.isfinite(acc)
                   else self.fix_std_m ** 2)
        in_frame: dict[LocalFrame, tuple[float, float]] = {}  # the fix, once per frame
        watched = self.watched
        for name, values in computed:
            p = watched.get(name)
            if p is not None and p.position:
                self._position(name, t, values, p, fix, (dn, de), var_fix, in_frame)

    def _position(self, pipeline: str, t: float, v: Mapping[str, float], p: Declared,
                  fix: GnssFix, moved: tuple[float, float], var_fix: float,
                  in_frame: dict[LocalFrame, tuple[float, float]]) -> None:
        """One pipeline's comparison (its values ``v`` at ``t``) with ``fix``, moved by
        ``moved`` (m) to the tick; ``in_frame`` holds the fix's north/east (m) in the
        frames converted so far."""
        own = p.frame
        qn, qe = p.position
        sn, se = "std_" + qn, "std_" + qe
        if own is None or not all(k in v and math.isfinite(v[k]) for k in (qn, qe, sn, se)):
            return
        offset = p.frame_offset
        frame = own if offset is not None else self.frame
        assert frame is not None  # positions_at compares only once it has a frame
        off_n, off_e = offset if offset is not None else (0.0, 0.0)
        ne = in_frame.get(frame)
        if ne is None:
            ne = in_frame[frame] = frame.to_ne(fix.lat_deg, fix.lon_deg)
        fn, fe = ne
        res = (v[qn] - (fn + off_n + moved[0]), v[qe] - (fe + off_e + moved[1]))
        var = (v[sn] ** 2 + var_fix, v[se] ** 2 + var_fix)
        self._position_nees(pipeline, t, res, var, var_fix)
        check = self.positions.get(pipeline)
        if check is None:
            check = self.positions[pipeline] = PositionCheck()
        verdict = check.add(t, res, var)
        if verdict is None:
            return
        self._flag(pipeline, "position_residual", verdict)
        if verdict and self._due("position_residual", pipeline, t):
            self._warn("position_residual", pipeline, t, (
                f"{pipeline} position is {check.median_m():.1f} m from GNSS "
                f"({check.median_sigma():.1f} sigma): its position and sigma are not to be "
                f"trusted; the fix's sigma is [sensors.gnss] position_std_m when it reports "
                f"none, the filter's noise in [pipelines.{pipeline}] (docs/integrity.md)"),
                details=(f"the median over {POSITION_WINDOW_S:.0f} s, with its stated "
                         f"{math.sqrt(v[sn] ** 2 + v[se] ** 2):.1f} m and the fix's "
                         f"{math.sqrt(var_fix):.1f} m"
                         + (REORIGINED if own is not frame and (own.lat0, own.lon0)
                            != (frame.lat0, frame.lon0) else "")))

    def _position_nees(self, pipeline: str, t: float, res: tuple[float, float],
                       var: tuple[float, float], var_fix: float) -> None:
        """The position NEES of ``pipeline`` at ``t`` against a fix of variance
        ``var_fix`` (m^2) better than the estimate on both axes (``var`` the sum of both,
        per axis); ``position_inconsistent`` while its :class:`PositionNeesCheck`
        fails."""
        lim = (1.0 + POSITION_NEES_FIX_RATIO) * var_fix
        if not (var[0] > lim and var[1] > lim):
            return
        check = self.position_nees.get(pipeline)
        if check is None:
            check = self.position_nees[pipeline] = PositionNeesCheck()
        was = check.failing
        now = check.add(res[0] * res[0] / var[0] + res[1] * res[1] / var[1])
        if now and check.first_failed is None:
            check.first_failed = t
        if now and self._due("position_inconsistent", pipeline, t):
            lo, hi = check.band
            self._warn("position_inconsistent", pipeline, t, (
                f"{pipeline} position: mean NEES {check.mean:.2f} against the fixes "
                f"better than it, outside [{lo:.2f}, {hi:.2f}]: its position sigma "
                + ("is too small" if check.mean > hi else "is larger than its error")
                + " (docs/integrity.md)"), details=(
                f"each block of {NIS_BLOCK_UPDATES} comparisons (dof 2; lag-1 "
                f"autocorrelation {check.rho:.2f})"), t_start=check.first_failed)
        if now != was:
            self._flag(pipeline, "position_inconsistent", now)

    # ------------------------------------------------------------------ speeds
    def _doppler(self, s: GnssFix) -> None:
        """A fix's speed over ground, to compare at the next tick."""
        sog = s.sog_mps
        if sog is None or not math.isfinite(sog):
            return
        acc = s.speed_acc_mps
        std = acc if acc is not None and acc > 0 and math.isfinite(acc) \
            else self.speed_std_mps
        self._speed_refs.append((s.t, sog, std * std, GNSS_DOPPLER))

    def _dvl(self, s: DvlVelocity) -> None:
        """A valid bottom-track report's forward speed, to compare at the next tick."""
        if s.track != "bottom" or not s.valid or not math.isfinite(s.vx):
            return
        fom = s.fom_mps
        std = fom if fom is not None and fom > 0 and math.isfinite(fom) else self.dvl_std_mps
        self._speed_refs.append((s.t, s.vx, std * std, "DVL"))

    def speeds_at(self, t: float, computed: Sequence[tuple[str, Mapping[str, float]]]
                  ) -> None:
        """Compare the pipelines' speeds at the tick at ``t`` (``computed``: each
        pipeline's name and values as it stepped, before any is withheld, so that a
        speed withheld for this check is still judged and its flag can clear) with the
        newest measurement of each kind since the previous tick (arrived at most
        :data:`FIX_MAX_AGE_S` before it)."""
        refs = self._speed_refs
        if not refs:
            return
        newest = {ref[3]: ref for ref in refs
                  if t - ref[0] <= (self.fix_max_age_s if ref[3] == GNSS_DOPPLER
                                    else FIX_MAX_AGE_S)}
        refs.clear()
        watched = self.watched
        for name, values in computed:
            p = watched.get(name)
            if p is not None and p.speed:
                for ref in newest.values():
                    self._speed(name, t, values, p.speed, ref)

    def _speed(self, pipeline: str, t: float, values: Mapping[str, float],
               qs: tuple[str, ...], ref: tuple[float, float, float, str]) -> None:
        """One pipeline's comparison with one measured speed; ``qs``: its speed role."""
        _, measured, var_ref, what = ref
        dvl = what == "DVL"
        own = _computed_speed(qs, values, forward_only=dvl)
        if own is None:
            return
        speed = own[0] if dvl else abs(own[0])
        per = self.speeds.setdefault(pipeline, {})
        check = per.get(what)
        if check is None:
            check = per[what] = SpeedCheck()
        verdict = check.add(t, speed - measured, own[1] + var_ref)
        if verdict is None:
            return
        self._flag(pipeline, "speed_mismatch", any(c.failing for c in per.values()))
        if verdict and self._due("speed_mismatch", pipeline, t):
            self._warn("speed_mismatch", pipeline, t, (
                f"{pipeline} speed is " + (
                    f"{check.median_mps():.2f} m/s" if check.gross_rms is None else
                    f"{check.gross_rms_mps():.2f} m/s RMS") + f" from the {what} speed: "
                "its speed and sigma are not to be trusted; onboard diagnose LOG names what "
                f"its model lacks, [pipelines.{pipeline}] sets its noise "
                "(docs/integrity.md)"), details=(
                (f"the median over {SPEED_WINDOW_S:.0f} s" if check.gross_rms is None else
                 f"over the last {SPEED_GROSS_WINDOW_S:.0f} s, {check.gross_rms:.1f} sigma "
                 "RMS")
                + f", with its stated {math.sqrt(own[1]):.2f} m/s and the measurement's "
                f"{math.sqrt(var_ref):.2f} m/s"))

    # ------------------------------------------------------------------ innovations
    def innovations(self, pipeline: str, records: Iterable[Innovation]) -> None:
        """The innovation records of one pipeline's tick: each accepted NIS into its
        channel's :class:`NisCheck`."""
        per = self.nis.get(pipeline)
        for rec in records:
            nis = rec.nis
            if not rec.accepted or not math.isfinite(nis) \
                    or rec.channel in NIS_EXEMPT_CHANNELS:
                if rec.reason in RESTART_REASONS and per and rec.channel in per:
                    per[rec.channel].t_start = None  # settles again from its prior
                continue
            if per is None:
                per = self.nis[pipeline] = {}
            check = per.get(rec.channel)
            if check is None or check.dof != rec.dof:
                check = per[rec.channel] = NisCheck(rec.dof)
            if check.t_start is None:
                check.t_start = rec.t
            adapted = self._adapted(pipeline, rec.channel)
            if adapted and not check.adapted:   # its blocks so far judged another filter
                check.restart()
            check.adapted = adapted
            was = self._failing(pipeline, rec.channel, check)
            check.add(nis / self._published_factor(pipeline, rec.channel),
                      check.judges_next and (
                          rec.t - check.t_start < NIS_SETTLE_S
                          or self._slow_error_holds(pipeline, rec.channel)))
            if not check._n:  # a block was judged: its mean into the run's
                self._run_mean(pipeline, rec.channel, check, rec.t)
            now = self._failing(pipeline, rec.channel, check) and adapted
            if now:
                if check.first_failed is None:
                    check.first_failed = rec.t
                if self._due("nis_out_of_band", pipeline, rec.t, rec.channel):
                    self._nis_warning(pipeline, rec.channel, check, rec.t)
            elif check.failing and adapted:
                self._band_note(pipeline, rec.channel, check, rec.t)
            if now != was:
                self._flag(pipeline, "nis_out_of_band", any(
                    self._failing(pipeline, c, k) for c, k in per.items()))

    def _failing(self, pipeline: str, channel: str, check: NisCheck) -> bool:
        """Whether the channel's check fails as an inconsistency: not on a side where its
        band is information (:meth:`_is_information`, :meth:`_band_note`)."""
        return check.failing and not self._is_information(pipeline, channel,
                                                          check.outside > 0)

    def _run_mean(self, pipeline: str, channel: str, check: NisCheck, t: float) -> None:
        """The block ``check`` has just judged into the channel's run mean;
        ``nis_far_above`` (once per channel) when it is far above its degrees of
        freedom."""
        dof = check.dof
        per = self.run_means.setdefault(pipeline, {})
        rm = per.get(channel)
        if rm is None or rm.dof != dof:
            rm = per[channel] = NisRunMean(dof)
        if not rm.add_block(check.mean, NIS_BLOCK_UPDATES):
            return
        self._flag(pipeline, "nis_far_above", True)
        self._warn("nis_far_above", pipeline, t, (
            f"{pipeline} {channel}: mean NIS {rm.mean:.1f} over {rm.n} updates, "
            f"{rm.mean / dof:.0f} times a consistent filter's {dof}: its innovations are "
            "not what its model predicts; a heading off the course over ground, an input "
            f"model that diverges, or its noise in [pipelines.{pipeline}] "
            "(docs/integrity.md)"), key=channel, details=(
            f"the mean of every accepted update so far against {NIS_FAR_FACTOR:.0f} times "
            "its degrees of freedom; rare huge innovations carry such a mean while most "
            "blocks stay in their band"))

    def counters_at(self, t: float) -> None:
        """Every :data:`DIVERGENCE_WINDOW_S`, the watched pipelines' input-model
        divergence counters (``*.diverged`` of their health); a storm is
        ``input_model_divergence`` on the pipeline, raised once per counter."""
        dc = self.divergences
        if not dc.due(t):
            return
        counters: dict[str, float] = {}
        for name, p in self.watched.items():
            health = getattr(p, "health", None)
            if health is None:
                continue
            for k, v in health().flat().items():
                if k.endswith(".diverged") and math.isfinite(v):
                    counters[f"{name}:{k}"] = v
        for key in dc.window(t, counters):
            name, axis = key.split(":", 1)
            n, span = dc.storms[key]
            self._flag(name, "input_model_divergence", True)
            self._warn("input_model_divergence", name, t, (
                f"{name} {axis.removesuffix('.diverged')} input model diverged {n:.0f} "
                f"times in {span:.0f} s (every {span / n:.1f} s): its estimate restarts "
                "each time and its sigma does not count it; a heading off the course, or "
                f"its divergence bounds in [pipelines.{name}] (docs/integrity.md)"),
                key=axis, t_start=dc.first[key])

    def _learned(self, pipeline: str, channel: str) -> object | None:
        """The channel's learned noise (a :class:`.NoiseScale`), None if its pipeline
        learns none for it."""
        noise = getattr(self.watched.get(pipeline), "noise", None)
        report = getattr(noise, "report", None)
        return report(channel) if report is not None else None

    def _published_factor(self, pipeline: str, channel: str) -> float:
        """The variance factor the pipeline's published sigma applies to what ``channel``
        measures (1: none): its NIS is judged over it, against the covariance the
        published sigma claims (an NIS out of band first drives that factor; algorithms.md
        §9.1)."""
        noise = getattr(self.watched.get(pipeline), "noise", None)
        published = getattr(noise, "published_factor", None)
        return published(channel) if published is not None else 1.0

    def _slow_error_holds(self, pipeline: str, channel: str) -> bool:
        """Whether the published sigma of what ``channel`` measures is held up by errors
        slower than its innovations show (``ChannelNoise.slow_error_holds``): its NIS is
        then not judged below its band."""
        noise = getattr(self.watched.get(pipeline), "noise", None)
        holds = getattr(noise, "slow_error_holds", None)
        return holds is not None and holds(channel)

    def _adapted(self, pipeline: str, channel: str) -> bool:
        """Whether the channel's NIS may be judged: its noise is not learned, has had its
        samples, or had none to learn from in a full window of updates (an NIS out of
        band first drives the adaptation; a channel whose forecast always dominates
        adapts nothing). Blocks judged before it adapted are dropped when it does
        (:meth:`NisCheck.restart`): the warning is about the adapted filter."""
        learned = self._learned(pipeline, channel)
        if learned is None or bool(getattr(learned, "learned", True)):
            return True
        return getattr(learned, "n", 0) == 0 and bool(
            getattr(getattr(learned, "consistency", None), "full", True))

    def _is_information(self, pipeline: str, channel: str, above: bool) -> bool:
        """Whether ``channel``'s NIS out of its band on that side is information: either
        side on one of the pipeline's ``regression_channels``; below on one of its
        ``unpublished_channels`` or ``calibrating_channels``."""
        p = self.watched.get(pipeline)
        if channel in getattr(p, "regression_channels", ()):
            return True
        return not above and (channel in getattr(p, "unpublished_channels", ())
                              or self._calibrating(pipeline, channel))

    def _calibrating(self, pipeline: str, channel: str) -> bool:
        """Whether ``channel`` is one of the pipeline's ``calibrating_channels``."""
        return channel in getattr(self.watched.get(pipeline), "calibrating_channels", ())

    def _band_note(self, pipeline: str, channel: str, check: NisCheck, t: float) -> None:
        """Once per channel, side and run: the channel's NIS out of its band as
        information (no flag; :meth:`_is_information`): ``nis_unpublished``, a
        regression's residual or the forecast of a quantity published without a sigma;
        ``nis_corrected``, the filter's forecast is conservative and the published sigma,
        corrected from these innovations, is not."""
        above = check.outside > 0
        noted = self._noted_below.setdefault(pipeline, [])
        tag = channel + (" (above)" if above else "")
        if tag in noted:
            return
        before = f" (noted before: {', '.join(noted)})" if noted else ""
        noted.append(tag)
        code, what, why = self._note_text(pipeline, channel, above)
        self.alerts.warn(code, (
            f"{pipeline} {channel}: mean NIS {_nis_vs_band(check, 'above' if above else 'below')}"
            ": information, not an "
            f"inconsistency: {what}{before} (docs/integrity.md)"), t,
            pipeline=pipeline, details=(
                f"each block of {NIS_BLOCK_UPDATES} updates against its {NIS_BAND:.0%} "
                f"band, for {abs(check.outside)} blocks in a row (dof {check.dof}; lag-1 "
                f"autocorrelation {check.rho:.2f}); {why}"))

    def _note_text(self, pipeline: str, channel: str, above: bool) -> tuple[str, str, str]:
        """The code, what the note says and why, for :meth:`_band_note`."""
        if channel in getattr(self.watched.get(pipeline), "regression_channels", ()):
            return "nis_unpublished", (
                "the channel is a regression's a-priori residual, whose variance is the "
                "regression's own running mean of its residuals: no gain uses it and no "
                "published sigma takes it; its residual is "
                + ("larger than that mean (a manoeuvre, the coefficients still converging)"
                   if above else "smaller than that mean (a straight leg, its start)")
                + f"; the mean's memory is [pipelines.{pipeline}]'s forgetting"), (
                "no configuration key sets that variance; it follows the residuals over "
                "the regression's forgetting memory (algorithms.md §9.2)")
        if self._calibrating(pipeline, channel):
            return "nis_corrected", (
                "the channel's innovations correct the published sigma both ways, and the "
                "forecast the filter's gain uses is more conservative than they show (its "
                f"process noise in [pipelines.{pipeline}], set for the controller)"), (
                "the published sigma is narrowed from these innovations (algorithms.md "
                "§5.1); the filter's covariance keeps its tuning")
        return "nis_unpublished", (
            "the channel forecasts what the pipeline publishes without a sigma, and "
            "that forecast is more conservative than its innovations show (its "
            f"process noise in [pipelines.{pipeline}])"), (
            "no published sigma takes a factor from these channels (algorithms.md "
            "§9.2)")

    def _nis_remedy(self, pipeline: str, channel: str, check: NisCheck) -> str:
        """What to change, with the key and a value from the data: the learned noise's
        when it sits at its bound on the failing side, or is learned below the declared
        and not applied; above the band, no key where the forecast would have to be more
        than :data:`FORECAST_FACTOR_MAX` times wider; else the process noise that sets
        the channel's forecast (:meth:`_forecast_remedy`)."""
        above = check.mean > check.band[1]
        n = self._learned(pipeline, channel)
        if n is not None and n.learned and (above or n.identified):  # type: ignore[attr-defined]
            if n.at_bound == (1 if above else -1):  # type: ignore[attr-defined]
                return (f"its learned noise is at its {'ceiling' if above else 'floor'}: "
                        f"set {_learned_key(n, '>=' if above else '<=')}")
            if not above and n.scale < 1.0 and n.applied == 1.0:  # type: ignore[attr-defined]
                return ("its noise is learned below the declared and not applied (the "
                        f"filter keeps the declared): set {_learned_key(n)}")
        if above:
            r, _, phi, c = self._forecast_factor(pipeline, channel, check, n)
            if r > 1.0 and c > FORECAST_FACTOR_MAX:
                learned = (f"its measurement noise is learned ({_learned_key(n)}), and "
                           if n is not None and n.learned and n.identified else "")  # type: ignore[attr-defined]
                return (f"no key's value explains it: {learned}the forecast is {phi:.0%} "
                        f"of S and would have to be {c:.2g} times wider (a tuning is at "
                        f"most {FORECAST_FACTOR_MAX:g}; the filter's own NIS {r:.3g} per "
                        "degree of freedom): the innovations carry an error the filter "
                        "does not model (a manoeuvre, a heading source off the course, "
                        "outliers; the other warnings of this stretch name them)")
        forecast = self._forecast_remedy(pipeline, channel, check, n)
        if n is not None and n.learned and n.identified:  # type: ignore[attr-defined]
            return (f"its measurement noise is learned ({_learned_key(n)}), the rest is "
                    f"the forecast's: {forecast}")
        if n is not None and not above:
            return (f"the innovations are smaller than its forecast alone explains "
                    f"({n.key} cannot be learned from them): {forecast}")  # type: ignore[attr-defined]
        return forecast

    def _forecast_factor(self, pipeline: str, channel: str, check: NisCheck,
                         n: object | None) -> tuple[float, float, float, float]:
        """``(r, pf, phi, c)``: the filter's own block-mean NIS per degree of freedom
        ``r`` (the check's, against the published sigma, times the published factor
        ``pf``), the forecast's share ``phi`` of ``S`` and the factor ``c = 1 + (r - 1) /
        phi`` on the forecast's variance that brings the NIS to 1."""
        pf = self._published_factor(pipeline, channel)
        r = check.mean * pf / check.dof
        phi = _forecast_share(n)
        return r, pf, phi, 1.0 + (r - 1.0) / phi

    def _forecast_remedy(self, pipeline: str, channel: str, check: NisCheck,
                         n: object | None) -> str:
        """The process noise that sets the channel's forecast, scaled so that the NIS
        comes to 1 (algorithms.md §9.2): with ``r`` the filter's own block-mean NIS per
        degree of freedom and ``phi`` the forecast's share of ``S``, the forecast's
        variance times ``c = 1 + (r - 1) / phi``; the key the pipeline names for the
        channel (``forecast_noise``), its variance in proportion to the forecast's. Where
        ``c`` would be below :data:`FORECAST_FACTOR_MIN` the measurement noise alone is
        larger than the innovations: its key and the value ``r / (1 - phi)`` of the noise
        applied. Where the NIS is above its band only against a published sigma narrowed
        by its consistency factor (``r`` at most 1), that factor is what is wrong."""
        r, pf, phi, c = self._forecast_factor(pipeline, channel, check, n)
        if check.mean > check.band[1] and r <= 1.0:
            return (f"the filter's own innovations are within what it expects (NIS {r:.3g} "
                    f"per degree of freedom); the published sigma's consistency factor "
                    f"{pf:.2g} on its variance (algorithms.md §9.1) narrows it below them: "
                    f"no key of [pipelines.{pipeline}] sets that factor")
        quiet = ""
        if c < FORECAST_FACTOR_MIN and n is not None and phi < 1.0:
            s = r / (1.0 - phi)
            quiet = (f"; the innovations are smaller than its measurement noise alone "
                     f"({s:.2g} of its variance): set "
                     f"{_learned_key(n, value=n.declared * math.sqrt(n.applied * s))}")  # type: ignore[attr-defined]
        c = max(c, FORECAST_FACTOR_MIN)
        how = (f"the forecast's variance times {c:.2g} brings the NIS to 1 (the filter's "
               f"own NIS {r:.3g} per degree of freedom, the forecast {phi:.0%} of S)")
        name = getattr(self.watched.get(pipeline), "forecast_noise", None)
        key = name(channel) if name is not None else None
        if key is None:
            return f"the process noise in [pipelines.{pipeline}]: {how}{quiet}"
        k, value, unit, power = key
        return (f"the forecast's process noise: set {k} = {value * c ** (1.0 / power):.3g} "
                f"(now {value:.3g} {unit}; {how}, taken in proportion to this key's "
                f"variance){quiet}")

    def _nis_warning(self, pipeline: str, channel: str, check: NisCheck, t: float) -> None:
        lo, hi = check.band
        how = ("larger than the filter expects: its sigmas are too small"
               if check.mean > hi else "smaller than the filter expects: its sigmas are "
               "larger than its errors")
        self._warn("nis_out_of_band", pipeline, t, (
            f"{pipeline} {channel}: mean NIS {_nis_vs_band(check)}, the innovations {how}; "
            f"{self._nis_remedy(pipeline, channel, check)} (docs/integrity.md)"), details=(
            f"each block of {NIS_BLOCK_UPDATES} updates against its {NIS_BAND:.0%} band, "
            f"for {abs(check.outside)} blocks in a row (dof {check.dof}; lag-1 "
            f"autocorrelation {check.rho:.2f})"), key=channel, t_start=check.first_failed)

    # ------------------------------------------------------------------ flags
    def _flag(self, pipeline: str, code: str, on: bool) -> None:
        flags = self.flags.setdefault(pipeline, set())
        if on:
            flags.add(code)
        else:
            flags.discard(code)

    def active(self) -> dict[str, list[str]]:
        """pipeline -> the codes it fails now (sorted; pipelines with none left out)."""
        return {p: sorted(f) for p, f in self.flags.items() if f}

    def _warn(self, code: str, pipeline: str, t: float, message: str, key: str = "",
              t_start: float | None = None, details: str = "") -> None:
        """Raise ``code`` at ``t`` (s) at most every :data:`WARN_EVERY_S` per (code,
        pipeline, key), spanning from ``t_start`` (default ``t``); ``message`` the
        actionable line, ``details`` after it."""
        if not self._due(code, pipeline, t, key):
            return
        self._last_warn[(code, pipeline + ":" + key)] = t
        self.alerts.warn(code, message, t if t_start is None else t_start,
                         pipeline=pipeline, t_end=t, details=details)

    def _due(self, code: str, pipeline: str, t: float, key: str = "") -> bool:
        """Whether :meth:`_warn` would raise ``code`` at ``t`` (s): a message is composed
        (window medians sorted) only when it is (a failing check fails at every fix)."""
        last = self._last_warn.get((code, pipeline + ":" + key))
        return last is None or not 0.0 <= t - last < WARN_EVERY_S
