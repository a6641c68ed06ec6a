"""Whether the data resolve the published current, per axis.

A current filter whose velocity measurements are noisy and whose random walk is fast
follows the measurements' noise: its estimate is ``x_hat = x + n``, the current plus a
noise of variance ``v``, nearly independent of the current. Publishing it errs by
``v``; publishing zero errs by ``E[x^2] = E[x_hat^2] - v``. The estimate is worse than
zero when ``E[x_hat^2] < 2 v``. A random-walk Kalman filter of small gain ``K`` claims
the one-sigma ``sigma`` with ``sigma^2 = K R`` (``R`` the measurement variance) while the
noise its estimate carries about a steady current is ``v = K R / (2 - K)``, about half of
``sigma^2``: the estimate is worse than zero when the RMS of ``x_hat`` is below its own
one-sigma. That is the criterion, over a window of :data:`RESOLVE_WINDOW_S`: the current
it claims lies inside its one-sigma of zero, and the data do not tell it from zero.

It is judged only where that one-sigma is material, above :data:`RESOLVE_MIN_STD_MPS`:
a component known within a smaller sigma is small whatever it is. A filter that follows
the current rather than its noise (a large current, a lagging estimate) can also fail the
criterion; it is then withheld although it was better than zero (the Kolumbo glider's
north current, docs/integrity.md "The current not resolved").
"""

from __future__ import annotations

from array import array

from mypy_extensions import mypyc_attr

RESOLVE_WINDOW_S = 600.0
"""The current's resolution is judged over this long (s): several times the memory of a
current filter (tens of seconds), and a glider's dive and climb."""
RESOLVE_MIN_SPAN = 0.8
"""Share of :data:`RESOLVE_WINDOW_S` the published values must span before it is judged."""
RESOLVE_SNR = 1.0
"""A component is resolved while the RMS of its published value over the window is at
least this many times the RMS of its one-sigma (module docstring: below it, the estimate
is worse than zero when its sigma is its noise's)."""
RESOLVE_MIN_STD_MPS = 0.15
"""A component whose one-sigma (RMS over the window, m/s) is at most this is resolved
whatever its value: its two-sigma is then within the 0.3 m/s beyond which the current
pipeline publishes a component as unknown (``[pipelines.current] unknown_above_std_mps``,
its default)."""
WINDOW_SHIFT_ENTRIES = 1024
"""Entries (count) that leave a window's front before its arrays are shifted down over
them: a shift moves the whole window (12 000 entries a component at 20 ticks a second), so
it runs once per this many ticks, for at most this many stale entries (24 kB) kept."""


@mypyc_attr(allow_interpreted_subclasses=True)
class AxisResolution:
    """One component's window of squared values and squared one-sigmas (m^2/s^2), one
    entry per tick, held as three arrays of doubles (24 B an entry) from index ``_first``.

    Attributes:
        unresolved: the newest verdict (False before the window is judged).
        rms: RMS (m/s) of the published value over the newest judged window.
        sigma: RMS (m/s) of its one-sigma there.
    """

    __slots__ = ("unresolved", "rms", "sigma", "_t", "_x2", "_s2", "_first", "_sx", "_ss")

    def __init__(self) -> None:
        self.unresolved = False
        self.rms = self.sigma = 0.0
        self._t = array("d")  # s
        self._x2 = array("d")  # value^2
        self._s2 = array("d")  # sigma^2
        self._first = 0
        self._sx = self._ss = 0.0

    def add(self, t: float, value: float, std: float) -> bool:
        """The published ``value`` (m/s) and its one-sigma ``std`` at ``t`` (s); returns
        :attr:`unresolved`."""
        ts, xs, ss = self._t, self._x2, self._s2
        x2, s2 = value * value, std * std
        ts.append(t)
        xs.append(x2)
        ss.append(s2)
        self._sx += x2
        self._ss += s2
        i = self._first
        while ts[i] < t - RESOLVE_WINDOW_S:
            self._sx -= xs[i]
            self._ss -= ss[i]
            i += 1
        if i >= WINDOW_SHIFT_ENTRIES:
            del ts[:i]
            del xs[:i]
            del ss[:i]
            i = 0
        self._first = i
        if t - ts[i] < RESOLVE_MIN_SPAN * RESOLVE_WINDOW_S:
            return self.unresolved
        n = len(ts) - i
        self.rms = (max(self._sx, 0.0) / n) ** 0.5
        self.sigma = (max(self._ss, 0.0) / n) ** 0.5
        self.unresolved = (self.sigma > RESOLVE_MIN_STD_MPS
                           and self.rms < RESOLVE_SNR * self.sigma)
        return self.unresolved


@mypyc_attr(allow_interpreted_subclasses=True)
class CurrentResolution:
    """Per component (north, east) of one pipeline's current, whether the data resolve
    it (module docstring)."""

    def __init__(self) -> None:
        self.axes: dict[str, AxisResolution] = {}

    def add(self, t: float, values: dict[str, float], qs: tuple[str, ...]) -> None:
        """The current's components ``qs`` in ``values`` (each with ``std_<q>``) at
        ``t`` (s); a component not published as a number is skipped."""
        for q in qs:
            v, sd = values.get(q), values.get("std_" + q)
            if v is None or sd is None:
                continue
            ax = self.axes.get(q)
            if ax is None:
                ax = self.axes[q] = AxisResolution()
            ax.add(t, v, sd)

    def unresolved(self) -> tuple[str, ...]:
        """The components not resolved now."""
        return tuple(q for q, ax in self.axes.items() if ax.unresolved)
