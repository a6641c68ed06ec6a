"""``wave_oscillation``: first-order wave motion, the orbital velocity of a regular sea.

A long-crested sea of period ``T`` travelling toward ``direction`` moves the water, and a
small boat with it, back and forth along ``direction`` at the phase
``phase = w t - k (N cos(direction) + E sin(direction))`` (``w = 2 pi / T``, deep-water
wavenumber ``k = w^2 / g``). The boat is displaced like the water particles at its
moving mean position, so its wave velocity is the rate of that displacement along its
track: the displacement times the phase rate the boat meets, the *encounter* frequency
``w_e = w - k V . d`` (``V`` its velocity over ground, ``d`` the unit vector toward
``direction``), which changes with its heading and speed. Heading into the waves the
oscillation is faster and larger than the orbital velocity at rest, running with them
slower and smaller. The oscillation is modelled in the earth frame,
``w_n = (w_e / w) (A_n sin(phase) + B_n cos(phase))`` and ``w_e`` alike (four linear
parameters once period and direction are fixed: the orbital velocity at rest, m/s), and
projected on the measured heading for the lateral and along-track channels. Period and
direction come from a search of the residual (:func:`onboard.offline.closure.select.find_wave`).
Without positions, ``k`` is taken as 0 (``w_e = w``). Reported: ``period`` (s),
``direction`` (rad) and the orbital velocity amplitude (m/s).
"""

from __future__ import annotations

import math

import numpy as np

from onboard.offline.closure.effects.base import Context, Effect

GRAVITY = 9.81


def track(ds, window_s: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """The vehicle's north and east positions (m) for the wave phase: the velocity over
    ground integrated along each contiguous segment, pulled onto the GNSS positions by
    their mean offset over ``window_s`` (a complementary filter). A fix is metres off
    (k = 0.64 rad/m at a 2.5 s period), its velocity centimetres per second: the
    integrated track keeps the phase coherent over a wave period, the fixes keep it from
    drifting. Zeros without positions."""
    n = len(ds)
    if not np.isfinite(ds.north).any():
        return np.zeros(n), np.zeros(n)
    change = np.flatnonzero(ds.run[1:] != ds.run[:-1]) + 1
    half = max(1, int(round(0.5 * window_s / ds.dt)))
    out = []
    for fix, vel in ((ds.north, ds.v_n), (ds.east, ds.v_e)):
        res = np.zeros(n)
        for a, b in zip(np.r_[0, change], np.r_[change, n]):
            t = ds.t[a:b]
            v = np.nan_to_num(vel[a:b])
            p = np.r_[0.0, np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))]
            off = fix[a:b] - p
            ok = np.isfinite(off)
            if not ok.any():
                continue
            # centred mean of the finite offsets over the window (clipped at the ends)
            i = np.arange(b - a)
            lo, hi = np.maximum(i - half, 0), np.minimum(i + half + 1, b - a)
            num = np.r_[0.0, np.cumsum(np.where(ok, off, 0.0))]
            den = np.r_[0.0, np.cumsum(ok)]
            cnt = den[hi] - den[lo]
            mean = (num[hi] - num[lo]) / np.maximum(cnt, 1.0)
            res[a:b] = p + np.where(cnt > 0, mean, float(np.mean(off[ok])))
        out.append(res)
    return out[0], out[1]


def wave_phase(ds, period_s: float, direction_rad: float) -> np.ndarray:
    """Phase (rad) of a deep-water wave of ``period_s`` toward ``direction_rad`` as seen
    by the vehicle along its :func:`track`."""
    w = 2.0 * math.pi / period_s
    k = w * w / GRAVITY
    north, east = track(ds)
    return w * ds.t - k * (north * math.cos(direction_rad) + east * math.sin(direction_rad))


def encounter_rate(ds, period_s: float, direction_rad: float) -> np.ndarray:
    """Rate (rad/s) of the wave phase of :func:`wave_phase` at the vehicle: the encounter
    frequency ``w - k V . d`` at its measured velocity over ground ``V`` (``w`` alone
    without positions)."""
    w = 2.0 * math.pi / period_s
    if not np.isfinite(ds.north).any():
        return np.full(len(ds), w)
    k = w * w / GRAVITY
    v_d = np.nan_to_num(ds.v_n) * math.cos(direction_rad) + np.nan_to_num(ds.v_e) * math.sin(direction_rad)
    return w - k * v_d


class WaveOscillation(Effect):
    """The orbital velocity of a regular sea at the encounter phase (module docstring);
    the period and direction come from the residual's spectrum."""

    name = "wave_oscillation"
    params = ("n_sin", "n_cos", "e_sin", "e_cos")

    def applies(self, ds, ctx: Context):
        """Only when the residual's spectrum showed a wave period (``ctx.wave_period_s``)."""
        return ctx.wave_period_s is not None

    def _basis(self, ds, ctx):
        direction = ctx.extra.get("wave_direction", 0.0)
        ph = wave_phase(ds, ctx.wave_period_s, direction)
        gain = encounter_rate(ds, ctx.wave_period_s, direction) * ctx.wave_period_s / (2.0 * math.pi)
        return gain * np.sin(ph), gain * np.cos(ph)

    def columns(self, ds, ctx):
        """The lateral channel's four columns. None in the derivative-form along channel:
        its target, a derivative smoothed over 1 s, attenuates an oscillation of a few
        seconds (docs/diagnose.md has the amplitudes with and without it), so the
        coefficients come from the lateral channel alone and the along channel carries the
        wave open loop (:meth:`along_output`)."""
        s, c = self._basis(ds, ctx)
        cp, sp = np.cos(ds.psi), np.sin(ds.psi)
        return {"lateral": np.column_stack([-sp * s, -sp * c, cp * s, cp * c])}

    def along_output(self, theta, ds, ctx):
        s, c = self._basis(ds, ctx)
        wn = theta[0] * s + theta[1] * c
        we = theta[2] * s + theta[3] * c
        return np.cos(ds.psi) * wn + np.sin(ds.psi) * we

    def describe(self, theta, std):
        amp = math.sqrt(0.5 * float(np.sum(np.asarray(theta) ** 2)))
        return ({"period": float("nan"), "direction": float("nan"),
                 "velocity_amplitude_mps": math.sqrt(2.0) * amp},
                {"velocity_amplitude_mps": float(np.sqrt(np.mean(np.asarray(std) ** 2)))})


EFFECT = WaveOscillation()


BATCH_ELEMENTS = 2_000_000
"""Samples x cells of one batch of :func:`lateral_shares` (each of its ten or so working
arrays is then at most 16 MB, whatever the log's length)."""
BATCH_CELLS = 500
"""Most cells in one batch of :func:`lateral_shares` (a short log's batch)."""


def _block_sums(starts: np.ndarray, n: int, rows: tuple[np.ndarray, ...]):
    """The sparse matrix that sums weighted samples by block: for each weight array ``w``
    of ``rows`` (length ``n``) one band of ``len(starts)`` rows, row ``b`` holding ``w`` on
    the samples of block ``b`` (``starts[b]`` up to the next start) and zeros elsewhere.
    ``M @ x`` is then, band by band, ``sum over block b of w * x``. Sparse: one entry per
    sample and weight, where the dense indicator was blocks x samples."""
    from scipy import sparse

    nb = len(starts)
    block = np.repeat(np.arange(nb), np.diff(np.r_[starts, n]))
    cols = np.arange(n)
    return sparse.vstack([sparse.csr_matrix((w, (block, cols)), shape=(nb, n)) for w in rows],
                         format="csr")


def lateral_shares(t: np.ndarray, north: np.ndarray, east: np.ndarray, psi: np.ndarray,
                   y: np.ndarray, periods: np.ndarray, directions: np.ndarray,
                   block_starts: np.ndarray | None = None, chunk: int | None = None,
                   v_north: np.ndarray | None = None,
                   v_east: np.ndarray | None = None) -> np.ndarray:
    """Share of the variance of the lateral residual ``y`` (m/s, zero mean) that the wave's
    lateral regressors (:meth:`WaveOscillation.columns`; with the encounter factor when
    the velocities are given) explain, for each cell
    ``(periods[i], directions[i])`` (s, rad), by least squares.

    With ``block_starts`` (indices where blocks begin) the four coefficients are fitted
    per block: each block is explained by a wave of its own amplitude and phase, so only
    the *encounter frequency* within a block has to match (the phase rate ``w - k V . d``
    at the block's velocity over ground ``V``), not the phase carried over the whole
    record. Without it one set of coefficients holds for all samples (the coherent fit
    that :class:`WaveOscillation` makes). The normal equations of all cells are built at
    once from block sums of the products of ``sin``/``cos`` of the phase and the heading.

    Args:
        t: time (s) of each sample.
        north: north position (m; zeros without positions).
        east: east position (m).
        psi: measured heading (rad).
        y: the residual to explain (m/s), zero mean.
        periods: wave period (s) of each cell.
        directions: direction the waves travel toward (rad) of each cell.
        block_starts: first index of each block, starting with 0; None for one block.
        chunk: cells evaluated per batch (memory: about 10 arrays of ``len(t) x chunk``);
            None for as many as keep each array within :data:`BATCH_ELEMENTS`, at most
            :data:`BATCH_CELLS`. The shares do not depend on it beyond the last digit.
        v_north: velocity over ground north (m/s), for the encounter factor ``w_e / w``
            of the regressors; None (with ``v_east``) for none.
        v_east: velocity over ground east (m/s).
    """
    y = np.asarray(y, float)
    n = len(y)
    sp, cp = np.sin(psi), np.cos(psi)
    starts = np.array([0]) if block_starts is None else np.asarray(block_starts, int)
    nb = len(starts)
    weights = _block_sums(starts, n, (sp * sp, sp * cp, cp * cp))
    proj = _block_sums(starts, n, (sp * y, cp * y))
    total = float(y @ y)
    out = np.zeros(len(periods))
    if total <= 0.0:
        return out
    if chunk is None:
        chunk = max(1, min(BATCH_CELLS, BATCH_ELEMENTS // max(n, 1)))
    for a in range(0, len(periods), chunk):
        w = 2.0 * math.pi / np.asarray(periods[a:a + chunk], float)
        d = np.asarray(directions[a:a + chunk], float)
        k = w * w / GRAVITY
        ph = np.outer(t, w) - np.outer(north, k * np.cos(d)) - np.outer(east, k * np.sin(d))
        s, c = np.sin(ph), np.cos(ph)
        if v_north is not None and v_east is not None:
            gain = 1.0 - (np.outer(v_north, np.cos(d)) + np.outer(v_east, np.sin(d))) * (k / w)
            s, c = gain * s, gain * c
        m = len(w)
        ss, sc, cc = ((weights @ x).reshape(3, nb, m) for x in (s * s, s * c, c * c))
        ys, yc = (proj @ s).reshape(2, nb, m), (proj @ c).reshape(2, nb, m)
        # columns [-sp s, -sp c, cp s, cp c]; ss[0] = sum sp^2 s^2, ss[1] = sum sp cp s^2 ...
        A = np.empty((nb, m, 4, 4))
        A[..., 0, 0], A[..., 0, 1], A[..., 0, 2], A[..., 0, 3] = ss[0], sc[0], -ss[1], -sc[1]
        A[..., 1, 1], A[..., 1, 2], A[..., 1, 3] = cc[0], -sc[1], -cc[1]
        A[..., 2, 2], A[..., 2, 3], A[..., 3, 3] = ss[2], sc[2], cc[2]
        for i in range(4):
            for j in range(i):
                A[..., i, j] = A[..., j, i]
        b = np.stack([-ys[0], -yc[0], ys[1], yc[1]], axis=-1)
        A += (1e-9 * np.trace(A, axis1=-2, axis2=-1)[..., None, None] + 1e-12) * np.eye(4)
        x = np.linalg.solve(A, b[..., None])[..., 0]
        out[a:a + chunk] = np.sum(x * b, axis=-1).sum(axis=0) / total
    return out
