"""Measurement points of the surge and heading axes, and the commands between them.

algorithms.md §1.3: every GNSS fix (heading) inside a window of ``step_s``
(``heading_step_s``) seconds is averaged into one point at the window's mean time, of
noise variance the mean of the fixes' own variances over their count (a 1 Hz receiver
gives the plain fix, a 5 Hz one five times less variance). Consecutive points give the
increments the axis filters measure. The input over a step between two points is the
time-weighted mean of the commands held over it (zero-order hold).
"""

from __future__ import annotations

import math

from mypy_extensions import mypyc_attr

from onboard.core.geo import wrap_pi

COMMANDS_KEPT = 4096
"""Commands held without a measurement point to trim them; beyond, the oldest half goes."""


@mypyc_attr(allow_interpreted_subclasses=True)
class Window:
    """Running sums of one measurement window (fixes, Doppler speeds, headings).

    Attributes:
        n_fix: fixes; st_fix, sn, se: sums of their times (s) and positions (m);
            sr: of their noise variances (m^2).
        n_v: Doppler speeds; sv: their sum (m/s); svx: sum of their noise variances
            above the configured one ((m/s)^2).
        n_h: headings; st_h, sh: sums of their times (s) and unwrapped values (rad).
        fix_source, heading_source: the sample source of the newest fix and heading.
    """

    __slots__ = ("n_fix", "st_fix", "sn", "se", "sr", "n_v", "sv", "svx", "n_h", "st_h",
                 "sh", "fix_source", "heading_source")

    def __init__(self) -> None:
        self.n_fix = 0
        self.st_fix = self.sn = self.se = 0.0
        self.sr = 0.0
        self.n_v = 0
        self.sv = 0.0
        self.svx = 0.0
        self.n_h = 0
        self.st_h = self.sh = 0.0
        self.fix_source = self.heading_source = ""

    def add_fix(self, t: float, n: float, e: float, var: float, source: str = "") -> None:
        """A fix at ``t`` (s), position ``(n, e)`` (m), noise variance ``var`` (m^2)."""
        self.fix_source = source
        self.n_fix += 1
        self.st_fix += t
        self.sn += n
        self.se += e
        self.sr += var

    def add_speed(self, v: float, extra_var: float) -> None:
        """A Doppler speed ``v`` (m/s) whose noise variance exceeds the configured one
        by ``extra_var`` ((m/s)^2)."""
        self.n_v += 1
        self.sv += v
        self.svx += extra_var

    def add_heading(self, t: float, psi: float, source: str = "") -> None:
        """A heading ``psi`` (rad, unwrapped against the previous one) at ``t`` (s)."""
        self.heading_source = source
        self.n_h += 1
        self.st_h += t
        self.sh += psi

    def fix_point(self) -> tuple[float, float, float, float]:
        """``(t, n, e, R)``: the mean fix and its noise variance, the mean of the fixes'
        variances over their count (independent fixes)."""
        n_fix = self.n_fix
        return (self.st_fix / n_fix, self.sn / n_fix, self.se / n_fix,
                self.sr / (n_fix * n_fix))

    def speed_point(self, sigma_v: float) -> tuple[float | None, float]:
        """``(y_v, R_v)``: the mean Doppler speed (m/s; None without one) and its noise
        variance, the configured ``sigma_v^2`` and the excess of worse fixes, over the
        count."""
        n_v = self.n_v
        if not n_v:
            return None, 0.0
        return self.sv / n_v, sigma_v ** 2 / n_v + self.svx / (n_v * n_v)

    def heading_point(self) -> tuple[float, float]:
        """``(t, psi)``: the mean heading (rad, unwrapped) and its time (s)."""
        return self.st_h / self.n_h, self.sh / self.n_h


@mypyc_attr(allow_interpreted_subclasses=True)
class CommandHistory:
    """The normalized commands of both axes in time order, held (zero-order) until the
    next one: ``(t, surge_command, yaw_command)``, either command None when unknown."""

    def __init__(self) -> None:
        self._cmds: list[tuple[float, float | None, float | None]] = []

    def add(self, t: float, surge: float | None, yaw: float | None) -> None:
        """A command at ``t`` (s)."""
        self._cmds.append((t, surge, yaw))
        if len(self._cmds) > COMMANDS_KEPT:
            del self._cmds[:COMMANDS_KEPT // 2]

    def latest(self, axis: int) -> float | None:
        """The newest command of ``axis`` (1 surge, 2 yaw), None without one."""
        return self._cmds[-1][axis] if self._cmds else None

    def mean(self, t_a: float, t_b: float, axis: int) -> float | None:
        """Time-weighted mean of the command of ``axis`` (1 surge, 2 yaw) held over
        ``[t_a, t_b]`` (s); the newest when the interval is empty, None without any."""
        cmds = self._cmds
        if not cmds:
            return None
        if t_b <= t_a:
            return cmds[-1][axis]
        acc = tot = 0.0
        for i, c in enumerate(cmds):
            t_s = max(c[0], t_a)
            t_e = min(cmds[i + 1][0] if i + 1 < len(cmds) else t_b, t_b)
            v = c[axis]
            if t_e <= t_s or v is None:
                continue
            acc += v * (t_e - t_s)
            tot += t_e - t_s
        return acc / tot if tot > 0.0 else None

    def trim(self, t_keep: float) -> None:
        """Drop the commands no step from ``t_keep`` (s) on needs (keep the one in
        force at ``t_keep``)."""
        keep = 0
        for i, c in enumerate(self._cmds):
            if c[0] <= t_keep:
                keep = i
            else:
                break
        if keep:
            del self._cmds[:keep]


@mypyc_attr(allow_interpreted_subclasses=True)
class HeadingUnwrapper:
    """Headings made continuous (rad): each new one within pi of the previous."""

    def __init__(self) -> None:
        self.last: float | None = None

    def __call__(self, psi: float) -> float:
        """``psi`` (rad) unwrapped against the previous heading."""
        u = psi if self.last is None else self.last + wrap_pi(psi - self.last)
        self.last = u
        return u


def clamp(x: float, lo: float, hi: float) -> float:
    """``x`` limited to ``[lo, hi]``."""
    return lo if x < lo else hi if x > hi else x


def finite_positive(x: float | None) -> bool:
    """True for a finite number above zero."""
    return x is not None and x > 0.0 and math.isfinite(x)
