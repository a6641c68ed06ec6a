"""Surge and heading models of a small boat, their measurements, and their identification.

Faros & Tanner, "System Identification and Adaptive Input Estimation on the Jaiabot",
arXiv 2504.02005 (2025), restated in algorithms.md §1:

* continuous model (§1.1), per axis, with mass/inertia normalized to 1::

      v' = -a v + u        (surge: v path speed m/s, u = tau/m in m/s^2)
      r' = -a_psi r + u    (heading: r yaw rate rad/s, u = tau_psi/I in rad/s^2)

* exact zero-order-hold discretization (§1.2) and the increment output
  ``y_k = s_k - s_{k-1}`` (path length, m) or ``wrap(psi_k - psi_{k-1})`` (rad);
* the measured increments from GPS and compass (§1.3), with the circular-arc correction;
* identification of ``a`` and of the input scaling ``u = gain * command + offset`` from a
  log by least squares, in the ARX form of §1.2 or as a separable output-error fit.

The input is an acceleration (the §1.1 recommendation m := 1). The command is the
normalized actuator command of :class:`onboard.core.messages.ActuatorCommand` reduced to one
number per axis by :func:`axis_commands` (throttle/rudder, or sum/difference of the two
thrusters of a skid-steered boat).

Pure functions of numbers; only :func:`identify_axis` and friends use numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, Sequence

import numpy as np
from numpy.typing import ArrayLike

from onboard.core.geo import wrap_pi
from onboard.core.messages import ActuatorCommand

_A_SMALL = 1e-6
"""Below this |a*Ts| the ZOH coefficients use their series limits (§1.2)."""

InputMode = Literal["auto", "throttle-rudder", "differential"]


@dataclass(frozen=True, slots=True)
class AxisModel:
    """One axis of the §1.1 model: ``x' = -a x + u``, ``u = gain * command + offset``.

    Attributes:
        a: damping rate (1/s); ``a = d/m`` (surge) or ``d_psi/I`` (heading).
        gain: input per unit normalized command (m/s^2 or rad/s^2 per unit).
        offset: input at zero command (same unit as ``u``).
        rmse: fit residual (unit of the fitted signal), NaN when not identified.
        fit_ratio: explained fraction of the fitted signal's variance, NaN when unknown.
    """

    a: float
    gain: float
    offset: float = 0.0
    rmse: float = math.nan
    fit_ratio: float = math.nan

    def input(self, command: float) -> float:
        """The modelled input ``u`` (m/s^2 or rad/s^2) for a normalized command."""
        return self.gain * command + self.offset

    def to_dict(self) -> dict[str, float]:
        """The model as a JSON-serializable dict (``a``, ``gain``, ``offset``, ``rmse``,
        ``fit_ratio``)."""
        return {"a": self.a, "gain": self.gain, "offset": self.offset,
                "rmse": self.rmse, "fit_ratio": self.fit_ratio}

    def __deepcopy__(self, memo: dict) -> AxisModel:
        """Itself: it is immutable (a copy of a pipeline shares it)."""
        return self


@dataclass(frozen=True, slots=True)
class Discrete:
    """ZOH coefficients of one axis over a step ``dt`` (§1.2).

    ``alpha = exp(-a dt)``, ``c1 = (1 - alpha)/a`` (-> dt), ``c2 = (dt - c1)/a``
    (-> dt^2/2). Then ``v+ = alpha v + c1 u`` and ``s+ = s + c1 v + c2 u``.
    """

    dt: float
    alpha: float
    c1: float
    c2: float

    def __deepcopy__(self, memo: dict) -> Discrete:
        """Itself: it is immutable (a copy of a pipeline shares it)."""
        return self


def discretize(a: float, dt: float) -> Discrete:
    """Exact ZOH discretization of ``x' = -a x + u`` over ``dt`` seconds (§1.2)."""
    if dt <= 0.0:
        raise ValueError(f"step must be positive, got {dt}")
    x = a * dt
    alpha = math.exp(-x)
    if abs(x) < _A_SMALL:
        c1 = dt * (1.0 - x / 2.0)
        c2 = dt * dt * (0.5 - x / 6.0)
    else:
        c1 = -math.expm1(-x) / a
        c2 = (dt - c1) / a
    return Discrete(dt, alpha, c1, c2)


DT_DIGITS = 4
"""Steps are discretized at dt rounded to this many decimals (0.1 ms), so that steps of
nearly equal length share one set of coefficients."""
CACHE_SIZE = 64
"""Coefficient sets kept by :class:`Discretization` before it starts afresh."""


class Discretization:
    """:func:`discretize` memoized on ``(a, dt)`` with ``dt`` rounded to
    :data:`DT_DIGITS` decimals (the steps between measurement points repeat)."""

    def __init__(self) -> None:
        self._cache: dict[tuple[float, float], Discrete] = {}
        self._exact: dict[tuple[float, float], Discrete] = {}
        """The same coefficients by the unrounded ``(a, dt)``: a step of a length seen
        before skips the rounding (``round(dt, 4)`` is the costly part of a call)."""

    def __call__(self, a: float, dt: float) -> Discrete:
        """The coefficients of ``x' = -a x + u`` over ``dt`` (s) rounded; a positive
        ``dt`` below the resolution takes the resolution (it must not round to zero)."""
        d = self._exact.get((a, dt))
        if d is None:
            d = self._rounded(a, dt)
            if len(self._exact) > CACHE_SIZE:
                self._exact.clear()
            self._exact[(a, dt)] = d
        return d

    def _rounded(self, a: float, dt: float) -> Discrete:
        """:meth:`__call__` by the rounded ``dt``."""
        key = (a, max(round(dt, DT_DIGITS), 10.0 ** -DT_DIGITS))
        d = self._cache.get(key)
        if d is None:
            if len(self._cache) > CACHE_SIZE:
                self._cache.clear()
            d = self._cache[key] = discretize(a, key[1])
        return d


def augmented_matrices(a: float, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The §1.2 augmented model ``X = [s, v, s_prev]``: ``(A, B, C)``, ``y = C X``.

    Provided for reference and tests; the filters run the equivalent two-state increment
    form (see :mod:`onboard.estimators.kalman`).
    """
    d = discretize(a, dt)
    A = np.array([[1.0, d.c1, 0.0], [0.0, d.alpha, 0.0], [1.0, 0.0, 0.0]])
    B = np.array([d.c2, d.c1, 0.0])
    C = np.array([1.0, 0.0, -1.0])
    return A, B, C


def arx_coefficients(a: float, dt: float) -> tuple[float, float, float]:
    """``(alpha, beta0, beta1)`` of ``y_{k+1} = alpha y_k + beta0 u_k + beta1 u_{k-1}``.

    §1.2: ``beta0 = c2`` (the first Markov parameter C B) and
    ``beta1 = c1^2 - alpha beta0`` (unit input gain).
    """
    d = discretize(a, dt)
    return d.alpha, d.c2, d.c1 * d.c1 - d.alpha * d.c2


# --------------------------------------------------------------------------------------
# Measurements (§1.3)


def heading_increment(psi_prev: float, psi: float) -> float:
    """Heading change (rad) from ``psi_prev`` to ``psi``, wrapped to (-pi, pi] (§1.2)."""
    return wrap_pi(psi - psi_prev)


def path_increment(dn: float, de: float, psi_prev: float, dpsi: float,
                   arc: bool = True) -> float:
    """Path length (m) travelled over one step, from the GPS displacement (§1.3).

    The displacement is projected on the mid-step heading ``psi_prev + dpsi/2`` (the
    direction of the chord of a circular arc) and scaled by the arc-to-chord ratio
    ``h / sin(h)``, ``h = dpsi/2``. The projection is linear in the displacement, so
    zero-mean GNSS noise leaves it unbiased; the chord's *magnitude* ``hypot(dn, de)``
    is not: the cross-track noise adds ``sigma_x^2 / (2 |d|)`` on average
    (docs/aie.md, "Unbiased increment").
    A crab angle ``beta`` between heading and track shortens the projection by
    ``1 - cos(beta)`` (0.4 % at 5 deg).

    Args:
        dn, de: displacement north/east (m) between consecutive fixes.
        psi_prev: heading (rad, clockwise from north) at the first fix.
        dpsi: wrapped heading change (rad) over the step.
        arc: apply the circular-arc correction; otherwise the plain projection of the
            displacement on the body x-axis at the first fix (the fallback of §1.3).

    Returns:
        The signed arc length: negative when the boat moved backwards.
    """
    if not arc:
        return math.cos(psi_prev) * dn + math.sin(psi_prev) * de
    mid = psi_prev + 0.5 * dpsi
    along = math.cos(mid) * dn + math.sin(mid) * de
    h = 0.5 * dpsi
    factor = 1.0 if abs(h) < 5e-4 else h / math.sin(h)
    return along * factor


def axis_commands(cmd: ActuatorCommand, mode: InputMode = "auto") -> tuple[float | None,
                                                                         float | None]:
    """Reduce an actuator command to ``(surge_command, yaw_command)`` (normalized).

    * ``throttle-rudder`` (Jaiabot-type): surge from ``throttle``, yaw from ``rudder_rad``
      (positive turns the bow to starboard).
    * ``differential`` (BlueBoat-type): surge from the mean ``(left + right)/2``, yaw from
      the half difference ``(left - right)/2`` (left ahead of right turns to starboard).
    * ``auto``: differential when both thruster fields are present, else throttle-rudder.

    A missing field gives None for that axis.
    """
    diff = cmd.left is not None and cmd.right is not None
    if mode == "differential" or (mode == "auto" and diff):
        if not diff:
            return None, None
        return 0.5 * (cmd.left + cmd.right), 0.5 * (cmd.left - cmd.right)  # type: ignore
    return cmd.throttle, cmd.rudder_rad


# --------------------------------------------------------------------------------------
# Identification (§1.2 ARX form, and the separable output-error refinement)

Signal = Literal["increment", "rate"]


def resample(t: ArrayLike, x: ArrayLike, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation of ``x(t)`` onto the grid ``t0 + k dt`` (s)."""
    ts = np.asarray(t, float)
    grid = np.arange(ts[0], ts[-1] + 1e-9, dt)
    return grid, np.interp(grid, ts, np.asarray(x, float))


def _regress(X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    res = y - X @ coef
    return coef, float(np.sqrt(np.mean(res * res)))


def _fit_arx(segs: list[tuple[np.ndarray, np.ndarray]], dt: float, signal: Signal,
             offset: bool) -> AxisModel:
    """Unconstrained least squares in the ARX form, then a, gain, offset (§1.2)."""
    rows, rhs = [], []
    for y, c in segs:
        if signal == "rate":  # x_{k+1} = alpha x_k + c1 (g c_k + o)
            cols = [y[:-1], c[:-1]] + ([np.ones(len(y) - 1)] if offset else [])
            rows.append(np.column_stack(cols))
            rhs.append(y[1:])
        else:  # y_{k+1} = alpha y_k + beta0 u_k + beta1 u_{k-1}, u_k feeds y_{k+1}
            # indices: y[k+1] ~ y[k], c[k], c[k-1]  (c[k] is the command over (k, k+1])
            cols = [y[1:-1], c[1:-1], c[:-2]] + ([np.ones(len(y) - 2)] if offset else [])
            rows.append(np.column_stack(cols))
            rhs.append(y[2:])
    X = np.vstack(rows)
    yy = np.concatenate(rhs)
    coef, rmse = _regress(X, yy)
    alpha = float(min(max(coef[0], 1e-6), 0.999999))
    a = -math.log(alpha) / dt
    d = discretize(a, dt)
    if signal == "rate":
        gain = coef[1] / d.c1
        off = coef[2] / d.c1 if offset else 0.0
    else:
        gain = coef[1] / d.c2
        off = coef[3] / (d.c2 + d.c1 * d.c1 - d.alpha * d.c2) if offset else 0.0
    var = float(np.var(yy)) or 1.0
    return AxisModel(a, float(gain), float(off), rmse, 1.0 - rmse * rmse / var)


def _simulate_basis(c: np.ndarray, a: float, dt: float, signal: Signal) -> np.ndarray:
    """Columns: the output of the model for unit gain, unit offset, unit initial state."""
    d = discretize(a, dt)
    n = len(c)
    out = np.zeros((n, 3))
    # state responses x_k for inputs: command (gain 1), constant 1 (offset), x0 = 1
    xs = np.zeros((n + 1, 3))
    xs[0] = (0.0, 0.0, 1.0)
    for k in range(n):
        xs[k + 1, 0] = d.alpha * xs[k, 0] + d.c1 * c[k]
        xs[k + 1, 1] = d.alpha * xs[k, 1] + d.c1
        xs[k + 1, 2] = d.alpha * xs[k, 2]
    if signal == "rate":
        out[:] = xs[:n]
    else:  # y_k = s_k - s_{k-1} = c1 x_{k-1} + c2 u_{k-1}
        out[1:, 0] = d.c1 * xs[: n - 1, 0] + d.c2 * c[: n - 1]
        out[1:, 1] = d.c1 * xs[: n - 1, 1] + d.c2
        out[1:, 2] = d.c1 * xs[: n - 1, 2]
    return out


def _fit_oe(segs: list[tuple[np.ndarray, np.ndarray]], dt: float, signal: Signal,
            offset: bool, a0: float) -> AxisModel:
    """Output-error fit: 1-D search over ``a``, linear least squares for the rest.

    For fixed ``a`` the simulated output is linear in (gain, offset, one initial state
    per segment), so the fit is separable; it is unbiased under white measurement noise
    where the ARX form is not (GPS increments have MA(1) noise, §1.3).
    """

    def solve(a: float) -> tuple[float, np.ndarray, float]:
        blocks, rhs = [], []
        nseg = len(segs)
        for i, (y, c) in enumerate(segs):
            basis = _simulate_basis(c, a, dt, signal)
            cols = [basis[:, 0]] + ([basis[:, 1]] if offset else [])
            x0 = np.zeros((len(y), nseg))
            x0[:, i] = basis[:, 2]
            blocks.append(np.column_stack(cols + [x0]))
            rhs.append(y)
            if signal == "increment":  # y_0 has no model value: drop it
                blocks[-1] = blocks[-1][1:]
                rhs[-1] = rhs[-1][1:]
        X = np.vstack(blocks)
        yy = np.concatenate(rhs)
        coef, rmse = _regress(X, yy)
        return rmse, coef, float(np.var(yy)) or 1.0

    lo, hi = math.log(max(a0, 1e-3) / 30.0), math.log(max(a0, 1e-3) * 30.0)
    grid = np.linspace(lo, hi, 25)
    costs = [solve(math.exp(g))[0] for g in grid]
    i = int(np.argmin(costs))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    phi = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - phi * (hi - lo), lo + phi * (hi - lo)
    f1, f2 = solve(math.exp(x1))[0], solve(math.exp(x2))[0]
    for _ in range(40):
        if f1 < f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - phi * (hi - lo)
            f1 = solve(math.exp(x1))[0]
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + phi * (hi - lo)
            f2 = solve(math.exp(x2))[0]
    a = math.exp(0.5 * (lo + hi))
    rmse, coef, var = solve(a)
    gain = float(coef[0])
    off = float(coef[1]) if offset else 0.0
    return AxisModel(a, gain, off, rmse, 1.0 - rmse * rmse / var)


def fit_axis(segments: Sequence[tuple[ArrayLike, ArrayLike]], dt: float,
             signal: Signal = "increment", method: Literal["arx", "oe"] = "oe",
             offset: bool = False) -> AxisModel:
    """Identify one axis from uniformly sampled segments (one per run).

    Args:
        segments: ``(y, command)`` pairs on a uniform grid of step ``dt``. ``y`` is the
            increment (m or rad per step, ``signal="increment"``) or the rate (m/s or
            rad/s, ``signal="rate"``); ``command[k]`` is the normalized command held over
            ``(k, k+1]``.
        dt: grid step (s).
        method: ``"arx"``: ordinary least squares in the ARX form of §1.2 (fast, biased
            toward small ``a`` by measurement noise); ``"oe"``: separable output-error
            least squares initialised by the ARX fit (default).
        offset: also fit a constant input ``offset`` (e.g. a thruster dead-band bias).

    Returns:
        The identified :class:`AxisModel` (``rmse`` in the unit of ``y``).
    """
    segs: list[tuple[np.ndarray, np.ndarray]] = []
    for y_seg, c_seg in segments:
        y = np.asarray(y_seg, float)
        c = np.asarray(c_seg, float)
        ok = np.isfinite(y) & np.isfinite(c)
        if not ok.all():  # split at gaps
            idx = np.flatnonzero(~ok)
            starts = np.concatenate(([0], idx + 1))
            ends = np.concatenate((idx, [len(y)]))
            segs += [(y[s:e], c[s:e]) for s, e in zip(starts, ends) if e - s > 4]
        elif len(y) > 4:
            segs.append((y, c))
    if not segs:
        raise ValueError("no segment long enough to identify a model")
    arx = _fit_arx(segs, dt, signal, offset)
    if method == "arx":
        return arx
    return _fit_oe(segs, dt, signal, offset, arx.a if math.isfinite(arx.a) else 1.0)


def identify_axis(t: Sequence[float], y: Sequence[float], command: Sequence[float],
                  dt: float | None = None, signal: Signal = "rate",
                  method: Literal["arx", "oe"] = "oe", offset: bool = False) -> AxisModel:
    """Identify ``a`` and the input scaling of one axis from one log (§1.2).

    ``t`` (s) may be irregular; ``y`` and ``command`` are interpolated onto a uniform grid
    of step ``dt`` (default: the median sample interval). For ``signal="increment"`` the
    increments are re-formed on the grid from the cumulative sum (so pass increments of
    consecutive samples). See :func:`fit_axis`.
    """
    if dt is None:
        dt = float(np.median(np.diff(np.asarray(t, float))))
    if signal == "increment":
        ya = np.asarray(y, float)
        _, sg = resample(t, np.concatenate(([0.0], np.cumsum(ya[1:]))), dt)
        yg = np.concatenate(([0.0], np.diff(sg)))
    else:
        _, yg = resample(t, y, dt)
    _, cg = resample(t, command, dt)
    return fit_axis([(yg, cg)], dt, signal, method, offset)


def identify_surge(t: Sequence[float], y: Sequence[float], command: Sequence[float],
                   dt: float | None = None, signal: Signal = "rate",
                   **kw: object) -> AxisModel:
    """Surge model from a log: speed (m/s, ``signal="rate"``) or path increments (m)."""
    return identify_axis(t, y, command, dt, signal, **kw)  # type: ignore[arg-type]


def identify_heading(t: Sequence[float], y: Sequence[float], command: Sequence[float],
                     dt: float | None = None, signal: Signal = "rate",
                     **kw: object) -> AxisModel:
    """Heading model from a log: yaw rate (rad/s) or wrapped heading increments (rad)."""
    return identify_axis(t, y, command, dt, signal, **kw)  # type: ignore[arg-type]
